//! The bank stage of the pipeline: scene -> organ mesh and supports ([`crate::organ`]) ->
//! reachable region R ([`crate::reach::Region`]) -> factorised compliance -> bank bytes: the
//! bank models only what the scene's tool can reach.
//!
//! [`Prepared`] holds the three stages (the compliance stays factorised, so the display can
//! produce any column on demand); [`Prepared::bank`] writes a bank, the one [`BankSpec`] names
//! (the scene's, a nodal one at another radius or precision, a sampled one from samples
//! computed already). `host bank`, `host demo`, `host sil` and the tests all go through here.
//! Two other products are not firmware banks and keep their own names: the contact samples
//! ([`Prepared::sampled_parts`], the costly part of a sampled bank, cached on their own) and
//! the host's probe bank ([`Prepared::probe_bank`]: unbounded, every pair one tool patch can
//! load, read only on the host). [`tool_pairs`] finds the pairs a tool contact loads together;
//! [`stats`] measures what a built bank gives the firmware (tool patches, detection
//! candidates).

pub mod cache;
pub mod sampled;
pub mod stats;
pub mod sweep;
pub mod tool_pairs;

pub use tool_pairs::{TOOL_DIVISIONS, ToolPairs, UNCOUPLED_TOL};

use crate::cache::fnv1a;
use crate::organ::Organ;
use crate::reach::Region;
use crate::scene::{ContactModel, Couplings, SampledContact, Scene};
use anyhow::{Context, Result, bail};
use bank_format::region::BANK_LEN;
use bank_format::{AlignedBytes, Bank, BankBuilder};
use fem::compliance::{Block3, Compliance};
use fem::progress::Progress;
use std::collections::BTreeSet;
use std::path::Path;

/// Rows of compliance blocks over R: `rows[a]` lists `(b, C(R[a], R[b]))` sorted by `b`.
pub type BlockRows = Vec<Vec<(usize, Block3)>>;

/// A bank's bytes and how many coupled pairs `C_kl` it keeps.
pub struct BuiltBank {
    /// The bank, as `host bank build` writes it.
    pub bytes: Vec<u8>,
    /// Coupled pairs `k < l` stored.
    pub pairs: usize,
    /// What the contact sampling measured (a sampled scene's bank only).
    pub sampled: Option<sampled::SampleStats>,
}

/// A sampled scene's contact samples, what computing them measured, and the hashes of the FEM
/// meshes they were computed on ([`Prepared::sampled_parts`]).
#[derive(Debug, Clone, PartialEq)]
pub struct SampledParts {
    /// The samples.
    pub samples: bank_format::ContactSamples,
    /// What computing them measured.
    pub stats: sampled::SampleStats,
    /// The FEM mesh's hash, then the Richardson partner's if any.
    pub mesh_hashes: Vec<u64>,
}

/// Which bank [`Prepared::bank`] writes.
pub enum BankSpec<'a> {
    /// The scene's bank, as `host bank build` writes it: a sampled scene's from its contact
    /// samples ([`Prepared::sampled_parts`], then as [`BankSpec::Sampled`]); a nodal scene's by
    /// its coupling rule (`bank.couplings`): the pairs within `bank.truncation_radius_m`, with
    /// "tool" also [`ToolPairs::sample`]'s, in `bank.precision`. The progress, if any, counts
    /// the compliance's supernodes (or the samples).
    Scene {
        /// Progress of the precompute.
        progress: Option<&'a dyn Progress>,
    },
    /// A nodal bank from `rows` (computed by [`Prepared::blocks`] for at least `radius`, and
    /// holding the pairs of `extra`): every pair within `radius`, every triangle edge and every
    /// pair of `extra` (`(a, b)`, `a < b`, indices into R) coupled. With `extra` the bank's
    /// truncation radius (its coverage guarantee, `SPEC.md` check 14) is the distance of the
    /// closest pair left uncoupled, if that exceeds `radius`.
    Nodal {
        /// Compliance rows over R.
        rows: &'a [Vec<(usize, Block3)>],
        /// Truncation radius, m.
        radius: f64,
        /// Pairs coupled besides those within `radius` and the triangle edges.
        extra: Option<&'a BTreeSet<(usize, usize)>>,
        /// Storage precision of the coupling blocks `C_kl`.
        precision: bank_format::Precision,
    },
    /// A sampled bank from contact samples already computed: R's collision data, the nodal
    /// compliance with only the triangle edges coupled (the nodal contact models' minimum, for
    /// comparison), the samples; its scene id is the scene's, then each FEM mesh's hash
    /// ([`SampledParts::mesh_hashes`]), and the blocks are stored in `bank.precision`.
    Sampled(SampledParts),
}

