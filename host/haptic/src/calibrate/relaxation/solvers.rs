//! The numerical solvers of the relaxation fit: non-negative least squares (Lawson & Hanson,
//! *Solving Least Squares Problems*, 1974, ch. 23) and Nelder-Mead minimisation.

use super::dot;

/// Non-negative least squares, `min |A x - b|`, `x >= 0` (Lawson & Hanson's active-set
/// algorithm, ch. 23), `A` given by columns. Solves the passive set's normal equations by
/// Cholesky; columns are scaled to unit norm first (the result is scaled back).
pub fn nnls(cols: &[Vec<f64>], b: &[f64]) -> Vec<f64> {
    let n = cols.len();
    let norms: Vec<f64> = cols
        .iter()
        .map(|c| c.iter().map(|v| v * v).sum::<f64>().sqrt())
        .collect();
    let a: Vec<Vec<f64>> = cols
        .iter()
        .zip(&norms)
        .map(|(c, &s)| {
            let s = if s > 0.0 { s } else { 1.0 };
            c.iter().map(|v| v / s).collect()
        })
        .collect();
    let gram: Vec<Vec<f64>> = (0..n)
        .map(|i| (0..n).map(|j| dot(&a[i], &a[j])).collect())
        .collect();
    let atb: Vec<f64> = a.iter().map(|c| dot(c, b)).collect();
    let mut x = vec![0.0; n];
    let mut passive = vec![false; n];
    let tol = 1e-12 * atb.iter().fold(0.0f64, |m, v| m.max(v.abs())).max(1e-300);
    for _ in 0..3 * n + 10 {
        // Gradient of -|Ax - b|^2 / 2: w = A^T (b - A x).
        let w: Vec<f64> = (0..n)
            .map(|i| atb[i] - (0..n).map(|j| gram[i][j] * x[j]).sum::<f64>())
            .collect();
        let Some(enter) = (0..n)
            .filter(|&i| !passive[i] && w[i] > tol)
            .max_by(|&i, &j| w[i].total_cmp(&w[j]))
        else {
            break;
        };
        passive[enter] = true;
        loop {
            let set: Vec<usize> = (0..n).filter(|&i| passive[i]).collect();
            let z = solve_spd(&gram, &atb, &set);
            if set.iter().zip(&z).all(|(_, &zi)| zi > 0.0) {
                for (&i, &zi) in set.iter().zip(&z) {
                    x[i] = zi;
                }
                break;
            }
            // Step toward z until a passive variable reaches zero; drop it.
            let mut alpha = 1.0f64;
            for (&i, &zi) in set.iter().zip(&z) {
                if zi <= 0.0 {
                    alpha = alpha.min(x[i] / (x[i] - zi));
                }
            }
            for (&i, &zi) in set.iter().zip(&z) {
                x[i] += alpha * (zi - x[i]);
                if x[i] <= 1e-15 * (1.0 + zi.abs()) {
                    x[i] = 0.0;
                    passive[i] = false;
                }
            }
            if !set.iter().any(|&i| passive[i]) {
                break;
            }
        }
    }
    x.iter()
        .zip(&norms)
        .map(|(&v, &s)| if s > 0.0 { v / s } else { 0.0 })
        .collect()
}

/// The solution of the normal equations restricted to `set` (Cholesky with a tiny ridge).
pub(super) fn solve_spd(gram: &[Vec<f64>], rhs: &[f64], set: &[usize]) -> Vec<f64> {
    let m = set.len();
    let mut l = vec![vec![0.0; m]; m];
    for i in 0..m {
        for j in 0..=i {
            let mut s = gram[set[i]][set[j]];
            if i == j {
                s += 1e-13;
            }
            s -= l[i][..j]
                .iter()
                .zip(&l[j][..j])
                .map(|(a, b)| a * b)
                .sum::<f64>();
            l[i][j] = if i == j {
                s.max(1e-300).sqrt()
            } else {
                s / l[j][j]
            };
        }
    }
    let mut y = vec![0.0; m];
    for i in 0..m {
        let s: f64 = (0..i).map(|k| l[i][k] * y[k]).sum();
        y[i] = (rhs[set[i]] - s) / l[i][i];
    }
    let mut z = vec![0.0; m];
    for i in (0..m).rev() {
        let s: f64 = (i + 1..m).map(|k| l[k][i] * z[k]).sum();
        z[i] = (y[i] - s) / l[i][i];
    }
    z
}

/// Nelder-Mead minimisation of `f` from `x0` with initial steps `step`.
pub(super) fn nelder_mead(
    f: impl Fn(&[f64]) -> f64,
    x0: &[f64],
    step: f64,
    iters: usize,
) -> Vec<f64> {
    let n = x0.len();
    let mut pts: Vec<Vec<f64>> = vec![x0.to_vec()];
    for i in 0..n {
        let mut p = x0.to_vec();
        p[i] += step;
        pts.push(p);
    }
    let mut vals: Vec<f64> = pts.iter().map(|p| f(p)).collect();
    for _ in 0..iters {
        let mut idx: Vec<usize> = (0..=n).collect();
        idx.sort_by(|&a, &b| vals[a].total_cmp(&vals[b]));
        pts = idx.iter().map(|&i| pts[i].clone()).collect();
        vals = idx.iter().map(|&i| vals[i]).collect();
        if (vals[n] - vals[0]).abs() <= 1e-10 * vals[0].abs() {
            break;
        }
        let centroid: Vec<f64> = (0..n)
            .map(|d| pts[..n].iter().map(|p| p[d]).sum::<f64>() / n as f64)
            .collect();
        let along = |s: f64| -> Vec<f64> {
            (0..n)
                .map(|d| centroid[d] + s * (pts[n][d] - centroid[d]))
                .collect()
        };
        let r = along(-1.0);
        let fr = f(&r);
        if fr < vals[0] {
            let e = along(-2.0);
            let fe = f(&e);
            (pts[n], vals[n]) = if fe < fr { (e, fe) } else { (r, fr) };
        } else if fr < vals[n - 1] {
            (pts[n], vals[n]) = (r, fr);
        } else {
            let k = along(0.5);
            let fk = f(&k);
            if fk < vals[n] {
                (pts[n], vals[n]) = (k, fk);
            } else {
                for i in 1..=n {
                    pts[i] = (0..n)
                        .map(|d| pts[0][d] + 0.5 * (pts[i][d] - pts[0][d]))
                        .collect();
                    vals[i] = f(&pts[i]);
                }
            }
        }
    }
    let best = (0..=n)
        .min_by(|&a, &b| vals[a].total_cmp(&vals[b]))
        .unwrap_or(0);
    pts.swap_remove(best)
}
