//! Gravity compensation of the instrument's own weight: the currents that hold the
//! instrument still at a few poses (device in constant-current mode) become joint efforts
//! `tau = i x transmission x Kt` (the firmware's current mapping inverted, see
//! [`bank_format::DeviceCalibration`]), and the eight coefficients of the potential
//!
//! `V = -(a_c + s b_c) cp cy - (a_s + s b_s) cp sy - (a_p + s b_p) sp - d_c cy - d_s sy`
//!
//! are fitted to them by least squares on `tau_g = dV/dq` (`bank-format` `SPEC.md`, "gravity",
//! which derives the basis from a rigid shaft's weight). All three joints' equations are
//! stacked unweighted (pitch and yaw in N m, insertion in N), and the fit is refused when the
//! poses do not determine every coefficient.

use super::csv::{CsvError, Table};
use bank_format::{DeviceCalibration, GRAVITY_COEFF_MAX, GRAVITY_COEFFS};
use faer::Mat;
use std::path::PathBuf;

/// Bench-file columns, in the order [`poses`] reads them.
pub const COLUMNS: [&str; 6] = [
    "pitch_rad",
    "yaw_rad",
    "insertion_m",
    "current_pitch_a",
    "current_yaw_a",
    "current_insertion_a",
];

/// Coefficient names, in the bank's order.
pub const NAMES: [&str; GRAVITY_COEFFS] = ["a_c", "a_s", "a_p", "b_c", "b_s", "b_p", "d_c", "d_s"];

/// Fewest poses accepted: 3 equations each, so 4 poses leave 4 equations over the 8 unknowns
/// for the residual to mean something.
pub const MIN_POSES: usize = 4;

/// Smallest singular value of the column-normalised design matrix, relative to its largest,
/// below which a coefficient is taken as not determined by the poses.
pub const DEGENERATE_REL: f64 = 1.0e-6;

/// One held pose.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    /// Pitch rad, yaw rad, insertion m.
    pub q: [f64; 3],
    /// Joint efforts that hold it: pitch N m, yaw N m, insertion N.
    pub effort: [f64; 3],
    /// CSV line (0 when made in code).
    pub line: u64,
}

/// The poses of a table read with [`COLUMNS`], with the currents turned into joint efforts by
/// the device's transmission and torque constants (`tau = i transmission Kt`).
pub fn poses(table: &Table, device: &DeviceCalibration) -> Result<Vec<Pose>, CsvError> {
    let cols: Vec<Vec<f64>> = (0..COLUMNS.len())
        .map(|c| table.numbers(c))
        .collect::<Result<_, _>>()?;
    let gain: [f64; 3] = std::array::from_fn(|j| {
        f64::from(device.transmission[j]) * f64::from(device.torque_constant_nm_per_a[j])
    });
    table
        .lines
        .iter()
        .enumerate()
        .map(|(i, &line)| {
            let v = |c: usize| cols.get(c).and_then(|col| col.get(i)).copied();
            let (Some(p), Some(y), Some(s)) = (v(0), v(1), v(2)) else {
                return Err(table.at(line, "missing value".into()));
            };
            if s < 0.0 {
                return Err(table.at(
                    line,
                    format!("column \"insertion_m\": must be >= 0 m, got {s}"),
                ));
            }
            let mut effort = [0.0; 3];
            for (j, e) in effort.iter_mut().enumerate() {
                let Some(current) = v(3 + j) else {
                    return Err(table.at(line, "missing value".into()));
                };
                *e = current * gain[j];
            }
            Ok(Pose {
                q: [p, y, s],
                effort,
                line,
            })
        })
        .collect()
}

/// `d tau_g / d coeffs` at `q`: row j is joint j's effort per unit of each coefficient
/// (`SPEC.md`, "gravity": the gradient of `V`, linear in the coefficients).
pub fn basis(q: [f64; 3]) -> [[f64; GRAVITY_COEFFS]; 3] {
    let (sp, cp) = q[0].sin_cos();
    let (sy, cy) = q[1].sin_cos();
    let s = q[2];
    let (pc, ps, pp) = (sp * cy, sp * sy, -cp);
    let (yc, ys) = (cp * sy, -cp * cy);
    [
        [pc, ps, pp, s * pc, s * ps, s * pp, 0.0, 0.0],
        [yc, ys, 0.0, s * yc, s * ys, 0.0, sy, -cy],
        [0.0, 0.0, 0.0, -cp * cy, -cp * sy, -sp, 0.0, 0.0],
    ]
}

/// `tau_g(q)` for coefficients `c`: pitch N m, yaw N m, insertion N.
pub fn efforts(c: &[f64; GRAVITY_COEFFS], q: [f64; 3]) -> [f64; 3] {
    basis(q).map(|row| row.iter().zip(c).map(|(b, c)| b * c).sum())
}