/// The pipeline's three stages up to the bank, for one scene: the organ, its reachable region
/// and its factorised compliance.
pub struct Prepared {
    /// The mesh stage: scene, mesh, boundary, supports.
    pub organ: Organ,
    /// The reach stage: R.
    pub region: Region,
    /// The compliance stage: `K_ff` factorised with the scene's supports.
    pub compliance: Compliance,
}

impl Prepared {
    /// [`Prepared::from_scene`] on the scene file at `path`.
    pub fn load(path: &Path) -> Result<Prepared> {
        Prepared::from_scene(Scene::load(path)?)
    }

    /// The organ ([`Organ::from_scene`]), its region ([`Region::of`]) and its compliance
    /// ([`Organ::factorize`]).
    pub fn from_scene(scene: Scene) -> Result<Prepared> {
        let organ = Organ::from_scene(scene)?;
        let region = Region::of(&organ)?;
        let compliance = organ.factorize()?;
        Ok(Prepared {
            organ,
            region,
            compliance,
        })
    }

    /// Blocks of R within `radius`, and at least along every triangle edge; the progress, if
    /// any, counts supernodes.
    pub fn blocks(&self, radius: f64, progress: Option<&dyn Progress>) -> Result<BlockRows> {
        Ok(self.compliance.blocks_within(
            &self.region.nodes,
            &self.region.positions,
            // Widened by a hair: the longest edge itself must pass the squared-distance test.
            radius.max(self.region.longest_edge() * (1.0 + 1e-9)),
            progress,
        )?)
    }

    /// A radius within which every pair of nodes one tool patch can load lies: a patch node
    /// is within the tip radius of the anchor (nodal quadrature) or a vertex of a triangle
    /// holding a quadrature point within the tip radius, so two of them are at most
    /// `2 (r + longest edge)` apart (checked by [`ToolPairs::sample`]).
    pub fn probe_radius(&self) -> f64 {
        2.0 * (self.organ.scene.tip_radius_m.max(0.0) + self.region.longest_edge()) * (1.0 + 1e-3)
    }

    /// The bank `spec` describes (see [`BankSpec`]).
    pub fn bank(&self, spec: &BankSpec<'_>) -> Result<BuiltBank> {
        match spec {
            BankSpec::Scene { progress } => self.by_scene(*progress),
            BankSpec::Nodal {
                rows,
                radius,
                extra,
                precision,
            } => {
                let (builder, pairs) = self.builder_in(rows, *radius, *extra)?;
                Ok(BuiltBank {
                    bytes: write(builder, *precision)?,
                    pairs,
                    sampled: None,
                })
            }
            BankSpec::Sampled(parts) => {
                let scene_id = parts
                    .mesh_hashes
                    .iter()
                    .fold(self.organ.scene_id, |id, h| fnv1a(id, &h.to_le_bytes()));
                let rows = self.blocks(0.0, None)?;
                let (mut builder, pairs) = self.builder_in(&rows, 0.0, None)?;
                builder.samples = Some(parts.samples.clone());
                builder.scene_id = scene_id;
                Ok(BuiltBank {
                    bytes: write(builder, self.organ.scene.bank.precision)?,
                    pairs,
                    sampled: Some(parts.stats),
                })
            }
        }
    }

