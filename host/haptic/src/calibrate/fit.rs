//! Least-squares polynomial laws (paper, section 3-4: "a least squares minimization is used to
//! find the polynomial function P(x) approximating d_r(x) and the polynomial function Q(x)
//! approximating f(x) ... the degree ranges from 4 to 10").
//!
//! The fit is solved by a Householder QR factorisation of the Chebyshev design matrix on the
//! data interval (never the normal equations of monomials, whose condition number is the
//! square of an already exponentially growing one). The degree can be chosen by k-fold
//! cross-validation, and a fit is only accepted when it is increasing on its domain, checked
//! exactly as the bank reader checks it ([`bank_format::TissueLaw`], f32 coefficients).
//!
//! Errors are relative to full scale: a residual divided by the largest `|y|` of the data
//! (pointwise relative errors are meaningless where the curve starts at zero).

use super::cheb;
use bank_format::{BankError, LAW_SAMPLES, MAX_LAW_COEFFS, TissueLaw};
use faer::Mat;
use faer::linalg::solvers::SolveLstsq;

/// Highest degree the bank can store (`MAX_LAW_COEFFS - 1`).
pub const MAX_DEGREE: usize = MAX_LAW_COEFFS - 1;
/// The cross-validated RMS error (relative to full scale) `--degree auto` is content with.
pub const DEFAULT_TARGET_RMS: f64 = 0.001;
/// Degrees `--degree auto` considers: the paper's range, and below it for curves that need
/// less.
pub const AUTO_DEGREES: std::ops::RangeInclusive<usize> = 1..=10;
/// Number of cross-validation folds (fewer when there are fewer points).
pub const FOLDS: usize = 10;
/// `auto` takes the smallest degree whose cross-validated error is within this factor of the
/// best one (or under the target): a higher degree must earn its keep.
pub const CV_SLACK: f64 = 1.05;

/// Fitting errors.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FitError {
    /// Degree outside what the bank can store.
    #[error("degree {degree} is out of range: use 1..={MAX_DEGREE}")]
    Degree {
        /// Requested degree.
        degree: usize,
    },
    /// Too few points for the degree.
    #[error(
        "degree {degree} needs at least {} points (one more than its {} coefficients), got {points}",
        degree + 2,
        degree + 1
    )]
    TooFewPoints {
        /// Requested degree.
        degree: usize,
        /// Points given.
        points: usize,
    },
    /// The x values do not span an interval.
    #[error("the x values span no interval ({lo} .. {hi})")]
    Domain {
        /// Smallest x.
        lo: f64,
        /// Largest x.
        hi: f64,
    },
    /// The fit is not increasing.
    #[error(
        "the degree-{degree} fit is not increasing near x = {at:.6} (domain [{lo:.6}, {hi:.6}]): \
         the law must increase on its domain; use a lower --degree, or --degree auto"
    )]
    NotMonotone {
        /// Degree of the refused fit.
        degree: usize,
        /// Where the slope is not positive.
        at: f64,
        /// Domain start.
        lo: f64,
        /// Domain end.
        hi: f64,
    },
    /// The bank refuses the law for another reason (non-finite values, domain).
    #[error("the degree-{degree} fit cannot be stored: {reason}")]
    Law {
        /// Degree of the refused fit.
        degree: usize,
        /// The bank reader's reason.
        reason: BankError,
    },
    /// `auto` found no increasing fit, and the data itself decreases somewhere.
    #[error(
        "no degree in {lo}..={hi} gives an increasing fit, and the data decreases: y falls \
         from {y0} to {y1} between x = {x0} and x = {x1}"
    )]
    NoMonotoneDegree {
        /// Smallest degree tried.
        lo: usize,
        /// Largest degree tried.
        hi: usize,
        /// x where the data starts to fall.
        x0: f64,
        /// x of the next point.
        x1: f64,
        /// y at `x0`.
        y0: f64,
        /// y at `x1`.
        y1: f64,
    },
    /// `auto` could try no degree: too few points for its cross-validation.
    #[error(
        "{points} points are too few for --degree auto (its 10-fold cross-validation needs at \
         least {need}); give a --degree or more points"
    )]
    TooFewForAuto {
        /// Points given.
        points: usize,
        /// Points the lowest degree needs.
        need: usize,
    },
}

