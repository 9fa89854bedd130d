//! Bench calibration: the fits recover known laws and motor constants from noisy
//! synthetic data, the chosen basis survives degree 10 where monomial normal equations do not,
//! the shipped brain-tissue data meets the accuracy goal and matches the host FEM, and bad
//! bench files fail with the line named and the scene untouched.

#[path = "support/cli.rs"]
mod cli;

use cli::run;
use faer::Mat;
use faer::linalg::solvers::Solve;
use fem::elasticity::Material;
use haptic::calibrate::fit::{self, FitError};
use haptic::calibrate::motor::{self, Sample};
use haptic::calibrate::scene_edit::{self, Law};
use haptic::calibrate::{cheb, csv, specimen, tissue};
use haptic::scene::Scene;
use std::path::{Path, PathBuf};

use haptic::rng::SplitMix64;

fn monomial(c: &[f64], x: f64) -> f64 {
    c.iter().rev().fold(0.0, |acc, &ci| acc * x + ci)
}

fn manifest(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(rel)
}

const BRAIN: &str = "data/brain-compression-500mm-min.csv";

#[test]
fn recovers_known_polynomials_from_noisy_data() {
    let mut noise = SplitMix64::new(7);
    // An increasing quintic on [0.2, 3], given by its Chebyshev coefficients on that interval
    // (every term well above the noise), sampled with 0.5 % noise of full scale.
    let domain = [0.2, 3.0];
    let truth = fit::ChebFit {
        degree: 5,
        domain,
        coeffs: vec![1.0, 1.0, 0.2, 0.1, 0.05, 0.04],
    };
    assert!(truth.law().is_ok(), "the reference law must be increasing");
    let x: Vec<f64> = (0..300).map(|i| 0.2 + 2.8 * f64::from(i) / 299.0).collect();
    let clean: Vec<f64> = x.iter().map(|&v| truth.eval(v)).collect();
    let scale = clean.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let sigma = 0.005 * scale;
    let y: Vec<f64> = clean.iter().map(|v| v + sigma * noise.normal()).collect();
    let f = fit::fit(&x, &y, 5).unwrap();
    for (got, want) in f.coeffs.iter().zip(&truth.coeffs) {
        assert!(
            (got - want).abs() < 3e-3,
            "{:?} vs {:?}",
            f.coeffs,
            truth.coeffs
        );
    }
    // Least squares with p = 6 unknowns and n = 300 points: the fitted curve's error is about
    // sigma sqrt(p / n) = 0.14 sigma; allow 0.6 sigma everywhere.
    let worst = x
        .iter()
        .zip(&clean)
        .map(|(&v, &c)| (f.eval(v) - c).abs())
        .fold(0.0, f64::max);
    assert!(
        worst < 0.6 * sigma,
        "max error {worst:e} vs sigma {sigma:e}"
    );
    // The residuals are the noise: RMS within 10 % of sigma.
    let rms = fit::relative_errors(
        &x.iter()
            .zip(&y)
            .map(|(&v, &yi)| yi - f.eval(v))
            .collect::<Vec<_>>(),
        &y,
    )
    .rms_rel
        * y.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    assert!(
        (rms / sigma - 1.0).abs() < 0.1,
        "residual rms {rms:e} vs {sigma:e}"
    );
    // Cross-validation picks the true degree: lower degrees miss the shape, higher ones only
    // fit noise.
    let rows = fit::survey(&x, &y, fit::AUTO_DEGREES).unwrap();
    assert_eq!(fit::choose(&rows, 0.0), Some(5), "{rows:#?}");
    // The law stored for the device (f32) evaluates the same curve.
    let law = f.law().unwrap();
    for &v in &x {
        let want = f.eval(v);
        assert!((f64::from(law.eval(v as f32)) - want).abs() < 1e-5 * scale);
    }
}

