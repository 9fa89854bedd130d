//! Cholesky factorisation `A = L L^T` of a small fixed-size symmetric positive definite matrix
//! (`D x D`, row-major arrays, f32) and the solves with it: the 3 x 3 `B C_SS B^T` of the
//! energy-minimal contact solve on the tick's path, the paper's 9 x 9 `C_SS` (eq. 6) off it.
//! Written out by hand rather than through nalgebra's `Cholesky`: it costs fewer instructions
//! on the MCU for the same result (`docs/firmware-loop.md`, "The card's crates"). Only the lower
//! triangle of `A` is read. No heap, no panics (every index goes through `get`).

/// `L` of `A = L L^T`, lower triangular (the strict upper triangle is zero).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cholesky<const D: usize> {
    l: [[f32; D]; D],
}

fn at<const D: usize>(m: &[[f32; D]; D], i: usize, j: usize) -> f32 {
    m.get(i).and_then(|r| r.get(j)).copied().unwrap_or(0.0)
}

fn set<const D: usize>(m: &mut [[f32; D]; D], i: usize, j: usize, v: f32) {
    if let Some(e) = m.get_mut(i).and_then(|r| r.get_mut(j)) {
        *e = v;
    }
}

impl<const D: usize> Cholesky<D> {
    /// The factor of the identity (`L = I`).
    // Evaluated at compile time: an index out of range would fail the build, never a tick.
    #[allow(clippy::indexing_slicing)]
    pub const IDENTITY: Cholesky<D> = {
        let mut l = [[0.0f32; D]; D];
        let mut i = 0;
        while i < D {
            l[i][i] = 1.0;
            i += 1;
        }
        Cholesky { l }
    };

    /// Factors `a` (its lower triangle), column by column: `L_jj = sqrt(a_jj - sum_k L_jk^2)`,
    /// `L_ij = (a_ij - sum_k L_ik L_jk) / L_jj` for `i > j`. `None` when a pivot is not
    /// positive (or NaN): `a` is not positive definite at f32 precision.
    pub fn new(a: &[[f32; D]; D]) -> Option<Cholesky<D>> {
        let mut l = [[0.0f32; D]; D];
        for j in 0..D {
            let mut d = at(a, j, j);
            for k in 0..j {
                let v = at(&l, j, k);
                d -= v * v;
            }
            // NaN is not positive either.
            if d.is_nan() || d <= 0.0 {
                return None;
            }
            let ljj = crate::vec3::sqrt(d);
            set(&mut l, j, j, ljj);
            for i in j + 1..D {
                let mut s = at(a, i, j);
                for k in 0..j {
                    s -= at(&l, i, k) * at(&l, j, k);
                }
                set(&mut l, i, j, s / ljj);
            }
        }
        Some(Cholesky { l })
    }

    /// The diagonal of `L` (the pivots' square roots).
    pub fn diagonal(&self) -> [f32; D] {
        core::array::from_fn(|i| at(&self.l, i, i))
    }

    /// `A^-1 b`: `L y = b` forward, then `L^T x = y` backward.
    pub fn solve(&self, b: &[f32; D]) -> [f32; D] {
        let mut y = [0.0f32; D];
        for i in 0..D {
            let mut s = b.get(i).copied().unwrap_or(0.0);
            for k in 0..i {
                s -= at(&self.l, i, k) * y.get(k).copied().unwrap_or(0.0);
            }
            if let Some(e) = y.get_mut(i) {
                *e = s / at(&self.l, i, i);
            }
        }
        let mut x = [0.0f32; D];
        for i in (0..D).rev() {
            let mut s = y.get(i).copied().unwrap_or(0.0);
            for k in i + 1..D {
                s -= at(&self.l, k, i) * x.get(k).copied().unwrap_or(0.0);
            }
            if let Some(e) = x.get_mut(i) {
                *e = s / at(&self.l, i, i);
            }
        }
        x
    }
}

#[cfg(test)]
#[allow(clippy::needless_range_loop)]
mod tests {
    extern crate std;
    use super::*;
    use crate::fixtures::gauss;
    use std::vec::Vec;

    /// An SPD matrix `M M^T + D` from a fixed pseudo-random `M`, scaled like a compliance.
    fn spd<const D: usize>(seed: u64) -> [[f32; D]; D] {
        let mut s = seed;
        let mut next = move || {
            s = s
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let m: Vec<Vec<f64>> = (0..D).map(|_| (0..D).map(|_| next()).collect()).collect();
        core::array::from_fn(|i| {
            core::array::from_fn(|j| {
                let mut v: f64 = (0..D).map(|k| m[i][k] * m[j][k]).sum();
                if i == j {
                    v += 0.1;
                }
                (1e-3 * v) as f32
            })
        })
    }

    fn check<const D: usize>(seed: u64) {
        let a = spd::<D>(seed);
        let b: [f32; D] =
            core::array::from_fn(|i| 1e-3 * (i as f32 + 1.0) * if i % 2 == 0 { 1.0 } else { -1.0 });
        let x = Cholesky::new(&a).unwrap().solve(&b);
        // Reference: f64 Gaussian elimination on the same (f32) entries.
        let a64: Vec<Vec<f64>> = a
            .iter()
            .map(|r| r.iter().map(|&v| f64::from(v)).collect())
            .collect();
        let want = gauss(a64, b.iter().map(|&v| f64::from(v)).collect());
        let norm = want.iter().map(|v| v * v).sum::<f64>().sqrt();
        let err = x
            .iter()
            .zip(&want)
            .map(|(&g, w)| (f64::from(g) - w).powi(2))
            .sum::<f64>()
            .sqrt()
            / norm;
        assert!(err < 1e-5, "D = {D}, seed {seed}: {err}");
        // L L^T reproduces A.
        let c = Cholesky::new(&a).unwrap();
        for i in 0..D {
            for j in 0..=i {
                let v: f32 = (0..D).map(|k| at(&c.l, i, k) * at(&c.l, j, k)).sum();
                assert!((v - a[i][j]).abs() <= 1e-6 * a[i][i].abs().max(a[j][j].abs()));
            }
        }
    }

    #[test]
    fn solves_spd_systems_against_f64_elimination() {
        for seed in 1..20 {
            check::<3>(seed);
            check::<9>(seed);
        }
    }

    #[test]
    fn refuses_matrices_that_are_not_positive_definite() {
        assert!(Cholesky::new(&[[1.0, 2.0], [2.0, 1.0]]).is_none());
        assert!(Cholesky::new(&[[0.0, 0.0], [0.0, 1.0]]).is_none());
        assert!(Cholesky::new(&[[f32::NAN, 0.0], [0.0, 1.0]]).is_none());
        let c = Cholesky::new(&[[4.0, 0.0], [2.0, 2.0]]).unwrap();
        // [[4, 2], [2, 2]] = L L^T with L = [[2, 0], [1, 1]].
        assert_eq!(c.diagonal(), [2.0, 1.0]);
        assert_eq!(c.solve(&[6.0, 4.0]), [1.0, 1.0]);
    }
}
