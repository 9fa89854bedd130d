//! `host calibrate tissue`: the tissue law Q or the display law P (paper, section 3-4, fig. 9)
//! fitted to a bench curve ([`fit::fit_law`]), checked, plotted and written into a scene.

use super::fit::{self, ChebFit, DegreeRow};
use super::plot::{self, PlotSpec};
use super::scene_edit::{self, Law};
use super::{csv, specimen, write_scene};
use anyhow::{Context, Result, bail};
use fem::elasticity::Material;
use std::path::PathBuf;

/// A compression specimen whose linear FEM prediction turns a displacement column into the
/// law's x ([`specimen::compress`]).
#[derive(Debug, Clone)]
pub struct Specimen {
    /// The specimen's cylinder mesh, axis z, m.
    pub mesh: PathBuf,
    /// Young's modulus of the linear model, Pa.
    pub young_pa: f64,
    /// Poisson's ratio of the linear model.
    pub poisson: f64,
}

/// What to fit: the options of `host calibrate tissue`.
#[derive(Debug, Clone)]
pub struct Config {
    /// Bench CSV.
    pub csv: PathBuf,
    /// Column of the law's x (the linear model's value, or the displacement with a specimen).
    pub x: String,
    /// Column of the measured value.
    pub y: String,
    /// Polynomial degree; `None`: chosen by cross-validation ([`fit::fit_law`]).
    pub degree: Option<usize>,
    /// Which law.
    pub law: Law,
    /// The automatic degree is content with this cross-validated RMS error (of full scale).
    pub target_rms: f64,
    /// Refuse a fit whose RMS error exceeds this fraction of full scale.
    pub max_rms: f64,
    /// Write a fit beyond `max_rms` anyway (the scene's comment says so).
    pub accept_poor_fit: bool,
    /// The x column is a platen displacement of this specimen.
    pub specimen: Option<Specimen>,
    /// Scene file to write the law into.
    pub scene: Option<PathBuf>,
    /// Plot path without extension (`.svg` and `.png` are written).
    pub plot: PathBuf,
}

/// The fitted law (serialised as `host calibrate tissue --json` prints it).
#[derive(Debug, Clone, serde::Serialize)]
pub struct Report {
    /// "Q" or "P".
    pub law: &'static str,
    /// The polynomial degree.
    pub degree: usize,
    /// Always "chebyshev".
    pub basis: &'static str,
    /// The data interval of the Chebyshev basis.
    pub domain: [f64; 2],
    /// The Chebyshev coefficients.
    pub coefficients: Vec<f64>,
    /// RMS error relative to full scale.
    pub rms_rel_error: f64,
    /// Largest error relative to full scale.
    pub max_rel_error: f64,
    /// Points fitted.
    pub points: usize,
    /// The degree survey (empty for a given degree).
    pub survey: Vec<DegreeRow>,
    /// The scene written, if any.
    pub scene: Option<PathBuf>,
    /// The plots written (SVG, PNG).
    pub plot: [PathBuf; 2],
    /// The fit.
    #[serde(skip)]
    pub fit: ChebFit,
    /// The law's x of every point (after the specimen's prediction, if any).
    #[serde(skip)]
    pub x: Vec<f64>,
    /// The measured value of every point.
    #[serde(skip)]
    pub y: Vec<f64>,
}

/// Reads the bench curve, fits the law, refuses a poor fit (unless accepted) and a Q that
/// pulls at first contact, writes the plots and, if given, the scene's law table.
pub fn run(a: &Config) -> Result<Report> {
    let which_law = a.law;
    let degree = a.degree;
    if !(a.target_rms.is_finite() && a.target_rms >= 0.0) {
        bail!("--target-rms must be >= 0, got {}", a.target_rms);
    }
    let table = csv::read(&a.csv, &[&a.x, &a.y])?;
    let need = degree.map_or(fit::AUTO_DEGREES.start() + 2, |d| d + 2);
    table.require_rows(need, "a fit needs more points than coefficients")?;
    let (mut x, y) = (table.numbers(0)?, table.numbers(1)?);
    table.require_increasing(0, &x)?;
    let mut x_name = a.x.clone();
    if let Some(s) = &a.specimen {
        let r = specimen::compress(
            &fem::mesh::load(&s.mesh)?,
            Material::new(s.young_pa, s.poisson)?,
        )
        .with_context(|| format!("{}: specimen compression", s.mesh.display()))?;
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
        && let Some(q0) = crate::scene::pull_at_first_contact(&law)
    {
        bail!(
            "{}: the fitted law gives Q(0) = {q0:.4} N, below -{:.1} % of its largest force: \
             rendered, it would pull the tool into the tissue at first contact; nothing was \
             written (check that the data starts at zero force, or fit a lower --degree)",
            a.csv.display(),
            100.0 * crate::scene::PULL_TOLERANCE
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

    Ok(Report {
        law: name,
        degree: f.degree,
        basis: "chebyshev",
        domain: f.domain,
        coefficients: f.coeffs.clone(),
        rms_rel_error: errors.rms_rel,
        max_rel_error: errors.max_rel,
        points: x.len(),
        survey,
        scene: a.scene.clone(),
        plot: plots,
        fit: f,
        x,
        y,
    })
}
