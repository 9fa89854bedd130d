//! Fung's quasi-linear viscoelasticity fitted to a bench ramp-and-hold test: the
//! reduced relaxation function `G(t) = g_inf + sum_k g_k exp(-t / tau_k)`, `G(0) = 1`, and
//! the instantaneous elastic response `Q_e(x)`, a monotone law of the displacement, together.
//!
//! **Model.** `F(t) = integral_0^t G(t - s) dQ_e(x(s))` (Fung, *Biomechanics*, 2nd ed., ch. 7)
//! over the measured `x(t)`, ramp and hold alike: the finite ramp is in the integral, so
//! nothing assumes an instantaneous step (the bias Abramowitch & Woo, J. Biomech. Eng. 126,
//! 2004, showed for the step assumption; they too fit ramp and hold together). `Q_e(x) = sum_j
//! c_j (x / x_max)^j`, `j = 1..=`[`ELASTIC_DEGREE`], `c_j >= 0`: increasing for `x >= 0`,
//! zero at zero. With the data taken as piecewise linear in time, each Prony term's
//! convolution is the exact recursion `H(i) = a H(i-1) + (1 - a) / (dt / tau) (u(i) - u(i-1))`,
//! `a = exp(-dt / tau)` (as the firmware's, `firmware::relax`).
//!
//! **Fit.** The model is linear in `c` for a fixed `G`, and in the Prony amplitudes for a
//! fixed `Q_e`: alternating non-negative least squares (Lawson & Hanson, *Solving Least
//! Squares Problems*, 1974, ch. 23: [`nnls`]) solves for one with the other fixed, then scales
//! so that `G(0) = 1`. Terms are chosen by the data: first on a log-spaced grid of
//! [`GRID_TAUS`] time constants over the test's time scales (NNLS leaves few non-zero), the
//! non-zero ones merged into clusters (neighbours on the grid), the largest
//! [`bank_format::MAX_PRONY_TERMS`] kept; then each count of terms from one to the clusters'
//! is refined (Nelder-Mead on `log tau`, the amplitudes by NNLS at each step), and the
//! smallest count whose RMS residual is within [`TERMS_RMS_SLACK`] of the best is taken.
//!
//! **Several tests** ([`fit_tests`]; e.g. ramps at several speeds): one `G` and one `Q_e` for
//! all, each test's hereditary integral over its own `x(t)` from rest, every row of every test
//! in one least-squares sum (the tests' columns concatenated); the grid spans the finest
//! sampling to the longest test. What one law cannot explain is reported per test
//! ([`TestFit`]: RMS residual against the test's noise, the peak-force error against its
//! standard error) and as a trend of the peak error against the ramp speed; a test beyond
//! [`RATE_WARN_RMS_OVER_NOISE`] noise levels or [`RATE_WARN_PEAK_SE`] standard errors is
//! warned about (QLV's `G` does not depend on the rate: a material whose relaxation does is
//! outside the model). The parameters' linearised standard errors (`standard_errors`) come
//! with the fit. [`run`] is `host calibrate relaxation`: files in, plot and scene out.
//!
//! **Refusals.** Data that is noise (the elastic response explains less than
//! [`MIN_SIGNAL_TO_NOISE`] times the noise) and data that does not relax (the fitted terms
//! lower the residual by less than [`MIN_RELAXATION_GAIN`] against the best elastic fit, or
//! relax less than [`MIN_RELAXATION_SNR`] noise levels of force) are refused, as is a test
//! without a hold.

mod command;
mod solvers;

pub use command::{Config, Report, TestReport, run};
pub use solvers::nnls;
use solvers::{nelder_mead, solve_spd};

use bank_format::MAX_PRONY_TERMS;

/// Degree of the instantaneous elastic law's polynomial in `x / x_max` (non-negative
/// coefficients).
pub const ELASTIC_DEGREE: usize = 3;
/// Time constants on the first, gridded, fit.
pub const GRID_TAUS: usize = 36;
/// A count of terms is taken when its RMS residual is within this factor of the best count's.
pub const TERMS_RMS_SLACK: f64 = 1.02;
/// The elastic response must explain this many noise levels of force (peak force over the
/// noise's standard deviation), or the data is refused as noise.
pub const MIN_SIGNAL_TO_NOISE: f64 = 20.0;
/// The relaxation must cut the elastic fit's RMS residual by this factor, or the data is
/// refused as not relaxing.
pub const MIN_RELAXATION_GAIN: f64 = 1.5;
/// The force the fitted terms relax over the hold must exceed this many noise levels.
pub const MIN_RELAXATION_SNR: f64 = 10.0;

