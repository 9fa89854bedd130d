//! `host bench law`: instructions one in-domain evaluation of the tissue law Q costs on the
//! MCU, per degree, from the thumbv7em disassembly of `TissueLaw::eval`
//! ([`host::calibrate::cost`] explains the count: instructions on the path, not cycles).

use anyhow::{Context, Result, bail};
use host::calibrate::cost;
use std::path::PathBuf;
use std::process::Command;

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

/// The cost model of `TissueLaw::eval` from the thumbv7em disassembly: `rlib` (default: build
/// bank-format for the MCU) read by `objdump` (default: rustup's llvm-tools). Returns the rlib
/// read and the cost.
pub fn measure(
    rlib: Option<PathBuf>,
    objdump: Option<PathBuf>,
) -> Result<(PathBuf, cost::EvalCost)> {
    let rlib = match rlib {
        Some(p) => p,
        None => host::mcu::build_rlib("bank-format")?,
    };
    let objdump = match objdump {
        Some(p) => p,
        None => host::mcu::objdump()?,
    };
    let out = Command::new(&objdump)
        .args(["-d", "-C", "--no-show-raw-insn"])
        .arg(&rlib)
        .output()
        .with_context(|| format!("running {}", objdump.display()))?;
    if !out.status.success() {
        bail!(
            "{} failed on {}: {}",
            objdump.display(),
            rlib.display(),
            String::from_utf8_lossy(&out.stderr).trim()
        );
    }
    let text = String::from_utf8_lossy(&out.stdout);
    let insns = cost::function(&text, "TissueLaw::eval");
    let c =
        cost::estimate(&insns).with_context(|| format!("TissueLaw::eval in {}", rlib.display()))?;
    Ok((rlib, c))
}

/// Runs the estimate and prints it.
pub fn run(args: LawArgs) -> Result<()> {
    let (rlib, c) = measure(args.rlib, args.objdump)?;
    let degrees: Vec<(usize, Option<usize>)> = (1..=10)
        .map(|d| (d, c.instructions_for_degree(d)))
        .collect();
    if args.json {
        println!(
            "{}",
            serde_json::json!({ "rlib": rlib, "target": host::mcu::TARGET, "cost": c, "per_degree": degrees })
        );
        return Ok(());
    }
    println!(
        "TissueLaw::eval, {}, {} ({} instructions)",
        host::mcu::TARGET,
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