    /// The scene's bank ([`BankSpec::Scene`]).
    fn by_scene(&self, progress: Option<&dyn Progress>) -> Result<BuiltBank> {
        let scene = &self.organ.scene;
        if let ContactModel::Sampled(spec) = &scene.contact {
            return self.bank(&BankSpec::Sampled(self.sampled_parts(spec, progress)?));
        }
        let radius = scene.bank.truncation_radius_m;
        let (rows, extra) = match scene.bank.couplings {
            Couplings::Radius => (self.blocks(radius, progress)?, None),
            Couplings::Tool => {
                let rows = self.blocks(radius.max(self.probe_radius()), progress)?;
                let pairs = self.tool_pairs_from(&rows)?.pairs;
                (rows, Some(pairs))
            }
        };
        self.bank(&BankSpec::Nodal {
            rows: &rows,
            radius,
            extra: extra.as_ref(),
            precision: scene.bank.precision,
        })
    }

    /// The writer's input for a nodal bank ([`BankSpec::Nodal`]), and the number of coupled
    /// pairs.
    fn builder_in(
        &self,
        rows: &[Vec<(usize, Block3)>],
        radius: f64,
        extra: Option<&BTreeSet<(usize, usize)>>,
    ) -> Result<(BankBuilder, usize)> {
        let region = &self.region;
        let scene = &self.organ.scene;
        let mut edges = region.edges();
        if let Some(extra) = extra {
            edges.extend(extra.iter().copied());
        }
        let mut c_kk = Vec::with_capacity(rows.len());
        let mut couplings = Vec::new();
        for (a, row) in rows.iter().enumerate() {
            let mut diag = None;
            for &(b, block) in row {
                if b == a {
                    diag = Some(block);
                } else if b > a && (region.dist(a, b) <= radius || edges.contains(&(a, b))) {
                    couplings.push((a as u32, b as u32, block));
                }
            }
            c_kk.push(diag.context("internal: a node's own block is missing")?);
        }
        let mut coverage = radius;
        if let Some(extra) = extra {
            let kept: BTreeSet<(usize, usize)> = couplings
                .iter()
                .map(|c| (c.0 as usize, c.1 as usize))
                .collect();
            if let Some(&p) = extra.iter().find(|p| !kept.contains(p)) {
                bail!(
                    "internal: the blocks of the tool's pair {p:?} were not computed (they lie \
                     beyond the rows' radius)"
                );
            }
            // The closest pair left out bounds the radius within which every pair is kept.
            let n = region.len();
            let closest = (0..n)
                .flat_map(|a| (a + 1..n).map(move |b| (a, b)))
                .filter(|p| !kept.contains(p))
                .map(|(a, b)| region.dist(a, b))
                .fold(f64::INFINITY, f64::min);
            if closest.is_finite() {
                coverage = coverage.max(closest * (1.0 - 1e-3));
            }
        }
        let grid = scene
            .bank
            .grid_cell_m
            .unwrap_or_else(|| region.mean_edge().max(1e-3));
        let pairs = couplings.len();
        let builder = BankBuilder {
            positions_m: region.positions.clone(),
            mesh_ids: region.nodes.iter().map(|&k| k as u32).collect(),
            triangles: region.triangles.clone(),
            c_kk,
            couplings,
            grid_cell_size_m: grid,
            truncation_radius_m: coverage,
            scene_id: self.organ.scene_id,
            law: scene.law,
            gravity: scene.gravity.map(|c| bank_format::GravityCompensation {
                coeffs: c.map(|v| v as f32),
            }),
            relaxation: scene
                .viscoelastic
                .as_ref()
                .map(|v| v.record())
                .transpose()
                .map_err(|e| anyhow::anyhow!("[viscoelastic]: {e}"))?,
            samples: None,
            device: scene.device,
        };
        Ok((builder, pairs))
    }
}

