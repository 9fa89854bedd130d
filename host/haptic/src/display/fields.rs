//! A sampled scene's display: the fine FEM mesh's surface deformed by precomputed
//! displacement fields, `u = U(p) F`, with no solve after a contact.
//!
//! For each contact sample `s` of the bank (a lattice point of the collision surface, the same
//! numbering as the bank's `W`), `U_s` holds the displacement of every display node under the
//! three unit tool loads at `s` (3 x 3 per node, m/N). A frame interpolates `U` at the contact
//! point with the bank's own lattice weights ([`bank_format::lattice_corners`]: the three
//! samples around the point, as the firmware interpolates `W`) and multiplies by the linear
//! tool force `F` (the sum of telemetry's contact forces, `F = W^-1 d`).
//!
//! The fields come from P1 on the scene's `fem_mesh` (`X_s = K^-1 B_s^T` in chunks, by
//! `Compliance::solve_loads`: a sparse forward substitution, then the dense backward solve;
//! P2 on the same mesh costs about ten times as much, some 200 s for the default scene's 977
//! samples against about 20 s). P1 is stiffer than the converged `W` the bank renders, so each
//! sample's field is scaled on the right by `W_P1,s^-1 W_s` (`W_P1,s = B_s X_s`): the load-weighted
//! mean displacement under the tool is then `W_s F = d`, the tip's own displacement, and the
//! shape around it is P1's. Stored as f16 (half the memory of f32; 3 significant digits are
//! below what a display shows); [`DisplayFields::bytes`] states the memory.
//!
//! Cached by [`DisplayFields::cached`] beside the scene's bank ([`crate::cache`]). Cache file
//! (little-endian): `b"HDF1"`,
//! `u32 version` (1), `u32 nodes, u32 triangles, u32 samples, u32 level, u32 bank triangles`,
//! `f32 rest[3 nodes]`, `u32 tri[3 triangles]`, `u16 ids[bank triangles x lattice_len(level)]`,
//! `u16 f16 U[samples][nodes][9]` (row-major 3 x 3: displacement component, load component).

use super::DisplayMesh;
use crate::bank::Prepared;
use crate::cache::{Store, fnv1a};
use crate::scene::{ContactModel, Scene};
use anyhow::{Context, Result, bail};
use fem::compliance::{Block3, Compliance};
use fem::elasticity::{Elasticity, Element};
use fem::progress::Progress;
use fem::tool::ToolSurface;
use half::f16;
use rayon::prelude::*;
use std::path::Path;

/// File magic of the cache file.
const MAGIC: &[u8; 4] = b"HDF1";
/// File version of the cache file.
const VERSION: u32 = 1;
/// Tool loads solved at once (three right-hand sides each).
const CHUNK_LOADS: usize = 64;
/// The cached field sets: about 71 MiB each for the default scene, four kept.
pub const FIELDS: Store = Store {
    kind: "fields",
    kept: 4,
};
/// The source files whose text decides the display fields besides the bank's inputs.
pub const FIELDS_SOURCES: [&str; 2] = [
    include_str!("fields.rs"),
    include_str!("../../../fem/src/elasticity/mod.rs"),
];

/// The fine surface and its displacement fields (module notes).
#[derive(Debug, Clone, PartialEq)]
pub struct DisplayFields {
    /// The displayed surface: the FEM mesh's boundary.
    pub mesh: DisplayMesh,
    /// Lattice steps per bank triangle side.
    level: u32,
    /// Per bank triangle, its samples ([`bank_format::Samples::triangle_samples`]).
    ids: Vec<u16>,
    /// Number of samples.
    samples: usize,
    /// `U[s][i][3 r + c]`, m/N.
    data: Vec<f16>,
}