#[test]
fn chebyshev_qr_survives_degree_10_where_monomial_normal_equations_fail() {
    // A smooth degree-10 curve on [1, 3] plus noise (sigma = 0.001): the least-squares fit
    // minimises the residual, so whichever solver leaves the smaller residual is the better
    // one, and the exact least-squares residual RMS is sigma sqrt((n - p) / n).
    let mut noise = SplitMix64::new(3);
    let domain = [1.0, 3.0];
    let truth = fit::ChebFit {
        degree: 10,
        domain,
        coeffs: vec![
            1.0, 1.0, 0.2, 0.1, 0.05, 0.04, 0.02, 0.01, 0.005, 0.003, 0.002,
        ],
    };
    let n = 200;
    let x: Vec<f64> = (0..n)
        .map(|i| 1.0 + 2.0 * i as f64 / (n - 1) as f64)
        .collect();
    let sigma = 1e-3;
    let y: Vec<f64> = x
        .iter()
        .map(|&v| truth.eval(v) + sigma * noise.normal())
        .collect();
    let rms = |r: &mut dyn Iterator<Item = f64>| {
        let v: Vec<f64> = r.collect();
        (v.iter().map(|e| e * e).sum::<f64>() / v.len() as f64).sqrt()
    };
    // Monomial normal equations (V^T V) c = V^T y, solved by LU with partial pivoting.
    let normal = |degree: usize| -> Vec<f64> {
        let v = Mat::from_fn(n, degree + 1, |i, k| x[i].powi(k as i32));
        let b = Mat::from_fn(n, 1, |i, _| y[i]);
        let c = (v.transpose() * &v)
            .partial_piv_lu()
            .solve(v.transpose() * &b);
        (0..=degree).map(|k| c[(k, 0)]).collect()
    };
    let ideal = sigma * ((n - 11) as f64 / n as f64).sqrt();

    let cheb = fit::fit(&x, &y, 10).unwrap();
    let r_cheb = rms(&mut x.iter().zip(&y).map(|(&v, &w)| w - cheb.eval(v)));
    assert!(
        (r_cheb / ideal - 1.0).abs() < 0.15,
        "Chebyshev/QR residual {r_cheb:e}"
    );
    let mono = normal(10);
    let r_mono = rms(&mut x.iter().zip(&y).map(|(&v, &w)| w - monomial(&mono, v)));
    assert!(
        r_mono > 1.5 * r_cheb,
        "normal equations residual {r_mono:e} vs Chebyshev/QR {r_cheb:e}"
    );

    // On the MCU (f32): the stored Chebyshev law evaluates the fit to ~1e-6 of full scale;
    // the monomial coefficients in f32 Horner lose far more to cancellation.
    let scale = y.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let law = cheb.law().unwrap();
    let mono32: Vec<f32> = mono.iter().map(|&c| c as f32).collect();
    let (mut e_cheb, mut e_mono) = (0.0f64, 0.0f64);
    for &v in &x {
        e_cheb = e_cheb.max((f64::from(law.eval(v as f32)) - cheb.eval(v)).abs() / scale);
        let h = mono32
            .iter()
            .rev()
            .fold(0.0f32, |acc, &c| acc * v as f32 + c);
        e_mono = e_mono.max((f64::from(h) - monomial(&mono, v)).abs() / scale);
    }
    assert!(e_cheb < 2e-6, "f32 Clenshaw {e_cheb:e}");
    assert!(
        e_mono > 100.0 * e_cheb,
        "f32 monomial {e_mono:e} vs {e_cheb:e}"
    );

    // At degree 4 both solvers agree: the failure is conditioning, not the method's idea.
    let c4 = fit::fit(&x, &y, 4).unwrap();
    let m4 = normal(4);
    for &v in &x {
        assert!((c4.eval(v) - monomial(&m4, v)).abs() < 1e-9 * scale);
    }
    // The design matrices explain it: Chebyshev columns on the data interval are nearly
    // orthogonal, monomials on [1, 3] are not (and the normal equations square that).
    let cond = |m: &Mat<f64>| {
        let s = m.singular_values().unwrap();
        s[0] / s[s.len() - 1]
    };
    let vc = cheb::design(&x, domain, 10);
    let vm = Mat::from_fn(n, 11, |i, k| x[i].powi(k as i32));
    assert!(cond(&vc) < 20.0, "{}", cond(&vc));
    assert!(cond(&vm) > 1e10, "{}", cond(&vm));
}

