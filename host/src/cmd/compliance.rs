//! `host compliance`: compliance blocks of requested nodes as JSON (a stable interface).

use super::fixing::{FixArgs, parse_list};
use crate::progress::Bar;
use anyhow::{Context, Result, bail};
use fem::compliance::Compliance;
use fem::elasticity::{Elasticity, Element, Material};
use haptic::scene::{Locking, p1_locking};
use std::io::Write;
use std::path::PathBuf;

/// Arguments of `host compliance`.
#[derive(clap::Args, Debug)]
#[command(
    after_help = "Prints {\"nodes\":[i,...],\"blocks\":[[[9 numbers],...],...]} where \
blocks[a][b] is C(nodes[a], nodes[b]) row-major in m/N. Node ids are 0-based positions in the \
file's node order.",
    allow_negative_numbers = true
)]
pub struct Args {
    /// Tetrahedral mesh (.msh v2/v4, .vtu, .vtk), coordinates in metres.
    #[arg(long)]
    mesh: PathBuf,
    /// Young's modulus in Pa.
    #[arg(long)]
    young: f64,
    /// Poisson's ratio.
    #[arg(long)]
    poisson: f64,
    #[command(flatten)]
    fix: FixArgs,
    /// Nodes whose blocks are wanted, comma separated.
    #[arg(long, value_name = "i,j,...")]
    nodes: String,
    /// Element formulation: `p1` (the paper's linear tetrahedron) or `anp` (average nodal
    /// pressure, free of volumetric locking as --poisson approaches 0.5; same nodes).
    #[arg(long, default_value_t = Element::P1, value_name = "p1|anp")]
    element: Element,
}

/// Runs the command.
pub fn run(args: Args) -> Result<()> {
    let mesh = fem::mesh::load(&args.mesh)?;
    if let Some(w) = haptic::organ::mesh_size_warning(&mesh, &args.mesh.display().to_string()) {
        eprintln!("{w}");
    }
    let nodes = parse_list::<usize>(&args.nodes).context("--nodes")?;
    let material = Material::new(args.young, args.poisson)?;
    // Only the paper's linear tetrahedron locks; `anp` is free of it.
    if args.element == Element::P1 {
        match p1_locking(args.poisson) {
            Locking::Meaningless(why) => bail!("--poisson: {why} (or use --element anp)"),
            Locking::Stiffens(warning) => eprintln!("{warning} (or use --element anp)"),
            Locking::Fine => {}
        }
    }
    let fixed = args.fix.build(&mesh)?;
    if fixed.count() == 3 * mesh.nodes.len() {
        bail!("the fixed set holds every node: nothing can deform (every block would be zero)");
    }
    let body = Elasticity::with_element(&mesh, material, args.element)?;
    let compliance = Compliance::factorize(&body, &fixed)?;
    let progress = Bar::new("supernodes");
    let blocks = compliance.blocks(&nodes, Some(&progress))?;
    progress.finish();
    if blocks
        .iter()
        .flatten()
        .flatten()
        .flatten()
        .any(|v| !v.is_finite())
    {
        bail!(
            "the compliance blocks are not finite numbers (--young {} Pa is outside what f64 \
             can resolve for this mesh); nothing was printed",
            args.young
        );
    }
    let flat: Vec<Vec<[f64; 9]>> = blocks
        .iter()
        .map(|row| {
            row.iter()
                .map(|b| std::array::from_fn(|i| b[i / 3][i % 3]))
                .collect()
        })
        .collect();
    let mut out = std::io::BufWriter::new(std::io::stdout().lock());
    serde_json::to_writer(
        &mut out,
        &serde_json::json!({ "nodes": nodes, "blocks": flat }),
    )?;
    writeln!(out)?;
    out.flush()?;
    Ok(())
}
