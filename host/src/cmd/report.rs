//! `host report`: runs the measurements of [`host::report`] and writes the page, the JSON and
//! the headline figure.

use anyhow::{Context, Result, bail};
use host::calibrate::{csv, fit};
use host::fsio::write_atomic;
use host::report::{self, Report, hard, law, locking, mesh};
use host::scene::Scene;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// The bench data the tissue-law knob fits (model-generated; see its header).
const BRAIN_DATA: &str = include_str!("../../data/brain-compression-500mm-min.csv");
const BRAIN_DATA_NAME: &str = "host/data/brain-compression-500mm-min.csv";

/// Arguments of `host report`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Scene whose mesh is measured and whose choices are marked (default: the embedded liver).
    #[arg(long)]
    scene: Option<PathBuf>,
    /// Coarse sweeps: under 3 minutes on a 2-core machine (the test command runs this).
    #[arg(long)]
    quick: bool,
    /// Output directory (created when missing): index.html, report.json, headline.png.
    #[arg(long)]
    out: PathBuf,
}

/// A finer mesh of the shipped organ, when the checkout has it.
fn shipped(name: &str) -> Option<PathBuf> {
    let p = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("meshes")
        .join(name);
    p.exists().then_some(p)
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
    let scene = Scene::load_or_default(args.scene.as_deref())?;
    let (organ, organ_name, _) = scene.load_mesh()?;
    let mut knobs = Vec::new();
    let mut cases = Vec::new();
    let mut not_measured = vec![
        "bank truncation rule and storage precision against force error, bytes and MCU \
         instructions"
            .to_string(),
        "contact model (point, alpha weights, energy-minimal, tool radius) under refinement"
            .to_string(),
        "firmware instructions per tick by phase from the QEMU image".to_string(),
        "f32 on the MCU against f64 on the host across the reachable region".to_string(),
        "bank size and display latency against mesh size; the 100k liver's precompute (ANP needs \
         about 12 GiB there: `host bench compliance --element anp`); Pareto front of combined \
         knobs"
            .to_string(),
        "hard cases of the loop: grazing, edge and vertex hits, a 5 cm strike, contact nodes \
         1 um apart, the reachable region's edge; condition numbers of K_ff and C_SS"
            .to_string(),
    ];

    // The element under near-incompressibility.
    let mut locking_meshes = vec![(organ_name.clone(), organ.clone())];
    if !args.quick
        && let Some(p) = shipped("liver-10k.msh")
    {
        locking_meshes.push(("liver-10k".into(), fem::mesh::load(&p)?));
    }
    let mut measured = Vec::new();
    for (name, m) in &locking_meshes {
        let (rows, nnz) = locking::measure(name, m, &step)?;
        measured.push((name.clone(), rows, nnz));
    }
    let (knob, rows) = locking::section(&measured);
    knobs.push(knob);
    cases.extend(rows);

    // Mesh size against precompute.
    let mut sizes = vec![(organ_name.clone(), organ.clone())];
    sizes.push((
        format!("{organ_name} split 1:8"),
        fem::reference::split_1_to_8(&organ),
    ));
    if let Some(p) = shipped("liver-10k.msh") {
        let fine = fem::mesh::load(&p)?;
        if !args.quick {
            sizes.push((
                "liver-10k split 1:8".into(),
                fem::reference::split_1_to_8(&fine),
            ));
        }
        sizes.push(("liver-10k".into(), fine));
    }
    sizes.sort_by_key(|(_, m)| m.nodes.len());
    let mut costs = Vec::new();
    for (name, m) in &sizes {
        step(&format!(
            "precompute cost: {name} ({} nodes)",
            m.nodes.len()
        ));
        costs.push((name.clone(), mesh::measure(m)?));
    }
    knobs.push(mesh::section(&costs));

    // The tissue law's degree.
    step("tissue law: fits and the MCU cost of TissueLaw::eval");
    let table = csv::parse(BRAIN_DATA_NAME, BRAIN_DATA, &["linear_force_n", "force_n"])?;
    let (x, y) = (table.numbers(0)?, table.numbers(1)?);
    let (_, cost) = super::bench_law::measure(None, None)
        .context("the law-degree knob counts instructions on the thumbv7em disassembly")?;
    knobs.push(law::section(&x, &y, &cost)?);
    let (_, fitted, _) = fit::fit_law(&x, &y, None, fit::DEFAULT_TARGET_RMS)?;
    cases.push(hard::law_outside_domain(&fitted));

    step("hard cases: exact references and refusals");
    cases.extend(hard::elastic_cases()?);
    if args.quick {
        not_measured.push(
            "liver-10k rows of the element knob (full run only: 10-node tetrahedra on it take \
             about 40 s per ratio)"
                .into(),
        );
    }

    let report = Report {
        scene: scene.path.display().to_string(),
        quick: args.quick,
        knobs,
        hard_cases: cases,
        not_measured,
    };
    report.check_finite().map_err(anyhow::Error::msg)?;
    write(&report, &args.out)?;
    for line in report.summary() {
        println!("{line}");
    }
    println!(
        "wrote {} (index.html, report.json, headline.png) in {:.0} s",
        args.out.display(),
        started.elapsed().as_secs_f64()
    );
    Ok(())
}

/// Writes the three files, each atomically.
fn write(report: &Report, dir: &Path) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let page = report::html::page(report)?;
    let json = serde_json::to_string_pretty(report)?;
    let headline = report
        .knobs
        .first()
        .map(report::html::png)
        .transpose()?
        .unwrap_or_default();
    write_atomic(&dir.join("report.json"), json.as_bytes(), &[])?;
    write_atomic(&dir.join("headline.png"), &headline, &[])?;
    write_atomic(&dir.join("index.html"), page.as_bytes(), &[])?;
    Ok(())
}
