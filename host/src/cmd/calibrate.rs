//! `host calibrate …`: bench calibration (issue 8). `tissue` fits the tissue law Q or the
//! display law P to a compression curve, `motor` the torque constants to load-cell
//! measurements, `gravity` the feed-forward for the instrument's weight to held poses,
//! `specimen` computes the linear FEM prediction for a compression specimen
//! (the x of Q and P). Results go into a scene file (comments kept, written atomically) and
//! plots (SVG and PNG).

use anyhow::{Context, Result, bail};
use fem::elasticity::Material;
use haptic::calibrate::fit::{self, ChebFit, DegreeRow};
use haptic::calibrate::motor::{self, AXES, AxisFit};
use haptic::calibrate::plot::{self, PlotSpec};
use haptic::calibrate::scene_edit::{self, Law};
use haptic::calibrate::{csv, gravity, specimen};
use haptic::fsio::write_atomic;
use haptic::scene::Scene;
use std::path::{Path, PathBuf};

/// Calibration commands.
#[derive(clap::Subcommand, Debug)]
pub enum Calibrate {
    /// Fit the tissue law Q (linear-model force -> measured force) or the display law P
    /// (linear radial displacement -> measured radial displacement) to bench data.
    Tissue(TissueArgs),
    /// Fit transmission x torque constant and a friction offset per axis to commanded current
    /// vs load-cell force at known poses.
    Motor(MotorArgs),
    /// Fit the gravity compensation of the instrument's own weight to the currents that hold
    /// it still at several poses (device in constant-current mode) and write it into the scene.
    Gravity(GravityArgs),
    /// The linear FEM prediction for a cylindrical compression specimen: force and radial
    /// displacement per metre of compression, as JSON.
    Specimen(SpecimenArgs),
    /// Fit the viscoelastic relaxation (Fung's QLV: Prony terms of G(t), G(0) = 1, with the
    /// instantaneous elastic law of the displacement) to a ramp-and-hold test, ramp and hold
    /// together, and write it into the scene's [viscoelastic] table.
    Relaxation(RelaxationArgs),
}

/// Arguments of `host calibrate relaxation`.
#[derive(clap::Args, Debug)]
pub struct RelaxationArgs {
    /// Bench CSV: a header row, then one row per sample (times increasing); `#` lines are
    /// comments. Repeat it for several tests (e.g. ramps at several speeds): one G(t) and one
    /// instantaneous law are fitted to all of them together, each test's own ramp in its
    /// hereditary integral, and the rate dependence the law cannot explain is reported.
    #[arg(long, required = true)]
    csv: Vec<PathBuf>,
    /// Column of the time, s.
    #[arg(long, default_value = "t_s")]
    t: String,
    /// Column of the displacement (indentation or compression, positive into the tissue), m.
    #[arg(long, default_value = "x_m")]
    x: String,
    /// Column of the force (positive pushing back), N.
    #[arg(long, default_value = "force_n")]
    f: String,
    /// Scene file to write [viscoelastic] into (comments and layout kept, written
    /// atomically); without it nothing is written.
    #[arg(long)]
    scene: Option<PathBuf>,
    /// Plot path without extension: writes <PLOT>.svg and <PLOT>.png (force against time, data
    /// and fit, residuals below).
    #[arg(long, default_value = "calibration-relaxation")]
    plot: PathBuf,
    /// Print one JSON object (g_inf, g, tau_s, the elastic law, residuals, per test in
    /// `tests`, `warnings`) instead of the table.
    #[arg(long)]
    json: bool,
}