/// A fit's result.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct GravityFit {
    /// `[a_c, a_s, a_p, b_c, b_s, b_p, d_c, d_s]` (N m, N m, N m, N, N, N, N m, N m).
    pub coeffs: [f64; GRAVITY_COEFFS],
    /// Poses used.
    pub poses: usize,
    /// RMS of the pitch and yaw residuals together, N m.
    pub rms_nm: f64,
    /// Largest pitch or yaw residual, N m, and its CSV line.
    pub worst_nm: (f64, u64),
    /// RMS of the insertion residuals, N.
    pub rms_n: f64,
    /// Largest insertion residual, N, and its CSV line.
    pub worst_n: (f64, u64),
    /// Smallest over largest singular value of the column-normalised design matrix (1 is
    /// ideal; below [`DEGENERATE_REL`] the fit is refused).
    pub conditioning: f64,
}

/// Why a gravity fit was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GravityError {
    /// Fewer than [`MIN_POSES`] poses.
    #[error(
        "{got} poses, need at least {MIN_POSES}: add held poses spread over pitch, yaw and insertion"
    )]
    TooFew {
        /// Poses given.
        got: usize,
    },
    /// The poses do not determine a coefficient.
    #[error(
        "the poses do not determine {name} (conditioning {conditioning:.1e} < {DEGENERATE_REL:.0e}): {hint}"
    )]
    Degenerate {
        /// The coefficient most involved in the undetermined direction.
        name: &'static str,
        /// What poses to add.
        hint: &'static str,
        /// Smallest over largest singular value.
        conditioning: f64,
    },
    /// The linear algebra failed (not expected for finite input).
    #[error("least-squares solve failed: {0}")]
    Solve(String),
    /// A fitted coefficient is beyond what the bank accepts.
    #[error(
        "fitted {name} = {value:.4} is beyond +-{GRAVITY_COEFF_MAX} (N m or N): check the currents' units and signs and the scene's transmission and torque constants"
    )]
    OutOfRange {
        /// The coefficient.
        name: &'static str,
        /// Its value.
        value: f64,
    },
}

fn hint(k: usize) -> &'static str {
    match k {
        0..=2 => {
            "add poses at three or more pitch angles (not only 0) and three or more yaw angles"
        }
        3..=5 => {
            "add poses at two or more insertions (the sliding shaft's weight needs the lever to change)"
        }
        _ => {
            "add poses at several pitch angles for the same yaw (the yaw frame's weight is told from the shaft's only by pitch)"
        }
    }
}

/// Least-squares fit of the coefficients to held poses (SVD of the column-normalised design
/// matrix, so the conditioning test does not depend on the units of the columns).
pub fn fit(poses: &[Pose]) -> Result<GravityFit, GravityError> {
    if poses.len() < MIN_POSES {
        return Err(GravityError::TooFew { got: poses.len() });
    }
    let rows = 3 * poses.len();
    let design = |r: usize, k: usize| {
        poses
            .get(r / 3)
            .map_or(0.0, |p| basis(p.q)[r % 3].get(k).copied().unwrap_or(0.0))
    };
    let norms: [f64; GRAVITY_COEFFS] =
        std::array::from_fn(|k| (0..rows).map(|r| design(r, k).powi(2)).sum::<f64>().sqrt());
    let scale = norms.iter().copied().fold(0.0f64, f64::max);
    if let Some(k) = norms
        .iter()
        .position(|&n| n <= DEGENERATE_REL * scale || n.is_nan())
    {
        return Err(GravityError::Degenerate {
            name: NAMES[k],
            hint: hint(k),
            conditioning: 0.0,
        });
    }
    let a = Mat::from_fn(rows, GRAVITY_COEFFS, |r, k| design(r, k) / norms[k]);
    let svd = a
        .thin_svd()
        .map_err(|e| GravityError::Solve(format!("{e:?}")))?;
    let s = svd.S().column_vector();
    let (u, v) = (svd.U(), svd.V());
    let (s_max, s_min) = (s[0], s[GRAVITY_COEFFS - 1]);
    let conditioning = if s_max > 0.0 { s_min / s_max } else { 0.0 };
    if conditioning < DEGENERATE_REL || conditioning.is_nan() {
        let k = (0..GRAVITY_COEFFS)
            .max_by(|&i, &j| {
                v[(i, GRAVITY_COEFFS - 1)]
                    .abs()
                    .total_cmp(&v[(j, GRAVITY_COEFFS - 1)].abs())
            })
            .unwrap_or(0);
        return Err(GravityError::Degenerate {
            name: NAMES[k],
            hint: hint(k),
            conditioning,
        });
    }
    let b = |r: usize| poses.get(r / 3).map_or(0.0, |p| p.effort[r % 3]);
    // x = V S^-1 U^T b, then undo the column scaling.
    let utb: Vec<f64> = (0..GRAVITY_COEFFS)
        .map(|i| (0..rows).map(|r| u[(r, i)] * b(r)).sum::<f64>() / s[i])
        .collect();
    let coeffs: [f64; GRAVITY_COEFFS] = std::array::from_fn(|k| {
        (0..GRAVITY_COEFFS).map(|i| v[(k, i)] * utb[i]).sum::<f64>() / norms[k]
    });
    if let Some(k) = coeffs
        .iter()
        .position(|c| c.abs() > f64::from(GRAVITY_COEFF_MAX) || !c.is_finite())
    {
        return Err(GravityError::OutOfRange {
            name: NAMES[k],
            value: coeffs[k],
        });
    }
    let (mut sum_nm, mut sum_n) = (0.0, 0.0);
    let (mut worst_nm, mut worst_n) = ((0.0f64, 0u64), (0.0f64, 0u64));
    for p in poses {
        let fitted = efforts(&coeffs, p.q);
        for (j, (want, got)) in p.effort.iter().zip(fitted).enumerate() {
            let r = want - got;
            let (sum, worst) = if j == 2 {
                (&mut sum_n, &mut worst_n)
            } else {
                (&mut sum_nm, &mut worst_nm)
            };
            *sum += r * r;
            if r.abs() > worst.0.abs() {
                *worst = (r, p.line);
            }
        }
    }
    let n = poses.len() as f64;
    Ok(GravityFit {
        coeffs,
        poses: poses.len(),
        rms_nm: (sum_nm / (2.0 * n)).sqrt(),
        worst_nm,
        rms_n: (sum_n / n).sqrt(),
        worst_n,
        conditioning,
    })
}

