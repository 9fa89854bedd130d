//! The bank stage of the pipeline: scene -> mesh and supports -> reachable region R ->
//! factorised compliance -> bank bytes: the bank models only what the scene's tool can reach.
//!
//! [`Prepared`] holds a scene with everything the later stages need (the compliance stays
//! factorised, so the display can produce any column on demand); [`Prepared::build_bank`]
//! writes the scene's bank. `host bank`, `host demo`, `host sil` and the tests all go through
//! here. [`stats`] measures what a built bank gives the firmware (tool patches, detection
//! candidates).

pub mod cache;
pub mod precompute;
pub mod sampled;
pub mod stats;
pub mod sweep;

use crate::kinematics::Workspace;
use crate::reach::reachable;
use crate::scene::{ContactModel, Couplings, SampledContact, Scene, fnv1a};
use anyhow::{Context, Result, bail};
use bank_format::region::BANK_LEN;
use bank_format::{AlignedBytes, Bank, BankBuilder};
use fem::compliance::{Block3, Compliance};
use fem::elasticity::{Elasticity, FixedSet};
use fem::mesh::{Surface, TetMesh};
use fem::progress::Progress;
use std::collections::{BTreeSet, HashMap};
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

/// A scene with its mesh, supports, factorised compliance and reachable region.
pub struct Prepared {
    /// The scene as read.
    pub scene: Scene,
    /// Its organ mesh, validated.
    pub mesh: TetMesh,
    /// The mesh's name for messages (file name, or the embedded mesh's name).
    pub mesh_name: String,
    /// The mesh's boundary.
    pub surface: Surface,
    /// `K_ff` factorised with the scene's supports.
    pub compliance: Compliance,
    /// The scene's identity written into the bank (scene file and mesh contents).
    pub scene_id: u64,
    /// R: mesh node ids, ascending.
    pub region: Vec<usize>,
    /// R's positions.
    pub positions: Vec<[f64; 3]>,
    /// Boundary triangles with all three vertices in R, as indices into `region`.
    pub triangles: Vec<[u32; 3]>,
    /// What is doubtful but not wrong (P1 locking, an implausible organ size), for the
    /// commands to print.
    pub warnings: Vec<String>,
}

/// Organ sizes (bounding-box diagonal, m) that are plausible in metres: a millimetre-sized
/// specimen up to a whole torso.
pub const ORGAN_SIZE_RANGE_M: (f64, f64) = (1e-3, 1.0);

/// A warning when `mesh`'s size is implausible in metres (a mesh in millimetres is 1000 times
/// too large, and silently 1000 times too soft per unit force).
pub fn mesh_size_warning(mesh: &TetMesh, name: &str) -> Option<String> {
    let (lo, hi) = mesh.bounding_box();
    let size = fem::vec3::norm(fem::vec3::sub(hi, lo));
    (!(ORGAN_SIZE_RANGE_M.0..=ORGAN_SIZE_RANGE_M.1).contains(&size)).then(|| {
        format!(
            "warning: {name} spans {size:.4} m, outside the [{}, {}] m an organ has: are its \
             coordinates in metres (a mesh in millimetres is 1000 times too large)?",
            ORGAN_SIZE_RANGE_M.0, ORGAN_SIZE_RANGE_M.1
        )
    })
}

impl Prepared {
    /// [`Prepared::from_scene`] on the scene file at `path`.
    pub fn load(path: &Path) -> Result<Prepared> {
        Prepared::from_scene(Scene::load(path)?)
    }

