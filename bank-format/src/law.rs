//! The quasi non-linear tissue force law Q (paper section 3-4): maps the magnitude of the linear
//! model's force along the imposed displacement to the force the real tissue gives.
//!
//! Stored as a Chebyshev series on the fitted domain (well conditioned in f32, evaluated with
//! Clenshaw's recurrence, no libm), continued linearly outside it, so Q is never evaluated
//! blindly past the fitted range.

use crate::error::BankError;
use crate::layout::{LAW_CHEBYSHEV, LAW_LINEAR, LawRecord, MAX_LAW_COEFFS, SectionKind};

/// The series loop handles this many coefficients per pass (no remainder: the reversed
/// coefficient copy is zero-padded to a multiple of it, and zero coefficients leave Clenshaw's
/// recurrence unchanged).
const UNROLL: usize = 4;

/// Number of sample intervals used to check monotonicity: the derivative is checked at the
/// `LAW_SAMPLES + 1` points `x_j = -1 + 2 j / LAW_SAMPLES` of the normalised domain.
pub const LAW_SAMPLES: u32 = 256;

/// The shape of Q.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LawKind {
    /// `Q(f) = c0 + c1 f` everywhere.
    Linear,
    /// Chebyshev series on the domain, linear continuation outside.
    Chebyshev,
}

/// A validated tissue force law: monotone increasing, finite, on a non-degenerate domain.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TissueLaw {
    kind: LawKind,
    len: usize,
    coeffs: [f32; MAX_LAW_COEFFS],
    domain: [f32; 2],
    /// Q and dQ/df at f_min.
    lo: [f32; 2],
    /// Q and dQ/df at f_max.
    hi: [f32; 2],
    /// `c_K, .., c_1` (highest first), `K` = degree rounded up to a multiple of [`UNROLL`],
    /// zero beyond the degree.
    rev: [f32; MAX_LAW_COEFFS],
    /// `K`.
    rev_len: usize,
    /// `(f_min + f_max) / 2` and `2 / (f_max - f_min)`: `x = (f - mid) scale`.
    mid: f32,
    scale: f32,
    /// Q(0): `c0` of a linear law, the series or its continuation at 0 for a Chebyshev one.
    at_zero: f32,
}

impl TissueLaw {
    /// `Q(f) = offset_n + gain * f`; `gain > 0`. The domain is informative (the range the gain
    /// was measured on) but must be valid.
    pub fn linear(offset_n: f32, gain: f32, domain_n: [f32; 2]) -> Result<TissueLaw, BankError> {
        let mut coeffs = [0.0; MAX_LAW_COEFFS];
        coeffs[0] = offset_n;
        coeffs[1] = gain;
        TissueLaw::from_record(&LawRecord {
            kind: LAW_LINEAR,
            coeff_count: 2,
            domain_n,
            coeffs,
        })
    }

    /// `Q(f) = sum_i coeffs[i] T_i(x)`, `x = (2 f - (f_min + f_max)) / (f_max - f_min)`, with
    /// 1 to 16 coefficients in N; must be increasing on the domain.
    pub fn chebyshev(coeffs: &[f32], domain_n: [f32; 2]) -> Result<TissueLaw, BankError> {
        let count = coeffs.len();
        let mut stored = [0.0; MAX_LAW_COEFFS];
        match stored.get_mut(..count) {
            Some(dst) if count > 0 => dst.copy_from_slice(coeffs),
            _ => {
                return Err(BankError::LawCoefficientCount {
                    count: u32::try_from(count).unwrap_or(u32::MAX),
                });
            }
        }
        TissueLaw::from_record(&LawRecord {
            kind: LAW_CHEBYSHEV,
            coeff_count: count as u32,
            domain_n,
            coeffs: stored,
        })
    }

