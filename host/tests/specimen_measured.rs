//! `host specimen --model linear-p` and `--measured` against independent references: an
//! identity P gives exactly `linear`; a hand-made P moves each marker's radial part as its
//! series (evaluated here by hand) says and keeps the axial part; on the committed synthetic
//! gel-cube data (`scripts/gen_specimen_markers.py`: the `large` model's positions plus a
//! 0.3 mm CT voxel's uniform noise) `large` with the truth parameters leaves the noise and
//! `linear` more at large strain; the plot and bad inputs.

#[path = "support/cli.rs"]
mod cli;

use bank_format::TissueLaw;
use haptic::report::large_strain::{self, STRAINS, noise_rms_mm};
use haptic::specimen::{self, Axis, End, Geometry, Model, Platens, SpecimenConfig};
use haptic::units::Units;
use std::io::Write;
use std::path::{Path, PathBuf};

fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("data")
        .join(name)
}

fn text_file(text: &str) -> tempfile::NamedTempFile {
    let mut f = tempfile::NamedTempFile::new().unwrap();
    f.write_all(text.as_bytes()).unwrap();
    f.flush().unwrap();
    f
}

/// A 20 x 20 x 30 mm box between bonded platens along z, markers spread through it.
fn slab(markers: &Path, model: Model, law: Option<TissueLaw>) -> SpecimenConfig {
    SpecimenConfig {
        geometry: Geometry::Box {
            lo: [0.0; 3],
            hi: [20.0, 20.0, 30.0],
        },
        units: Units::Mm,
        cells: Some(3),
        tolerance: None,
        symmetry: true,
        young_pa: 5000.0,
        poisson: 0.45,
        axis: Axis::Z,
        moving: End::Max,
        platens: Platens::Bonded,
        strains: vec![0.05, 0.2],
        markers: markers.to_path_buf(),
        model,
        display_law: law,
    }
}

const SLAB_MARKERS: &str = "x,y,z\n0,10,15\n20,20,15\n3,17,5\n10,10,15\n10,10,30\n14,2,25\n";

/// P(x) = x as a Chebyshev series on [0, 2 mm] (c0 = 1 mm, c1 = 1 mm): no correction, the
/// markers are `linear`'s (to the round-off of two solves).
#[test]
fn an_identity_p_gives_exactly_linear() {
    let f = text_file(SLAB_MARKERS);
    let identity = TissueLaw::chebyshev(&[0.001, 0.001], [0.0, 0.002]).unwrap();
    let linear = specimen::run(&slab(f.path(), Model::Linear, None)).unwrap();
    let p = specimen::run(&slab(f.path(), Model::LinearP, Some(identity))).unwrap();
    // Two runs solve twice: the parallel sparse factorisation may round the last bits
    // differently between them (seen: 3 ulp), so the runs agree to round-off; the law itself
    // is `None` for an identity P (`DisplayLaw::new`, tested bit for bit in the display).
    assert_eq!(linear.levels.len(), p.levels.len());
    for (a, b) in linear.levels.iter().zip(&p.levels) {
        assert_eq!(a.strain, b.strain);
        for (x, y) in a.markers.iter().zip(&b.markers) {
            for k in 0..3 {
                assert!(
                    (x[k] - y[k]).abs() <= 1e-14 * x[k].abs().max(1.0),
                    "{x:?} vs {y:?}"
                );
            }
        }
    }
}