    /// Loads the scene's mesh, factorises its compliance and finds its reachable region.
    pub fn from_scene(scene: Scene) -> Result<Prepared> {
        let path = scene.path.clone();
        let (mesh, mesh_name, mesh_hash) = scene.load_mesh()?;
        let surface = fem::mesh::boundary(&mesh)?;
        let fixed: FixedSet = scene.fixed_set(&mesh)?;
        let workspace = Workspace::from_device(&scene.device);
        if let Some(t) = mesh.tet_containing(workspace.fulcrum) {
            bail!(
                "{}: device.fulcrum_m lies inside the organ (tetrahedron {t}): the trocar must be \
                 outside the tissue it enters",
                path.display()
            );
        }
        let home = scene.device.home_joint.map(f64::from);
        let home_tip = workspace.tip(home[0], home[1], home[2]);
        if let Some(t) = mesh.tet_containing(home_tip) {
            bail!(
                "{}: device.home puts the tool tip inside the organ (tetrahedron {t}, tip at \
                 [{:.4}, {:.4}, {:.4}] m): the device starts with its tip outside the tissue",
                path.display(),
                home_tip[0],
                home_tip[1],
                home_tip[2]
            );
        }
        if fixed.count() == 3 * mesh.nodes.len() {
            bail!(
                "{}: [fixed] holds every node of the mesh: nothing can deform (every compliance \
                 would be zero); fix only the supports",
                path.display()
            );
        }
        let region = reachable(
            &workspace,
            &mesh.nodes,
            &surface.nodes,
            |k| (0..3).any(|c| fixed.is_fixed(k, c)),
            scene.tip_radius_m,
            scene.bank.reach_margin_m,
        );
        if region.is_empty() {
            bail!(
                "{}: the tool reaches no free surface node (check device.fulcrum_m, the ranges \
                 and bank.reach_margin_m)",
                path.display()
            );
        }
        if region.len() > bank_format::MAX_NODES {
            bail!(
                "{}: the reachable region has {} nodes; a bank holds at most {} (u16 indices): \
                 narrow the device's ranges",
                path.display(),
                region.len(),
                bank_format::MAX_NODES
            );
        }
        let local: HashMap<usize, u32> = region
            .iter()
            .enumerate()
            .map(|(i, &k)| (k, i as u32))
            .collect();
        let triangles = surface
            .triangles
            .iter()
            .filter_map(|t| Some([*local.get(&t[0])?, *local.get(&t[1])?, *local.get(&t[2])?]))
            .collect();
        let positions = region.iter().map(|&k| mesh.nodes[k]).collect();
        let body = Elasticity::with_element(&mesh, scene.material, scene.element)?;
        let compliance = Compliance::factorize(&body, &fixed)
            .with_context(|| format!("{}: [fixed]", path.display()))?;
        let scene_id = scene.scene_id(mesh_hash);
        let mut warnings = scene.warnings();
        warnings.extend(mesh_size_warning(&mesh, &mesh_name));
        Ok(Prepared {
            scene,
            mesh,
            mesh_name,
            surface,
            compliance,
            scene_id,
            region,
            positions,
            triangles,
            warnings,
        })
    }

    /// R's triangle edges `(a, b)`, `a < b`, as indices into [`Prepared::region`].
    pub fn edges(&self) -> BTreeSet<(usize, usize)> {
        let mut e = BTreeSet::new();
        for t in &self.triangles {
            for i in 0..3 {
                let (a, b) = (t[i] as usize, t[(i + 1) % 3] as usize);
                e.insert((a.min(b), a.max(b)));
            }
        }
        e
    }

    /// Distance between R's nodes `a` and `b` at rest, m.
    pub fn dist(&self, a: usize, b: usize) -> f64 {
        let (p, q) = (self.positions[a], self.positions[b]);
        (0..3).map(|i| (p[i] - q[i]).powi(2)).sum::<f64>().sqrt()
    }

    /// Mean length of R's triangle edges, m (0 without triangles).
    pub fn mean_edge(&self) -> f64 {
        let e = self.edges();
        if e.is_empty() {
            return 0.0;
        }
        e.iter().map(|&(a, b)| self.dist(a, b)).sum::<f64>() / e.len() as f64
    }

    /// Length of R's longest triangle edge, m (0 without triangles).
    pub fn longest_edge(&self) -> f64 {
        self.edges()
            .iter()
            .map(|&(a, b)| self.dist(a, b))
            .fold(0.0, f64::max)
    }

    /// Blocks of R within `radius`, and at least along every triangle edge; the progress, if
    /// any, counts supernodes.
    pub fn blocks(&self, radius: f64, progress: Option<&dyn Progress>) -> Result<BlockRows> {
        Ok(self.compliance.blocks_within(
            &self.region,
            &self.positions,
            // Widened by a hair: the longest edge itself must pass the squared-distance test.
            radius.max(self.longest_edge() * (1.0 + 1e-9)),
            progress,
        )?)
    }