impl DisplayFields {
    /// Computes the fields on the P1 body of `fem_mesh` (the scene's material and supports)
    /// for the bank's `samples`, whose lattice points on the collision surface are `points`
    /// (sample order), for a tool of radius `radius`.
    pub fn compute(
        scene: &Scene,
        fem_mesh: &Path,
        samples: &bank_format::Samples<'_>,
        triangles: usize,
        points: &[[f64; 3]],
        progress: Option<&dyn Progress>,
    ) -> Result<DisplayFields> {
        if points.len() != samples.count() {
            bail!(
                "the bank has {} contact samples but the scene's lattice {} points: the bank \
                 was not built from this scene",
                samples.count(),
                points.len()
            );
        }
        let (mesh, _) = scene.read_organ_mesh(fem_mesh, "[contact] fem_mesh")?;
        let boundary = fem::mesh::boundary(&mesh)?;
        let name = fem_mesh.display();
        let fixed = scene.fixed_set(&mesh)?;
        let body = Elasticity::with_element(&mesh, scene.material, Element::P1)?;
        let compliance = Compliance::factorize(&body, &fixed)
            .with_context(|| format!("{}: [fixed] on {name}", scene.path.display()))?;
        let tool = ToolSurface::linear(&mesh, &boundary)?;
        let radius = f64::from(samples.tip_radius_m());
        let loads = points
            .iter()
            .map(|&q| tool.tool_weights(tool.closest_point(q).point, radius))
            .collect::<Result<Vec<_>, _>>()?;
        let display: Vec<usize> = boundary.nodes.clone();
        let mut index = vec![u32::MAX; mesh.nodes.len()];
        for (i, &n) in display.iter().enumerate() {
            index[n] = i as u32;
        }
        let rest = display
            .iter()
            .map(|&n| mesh.nodes[n].map(|x| x as f32))
            .collect();
        let tris = boundary
            .triangles
            .iter()
            .map(|t| t.map(|n| index[n]))
            .collect();
        let w: Vec<Block3> = (0..samples.count())
            .map(|s| {
                let [xx, xy, xz, yy, yz, zz] = samples.sample(s).unwrap_or_default().map(f64::from);
                [[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]]
            })
            .collect();
        let nodes = display.len();
        let mut data = vec![f16::ZERO; samples.count() * nodes * 9];
        if let Some(bar) = progress {
            bar.start(loads.len().div_ceil(CHUNK_LOADS) as u64);
        }
        for (c, chunk) in loads.chunks(CHUNK_LOADS).enumerate() {
            let first = c * CHUNK_LOADS;
            let x = compliance.solve_loads(chunk)?;
            let out = &mut data[first * nodes * 9..(first + chunk.len()) * nodes * 9];
            out.par_chunks_mut(nodes * 9)
                .zip(chunk.par_iter())
                .enumerate()
                .try_for_each(|(j, (u, load))| {
                    let col = |n: usize, r: usize, k: usize| {
                        compliance
                            .dofs()
                            .free_dof(n, r)
                            .map_or(0.0, |d| x[(d, 3 * j + k)])
                    };
                    let mut w_p1 = [[0.0; 3]; 3];
                    for &(n, wt) in load {
                        for (r, row) in w_p1.iter_mut().enumerate() {
                            for (k, v) in row.iter_mut().enumerate() {
                                *v += wt * col(n, r, k);
                            }
                        }
                    }
                    // M = W_P1^-1 W, column by column.
                    let cols: Block3 = std::array::from_fn(|k| {
                        crate::linalg::solve3(&w_p1, std::array::from_fn(|r| w[first + j][r][k]))
                    });
                    if !cols.iter().flatten().all(|v| v.is_finite()) {
                        bail!(
                            "the P1 patch compliance of sample {} is singular (a fixed region \
                             under the tool?)",
                            first + j
                        );
                    }
                    let m: Block3 = std::array::from_fn(|l| std::array::from_fn(|k| cols[k][l]));
                    for (i, &n) in display.iter().enumerate() {
                        for r in 0..3 {
                            for k in 0..3 {
                                let v: f64 = (0..3).map(|l| col(n, r, l) * m[l][k]).sum();
                                u[9 * i + 3 * r + k] = f16::from_f64(v);
                            }
                        }
                    }
                    Ok::<(), anyhow::Error>(())
                })?;
            if let Some(bar) = progress {
                bar.advance(1);
            }
        }
        let ids = (0..triangles)
            .flat_map(|t| samples.triangle_samples(t).iter().copied())
            .collect();
        Ok(DisplayFields {
            mesh: DisplayMesh {
                rest,
                triangles: tris,
            },
            level: samples.level(),
            ids,
            samples: samples.count(),
            data,
        })
    }