/// Why a relaxation fit was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RelaxationError {
    /// Too few rows, or times not increasing.
    #[error("{0}")]
    Data(String),
    /// The displacement has no hold after its ramp.
    #[error(
        "no hold: the displacement must rise to its largest value and stay within 2 % of it for \
         at least a third of the test ({0})"
    )]
    NoHold(String),
    /// The force is noise.
    #[error(
        "the force is noise: the elastic response explains {snr:.1} noise levels, fewer than \
         {MIN_SIGNAL_TO_NOISE} (a wrong column, an unplugged load cell?)"
    )]
    Noise {
        /// Peak model force over the noise level.
        snr: f64,
    },
    /// The force does not relax.
    #[error(
        "the data does not relax: {why} (an elastic material, or a hold too short to see it); \
         keep the scene elastic"
    )]
    NoRelaxation {
        /// The measure that failed.
        why: String,
    },
}

/// `sum_j c_j xi^j`, `j = 1..`.
fn elastic(c: &[f64], xi: f64) -> f64 {
    c.iter()
        .enumerate()
        .map(|(j, &cj)| cj * xi.powi(j as i32 + 1))
        .sum()
}

/// `integral_0^t exp(-(t - s) / tau) du(s)` at every row for `u` piecewise linear in time
/// (exact recursion), `u` taken as 0 before the first row.
fn convolve(t: &[f64], u: &[f64], tau: f64) -> Vec<f64> {
    let mut out = Vec::with_capacity(u.len());
    let mut h = 0.0;
    for i in 0..u.len() {
        let (du, dt) = if i == 0 {
            (u[0], 0.0)
        } else {
            (u[i] - u[i - 1], t[i] - t[i - 1])
        };
        let x = dt / tau;
        let (a, b) = if x > 0.0 {
            ((-x).exp(), -(-x).exp_m1() / x)
        } else {
            (1.0, 1.0)
        };
        h = a * h + b * du;
        out.push(h);
    }
    out
}

/// The responses to `u` of `G`'s parts: `u` itself (g_inf) and each term's convolution.
fn columns(t: &[f64], u: &[f64], taus: &[f64]) -> Vec<Vec<f64>> {
    let mut cols = vec![u.to_vec()];
    cols.extend(taus.iter().map(|&tau| convolve(t, u, tau)));
    cols
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

fn rms(a: &[f64], b: &[f64]) -> f64 {
    (a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum::<f64>() / a.len() as f64).sqrt()
}

/// One test's rows, as the fit uses them.
struct Rows<'a> {
    /// Times, s.
    t: &'a [f64],
    /// `x / x_max` of the whole fit (all tests share `Q_e`'s domain).
    xi: Vec<f64>,
}

/// Each basis function `xi^j` of the elastic law, `j = 1..=`[`ELASTIC_DEGREE`]: its response to
/// every part of `G` (`columns`), each test's own history convolved on its own (every test
/// starts from rest), the tests' rows concatenated.
fn parts(tests: &[Rows], taus: &[f64]) -> Vec<Vec<Vec<f64>>> {
    (1..=ELASTIC_DEGREE)
        .map(|j| {
            let mut cols = vec![Vec::new(); taus.len() + 1];
            for test in tests {
                let u: Vec<f64> = test.xi.iter().map(|v| v.powi(j as i32)).collect();
                for (col, part) in cols.iter_mut().zip(columns(test.t, &u, taus)) {
                    col.extend(part);
                }
            }
            cols
        })
        .collect()
}

/// A fit for fixed time constants ([`fit_fixed`]).
struct Inner {
    /// The elastic law's `c_j`, N.
    c: Vec<f64>,
    /// `g_k`, one per time constant (`g_inf = 1 - sum`).
    g: Vec<f64>,
    /// The model's force per row (the tests' rows concatenated), N.
    model: Vec<f64>,
    /// RMS residual, N.
    rms: f64,
}

