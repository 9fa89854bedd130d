//! Exact orientation predicates for the self-intersection test: the sign of `orient2d` and
//! `orient3d` as exact arithmetic on the `f64` inputs would give it. A floating-point filter
//! (Shewchuk's first error bounds) answers almost every call; the rest are evaluated exactly
//! with floating-point expansions (sums of non-overlapping `f64`s; Shewchuk, "Adaptive
//! precision floating-point arithmetic and fast robust geometric predicates", 1997), without
//! his intermediate adaptive stages. Exact unless a product underflows (coordinates below
//! about 1e-150), which an organ's surface does not reach.

use std::cmp::Ordering;

const EPS: f64 = f64::EPSILON * 0.5;

/// `a + b` as `(rounded sum, exact error)`.
fn two_sum(a: f64, b: f64) -> (f64, f64) {
    let x = a + b;
    let bv = x - a;
    let av = x - bv;
    (x, (a - av) + (b - bv))
}

/// `a * b` as `(rounded product, exact error)` (the fused multiply-add is exact).
fn two_product(a: f64, b: f64) -> (f64, f64) {
    let x = a * b;
    (x, a.mul_add(b, -x))
}

/// An exact sum of `f64` components, non-overlapping, in increasing magnitude.
#[derive(Debug, Clone)]
struct Expansion(Vec<f64>);

impl Expansion {
    /// `a - b`, exactly.
    fn diff(a: f64, b: f64) -> Expansion {
        let (x, y) = two_sum(a, -b);
        Expansion(vec![y, x])
    }

    /// `self + b` (Shewchuk's Grow-Expansion, zero components dropped).
    fn grow(&self, b: f64) -> Expansion {
        let mut q = b;
        let mut out = Vec::with_capacity(self.0.len() + 1);
        for &e in &self.0 {
            let (x, y) = two_sum(q, e);
            if y != 0.0 {
                out.push(y);
            }
            q = x;
        }
        if q != 0.0 || out.is_empty() {
            out.push(q);
        }
        Expansion(out)
    }

    /// `self + other`.
    fn add(&self, other: &Expansion) -> Expansion {
        other.0.iter().fold(self.clone(), |acc, &b| acc.grow(b))
    }

    /// `self - other`.
    fn sub(&self, other: &Expansion) -> Expansion {
        other.0.iter().fold(self.clone(), |acc, &b| acc.grow(-b))
    }

    /// `self * other`.
    fn mul(&self, other: &Expansion) -> Expansion {
        let mut acc = Expansion(vec![0.0]);
        for &a in &self.0 {
            for &b in &other.0 {
                let (x, y) = two_product(a, b);
                acc = acc.grow(y).grow(x);
            }
        }
        acc
    }

    /// The sign of the sum: that of its largest (last non-zero) component.
    fn sign(&self) -> Ordering {
        self.0
            .iter()
            .rev()
            .find(|&&x| x != 0.0)
            .map_or(Ordering::Equal, |x| {
                x.partial_cmp(&0.0).unwrap_or(Ordering::Equal)
            })
    }
}

fn sign_of(x: f64) -> Ordering {
    x.partial_cmp(&0.0).unwrap_or(Ordering::Equal)
}