    /// A radius within which every pair of nodes one tool patch can load lies: a patch node
    /// is within the tip radius of the anchor (nodal quadrature) or a vertex of a triangle
    /// holding a quadrature point within the tip radius, so two of them are at most
    /// `2 (r + longest edge)` apart (checked by [`Prepared::tool_pairs`]).
    pub fn probe_radius(&self) -> f64 {
        2.0 * (self.scene.tip_radius_m.max(0.0) + self.longest_edge()) * (1.0 + 1e-3)
    }

    /// The bank for truncation radius `radius` from `rows` (computed for at least that
    /// radius by [`Prepared::blocks`]).
    pub fn bank(&self, rows: &[Vec<(usize, Block3)>], radius: f64) -> Result<BuiltBank> {
        self.bank_keeping(rows, radius, None)
    }

    /// The bank that couples every pair within `radius`, every triangle edge and, if given,
    /// every pair of `extra` (`(a, b)`, `a < b`, indices into R; `rows` must hold them). With
    /// `extra` the bank's truncation radius (its coverage guarantee, `SPEC.md` check 14) is the
    /// distance of the closest pair left uncoupled, if that exceeds `radius`.
    pub fn bank_keeping(
        &self,
        rows: &[Vec<(usize, Block3)>],
        radius: f64,
        extra: Option<&BTreeSet<(usize, usize)>>,
    ) -> Result<BuiltBank> {
        self.bank_in(rows, radius, extra, self.scene.bank.precision)
    }

    /// [`Prepared::bank_keeping`] with the coupling blocks stored in `precision` (the scene's
    /// `bank.precision` aside).
    pub fn bank_in(
        &self,
        rows: &[Vec<(usize, Block3)>],
        radius: f64,
        extra: Option<&BTreeSet<(usize, usize)>>,
        precision: bank_format::Precision,
    ) -> Result<BuiltBank> {
        let (builder, pairs) = self.builder_in(rows, radius, extra)?;
        let bytes = builder
            .build_with_precision(precision)
            .map_err(|e| anyhow::anyhow!("the bank writer refused the scene's data: {e}"))?;
        Ok(BuiltBank {
            bytes,
            pairs,
            sampled: None,
        })
    }

    /// The writer's input for [`Prepared::bank_in`], and the number of coupled pairs.
    fn builder_in(
        &self,
        rows: &[Vec<(usize, Block3)>],
        radius: f64,
        extra: Option<&BTreeSet<(usize, usize)>>,
    ) -> Result<(BankBuilder, usize)> {
        let mut edges = self.edges();
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
                } else if b > a && (self.dist(a, b) <= radius || edges.contains(&(a, b))) {
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
            let n = self.positions.len();
            let closest = (0..n)
                .flat_map(|a| (a + 1..n).map(move |b| (a, b)))
                .filter(|p| !kept.contains(p))
                .map(|(a, b)| self.dist(a, b))
                .fold(f64::INFINITY, f64::min);
            if closest.is_finite() {
                coverage = coverage.max(closest * (1.0 - 1e-3));
            }
        }
        let grid = self
            .scene
            .bank
            .grid_cell_m
            .unwrap_or_else(|| self.mean_edge().max(1e-3));
        let pairs = couplings.len();
        let builder = BankBuilder {
            positions_m: self.positions.clone(),
            mesh_ids: self.region.iter().map(|&k| k as u32).collect(),
            triangles: self.triangles.clone(),
            c_kk,
            couplings,
            grid_cell_size_m: grid,
            truncation_radius_m: coverage,
            scene_id: self.scene_id,
            law: self.scene.law,
            gravity: self
                .scene
                .gravity
                .map(|c| bank_format::GravityCompensation {
                    coeffs: c.map(|v| v as f32),
                }),
            relaxation: self
                .scene
                .viscoelastic
                .as_ref()
                .map(|v| v.record())
                .transpose()
                .map_err(|e| anyhow::anyhow!("[viscoelastic]: {e}"))?,
            samples: None,
            device: self.scene.device,
        };
        Ok((builder, pairs))
    }
}

/// Anchors per triangle side of the lattice [`Prepared::tool_pairs`] samples: the anchors are
/// the points of barycentric coordinates `(i, j, k) / TOOL_DIVISIONS`, `i + j + k =
/// TOOL_DIVISIONS`, of every triangle of R (91 per triangle).
pub const TOOL_DIVISIONS: usize = 12;