/// The QLV fit for fixed time constants `taus`, over every test at once (one `G`, one `Q_e`;
/// `f` the tests' forces concatenated): alternating NNLS on `c` (the elastic law, in
/// `xi = x / x_max`) and on the amplitudes `(g_inf, g_k)` of `G`, normalised to `G(0) = 1`,
/// while the residual falls (each half-step cannot raise it: both are least-squares optima
/// with the other half fixed).
fn fit_fixed(tests: &[Rows], f: &[f64], taus: &[f64]) -> Inner {
    // Each basis function's response to every part of G (computed once).
    let parts = parts(tests, taus);
    let (mut g_inf, mut g) = (0.5, vec![0.5 / taus.len().max(1) as f64; taus.len()]);
    let mut best = Inner {
        c: vec![0.0; ELASTIC_DEGREE],
        g: g.clone(),
        model: vec![0.0; f.len()],
        rms: rms(&vec![0.0; f.len()], f),
    };
    for _ in 0..200 {
        // c for fixed G.
        let cols: Vec<Vec<f64>> = parts
            .iter()
            .map(|p| {
                (0..f.len())
                    .map(|i| {
                        g_inf * p[0][i]
                            + g.iter().zip(&p[1..]).map(|(gk, h)| gk * h[i]).sum::<f64>()
                    })
                    .collect()
            })
            .collect();
        let mut c = nnls(&cols, f);
        // G's amplitudes for fixed Q_e: the parts' responses combine linearly in c.
        let amp_cols: Vec<Vec<f64>> = (0..=taus.len())
            .map(|k| {
                (0..f.len())
                    .map(|i| c.iter().zip(&parts).map(|(cj, p)| cj * p[k][i]).sum())
                    .collect()
            })
            .collect();
        let w = nnls(&amp_cols, f);
        let s: f64 = w.iter().sum();
        if s.is_nan() || s <= 0.0 {
            break;
        }
        g_inf = w[0] / s;
        g = w[1..].iter().map(|v| v / s).collect();
        c.iter_mut().for_each(|v| *v *= s);
        let model: Vec<f64> = (0..f.len())
            .map(|i| amp_cols.iter().zip(&w).map(|(col, wk)| wk * col[i]).sum())
            .collect();
        let r = rms(&model, f);
        let done = r.is_nan() || r >= best.rms * (1.0 - 1e-9);
        if r <= best.rms {
            best = Inner {
                c,
                g: g.clone(),
                model,
                rms: r,
            };
        }
        if done {
            break;
        }
    }
    best
}

/// One ramp-and-hold test to fit: times `t` (s, increasing), displacement `x` (m, compression
/// or indentation positive) and force `f` (N, same sign), named for messages (its file).
#[derive(Clone, Debug)]
pub struct Test {
    /// What the messages call it (the CSV's path).
    pub name: String,
    /// Times, s.
    pub t: Vec<f64>,
    /// Displacement, m.
    pub x: Vec<f64>,
    /// Force, N.
    pub f: Vec<f64>,
}

/// How the jointly fitted law does on one test.
#[derive(Clone, Debug, PartialEq)]
pub struct TestFit {
    /// The test's name ([`Test::name`]).
    pub name: String,
    /// Rows.
    pub rows: usize,
    /// The ramp's duration, s: the time from 2 % to 98 % of the test's largest displacement
    /// over 0.96 (the duration of a linear ramp with those crossings).
    pub ramp_s: f64,
    /// The ramp's mean speed, m/s: the largest displacement over [`TestFit::ramp_s`].
    pub rate_m_s: f64,
    /// The model's force at each row, N.
    pub model: Vec<f64>,
    /// RMS of `data - model` over the test, N.
    pub rms: f64,
    /// The test's noise (standard deviation from its hold's successive differences), N.
    pub noise: f64,
    /// The model's largest force over the test, N.
    pub peak_force: f64,
    /// `model - data` averaged over the [`PEAK_WINDOW`] rows centred on the model's peak, N
    /// (positive: the fit overshoots the peak).
    pub peak_error: f64,
    /// The standard error of [`TestFit::peak_error`] from the noise alone,
    /// `noise / sqrt(rows averaged)`, N.
    pub peak_error_se: f64,
}

impl TestFit {
    /// The RMS residual in noise levels (1 when the law explains everything but the noise).
    pub fn rms_over_noise(&self) -> f64 {
        self.rms / self.noise
    }

    /// The residual the noise does not account for, `sqrt(max(rms^2 - noise^2, 0))`, N.
    pub fn unexplained(&self) -> f64 {
        (self.rms * self.rms - self.noise * self.noise)
            .max(0.0)
            .sqrt()
    }
}

/// Rows averaged for a test's peak-force error.
pub const PEAK_WINDOW: usize = 11;
/// A test whose RMS residual exceeds this many times its noise is not explained by the law
/// (for Gaussian noise over the 2,000 or more rows of a bench test the ratio is 1 within a
/// few per cent, and the median-based noise estimate within about 5 %; the displacement's own
/// noise adds a few per cent more: 1.5 leaves a margin of ten times those).
pub const RATE_WARN_RMS_OVER_NOISE: f64 = 1.5;
/// A test whose peak-force error exceeds this many of its standard errors is not explained
/// by the law (a Gaussian mean beyond 5 standard errors by chance: under 1e-6).
pub const RATE_WARN_PEAK_SE: f64 = 5.0;

