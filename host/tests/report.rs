//! The quick report ([`haptic::report::pipeline::run`], what `host report --quick` runs): the page
//! renders in headless Chromium with every plot drawn and no console error; `report.json` holds
//! each knob's series with at least three finite points; and its numbers agree with the tests'
//! references (the relaxation section's with the SIL test's), and with the user guide's figures
//! file (`docs/figures.md`), each to its stated tolerance. `host report`'s own refusal of an
//! `--out` that is a file is checked on the binary.

mod support;
use support::chromium;

use haptic::bank::{BankSpec, Prepared};
use haptic::report::pipeline::{self, ReportConfig};
use haptic::sil::cost::CODE_PHASES;
use std::path::Path;
use std::process::Command;

/// `--dump-dom` of `page` and Chromium's stderr (with `--enable-logging=stderr`, console
/// messages and uncaught errors appear there as `INFO:CONSOLE` lines).
fn render(page: &Path) -> (String, String) {
    let profile = tempfile::tempdir().unwrap();
    let out = Command::new(chromium())
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--enable-logging=stderr",
            "--v=0",
            "--virtual-time-budget=2000",
            "--dump-dom",
        ])
        .arg(format!("--user-data-dir={}", profile.path().display()))
        .arg(format!("file://{}", page.display()))
        .output()
        .unwrap();
    assert!(out.status.success(), "chromium failed");
    (
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn report_refuses_an_out_that_is_a_file() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("report");
    std::fs::write(&file, "not a directory").unwrap();
    let run = Command::new(env!("CARGO_BIN_EXE_host"))
        .args(["report", "--quick", "--out"])
        .arg(&file)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert_eq!(run.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains(&format!(
            "--out {}: exists and is not a directory",
            file.display()
        )),
        "{stderr}"
    );
    assert_eq!(
        std::fs::read_to_string(&file).unwrap(),
        "not a directory",
        "the file is left alone"
    );
}