/// Arguments of `host calibrate tissue`.
#[derive(clap::Args, Debug)]
pub struct TissueArgs {
    /// Bench CSV: a header row, then one row per point; `#` lines are comments.
    #[arg(long)]
    csv: PathBuf,
    /// Column of the linear model's value (x of the law), or of the displacement with
    /// --specimen; must increase from row to row.
    #[arg(long, default_value = "x")]
    x: String,
    /// Column of the measured value (y of the law).
    #[arg(long, default_value = "y")]
    y: String,
    /// Polynomial degree (1 to 15), or `auto`: the smallest increasing degree in 1..=10 whose
    /// 10-fold cross-validated RMS error is within 5 % of the best or under --target-rms.
    #[arg(long, default_value = "auto")]
    degree: String,
    /// Which law: Q (force, scene table [law]) or P (radial displacement, [display_law]).
    #[arg(long, value_enum, default_value_t = LawArg::Q, ignore_case = true)]
    law: LawArg,
    /// `auto` is content with this cross-validated RMS error relative to full scale.
    #[arg(long, default_value_t = fit::DEFAULT_TARGET_RMS)]
    target_rms: f64,
    /// Refuse a fit whose RMS error exceeds this fraction of full scale: 5 % is several times
    /// what a load cell and a displacement stage leave (the shipped brain data fits to 0.03 %),
    /// so a fit worse than that says the data is not a law of this kind.
    #[arg(long, default_value_t = 0.05)]
    max_rms: f64,
    /// Write a fit beyond --max-rms anyway (the scene's comment says so).
    #[arg(long)]
    accept_poor_fit: bool,
    /// For a (displacement, measured) bench curve: the specimen's cylinder mesh (axis z, m).
    /// The --x column is then the platen displacement, and the law's x is the linear FEM's
    /// prediction for it (`calibrate specimen`): top force for Q, mid-height radial
    /// displacement for P.
    #[arg(long, requires_all = ["young", "poisson"])]
    specimen: Option<PathBuf>,
    /// Young's modulus of the linear model for --specimen, Pa.
    #[arg(long, requires = "specimen")]
    young: Option<f64>,
    /// Poisson's ratio of the linear model for --specimen.
    #[arg(long, requires = "specimen")]
    poisson: Option<f64>,
    /// Scene file to write the law into (comments and layout kept, written atomically).
    #[arg(long)]
    scene: Option<PathBuf>,
    /// Plot path without extension: writes <PLOT>.svg and <PLOT>.png.
    #[arg(long, default_value = "calibration")]
    plot: PathBuf,
    /// Print one JSON object instead of the tables.
    #[arg(long)]
    json: bool,
}

/// `--law` of `host calibrate tissue`: which law a fit goes to ([`Law`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum LawArg {
    /// Tissue force law Q: table `[law]`, domain key `domain_n` (N).
    Q,
    /// Display (radial displacement) law P: table `[display_law]`, domain key `domain_m` (m).
    P,
}

impl From<LawArg> for Law {
    fn from(a: LawArg) -> Law {
        match a {
            LawArg::Q => Law::Q,
            LawArg::P => Law::P,
        }
    }
}

/// Arguments of `host calibrate motor`.
#[derive(clap::Args, Debug)]
pub struct MotorArgs {
    /// Bench CSV with columns axis (pitch|yaw|insertion or 0|1|2), insertion_m (tip distance
    /// from the fulcrum: the lever of pitch and yaw), current_a, force_n (load cell, N).
    #[arg(long)]
    csv: PathBuf,
    /// Scene file: its gear_ratio turns the fitted gains into torque constants, which are
    /// written back with the friction offsets (comments kept, written atomically).
    #[arg(long)]
    scene: Option<PathBuf>,
    /// Plot path without extension: writes <PLOT>-<axis>.svg and .png per fitted axis.
    #[arg(long, default_value = "calibration-motor")]
    plot: PathBuf,
    /// Print one JSON object instead of the table.
    #[arg(long)]
    json: bool,
}

/// Arguments of `host calibrate gravity`.
#[derive(clap::Args, Debug)]
pub struct GravityArgs {
    /// CSV with columns pitch_rad, yaw_rad, insertion_m, current_pitch_a, current_yaw_a,
    /// current_insertion_a: one held pose per row, `#` lines are comments.
    #[arg(long)]
    csv: PathBuf,
    /// Scene file: its motor calibration (gear_ratio, torque constants) turns the currents into
    /// joint efforts; the coefficients are written into its [gravity] table (comments kept,
    /// written atomically) unless --out is given.
    #[arg(long)]
    scene: PathBuf,
    /// Write the calibrated scene here instead of editing --scene in place.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Print one JSON object instead of the table.
    #[arg(long)]
    json: bool,
}

/// Arguments of `host calibrate specimen`.
#[derive(clap::Args, Debug)]
pub struct SpecimenArgs {
    /// Cylinder mesh of the specimen, axis along z, in m.
    #[arg(long)]
    mesh: PathBuf,
    /// Young's modulus of the linear model, Pa.
    #[arg(long)]
    young: f64,
    /// Poisson's ratio of the linear model.
    #[arg(long)]
    poisson: f64,
}