/// The fitted law.
#[derive(Clone, Debug, PartialEq)]
pub struct RelaxationFit {
    /// `g_inf = 1 - sum g`.
    pub g_inf: f64,
    /// `g_k`, by increasing `tau_k`.
    pub g: Vec<f64>,
    /// `tau_k`, s, increasing.
    pub tau_s: Vec<f64>,
    /// Linearised standard error of each `g_k` (`standard_errors`).
    pub g_se: Vec<f64>,
    /// Linearised standard error of each `tau_k`, s.
    pub tau_se: Vec<f64>,
    /// `c_j` of `Q_e(x) = sum_j c_j (x / x_max)^j`, N, `j = 1..`.
    pub elastic: Vec<f64>,
    /// `x_max`, m (the largest displacement of all tests).
    pub x_max: f64,
    /// Per test, in the order given.
    pub tests: Vec<TestFit>,
    /// RMS of `data - model` over every row of every test, N.
    pub rms: f64,
    /// RMS residual of the best elastic fit (`G = 1`), N.
    pub elastic_rms: f64,
    /// The noise's standard deviation, the tests' pooled by rows, N.
    pub noise: f64,
    /// Per count of terms tried: (count, RMS residual in N).
    pub survey: Vec<(usize, f64)>,
    /// The trend of the peak-force error (relative to each test's peak) against the ramp
    /// speed: least-squares slope per decade of speed (`None` with fewer than two speeds).
    pub peak_error_per_decade: Option<f64>,
    /// What the law leaves unexplained, one sentence each: with several tests, the rate
    /// dependence QLV cannot explain ([`RATE_WARN_RMS_OVER_NOISE`], [`RATE_WARN_PEAK_SE`]).
    pub warnings: Vec<String>,
}

impl RelaxationFit {
    /// `Q_e(x)`, N.
    pub fn elastic_at(&self, x: f64) -> f64 {
        elastic(&self.elastic, x / self.x_max)
    }
}

/// A test checked and measured before the fit.
struct Checked {
    /// The hold's duration, s.
    hold: f64,
    /// [`TestFit::ramp_s`].
    ramp_s: f64,
    /// Largest displacement, m.
    x_peak: f64,
    /// Noise, N.
    noise: f64,
}

/// Checks one test (rows, increasing time, a ramp then a hold) and estimates its noise.
fn check(test: &Test) -> Result<Checked, RelaxationError> {
    let (t, x, f) = (&test.t, &test.x, &test.f);
    let n = t.len();
    let name = &test.name;
    if n < 20 || x.len() != n || f.len() != n {
        return Err(RelaxationError::Data(format!(
            "{name}: {n} rows: a ramp and a hold need at least 20"
        )));
    }
    if let Some(i) = (1..n).find(|&i| t[i].is_nan() || t[i] <= t[i - 1]) {
        return Err(RelaxationError::Data(format!(
            "{name}: time does not increase at data row {}",
            i + 1
        )));
    }
    if let Some(i) = (0..n).find(|&i| !(t[i].is_finite() && x[i].is_finite() && f[i].is_finite())) {
        return Err(RelaxationError::Data(format!(
            "{name}: a value is not finite at data row {}",
            i + 1
        )));
    }
    let x_peak = x.iter().fold(0.0f64, |m, &v| m.max(v));
    if x_peak <= 0.0 {
        return Err(RelaxationError::NoHold(format!(
            "{name}: the displacement never rises above 0"
        )));
    }
    let peak_at = x.iter().position(|&v| v >= 0.98 * x_peak).unwrap_or(0);
    let hold_end = (peak_at..n).find(|&i| x[i] < 0.98 * x_peak).unwrap_or(n);
    let duration = t[n - 1] - t[0];
    let hold = t[hold_end - 1] - t[peak_at];
    if hold < duration / 3.0 || hold_end - peak_at < 10 {
        return Err(RelaxationError::NoHold(format!(
            "{name}: it holds {hold:.3} s of {duration:.3} s"
        )));
    }
    let start = x.iter().position(|&v| v >= 0.02 * x_peak).unwrap_or(0);
    let ramp_s = (t[peak_at] - t[start]) / 0.96;
    // Noise from the hold's successive differences (the relaxation's own change between rows
    // is second order there): sigma = rms(diff) / sqrt(2), from the median-based estimate so a
    // fast early relaxation does not count.
    let mut diffs: Vec<f64> = (peak_at + 1..hold_end)
        .map(|i| (f[i] - f[i - 1]).abs())
        .collect();
    diffs.sort_by(f64::total_cmp);
    let noise = diffs[diffs.len() / 2] / (0.6745 * std::f64::consts::SQRT_2);
    Ok(Checked {
        hold,
        ramp_s,
        x_peak,
        noise,
    })
}