    /// Validate a stored record (the checks listed in `SPEC.md`, in this order: kind,
    /// coefficient count, finite values, unused coefficients zero, domain, monotonicity).
    pub fn from_record(record: &LawRecord) -> Result<TissueLaw, BankError> {
        let section = SectionKind::TissueLaw;
        let kind = match record.kind {
            LAW_LINEAR => LawKind::Linear,
            LAW_CHEBYSHEV => LawKind::Chebyshev,
            kind => return Err(BankError::LawKind { kind }),
        };
        let count = record.coeff_count;
        let len = count as usize;
        let count_ok = match kind {
            LawKind::Linear => len == 2,
            LawKind::Chebyshev => (1..=MAX_LAW_COEFFS).contains(&len),
        };
        if !count_ok {
            return Err(BankError::LawCoefficientCount { count });
        }
        if !record
            .coeffs
            .iter()
            .chain(&record.domain_n)
            .all(|v| v.is_finite())
        {
            return Err(BankError::NonFinite { section, entry: 0 });
        }
        if record.coeffs.iter().skip(len).any(|&c| c != 0.0) {
            return Err(BankError::ReservedNotZero { section });
        }
        let [a, b] = record.domain_n;
        if !(a >= 0.0 && b > a && (b - a) >= 1.0e-5 * b.max(1.0e-3)) {
            return Err(BankError::LawDomain);
        }
        let mut law = TissueLaw {
            kind,
            len,
            coeffs: record.coeffs,
            domain: record.domain_n,
            lo: [0.0; 2],
            hi: [0.0; 2],
            rev: [0.0; MAX_LAW_COEFFS],
            rev_len: 0,
            mid: ((f64::from(a) + f64::from(b)) / 2.0) as f32,
            scale: (2.0 / (f64::from(b) - f64::from(a))) as f32,
            at_zero: 0.0,
        };
        let degree = len.saturating_sub(1);
        law.rev_len = degree.div_ceil(UNROLL) * UNROLL;
        for (j, slot) in law.rev.iter_mut().take(law.rev_len).enumerate() {
            // c_{K - j}; past the degree the record holds zeros, past the array too.
            *slot = record.coeffs.get(law.rev_len - j).copied().unwrap_or(0.0);
        }
        match kind {
            LawKind::Linear => {
                if !(record.coeffs[1] > 0.0) {
                    return Err(BankError::LawNotMonotone { sample: 0 });
                }
            }
            LawKind::Chebyshev => {
                let mut deriv = [0.0f64; MAX_LAW_COEFFS];
                let dlen = chebyshev_derivative(law.coeffs(), &mut deriv);
                let scale = 2.0 / (f64::from(b) - f64::from(a));
                for j in 0..=LAW_SAMPLES {
                    let x = -1.0 + 2.0 * f64::from(j) / f64::from(LAW_SAMPLES);
                    let slope = clenshaw_f64(deriv.get(..dlen).unwrap_or(&[]), x) * scale;
                    // NaN fails too.
                    if !(slope > 0.0) {
                        return Err(BankError::LawNotMonotone { sample: j });
                    }
                }
                let ends = |x: f64| -> [f32; 2] {
                    let q = law.series(x as f32);
                    let dq = clenshaw_f64(deriv.get(..dlen).unwrap_or(&[]), x) * scale;
                    [q, dq as f32]
                };
                let (lo, hi) = (ends(-1.0), ends(1.0));
                law.lo = lo;
                law.hi = hi;
                // Slopes can underflow f32 although positive in f64; the continuation must rise.
                if !(law.lo[1] > 0.0 && law.lo[1].is_finite()) {
                    return Err(BankError::LawNotMonotone { sample: 0 });
                }
                if !(law.hi[1] > 0.0 && law.hi[1].is_finite()) {
                    return Err(BankError::LawNotMonotone {
                        sample: LAW_SAMPLES,
                    });
                }
                if !(law.lo[0].is_finite() && law.hi[0].is_finite()) {
                    return Err(BankError::NonFinite { section, entry: 0 });
                }
            }
        }
        law.at_zero = law.eval(0.0);
        if !law.at_zero.is_finite() {
            return Err(BankError::NonFinite { section, entry: 0 });
        }
        Ok(law)
    }

