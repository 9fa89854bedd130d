//! The report's pipeline: every section of [`super`] measured on one scene in page order, the
//! firmware's under QEMU when `qemu-system-arm` is installed and the SIL image builds (else
//! the page says what was not measured and why), and the four files written: `index.html`,
//! `report.json`, `headline.png` and `figures.md` (the user guide's measured figures).

use super::{
    Report, couplings, hard, html, large_press, large_strain, law, locking, loops, pareto,
    precision, precompute_cost, relaxation, sampled, scale, tick_cost,
};
use crate::bank::{BankSpec, Prepared};
use crate::calibrate::{csv, fit};
use crate::fsio::write_atomic;
use crate::mcu::law_cost;
use crate::scene::{ContactModel, Couplings, MeshSource, Scene};
use crate::sil::harness::Setup;
use anyhow::{Context, Result};
use std::path::{Path, PathBuf};

/// The bench data the tissue-law knob fits (model-generated; see its header).
const BRAIN_DATA: &str = include_str!("../../../data/brain-compression-500mm-min.csv");
const BRAIN_DATA_NAME: &str = "host/data/brain-compression-500mm-min.csv";

/// What `host report` measures and where it writes.
#[derive(Debug, Clone)]
pub struct ReportConfig {
    /// Scene whose mesh is measured and whose choices are marked (`None`: the embedded
    /// liver).
    pub scene: Option<PathBuf>,
    /// Coarse sweeps, the QEMU runs included: about 4 minutes on a 2-core machine.
    pub quick: bool,
    /// Output directory, created when missing (it must not be a file): `index.html`,
    /// `report.json`, `headline.png`.
    pub out: PathBuf,
}

/// A finer mesh of the shipped organ, when the checkout has it.
fn shipped(name: &str) -> Option<PathBuf> {
    let p = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../meshes")
        .join(name);
    p.exists().then_some(p)
}