/// A Chebyshev series fitted on `domain` (the data interval).
#[derive(Debug, Clone, PartialEq)]
pub struct ChebFit {
    /// Polynomial degree (`coeffs.len() - 1`).
    pub degree: usize,
    /// `[min x, max x]` of the data.
    pub domain: [f64; 2],
    /// Chebyshev coefficients, units of y.
    pub coeffs: Vec<f64>,
}

/// Fit errors relative to full scale (`max |y|`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FitErrors {
    /// RMS of the residuals / max |y|.
    pub rms_rel: f64,
    /// Largest |residual| / max |y|.
    pub max_rel: f64,
}

/// One degree of a survey.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct DegreeRow {
    /// Degree.
    pub degree: usize,
    /// RMS error of the fit on all data, relative to full scale.
    pub rms_rel: f64,
    /// Largest error of the fit on all data, relative to full scale.
    pub max_rel: f64,
    /// Cross-validated RMS error (held-out points), relative to full scale.
    pub cv_rms_rel: f64,
    /// Whether the fit on all data is increasing (storable).
    pub monotone: bool,
}

impl ChebFit {
    /// Value at `x` (f64; polynomial continuation outside the domain).
    pub fn eval(&self, x: f64) -> f64 {
        cheb::eval(&self.coeffs, self.domain, x)
    }

    /// The law as the device stores it (f32 coefficients), checked increasing on the domain
    /// exactly as the bank reader checks it.
    pub fn law(&self) -> Result<TissueLaw, FitError> {
        let coeffs: Vec<f32> = self.coeffs.iter().map(|&c| c as f32).collect();
        let domain = self.domain.map(|v| v as f32);
        TissueLaw::chebyshev(&coeffs, domain).map_err(|reason| match reason {
            BankError::LawNotMonotone { sample } => {
                let [lo, hi] = self.domain;
                FitError::NotMonotone {
                    degree: self.degree,
                    at: lo + (hi - lo) * f64::from(sample) / f64::from(LAW_SAMPLES),
                    lo,
                    hi,
                }
            }
            reason => FitError::Law {
                degree: self.degree,
                reason,
            },
        })
    }

    /// Errors on `(x, y)` relative to full scale.
    pub fn errors(&self, x: &[f64], y: &[f64]) -> FitErrors {
        let residuals: Vec<f64> = x
            .iter()
            .zip(y)
            .map(|(&xi, &yi)| yi - self.eval(xi))
            .collect();
        relative_errors(&residuals, y)
    }
}

/// RMS and largest `|r|`, both divided by `max |y|`.
pub fn relative_errors(residuals: &[f64], y: &[f64]) -> FitErrors {
    let scale = y.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let n = residuals.len().max(1) as f64;
    let rms = (residuals.iter().map(|r| r * r).sum::<f64>() / n).sqrt();
    let max = residuals.iter().fold(0.0f64, |m, r| m.max(r.abs()));
    if scale > 0.0 {
        FitErrors {
            rms_rel: rms / scale,
            max_rel: max / scale,
        }
    } else {
        FitErrors {
            rms_rel: rms,
            max_rel: max,
        }
    }
}

/// Least-squares Chebyshev fit of `y(x)` of degree `degree` on `[min x, max x]`, by QR.
pub fn fit(x: &[f64], y: &[f64], degree: usize) -> Result<ChebFit, FitError> {
    if !(1..=MAX_DEGREE).contains(&degree) {
        return Err(FitError::Degree { degree });
    }
    let points = x.len().min(y.len());
    if points < degree + 2 {
        return Err(FitError::TooFewPoints { degree, points });
    }
    let (x, y) = (&x[..points], &y[..points]);
    let lo = x.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = x.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    if !(hi > lo && (hi - lo).is_finite()) {
        return Err(FitError::Domain { lo, hi });
    }
    let domain = [lo, hi];
    let a = cheb::design(x, domain, degree);
    let b = Mat::from_fn(points, 1, |i, _| y[i]);
    let c = a.qr().solve_lstsq(&b);
    Ok(ChebFit {
        degree,
        domain,
        coeffs: (0..=degree).map(|k| c[(k, 0)]).collect(),
    })
}