/// Fits `G` and `Q_e` to one ramp-and-hold test: times `t` (s, increasing), displacement `x`
/// (m, compression or indentation positive) and force `f` (N, same sign).
pub fn fit(t: &[f64], x: &[f64], f: &[f64]) -> Result<RelaxationFit, RelaxationError> {
    fit_tests(&[Test {
        name: "the test".into(),
        t: t.to_vec(),
        x: x.to_vec(),
        f: f.to_vec(),
    }])
}

/// Fits one `G` and one `Q_e` to every test at once (each test's own ramp in its hereditary
/// integral, `F_i(t) = integral_0^t G(t - s) dQ_e(x_i(s))`, the residuals of all rows in one
/// least-squares sum), then reports per test what the joint law leaves: residual, peak-force
/// error, and with several tests the rate dependence QLV cannot explain (its `G` is the same
/// whatever the ramp: a test that the law misses beyond its noise is reported in
/// [`RelaxationFit::warnings`]).
pub fn fit_tests(tests: &[Test]) -> Result<RelaxationFit, RelaxationError> {
    if tests.is_empty() {
        return Err(RelaxationError::Data("no test to fit".into()));
    }
    let checked = tests.iter().map(check).collect::<Result<Vec<_>, _>>()?;
    let x_max = checked.iter().fold(0.0f64, |m, c| m.max(c.x_peak));
    let rows: Vec<Rows> = tests
        .iter()
        .map(|test| Rows {
            t: &test.t,
            xi: test.x.iter().map(|v| v / x_max).collect(),
        })
        .collect();
    let f: Vec<f64> = tests
        .iter()
        .flat_map(|test| test.f.iter().copied())
        .collect();
    let n_all = f.len();
    let noise = (tests
        .iter()
        .zip(&checked)
        .map(|(test, c)| test.t.len() as f64 * c.noise * c.noise)
        .sum::<f64>()
        / n_all as f64)
        .sqrt();

    let elastic_fit = fit_fixed(&rows, &f, &[]);
    let peak = elastic_fit.model.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let snr = peak / noise.max(1e-300);
    if snr.is_nan() || snr < MIN_SIGNAL_TO_NOISE {
        return Err(RelaxationError::Noise { snr });
    }

    // Gridded time constants: from the data's finest sampling (at least two bench samples)
    // to the longest test's length.
    let dt_min = tests
        .iter()
        .flat_map(|test| test.t.windows(2).map(|w| w[1] - w[0]))
        .fold(f64::INFINITY, f64::min);
    let duration = tests
        .iter()
        .map(|test| test.t[test.t.len() - 1] - test.t[0])
        .fold(0.0f64, f64::max);
    let lo = (2.0 * dt_min).max(f64::from(bank_format::RELAXATION_TAU_MIN_S));
    let hi = duration.min(f64::from(bank_format::RELAXATION_TAU_MAX_S));
    if hi <= lo {
        return Err(RelaxationError::Data(format!(
            "the longest test lasts {duration} s: too short for time constants above {lo} s"
        )));
    }
    let grid: Vec<f64> = (0..GRID_TAUS)
        .map(|i| lo * (hi / lo).powf(i as f64 / (GRID_TAUS - 1) as f64))
        .collect();
    let gridded = fit_fixed(&rows, &f, &grid);
    // Clusters of non-zero grid amplitudes (neighbours merge), weighted geometric mean tau.
    let mut clusters: Vec<(f64, f64)> = Vec::new(); // (amplitude, amplitude-weighted ln tau)
    let mut prev_on = false;
    for (k, &gk) in gridded.g.iter().enumerate() {
        let on = gk > 1e-4;
        if on {
            let ln = grid[k].ln();
            match clusters.last_mut() {
                Some(c) if prev_on => {
                    c.0 += gk;
                    c.1 += gk * ln;
                }
                _ => clusters.push((gk, gk * ln)),
            }
        }
        prev_on = on;
    }
    clusters.sort_by(|a, b| b.0.total_cmp(&a.0));
    clusters.truncate(MAX_PRONY_TERMS);
    let mut starts: Vec<f64> = clusters.iter().map(|c| c.1 / c.0).collect();
    if starts.is_empty() {
        return Err(RelaxationError::NoRelaxation {
            why: "no time constant on the grid takes any share of the force".into(),
        });
    }
    starts.sort_by(f64::total_cmp);

    // Refine each count of terms: the largest clusters, log tau by Nelder-Mead.
    let (ln_lo, ln_hi) = (lo.ln(), hi.ln());
    let mut survey = Vec::new();
    let mut best: Vec<(Vec<f64>, Inner)> = Vec::new();
    for count in 1..=starts.len() {
        let mut by_size = clusters[..count].to_vec();
        by_size.sort_by(|a, b| (a.1 / a.0).total_cmp(&(b.1 / b.0)));
        let x0: Vec<f64> = by_size.iter().map(|c| c.1 / c.0).collect();
        let objective = |ln_tau: &[f64]| {
            if ln_tau.iter().any(|&v| v < ln_lo - 0.5 || v > ln_hi + 1.0) {
                return f64::INFINITY;
            }
            let taus: Vec<f64> = ln_tau.iter().map(|v| v.exp()).collect();
            fit_fixed(&rows, &f, &taus).rms
        };
        let ln_tau = nelder_mead(objective, &x0, 0.3, 60 * count);
        let mut taus: Vec<f64> = ln_tau.iter().map(|v| v.exp()).collect();
        taus.sort_by(f64::total_cmp);
        let inner = fit_fixed(&rows, &f, &taus);
        survey.push((count, inner.rms));
        best.push((taus, inner));
    }
    let best_rms = survey.iter().map(|s| s.1).fold(f64::INFINITY, f64::min);
    let chosen = survey
        .iter()
        .position(|s| s.1 <= TERMS_RMS_SLACK * best_rms)
        .unwrap_or(0);
    let (taus, inner) = best.swap_remove(chosen);
    // Drop terms the fit gave no share (NNLS may zero one).
    let (g, tau_s): (Vec<f64>, Vec<f64>) = inner
        .g
        .iter()
        .zip(&taus)
        .filter(|(g, _)| **g > 0.0)
        .map(|(g, t)| (*g, *t))
        .unzip();

    if elastic_fit.rms < MIN_RELAXATION_GAIN * inner.rms {
        return Err(RelaxationError::NoRelaxation {
            why: format!(
                "relaxation lowers the RMS residual only from {:.3e} to {:.3e} N",
                elastic_fit.rms, inner.rms
            ),
        });
    }
    // Force the terms relax over the longest hold: Q_e(x_max) times their share that decays
    // in it.
    let hold = checked.iter().map(|c| c.hold).fold(0.0f64, f64::max);
    let q_peak = elastic(&inner.c, 1.0);
    let relaxed: f64 = g
        .iter()
        .zip(&tau_s)
        .map(|(gk, tk)| q_peak * gk * (1.0 - (-hold / tk).exp()))
        .sum();
    if relaxed.is_nan() || relaxed < MIN_RELAXATION_SNR * noise {
        return Err(RelaxationError::NoRelaxation {
            why: format!(
                "the fitted terms relax {relaxed:.3e} N over the hold, under {MIN_RELAXATION_SNR} \
                 noise levels ({noise:.3e} N)"
            ),
        });
    }

    // Per test: its rows of the joint model, residual, peak.
    let mut tests_fit = Vec::with_capacity(tests.len());
    let mut offset = 0;
    for (test, c) in tests.iter().zip(&checked) {
        let n = test.t.len();
        let model = inner.model[offset..offset + n].to_vec();
        offset += n;
        let at = (0..n)
            .max_by(|&i, &j| model[i].total_cmp(&model[j]))
            .unwrap_or(0);
        let (from, to) = (
            at.saturating_sub(PEAK_WINDOW / 2),
            (at + PEAK_WINDOW / 2 + 1).min(n),
        );
        let averaged = (to - from) as f64;
        tests_fit.push(TestFit {
            name: test.name.clone(),
            rows: n,
            ramp_s: c.ramp_s,
            rate_m_s: c.x_peak / c.ramp_s,
            rms: rms(&model, &test.f),
            noise: c.noise,
            peak_force: model[at],
            peak_error: (from..to).map(|i| model[i] - test.f[i]).sum::<f64>() / averaged,
            peak_error_se: c.noise / averaged.sqrt(),
            model,
        });
    }
    let (peak_error_per_decade, warnings) = rate_dependence(&tests_fit);
    let (g_se, tau_se) = standard_errors(&rows, &inner.c, &g, &tau_s, inner.rms);
    Ok(RelaxationFit {
        g_inf: 1.0 - g.iter().sum::<f64>(),
        g,
        tau_s,
        g_se,
        tau_se,
        elastic: inner.c,
        x_max,
        tests: tests_fit,
        rms: inner.rms,
        elastic_rms: elastic_fit.rms,
        noise,
        survey,
        peak_error_per_decade,
        warnings,
    })
}

