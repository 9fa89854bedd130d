//! Motor calibration on a bench: the tool tip pushes a load cell at known poses while a known
//! current is commanded; per axis, the joint effort the load cell sees is fitted as
//!
//! `tau = k i - c`,
//!
//! with `k = transmission x torque_constant` (N m/A for pitch and yaw, N/A for insertion: the
//! firmware's `i = tau / (transmission torque_constant)`, see
//! [`bank_format::DeviceCalibration`]) and `c` the friction offset (N m, or N), the effort
//! lost to static friction in a quasi-static push. The effort is `tau = F L` for pitch and yaw
//! (force `F` perpendicular to the shaft at the tip, lever `L` = the tip's distance from the
//! fulcrum, i.e. the insertion) and `tau = F` for insertion.

use super::csv::{CsvError, Table};
use super::plot::{self, PlotSpec};
use super::scene_edit;
use crate::scene::Scene;
use anyhow::{Context, Result, bail};
use std::path::{Path, PathBuf};

/// Axis names, in joint order (0 = pitch, 1 = yaw, 2 = insertion).
pub const AXES: [&str; 3] = ["pitch", "yaw", "insertion"];
/// Points needed per fitted axis.
pub const MIN_POINTS: usize = 3;

/// One bench measurement.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    /// Joint: 0 = pitch, 1 = yaw, 2 = insertion.
    pub axis: usize,
    /// Tip distance from the fulcrum at the pose, m.
    pub insertion_m: f64,
    /// Commanded motor current, A.
    pub current_a: f64,
    /// Load-cell force along the joint's direction of motion at the tip, N.
    pub force_n: f64,
    /// CSV line.
    pub line: u64,
}

impl Sample {
    /// The joint effort the load cell measures: N m for pitch and yaw, N for insertion.
    pub fn effort(&self) -> f64 {
        if self.axis == 2 {
            self.force_n
        } else {
            self.force_n * self.insertion_m
        }
    }
}

/// The fit of one axis.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct AxisFit {
    /// Joint index (`axis_index` in JSON, beside the axis name of a [`Row`]).
    #[serde(rename = "axis_index")]
    pub axis: usize,
    /// Points used.
    pub points: usize,
    /// `k = transmission x torque_constant`, N m/A (N/A for insertion).
    pub gain: f64,
    /// Friction offset `c`, N m (N for insertion).
    pub friction: f64,
    /// RMS of the effort residuals, N m (N).
    pub rms: f64,
    /// RMS residual / largest measured effort.
    pub rms_rel: f64,
    /// `(current, effort residual)` per point.
    pub residuals: Vec<(f64, f64)>,
}

/// Bench-file columns, in the order [`samples`] reads them.
pub const COLUMNS: [&str; 4] = ["axis", "insertion_m", "current_a", "force_n"];

/// The samples of a table read with [`COLUMNS`]; `axis` is a name (`pitch`, `yaw`,
/// `insertion`) or an index (0, 1, 2).
pub fn samples(table: &Table) -> Result<Vec<Sample>, CsvError> {
    let insertion = table.numbers(1)?;
    let current = table.numbers(2)?;
    let force = table.numbers(3)?;
    table
        .text(0)
        .zip(&table.lines)
        .enumerate()
        .map(|(i, (name, &line))| {
            let axis = AXES
                .iter()
                .position(|a| a.eq_ignore_ascii_case(name))
                .or_else(|| name.parse::<usize>().ok().filter(|&a| a < 3))
                .ok_or_else(|| {
                    table.at(
                        line,
                        format!("column \"axis\": {name:?} is not pitch, yaw, insertion, 0, 1 or 2"),
                    )
                })?;
            if axis != 2 && !(insertion[i] > 0.0 && insertion[i].is_finite()) {
                return Err(table.at(
                    line,
                    format!(
                        "column \"insertion_m\": the lever of a {} measurement must be > 0 m, got {}",
                        AXES[axis], insertion[i]
                    ),
                ));
            }
            Ok(Sample {
                axis,
                insertion_m: insertion[i],
                current_a: current[i],
                force_n: force[i],
                line,
            })
        })
        .collect()
}

/// Motor-fit errors.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MotorError {
    /// No axis has data.
    #[error("no measurements")]
    Empty,
    /// Too few points, or a single current, on an axis.
    #[error(
        "axis {axis}: {points} points with {distinct} distinct currents; need at least {MIN_POINTS} points and 2 currents"
    )]
    Underdetermined {
        /// Axis name.
        axis: &'static str,
        /// Points on it.
        points: usize,
        /// Distinct currents.
        distinct: usize,
    },
}