/// What `host calibrate gravity` fits: its options.
#[derive(Debug, Clone)]
pub struct Config {
    /// CSV of held poses with [`COLUMNS`].
    pub csv: PathBuf,
    /// Scene file: its motor calibration turns the currents into joint efforts.
    pub scene: PathBuf,
    /// Where the calibrated scene goes; `None`: `scene`, edited in place.
    pub out: Option<PathBuf>,
}

/// The gravity fit (serialised as `host calibrate gravity --json` prints it).
#[derive(Debug, Clone, serde::Serialize)]
pub struct Report {
    /// The fit.
    pub fit: GravityFit,
    /// The coefficients' names ([`NAMES`]).
    pub names: [&'static str; GRAVITY_COEFFS],
    /// The scene written.
    pub scene: PathBuf,
}

/// Reads the poses, fits the coefficients ([`fit`]) and writes them into the scene's
/// `[gravity]` table (of `out`, or of the scene in place).
pub fn run(a: &Config) -> anyhow::Result<Report> {
    use anyhow::Context;
    let scene = crate::scene::Scene::load(&a.scene)?;
    let table = super::csv::read(&a.csv, &COLUMNS)?;
    let poses = poses(&table, &scene.device)?;
    let f = fit(&poses).with_context(|| a.csv.display().to_string())?;
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
    let new = super::scene_edit::set_gravity(out, &text, &f.coeffs, &source)?;
    crate::fsio::write_atomic(out, new.as_bytes(), &[])
        .with_context(|| format!("writing {}", out.display()))?;
    Ok(Report {
        fit: f,
        names: NAMES,
        scene: out.to_path_buf(),
    })
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::indexing_slicing, clippy::panic)]
mod tests {
    use super::*;

    const TRUE: [f64; 8] = [0.012, -0.004, 0.03, 0.35, 0.08, -0.6, 0.02, -0.01];

    /// A grid of poses over pitch, yaw (+-0.6 rad) and insertion (4-16 cm).
    fn grid() -> Vec<[f64; 3]> {
        let mut q = Vec::new();
        for p in [-0.6, -0.2, 0.2, 0.6] {
            for y in [-0.6, 0.0, 0.6] {
                for s in [0.04, 0.1, 0.16] {
                    q.push([p, y, s]);
                }
            }
        }
        q
    }

    /// Deterministic noise uniform in [-1, 1).
    fn noise(rng: &mut crate::rng::SplitMix64) -> f64 {
        2.0 * rng.unit() - 1.0
    }