#[test]
fn recovers_known_motor_constants() {
    let mut noise = SplitMix64::new(11);
    let kt: f64 = 0.025;
    let gear = [12.0, -12.0, 400.0];
    let friction = [0.004, 0.006, 0.9];
    let mut samples = Vec::new();
    for axis in 0..3 {
        for pose in 0..3 {
            let lever = 0.06 + 0.03 * f64::from(pose);
            for step in 1..=10 {
                let k = kt * gear[axis];
                let current = 0.15 * f64::from(step) * k.signum();
                let effort = k * current - friction[axis];
                let mut force = if axis == 2 { effort } else { effort / lever };
                force *= 1.0 + 0.003 * noise.normal();
                samples.push(Sample {
                    axis,
                    insertion_m: lever,
                    current_a: current,
                    force_n: force,
                    line: 0,
                });
            }
        }
    }
    let fits = motor::fit(&samples).unwrap();
    assert_eq!(fits.len(), 3);
    for f in &fits {
        let k = kt * gear[f.axis];
        assert!(
            (f.gain / k - 1.0).abs() < 0.01,
            "axis {}: {} vs {k}",
            f.axis,
            f.gain
        );
        let tol = 0.15 * friction[f.axis];
        assert!(
            (f.friction - friction[f.axis]).abs() < tol,
            "axis {}: friction {} vs {}",
            f.axis,
            f.friction,
            friction[f.axis]
        );
        assert!(f.rms_rel < 0.01);
    }
    // Too few points on an axis is refused with its name.
    let e = motor::fit(&samples[..2]).unwrap_err();
    assert!(e.to_string().starts_with("axis pitch: 2 points"), "{e}");
}

#[test]
fn shipped_brain_data_meets_the_goal_and_matches_the_host_fem() {
    let table = csv::read(
        &manifest(BRAIN),
        &[
            "displacement_m",
            "force_n",
            "radial_m",
            "linear_force_n",
            "linear_radial_m",
        ],
    )
    .unwrap();
    let col = |i| table.numbers(i).unwrap();
    let (d, force, radial, lf, lr) = (col(0), col(1), col(2), col(3), col(4));
    // The linear columns are the host FEM's prediction on the specimen mesh.
    let mesh = fem::mesh::load(&manifest("meshes/brain-specimen.msh")).unwrap();
    let r = specimen::compress(&mesh, Material::new(3.0 * 842.0, 0.45).unwrap()).unwrap();
    for i in 1..d.len() {
        assert!(
            (lf[i] / (r.force_per_m * d[i]) - 1.0).abs() < 1e-5,
            "row {i}"
        );
        assert!(
            (lr[i] / (r.radial_per_m * d[i]) - 1.0).abs() < 1e-5,
            "row {i}"
        );
    }
    // Goal: <= 2 % RMS (full scale) at degree <= 6 for Q, and P too.
    for (x, y, name) in [(&lf, &force, "Q"), (&lr, &radial, "P")] {
        let f = fit::fit(x, y, 6).unwrap();
        let e = f.errors(x, y);
        assert!(e.rms_rel < 0.02, "{name}: {e:?}");
        assert!(f.law().is_ok(), "{name} degree 6 must be increasing");
    }
    // The model is clearly non-linear: a straight line misses by more than 5 %.
    let line = fit::fit(&lf, &force, 1).unwrap();
    assert!(line.errors(&lf, &force).rms_rel > 0.05);
}

/// A box is no compression cylinder: refused, with where its side nodes lie.
#[test]
fn a_box_is_refused_as_a_specimen() {
    let beam = fem::mesh::load(&manifest("meshes/beam.msh")).unwrap();
    let e = specimen::compress(&beam, Material::new(3000.0, 0.45).unwrap())
        .unwrap_err()
        .to_string();
    assert!(e.contains("not a cylinder along z"), "{e}");
    let box_mesh = fem::mesh::structured::box_mesh([0.03, 0.03, 0.013], [6, 6, 3]);
    let e = specimen::compress(&box_mesh, Material::new(3000.0, 0.45).unwrap())
        .unwrap_err()
        .to_string();
    assert!(e.contains("not a cylinder along z"), "{e}");
}

#[test]
fn specimen_fem_matches_the_papers_formulas() {
    // Paper, section 3-4: f^L = s E x / h, d_r^L = nu r x / h. The FEM's top face is the
    // inscribed polygon of the circle, slightly smaller than pi r^2.
    let mesh = fem::mesh::load(&manifest("meshes/brain-specimen.msh")).unwrap();
    let (e, nu) = (2526.0, 0.45);
    let r = specimen::compress(&mesh, Material::new(e, nu).unwrap()).unwrap();
    let s = std::f64::consts::PI * r.radius_m * r.radius_m;
    let force = s * e / r.height_m;
    assert!(
        (r.force_per_m / force - 1.0).abs() < 0.005,
        "{r:?} vs {force}"
    );
    let radial = nu * r.radius_m / r.height_m;
    assert!(
        (r.radial_per_m / radial - 1.0).abs() < 0.002,
        "{r:?} vs {radial}"
    );
    assert!(r.ring_nodes > 20 && r.top_nodes > 50, "{r:?}");
}