/// Runs a calibration command.
pub fn run(cmd: Calibrate) -> Result<()> {
    match cmd {
        Calibrate::Tissue(a) => tissue(a),
        Calibrate::Motor(a) => motor_cmd(a),
        Calibrate::Gravity(a) => gravity_cmd(a),
        Calibrate::Specimen(a) => specimen_cmd(a),
        Calibrate::Relaxation(a) => relaxation_cmd(a),
    }
}

fn parse_degree(s: &str) -> Result<Option<usize>> {
    if s.eq_ignore_ascii_case("auto") {
        return Ok(None);
    }
    match s.parse::<usize>() {
        Ok(d) if (1..=fit::MAX_DEGREE).contains(&d) => Ok(Some(d)),
        _ => bail!(
            "--degree {s:?}: use an integer in 1..={} or \"auto\"",
            fit::MAX_DEGREE
        ),
    }
}

#[derive(serde::Serialize)]
struct RelaxationReport<'a> {
    g_inf: f64,
    g: &'a [f64],
    tau_s: &'a [f64],
    /// Linearised standard errors of g and tau_s.
    g_se: &'a [f64],
    tau_s_se: &'a [f64],
    /// `Q_e(x) = sum_j c_j (x / x_max)^j`, j = 1.., N.
    elastic_coeffs_n: &'a [f64],
    x_max_m: f64,
    rms_n: f64,
    elastic_only_rms_n: f64,
    noise_n: f64,
    survey: Vec<[f64; 2]>,
    /// Rows of all tests.
    rows: usize,
    tests: Vec<RelaxationTestReport<'a>>,
    /// Slope of the relative peak-force error per decade of ramp speed (null for one speed).
    peak_error_per_decade: Option<f64>,
    warnings: &'a [String],
    scene: Option<&'a Path>,
    plot: [PathBuf; 2],
}

/// One test of `RelaxationReport`.
#[derive(serde::Serialize)]
struct RelaxationTestReport<'a> {
    csv: &'a Path,
    rows: usize,
    ramp_s: f64,
    ramp_speed_m_s: f64,
    rms_n: f64,
    noise_n: f64,
    rms_over_noise: f64,
    unexplained_n: f64,
    peak_force_n: f64,
    peak_error_n: f64,
    peak_error_se_n: f64,
}

