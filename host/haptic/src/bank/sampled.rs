//! The sampled contact of a scene (`[contact] model = "sampled"`, bank format 6 "contact
//! samples"): the tool's patch compliance `W(p) = B(p) C B(p)^T` computed on a FEM mesh of its
//! own (any size, graded where the tool reaches; P1, ANP or P2) at the lattice points of the
//! collision surface (the scene's `mesh`, R's triangles), so that the bank's size follows the
//! reachable area and the lattice, not the FEM's resolution: three resolutions, not one.
//!
//! Per lattice point `q` of a collision triangle: the closest point `p` of the FEM mesh's
//! surface (their distance is the collision surface's depth error, reported), the tool's
//! parabolic pressure of the scene's tip radius centred at `p` as consistent nodal weights `B(p)`
//! ([`fem::tool::ToolSurface::tool_weights`]), and `W(p)` from the kept factor
//! ([`fem::compliance::Compliance::patch_compliances`]). The firmware interpolates `W` between
//! lattice points ([`bank_format::Samples::interpolate`]) and renders `f = W^-1 d` (the paper's
//! eq. 8 for one rigid tool, in compliance form), with Q on top.

use crate::scene::{FemElement, SampledContact, Scene};
use anyhow::{Context, Result, bail};
use bank_format::{ContactSamples, SharedLattice};
use fem::compliance::{Block3, Compliance, FactorStats};
use fem::elasticity::quadratic::QuadraticBody;
use fem::elasticity::{Elasticity, FixedSet};
use fem::mesh::TetMesh;
use fem::progress::Progress;
use fem::tool::ToolSurface;
use std::path::Path;
use std::time::Instant;

/// A FEM body for the patch compliance: its factor and its tool surface.
pub struct SampledFem {
    /// The FEM mesh's name for messages.
    pub mesh_name: String,
    /// FNV-1a 64 of the mesh file's bytes (part of the bank's scene id).
    pub mesh_hash: u64,
    /// Vertices of the FEM mesh.
    pub vertices: usize,
    /// Nodes of the body (vertices, and edge nodes for P2).
    pub nodes: usize,
    /// The element.
    pub element: FemElement,
    /// `K_ff` factorised with the scene's supports.
    pub compliance: Compliance,
    /// The body's boundary with its shape functions.
    pub surface: ToolSurface,
    /// Seconds to read, assemble and factorise.
    pub factor_s: f64,
}

/// One tool load on the FEM: `(node, weight)` pairs (the pressure's nodal weights, summing
/// to 1).
pub type ToolLoad = Vec<(usize, f64)>;

/// What the sampling measured besides the samples.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SampleStats {
    /// Lattice points (distinct samples).
    pub samples: usize,
    /// Largest and mean distance from a lattice point of the collision surface to the FEM
    /// mesh's surface, m (a depth error of the collision surface).
    pub gap_max_m: f64,
    /// Mean of the same, m.
    pub gap_mean_m: f64,
    /// Largest number of FEM nodes one patch loads.
    pub max_patch_nodes: usize,
    /// FEM vertices and body nodes.
    pub fem_vertices: usize,
    /// Nodes of the body (P2: vertices and edge nodes).
    pub fem_nodes: usize,
    /// Size figures of the FEM factor.
    pub factor: FactorStats,
    /// Seconds to read, assemble and factorise the FEM.
    pub factor_s: f64,
    /// Seconds for the tool weights and `W` of every sample.
    pub w_s: f64,
}

impl SampledFem {
    /// Reads the scene's FEM mesh, builds the body with the scene's material and fixed boxes,
    /// and factorises it.
    pub fn new(scene: &Scene, spec: &SampledContact) -> Result<SampledFem> {
        SampledFem::load(scene, &spec.fem_mesh, spec.element)
    }

    /// [`SampledFem::new`] on the mesh file `path` with `element`.
    pub fn load(scene: &Scene, path: &Path, element: FemElement) -> Result<SampledFem> {
        let t0 = Instant::now();
        let (mesh, mesh_hash) = scene.read_organ_mesh(path, "[contact] mesh")?;
        let boundary = fem::mesh::boundary(&mesh)?;
        let name = path.display().to_string();
        let (compliance, surface, nodes) = match element {
            FemElement::Linear(element) => {
                let fixed = scene.fixed_set(&mesh)?;
                let body = Elasticity::with_element(&mesh, scene.material, element)?;
                let c = Compliance::factorize(&body, &fixed)
                    .with_context(|| format!("{}: [fixed] on {name}", scene.path.display()))?;
                let s = ToolSurface::linear(&mesh, &boundary)?;
                (c, s, mesh.nodes.len())
            }
            FemElement::Quadratic => {
                let body = QuadraticBody::new(&mesh, scene.material)?;
                // The supports act on every node of the body, edge nodes included.
                let all = TetMesh {
                    nodes: body.positions().to_vec(),
                    tets: Vec::new(),
                };
                let fixed: FixedSet = scene.fixed_set(&all)?;
                let c = Compliance::factorize(&body, &fixed)
                    .with_context(|| format!("{}: [fixed] on {name}", scene.path.display()))?;
                let s = ToolSurface::quadratic(&mesh, &boundary, &body)?;
                (c, s, body.positions().len())
            }
        };
        Ok(SampledFem {
            mesh_name: name,
            mesh_hash,
            vertices: mesh.nodes.len(),
            nodes,
            element,
            compliance,
            surface,
            factor_s: t0.elapsed().as_secs_f64(),
        })
    }

