//! `host calibrate relaxation` (issue 30): the QLV fit recovers the published brain law the
//! bench data was generated from (`scripts/gen_relaxation_bench.py`: Miller & Chinzei 2002,
//! g = (0.450, 0.365), tau = (0.5, 50) s, with a finite ramp and noise), refuses noise and data
//! that does not relax, and writes the scene atomically (a refused fit leaves it untouched).

use host::calibrate::csv;
use host::calibrate::relaxation::{self, RelaxationError};
use host::scene::Scene;
use std::path::{Path, PathBuf};
use std::process::Command;

fn manifest(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(rel)
}

const BENCH: &str = "data/brain-relaxation-ramp-hold.csv";
/// The generator's force noise, N (its docstring).
const FORCE_NOISE: f64 = 0.5e-3;

/// The `t_s`, `x_m`, `force_n` columns of a bench CSV, by the calibration's own reader.
fn columns(text: &str) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let table = csv::parse(BENCH, text, &["t_s", "x_m", "force_n"]).unwrap();
    let col = |c| table.numbers(c).unwrap();
    (col(0), col(1), col(2))
}

#[path = "support/noise.rs"]
mod noise;
use noise::Noise;

#[test]
fn the_fit_recovers_the_published_brain_law_within_the_noise() {
    let text = std::fs::read_to_string(manifest(BENCH)).unwrap();
    let (t, x, f) = columns(&text);
    let fit = relaxation::fit(&t, &x, &f).unwrap();
    eprintln!(
        "{fit:?}",
        fit = (
            &fit.g,
            &fit.tau_s,
            fit.g_inf,
            fit.rms,
            fit.noise,
            &fit.survey
        )
    );
    assert_eq!(
        fit.g.len(),
        2,
        "two terms, as the law has: {:?}",
        fit.survey
    );
    let (g, tau) = ([0.450, 0.365], [0.5, 50.0]);
    for k in 0..2 {
        assert!(
            (fit.g[k] - g[k]).abs() < 0.01,
            "g_{k} {} vs {}",
            fit.g[k],
            g[k]
        );
        assert!(
            (fit.tau_s[k] / tau[k] - 1.0).abs() < 0.05,
            "tau_{k} {} vs {}",
            fit.tau_s[k],
            tau[k]
        );
    }
    assert!((fit.g_inf - 0.185).abs() < 0.01, "{}", fit.g_inf);
    // The force curve: the residual is the noise (the model is right), within 5 %.
    assert!(
        (fit.rms / FORCE_NOISE - 1.0).abs() < 0.05,
        "rms {} vs noise {FORCE_NOISE}",
        fit.rms
    );
    assert!(
        (fit.noise / FORCE_NOISE - 1.0).abs() < 0.15,
        "{}",
        fit.noise
    );
}

/// A ramp-and-hold whose force is the elastic response only (no relaxation), or noise only:
/// refused, each with its reason.
#[test]
fn noise_and_elastic_data_are_refused() {
    let mut noise = Noise(11);
    let t: Vec<f64> = (0..3000).map(|i| 0.01 * i as f64).collect();
    let x: Vec<f64> = t.iter().map(|&s| (s / 0.5).min(1.0) * 2e-3).collect();
    let elastic: Vec<f64> = x
        .iter()
        .map(|&v| 100.0 * v + 2e4 * v * v + 1e-3 * noise.normal())
        .collect();
    match relaxation::fit(&t, &x, &elastic) {
        Err(RelaxationError::NoRelaxation { .. }) => {}
        other => panic!("{other:?}"),
    }
    let pure: Vec<f64> = t.iter().map(|_| 1e-3 * noise.normal()).collect();
    match relaxation::fit(&t, &x, &pure) {
        Err(RelaxationError::Noise { snr }) => assert!(snr < 20.0),
        other => panic!("{other:?}"),
    }
    // No hold: a ramp all the way.
    let ramp: Vec<f64> = t.iter().map(|&s| s * 1e-4).collect();
    match relaxation::fit(&t, &ramp, &elastic) {
        Err(RelaxationError::NoHold(_)) => {}
        other => panic!("{other:?}"),
    }
}

fn host() -> Command {
    Command::new(env!("CARGO_BIN_EXE_host"))
}

/// The command writes `[viscoelastic]` into a copy of the shipped scene (which then loads with
/// the fitted law and builds a relaxing bank's record), prints one JSON object with `--json`,
/// and leaves the scene byte for byte as it was when the fit is refused.
#[test]
fn the_command_writes_the_scene_or_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("liver.toml");
    let original = std::fs::read_to_string(manifest("scenes/liver.toml")).unwrap();
    // Its FEM meshes are named relative to it.
    let meshes = format!("\"{}/", manifest("meshes").display());
    let original = original.replace("\"../meshes/", &meshes);
    std::fs::write(&scene, &original).unwrap();
    let plot = dir.path().join("fit");
    let bench = manifest(BENCH);
    let out = host()
        .args(["calibrate", "relaxation", "--json", "--csv"])
        .arg(&bench)
        .arg("--scene")
        .arg(&scene)
        .arg("--plot")
        .arg(&plot)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let g: Vec<f64> = serde_json::from_value(json["g"].clone()).unwrap();
    let tau: Vec<f64> = serde_json::from_value(json["tau_s"].clone()).unwrap();
    let g_inf = json["g_inf"].as_f64().unwrap();
    assert!((g_inf + g.iter().sum::<f64>() - 1.0).abs() < 1e-12);
    assert!(plot.with_extension("png").exists() && plot.with_extension("svg").exists());
    let loaded = Scene::load(&scene).unwrap();
    let v = loaded.viscoelastic.unwrap();
    // Written to 9 significant digits.
    let close = |a: &[f64], b: &[f64]| {
        a.len() == b.len() && a.iter().zip(b).all(|(p, q)| (p / q - 1.0).abs() < 1e-8)
    };
    assert!(
        close(&v.g, &g) && close(&v.tau_s, &tau),
        "{v:?} vs {g:?} {tau:?}"
    );
    assert!(v.record().is_ok());

    // Refused (noise): the scene is untouched.
    let written = std::fs::read(&scene).unwrap();
    let noisy = dir.path().join("noise.csv");
    let mut text = String::from("t_s,x_m,force_n\n");
    let mut noise = Noise(3);
    for i in 0..500 {
        let t = 0.01 * i as f64;
        text += &format!(
            "{t},{},{}\n",
            (t / 0.5).min(1.0) * 1e-3,
            1e-3 * noise.normal()
        );
    }
    std::fs::write(&noisy, text).unwrap();
    let out = host()
        .args(["calibrate", "relaxation", "--csv"])
        .arg(&noisy)
        .arg("--scene")
        .arg(&scene)
        .arg("--plot")
        .arg(&plot)
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("noise") && err.contains("nothing was written"),
        "{err}"
    );
    assert_eq!(std::fs::read(&scene).unwrap(), written);
}