fn relaxation_cmd(a: RelaxationArgs) -> Result<()> {
    use haptic::calibrate::relaxation::{self, Test};
    let mut tests = Vec::with_capacity(a.csv.len());
    for path in &a.csv {
        let table = csv::read(path, &[&a.t, &a.x, &a.f])?;
        table.require_rows(20, "a ramp and a hold")?;
        let t = table.numbers(0)?;
        table.require_increasing(0, &t)?;
        tests.push(Test {
            name: path.display().to_string(),
            t,
            x: table.numbers(1)?,
            f: table.numbers(2)?,
        });
    }
    let names = a
        .csv
        .iter()
        .map(|p| p.display().to_string())
        .collect::<Vec<_>>()
        .join(", ");
    let fit = relaxation::fit_tests(&tests)
        .with_context(|| format!("{names}: fitting the relaxation; nothing was written"))?;
    let residuals: Vec<(f64, f64)> = tests
        .iter()
        .zip(&fit.tests)
        .flat_map(|(test, tf)| {
            test.t
                .iter()
                .zip(test.f.iter().zip(&tf.model))
                .map(|(&ti, (&fi, &mi))| (ti, 1e3 * (fi - mi)))
        })
        .collect();
    let rounded = |v: &[f64]| {
        v.iter()
            .map(|v| (v * 1e3).round() / 1e3)
            .collect::<Vec<_>>()
    };
    let law = format!(
        "g = {:?}, tau = {:?} s",
        rounded(&fit.g),
        rounded(&fit.tau_s)
    );
    let mut curves: Vec<(String, Vec<(f64, f64)>)> = tests
        .iter()
        .zip(&fit.tests)
        .map(|(test, tf)| {
            let name = if tests.len() == 1 {
                format!("QLV fit: {law}")
            } else {
                format!("joint QLV fit, ramp {:.3} s", tf.ramp_s)
            };
            (
                name,
                test.t
                    .iter()
                    .copied()
                    .zip(tf.model.iter().copied())
                    .collect(),
            )
        })
        .collect();
    if let [test] = &tests[..] {
        curves.push((
            "instantaneous elastic response Q_e(x(t))".into(),
            test.t
                .iter()
                .zip(&test.x)
                .map(|(&ti, &xi)| (ti, fit.elastic_at(xi)))
                .collect(),
        ));
    }
    // One file by its name; several by their count (the legend names their ramps).
    let file_names = match &a.csv[..] {
        [one] => one
            .file_name()
            .map_or(String::new(), |n| n.to_string_lossy().into_owned()),
        several => format!("{} tests", several.len()),
    };
    let spec = PlotSpec {
        title: format!(
            "QLV relaxation: {file_names} (g_inf {:.3}, {} term(s), RMS {:.3e} N)",
            fit.g_inf,
            fit.g.len(),
            fit.rms
        ),
        x_label: format!("time ({}), s", a.t),
        y_label: format!("force ({}), N", a.f),
        data: (
            if tests.len() == 1 {
                "bench data".into()
            } else {
                format!("bench data, {} tests ({law})", tests.len())
            },
            tests
                .iter()
                .flat_map(|test| test.t.iter().copied().zip(test.f.iter().copied()))
                .collect(),
        ),
        curves,
        residual_label: "residual, mN".into(),
        residuals,
    };
    let plots = plot::write(&a.plot, &spec)?;
    if let Some(scene) = &a.scene {
        let source = format!(
            "{names}, columns {}, {}, {}: g_inf {:.4}, RMS residual {:.3e} N (noise {:.3e} N){}",
            a.t,
            a.x,
            a.f,
            fit.g_inf,
            fit.rms,
            fit.noise,
            if fit.warnings.is_empty() {
                String::new()
            } else {
                "; WARNING: rate dependence not explained (see the calibration's output)".into()
            }
        );
        write_scene(scene, |text| {
            Ok(scene_edit::set_viscoelastic(
                scene, text, &fit.g, &fit.tau_s, &source,
            )?)
        })?;
    }
    for w in &fit.warnings {
        eprintln!("warning: {w}");
    }
    if a.json {
        let report = RelaxationReport {
            g_inf: fit.g_inf,
            g: &fit.g,
            tau_s: &fit.tau_s,
            g_se: &fit.g_se,
            tau_s_se: &fit.tau_se,
            elastic_coeffs_n: &fit.elastic,
            x_max_m: fit.x_max,
            rms_n: fit.rms,
            elastic_only_rms_n: fit.elastic_rms,
            noise_n: fit.noise,
            survey: fit.survey.iter().map(|&(n, r)| [n as f64, r]).collect(),
            rows: tests.iter().map(|t| t.t.len()).sum(),
            tests: a
                .csv
                .iter()
                .zip(&fit.tests)
                .map(|(csv, tf)| RelaxationTestReport {
                    csv,
                    rows: tf.rows,
                    ramp_s: tf.ramp_s,
                    ramp_speed_m_s: tf.rate_m_s,
                    rms_n: tf.rms,
                    noise_n: tf.noise,
                    rms_over_noise: tf.rms_over_noise(),
                    unexplained_n: tf.unexplained(),
                    peak_force_n: tf.peak_force,
                    peak_error_n: tf.peak_error,
                    peak_error_se_n: tf.peak_error_se,
                })
                .collect(),
            peak_error_per_decade: fit.peak_error_per_decade,
            warnings: &fit.warnings,
            scene: a.scene.as_deref(),
            plot: plots,
        };
        println!("{}", serde_json::to_string(&report)?);
        return Ok(());
    }
    println!("terms  rms residual (N)");
    for (n, r) in &fit.survey {
        let mark = if *n == fit.g.len() { "  <- chosen" } else { "" };
        println!("{n:>5}  {r:.4e}{mark}");
    }
    println!(
        "elastic only (G = 1): rms {:.4e} N; noise estimate {:.4e} N",
        fit.elastic_rms, fit.noise
    );
    println!("g_inf = {:.5}", fit.g_inf);
    for (k, (g, tau)) in fit.g.iter().zip(&fit.tau_s).enumerate() {
        println!(
            "term {k}: g = {g:.5} +- {:.1e}, tau = {tau:.5} +- {:.1e} s (standard errors)",
            fit.g_se[k], fit.tau_se[k]
        );
    }
    println!(
        "instantaneous elastic law: Q_e(x) = sum_j c_j (x / {:.4e} m)^j, c = {:?} N",
        fit.x_max, fit.elastic
    );
    println!("test  ramp (s)  speed (m/s)  rms (N)    rms/noise  peak error (N, %, std errors)");
    for (i, tf) in fit.tests.iter().enumerate() {
        println!(
            "{i:>4}  {:>8.3}  {:>11.3e}  {:.3e}  {:>9.2}  {:+.3e} ({:+.2} %, {:+.1})  {}",
            tf.ramp_s,
            tf.rate_m_s,
            tf.rms,
            tf.rms_over_noise(),
            tf.peak_error,
            100.0 * tf.peak_error / tf.peak_force,
            tf.peak_error / tf.peak_error_se,
            tf.name
        );
    }
    if let Some(s) = fit.peak_error_per_decade {
        println!(
            "peak-force error against ramp speed: {:+.3} % per decade",
            100.0 * s
        );
    }
    println!("plot: {} and {}", plots[0].display(), plots[1].display());
    if let Some(scene) = &a.scene {
        println!("wrote [viscoelastic] into {}", scene.display());
    }
    Ok(())
}

