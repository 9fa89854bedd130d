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
    /// Joint index.
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