#[test]
fn quick_report_renders_every_plot_and_agrees_with_the_references() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("report");
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/liver-nodal.toml");
    let config = ReportConfig {
        scene: Some(scene.clone()),
        quick: true,
        out: out.clone(),
    };
    let report = pipeline::run(&config, &|what: &str| eprintln!("{what}")).unwrap();
    let summary = report.summary();
    assert!(
        summary.last().unwrap().starts_with("hard cases:"),
        "{summary:?}"
    );

    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    let knobs = json["knobs"].as_array().unwrap();
    assert!(knobs.len() >= 3, "{} knobs", knobs.len());
    for knob in knobs {
        for series in knob["series"].as_array().unwrap() {
            let points = series["points"].as_array().unwrap();
            assert!(points.len() >= 3, "{} / {}", knob["id"], series["name"]);
            for p in points {
                assert!(
                    p["x"].as_f64().unwrap().is_finite() && p["y"].as_f64().unwrap().is_finite()
                );
            }
        }
    }
    // Against the references the fem tests use: the independent P2 punch forces on
    // liver-1k4 (0.366, 0.389, 0.409 N) and the exact box compression.
    let cases = json["hard_cases"].as_array().unwrap();
    let find = |prefix: &str| {
        cases
            .iter()
            .find(|c| c["case"].as_str().unwrap().starts_with(prefix))
            .unwrap_or_else(|| panic!("no hard case {prefix}"))
    };
    for (nu, p2) in [("0.45", 0.366), ("0.49", 0.389), ("0.499", 0.409)] {
        let row = find(&format!("nu = {nu}, anp"));
        let reference = row["reference_value"].as_f64().unwrap();
        assert!((reference - p2).abs() < 0.001, "nu {nu}: P2 {reference}");
        assert_eq!(row["verdict"], "matches_reference", "{row}");
        assert_eq!(find(&format!("nu = {nu}, p1"))["verdict"], "weakness");
    }
    for c in cases
        .iter()
        .filter(|c| c["case"].as_str().unwrap().contains("box compression"))
    {
        assert!(c["value"].as_f64().unwrap() < 1e-9, "{c}");
    }
    assert_eq!(find("contact at the fixed boundary")["verdict"], "refused");
    assert_eq!(find("sliver")["verdict"], "refused");

    // The new knobs are all there (the test command installs QEMU, so the firmware's too).
    let knob = |id: &str| {
        knobs
            .iter()
            .find(|k| k["id"] == id)
            .unwrap_or_else(|| panic!("no knob {id}"))
    };
    let ys = |id: &str| -> Vec<f64> {
        knob(id)["series"]
            .as_array()
            .unwrap()
            .iter()
            .flat_map(|s| s["points"].as_array().unwrap().iter())
            .map(|p| p["y"].as_f64().unwrap())
            .collect()
    };
    for id in [
        "firmware-histogram",
        "firmware-phases",
        "firmware-code-phase-histogram",
        "firmware-code-phases",
        "f32-vs-f64",
        "contact-refinement",
        "mesh-bank",
        "mesh-display",
        "pareto",
        "bank-couplings",
    ] {
        assert!(!ys(id).is_empty(), "{id}");
    }
    // The bank's couplings: the tool rule is exact (host/tests/exact_contacts.rs holds it to
    // 1e-4 on 1,200 sites), a bank without couplings (radius 0) is not, and the row says so.
    assert_eq!(
        find("every contact the tool can make (tool rule)")["verdict"],
        "matches_reference"
    );
    let series = |name: &str| -> Vec<f64> {
        knob("bank-couplings")["series"]
            .as_array()
            .unwrap()
            .iter()
            .find(|s| s["name"] == name)
            .unwrap_or_else(|| panic!("no series {name}"))["points"]
            .as_array()
            .unwrap()
            .iter()
            .map(|p| p["y"].as_f64().unwrap())
            .collect()
    };
    assert!(
        series("tool rule (+ radius), tool patch")
            .iter()
            .all(|&e| e <= 1e-4)
    );
    assert!(series("radius rule, tool patch")[0] > 1e-3);
    // f32 against f64 over the reachable region: the bound host/tests/loop_vs_host.rs and
    // tests/tests/solve_vs_host.rs hold the firmware's solves to, on the untruncated
    // compliance.
    let worst = ys("f32-vs-f64").into_iter().fold(0.0, f64::max);
    // Measured 8.8e-7 (docs/figures.md).
    assert!(worst <= 5e-6, "f32 vs f64: {worst:e}");
    assert_eq!(
        find("nu = 0.45: f32 force error")["verdict"],
        "matches_reference"
    );
    assert_eq!(find("edge and vertex hits")["verdict"], "matches_reference");
    // The supervisor's overspeed rule (firmware/src/safety.rs) refuses a 50 m/s tip.
    assert_eq!(find("a 5 cm strike in one tick")["verdict"], "refused");
    // Every histogram series is a distribution of the script's (or the code phase's) ticks:
    // its shares sum to 100 %.
    let histograms = ["firmware-histogram", "firmware-code-phase-histogram"];
    for s in histograms
        .iter()
        .flat_map(|id| knob(id)["series"].as_array().unwrap())
    {
        let total: f64 = s["points"]
            .as_array()
            .unwrap()
            .iter()
            .map(|p| p["y"].as_f64().unwrap())
            .sum();
        assert!((total - 100.0).abs() < 1e-6, "{}: {total}", s["name"]);
    }
    // The worst tick (the report's scene bank is the nodal model's) within that model's goal,
    // not only within its 1 ms period (125,000 instructions at 125 MIPS).
    let worst = find("worst-case tick on the MCU");
    let worst_tick = worst["value"].as_f64().unwrap();
    assert!(
        worst_tick > 0.0 && worst_tick <= f64::from(haptic::sil::cost::NODAL_TICK_GOAL),
        "{worst_tick}"
    );
    assert_eq!(worst["verdict"], "bounded", "{worst}");
    // Every code phase ran (the scripts touch the organ, so patch and solve did too), and
    // the whole tick holds the link phase and the body's phases.
    let code_worst = knob("firmware-code-phases")["series"][0]["points"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["y"].as_f64().unwrap())
        .collect::<Vec<_>>();
    assert_eq!(code_worst.len(), CODE_PHASES.len());
    assert!(code_worst.iter().all(|&w| w > 0.0), "{code_worst:?}");
    let link = code_worst[CODE_PHASES.len() - 1];
    assert!(link < worst_tick, "{code_worst:?} {worst_tick}");
    // Viscoelastic relaxation: press-hold on liver-qlv under QEMU follows the
    // analytic QLV response (the SIL test's 1e-4 of the peak), the force relaxes during the
    // hold (the rendered force at the end below its peak, above g_inf of it), and the cost is
    // measured for 0 to 4 Prony terms, the law phase growing with them.
    let press_hold = find("press-hold on the QLV scene");
    assert_eq!(press_hold["verdict"], "matches_reference", "{press_hold}");
    assert!(press_hold["value"].as_f64().unwrap() < 1e-4);
    let trace = knob("relaxation-press-hold")["series"][0]["points"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| (p["x"].as_f64().unwrap(), p["y"].as_f64().unwrap()))
        .collect::<Vec<_>>();
    let peak = trace.iter().map(|p| p.1).fold(0.0, f64::max);
    let held = trace.iter().find(|p| p.0 >= 10.9).unwrap();
    assert!(held.1 < 0.8 * peak && held.1 > 0.1 * peak, "{trace:?}");
    // Released: no force once the tool is out.
    assert_eq!(trace.last().unwrap().1, 0.0, "{trace:?}");
    let terms = knob("relaxation-terms")["series"][0]["points"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| (p["x"].as_f64().unwrap(), p["y"].as_f64().unwrap()))
        .collect::<Vec<_>>();
    assert_eq!(
        terms.iter().map(|p| p.0).collect::<Vec<_>>(),
        [0.0, 1.0, 2.0, 3.0, 4.0]
    );
    assert!(
        terms[4].1 > terms[1].1 && terms[1].1 > terms[0].1,
        "{terms:?}"
    );
    // The scene's bank on the plot is the one `host bank build` writes.
    let built = Prepared::load(&scene)
        .unwrap()
        .bank(&BankSpec::Scene { progress: None })
        .unwrap();
    let chosen = knob("mesh-bank")["chosen"]["y"].as_f64().unwrap();
    assert_eq!(chosen, built.bytes.len() as f64);

    let png = std::fs::read(out.join("headline.png")).unwrap();
    assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n");

    let (dom, log) = render(&out.join("index.html"));
    let attr = |name: &str| {
        let key = format!("data-{name}=\"");
        let at = dom
            .find(&key)
            .unwrap_or_else(|| panic!("no {key} on <body>: script did not run"));
        dom[at + key.len()..]
            .split('"')
            .next()
            .unwrap()
            .parse::<usize>()
            .unwrap()
    };
    assert_eq!(attr("plots"), knobs.len());
    assert_eq!(attr("drawn"), knobs.len(), "an empty plot");
    // Chromium logs every console message (errors and uncaught exceptions included) as
    // `INFO:CONSOLE`, without its level; the page writes none when all is well.
    let console: Vec<&str> = log.lines().filter(|l| l.contains(":CONSOLE")).collect();
    assert!(console.is_empty(), "console messages: {console:?}");

    // The user guide's measured figures (docs/figures.md, written by scripts/gen-figures.sh
    // from this same command) are this run's, each to the tolerance its row states.
    let fresh = std::fs::read_to_string(out.join("figures.md")).unwrap();
    let committed =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/figures.md"))
            .unwrap();
    let problems = haptic::report::figures::compare(&committed, &fresh);
    assert!(
        problems.is_empty(),
        "docs/figures.md disagrees with this report (run scripts/gen-figures.sh if the change \
         is meant):\n{}",
        problems.join("\n")
    );
}