/// A patch with fewer than [`firmware::solve::MAX_CONTACT_NODES`] nodes that dropped more than
/// this share of its load left a node out for want of a coupling (below it: f32 rounding of
/// `1 - kept / total`).
pub const UNCOUPLED_TOL: f32 = 1e-5;

/// The pairs of R the scene's tool can put into one contact set, and what the sampling saw.
#[derive(Debug, Clone)]
pub struct ToolPairs {
    /// Pairs `(a, b)`, `a < b`, indices into R: nodes of one tool patch, and the node the
    /// firmware's nodal quadrature starts from with every node within the tip radius.
    pub pairs: BTreeSet<(usize, usize)>,
    /// Anchors sampled.
    pub anchors: usize,
    /// Most nodes in one patch.
    pub max_nodes: usize,
    /// Largest share of a patch's load the firmware dropped (more than
    /// [`firmware::solve::MAX_CONTACT_NODES`] nodes).
    pub max_dropped: f32,
}

impl Prepared {
    /// The pairs the scene's tool can put into one contact set: the firmware's own patch rule
    /// ([`firmware::patch::tool_patch`], f32, on `probe`, a bank of this scene that couples
    /// every pair within [`Prepared::probe_radius`]) at the anchors of a lattice with
    /// `divisions` steps per side on every triangle of R (the reachable surface). Besides
    /// the patch's nodes, the nodal quadrature's start (the contact triangle's vertex of
    /// largest barycentric coordinate) is paired with every node within the tip radius, so
    /// that the firmware finds the same nodal pressures on the smaller bank. Fails if the
    /// probe left a patch node uncoupled.
    pub fn tool_pairs(&self, probe: &Bank, divisions: usize) -> Result<ToolPairs> {
        let radius = self.scene.tip_radius_m as f32;
        let r2 = radius * radius;
        let n = divisions.max(1);
        let positions = probe.positions();
        let mut out = ToolPairs {
            pairs: BTreeSet::new(),
            anchors: 0,
            max_nodes: 0,
            max_dropped: 0.0,
        };
        for (t, tri) in probe.triangles().iter().enumerate() {
            let v = tri.map(|k| positions[usize::from(k)]);
            for i in 0..=n {
                for j in 0..=n - i {
                    let bary = [i, j, n - i - j].map(|m| m as f32 / n as f32);
                    let anchor: [f32; 3] = std::array::from_fn(|c| {
                        bary[0] * v[0][c] + bary[1] * v[1][c] + bary[2] * v[2][c]
                    });
                    let patch =
                        firmware::patch::tool_patch(probe, t as u32, *tri, bary, anchor, radius);
                    let nodes = patch.nodes();
                    if patch.dropped > UNCOUPLED_TOL
                        && nodes.len() < firmware::solve::MAX_CONTACT_NODES
                    {
                        bail!(
                            "internal: the probe bank (pairs within {:.4} m) left a node of the \
                             tool patch at triangle {t} uncoupled",
                            self.probe_radius()
                        );
                    }
                    out.anchors += 1;
                    out.max_nodes = out.max_nodes.max(nodes.len());
                    out.max_dropped = out.max_dropped.max(patch.dropped);
                    for (x, &a) in nodes.iter().enumerate() {
                        for &b in &nodes[x + 1..] {
                            let (a, b) = (usize::from(a), usize::from(b));
                            out.pairs.insert((a.min(b), a.max(b)));
                        }
                    }
                    // The firmware's nodal pressures: the nearest vertex (first largest
                    // coordinate) and its neighbours within the tip radius.
                    let nearest =
                        (0..3).fold(0, |best, c| if bary[c] > bary[best] { c } else { best });
                    let a = tri[nearest];
                    for &b in probe.neighbours(usize::from(a)) {
                        let p = positions[usize::from(b)];
                        let d2: f32 = (0..3).map(|c| (p[c] - anchor[c]).powi(2)).sum();
                        if d2 < r2 {
                            let (a, b) = (usize::from(a), usize::from(b));
                            out.pairs.insert((a.min(b), a.max(b)));
                        }
                    }
                }
            }
        }
        Ok(out)
    }