/// Least-squares `tau = k i - c` on every axis that has data (centred sums: the 2x2 normal
/// equations of a centred straight line are diagonal, so exact).
pub fn fit(samples: &[Sample]) -> Result<Vec<AxisFit>, MotorError> {
    let mut fits = Vec::new();
    for (axis, name) in AXES.iter().enumerate() {
        let pts: Vec<(f64, f64)> = samples
            .iter()
            .filter(|s| s.axis == axis)
            .map(|s| (s.current_a, s.effort()))
            .collect();
        if pts.is_empty() {
            continue;
        }
        let mut currents: Vec<f64> = pts.iter().map(|p| p.0).collect();
        currents.sort_by(f64::total_cmp);
        currents.dedup();
        if pts.len() < MIN_POINTS || currents.len() < 2 {
            return Err(MotorError::Underdetermined {
                axis: name,
                points: pts.len(),
                distinct: currents.len(),
            });
        }
        let n = pts.len() as f64;
        let mi = pts.iter().map(|p| p.0).sum::<f64>() / n;
        let mt = pts.iter().map(|p| p.1).sum::<f64>() / n;
        let sii: f64 = pts.iter().map(|p| (p.0 - mi) * (p.0 - mi)).sum();
        let sit: f64 = pts.iter().map(|p| (p.0 - mi) * (p.1 - mt)).sum();
        let gain = sit / sii;
        let intercept = mt - gain * mi;
        let residuals: Vec<(f64, f64)> = pts
            .iter()
            .map(|&(i, t)| (i, t - (gain * i + intercept)))
            .collect();
        let rms = (residuals.iter().map(|r| r.1 * r.1).sum::<f64>() / n).sqrt();
        let scale = pts.iter().fold(0.0f64, |m, p| m.max(p.1.abs()));
        fits.push(AxisFit {
            axis,
            points: pts.len(),
            gain,
            friction: -intercept,
            rms,
            rms_rel: if scale > 0.0 { rms / scale } else { rms },
            residuals,
        });
    }
    if fits.is_empty() {
        return Err(MotorError::Empty);
    }
    Ok(fits)
}
/// What `host calibrate motor` fits: its options.
#[derive(Debug, Clone)]
pub struct Config {
    /// Bench CSV with [`COLUMNS`].
    pub csv: PathBuf,
    /// Scene file whose gear ratios turn the gains into torque constants, written back with
    /// the friction offsets.
    pub scene: Option<PathBuf>,
    /// Plot path without extension: `<plot>-<axis>.svg` and `.png` per fitted axis.
    pub plot: PathBuf,
}

/// One fitted axis of a [`Report`].
#[derive(Debug, Clone, serde::Serialize)]
pub struct Row {
    /// Its name ([`AXES`]).
    pub axis: &'static str,
    /// The fit.
    #[serde(flatten)]
    pub fit: AxisFit,
    /// `k / transmission` with a scene, N m/A (N/A for insertion).
    pub torque_constant_nm_per_a: Option<f64>,
}

/// The motor fit (serialised as `host calibrate motor --json` prints it).
#[derive(Debug, Clone, serde::Serialize)]
pub struct Report {
    /// The fitted axes.
    pub axes: Vec<Row>,
    /// The plots written.
    pub plots: Vec<PathBuf>,
    /// The scene written, if any.
    pub scene: Option<PathBuf>,
}

/// Reads the bench file, fits every measured axis ([`fit`]), refuses a gain whose sign
/// disagrees with the scene's gear ratio, writes the plots and, with a scene, its torque
/// constants and friction offsets.
pub fn run(a: &Config) -> Result<Report> {
    let table = super::csv::read(&a.csv, &COLUMNS)?;
    table.require_rows(MIN_POINTS, "three per fitted axis")?;
    let samples = samples(&table)?;
    let fits = fit(&samples).with_context(|| a.csv.display().to_string())?;
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
        super::write_scene(path, |text| {
            Ok(scene_edit::set_motor(path, text, kt, friction)?)
        })?;
    }
    let axes = fits
        .into_iter()
        .map(|f| Row {
            axis: AXES[f.axis],
            torque_constant_nm_per_a: kt[f.axis],
            fit: f,
        })
        .collect();
    Ok(Report {
        axes,
        plots,
        scene: a.scene.clone(),
    })
}