fn write_scene(path: &Path, edit: impl FnOnce(&str) -> Result<String>) -> Result<()> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("{}: cannot read the scene", path.display()))?;
    let new = edit(&text)?;
    // The scene is edited in place on purpose (through a link to it, with its mode kept).
    write_atomic(path, new.as_bytes(), &[]).with_context(|| format!("writing {}", path.display()))
}

#[derive(serde::Serialize)]
struct TissueReport<'a> {
    law: &'static str,
    degree: usize,
    basis: &'static str,
    domain: [f64; 2],
    coefficients: &'a [f64],
    rms_rel_error: f64,
    max_rel_error: f64,
    points: usize,
    survey: &'a [DegreeRow],
    scene: Option<&'a Path>,
    plot: [PathBuf; 2],
}

fn tissue(a: TissueArgs) -> Result<()> {
    let which_law = Law::from(a.law);
    let degree = parse_degree(&a.degree)?;
    if !(a.target_rms.is_finite() && a.target_rms >= 0.0) {
        bail!("--target-rms must be >= 0, got {}", a.target_rms);
    }
    let table = csv::read(&a.csv, &[&a.x, &a.y])?;
    let need = degree.map_or(fit::AUTO_DEGREES.start() + 2, |d| d + 2);
    table.require_rows(need, "a fit needs more points than coefficients")?;
    let (mut x, y) = (table.numbers(0)?, table.numbers(1)?);
    table.require_increasing(0, &x)?;
    let mut x_name = a.x.clone();
    if let (Some(mesh), Some(young), Some(poisson)) = (&a.specimen, a.young, a.poisson) {
        let r = specimen::compress(&fem::mesh::load(mesh)?, Material::new(young, poisson)?)
            .with_context(|| format!("{}: specimen compression", mesh.display()))?;
        let per_m = match which_law {
            Law::Q => r.force_per_m,
            Law::P => r.radial_per_m,
        };
        x.iter_mut().for_each(|v| *v *= per_m);
        x_name = format!("FEM x {}", a.x);
    }
    if !(a.max_rms.is_finite() && a.max_rms > 0.0) {
        bail!("--max-rms must be > 0, got {}", a.max_rms);
    }
    let (f, law, survey) = fit::fit_law(&x, &y, degree, a.target_rms)
        .with_context(|| format!("{}: fitting {:?}", a.csv.display(), which_law))?;
    let errors = f.errors(&x, &y);
    let poor = errors.rms_rel > a.max_rms;
    if poor && !a.accept_poor_fit {
        bail!(
            "{}: the degree-{} fit leaves an RMS error of {:.1} % of full scale, more than \
             --max-rms {:.1} %: the data does not follow a smooth increasing law (noise, a \
             wrong column, mixed runs?); nothing was written. Pass --accept-poor-fit to write \
             it anyway",
            a.csv.display(),
            f.degree,
            100.0 * errors.rms_rel,
            100.0 * a.max_rms
        );
    }
    if matches!(which_law, Law::Q)
        && let Some(q0) = haptic::scene::pull_at_first_contact(&law)
    {
        bail!(
            "{}: the fitted law gives Q(0) = {q0:.4} N, below -{:.1} % of its largest force: \
             rendered, it would pull the tool into the tissue at first contact; nothing was \
             written (check that the data starts at zero force, or fit a lower --degree)",
            a.csv.display(),
            100.0 * haptic::scene::PULL_TOLERANCE
        );
    }
    let name = match which_law {
        Law::Q => "Q",
        Law::P => "P",
    };

    let residuals: Vec<f64> = x.iter().zip(&y).map(|(&xi, &yi)| yi - f.eval(xi)).collect();
    let scale = y.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let [lo, hi] = f.domain;
    let curve: Vec<(f64, f64)> = (0..=400)
        .map(|i| lo + (hi - lo) * 1.08 * f64::from(i) / 400.0)
        .map(|v| (v, f64::from(law.eval(v as f32))))
        .collect();
    let (unit, what) = match which_law {
        Law::Q => ("N", "force"),
        Law::P => ("m", "radial displacement"),
    };
    let spec = PlotSpec {
        title: format!(
            "{name}: {} (degree {}, RMS {:.2} %, max {:.2} % of full scale)",
            a.csv
                .file_name()
                .map_or(String::new(), |n| n.to_string_lossy().into_owned()),
            f.degree,
            100.0 * errors.rms_rel,
            100.0 * errors.max_rel
        ),
        x_label: format!("linear model {what} ({x_name}), {unit}"),
        y_label: format!("measured {what} ({}), {unit}", a.y),
        data: (
            "bench data".into(),
            x.iter().copied().zip(y.iter().copied()).collect(),
        ),
        curves: vec![
            (
                format!(
                    "{name}: Chebyshev degree {}, f32 Clenshaw as on the MCU (linear past the domain)",
                    f.degree
                ),
                curve,
            ),
            (
                "linear model (y = x)".into(),
                vec![(lo, lo), (hi * 1.08, hi * 1.08)],
            ),
        ],
        residual_label: "residual, % of full scale".into(),
        residuals: x
            .iter()
            .zip(&residuals)
            .map(|(&xi, &r)| (xi, 100.0 * r / scale))
            .collect(),
    };
    let plots = plot::write(&a.plot, &spec)?;

    if let Some(scene) = &a.scene {
        let source = format!(
            "{}, columns {} -> {}, degree {}, RMS {:.3} % of full scale{}",
            a.csv.display(),
            a.x,
            a.y,
            f.degree,
            100.0 * errors.rms_rel,
            if poor {
                format!(
                    "; ABOVE --max-rms {:.1} %, written with --accept-poor-fit",
                    100.0 * a.max_rms
                )
            } else {
                String::new()
            }
        );
        write_scene(scene, |text| {
            Ok(scene_edit::set_law(
                scene, text, which_law, &f.coeffs, f.domain, &source,
            )?)
        })?;
    }

    if a.json {
        let report = TissueReport {
            law: name,
            degree: f.degree,
            basis: "chebyshev",
            domain: f.domain,
            coefficients: &f.coeffs,
            rms_rel_error: errors.rms_rel,
            max_rel_error: errors.max_rel,
            points: x.len(),
            survey: &survey,
            scene: a.scene.as_deref(),
            plot: plots,
        };
        println!("{}", serde_json::to_string(&report)?);
        return Ok(());
    }
    print_tissue(&a, name, &f, (&x, &y), &survey, &plots);
    Ok(())
}

