//! `host calibrate …`: bench calibration ([`haptic::calibrate`]). `tissue` fits the tissue
//! law Q or the display law P to a compression curve, `motor` the torque constants to
//! load-cell measurements, `gravity` the feed-forward for the instrument's weight to held
//! poses, `specimen` computes the linear FEM prediction for a compression specimen (the x of Q
//! and P), `relaxation` the viscoelastic relaxation to ramp-and-hold tests. Results go into a scene file (comments kept, written atomically) and
//! plots (SVG and PNG); each command prints its library report as text or as JSON.

use anyhow::{Result, bail};
use haptic::calibrate::fit;
use haptic::calibrate::scene_edit::Law;
use haptic::calibrate::{gravity, motor, relaxation, specimen, tissue};
use std::path::PathBuf;

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
        Calibrate::Tissue(a) => tissue_cmd(a),
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

fn relaxation_cmd(a: RelaxationArgs) -> Result<()> {
    let rep = relaxation::run(&relaxation::Config {
        csv: a.csv.clone(),
        t: a.t.clone(),
        x: a.x.clone(),
        f: a.f.clone(),
        scene: a.scene.clone(),
        plot: a.plot.clone(),
    })?;
    for w in &rep.warnings {
        eprintln!("warning: {w}");
    }
    if a.json {
        println!("{}", serde_json::to_string(&rep)?);
        return Ok(());
    }
    println!("terms  rms residual (N)");
    for (n, r) in &rep.survey {
        let mark = if *n == rep.g.len() { "  <- chosen" } else { "" };
        println!("{n:>5}  {r:.4e}{mark}");
    }
    println!(
        "elastic only (G = 1): rms {:.4e} N; noise estimate {:.4e} N",
        rep.elastic_only_rms_n, rep.noise_n
    );
    println!("g_inf = {:.5}", rep.g_inf);
    for (k, (g, tau)) in rep.g.iter().zip(&rep.tau_s).enumerate() {
        println!(
            "term {k}: g = {g:.5} +- {:.1e}, tau = {tau:.5} +- {:.1e} s (standard errors)",
            rep.g_se[k], rep.tau_s_se[k]
        );
    }
    println!(
        "instantaneous elastic law: Q_e(x) = sum_j c_j (x / {:.4e} m)^j, c = {:?} N",
        rep.x_max_m, rep.elastic_coeffs_n
    );
    println!("test  ramp (s)  speed (m/s)  rms (N)    rms/noise  peak error (N, %, std errors)");
    for (i, tf) in rep.tests.iter().enumerate() {
        println!(
            "{i:>4}  {:>8.3}  {:>11.3e}  {:.3e}  {:>9.2}  {:+.3e} ({:+.2} %, {:+.1})  {}",
            tf.ramp_s,
            tf.ramp_speed_m_s,
            tf.rms_n,
            tf.rms_over_noise,
            tf.peak_error_n,
            100.0 * tf.peak_error_n / tf.peak_force_n,
            tf.peak_error_n / tf.peak_error_se_n,
            tf.csv.display()
        );
    }
    if let Some(s) = rep.peak_error_per_decade {
        println!(
            "peak-force error against ramp speed: {:+.3} % per decade",
            100.0 * s
        );
    }
    println!(
        "plot: {} and {}",
        rep.plot[0].display(),
        rep.plot[1].display()
    );
    if let Some(scene) = &rep.scene {
        println!("wrote [viscoelastic] into {}", scene.display());
    }
    Ok(())
}

fn tissue_cmd(a: TissueArgs) -> Result<()> {
    let degree = parse_degree(&a.degree)?;
    let specimen = match (&a.specimen, a.young, a.poisson) {
        (Some(mesh), Some(young_pa), Some(poisson)) => Some(tissue::Specimen {
            mesh: mesh.clone(),
            young_pa,
            poisson,
        }),
        _ => None,
    };
    let rep = tissue::run(&tissue::Config {
        csv: a.csv.clone(),
        x: a.x.clone(),
        y: a.y.clone(),
        degree,
        law: a.law.into(),
        target_rms: a.target_rms,
        max_rms: a.max_rms,
        accept_poor_fit: a.accept_poor_fit,
        specimen,
        scene: a.scene.clone(),
        plot: a.plot.clone(),
    })?;
    if a.json {
        println!("{}", serde_json::to_string(&rep)?);
        return Ok(());
    }
    print_tissue(&a, &rep);
    Ok(())
}

/// The degree survey, the residual table and the result, for people.
fn print_tissue(a: &TissueArgs, rep: &tissue::Report) {
    let (name, f, survey, plots) = (rep.law, &rep.fit, &rep.survey, &rep.plot);
    let (x, y) = (&rep.x, &rep.y);
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

fn motor_cmd(a: MotorArgs) -> Result<()> {
    let rep = motor::run(&motor::Config {
        csv: a.csv.clone(),
        scene: a.scene.clone(),
        plot: a.plot.clone(),
    })?;
    if a.json {
        // Through a JSON value, whose objects list their keys in sorted order.
        println!("{}", serde_json::to_value(&rep)?);
        return Ok(());
    }
    println!(
        "{:>10} {:>6} {:>14} {:>14} {:>12} {:>12} {:>8}",
        "axis", "points", "k (/A)", "Kt (N m/A)", "friction", "rms", "rms %"
    );
    for r in &rep.axes {
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
    if let Some(s) = &rep.scene {
        println!(
            "wrote [device] torque_constant_nm_per_a and friction_offset of {}",
            s.display()
        );
    }
    for p in &rep.plots {
        println!("plot: {}", p.display());
    }
    Ok(())
}

fn gravity_cmd(a: GravityArgs) -> Result<()> {
    let rep = gravity::run(&gravity::Config {
        csv: a.csv.clone(),
        scene: a.scene.clone(),
        out: a.out.clone(),
    })?;
    if a.json {
        // Through a JSON value, whose objects list their keys in sorted order.
        println!("{}", serde_json::to_value(&rep)?);
        return Ok(());
    }
    let f = &rep.fit;
    println!("{:>6} {:>14}", "coeff", "value");
    for (name, c) in rep.names.iter().zip(&f.coeffs) {
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
    println!("wrote [gravity] coeffs of {}", rep.scene.display());
    Ok(())
}

fn specimen_cmd(a: SpecimenArgs) -> Result<()> {
    let r = specimen::run(&specimen::Config {
        mesh: a.mesh.clone(),
        young_pa: a.young,
        poisson: a.poisson,
    })?;
    println!("{}", serde_json::to_string(&r)?);
    Ok(())
}
