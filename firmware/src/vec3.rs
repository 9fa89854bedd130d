//! Small 3-vector helpers on `[f32; 3]` shared by the loop's modules (f32, the `libm` square
//! root, so the MCU image and a native build compute bit for bit alike).

/// `sqrt(x)` (`libm::sqrtf`: correctly rounded, 53 instructions on the MCU; micromath's is
/// 10 but 6% off, README "the card's crates").
pub(crate) fn sqrt(x: f32) -> f32 {
    libm::sqrtf(x)
}

/// `a - b`.
pub(crate) fn sub(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// `a + b`.
pub(crate) fn add(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

/// `s a`.
pub(crate) fn scale(a: [f32; 3], s: f32) -> [f32; 3] {
    [a[0] * s, a[1] * s, a[2] * s]
}

/// `a . b`.
pub(crate) fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// `a x b`.
pub(crate) fn cross(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// `|a - b|^2`.
pub(crate) fn dist2(a: [f32; 3], b: [f32; 3]) -> f32 {
    let d = sub(a, b);
    dot(d, d)
}

/// `a / |a|`, `None` for a zero or non-finite vector.
pub(crate) fn unit(a: [f32; 3]) -> Option<[f32; 3]> {
    let n = sqrt(dot(a, a));
    (n > 0.0 && n.is_finite()).then(|| a.map(|x| x / n))
}