/// The degree survey, the residual table and the result, for people.
fn print_tissue(
    a: &TissueArgs,
    name: &str,
    f: &ChebFit,
    (x, y): (&[f64], &[f64]),
    survey: &[DegreeRow],
    plots: &[PathBuf; 2],
) {
    let residuals: Vec<f64> = x.iter().zip(y).map(|(&xi, &yi)| yi - f.eval(xi)).collect();
    let scale = y.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    if !survey.is_empty() {
        println!(
            "degree survey (errors relative to full scale {scale:.6}; CV = {}-fold cross-validation):",
            fit::FOLDS
        );
        println!(
            "{:>6} {:>10} {:>10} {:>10} {:>9}",
            "degree", "rms %", "max %", "cv rms %", "monotone"
        );
        for r in survey {
            println!(
                "{:>6} {:>10.3e} {:>10.3e} {:>10.3e} {:>9}{}",
                r.degree,
                100.0 * r.rms_rel,
                100.0 * r.max_rel,
                100.0 * r.cv_rms_rel,
                if r.monotone { "yes" } else { "no" },
                if r.degree == f.degree {
                    "  <- chosen"
                } else {
                    ""
                }
            );
        }
        println!();
    }
    println!("residuals of {name} (degree {}):", f.degree);
    println!(
        "{:>5} {:>14} {:>14} {:>14} {:>14} {:>8}",
        "row", a.x, a.y, "fit", "residual", "% fs"
    );
    for (i, (&xi, &yi)) in x.iter().zip(y).enumerate() {
        println!(
            "{:>5} {:>14.6e} {:>14.6e} {:>14.6e} {:>14.3e} {:>8.3}",
            i + 1,
            xi,
            yi,
            f.eval(xi),
            residuals[i],
            100.0 * residuals[i] / scale
        );
    }
    let e = fit::relative_errors(&residuals, y);
    println!();
    println!(
        "{name}: Chebyshev degree {} on [{:.6e}, {:.6e}]: RMS {:.3} %, max {:.3} % of full scale",
        f.degree,
        f.domain[0],
        f.domain[1],
        100.0 * e.rms_rel,
        100.0 * e.max_rel
    );
    println!("coefficients: {:?}", f.coeffs);
    if let Some(s) = &a.scene {
        println!("wrote [{}] of {}", Law::from(a.law).table(), s.display());
    }
    println!("plots: {} {}", plots[0].display(), plots[1].display());
}