#[test]
fn scene_edit_keeps_comments_and_validates() {
    let path = manifest("scenes/liver.toml");
    let text = std::fs::read_to_string(&path).unwrap();
    let coeffs = [0.6, 0.75, 0.2, 0.045, 0.009];
    let q = scene_edit::set_law(&path, &text, Law::Q, &coeffs, [0.0, 0.53], "test").unwrap();
    let both =
        scene_edit::set_law(&path, &q, Law::P, &[1.4e-3, 1.5e-3, 1e-4], [0.0, 2e-3], "t").unwrap();
    for line in text.lines().filter(|l| l.trim_start().starts_with('#')) {
        assert!(both.contains(line), "lost comment {line:?}");
    }
    let s = Scene::parse(&path, &both).unwrap();
    let law = s.law;
    assert_eq!(law.coeffs(), &coeffs.map(|c| c as f32));
    let p = s.display_law.unwrap();
    assert_eq!(p.domain(), [0.0, 2e-3]);
    // A decreasing law is refused before anything is written.
    let e = scene_edit::set_law(&path, &text, Law::Q, &[0.0, -1.0], [0.0, 1.0], "t").unwrap_err();
    assert!(e.to_string().contains("law.coeffs"), "{e}");
    // Motor constants go to [device]; other values stay.
    let m = scene_edit::set_motor(&path, &text, [Some(0.03), None, None], [Some(0.01); 3]).unwrap();
    let s = Scene::parse(&path, &m).unwrap();
    assert_eq!(s.device.torque_constant_nm_per_a, [0.03, 0.025, 0.025]);
    assert_eq!(s.friction_offset, [0.01; 3]);
}

#[test]
fn non_monotone_fit_is_refused() {
    // Degree 2 on the brain curve dips near zero force.
    let table = csv::read(&manifest(BRAIN), &["linear_force_n", "force_n"]).unwrap();
    let (x, y) = (table.numbers(0).unwrap(), table.numbers(1).unwrap());
    let e = fit::fit(&x, &y, 2).unwrap().law().unwrap_err();
    assert!(matches!(e, FitError::NotMonotone { degree: 2, .. }), "{e}");
    let rows = fit::survey(&x, &y, fit::AUTO_DEGREES).unwrap();
    assert!(rows.iter().any(|r| r.degree == 2 && !r.monotone));
    assert_ne!(fit::choose(&rows, 0.02), Some(2));
}