    /// The patch compliance of a tool of radius `radius` pressed at the FEM surface point
    /// closest to each of `points`, with that point and its distance.
    pub fn patch_compliance(
        &self,
        points: &[[f64; 3]],
        radius: f64,
        progress: Option<&dyn Progress>,
    ) -> Result<(Vec<Block3>, Vec<fem::tool::SurfacePoint>, usize)> {
        let (loads, at) = self.tool_loads(points, radius)?;
        let widest = loads.iter().map(Vec::len).max().unwrap_or(0);
        let w = self.compliance.patch_compliances(&loads, progress)?;
        Ok((w, at, widest))
    }

    /// The tool's loads of `radius` (m) at the FEM surface points closest to `points`: per
    /// point, the `(node, weight)` list of the parabolic pressure, and the surface point.
    pub fn tool_loads(
        &self,
        points: &[[f64; 3]],
        radius: f64,
    ) -> Result<(Vec<ToolLoad>, Vec<fem::tool::SurfacePoint>)> {
        let at: Vec<fem::tool::SurfacePoint> = points
            .iter()
            .map(|&q| self.surface.closest_point(q))
            .collect();
        let loads = at
            .iter()
            .map(|p| self.surface.tool_weights(p.point, radius))
            .collect::<Result<Vec<_>, _>>()?;
        Ok((loads, at))
    }
}

/// The lattice of `triangles` (R's, node indices into `positions`) at `level` and its points'
/// positions.
pub fn lattice_points(
    positions: &[[f64; 3]],
    triangles: &[[u32; 3]],
    level: u32,
) -> (SharedLattice, Vec<[f64; 3]>) {
    let lattice = SharedLattice::new(triangles, level);
    let points = lattice
        .points
        .iter()
        .map(|&(t, b)| {
            let tri = triangles[t].map(|k| positions[k as usize]);
            std::array::from_fn(|c| b[0] * tri[0][c] + b[1] * tri[1][c] + b[2] * tri[2][c])
        })
        .collect();
    (lattice, points)
}

/// `W_f + factor (W_f - W_c)` entry by entry (Richardson extrapolation,
/// [`crate::scene::Richardson`]).
pub fn extrapolated(fine: &[Block3], coarse: &[Block3], factor: f64) -> Vec<Block3> {
    fine.iter()
        .zip(coarse)
        .map(|(f, c)| {
            std::array::from_fn(|i| std::array::from_fn(|j| f[i][j] + factor * (f[i][j] - c[i][j])))
        })
        .collect()
}

/// The contact samples of `triangles` (R's, node indices into `positions`) for the scene's
/// tool at lattice level `level`, computed on `fem`; with `coarse`, Richardson-extrapolated
/// with `W` computed on that body too (the pair's [`crate::scene::Richardson::factor`]).
pub fn contact_samples(
    fem: &SampledFem,
    positions: &[[f64; 3]],
    triangles: &[[u32; 3]],
    level: u32,
    radius: f64,
    progress: Option<&dyn Progress>,
) -> Result<(ContactSamples, SampleStats)> {
    let (lattice, points) = lattice_points(positions, triangles, level);
    let t0 = Instant::now();
    let (w, at, widest) = fem.patch_compliance(&points, radius, progress)?;
    let total = t0.elapsed().as_secs_f64();
    samples_from(lattice, &points, w, &at, widest, fem, level, radius, total)
}

/// The samples and their statistics from `W` at the lattice's points.
#[allow(clippy::too_many_arguments)]
pub fn samples_from(
    lattice: SharedLattice,
    points: &[[f64; 3]],
    w: Vec<Block3>,
    at: &[fem::tool::SurfacePoint],
    widest: usize,
    fem: &SampledFem,
    level: u32,
    radius: f64,
    total: f64,
) -> Result<(ContactSamples, SampleStats)> {
    for (s, m) in w.iter().enumerate() {
        if !spd(m) {
            let p = points[s];
            bail!(
                "the patch compliance at [{:.4}, {:.4}, {:.4}] m is not positive definite (a \
                 fixed region under the tool?)",
                p[0],
                p[1],
                p[2]
            );
        }
    }
    let gaps: Vec<f64> = at.iter().map(|p| p.distance).collect();
    let stats = SampleStats {
        samples: points.len(),
        gap_max_m: gaps.iter().copied().fold(0.0, f64::max),
        gap_mean_m: gaps.iter().sum::<f64>() / gaps.len().max(1) as f64,
        max_patch_nodes: widest,
        fem_vertices: fem.vertices,
        fem_nodes: fem.nodes,
        factor: fem.compliance.stats(),
        factor_s: fem.factor_s,
        w_s: total,
    };
    let samples = ContactSamples {
        level,
        tip_radius_m: radius,
        triangle_samples: lattice.triangle_points,
        w,
    };
    Ok((samples, stats))
}