#[derive(serde::Serialize)]
struct MotorRow<'a> {
    axis: &'static str,
    #[serde(flatten)]
    fit: &'a AxisFit,
    torque_constant_nm_per_a: Option<f64>,
}

fn motor_cmd(a: MotorArgs) -> Result<()> {
    let table = csv::read(&a.csv, &motor::COLUMNS)?;
    table.require_rows(motor::MIN_POINTS, "three per fitted axis")?;
    let samples = motor::samples(&table)?;
    let fits = motor::fit(&samples).with_context(|| a.csv.display().to_string())?;
    let scene = a.scene.as_deref().map(Scene::load).transpose()?;
    let mut kt = [None; 3];
    let mut friction = [None; 3];
    for f in &fits {
        friction[f.axis] = Some(f.friction);
        if let Some(s) = &scene {
            let g = f64::from(s.device.transmission[f.axis]);
            let k = f.gain / g;
            if !(k > 0.0 && k.is_finite()) {
                bail!(
                    "{}: axis {}: fitted gain {:.6} has the opposite sign of gear_ratio {g}: \
                     check the load cell's direction or the motor wiring",
                    a.csv.display(),
                    AXES[f.axis],
                    f.gain
                );
            }
            kt[f.axis] = Some(k);
        }
    }
    let mut plots = Vec::new();
    for f in &fits {
        let name = AXES[f.axis];
        let unit = if f.axis == 2 { "N" } else { "N m" };
        let pts: Vec<(f64, f64)> = samples
            .iter()
            .filter(|s| s.axis == f.axis)
            .map(|s| (s.current_a, s.effort()))
            .collect();
        let (lo, hi) = pts
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), p| {
                (l.min(p.0), h.max(p.0))
            });
        let line = |i: f64| f.gain * i - f.friction;
        let mut stem = a.plot.clone().into_os_string();
        stem.push(format!("-{name}"));
        let spec = PlotSpec {
            title: format!(
                "{name}: k = {:.5} {unit}/A, friction {:.4} {unit}, RMS {:.2} %",
                f.gain,
                f.friction,
                100.0 * f.rms_rel
            ),
            x_label: "commanded current, A".into(),
            y_label: format!("joint effort from the load cell, {unit}"),
            data: ("bench data".into(), pts),
            curves: vec![(
                "fit: k i - friction".into(),
                vec![(lo, line(lo)), (hi, line(hi))],
            )],
            residual_label: format!("residual, {unit}"),
            residuals: f.residuals.clone(),
        };
        plots.extend(plot::write(Path::new(&stem), &spec)?);
    }
    if let Some(path) = &a.scene {
        write_scene(path, |text| {
            Ok(scene_edit::set_motor(path, text, kt, friction)?)
        })?;
    }
    let rows: Vec<MotorRow> = fits
        .iter()
        .map(|f| MotorRow {
            axis: AXES[f.axis],
            fit: f,
            torque_constant_nm_per_a: kt[f.axis],
        })
        .collect();
    if a.json {
        println!(
            "{}",
            serde_json::json!({ "axes": rows, "scene": a.scene, "plots": plots })
        );
        return Ok(());
    }
    println!(
        "{:>10} {:>6} {:>14} {:>14} {:>12} {:>12} {:>8}",
        "axis", "points", "k (/A)", "Kt (N m/A)", "friction", "rms", "rms %"
    );
    for r in &rows {
        println!(
            "{:>10} {:>6} {:>14.6} {:>14} {:>12.5} {:>12.3e} {:>8.3}",
            r.axis,
            r.fit.points,
            r.fit.gain,
            r.torque_constant_nm_per_a
                .map_or("-".into(), |k| format!("{k:.6}")),
            r.fit.friction,
            r.fit.rms,
            100.0 * r.fit.rms_rel
        );
    }
    println!("(pitch, yaw: k in N m/A, friction in N m; insertion: N/A and N)");
    if let Some(s) = &a.scene {
        println!(
            "wrote [device] torque_constant_nm_per_a and friction_offset of {}",
            s.display()
        );
    }
    for p in &plots {
        println!("plot: {}", p.display());
    }
    Ok(())
}