/// The rate dependence the jointly fitted law leaves: the least-squares slope of the tests'
/// relative peak-force errors (`peak_error / peak_force`) against `log10` of their ramp
/// speeds (per decade; `None` with fewer than two distinct speeds), and one warning per test
/// whose RMS residual exceeds [`RATE_WARN_RMS_OVER_NOISE`] noise levels or whose peak error
/// exceeds [`RATE_WARN_PEAK_SE`] standard errors.
fn rate_dependence(tests: &[TestFit]) -> (Option<f64>, Vec<String>) {
    let pts: Vec<(f64, f64)> = tests
        .iter()
        .map(|t| (t.rate_m_s.log10(), t.peak_error / t.peak_force))
        .collect();
    let m = pts.len() as f64;
    let (mx, my) = (
        pts.iter().map(|p| p.0).sum::<f64>() / m,
        pts.iter().map(|p| p.1).sum::<f64>() / m,
    );
    let sxx: f64 = pts.iter().map(|p| (p.0 - mx) * (p.0 - mx)).sum();
    let sxy: f64 = pts.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    // Speeds within 1 % of each other are one speed.
    let slope = (sxx > m * 0.0043f64.powi(2)).then(|| sxy / sxx);
    let mut warnings = Vec::new();
    let off: Vec<&TestFit> = tests
        .iter()
        .filter(|t| {
            t.rms_over_noise() > RATE_WARN_RMS_OVER_NOISE
                || (t.peak_error / t.peak_error_se).abs() > RATE_WARN_PEAK_SE
        })
        .collect();
    for t in &off {
        warnings.push(format!(
            "{}: ramp {:.3} s ({:.3e} m/s): the joint law leaves an RMS residual of {:.2} noise \
             levels ({:.3e} N unexplained beyond the noise) and a peak-force error of {:+.2} % \
             ({:+.1} standard errors)",
            t.name,
            t.ramp_s,
            t.rate_m_s,
            t.rms_over_noise(),
            t.unexplained(),
            100.0 * t.peak_error / t.peak_force,
            t.peak_error / t.peak_error_se
        ));
    }
    if !off.is_empty() && tests.len() > 1 {
        warnings.push(format!(
            "rate dependence QLV cannot explain: one G(t) and one Q_e do not fit the {} ramps \
             within the noise (warned beyond {RATE_WARN_RMS_OVER_NOISE} noise levels RMS or \
             {RATE_WARN_PEAK_SE} standard errors at the peak){}; the material's relaxation \
             depends on the loading rate, so the law fitted is a compromise",
            tests.len(),
            slope.map_or(String::new(), |s| format!(
                ", peak-force error trend {:+.2} % per decade of ramp speed",
                100.0 * s
            ))
        ));
    }
    (slope, warnings)
}

