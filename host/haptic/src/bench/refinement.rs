//! The refinement series (`host bench refinement`): the same tool press on one organ meshed at
//! several sizes, with point contact and with the finite tool tip. A point force has unbounded
//! displacement, so the point contact's force falls as the mesh is refined; the tip's pressure
//! patch should converge. A patch with more nodes than the firmware carries is also solved
//! capped as the firmware caps it (its heaviest `MAX_CONTACT_NODES`, renormalised): its force
//! and dropped share. Measures, asserts nothing.

use crate::contact::{ContactSurface, capped_patch, patch_force};
use anyhow::{Context, Result};
use fem::compliance::Compliance;
use fem::elasticity::{Elasticity, FixedSet, Material};
use fem::mesh::TetMesh;
use firmware::solve::MAX_CONTACT_NODES;
use std::path::Path;
use std::time::Instant;

/// One press of the series.
#[derive(Debug, Clone)]
pub struct Config {
    /// The organ's material.
    pub material: Material,
    /// Thickness of the fixed bed at the bottom of the organ's bounding box, m.
    pub bed_m: f64,
    /// Where the tool enters: a point above the organ, m; the tool moves straight down.
    pub from: [f64; 3],
    /// Press depth along the ray, m.
    pub depth_m: f64,
    /// Tool tip radii to compare with point contact, m.
    pub radii_m: Vec<f64>,
}

/// The forces of one press on one mesh.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Forces {
    /// Nodes of the mesh.
    pub nodes: usize,
    /// Mean edge of the surface triangles, m.
    pub mean_surface_edge_m: f64,
    /// Force on the tool along the press for point contact, N.
    pub point_force_n: f64,
    /// `(radius_m, nodes in the patch, force_n)` for each tip radius.
    pub tips: Vec<(f64, usize, f64)>,
    /// `(radius_m, force_n, dropped share)` of the patch the firmware would use, capped at its
    /// `MAX_CONTACT_NODES` heaviest nodes renormalised (the same as `tips` when it fits).
    pub capped: Vec<(f64, f64, f64)>,
}

/// One mesh's row of the series.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Row {
    /// The mesh file.
    pub mesh: String,
    /// Its forces.
    #[serde(flatten)]
    pub forces: Forces,
    /// Wall time of the load, factorisation and solves, s.
    pub seconds: f64,
}

/// The press of `config` on `mesh`, held on a bed of `config.bed_m` at the bottom of its
/// bounding box.
pub fn press(mesh: &TetMesh, config: &Config) -> Result<Forces> {
    let surface = fem::mesh::boundary(mesh)?;
    let (lo, hi) = mesh.bounding_box();
    let mut fixed = FixedSet::none(mesh.nodes.len());
    fixed.fix_box(
        mesh,
        [lo[0], lo[1], lo[2], hi[0], hi[1], lo[2] + config.bed_m],
        [true; 3],
    )?;
    let body = Elasticity::new(mesh, config.material)?;
    let compliance = Compliance::factorize(&body, &fixed)?;
    let contact = ContactSurface::new(mesh, &surface);
    let hit = contact
        .ray_entry(config.from, [0.0, 0.0, -1.0])
        .context("the ray from the tool misses the organ")?;
    let free = |k: usize| (0..3).all(|c| !fixed.is_fixed(k, c));
    let depth = [0.0, 0.0, -config.depth_m];
    let along = |f: [f64; 3]| -f[2];
    let point_force_n = along(patch_force(
        &compliance,
        &contact.tool_patch(&hit, 0.0, free),
        depth,
    )?);
    let mut tips = Vec::new();
    let mut capped = Vec::new();
    for &r in &config.radii_m {
        let patch = contact.tool_patch(&hit, r, free);
        tips.push((
            r,
            patch.len(),
            along(patch_force(&compliance, &patch, depth)?),
        ));
        let (kept, dropped) = capped_patch(&patch, MAX_CONTACT_NODES);
        capped.push((r, along(patch_force(&compliance, &kept, depth)?), dropped));
    }
    Ok(Forces {
        nodes: mesh.nodes.len(),
        mean_surface_edge_m: contact.mean_edge(),
        point_force_n,
        tips,
        capped,
    })
}

/// The press of `config` on the mesh file at `path`.
pub fn run(path: &Path, config: &Config) -> Result<Row> {
    let t = Instant::now();
    let mesh = fem::mesh::load(path)?;
    let forces = press(&mesh, config).with_context(|| path.display().to_string())?;
    Ok(Row {
        mesh: path.display().to_string(),
        forces,
        seconds: t.elapsed().as_secs_f64(),
    })
}