impl Prepared {
    /// The contact samples of a sampled scene ([`sampled::contact_samples`] on the scene's FEM
    /// mesh, Richardson-extrapolated with the coarse one when the scene says so) and the hashes
    /// of the FEM meshes, which the bank's scene id covers.
    pub fn sampled_parts(
        &self,
        spec: &SampledContact,
        progress: Option<&dyn Progress>,
    ) -> Result<SampledParts> {
        let fem = sampled::SampledFem::new(&self.organ.scene, spec)?;
        let (positions, triangles) = (&self.region.positions, &self.region.triangles);
        let r = self.organ.scene.tip_radius_m;
        let Some(rich) = &spec.richardson else {
            let (samples, stats) =
                sampled::contact_samples(&fem, positions, triangles, spec.level, r, progress)?;
            return Ok(SampledParts {
                samples,
                stats,
                mesh_hashes: vec![fem.mesh_hash],
            });
        };
        let (lattice, points) = sampled::lattice_points(positions, triangles, spec.level);
        // W on the fine mesh, then (its factor dropped first) on the coarse one.
        let t0 = std::time::Instant::now();
        let (w_fine, at, widest) = fem.patch_compliance(&points, r, progress)?;
        let fine_s = t0.elapsed().as_secs_f64();
        let (mut samples, mut stats) = sampled::samples_from(
            lattice, &points, w_fine, &at, widest, &fem, spec.level, r, fine_s,
        )?;
        let fem_hash = fem.mesh_hash;
        drop(fem);
        let coarse = sampled::SampledFem::load(&self.organ.scene, &rich.mesh, spec.element)?;
        let t1 = std::time::Instant::now();
        let (w_coarse, ..) = coarse.patch_compliance(&points, r, progress)?;
        samples.w = sampled::extrapolated(&samples.w, &w_coarse, rich.factor());
        if let Some(s) = samples.w.iter().position(|w| !sampled::spd(w)) {
            let p = points[s];
            bail!(
                "the Richardson-extrapolated patch compliance at [{:.4}, {:.4}, {:.4}] m is not \
                 positive definite: {} and {} disagree too much there (lower \
                 contact.richardson_order, or drop the extrapolation)",
                p[0],
                p[1],
                p[2],
                spec.fem_mesh.display(),
                rich.mesh.display()
            );
        }
        stats.factor_s += coarse.factor_s;
        stats.w_s += t1.elapsed().as_secs_f64();
        Ok(SampledParts {
            samples,
            stats,
            mesh_hashes: vec![fem_hash, coarse.mesh_hash],
        })
    }

    /// The probe bank: every pair within [`Prepared::probe_radius`] coupled, from `rows`
    /// (computed for at least that radius), f32 blocks. The host's own: it couples every pair
    /// one tool patch can load, however many a node (about 200 on the shipped liver), beyond
    /// the firmware's tick limits (`BankBuilder::build_unbounded`, read with
    /// `Bank::parse_unbounded`).
    pub fn probe_bank(&self, rows: &[Vec<(usize, Block3)>]) -> Result<AlignedBytes> {
        let (builder, _) = self.builder_in(rows, self.probe_radius(), None)?;
        let bytes = builder
            .build_unbounded(bank_format::Precision::F32)
            .map_err(|e| anyhow::anyhow!("internal: the probe bank is invalid: {e}"))?;
        Ok(AlignedBytes::new(&bytes))
    }

    /// [`ToolPairs::sample`] on the probe bank built from `rows` (computed for at least
    /// [`Prepared::probe_radius`]).
    pub fn tool_pairs_from(&self, rows: &[Vec<(usize, Block3)>]) -> Result<ToolPairs> {
        let aligned = self.probe_bank(rows)?;
        let bank = Bank::parse_unbounded(&aligned)
            .map_err(|e| anyhow::anyhow!("internal: the probe bank is invalid: {e}"))?;
        ToolPairs::sample(&bank, self.organ.scene.tip_radius_m, TOOL_DIVISIONS)
    }
}

/// The bank's bytes from the writer's input, blocks stored in `precision`.
fn write(builder: BankBuilder, precision: bank_format::Precision) -> Result<Vec<u8>> {
    builder
        .build_with_precision(precision)
        .map_err(|e| anyhow::anyhow!("the bank writer refused the scene's data: {e}"))
}

/// The bank of the scene file at `scene` (what `host bank build` writes), refused when it does
/// not fit the device's bank region ([`BANK_LEN`]).
/// A sampled scene's bank comes from the cache ([`cache::scene_bank_cached`]) when its inputs
/// are unchanged.
pub fn scene_bank(scene: &Path) -> Result<Vec<u8>> {
    let prep = Prepared::load(scene)?;
    let bytes = cache::scene_bank_cached(&prep, None)?.0.bytes;
    if bytes.len() > BANK_LEN {
        bail!(
            "{}: the bank would be {} bytes, more than the {BANK_LEN} bytes of the bank region",
            scene.display(),
            bytes.len()
        );
    }
    Ok(bytes)
}