fn gravity_cmd(a: GravityArgs) -> Result<()> {
    let scene = Scene::load(&a.scene)?;
    let table = csv::read(&a.csv, &gravity::COLUMNS)?;
    let poses = gravity::poses(&table, &scene.device)?;
    let f = gravity::fit(&poses).with_context(|| a.csv.display().to_string())?;
    let source = format!(
        "{}, {} poses, residual RMS {:.3e} N m (worst {:.3e}), insertion {:.3e} N (worst {:.3e})",
        a.csv.display(),
        f.poses,
        f.rms_nm,
        f.worst_nm.0.abs(),
        f.rms_n,
        f.worst_n.0.abs()
    );
    let text = std::fs::read_to_string(&a.scene)
        .with_context(|| format!("{}: cannot read the scene", a.scene.display()))?;
    let out = a.out.as_deref().unwrap_or(&a.scene);
    let new = scene_edit::set_gravity(out, &text, &f.coeffs, &source)?;
    write_atomic(out, new.as_bytes(), &[]).with_context(|| format!("writing {}", out.display()))?;
    if a.json {
        println!(
            "{}",
            serde_json::json!({ "fit": f, "names": gravity::NAMES, "scene": out })
        );
        return Ok(());
    }
    println!("{:>6} {:>14}", "coeff", "value");
    for (name, c) in gravity::NAMES.iter().zip(&f.coeffs) {
        let unit = if name.starts_with('b') { "N" } else { "N m" };
        println!("{name:>6} {c:>14.6e} {unit}");
    }
    println!(
        "residual over {} poses: pitch/yaw RMS {:.3e} N m, worst {:.3e} N m (line {}); \
         insertion RMS {:.3e} N, worst {:.3e} N (line {}); conditioning {:.2e}",
        f.poses,
        f.rms_nm,
        f.worst_nm.0.abs(),
        f.worst_nm.1,
        f.rms_n,
        f.worst_n.0.abs(),
        f.worst_n.1,
        f.conditioning
    );
    println!("wrote [gravity] coeffs of {}", out.display());
    Ok(())
}

fn specimen_cmd(a: SpecimenArgs) -> Result<()> {
    let mesh = fem::mesh::load(&a.mesh)?;
    let material = Material::new(a.young, a.poisson)?;
    let r = specimen::compress(&mesh, material)
        .with_context(|| format!("{}: specimen compression", a.mesh.display()))?;
    println!("{}", serde_json::to_string(&r)?);
    Ok(())
}
