//! `host calibrate relaxation`: the QLV fit of several ramp-and-hold tests together
//! ([`super::fit_tests`]), plotted and written into a scene's `[viscoelastic]` table.

use super::super::csv;
use super::super::plot::{self, PlotSpec};
use super::super::scene_edit;
use super::Test;
use anyhow::{Context, Result};
use std::path::PathBuf;

/// What to fit: the options of `host calibrate relaxation`.
#[derive(Debug, Clone)]
pub struct Config {
    /// Bench CSVs, one per test (a header row, then one row per sample, times increasing).
    pub csv: Vec<PathBuf>,
    /// Column of the time, s.
    pub t: String,
    /// Column of the displacement (positive into the tissue), m.
    pub x: String,
    /// Column of the force (positive pushing back), N.
    pub f: String,
    /// Scene file to write `[viscoelastic]` into.
    pub scene: Option<PathBuf>,
    /// Plot path without extension (`.svg` and `.png` are written).
    pub plot: PathBuf,
}

/// The relaxation fit (serialised as `host calibrate relaxation --json` prints it).
#[derive(Debug, Clone, serde::Serialize)]
pub struct Report {
    /// `G`'s equilibrium value, `1 - sum g`.
    pub g_inf: f64,
    /// Prony amplitudes.
    pub g: Vec<f64>,
    /// Prony time constants, s.
    pub tau_s: Vec<f64>,
    /// Linearised standard errors of g.
    pub g_se: Vec<f64>,
    /// Linearised standard errors of tau_s.
    pub tau_s_se: Vec<f64>,
    /// `Q_e(x) = sum_j c_j (x / x_max)^j`, j = 1.., N.
    pub elastic_coeffs_n: Vec<f64>,
    /// The `x_max` of `Q_e`, m.
    pub x_max_m: f64,
    /// RMS residual over all tests, N.
    pub rms_n: f64,
    /// RMS residual of the best elastic fit alone (G = 1), N.
    pub elastic_only_rms_n: f64,
    /// Noise estimate, N.
    pub noise_n: f64,
    /// RMS residual for each count of terms tried, as `[terms, rms]`.
    #[serde(serialize_with = "survey_rows")]
    pub survey: Vec<(usize, f64)>,
    /// Rows of all tests.
    pub rows: usize,
    /// Per test.
    pub tests: Vec<TestReport>,
    /// Slope of the relative peak-force error per decade of ramp speed (null for one speed).
    pub peak_error_per_decade: Option<f64>,
    /// What the law leaves unexplained, one sentence each.
    pub warnings: Vec<String>,
    /// The scene written, if any.
    pub scene: Option<PathBuf>,
    /// The plots written (SVG, PNG).
    pub plot: [PathBuf; 2],
}

/// One test of a [`Report`].
#[derive(Debug, Clone, serde::Serialize)]
pub struct TestReport {
    /// Its CSV.
    pub csv: PathBuf,
    /// Its rows.
    pub rows: usize,
    /// Its ramp's duration, s.
    pub ramp_s: f64,
    /// Its ramp's speed, m/s.
    pub ramp_speed_m_s: f64,
    /// Its RMS residual, N.
    pub rms_n: f64,
    /// Its noise estimate, N.
    pub noise_n: f64,
    /// `rms_n / noise_n`.
    pub rms_over_noise: f64,
    /// The residual its noise does not account for, `sqrt(max(rms^2 - noise^2, 0))`, N.
    pub unexplained_n: f64,
    /// Its peak force, N.
    pub peak_force_n: f64,
    /// The model's error at the peak, N.
    pub peak_error_n: f64,
    /// The standard error of that peak error, N.
    pub peak_error_se_n: f64,
}

/// The survey's `(terms, rms)` rows as `[terms, rms]` number pairs.
fn survey_rows<S: serde::Serializer>(rows: &[(usize, f64)], s: S) -> Result<S::Ok, S::Error> {
    s.collect_seq(rows.iter().map(|&(n, r)| [n as f64, r]))
}

/// Reads the tests, fits them together, writes the plot (force against time, data and fit,
/// residuals below) and, if given, the scene's `[viscoelastic]` table.
pub fn run(a: &Config) -> Result<Report> {
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
    let fit = super::fit_tests(&tests)
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
        super::super::write_scene(scene, |text| {
            Ok(scene_edit::set_viscoelastic(
                scene, text, &fit.g, &fit.tau_s, &source,
            )?)
        })?;
    }
    let rows = tests.iter().map(|t| t.t.len()).sum();
    Ok(Report {
        g_inf: fit.g_inf,
        tau_s: fit.tau_s,
        g_se: fit.g_se,
        tau_s_se: fit.tau_se,
        elastic_coeffs_n: fit.elastic,
        x_max_m: fit.x_max,
        rms_n: fit.rms,
        elastic_only_rms_n: fit.elastic_rms,
        noise_n: fit.noise,
        survey: fit.survey,
        rows,
        tests: a
            .csv
            .iter()
            .zip(&fit.tests)
            .map(|(csv, tf)| TestReport {
                csv: csv.clone(),
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
        g: fit.g,
        peak_error_per_decade: fit.peak_error_per_decade,
        warnings: fit.warnings,
        scene: a.scene.clone(),
        plot: plots,
    })
}