/// Linearised standard errors of `g_k` and `tau_k` (Gauss-Newton: the covariance of the
/// parameters `p = (g_k, ln tau_k, c_j)` is `s^2 (J^T J)^-1`, `J` the model's derivatives at
/// every row, `s` the RMS residual; Seber & Wild, *Nonlinear Regression*, 1989, sec. 2.1).
/// `d/dg_k` and `d/dc_j` are exact (the model is linear in each); `d/d ln tau_k` is a central
/// difference of the convolution (step 1e-4).
fn standard_errors(
    tests: &[Rows],
    c: &[f64],
    g: &[f64],
    taus: &[f64],
    s: f64,
) -> (Vec<f64>, Vec<f64>) {
    let parts = parts(tests, taus);
    let n = parts[0][0].len();
    let kk = g.len();
    let g_inf = 1.0 - g.iter().sum::<f64>();
    let mut jac: Vec<Vec<f64>> = Vec::with_capacity(2 * kk + c.len());
    for k in 0..kk {
        jac.push(
            (0..n)
                .map(|i| {
                    c.iter()
                        .zip(&parts)
                        .map(|(cj, p)| cj * (p[k + 1][i] - p[0][i]))
                        .sum()
                })
                .collect(),
        );
    }
    let h = 1e-4f64;
    for k in 0..kk {
        let up = parts_one(tests, taus[k] * h.exp());
        let down = parts_one(tests, taus[k] * (-h).exp());
        jac.push(
            (0..n)
                .map(|i| {
                    g[k] * c
                        .iter()
                        .enumerate()
                        .map(|(j, cj)| cj * (up[j][i] - down[j][i]) / (2.0 * h))
                        .sum::<f64>()
                })
                .collect(),
        );
    }
    for p in &parts {
        jac.push(
            (0..n)
                .map(|i| {
                    g_inf * p[0][i]
                        + g.iter()
                            .enumerate()
                            .map(|(k, gk)| gk * p[k + 1][i])
                            .sum::<f64>()
                })
                .collect(),
        );
    }
    // Columns scaled to unit norm for the inverse, scaled back after.
    let norms: Vec<f64> = jac
        .iter()
        .map(|col| dot(col, col).sqrt().max(1e-300))
        .collect();
    let scaled: Vec<Vec<f64>> = jac
        .iter()
        .zip(&norms)
        .map(|(col, s)| col.iter().map(|v| v / s).collect())
        .collect();
    let m = scaled.len();
    let gram: Vec<Vec<f64>> = (0..m)
        .map(|a| (0..m).map(|b| dot(&scaled[a], &scaled[b])).collect())
        .collect();
    let all: Vec<usize> = (0..m).collect();
    let variance = |q: usize| {
        let mut e = vec![0.0; m];
        e[q] = 1.0;
        s * s * solve_spd(&gram, &e, &all)[q] / (norms[q] * norms[q])
    };
    let g_se = (0..kk).map(|k| variance(k).max(0.0).sqrt()).collect();
    let tau_se = (0..kk)
        .map(|k| taus[k] * variance(kk + k).max(0.0).sqrt())
        .collect();
    (g_se, tau_se)
}