/// `--scene` through a symbolic link: the real scene is updated, the link stays a link, and
/// the scene keeps its mode.
/// `host calibrate tissue` on the shipped brain curve (Q: the linear model's force against the
/// measured one) into `scene`, plots at `plot`, with `extra` arguments.
fn fit_brain_q(scene: &Path, plot: &Path, extra: &[&str]) -> (bool, String, String) {
    let brain = manifest(BRAIN);
    let mut args = vec![
        "calibrate",
        "tissue",
        "--csv",
        brain.to_str().unwrap(),
        "--x",
        "linear_force_n",
        "--y",
        "force_n",
        "--scene",
        scene.to_str().unwrap(),
        "--plot",
        plot.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    run(&args)
}

#[test]
fn calibrating_a_linked_private_scene_keeps_the_link_and_the_mode() {
    use std::os::unix::fs::PermissionsExt;
    let dir = tempfile::tempdir().unwrap();
    let real = dir.path().join("real.toml");
    std::fs::copy(manifest("scenes/liver.toml"), &real).unwrap();
    std::fs::set_permissions(&real, std::fs::Permissions::from_mode(0o600)).unwrap();
    let link = dir.path().join("scene.toml");
    std::os::unix::fs::symlink("real.toml", &link).unwrap();
    let (ok, _, err) = fit_brain_q(&link, &dir.path().join("q"), &[]);
    assert!(ok, "{err}");
    assert!(
        std::fs::symlink_metadata(&link)
            .unwrap()
            .file_type()
            .is_symlink()
    );
    let mode = std::fs::metadata(&real).unwrap().permissions().mode() & 0o777;
    assert_eq!(mode, 0o600);
    // The shipped scene's law is linear (two coefficients); the fitted one has degree >= 4.
    let law = Scene::load(&real).unwrap().law;
    assert!(
        law.coeffs().len() >= 5,
        "the real scene was not calibrated: {law:?}"
    );
}

#[test]
fn cli_fits_writes_scene_json_and_plots() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("scene.toml");
    let original = std::fs::read_to_string(manifest("scenes/liver.toml")).unwrap();
    std::fs::write(&scene, &original).unwrap();
    let stem = dir.path().join("q");
    let (ok, out, err) = fit_brain_q(&scene, &stem, &["--degree", "auto", "--json"]);
    assert!(ok, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let degree = v["degree"].as_u64().unwrap() as usize;
    assert!((4..=6).contains(&degree), "{v}");
    assert_eq!(v["basis"], "chebyshev");
    assert!(v["rms_rel_error"].as_f64().unwrap() < 0.001);
    assert!(v["max_rel_error"].as_f64().unwrap() < 0.005);
    let coeffs: Vec<f64> = serde_json::from_value(v["coefficients"].clone()).unwrap();
    assert_eq!(coeffs.len(), degree + 1);
    let s = Scene::load(&scene).unwrap();
    let want: Vec<f32> = coeffs.iter().map(|&c| c as f32).collect();
    for (a, b) in s.law.coeffs().iter().zip(&want) {
        assert!((a - b).abs() <= 1e-7 * b.abs().max(1e-3), "{a} vs {b}");
    }
    for ext in ["svg", "png"] {
        let p = stem.with_extension(ext);
        assert!(
            std::fs::metadata(&p).unwrap().len() > 5000,
            "{}",
            p.display()
        );
    }

    // Motor: a bench file from known constants, through the CLI, into the scene.
    let bench = dir.path().join("motor.csv");
    let mut text = String::from("axis,insertion_m,current_a,force_n\n");
    for (axis, g, c) in [
        ("pitch", 12.0, 0.005),
        ("yaw", 12.0, 0.005),
        ("insertion", 400.0, 0.5),
    ] {
        for lever in [0.06, 0.1] {
            for i in 1..=5 {
                let current = 0.2 * f64::from(i);
                let effort = 0.03 * g * current - c;
                let force = if axis == "insertion" {
                    effort
                } else {
                    effort / lever
                };
                text.push_str(&format!("{axis},{lever},{current},{force}\n"));
            }
        }
    }
    std::fs::write(&bench, text).unwrap();
    let mstem = dir.path().join("m");
    let (ok, out, err) = run(&[
        "calibrate",
        "motor",
        "--csv",
        bench.to_str().unwrap(),
        "--scene",
        scene.to_str().unwrap(),
        "--plot",
        mstem.to_str().unwrap(),
        "--json",
    ]);
    assert!(ok, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let names: Vec<_> = v["axes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|a| {
            (
                a["axis"].as_str().unwrap(),
                a["axis_index"].as_u64().unwrap(),
            )
        })
        .collect();
    assert_eq!(names, [("pitch", 0), ("yaw", 1), ("insertion", 2)], "{v}");
    let s = Scene::load(&scene).unwrap();
    for k in s.device.torque_constant_nm_per_a {
        assert!((k - 0.03).abs() < 1e-6, "{k}");
    }
    assert!((s.friction_offset[2] - 0.5).abs() < 1e-9);
    assert!(dir.path().join("m-insertion.png").exists());
}

/// Pure noise (y = x + N(0, 1) on [0, 5]) is no tissue law: refused with
/// the RMS error named and the scene left alone; forced with --accept-poor-fit, the law still
/// may not pull the tool in at first contact, and when written the scene says it was forced.
#[test]
fn a_fit_to_noise_or_a_pulling_law_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("scene.toml");
    let original = std::fs::read_to_string(manifest("scenes/liver.toml")).unwrap();
    std::fs::write(&scene, &original).unwrap();
    let mut noise = SplitMix64::new(7);
    let rows: String = (0..200)
        .map(|i| {
            let x = 5.0 * f64::from(i) / 199.0;
            format!("{x},{}\n", x + noise.normal())
        })
        .collect();
    let csv = dir.path().join("noise.csv");
    std::fs::write(&csv, format!("x,y\n{rows}")).unwrap();
    let plot = dir.path().join("p");
    let args = |extra: &[&'static str]| {
        let mut v = vec![
            "calibrate",
            "tissue",
            "--csv",
            csv.to_str().unwrap(),
            "--scene",
            scene.to_str().unwrap(),
            "--plot",
            plot.to_str().unwrap(),
        ];
        v.extend_from_slice(extra);
        v.into_iter().map(String::from).collect::<Vec<_>>()
    };
    let run_with = |extra: &[&'static str]| {
        let a = args(extra);
        run(&a.iter().map(String::as_str).collect::<Vec<_>>())
    };
    let (ok, _, err) = run_with(&[]);
    assert!(!ok);
    assert!(err.contains("more than --max-rms 5.0 %"), "{err}");
    assert_eq!(std::fs::read_to_string(&scene).unwrap(), original);
    // Forced: written with a note, unless the law pulls at zero force.
    let (ok, _, err) = run_with(&["--accept-poor-fit", "--degree", "1"]);
    let text = std::fs::read_to_string(&scene).unwrap();
    if ok {
        assert!(text.contains("written with --accept-poor-fit"), "{text}");
        assert!(haptic::scene::pull_at_first_contact(&Scene::load(&scene).unwrap().law).is_none());
    } else {
        assert!(err.contains("pull the tool"), "{err}");
        assert_eq!(text, original);
    }
}