/// Whether a symmetric 3 x 3 block is positive definite (Cholesky pivots, relative to its
/// largest diagonal entry, above the bank reader's [`bank_format::SPD_PIVOT_REL`]).
pub fn spd(m: &Block3) -> bool {
    let d = m[0][0].max(m[1][1]).max(m[2][2]);
    let tol = bank_format::SPD_PIVOT_REL * d;
    let l00 = m[0][0];
    // A NaN pivot compares as none: not positive definite.
    let above = |x: f64| x.partial_cmp(&tol) == Some(std::cmp::Ordering::Greater);
    if !above(l00) {
        return false;
    }
    let (a, b) = (m[1][0] / l00, m[2][0] / l00);
    let p1 = m[1][1] - a * m[1][0];
    if !above(p1) {
        return false;
    }
    let c = (m[2][1] - b * m[1][0]) / p1;
    let p2 = m[2][2] - b * m[2][0] - c * (m[2][1] - b * m[1][0]);
    above(p2)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The shipped scene with its meshes replaced by `mesh` (`mesh` and `[contact] fem_mesh`,
    /// P1, no Richardson mesh) in `units`, written beside it in `dir`.
    fn scene_on(dir: &Path, name: &str, mesh: &TetMesh, units: &str) -> Scene {
        let mut bytes = Vec::new();
        mesh.write_msh4_ascii(&mut bytes).unwrap();
        std::fs::write(dir.join(format!("{name}.msh")), bytes).unwrap();
        let mut text = String::new();
        for line in include_str!("../../../scenes/liver.toml").lines() {
            let key = line.split('=').next().unwrap_or("").trim();
            match key {
                "mesh" => text += &format!("mesh = \"{name}.msh\"\nmesh_units = \"{units}\"\n"),
                "fem_mesh" => text += &format!("fem_mesh = \"{name}.msh\"\n"),
                "fem_element" => text += "fem_element = \"p1\"\n",
                k if k.starts_with("richardson") => {}
                _ => text += &format!("{line}\n"),
            }
        }
        Scene::parse(&dir.join(format!("{name}.toml")), &text).unwrap()
    }

    /// One organ, one unit: with `mesh_units = "mm"` a sampled contact's `fem_mesh` is read in
    /// millimetres as the scene's `mesh` is, and its patch compliance is the one the same
    /// meshes give in metres.
    #[test]
    fn millimetre_meshes_give_the_compliance_of_metres() {
        let dir = tempfile::tempdir().unwrap();
        let metres = fem::mesh::parse_msh(include_bytes!("../../../meshes/liver-1k4.msh")).unwrap();
        let mut millimetres = metres.clone();
        millimetres
            .nodes
            .iter_mut()
            .flatten()
            .for_each(|x| *x *= 1e3);
        let m_scene = scene_on(dir.path(), "m", &metres, "m");
        let in_m = SampledFem::new(&m_scene, spec(&m_scene)).unwrap();
        let mm_scene = scene_on(dir.path(), "mm", &millimetres, "mm");
        let in_mm = SampledFem::new(&mm_scene, spec(&mm_scene)).unwrap();
        assert_ne!(in_m.mesh_hash, in_mm.mesh_hash);
        // The five highest boundary nodes: on the liver's free top, where the tool presses.
        let boundary = fem::mesh::boundary(&metres).unwrap();
        let mut top = boundary.nodes.clone();
        top.sort_by(|&a, &b| metres.nodes[b][2].total_cmp(&metres.nodes[a][2]));
        let points: Vec<[f64; 3]> = top[..5].iter().map(|&n| metres.nodes[n]).collect();
        let (w_m, ..) = in_m.patch_compliance(&points, 0.003, None).unwrap();
        let (w_mm, ..) = in_mm.patch_compliance(&points, 0.003, None).unwrap();
        for (a, b) in w_m.iter().zip(&w_mm) {
            let scale = a.iter().flatten().fold(0.0f64, |m, x| m.max(x.abs()));
            assert!(scale > 0.0);
            for (x, y) in a.iter().flatten().zip(b.iter().flatten()) {
                assert!((x - y).abs() <= 1e-9 * scale, "{a:?} vs {b:?}");
            }
        }
    }

    /// The scene's sampled `[contact]`.
    fn spec(scene: &Scene) -> &SampledContact {
        match &scene.contact {
            crate::scene::ContactModel::Sampled(spec) => spec,
            crate::scene::ContactModel::Nodal => panic!("the scene is sampled"),
        }
    }
}
