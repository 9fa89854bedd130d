//! `host bench refinement`: the refinement series of [`haptic::bench::refinement`] on each mesh,
//! printed as a table (or JSON).

use anyhow::Result;
use fem::elasticity::Material;
use firmware::solve::MAX_CONTACT_NODES;
use haptic::bench::refinement::{self, Config};
use std::path::PathBuf;

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
    let config = Config {
        material: Material::new(args.organ.young, args.organ.poisson)?,
        bed_m: args.organ.bed,
        from: [fx, fy, fz],
        depth_m: args.depth,
        radii_m: args.radius.clone(),
    };
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
        let row = refinement::run(path, &config)?;
        if args.json {
            println!("{}", serde_json::to_string(&row)?);
        } else {
            let name = path
                .file_name()
                .map_or(row.mesh.clone(), |n| n.to_string_lossy().into());
            let f = &row.forces;
            let tips: Vec<String> = f
                .tips
                .iter()
                .zip(&f.capped)
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
                f.nodes,
                f.mean_surface_edge_m * 1e3,
                f.point_force_n,
                tips.join("  ")
            );
        }
    }
    Ok(())
}