/// A scene whose law pulls at zero force (Q(0) < 0) is refused, naming the key.
#[test]
fn a_scene_law_that_pulls_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let original = std::fs::read_to_string(manifest("scenes/liver.toml")).unwrap();
    let with = |law: &str| {
        let text = original.replacen("\nkind = \"linear\"\n", &format!("\n{law}\n"), 1);
        assert_ne!(text, original, "the scene's [law] kind line moved");
        let p = dir.path().join("s.toml");
        std::fs::write(&p, text).unwrap();
        Scene::load(&p).map(|_| ()).map_err(|e| e.to_string())
    };
    assert!(with("kind = \"linear\"\noffset_n = 0.0").is_ok());
    let e = with("kind = \"linear\"\noffset_n = -1.0").unwrap_err();
    assert!(e.contains("law.offset_n") && e.contains("pull"), "{e}");
    let e = with("kind = \"chebyshev\"\ncoeffs = [0.5, 1.0]\ndomain_n = [0.0, 5.0]").unwrap_err();
    assert!(e.contains("law.coeffs") && e.contains("Q(0) = -0.5"), "{e}");
}

/// Materials a scene cannot model are refused, naming the key: a locked Poisson's ratio, a
/// Young's modulus outside what the f32 bank represents.
#[test]
fn scene_materials_outside_what_works_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let original = std::fs::read_to_string(manifest("scenes/liver.toml")).unwrap();
    let with = |from: &str, to: &str| {
        let text = original.replacen(from, to, 1);
        assert!(text != original, "{from} not in the scene");
        let p = dir.path().join("s.toml");
        std::fs::write(&p, text).unwrap();
        Scene::load(&p)
            .map(|s| s.warnings())
            .map_err(|e| e.to_string())
    };
    let e = with("poisson = 0.45", "poisson = 0.49999999").unwrap_err();
    assert!(e.contains("material.poisson") && e.contains("lock"), "{e}");
    let w = with("poisson = 0.45", "poisson = 0.49").unwrap();
    assert!(w.len() == 1 && w[0].contains("too stiff"), "{w:?}");
    let shipped = Scene::load(&manifest("scenes/liver.toml")).unwrap();
    assert_eq!(shipped.warnings(), Vec::<String>::new());
    // The average-nodal-pressure element does not lock: no refusal, no warning.
    let anp = "poisson = 0.4999\nelement = \"anp\"";
    assert_eq!(with("poisson = 0.45", anp).unwrap(), Vec::<String>::new());
    let e = with("poisson = 0.45", "poisson = 0.45\nelement = \"q2\"").unwrap_err();
    assert!(e.contains("material.element"), "{e}");
    for young in ["1e300", "1e-300"] {
        let e = with("young_pa = 3000.0", &format!("young_pa = {young}")).unwrap_err();
        assert!(
            e.contains("material.young_pa") && e.contains("Pa is outside"),
            "{e}"
        );
    }
}

