//! `host report`: runs the measurements of [`haptic::report`] ([`haptic::report::pipeline::run`])
//! and prints the summary; the page, the JSON and the headline figure are written by the
//! library.

use anyhow::{Result, bail};
use haptic::report::pipeline::{self, ReportConfig};
use std::path::PathBuf;
use std::time::Instant;

/// Arguments of `host report`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Scene whose mesh is measured and whose choices are marked (default: the embedded liver).
    #[arg(long)]
    scene: Option<PathBuf>,
    /// Coarse sweeps, its QEMU runs included: about 4 minutes on a 2-core machine (the test
    /// command runs this).
    #[arg(long)]
    quick: bool,
    /// Output directory (created when missing): index.html, report.json, headline.png,
    /// figures.md (the figures the user guide quotes).
    #[arg(long)]
    out: PathBuf,
}

/// Runs the report.
pub fn run(args: Args) -> Result<()> {
    if args.out.exists() && !args.out.is_dir() {
        bail!(
            "--out {}: exists and is not a directory",
            args.out.display()
        );
    }
    let started = Instant::now();
    let step = |what: &str| eprintln!("[{:>6.1} s] {what}", started.elapsed().as_secs_f64());
    let cfg = ReportConfig {
        scene: args.scene,
        quick: args.quick,
        out: args.out,
    };
    let report = pipeline::run(&cfg, &step)?;
    for line in report.summary() {
        println!("{line}");
    }
    println!(
        "wrote {} (index.html, report.json, headline.png, figures.md) in {:.0} s",
        cfg.out.display(),
        started.elapsed().as_secs_f64()
    );
    Ok(())
}