/// The sign of `det[a - c; b - c]`: `Greater` when `a b c` turn counter-clockwise.
pub fn orient2d(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> Ordering {
    let l = (a[0] - c[0]) * (b[1] - c[1]);
    let r = (a[1] - c[1]) * (b[0] - c[0]);
    let det = l - r;
    let bound = (3.0 + 16.0 * EPS) * EPS * (l.abs() + r.abs());
    if det.abs() > bound {
        return sign_of(det);
    }
    let [acx, acy, bcx, bcy] = [
        Expansion::diff(a[0], c[0]),
        Expansion::diff(a[1], c[1]),
        Expansion::diff(b[0], c[0]),
        Expansion::diff(b[1], c[1]),
    ];
    acx.mul(&bcy).sub(&acy.mul(&bcx)).sign()
}

/// The sign of `det[a - d; b - d; c - d]`: `Greater` when `d` lies below the plane of `a b c`
/// (the side from which `a b c` turn clockwise), `Equal` when the four are coplanar.
pub fn orient3d(a: [f64; 3], b: [f64; 3], c: [f64; 3], d: [f64; 3]) -> Ordering {
    let ad = [a[0] - d[0], a[1] - d[1], a[2] - d[2]];
    let bd = [b[0] - d[0], b[1] - d[1], b[2] - d[2]];
    let cd = [c[0] - d[0], c[1] - d[1], c[2] - d[2]];
    let det = ad[0] * (bd[1] * cd[2] - bd[2] * cd[1])
        + bd[0] * (cd[1] * ad[2] - cd[2] * ad[1])
        + cd[0] * (ad[1] * bd[2] - ad[2] * bd[1]);
    let permanent = ad[0].abs() * ((bd[1] * cd[2]).abs() + (bd[2] * cd[1]).abs())
        + bd[0].abs() * ((cd[1] * ad[2]).abs() + (cd[2] * ad[1]).abs())
        + cd[0].abs() * ((ad[1] * bd[2]).abs() + (ad[2] * bd[1]).abs());
    let bound = (7.0 + 56.0 * EPS) * EPS * permanent;
    if det.abs() > bound {
        return sign_of(det);
    }
    let e = |p: [f64; 3]| [0, 1, 2].map(|k| Expansion::diff(p[k], d[k]));
    let (ad, bd, cd) = (e(a), e(b), e(c));
    let minor = |u: &[Expansion; 3], v: &[Expansion; 3]| u[1].mul(&v[2]).sub(&u[2].mul(&v[1]));
    ad[0]
        .mul(&minor(&bd, &cd))
        .add(&bd[0].mul(&minor(&cd, &ad)))
        .add(&cd[0].mul(&minor(&ad, &bd)))
        .sign()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exact_where_the_filter_cannot_decide() {
        // Points on the line y = x, perturbed by one unit in the last place: the naive
        // determinant rounds to zero or to the wrong sign for some of them.
        let x = 0.5 + f64::EPSILON;
        assert_eq!(
            orient2d([0.5, 0.5], [12.0, 12.0], [24.0, 24.0]),
            Ordering::Equal
        );
        assert_eq!(
            orient2d([x, 0.5], [12.0, 12.0], [24.0, 24.0]),
            Ordering::Less
        );
        assert_eq!(
            orient2d([0.5, x], [12.0, 12.0], [24.0, 24.0]),
            Ordering::Greater
        );
        // Four exactly coplanar points far from the origin (the plane z = x + y - o, every
        // coordinate exact), and the fourth moved off it by one unit in the last place.
        let o = 1_048_576.0;
        let p = |x: f64, y: f64, dz: f64| [o + x, o + y, o + x + y + dz];
        let (a, b, c) = (p(0.25, 0.5, 0.0), p(0.75, 0.125, 0.0), p(0.5, 0.875, 0.0));
        let ulp = f64::EPSILON * 2.0 * o;
        assert_eq!(orient3d(a, b, c, p(0.375, 0.25, 0.0)), Ordering::Equal);
        let up = orient3d(a, b, c, p(0.375, 0.25, ulp));
        let down = orient3d(a, b, c, p(0.375, 0.25, -ulp));
        assert!(
            up != Ordering::Equal && down == up.reverse(),
            "{up:?} {down:?}"
        );
        // Coplanar on an axis plane.
        assert_eq!(
            orient3d(
                [0.1, 0.3, 0.0],
                [7.3, 0.2, 0.0],
                [1.1, 5.0, 0.0],
                [3.3, 3.3, 0.0]
            ),
            Ordering::Equal
        );
        // Above the counter-clockwise triangle (seen from +z): Less.
        assert_eq!(
            orient3d([0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.2, 0.2, 1e-9]),
            Ordering::Less
        );
    }

    #[test]
    fn expansions_add_exactly() {
        let e = Expansion::diff(1e16, -1.0).grow(-1e16);
        assert_eq!(e.sign(), Ordering::Greater);
        let p =
            Expansion::diff(1.0 + f64::EPSILON, 0.0).mul(&Expansion::diff(1.0 - f64::EPSILON, 0.0));
        // (1 + e)(1 - e) = 1 - e^2 < 1.
        assert_eq!(p.grow(-1.0).sign(), Ordering::Less);
    }
}