#[test]
fn bad_csvs_name_the_line_and_leave_the_scene_alone() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("scene.toml");
    let original = std::fs::read_to_string(manifest("scenes/liver.toml")).unwrap();
    std::fs::write(&scene, &original).unwrap();
    let good: String = (0..12)
        .map(|i| format!("{},{}\n", f64::from(i) * 0.1, f64::from(i) * 0.12))
        .collect();
    for (name, body, want) in [
        (
            "missing.csv",
            format!("x,z\n{good}"),
            "bad.csv:1: missing column \"y\"",
        ),
        (
            "nan.csv",
            format!("x,y\n{good}0.5,abc\n"),
            "bad.csv:14: column \"y\": \"abc\" is not a number",
        ),
        (
            "few.csv",
            "x,y\n0,0\n1,1\n".to_string(),
            "bad.csv: 2 data rows, need at least",
        ),
        (
            "order.csv",
            format!("# note\nx,y\n{good}1.0,2.0\n"),
            "bad.csv:15: column \"x\" must increase",
        ),
        (
            "empty.csv",
            format!("x,y\n{good}1.5,\n"),
            "bad.csv:14: column \"y\": empty value",
        ),
    ] {
        let path = dir.path().join("bad.csv");
        std::fs::write(&path, body).unwrap();
        let (ok, _, err) = run(&[
            "calibrate",
            "tissue",
            "--csv",
            path.to_str().unwrap(),
            "--scene",
            scene.to_str().unwrap(),
            "--plot",
            dir.path().join("p").to_str().unwrap(),
        ]);
        assert!(!ok, "{name} accepted");
        assert!(err.contains(want), "{name}: {err}");
        assert!(!err.contains("panicked"), "{name}: {err}");
    }
    // A degree that gives a decreasing law is refused, and says why.
    let (ok, _, err) = fit_brain_q(&scene, &dir.path().join("p"), &["--degree", "2"]);
    assert!(!ok);
    assert!(err.contains("not increasing near"), "{err}");
    let (ok, _, err) = run(&[
        "calibrate",
        "motor",
        "--csv",
        manifest(BRAIN).to_str().unwrap(),
        "--scene",
        scene.to_str().unwrap(),
    ]);
    assert!(!ok);
    assert!(err.contains("missing column \"axis\""), "{err}");
    assert_eq!(std::fs::read_to_string(&scene).unwrap(), original);
    let leftovers: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().ends_with(".tmp"))
        .collect();
    assert!(leftovers.is_empty());
}

/// The library's tissue fit ([`tissue::run`]) on the displacement column with the specimen's
/// FEM prediction gives the law fitted to the linear-model columns the bench file also holds
/// (computed from the same mesh and material).
#[test]
fn displacement_curve_with_specimen_fem_equals_the_linear_columns() {
    let dir = tempfile::tempdir().unwrap();
    let fit_law = |law: Law, x: &str, y: &str, specimen: Option<tissue::Specimen>| {
        tissue::run(&tissue::Config {
            csv: manifest(BRAIN),
            x: x.into(),
            y: y.into(),
            degree: Some(5),
            law,
            target_rms: fit::DEFAULT_TARGET_RMS,
            max_rms: 0.05,
            accept_poor_fit: false,
            specimen,
            scene: None,
            plot: dir.path().join("p"),
        })
        .unwrap()
    };
    for (law, linear, measured) in [
        (Law::Q, "linear_force_n", "force_n"),
        (Law::P, "linear_radial_m", "radial_m"),
    ] {
        let a = fit_law(law, linear, measured, None);
        let specimen = tissue::Specimen {
            mesh: manifest("meshes/brain-specimen.msh"),
            young_pa: 2526.0,
            poisson: 0.45,
        };
        let b = fit_law(law, "displacement_m", measured, Some(specimen));
        let (ca, cb) = (&a.coefficients, &b.coefficients);
        let scale = ca.iter().fold(0.0f64, |m, c| m.max(c.abs()));
        for (x, y) in ca.iter().zip(cb) {
            assert!((x - y).abs() < 1e-5 * scale, "{law:?}: {ca:?} vs {cb:?}");
        }
    }
}
