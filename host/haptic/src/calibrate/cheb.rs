//! The Chebyshev basis on a data interval: `T_k(t)`, `t = (2 x - (a + b)) / (b - a)` maps
//! `[a, b]` onto `[-1, 1]`. On that interval the basis is close to orthogonal for spread-out
//! samples, so least squares in it stays well conditioned at the paper's degrees (4 to 10);
//! the same coefficients are what [`bank_format::TissueLaw`] evaluates with Clenshaw's
//! recurrence on the device.

use faer::Mat;

/// `x` mapped from `domain = [a, b]` onto `[-1, 1]`.
pub fn to_unit(x: f64, domain: [f64; 2]) -> f64 {
    let [a, b] = domain;
    (2.0 * x - (a + b)) / (b - a)
}

/// `T_0(t) .. T_degree(t)` into `out` (length `degree + 1`), by the three-term recurrence
/// `T_{k+1} = 2 t T_k - T_{k-1}`.
pub fn basis(t: f64, out: &mut [f64]) {
    for k in 0..out.len() {
        out[k] = match k {
            0 => 1.0,
            1 => t,
            _ => 2.0 * t * out[k - 1] - out[k - 2],
        };
    }
}

/// The design matrix: row `i` is `T_0 .. T_degree` at `x[i]` on `domain`.
pub fn design(x: &[f64], domain: [f64; 2], degree: usize) -> Mat<f64> {
    let mut row = vec![0.0; degree + 1];
    let mut m = Mat::zeros(x.len(), degree + 1);
    for (i, &xi) in x.iter().enumerate() {
        basis(to_unit(xi, domain), &mut row);
        for (k, &v) in row.iter().enumerate() {
            m[(i, k)] = v;
        }
    }
    m
}

/// `sum_k coeffs[k] T_k(t(x))` in f64.
pub fn eval(coeffs: &[f64], domain: [f64; 2], x: f64) -> f64 {
    let mut row = vec![0.0; coeffs.len()];
    basis(to_unit(x, domain), &mut row);
    row.iter().zip(coeffs).map(|(t, c)| t * c).sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn basis_matches_cosines() {
        // T_k(cos th) = cos(k th).
        let mut row = [0.0; 11];
        for i in 0..=20 {
            let th = 0.15 * f64::from(i);
            basis(th.cos(), &mut row);
            for (k, v) in row.iter().enumerate() {
                assert!((v - (k as f64 * th).cos()).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn domain_ends_map_to_unit_ends() {
        assert_eq!(to_unit(2.0, [2.0, 6.0]), -1.0);
        assert_eq!(to_unit(6.0, [2.0, 6.0]), 1.0);
        assert_eq!(to_unit(4.0, [2.0, 6.0]), 0.0);
    }
}