    /// The fields of `prep`'s scene for `bank` (built from it); `None` for a nodal scene or a
    /// bank without samples.
    pub fn for_bank(
        prep: &Prepared,
        bank: &bank_format::Bank<'_>,
        progress: Option<&dyn Progress>,
    ) -> Result<Option<DisplayFields>> {
        let (ContactModel::Sampled(spec), Some(samples)) =
            (&prep.organ.scene.contact, bank.samples())
        else {
            return Ok(None);
        };
        let (_, points) = crate::bank::sampled::lattice_points(
            &prep.region.positions,
            &prep.region.triangles,
            spec.level,
        );
        DisplayFields::compute(
            &prep.organ.scene,
            &spec.fem_mesh,
            &samples,
            prep.region.triangles.len(),
            &points,
            progress,
        )
        .map(Some)
    }

    /// The fields of a sampled scene ([`DisplayFields::for_bank`] for `bank`, the scene's bank)
    /// from the cache, or computed and cached; `None` for a nodal scene. The second value says
    /// whether they came from the cache. The key is what they are computed from: the samples'
    /// inputs ([`crate::bank::cache::samples_key`]), the samples as the bank stores them (so
    /// the same organ under another law or relaxation shares its fields) and the text of the
    /// code that computes them ([`FIELDS_SOURCES`]).
    pub fn cached(
        prep: &Prepared,
        bank: &bank_format::Bank<'_>,
        progress: Option<&dyn Progress>,
    ) -> Result<Option<(DisplayFields, bool)>> {
        let (ContactModel::Sampled(spec), Some(samples)) =
            (&prep.organ.scene.contact, bank.samples())
        else {
            return Ok(None);
        };
        let mut key = crate::bank::cache::samples_key(prep, spec)?;
        key = fnv1a(key, &samples.tip_radius_m().to_bits().to_le_bytes());
        for s in 0..samples.count() {
            for v in samples.sample(s).unwrap_or_default() {
                key = fnv1a(key, &v.to_bits().to_le_bytes());
            }
        }
        let key = FIELDS_SOURCES
            .iter()
            .fold(key, |h, s| fnv1a(h, s.as_bytes()));
        if let Some(fields) = FIELDS.load(key, |bytes| DisplayFields::decode(&bytes)) {
            return Ok(Some((fields, true)));
        }
        let Some(fields) = DisplayFields::for_bank(prep, bank, progress)? else {
            return Ok(None);
        };
        FIELDS.save(key, &fields.encode());
        Ok(Some((fields, false)))
    }

    /// Bytes held in memory (positions, triangles, lattice ids, fields).
    pub fn bytes(&self) -> usize {
        12 * self.mesh.rest.len()
            + 12 * self.mesh.triangles.len()
            + 2 * self.ids.len()
            + 2 * self.data.len()
    }

    /// Samples.
    pub fn samples(&self) -> usize {
        self.samples
    }

    /// The displacement of every display node (m) for the linear tool force `force` (N, on the
    /// tissue) at barycentric point `bary` of bank triangle `triangle`; zero for a point
    /// outside the bank's triangles.
    pub fn displacement(
        &self,
        triangle: u32,
        bary: [f32; 3],
        force: [f32; 3],
        u: &mut Vec<[f32; 3]>,
    ) {
        let nodes = self.mesh.rest.len();
        u.clear();
        u.resize(nodes, [0.0; 3]);
        let len = bank_format::lattice_len(self.level);
        let at = triangle as usize * len;
        let Some((ids, weights)) = self
            .ids
            .get(at..at + len)
            .and_then(|ids| bank_format::lattice_corners(ids, self.level, bary))
        else {
            return;
        };
        for (&s, &wt) in ids.iter().zip(&weights) {
            let s = usize::from(s);
            if wt == 0.0 || s >= self.samples {
                continue;
            }
            let field = &self.data[s * nodes * 9..(s + 1) * nodes * 9];
            let f = force.map(|x| wt * x);
            u.par_iter_mut()
                .zip(field.par_chunks(9))
                .for_each(|(ui, m)| {
                    for (r, v) in ui.iter_mut().enumerate() {
                        *v += m[3 * r].to_f32() * f[0]
                            + m[3 * r + 1].to_f32() * f[1]
                            + m[3 * r + 2].to_f32() * f[2];
                    }
                });
        }
    }

