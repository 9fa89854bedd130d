//! `host bench law`: instructions one in-domain evaluation of the tissue law Q costs on the
//! MCU, per degree, from the thumbv7em disassembly of `TissueLaw::eval`
//! ([`haptic::mcu::law_cost`] explains the count: instructions on the path, not cycles).

use anyhow::Result;
use haptic::mcu::law_cost;
use std::path::PathBuf;

/// Arguments of `host bench law`.
#[derive(clap::Args, Debug)]
pub struct LawArgs {
    /// The bank-format rlib built for thumbv7em; default: build it with cargo and take the
    /// newest one in target/thumbv7em-none-eabihf/release/deps.
    #[arg(long)]
    rlib: Option<PathBuf>,
    /// llvm-objdump to use; default: the one `rustup component add llvm-tools` installs.
    #[arg(long)]
    objdump: Option<PathBuf>,
    /// Print one JSON object instead of the table.
    #[arg(long)]
    json: bool,
}

/// Runs the estimate ([`law_cost::measure`]) and prints it.
pub fn run(args: LawArgs) -> Result<()> {
    let (rlib, c) = law_cost::measure(args.rlib, args.objdump)?;
    let degrees: Vec<(usize, Option<usize>)> = (1..=10)
        .map(|d| (d, c.instructions_for_degree(d)))
        .collect();
    if args.json {
        println!(
            "{}",
            serde_json::json!({ "rlib": rlib, "target": haptic::mcu::TARGET, "cost": c, "per_degree": degrees })
        );
        return Ok(());
    }
    println!(
        "TissueLaw::eval, {}, {} ({} instructions)",
        haptic::mcu::TARGET,
        rlib.display(),
        c.instructions
    );
    println!("paths (multiply-accumulates: instructions):");
    for p in &c.paths {
        println!("{:>6}: {}", p.macs, p.instructions);
    }
    println!("one in-domain evaluation:");
    println!("{:>6} {:>13}", "degree", "instructions");
    for (d, n) in degrees {
        println!(
            "{d:>6} {:>13}",
            n.map_or("-".to_string(), |n| n.to_string())
        );
    }
    Ok(())
}
