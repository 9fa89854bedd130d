//! `host bench refinement`: the same tool press on one organ meshed at several sizes, with point
//! contact and with the finite tool tip. A point force
//! has unbounded displacement, so the point contact's force falls as the mesh is refined; the
//! tip's pressure patch should converge. Prints a table (or JSON), asserts nothing. A patch
//! with more nodes than the firmware carries is also solved capped as the firmware caps it (its
//! heaviest `MAX_CONTACT_NODES`, renormalised): its force, error and dropped share.

use anyhow::{Context, Result};
use fem::compliance::Compliance;
use fem::elasticity::{Elasticity, FixedSet, Material};
use firmware::solve::MAX_CONTACT_NODES;
use haptic::contact::{ContactSurface, capped_patch, patch_force};
use std::path::PathBuf;
use std::time::Instant;

/// Arguments of `host bench refinement`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Meshes of the same organ, coarse to fine; default: the shipped livers (1.4k, 10k) and
    /// host/meshes/generated/liver-100k.msh when present.
    #[arg(long)]
    mesh: Vec<PathBuf>,
    #[command(flatten)]
    organ: super::organ::OrganArgs,
    /// Where the tool enters: a point above the organ, m (the shipped scene's trocar).
    #[arg(long, value_delimiter = ',', default_value = "0,0,0.16")]
    from: Vec<f64>,
    /// Press depth along the ray (straight down), m.
    #[arg(long, default_value_t = 0.005)]
    depth: f64,
    /// Tool tip radii to compare with point contact, m.
    #[arg(long, value_delimiter = ',', default_value = "0.003,0.005")]
    radius: Vec<f64>,
    /// Print one JSON object per mesh instead of a table.
    #[arg(long)]
    json: bool,
}

#[derive(serde::Serialize)]
struct Row {
    mesh: String,
    nodes: usize,
    mean_surface_edge_m: f64,
    /// Force on the tool along the press for point contact, N.
    point_force_n: f64,
    /// `(radius_m, nodes in the patch, force_n)` for each tip radius.
    tips: Vec<(f64, usize, f64)>,
    /// `(radius_m, force_n, dropped share)` of the patch the firmware would use, capped at its
    /// `MAX_CONTACT_NODES` heaviest nodes renormalised (the same as `tips` when it fits).
    capped: Vec<(f64, f64, f64)>,
    seconds: f64,
}

/// Runs the benchmark.
pub fn run(args: Args) -> Result<()> {
    let meshes = if args.mesh.is_empty() {
        super::organ::default_meshes()
    } else {
        args.mesh.clone()
    };
    let [fx, fy, fz] = args.from[..] else {
        anyhow::bail!("--from needs three numbers x,y,z, got {:?}", args.from);
    };
    let material = Material::new(args.organ.young, args.organ.poisson)?;
    if !args.json {
        println!(
            "press {:.1} mm straight down from ({fx}, {fy}, {fz}); E = {} Pa, nu = {}; force on the tool, N",
            args.depth * 1e3,
            args.organ.young,
            args.organ.poisson
        );
        let tips: Vec<String> = args
            .radius
            .iter()
            .map(|r| format!("tip r = {:.1} mm (nodes)", r * 1e3))
            .collect();
        println!(
            "{:<22} {:>8} {:>10} {:>10}  {}",
            "mesh",
            "nodes",
            "edge mm",
            "point",
            tips.join("  ")
        );
    }
    for path in &meshes {
        let t = Instant::now();
        let mesh = fem::mesh::load(path)?;
        let surface = fem::mesh::boundary(&mesh)?;
        let (lo, hi) = mesh.bounding_box();
        let mut fixed = FixedSet::none(mesh.nodes.len());
        fixed.fix_box(
            &mesh,
            [lo[0], lo[1], lo[2], hi[0], hi[1], lo[2] + args.organ.bed],
            [true; 3],
        )?;
        let body = Elasticity::new(&mesh, material)?;
        let compliance = Compliance::factorize(&body, &fixed)?;
        let contact = ContactSurface::new(&mesh, &surface);
        let hit = contact
            .ray_entry([fx, fy, fz], [0.0, 0.0, -1.0])
            .with_context(|| {
                format!("{}: the ray from the tool misses the organ", path.display())
            })?;
        let free = |k: usize| (0..3).all(|c| !fixed.is_fixed(k, c));
        let press = [0.0, 0.0, -args.depth];
        let along = |f: [f64; 3]| -f[2];
        let point = along(patch_force(
            &compliance,
            &contact.tool_patch(&hit, 0.0, free),
            press,
        )?);
        let mut tips = Vec::new();
        let mut capped = Vec::new();
        for &r in &args.radius {
            let patch = contact.tool_patch(&hit, r, free);
            tips.push((
                r,
                patch.len(),
                along(patch_force(&compliance, &patch, press)?),
            ));
            let (kept, dropped) = capped_patch(&patch, MAX_CONTACT_NODES);
            capped.push((r, along(patch_force(&compliance, &kept, press)?), dropped));
        }
        let row = Row {
            mesh: path.display().to_string(),
            nodes: mesh.nodes.len(),
            mean_surface_edge_m: contact.mean_edge(),
            point_force_n: point,
            tips,
            capped,
            seconds: t.elapsed().as_secs_f64(),
        };
        if args.json {
            println!("{}", serde_json::to_string(&row)?);
        } else {
            let name = path
                .file_name()
                .map_or(row.mesh.clone(), |n| n.to_string_lossy().into());
            let tips: Vec<String> = row
                .tips
                .iter()
                .zip(&row.capped)
                .map(|((_, n, f), (_, fc, dropped))| {
                    if *n > MAX_CONTACT_NODES {
                        format!(
                            "{f:>12.4} ({n:>2}; capped {fc:.4}, {:+.1} %, {:.0} % dropped)",
                            100.0 * (fc - f) / f,
                            100.0 * dropped
                        )
                    } else {
                        format!("{f:>12.4} ({n:>2})")
                    }
                })
                .collect();
            println!(
                "{name:<22} {:>8} {:>10.2} {:>10.4}  {}",
                row.nodes,
                row.mean_surface_edge_m * 1e3,
                row.point_force_n,
                tips.join("  ")
            );
        }
    }
    Ok(())
}