    /// The cache file's bytes (module notes).
    pub fn encode(&self) -> Vec<u8> {
        let mut b = Vec::with_capacity(28 + self.bytes());
        b.extend(MAGIC);
        for v in [
            VERSION,
            self.mesh.rest.len() as u32,
            self.mesh.triangles.len() as u32,
            self.samples as u32,
            self.level,
            (self.ids.len() / bank_format::lattice_len(self.level).max(1)) as u32,
        ] {
            b.extend(v.to_le_bytes());
        }
        self.mesh
            .rest
            .iter()
            .flatten()
            .for_each(|x| b.extend(x.to_le_bytes()));
        self.mesh
            .triangles
            .iter()
            .flatten()
            .for_each(|x| b.extend(x.to_le_bytes()));
        self.ids.iter().for_each(|x| b.extend(x.to_le_bytes()));
        self.data
            .iter()
            .for_each(|x| b.extend(x.to_bits().to_le_bytes()));
        b
    }

    /// Reads a cache file's bytes; an error says what does not fit.
    pub fn decode(bytes: &[u8]) -> Result<DisplayFields> {
        let mut r = Reader { bytes, at: 0 };
        if r.take(4)? != MAGIC {
            bail!("not a display-fields file (magic)");
        }
        let version = r.u32()?;
        if version != VERSION {
            bail!("display-fields file version {version}, this host reads {VERSION}");
        }
        let (nodes, triangles, samples, level, bank_triangles) =
            (r.u32()?, r.u32()?, r.u32()?, r.u32()?, r.u32()?);
        let (nodes, triangles, samples) = (nodes as usize, triangles as usize, samples as usize);
        let rest = (0..nodes)
            .map(|_| Ok([r.f32()?, r.f32()?, r.f32()?]))
            .collect::<Result<Vec<_>>>()?;
        let tris = (0..triangles)
            .map(|_| Ok([r.u32()?, r.u32()?, r.u32()?]))
            .collect::<Result<Vec<[u32; 3]>>>()?;
        if let Some(t) = tris.iter().flatten().find(|&&k| k as usize >= nodes) {
            bail!("display-fields file: triangle vertex {t} of {nodes} nodes");
        }
        let ids = (0..bank_triangles as usize * bank_format::lattice_len(level))
            .map(|_| r.u16())
            .collect::<Result<Vec<_>>>()?;
        let data = (0..samples * nodes * 9)
            .map(|_| Ok(f16::from_bits(r.u16()?)))
            .collect::<Result<Vec<_>>>()?;
        if r.at != bytes.len() {
            bail!(
                "display-fields file: {} bytes after the fields",
                bytes.len() - r.at
            );
        }
        Ok(DisplayFields {
            mesh: DisplayMesh {
                rest,
                triangles: tris,
            },
            level,
            ids,
            samples,
            data,
        })
    }
}

/// Little-endian reads with a clear error at the end of the bytes.
struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl Reader<'_> {
    fn take(&mut self, n: usize) -> Result<&[u8]> {
        let b = self
            .bytes
            .get(self.at..self.at + n)
            .ok_or_else(|| anyhow::anyhow!("display-fields file truncated at byte {}", self.at))?;
        self.at += n;
        Ok(b)
    }
    fn u32(&mut self) -> Result<u32> {
        Ok(u32::from_le_bytes(self.take(4)?.try_into()?))
    }
    fn u16(&mut self) -> Result<u16> {
        Ok(u16::from_le_bytes(self.take(2)?.try_into()?))
    }
    fn f32(&mut self) -> Result<f32> {
        Ok(f32::from_le_bytes(self.take(4)?.try_into()?))
    }
}