    /// The stored form.
    pub fn to_record(&self) -> LawRecord {
        LawRecord {
            kind: match self.kind {
                LawKind::Linear => LAW_LINEAR,
                LawKind::Chebyshev => LAW_CHEBYSHEV,
            },
            coeff_count: self.len as u32,
            domain_n: self.domain,
            coeffs: self.coeffs,
        }
    }

    /// Linear or Chebyshev.
    pub fn kind(&self) -> LawKind {
        self.kind
    }

    /// The coefficients in use (linear: `[c0, c1]`; Chebyshev: `c_0..c_{n-1}`), N.
    pub fn coeffs(&self) -> &[f32] {
        self.coeffs.get(..self.len).unwrap_or(&[])
    }

    /// The fitted domain `[f_min, f_max]`, N.
    pub fn domain(&self) -> [f32; 2] {
        self.domain
    }

    /// Q(0), N ([`TissueLaw::eval`] at 0, kept from validation): what the law alone would
    /// render at zero penetration. A linear law's offset, or a fit continued below its domain,
    /// can make it positive; the firmware blends that out near zero
    /// (`firmware::solve::apply_tissue_law`), so the rendered force is 0 at the surface.
    pub fn at_zero(&self) -> f32 {
        self.at_zero
    }

    /// Q(f) in N for a linear-model force magnitude `f` in N. Inside the domain: Clenshaw in
    /// f32 at `x = (f - mid) scale` (for `f` in the domain `|x| <= 1` up to rounding, so no
    /// clamp is needed); outside: the tangent line at the nearer end. NaN in, NaN out.
    pub fn eval(&self, f: f32) -> f32 {
        let [a, b] = self.domain;
        match self.kind {
            LawKind::Linear => self.coeffs[0] + self.coeffs[1] * f,
            LawKind::Chebyshev => {
                if f < a {
                    self.lo[0] + self.lo[1] * (f - a)
                } else if f > b {
                    self.hi[0] + self.hi[1] * (f - b)
                } else {
                    self.series((f - self.mid) * self.scale)
                }
            }
        }
    }

    /// dQ/df (dimensionless) at `f`: the derivative series inside the domain, the end slopes
    /// outside.
    pub fn slope(&self, f: f32) -> f32 {
        let [a, b] = self.domain;
        match self.kind {
            LawKind::Linear => self.coeffs[1],
            LawKind::Chebyshev => {
                if f < a {
                    self.lo[1]
                } else if f > b {
                    self.hi[1]
                } else {
                    let mut deriv = [0.0f64; MAX_LAW_COEFFS];
                    let dlen = chebyshev_derivative(self.coeffs(), &mut deriv);
                    let x = ((2.0 * f - (a + b)) / (b - a)).clamp(-1.0, 1.0);
                    let scale = 2.0 / (f64::from(b) - f64::from(a));
                    (clenshaw_f64(deriv.get(..dlen).unwrap_or(&[]), f64::from(x)) * scale) as f32
                }
            }
        }
    }
}

impl TissueLaw {
    /// `sum_k c_k T_k(x)` by Clenshaw's recurrence in f32, [`UNROLL`] coefficients per pass
    /// over the zero-padded reversed copy (a loop without remainder handling). Inlined so the
    /// 1 kHz loop's call of [`TissueLaw::eval`] makes no further call.
    #[inline(always)]
    fn series(&self, x: f32) -> f32 {
        let x2 = x + x;
        let (mut b1, mut b2) = (0.0f32, 0.0f32);
        // At most MAX_LAW_COEFFS / UNROLL passes over a fixed-size array: the compiler lays
        // them out straight, without remainder handling.
        for quad in self.rev.chunks_exact(UNROLL).take(self.rev_len / UNROLL) {
            for &ck in quad {
                let b0 = ck + x2 * b1 - b2;
                b2 = b1;
                b1 = b0;
            }
        }
        self.coeffs[0] + x * b1 - b2
    }
}