/// Runs the report on `cfg`'s scene and writes its files to `cfg.out` (each atomically);
/// `step` is told each stage as it starts. Returns what the page shows ([`Report::summary`]
/// says it in a few lines).
pub fn run(cfg: &ReportConfig, step: &dyn Fn(&str)) -> Result<Report> {
    let mut scene = Scene::load_or_default(cfg.scene.as_deref())?;
    // A sampled scene: its own knobs (section `sampled`), and everything else measured on the
    // nodal model of the same scene (the nodal knobs, and the comparison point).
    let sampled_scene = matches!(scene.contact, ContactModel::Sampled(_)).then(|| scene.clone());
    scene.contact = ContactModel::Nodal;
    let (organ, organ_name, _) = scene.load_mesh()?;
    let mut knobs = Vec::new();
    let mut cases = Vec::new();
    let mut not_measured = vec![
        "the 100k liver's precompute (ANP needs about 12 GiB there: `host bench compliance \
         --element anp`)"
            .to_string(),
    ];

    // The element under near-incompressibility.
    let mut locking_meshes = vec![(organ_name.clone(), organ.clone())];
    if !cfg.quick
        && let Some(p) = shipped("liver-10k.msh")
    {
        locking_meshes.push(("liver-10k".into(), fem::mesh::load(&p)?));
    }
    let mut measured = Vec::new();
    for (name, m) in &locking_meshes {
        let (rows, nnz) = locking::measure(name, m, step)?;
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
        if !cfg.quick {
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
        costs.push((name.clone(), precompute_cost::measure(m)?));
    }
    knobs.push(precompute_cost::section(&costs));

    // The tissue law's degree.
    step("tissue law: fits and the MCU cost of TissueLaw::eval");
    let table = csv::parse(BRAIN_DATA_NAME, BRAIN_DATA, &["linear_force_n", "force_n"])?;
    let (x, y) = (table.numbers(0)?, table.numbers(1)?);
    let (_, cost) = law_cost::measure(None, None)
        .context("the law-degree knob counts instructions on the thumbv7em disassembly")?;
    knobs.push(law::section(&x, &y, &cost)?);
    let (_, fitted, _) = fit::fit_law(&x, &y, None, fit::DEFAULT_TARGET_RMS)?;
    cases.push(hard::law_outside_domain(&fitted));

    step("hard cases: exact references and refusals");
    cases.extend(hard::elastic_cases()?);

    let (models, p_rms) = large_strain::measure(step)?;
    let (knob, rows) = large_strain::section(&models, p_rms);
    knobs.push(knob);
    cases.extend(rows);

    // The scene's bank: f32 against f64, the loop's hard cases, the firmware under QEMU.
    step("the scene's bank");
    let prepared = Prepared::from_scene(scene.clone())?;
    let built = prepared.bank(&BankSpec::Scene { progress: None })?;
    let bytes = bank_format::AlignedBytes::new(&built.bytes);
    let bank = bank_format::Bank::parse(&bytes)
        .map_err(|e| anyhow::anyhow!("the scene's bank does not parse: {e}"))?;
    step("f32 against f64 across the reachable region");
    // Arithmetic precision alone: the scene's bank with f32 blocks (the storage precision is
    // the bank-couplings knob's).
    let mut p32 = Prepared::from_scene(scene.clone())?;
    p32.organ.scene.bank.precision = bank_format::Precision::F32;
    let built32 = p32.bank(&BankSpec::Scene { progress: None })?;
    let bytes32 = bank_format::AlignedBytes::new(&built32.bytes);
    let bank32 = bank_format::Bank::parse(&bytes32)
        .map_err(|e| anyhow::anyhow!("the scene's f32 bank does not parse: {e}"))?;
    let errors = precision::region_errors(&p32, &bank32, cfg.quick)?;
    knobs.push(precision::section(
        &errors,
        prepared.organ.scene.bank.truncation_radius_m,
    ));
    cases.extend(precision::nu_cases(&precision::nu_rows(
        &p32,
        &locking::POISSON,
        step,
    )?));
    step("bank couplings: truncation rules against the untruncated solve");
    let swept = couplings::measure(&prepared, cfg.quick)?;
    let (knob, rows) = couplings::section(&swept, &prepared);
    knobs.push(knob);
    cases.extend(rows);
    step("hard cases of the loop (firmware code, natively)");
    // Their references are f32 against f64: on the f32 bank (the storage's error is the
    // bank-couplings knob's).
    cases.extend(loops::cases(&p32, &bank32)?);

    let seconds = if cfg.quick { 1.5 } else { 3.0 };
    let image = qemu_image();
    let (groups, run_banks) = match &image {
        Ok(image) => {
            let (setup, _dir) = image.with_bank(&built.bytes)?;
            let sil = tick_cost::measure(&setup, &bank, seconds, step)?;
            let (sil_knobs, row) = tick_cost::section(&sil);
            knobs.extend(sil_knobs);
            cases.push(row);
            // Every swept bank that fits, on the image too (the Pareto front's cost axis).
            let mut run_banks = Vec::new();
            for row in swept.iter().filter(|r| r.fits_region) {
                step(&format!(
                    "firmware on the {} {:.0} mm {} bank",
                    row.rule,
                    row.radius_m * 1e3,
                    row.precision
                ));
                let aligned = bank_format::AlignedBytes::new(&row.bank);
                let parsed = bank_format::Bank::parse(&aligned)
                    .map_err(|e| anyhow::anyhow!("internal: a swept bank does not parse: {e}"))?;
                let (setup, _dir) = image.with_bank(&row.bank)?;
                let quiet = |_: &str| {};
                let sil = tick_cost::measure(&setup, &parsed, seconds, &quiet)?;
                run_banks.push(pareto::RunBank {
                    row: row.clone(),
                    costs: sil.by_contact_nodes(),
                });
            }
            (Some(sil.by_contact_nodes()), run_banks)
        }
        Err(why) => {
            step(&format!("firmware knobs skipped: {why}"));
            not_measured.push(format!(
                "firmware instructions per tick (QEMU image) and the MCU cost of the contact \
                 models and of the Pareto front: {why}"
            ));
            (None, Vec::new())
        }
    };
    let instructions = |nodes: usize| {
        groups
            .as_ref()
            .and_then(|g| tick_cost::body_worst(g, nodes))
    };

    // Viscoelastic relaxation: press-hold on the shipped QLV scene, on the image.
    let skipped = match (&image, relaxation::shipped_scenes()) {
        (Ok(image), Ok((qlv_scene, elastic_scene))) => {
            step("relaxation: the QLV scene's banks (elastic and relaxing)");
            let banks = relaxation::banks(&qlv_scene, &elastic_scene)?;
            // The whole script, quick or not (5 runs of 12 s, two at a time, take about 16 s here).
            let seconds = relaxation::PRESS_HOLD_S;
            let measured = relaxation::measure(
                &banks,
                &|bytes: &[u8]| image.with_bank(bytes),
                seconds,
                step,
            )?;
            let (relax_knobs, row) = relaxation::section(&measured);
            knobs.extend(relax_knobs);
            cases.push(row);
            None
        }
        (Err(why), _) => Some(why.clone()),
        (_, Err(why)) => Some(format!("{why:#}")),
    };
    if let Some(why) = skipped {
        step(&format!("relaxation knobs skipped: {why}"));
        not_measured.push(format!(
            "press-hold's force against time on the QLV scene and instructions per tick \
             against Prony terms (QEMU image): {why}; the SIL test \
             press_hold_relaxes_as_the_scenes_qlv_law measures both (docs/calibration.md, \
             \"Viscoelastic tissue\")"
        ));
    }

    if let Some(sampled_scene) = &sampled_scene {
        let mut variants = sampled::measure(sampled_scene, cfg.quick, step)?;
        if let Ok(image) = &image {
            let chosen_fem = variants.iter().find(|v| v.chosen).map(|v| v.fem.clone());
            let mut by_level = std::collections::BTreeMap::new();
            for v in variants
                .iter()
                .filter(|v| Some(&v.fem) == chosen_fem.as_ref())
            {
                step(&format!("firmware on the sampled level-{} bank", v.level));
                let aligned = bank_format::AlignedBytes::new(&v.bank);
                let parsed = bank_format::Bank::parse(&aligned)
                    .map_err(|e| anyhow::anyhow!("internal: a sampled bank does not parse: {e}"))?;
                let (setup, _dir) = image.with_bank(&v.bank)?;
                let sil = tick_cost::measure(&setup, &parsed, seconds, &|_: &str| {})?;
                let worst = sil.by_contact_nodes().values().map(|g| g.body_max).max();
                by_level.insert(v.level, worst.map(f64::from));
            }
            for v in &mut variants {
                v.instructions = by_level.get(&v.level).copied().flatten();
            }
        }
        let study = sampled::reference()?;
        let depths: &[f64] = if cfg.quick {
            &[0.005]
        } else {
            &[0.002, 0.005, 0.008]
        };
        // The nodal banks on the same axis: every swept bank run on the image (else the
        // scene's own); a bank whose patch the probe cannot form (couplings truncated away)
        // is left out.
        let mut nodal = Vec::new();
        let own = [(
            format!(
                "{} bank (scene)",
                prepared.organ.scene.bank.precision.name()
            ),
            built.bytes.clone(),
            groups.clone(),
        )];
        let swept_banks: Vec<_> = run_banks
            .iter()
            .map(|b| {
                (
                    format!(
                        "{} {:.0} mm {}",
                        b.row.rule,
                        b.row.radius_m * 1e3,
                        b.row.precision
                    ),
                    b.row.bank.clone(),
                    Some(b.costs.clone()),
                )
            })
            .collect();
        let nodal_banks = if swept_banks.is_empty() {
            &own[..]
        } else {
            &swept_banks[..]
        };
        for (name, bytes, costs) in nodal_banks {
            let aligned = bank_format::AlignedBytes::new(bytes);
            let parsed = bank_format::Bank::parse(&aligned)
                .map_err(|e| anyhow::anyhow!("internal: a nodal bank does not parse: {e}"))?;
            if let Ok(error) = sampled::force_error(&prepared.organ, &parsed, &study, depths) {
                nodal.push(sampled::NodalPoint {
                    name: format!("nodal tool patch on {organ_name}, {name}"),
                    bytes: bytes.len(),
                    error,
                    instructions: costs
                        .as_ref()
                        .and_then(|g| g.values().map(|c| c.body_max).max())
                        .map(f64::from),
                });
            }
        }
        let (knob, rows) = sampled::section(&variants, &nodal);
        knobs.push(knob);
        cases.extend(rows);
        cases.extend(sampled::refinement_case(&study));
        if let Some(chosen) = variants.iter().find(|v| v.chosen) {
            step("sampled contact: presses on the organ's own surface");
            match super::surface::section(sampled_scene, &chosen.bank) {
                Ok(rows) => cases.extend(rows),
                Err(e) => not_measured.push(format!("the presses on the organ's surface: {e:#}")),
            }
        }
        let cylinder = shipped("cylinder-2k.msh");
        let (k, c, n) = large_press::run(sampled_scene, cylinder.as_deref(), step)?;
        knobs.extend(k);
        cases.extend(c);
        not_measured.extend(n);
    } else {
        not_measured.push(
            "the sampled patch compliance's knobs (the scene's contact model is nodal)".into(),
        );
    }

    // Mesh size: contact models, bank size, display.
    let ray = scale::press_ray(&prepared);
    let liver = match &scene.mesh {
        MeshSource::BuiltinLiver => true,
        MeshSource::File(p) => p.ends_with("liver-1k4.msh"),
    };
    let split = fem::reference::split_1_to_8(&organ);
    let mut meshes = vec![(organ_name.clone(), organ.clone())];
    match shipped("liver-10k.msh").filter(|_| liver) {
        Some(p) => {
            meshes.push((format!("{organ_name} split 1:8"), split));
            let fine = fem::mesh::load(&p)?;
            if !cfg.quick {
                meshes.push((
                    "liver-10k split 1:8".into(),
                    fem::reference::split_1_to_8(&fine),
                ));
                if let Some(p) = shipped("generated/liver-100k.msh") {
                    meshes.push(("liver-100k".into(), fem::mesh::load(&p)?));
                }
            }
            meshes.push(("liver-10k".into(), fine));
        }
        None => {
            meshes.push((
                format!("{organ_name} split 1:8 twice"),
                fem::reference::split_1_to_8(&split),
            ));
            meshes.push((format!("{organ_name} split 1:8"), split));
        }
    }
    meshes.sort_by_key(|(_, m)| m.nodes.len());
    let mut runs = Vec::new();
    for (name, m) in &meshes {
        step(&format!(
            "contact models, bank and display: {name} ({} nodes)",
            m.nodes.len()
        ));
        runs.push(scale::measure(&scene, name, m, ray)?);
    }
    knobs.extend(scale::section(&runs, &instructions));
    cases.extend(scale::refinement_cases(&runs));
    let own = &prepared.organ.scene.bank;
    let own_rule = match own.couplings {
        Couplings::Radius => "radius",
        Couplings::Tool => "tool",
    };
    match pareto::section(
        &runs,
        &run_banks,
        (own_rule, own.truncation_radius_m, own.precision.name()),
    ) {
        Some(k) => knobs.push(k),
        None => not_measured.push(
            "the Pareto front (it needs the firmware's instruction counts and a tool-patch \
             reference)"
                .into(),
        ),
    }
    if cfg.quick {
        not_measured.push(
            "liver-10k rows of the element knob (full run only: 10-node tetrahedra on it take \
             about 40 s per ratio)"
                .into(),
        );
    }

    let report = Report {
        scene: scene.path.display().to_string(),
        quick: cfg.quick,
        knobs,
        hard_cases: cases,
        not_measured,
    };
    report.check_finite().map_err(anyhow::Error::msg)?;
    write(&report, &cfg.out)?;
    Ok(report)
}

/// QEMU and the SIL image, found and built.
struct Image {
    qemu: PathBuf,
    image: PathBuf,
}

impl Image {
    /// The set-up for `bank` (written to a temporary directory, returned to keep it alive).
    fn with_bank(&self, bank: &[u8]) -> Result<(Setup, tempfile::TempDir)> {
        let dir = tempfile::tempdir().context("a temporary directory for the bank")?;
        let path = dir.path().join("scene.bank");
        std::fs::write(&path, bank).with_context(|| format!("writing {}", path.display()))?;
        let setup = Setup {
            qemu: self.qemu.clone(),
            image: self.image.clone(),
            bank: path,
        };
        Ok((setup, dir))
    }
}

/// QEMU and the image, or why the firmware cannot be run: QEMU not installed, or the image
/// does not build.
fn qemu_image() -> std::result::Result<Image, String> {
    let qemu = PathBuf::from("qemu-system-arm");
    let found = std::process::Command::new(&qemu)
        .arg("--version")
        .output()
        .is_ok_and(|o| o.status.success());
    if !found {
        return Err(
            "qemu-system-arm is not installed (Debian: apt-get install qemu-system-arm)".into(),
        );
    }
    eprintln!("building the QEMU image (firmware/qemu, cargo build --release) ...");
    let image = crate::mcu::build_qemu_image()
        .map_err(|e| format!("the QEMU image does not build: {e:#}"))?;
    Ok(Image { qemu, image })
}

/// Writes the four files, each atomically.
fn write(report: &Report, dir: &Path) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let page = html::page(report)?;
    let json = serde_json::to_string_pretty(report)?;
    let headline = report
        .knobs
        .first()
        .map(html::png)
        .transpose()?
        .unwrap_or_default();
    write_atomic(&dir.join("report.json"), json.as_bytes(), &[])?;
    write_atomic(&dir.join("headline.png"), &headline, &[])?;
    write_atomic(&dir.join("index.html"), page.as_bytes(), &[])?;
    // The guide's measured figures (docs/figures.md is this file, copied by gen-figures.sh).
    let figures = super::figures::markdown(report);
    write_atomic(&dir.join("figures.md"), figures.as_bytes(), &[])?;
    Ok(())
}
