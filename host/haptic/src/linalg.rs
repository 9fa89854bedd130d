//! Small dense linear algebra on 3 x 3 blocks (a patch compliance `W`, m/N), shared by the
//! convergence study, the display fields and the report.

use fem::compliance::Block3;
use fem::vec3::dot;

/// `W^-1 d` (Cramer's rule): the tool force of a patch compliance `W` (m/N) at displacement
/// `d` (m), N.
pub fn solve3(w: &Block3, d: [f64; 3]) -> [f64; 3] {
    let det = |m: [[f64; 3]; 3]| {
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
            - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    };
    let whole = det(*w);
    std::array::from_fn(|c| {
        let mut m = *w;
        for (r, row) in m.iter_mut().enumerate() {
            row[c] = d[r];
        }
        det(m) / whole
    })
}

/// `n . W n`.
pub fn normal_compliance(w: &Block3, n: [f64; 3]) -> f64 {
    let wn: [f64; 3] = std::array::from_fn(|i| dot(w[i], n));
    dot(n, wn)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn solve3_inverts_a_general_matrix() {
        let a = [[4.0, 1.0, 0.5], [2.0, 3.0, 1.0], [0.0, 1.0, 5.0]];
        let d = [1.0, -2.0, 0.5];
        let x = solve3(&a, d);
        for (row, want) in a.iter().zip(d) {
            assert!((dot(*row, x) - want).abs() < 1e-12, "{x:?}");
        }
        let singular = [[1.0, 2.0, 3.0], [2.0, 4.0, 6.0], [0.0, 0.0, 1.0]];
        assert!(!solve3(&singular, d).iter().all(|v| v.is_finite()));
    }

    /// `n . W n` by hand for a symmetric `W` and a unit `n`.
    #[test]
    fn normal_compliance_is_the_quadratic_form() {
        let w = [[2.0, 0.5, 0.0], [0.5, 1.0, 0.25], [0.0, 0.25, 3.0]];
        let s = 0.5f64.sqrt();
        // n = (s, s, 0): (2 + 2 * 0.5 + 1) * 0.5 = 2.
        assert!((normal_compliance(&w, [s, s, 0.0]) - 2.0).abs() < 1e-12);
        assert_eq!(normal_compliance(&w, [0.0, 0.0, 1.0]), 3.0);
    }
}