    /// The scene's bank by its coupling rule (`bank.couplings`): the pairs within
    /// `bank.truncation_radius_m`, and with "tool" also [`Prepared::tool_pairs`].
    pub fn build_bank(&self, progress: Option<&dyn Progress>) -> Result<BuiltBank> {
        if let ContactModel::Sampled(spec) = &self.scene.contact {
            return self.sampled_bank(spec, progress);
        }
        let radius = self.scene.bank.truncation_radius_m;
        match self.scene.bank.couplings {
            Couplings::Radius => {
                let rows = self.blocks(radius, progress)?;
                self.bank(&rows, radius)
            }
            Couplings::Tool => {
                let rows = self.blocks(radius.max(self.probe_radius()), progress)?;
                let pairs = self.tool_pairs_from(&rows)?.pairs;
                self.bank_keeping(&rows, radius, Some(&pairs))
            }
        }
    }

    /// The bank of a sampled scene: R's collision data and nodal compliance with only the
    /// triangle edges coupled (the nodal contact models' minimum, for comparison), plus the
    /// contact samples computed on the scene's FEM mesh ([`sampled::contact_samples`]). The
    /// scene id also covers the FEM mesh's bytes.
    pub fn sampled_bank(
        &self,
        spec: &SampledContact,
        progress: Option<&dyn Progress>,
    ) -> Result<BuiltBank> {
        let fem = sampled::SampledFem::new(&self.scene, spec)?;
        let Some(rich) = &spec.richardson else {
            return self.sampled_bank_on(&fem, spec.level, progress);
        };
        // W on the fine mesh, then (its factor dropped first) on the coarse one.
        let (lattice, points) =
            sampled::lattice_points(&self.positions, &self.triangles, spec.level);
        let r = self.scene.tip_radius_m;
        let t0 = std::time::Instant::now();
        let (w_fine, at, widest) = fem.patch_compliance(&points, r, progress)?;
        let fine_s = t0.elapsed().as_secs_f64();
        let (mut samples, mut stats) = sampled::samples_from(
            lattice, &points, w_fine, &at, widest, &fem, spec.level, r, fine_s,
        )?;
        let fem_hash = fem.mesh_hash;
        drop(fem);
        let coarse = sampled::SampledFem::load(&self.scene, &rich.mesh, spec.element)?;
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
        let coarse_hash = coarse.mesh_hash;
        drop(coarse);
        let id = fnv1a(
            fnv1a(self.scene_id, &fem_hash.to_le_bytes()),
            &coarse_hash.to_le_bytes(),
        );
        self.sampled_bank_with(samples, stats, id)
    }

    /// [`Prepared::sampled_bank`] on an already factorised FEM body, at lattice level `level`.
    pub fn sampled_bank_on(
        &self,
        fem: &sampled::SampledFem,
        level: u32,
        progress: Option<&dyn Progress>,
    ) -> Result<BuiltBank> {
        let (samples, stats) = sampled::contact_samples(
            fem,
            &self.positions,
            &self.triangles,
            level,
            self.scene.tip_radius_m,
            progress,
        )?;
        let id = fnv1a(self.scene_id, &fem.mesh_hash.to_le_bytes());
        self.sampled_bank_with(samples, stats, id)
    }

    /// The sampled bank from its samples: R's collision data, the nodal compliance with the
    /// triangle edges coupled, the samples, scene id `scene_id`.
    pub fn sampled_bank_with(
        &self,
        samples: bank_format::ContactSamples,
        stats: sampled::SampleStats,
        scene_id: u64,
    ) -> Result<BuiltBank> {
        let rows = self.blocks(0.0, None)?;
        let (mut builder, pairs) = self.builder_in(&rows, 0.0, None)?;
        builder.samples = Some(samples);
        builder.scene_id = scene_id;
        let bytes = builder
            .build_with_precision(self.scene.bank.precision)
            .map_err(|e| anyhow::anyhow!("the bank writer refused the scene's data: {e}"))?;
        Ok(BuiltBank {
            bytes,
            pairs,
            sampled: Some(stats),
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

    /// [`Prepared::tool_pairs`] on the probe bank built from `rows` (computed for at least
    /// [`Prepared::probe_radius`]).
    pub fn tool_pairs_from(&self, rows: &[Vec<(usize, Block3)>]) -> Result<ToolPairs> {
        let aligned = self.probe_bank(rows)?;
        let bank = Bank::parse_unbounded(&aligned)
            .map_err(|e| anyhow::anyhow!("internal: the probe bank is invalid: {e}"))?;
        self.tool_pairs(&bank, TOOL_DIVISIONS)
    }
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