/// A curved P (three Chebyshev coefficients on [0, 3 mm]): each marker's axial displacement is
/// `linear`'s, its radial one (x-y) is parallel to `linear`'s with amplitude
/// `P(r) - P(0)`, `r` the linear amplitude, the series evaluated here in f64 by hand.
#[test]
fn a_hand_made_p_moves_the_radial_part_as_it_says() {
    let f = text_file(SLAB_MARKERS);
    let points = specimen::markers::read(f.path()).unwrap().points;
    let domain = [0.0, 0.003];
    let c = [2.4e-3, 2.2e-3, 2.0e-4];
    let law = TissueLaw::chebyshev(&c.map(|v| v as f32), domain.map(|v| v as f32)).unwrap();
    let series = |x: f64| {
        let t = (2.0 * x - domain[0] - domain[1]) / (domain[1] - domain[0]);
        c[0] + c[1] * t + c[2] * (2.0 * t * t - 1.0)
    };
    let linear = specimen::run(&slab(f.path(), Model::Linear, None)).unwrap();
    let shown = specimen::run(&slab(f.path(), Model::LinearP, Some(law))).unwrap();
    let mut moved = 0;
    for (l, s) in linear.levels.iter().zip(&shown.levels) {
        for ((p, a), b) in points.iter().zip(&l.markers).zip(&s.markers) {
            // Displacements in metres.
            let u: [f64; 3] = std::array::from_fn(|k| 1e-3 * (a[k] - p[k]));
            let v: [f64; 3] = std::array::from_fn(|k| 1e-3 * (b[k] - p[k]));
            assert!((v[2] - u[2]).abs() < 1e-15, "axial {} vs {}", v[2], u[2]);
            let r = u[0].hypot(u[1]);
            let want = if r > 0.0 {
                (series(r) - series(0.0)).max(0.0)
            } else {
                0.0
            };
            // f32 evaluation of the law: 1e-9 m on amplitudes of a millimetre.
            assert!(
                (v[0].hypot(v[1]) - want).abs() < 1e-9,
                "marker {p:?} strain {}: radial {} m, P says {want} m (linear {r})",
                l.strain,
                v[0].hypot(v[1])
            );
            if r > 1e-6 {
                moved += 1;
                let cross = u[0] * v[1] - u[1] * v[0];
                assert!(cross.abs() < 1e-6 * r * want && u[0] * v[0] + u[1] * v[1] > 0.0);
            }
        }
    }
    // The face-centre marker and the top marker have no radial displacement; the others do.
    assert!(moved >= 6, "{moved}");
}

/// `host specimen` with `args` ([`cli::run`]).
fn host(args: &[&str]) -> (bool, String, String) {
    cli::run(&[&["specimen"][..], args].concat())
}

/// The generator's case (scripts/gen_specimen_markers.py) on the command line.
fn gel_cube_args<'a>(model: &'a str, markers: &'a str, measured: &'a str) -> Vec<&'a str> {
    vec![
        "--box",
        "0,0,0,40,40,40",
        "--units",
        "mm",
        "--cells",
        "4",
        "--young",
        "5000",
        "--poisson",
        "0.49",
        "--axis",
        "z",
        "--moving",
        "max",
        "--platens",
        "bonded",
        "--strain",
        "0.05,0.1,0.15,0.2",
        "--markers",
        markers,
        "--measured",
        measured,
        "--model",
        model,
        "--json",
    ]
}

