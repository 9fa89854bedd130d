//! `host demo`: the default liver scene.
//!
//! The interactive browser demo (mouse-driven tool, live force, deforming organ) is not built
//! yet; until it is, this command runs the part of the pipeline that exists, the compliance
//! precompute and the contact-force solve, on the embedded default liver, and says so.

use anyhow::{Context, Result};
use host::compliance::{Compliance, contact_forces};
use host::fem::{Elasticity, FixedSet, Material};
use std::path::PathBuf;
use std::time::Instant;

/// Arguments of `host demo`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Use this mesh instead of the embedded liver.
    #[arg(long)]
    mesh: Option<PathBuf>,
    /// Young's modulus in Pa (liver parenchyma is a few kPa).
    #[arg(long, default_value_t = 3.0e3)]
    young: f64,
    /// Poisson's ratio.
    #[arg(long, default_value_t = 0.45)]
    poisson: f64,
    /// How far the tool presses into the organ, in metres.
    #[arg(long, default_value_t = 0.005)]
    depth: f64,
}

/// Runs the command.
pub fn run(args: Args) -> Result<()> {
    println!(
        "NOTE: the interactive demo (browser view, mouse-driven tool, live force) is not built \
         yet.\nThis run shows what exists today: the compliance precompute and the contact-force \
         solve on the default liver scene.\n"
    );
    let t = Instant::now();
    let (mesh, name) = match &args.mesh {
        Some(p) => (host::mesh::load(p)?, p.display().to_string()),
        None => (
            host::mesh::parse_msh(host::scene::BUILTIN_LIVER).context("embedded default liver")?,
            "embedded liver-1k4.msh".to_string(),
        ),
    };
    let surface = host::mesh::boundary(&mesh)?;
    let (lo, hi) = mesh.bounding_box();
    println!(
        "mesh      {name}: {} nodes, {} tetrahedra, {} surface triangles, {:.3} x {:.3} x {:.3} m",
        mesh.nodes.len(),
        mesh.tets.len(),
        surface.triangles.len(),
        hi[0] - lo[0],
        hi[1] - lo[1],
        hi[2] - lo[2]
    );
    let material = Material::new(args.young, args.poisson)?;
    let mut fixed = FixedSet::none(mesh.nodes.len());
    let bed = lo[2] + 0.01;
    let held = fixed.fix_box(&mesh, [lo[0], lo[1], lo[2], hi[0], hi[1], bed], [true; 3])?;
    println!(
        "material  E = {} Pa, nu = {}; organ resting on a bed: {held} nodes with z <= {bed:.4} m fixed",
        args.young, args.poisson
    );
    let body = Elasticity::new(&mesh, material)?;
    let compliance = Compliance::factorize(&body, &fixed)?;
    let free_surface: Vec<usize> = surface
        .nodes
        .iter()
        .copied()
        .filter(|&i| (0..3).all(|c| !fixed.is_fixed(i, c)))
        .collect();
    let blocks = compliance.blocks(&free_surface, None)?;
    println!(
        "compliance {} free surface nodes, all blocks C_nk in {:.3} s (the paper: 8 hours)",
        free_surface.len(),
        t.elapsed().as_secs_f64()
    );

    // Press at the top of the organ, straight down: first one node, then a triangle.
    let centre = [0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1])];
    let top = (0..free_surface.len())
        .max_by(|&a, &b| {
            let score = |i: usize| {
                let p = mesh.nodes[free_surface[i]];
                p[2] - 0.5 * ((p[0] - centre[0]).powi(2) + (p[1] - centre[1]).powi(2)).sqrt()
            };
            score(a).total_cmp(&score(b))
        })
        .context("the mesh has no free surface node")?;
    let press = [0.0, 0.0, -args.depth];
    let single = contact_forces(&[vec![blocks[top][top]]], &[press])?;
    println!(
        "press     node {} by {:.1} mm: force on the tool {:.4} N (point contact)",
        free_surface[top],
        args.depth * 1e3,
        -single.forces[0][2]
    );
    if let Some(tri) = surface
        .triangles
        .iter()
        .find(|t| t.contains(&free_surface[top]) && t.iter().all(|v| free_surface.contains(v)))
    {
        let idx: Vec<usize> = tri
            .iter()
            .map(|v| free_surface.iter().position(|w| w == v).unwrap_or(top))
            .collect();
        let c_ss: Vec<Vec<_>> = idx
            .iter()
            .map(|&a| idx.iter().map(|&b| blocks[a][b]).collect())
            .collect();
        let three = contact_forces(&c_ss, &[press; 3])?;
        let total: f64 = three.forces.iter().map(|f| -f[2]).sum();
        println!(
            "press     triangle {tri:?} by {:.1} mm: force on the tool {total:.4} N (3 contact nodes)",
            args.depth * 1e3
        );
    }
    Ok(())
}