/// `sum_k c_k T_k(x)` by Clenshaw's recurrence, f64.
fn clenshaw_f64(c: &[f64], x: f64) -> f64 {
    let (mut b1, mut b2) = (0.0f64, 0.0f64);
    let Some((c0, rest)) = c.split_first() else {
        return 0.0;
    };
    for &ck in rest.iter().rev() {
        let b0 = ck + 2.0 * x * b1 - b2;
        b2 = b1;
        b1 = b0;
    }
    c0 + x * b1 - b2
}

/// Chebyshev coefficients of d/dx of the series `c` (in f64); returns their count (at least 1).
fn chebyshev_derivative(c: &[f32], out: &mut [f64; MAX_LAW_COEFFS]) -> usize {
    *out = [0.0; MAX_LAW_COEFFS];
    let n = c.len().min(MAX_LAW_COEFFS);
    if n < 2 {
        return 1;
    }
    // d_{k-1} = d_{k+1} + 2 k c_k, k = n-1 .. 1; then d_0 /= 2.
    let mut d_next = 0.0f64; // d_{k+1}
    let mut d_cur = 0.0f64; // d_k
    for k in (1..n).rev() {
        let ck = f64::from(*c.get(k).unwrap_or(&0.0));
        let d_prev = d_next + 2.0 * (k as f64) * ck;
        if let Some(slot) = out.get_mut(k - 1) {
            *slot = d_prev;
        }
        d_next = d_cur;
        d_cur = d_prev;
    }
    out[0] *= 0.5;
    n - 1
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn derivative_of_t3_is_3u2() {
        // T3 = 4x^3 - 3x, T3' = 12x^2 - 3 = 3 T0 + 6 T2.
        let mut d = [0.0; MAX_LAW_COEFFS];
        let n = chebyshev_derivative(&[0.0, 0.0, 0.0, 1.0], &mut d);
        assert_eq!(n, 3);
        assert_eq!(&d[..3], &[3.0, 0.0, 6.0]);
    }

    #[test]
    fn clenshaw_matches_power_form() {
        // On the domain [0, 2], x = f - 1.
        let law = TissueLaw::chebyshev(&[0.5, 1.0, 0.25, 0.125], [0.0, 2.0]).unwrap();
        for i in 0..=20 {
            let x = -1.0 + 0.1 * i as f32;
            let t2 = 2.0 * x * x - 1.0;
            let t3 = 4.0 * x * x * x - 3.0 * x;
            let want = 0.5 + x + 0.25 * t2 + 0.125 * t3;
            assert!((law.series(x) - want).abs() < 1e-6);
            assert!((law.eval(x + 1.0) - want).abs() < 1e-6);
        }
    }

    #[test]
    fn padding_to_the_unroll_does_not_change_the_series() {
        // Degrees 1 ..= 15 against the plain recurrence in f64.
        for degree in 1..MAX_LAW_COEFFS {
            let c: [f32; MAX_LAW_COEFFS] = core::array::from_fn(|k| {
                if k == 1 {
                    8.0
                } else {
                    0.3 / (1 + k * k) as f32
                }
            });
            let c = &c[..=degree];
            let law = TissueLaw::chebyshev(c, [1.0, 3.0]).unwrap();
            let c64: [f64; MAX_LAW_COEFFS] =
                core::array::from_fn(|k| c.get(k).map_or(0.0, |&v| f64::from(v)));
            for i in 0..=40 {
                let x = -1.0 + 0.05 * f64::from(i);
                let want = clenshaw_f64(&c64[..=degree], x);
                let got = f64::from(law.series(x as f32));
                assert!(
                    (got - want).abs() < 1e-5,
                    "degree {degree} x {x}: {got} vs {want}"
                );
            }
        }
    }
}
