//! The linear model's force for a displacement, computed here as the tests' own reference.

/// `W^-1 d` by Cramer's rule: the tool force (N) that the patch compliance `w` (m/N, symmetric
/// 3 x 3) gives for the displacement `d` (m), the energy-minimal contact solve on one point.
pub fn linear_force(w: [[f64; 3]; 3], d: [f64; 3]) -> [f64; 3] {
    let det3 = |m: [[f64; 3]; 3]| {
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
            - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    };
    let det = det3(w);
    std::array::from_fn(|c| {
        let mut m = w;
        for (row, di) in m.iter_mut().zip(d) {
            row[c] = di;
        }
        det3(m) / det
    })
}
