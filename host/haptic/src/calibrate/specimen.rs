//! The linear model's prediction for a compression specimen (paper, section 3-4: "for a
//! cylindrical sample of height h and radius r, the theoretical radial deformation is
//! d_r^L(x) = nu r x / h while the force is f(x) = s E x / h"), computed with the project's own
//! FEM on a cylinder mesh of the specimen's size instead of the formula.
//!
//! Unconfined compression between frictionless platens: the bottom face is held axially, the
//! top face is pushed down axially, both slide freely; one bottom node near the axis is held
//! laterally and another bottom node is held in y (this removes the rigid motions without
//! constraining the deformation). The response is linear, so one solve gives the force and the
//! radial displacement per metre of compression.

use anyhow::{Context, Result, bail};
use fem::compliance::solve_prescribed;
use fem::elasticity::{Elasticity, FixedSet, Material};
use fem::mesh::TetMesh;
use std::path::PathBuf;

/// The specimen's linear response per metre of axial compression.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct SpecimenResponse {
    /// Mesh nodes.
    pub nodes: usize,
    /// Specimen height (z extent), m.
    pub height_m: f64,
    /// Specimen radius (largest distance from the axis), m.
    pub radius_m: f64,
    /// Axial force per metre of compression, N/m (the top platen's reaction).
    pub force_per_m: f64,
    /// Mean radial displacement of the side nodes around mid-height per metre of compression
    /// (dimensionless).
    pub radial_per_m: f64,
    /// Nodes on the top face.
    pub top_nodes: usize,
    /// Side nodes averaged for the radial displacement.
    pub ring_nodes: usize,
}

/// How far a side node may lie inside the cylinder's radius, relative to it: a meshed circle
/// of at least 24 segments stays within 1 % (its facets' midpoints are not nodes), while a box
/// has side nodes down to 71 % of its corners' distance.
pub const CYLINDER_TOLERANCE: f64 = 0.02;

/// Refuses a specimen that is not a cylinder along z: every boundary node off the end faces
/// must lie at the radius `r` (within [`CYLINDER_TOLERANCE`]).
fn check_cylinder(
    mesh: &TetMesh,
    z_lo: f64,
    z_hi: f64,
    r: f64,
    tol: f64,
    dist: &dyn Fn(&[f64; 3]) -> f64,
) -> Result<()> {
    let surface = fem::mesh::boundary(mesh)?;
    let side = surface
        .nodes
        .iter()
        .map(|&n| &mesh.nodes[n])
        .filter(|p| p[2] > z_lo + tol && p[2] < z_hi - tol);
    let inner = side.map(dist).fold(f64::INFINITY, f64::min);
    if inner.is_finite() && inner < (1.0 - CYLINDER_TOLERANCE) * r {
        bail!(
            "the specimen is not a cylinder along z: side nodes lie from {:.2} mm to {:.2} mm \
             from its axis (a cylinder's all lie at its radius, within {} %)",
            1e3 * inner,
            1e3 * r,
            100.0 * CYLINDER_TOLERANCE
        );
    }
    Ok(())
}

/// Compresses a cylinder mesh with its axis along z (centred on its bounding box) by a unit
/// top displacement; see the module documentation for the supports.
pub fn compress(mesh: &TetMesh, material: Material) -> Result<SpecimenResponse> {
    let (lo, hi) = mesh.bounding_box();
    let h = hi[2] - lo[2];
    let centre = [0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1])];
    let radial = |p: &[f64; 3]| [p[0] - centre[0], p[1] - centre[1]];
    let dist = |p: &[f64; 3]| {
        let r = radial(p);
        (r[0] * r[0] + r[1] * r[1]).sqrt()
    };
    let r = mesh.nodes.iter().map(dist).fold(0.0, f64::max);
    if !(h > 0.0 && r > 0.0) {
        bail!("the specimen mesh is flat (height {h} m, radius {r} m)");
    }
    let tol = 1e-6 * h.max(r);
    let on = |z: f64| -> Vec<usize> {
        (0..mesh.nodes.len())
            .filter(|&i| (mesh.nodes[i][2] - z).abs() <= tol)
            .collect()
    };
    let (bottom, top) = (on(lo[2]), on(hi[2]));
    if bottom.len() < 3 || top.len() < 3 {
        bail!(
            "the specimen mesh has no flat end faces at z = {} and z = {}",
            lo[2],
            hi[2]
        );
    }
    check_cylinder(mesh, lo[2], hi[2], r, tol, &dist)?;
    let body = Elasticity::new(mesh, material)?;
    let mut held = FixedSet::none(mesh.nodes.len());
    let mut u = vec![0.0; 3 * mesh.nodes.len()];
    for &n in &bottom {
        held.fix_component(n, 2)?;
    }
    for &n in &top {
        held.fix_component(n, 2)?;
        u[3 * n + 2] = -1.0;
    }
    let by = |key: &dyn Fn(usize) -> f64| {
        bottom
            .iter()
            .copied()
            .min_by(|&a, &b| key(a).total_cmp(&key(b)))
            .unwrap_or(0)
    };
    let axis_node = by(&|n| dist(&mesh.nodes[n]));
    let far_node = by(&|n| -radial(&mesh.nodes[n])[0]);
    held.fix_component(axis_node, 0)?;
    held.fix_component(axis_node, 1)?;
    held.fix_component(far_node, 1)?;
    let (u, forces) = solve_prescribed(&body, &held, &u)?;
    let force_per_m = -top.iter().map(|&n| forces[3 * n + 2]).sum::<f64>();
    let mid = lo[2] + 0.5 * h;
    let ring: Vec<usize> = (0..mesh.nodes.len())
        .filter(|&n| {
            let p = &mesh.nodes[n];
            (dist(p) - r).abs() <= 1e-3 * r && (p[2] - mid).abs() <= h / 6.0
        })
        .collect();
    if ring.is_empty() {
        bail!("the specimen mesh has no side nodes near mid-height");
    }
    let radial_per_m = ring
        .iter()
        .map(|&n| {
            let p = radial(&mesh.nodes[n]);
            let d = dist(&mesh.nodes[n]);
            (u[3 * n] * p[0] + u[3 * n + 1] * p[1]) / d
        })
        .sum::<f64>()
        / ring.len() as f64;
    Ok(SpecimenResponse {
        nodes: mesh.nodes.len(),
        height_m: h,
        radius_m: r,
        force_per_m,
        radial_per_m,
        top_nodes: top.len(),
        ring_nodes: ring.len(),
    })
}
/// What `host calibrate specimen` computes: its options.
#[derive(Debug, Clone)]
pub struct Config {
    /// The specimen's cylinder mesh, axis z, m.
    pub mesh: PathBuf,
    /// Young's modulus of the linear model, Pa.
    pub young_pa: f64,
    /// Poisson's ratio of the linear model.
    pub poisson: f64,
}

/// Loads the mesh and computes its response ([`compress`]).
pub fn run(a: &Config) -> Result<SpecimenResponse> {
    let mesh = fem::mesh::load(&a.mesh)?;
    let material = Material::new(a.young_pa, a.poisson)?;
    compress(&mesh, material).with_context(|| format!("{}: specimen compression", a.mesh.display()))
}