/// Per-level RMS marker errors (mm) of `model` against the synthetic data, from the CLI's JSON.
fn rms_against_data(model: &str, extra: &[&str]) -> Vec<f64> {
    let markers = data("specimen-gel-cube-markers.csv");
    let measured = data("specimen-gel-cube-measured.csv");
    let mut args = gel_cube_args(model, markers.to_str().unwrap(), measured.to_str().unwrap());
    args.extend_from_slice(extra);
    let (ok, out, err) = host(&args);
    assert!(ok, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let levels = v["measured"]["levels"].as_array().unwrap();
    assert_eq!(levels.len(), 4);
    levels
        .iter()
        .map(|l| {
            let errors = l["errors"].as_array().unwrap();
            assert_eq!(errors.len(), 125);
            // The RMS is that of the per-marker errors, and in metres the same.
            let rms = l["rms"].as_f64().unwrap();
            let mean_sq = errors
                .iter()
                .map(|e| e.as_f64().unwrap().powi(2))
                .sum::<f64>()
                / 125.0;
            assert!((rms - mean_sq.sqrt()).abs() < 1e-12 * rms);
            assert!((l["rms_m"].as_f64().unwrap() - 1e-3 * rms).abs() < 1e-15);
            rms
        })
        .collect()
}

/// `large` with the truth parameters on the generator's mesh recovers the data to its noise:
/// the residual is the noise (uniform +-0.15 mm per coordinate, expected RMS marker error
/// 0.150 mm). Asserted: each level's RMS within 15 % of 0.150 mm. With 125 markers (375
/// coordinates) the sample RMS of that noise has a relative spread of 2.3 % (the mean of
/// e^2 over 375 uniform errors: sqrt(0.8 / 375) / 2), so 15 % is six of those, and a model
/// error of a tenth of a millimetre would exceed it. `linear` matches the data at 5 % strain
/// as well (its model error there, 0.03 mm RMS, adds in quadrature), and at 20 % it is off by
/// more than twice the noise.
#[test]
fn large_recovers_the_synthetic_markers_to_the_noise_and_linear_does_not() {
    let noise = noise_rms_mm();
    assert!((noise - 0.15).abs() < 1e-12);
    let large = rms_against_data("large", &[]);
    let linear = rms_against_data("linear", &[]);
    println!("large {large:?}\nlinear {linear:?}");
    for (s, rms) in STRAINS.iter().zip(&large) {
        assert!(
            (rms / noise - 1.0).abs() < 0.15,
            "large at {s}: RMS {rms} mm against the noise's {noise}"
        );
    }
    assert!((linear[0] / noise - 1.0).abs() < 0.15, "{linear:?}");
    assert!(linear[3] > 2.0 * noise, "{linear:?}");
    // The error grows with the strain.
    assert!(linear.windows(2).all(|w| w[1] > w[0]), "{linear:?}");
}

/// `--model linear-p` with a `--display-law` file on the command line is the library's run
/// with the same P, and a scene holding the same table gives the same markers; without P,
/// with P and another model, and with a scene that has none, it is refused clearly.
#[test]
fn linear_p_on_the_command_line() {
    let f = text_file(SLAB_MARKERS);
    let m = f.path().to_str().unwrap();
    let p = text_file(
        "[display_law]\nkind = \"chebyshev\"\ncoeffs = [2.4e-3, 2.2e-3, 2.0e-4]\n\
         domain_m = [0.0, 0.003]\n",
    );
    let args = |model: &'static str| {
        vec![
            "--box",
            "0,0,0,20,20,30",
            "--units",
            "mm",
            "--cells",
            "3",
            "--young",
            "5000",
            "--poisson",
            "0.45",
            "--axis",
            "z",
            "--moving",
            "max",
            "--platens",
            "bonded",
            "--strain",
            "0.05,0.2",
            "--markers",
            m,
            "--model",
            model,
            "--json",
        ]
    };
    let mut a = args("linear-p");
    a.extend(["--display-law", p.path().to_str().unwrap()]);
    let (ok, out, err) = host(&a);
    assert!(ok, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let law = haptic::specimen::linear_p::read(p.path()).unwrap();
    let lib = specimen::run(&slab(f.path(), Model::LinearP, Some(law))).unwrap();
    // Two solves (the CLI's and this one): equal to round-off, as above.
    for (l, want) in v["levels"].as_array().unwrap().iter().zip(&lib.levels) {
        let got: Vec<[f64; 3]> = serde_json::from_value(l["markers"].clone()).unwrap();
        assert_eq!(got.len(), want.markers.len());
        for (g, w) in got.iter().zip(&want.markers) {
            for k in 0..3 {
                assert!(
                    (g[k] - w[k]).abs() <= 1e-14 * w[k].abs().max(1.0),
                    "{g:?} vs {w:?}"
                );
            }
        }
    }
    // The same P as a scene's [display_law] (the shipped liver scene with the table added).
    let dir = tempfile::tempdir().unwrap();
    let with_p = dir.path().join("liver-with-p.toml");
    let liver = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/liver.toml");
    let table = std::fs::read_to_string(p.path()).unwrap();
    std::fs::write(
        &with_p,
        std::fs::read_to_string(&liver).unwrap() + "\n" + &table,
    )
    .unwrap();
    let mut a = args("linear-p");
    a.extend(["--scene", with_p.to_str().unwrap()]);
    let (ok, from_scene, err) = host(&a);
    assert!(ok, "{err}");
    let from_scene: serde_json::Value = serde_json::from_str(&from_scene).unwrap();
    assert_eq!(from_scene["levels"], v["levels"]);
    let (ok, _, err) = host(&args("linear-p"));
    assert!(
        !ok && err.contains("linear-p needs a display law P"),
        "{err}"
    );
    let mut a = args("linear");
    a.extend(["--display-law", p.path().to_str().unwrap()]);
    let (ok, _, err) = host(&a);
    assert!(!ok && err.contains("linear-p only"), "{err}");
    let mut a = args("linear-p");
    a.extend(["--scene", liver.to_str().unwrap()]);
    let (ok, _, err) = host(&a);
    assert!(
        !ok && err.contains("liver.toml") && err.contains("no [display_law]"),
        "{err}"
    );
}

/// `--plot` writes the slice: the 25 markers of the middle layer y = 20 mm, two arrows each
/// in each of the four panels; a measured file of the wrong length is refused naming it and
/// the count the layout needs.
#[test]
fn the_plot_and_a_measured_file_of_the_wrong_length() {
    let markers = data("specimen-gel-cube-markers.csv");
    let measured = data("specimen-gel-cube-measured.csv");
    let dir = tempfile::tempdir().unwrap();
    let svg = dir.path().join("slice.svg");
    let mut args = gel_cube_args(
        "linear",
        markers.to_str().unwrap(),
        measured.to_str().unwrap(),
    );
    args.extend(["--plot", svg.to_str().unwrap()]);
    let (ok, _, err) = host(&args);
    assert!(ok, "{err}");
    let text = std::fs::read_to_string(&svg).unwrap();
    assert!(text.starts_with("<svg") && text.trim_end().ends_with("</svg>"));
    assert_eq!(text.matches("<circle").count(), 4 * 25);
    assert_eq!(text.matches("<line").count(), 4 * 25 * 2);
    assert!(text.contains("slice x-z through the axis (25 markers)"));

    let short: String = std::fs::read_to_string(&measured)
        .unwrap()
        .lines()
        .take(400)
        .map(|l| format!("{l}\n"))
        .collect();
    let f = text_file(&short);
    let (ok, _, err) = host(&gel_cube_args(
        "linear",
        markers.to_str().unwrap(),
        f.path().to_str().unwrap(),
    ));
    assert!(
        !ok && err.contains(f.path().to_str().unwrap())
            && err.contains("need 125 markers x 4 levels = 500"),
        "{err}"
    );
}

/// The report's section on the same data: P fitted to the separate slab, the three models'
/// RMS per strain; `large` recovers the noise at every strain, `linear-p` is closer to the
/// data than `linear` at 20 %.
#[test]
fn the_report_section_measures_the_three_models() {
    let (models, p_rms) = large_strain::measure(&|_| {}).unwrap();
    let (knob, cases) = large_strain::section(&models, p_rms);
    for m in &models {
        println!(
            "{}: {:?}",
            m.name,
            m.comparison
                .levels
                .iter()
                .map(|l| l.rms)
                .collect::<Vec<_>>()
        );
    }
    println!("P fit RMS {p_rms}; {}", knob.finding);
    assert_eq!(knob.series.len(), 4);
    assert_eq!(cases.len(), 12);
    let rms20 = |name: &str| {
        models
            .iter()
            .find(|m| m.name == name)
            .unwrap()
            .comparison
            .levels[3]
            .rms
    };
    assert!(rms20("linear-p") < rms20("linear"));
    assert!(
        cases
            .iter()
            .filter(|c| c.case.starts_with("large "))
            .all(|c| c.verdict == haptic::report::Verdict::MatchesReference)
    );
}