    /// The efforts a rigid shaft would need, written from the potential directly: weight G
    /// (N) in the device frame, centre of mass l behind the tip, so
    /// `V = -(s - l) (G_1 cp cy + G_2 cp sy + G_3 sp) - d_c cy - d_s sy`, differentiated by hand.
    fn shaft_efforts(g: [f64; 3], l: f64, d: [f64; 2], q: [f64; 3]) -> [f64; 3] {
        let (sp, cp) = q[0].sin_cos();
        let (sy, cy) = q[1].sin_cos();
        let r = q[2] - l;
        let gu = g[0] * cp * cy + g[1] * cp * sy + g[2] * sp;
        let dgu_dp = -g[0] * sp * cy - g[1] * sp * sy + g[2] * cp;
        let dgu_dy = -g[0] * cp * sy + g[1] * cp * cy;
        [-r * dgu_dp, -r * dgu_dy + d[0] * sy - d[1] * cy, -gu]
    }

    #[test]
    fn exact_data_from_a_rigid_shaft_recovers_its_weight_and_lever() {
        let (g, l, d) = ([0.3, -0.1, -1.2], 0.08, [0.015, -0.02]);
        let poses: Vec<Pose> = grid()
            .into_iter()
            .map(|q| Pose {
                q,
                effort: shaft_efforts(g, l, d, q),
                line: 0,
            })
            .collect();
        let f = fit(&poses).unwrap();
        let want = [
            -l * g[0],
            -l * g[1],
            -l * g[2],
            g[0],
            g[1],
            g[2],
            d[0],
            d[1],
        ];
        for (got, want) in f.coeffs.iter().zip(want) {
            assert!((got - want).abs() < 1e-12, "{:?} vs {want:?}", f.coeffs);
        }
        assert!(f.rms_nm < 1e-13 && f.rms_n < 1e-13, "{f:?}");
    }

    /// With noise of known RMS e on every effort, the least-squares residual's expected mean
    /// square is `e^2 (m - 8) / m` for m equations (the residual is the noise projected off the
    /// 8 fitted directions): the reported RMS must match it, and the coefficients stay close.
    #[test]
    fn noisy_data_reports_the_noise_as_residual() {
        let mut seed = crate::rng::SplitMix64::new(0x9e37_79b9_7f4a_7c15);
        let amp = 2e-3; // N m and N; uniform, so RMS amp / sqrt(3)
        let mut q = Vec::new();
        for _ in 0..10 {
            q.extend(grid());
        }
        let mut sq = 0.0;
        let poses: Vec<Pose> = q
            .into_iter()
            .map(|q| {
                let mut e = efforts(&TRUE, q);
                for v in &mut e {
                    let n = amp * noise(&mut seed);
                    sq += n * n;
                    *v += n;
                }
                Pose {
                    q,
                    effort: e,
                    line: 0,
                }
            })
            .collect();
        let m = 3.0 * poses.len() as f64;
        let noise_rms = (sq / m).sqrt();
        assert!((noise_rms - amp / 3f64.sqrt()).abs() < 0.05 * amp);
        let f = fit(&poses).unwrap();
        let all_rms = ((2.0 * f.rms_nm.powi(2) + f.rms_n.powi(2)) / 3.0).sqrt();
        let expect = noise_rms * ((m - 8.0) / m).sqrt();
        assert!(
            (all_rms - expect).abs() < 0.02 * expect,
            "{all_rms} vs {expect}"
        );
        // The worst residual is about the noise's bound (the fit moves it by its own error).
        for worst in [f.worst_nm.0, f.worst_n.0] {
            assert!((0.8 * amp..1.2 * amp).contains(&worst.abs()), "{f:?}");
        }
        for (got, want) in f.coeffs.iter().zip(TRUE) {
            assert!((got - want).abs() < 2e-3, "{:?}", f.coeffs);
        }
    }

    #[test]
    fn too_few_or_degenerate_poses_are_refused_naming_what_to_add() {
        let at = |qs: &[[f64; 3]]| -> Vec<Pose> {
            qs.iter()
                .map(|&q| Pose {
                    q,
                    effort: efforts(&TRUE, q),
                    line: 0,
                })
                .collect()
        };
        let three = at(&grid()[..3]);
        assert_eq!(fit(&three), Err(GravityError::TooFew { got: 3 }));
        // All at pitch = yaw = 0: a_c's column is zero.
        let straight: Vec<[f64; 3]> = (0..6).map(|i| [0.0, 0.0, 0.03 * i as f64]).collect();
        match fit(&at(&straight)) {
            Err(GravityError::Degenerate { name, .. }) => assert_eq!(name, "a_c"),
            other => panic!("{other:?}"),
        }
        // Pitch always 0: the yaw equation sees only a_c + d_c and a_s + d_s.
        let level: Vec<[f64; 3]> = grid().into_iter().map(|q| [0.0, q[1], q[2]]).collect();
        match fit(&at(&level)) {
            Err(GravityError::Degenerate { name, hint, .. }) => {
                assert!(["a_c", "a_s", "d_c", "d_s"].contains(&name), "{name}");
                assert!(hint.contains("pitch"), "{hint}");
            }
            other => panic!("{other:?}"),
        }
    }
}