/// Cross-validated RMS error relative to full scale: `k = min(FOLDS, n)` interleaved folds
/// (point `i` is held out in fold `i mod k`, so every training set spans the data); each fold
/// is fitted on the other points and predicts its own.
pub fn cross_validate(x: &[f64], y: &[f64], degree: usize) -> Result<f64, FitError> {
    let n = x.len().min(y.len());
    let k = FOLDS.min(n).max(1);
    let mut residuals = Vec::with_capacity(n);
    for fold in 0..k {
        let (mut tx, mut ty, mut vx, mut vy) = (vec![], vec![], vec![], vec![]);
        for i in 0..n {
            if i % k == fold {
                vx.push(x[i]);
                vy.push(y[i]);
            } else {
                tx.push(x[i]);
                ty.push(y[i]);
            }
        }
        let f = fit(&tx, &ty, degree)?;
        residuals.extend(vx.iter().zip(&vy).map(|(&xi, &yi)| yi - f.eval(xi)));
    }
    Ok(relative_errors(&residuals, &y[..n]).rms_rel)
}

/// Fit, cross-validation and monotonicity for each degree (skipping degrees with too few
/// points).
pub fn survey(
    x: &[f64],
    y: &[f64],
    degrees: impl IntoIterator<Item = usize>,
) -> Result<Vec<DegreeRow>, FitError> {
    let mut rows = Vec::new();
    for degree in degrees {
        let n = x.len().min(y.len());
        // Each training set of the cross-validation must still over-determine the fit.
        if n - n.div_ceil(FOLDS.min(n).max(1)) < degree + 2 {
            continue;
        }
        let f = fit(x, y, degree)?;
        let e = f.errors(x, y);
        rows.push(DegreeRow {
            degree,
            rms_rel: e.rms_rel,
            max_rel: e.max_rel,
            cv_rms_rel: cross_validate(x, y, degree)?,
            monotone: f.law().is_ok(),
        });
    }
    Ok(rows)
}

/// The degree `auto` picks from a survey: the smallest increasing one whose cross-validated
/// error is at most `max(target_rms_rel, CV_SLACK x best)`, the best taken over increasing
/// fits.
pub fn choose(rows: &[DegreeRow], target_rms_rel: f64) -> Option<usize> {
    let ok = || {
        rows.iter()
            .filter(|r| r.monotone && r.cv_rms_rel.is_finite())
    };
    let best = ok().map(|r| r.cv_rms_rel).fold(f64::INFINITY, f64::min);
    let bar = target_rms_rel.max(CV_SLACK * best);
    ok().find(|r| r.cv_rms_rel <= bar).map(|r| r.degree)
}

/// Fits with `degree`, or the degree [`choose`] picks when `None`; the returned fit is
/// increasing, with its law. Also returns the survey of [`AUTO_DEGREES`] (empty for a fixed
/// degree).
pub fn fit_law(
    x: &[f64],
    y: &[f64],
    degree: Option<usize>,
    target_rms_rel: f64,
) -> Result<(ChebFit, TissueLaw, Vec<DegreeRow>), FitError> {
    let (degree, rows) = match degree {
        Some(d) => (d, Vec::new()),
        None => {
            let rows = survey(x, y, AUTO_DEGREES)?;
            match choose(&rows, target_rms_rel) {
                Some(d) => (d, rows),
                None => return Err(why_no_degree(x, y, &rows)),
            }
        }
    };
    let f = fit(x, y, degree)?;
    let law = f.law()?;
    Ok((f, law, rows))
}

