//! `host bench law`: instructions one in-domain evaluation of the tissue law Q costs on the
//! MCU, per degree, from the thumbv7em disassembly of `TissueLaw::eval`
//! ([`host::calibrate::cost`] explains the count: instructions on the path, not cycles).

use anyhow::{Context, Result, bail};
use host::calibrate::cost;
use std::path::{Path, PathBuf};
use std::process::Command;

const TARGET: &str = "thumbv7em-none-eabihf";

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

fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .map_or_else(|| PathBuf::from("."), Path::to_path_buf)
}

fn build_rlib() -> Result<PathBuf> {
    let root = workspace();
    eprintln!("building bank-format for {TARGET} ...");
    let status = Command::new(std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into()))
        .args([
            "build",
            "--release",
            "-p",
            "bank-format",
            "--target",
            TARGET,
        ])
        .current_dir(&root)
        .status()
        .context("running cargo")?;
    if !status.success() {
        bail!("cargo build -p bank-format --target {TARGET} failed");
    }
    let target_dir =
        std::env::var_os("CARGO_TARGET_DIR").map_or_else(|| root.join("target"), PathBuf::from);
    let deps = target_dir.join(TARGET).join("release").join("deps");
    std::fs::read_dir(&deps)
        .with_context(|| format!("reading {}", deps.display()))?
        .filter_map(|e| e.ok())
        .filter(|e| {
            let n = e.file_name();
            let n = n.to_string_lossy();
            n.starts_with("libbank_format-") && n.ends_with(".rlib")
        })
        .max_by_key(|e| e.metadata().and_then(|m| m.modified()).ok())
        .map(|e| e.path())
        .with_context(|| format!("no libbank_format-*.rlib in {}", deps.display()))
}

fn find_objdump() -> Result<PathBuf> {
    let out = Command::new("rustc")
        .args(["--print", "sysroot"])
        .output()
        .context("running rustc --print sysroot")?;
    let sysroot = PathBuf::from(String::from_utf8_lossy(&out.stdout).trim());
    let rustlib = sysroot.join("lib").join("rustlib");
    let found = std::fs::read_dir(&rustlib)
        .into_iter()
        .flatten()
        .filter_map(|e| e.ok())
        .map(|e| e.path().join("bin").join("llvm-objdump"))
        .find(|p| p.exists());
    found.with_context(|| {
        format!(
            "llvm-objdump not found under {}: install it with `rustup component add llvm-tools`, or pass --objdump",
            rustlib.display()
        )
    })
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
        None => build_rlib()?,
    };
    let objdump = match objdump {
        Some(p) => p,
        None => find_objdump()?,
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
            serde_json::json!({ "rlib": rlib, "target": TARGET, "cost": c, "per_degree": degrees })
        );
        return Ok(());
    }
    println!(
        "TissueLaw::eval, {TARGET}, {} ({} instructions)",
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