/// Each elastic basis function's convolution with one time constant (`parts` for `tau`
/// alone, its `g_inf` column left out).
fn parts_one(tests: &[Rows], tau: f64) -> Vec<Vec<f64>> {
    parts(tests, &[tau])
        .into_iter()
        .map(|mut p| p.swap_remove(1))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// NNLS against a problem with a known answer: an exact non-negative combination is
    /// recovered; a negative one is clipped to the constrained optimum (checked by the KKT
    /// conditions).
    #[test]
    fn nnls_recovers_and_respects_the_bound() {
        let m = 30;
        let col = |k: usize| -> Vec<f64> {
            (0..m)
                .map(|i| ((i + 1) as f64 * 0.1 * (k + 1) as f64).sin() + 0.1 * k as f64)
                .collect()
        };
        let cols: Vec<Vec<f64>> = (0..4).map(col).collect();
        let want = [0.5, 0.0, 2.0, 0.25];
        let b: Vec<f64> = (0..m)
            .map(|i| (0..4).map(|k| want[k] * cols[k][i]).sum())
            .collect();
        let x = nnls(&cols, &b);
        for k in 0..4 {
            assert!((x[k] - want[k]).abs() < 1e-8, "{x:?}");
        }
        let b2: Vec<f64> = (0..m).map(|i| cols[0][i] - 3.0 * cols[1][i]).collect();
        let x = nnls(&cols, &b2);
        assert!(x.iter().all(|&v| v >= 0.0));
        // KKT: w = A^T (b - Ax) <= 0, and = 0 where x > 0.
        let r: Vec<f64> = (0..m)
            .map(|i| b2[i] - (0..4).map(|k| x[k] * cols[k][i]).sum::<f64>())
            .collect();
        for k in 0..4 {
            let w = dot(&cols[k], &r);
            assert!(w < 1e-8, "{k}: {w}");
            if x[k] > 0.0 {
                assert!(w.abs() < 1e-8, "{k}: {w}");
            }
        }
    }

    /// The recursion against the closed form of a ramp's convolution:
    /// `integral_0^t e^{-(t-s)/tau} r ds = r tau (1 - e^{-t/tau})`.
    #[test]
    fn the_convolution_of_a_ramp_is_exact() {
        let t: Vec<f64> = (0..200)
            .map(|i| 0.003 * i as f64 + 1e-4 * (i % 3) as f64)
            .collect();
        let u: Vec<f64> = t.iter().map(|&s| 2.0 * s).collect();
        let h = convolve(&t, &u, 0.1);
        for (i, &ti) in t.iter().enumerate() {
            let want = 2.0 * 0.1 * (1.0 - (-ti / 0.1).exp());
            // The first row is a step from 0 to u(t_0) at t_0.
            let step0 = 2.0 * t[0] * (-(ti - t[0]) / 0.1).exp();
            let want = want
                - 2.0 * 0.1 * (1.0 - (-t[0] / 0.1f64).exp()) * (-(ti - t[0]) / 0.1).exp()
                + step0;
            assert!((h[i] - want).abs() < 1e-12, "{i}: {} vs {want}", h[i]);
        }
    }
}