/// Why [`choose`] found nothing in `rows`: too few points to try any degree, data that
/// decreases (where), or, for increasing data, what refuses the lowest degree's law (for
/// example a domain too narrow for f32, or a slope that f32 rounds to zero).
fn why_no_degree(x: &[f64], y: &[f64], rows: &[DegreeRow]) -> FitError {
    let n = x.len().min(y.len());
    let Some(first) = rows.first() else {
        // A training set of the cross-validation leaves one point out of n <= FOLDS, and
        // must still over-determine the lowest degree.
        return FitError::TooFewForAuto {
            points: n,
            need: *AUTO_DEGREES.start() + 3,
        };
    };
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&a, &b| x[a].total_cmp(&x[b]));
    if let Some(w) = order.windows(2).find(|w| y[w[1]] < y[w[0]]) {
        return FitError::NoMonotoneDegree {
            lo: *AUTO_DEGREES.start(),
            hi: *AUTO_DEGREES.end(),
            x0: x[w[0]],
            x1: x[w[1]],
            y0: y[w[0]],
            y1: y[w[1]],
        };
    }
    match fit(x, y, first.degree).and_then(|f| f.law()) {
        Err(e) => e,
        // Increasing and storable, yet not chosen: its cross-validation failed.
        Ok(_) => FitError::TooFewForAuto {
            points: n,
            need: first.degree + 3,
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn auto_says_why_it_found_no_degree() {
        // Three points: monotone, but too few for the cross-validation.
        let e = fit_law(&[0.0, 1.0, 2.0], &[0.0, 1.0, 2.0], None, 1e-3).unwrap_err();
        assert_eq!(e, FitError::TooFewForAuto { points: 3, need: 4 });
        // Decreasing data: where it falls.
        let x: Vec<f64> = (0..20).map(f64::from).collect();
        let y: Vec<f64> = x.iter().map(|v| 30.0 - v).collect();
        let e = fit_law(&x, &y, None, 1e-3).unwrap_err().to_string();
        assert!(
            e.contains("falls from 30 to 29 between x = 0 and x = 1"),
            "{e}"
        );
        // Increasing but so finely spaced that f32 cannot hold the domain: that is the reason.
        let x: Vec<f64> = (0..20).map(|i| 1.0 + 1e-12 * f64::from(i)).collect();
        let e = fit_law(&x, &x, None, 1e-3).unwrap_err();
        assert!(matches!(e, FitError::Law { .. }), "{e}");
    }

    #[test]
    fn exact_on_a_polynomial_of_the_fitted_degree() {
        let x: Vec<f64> = (0..30).map(|i| 0.1 * f64::from(i)).collect();
        let y: Vec<f64> = x.iter().map(|&v| 1.0 + 2.0 * v + 0.5 * v * v * v).collect();
        let f = fit(&x, &y, 3).unwrap();
        for (&xi, &yi) in x.iter().zip(&y) {
            assert!((f.eval(xi) - yi).abs() < 1e-12);
        }
        assert!(f.law().is_ok());
    }

    #[test]
    fn decreasing_fit_is_refused_with_location() {
        // y = -(x - 0.5)^2 + 2x decreases for x > 1.5.
        let x: Vec<f64> = (0..40).map(|i| 0.05 * f64::from(i)).collect();
        let y: Vec<f64> = x
            .iter()
            .map(|&v| 2.0 * v - (v - 0.5) * (v - 0.5) * 1.5)
            .collect();
        let e = fit(&x, &y, 2).unwrap().law().unwrap_err();
        match e {
            FitError::NotMonotone { at, .. } => assert!(at > 1.1 && at < 1.25, "{at}"),
            other => panic!("{other}"),
        }
    }

    #[test]
    fn too_few_points() {
        let e = fit(&[0.0, 1.0, 2.0], &[0.0, 1.0, 2.0], 2).unwrap_err();
        assert_eq!(
            e,
            FitError::TooFewPoints {
                degree: 2,
                points: 3
            }
        );
        assert_eq!(survey(&[], &[], AUTO_DEGREES), Ok(vec![]));
        let e = fit_law(&[], &[], None, 0.0).unwrap_err();
        assert_eq!(e, FitError::TooFewForAuto { points: 0, need: 4 });
    }
}
