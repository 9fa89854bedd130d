//! The display law P (paper, section 3, eq. 4): the displayed displacement of a node is split
//! into `u = u^t + u^r`, `u^t` collinear with the constraint and `u^r` orthogonal to it; `u^t`
//! stays linear while the amplitude of `u^r` follows the bench's radial curve,
//! `|u^r| -> P(|u^r|)`, its direction kept.
//!
//! Two choices the paper leaves open, made here:
//!
//! - **The constraint's direction** is that of the total contact force of the frame (the force
//!   the tool imposes, what the device reports for both contact models; for a frictionless
//!   press it is the press direction). A frame without contact force has no constraint and is
//!   displayed as computed.
//! - **P is taken relative to P(0)**: the displayed amplitude is `max(P(x) - P(0), 0)`, so a
//!   fitted curve whose constant term is not exactly zero moves no node that the linear model
//!   leaves at rest (a fit's offset is its error at zero, not a displacement of the whole
//!   organ).
//!
//! A P that is the identity to f32 rounding over its domain (and so, continued linearly, over
//! every amplitude) is no correction: [`DisplayLaw::new`] returns `None` and the display runs
//! exactly as without P, bit for bit.

use bank_format::TissueLaw;

/// Relative deviation from the identity, over the law's domain, under which P is the identity:
/// a few f32 ulps of the domain's end, what evaluating an exact `P(x) = x` in f32 can leave.
const IDENTITY_TOLERANCE: f32 = 8.0 * f32::EPSILON;

/// Points of the domain at which [`DisplayLaw::new`] compares P with the identity (the law's
/// own monotonicity grid, [`bank_format::LAW_SAMPLES`]).
const IDENTITY_SAMPLES: u32 = bank_format::LAW_SAMPLES;

/// A frame's radial amplitudes: the largest `|u^r|` of the linear model and the largest shown.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct RadialExtent {
    /// Largest linear `|u^r|` over the frame's nodes, m.
    pub linear_m: f32,
    /// Largest displayed `|u^r|` (after P), m.
    pub displayed_m: f32,
}

/// P as the display applies it (see the module notes).
#[derive(Debug, Clone, Copy)]
pub struct DisplayLaw {
    law: TissueLaw,
    at_zero: f32,
}

impl DisplayLaw {
    /// The display law for the fitted `law` (m -> m), or `None` when `law` is the identity to
    /// f32 rounding on its domain.
    pub fn new(law: TissueLaw) -> Option<DisplayLaw> {
        let p = DisplayLaw {
            law,
            at_zero: law.eval(0.0),
        };
        let [a, b] = law.domain();
        let scale = a.abs().max(b.abs());
        let identity = (0..=IDENTITY_SAMPLES).all(|j| {
            let x = a + (b - a) * j as f32 / IDENTITY_SAMPLES as f32;
            (law.eval(x) - x).abs() <= IDENTITY_TOLERANCE * scale
        }) && p.at_zero.abs() <= IDENTITY_TOLERANCE * scale
            && (law.slope(a) - 1.0).abs() <= IDENTITY_TOLERANCE
            && (law.slope(b) - 1.0).abs() <= IDENTITY_TOLERANCE;
        (!identity).then_some(p)
    }

    /// The displayed radial amplitude for a linear one `x >= 0`, m: `max(P(x) - P(0), 0)`.
    pub fn radial(&self, x: f32) -> f32 {
        (self.law.eval(x) - self.at_zero).max(0.0)
    }

    /// Eq. 4 on every node of `u` (m, in place): the component along `direction` (unit) kept,
    /// the orthogonal one's amplitude replaced by [`DisplayLaw::radial`]. Returns the frame's
    /// largest radial amplitudes before and after.
    pub fn apply(&self, direction: [f32; 3], u: &mut [[f32; 3]]) -> RadialExtent {
        let mut extent = RadialExtent::default();
        for v in u {
            let (s, r, len) = split(direction, *v);
            extent.linear_m = extent.linear_m.max(len);
            if len > 0.0 {
                let shown = self.radial(len);
                extent.displayed_m = extent.displayed_m.max(shown);
                let k = shown / len;
                *v = std::array::from_fn(|i| s * direction[i] + k * r[i]);
            }
        }
        extent
    }
}

/// The largest `|u^r|` of `u` orthogonal to `direction` (unit), m: a frame's radial extent
/// without P (linear and displayed the same).
pub fn radial_extent(direction: [f32; 3], u: &[[f32; 3]]) -> RadialExtent {
    let m = u
        .iter()
        .map(|&v| split(direction, v).2)
        .fold(0.0f32, f32::max);
    RadialExtent {
        linear_m: m,
        displayed_m: m,
    }
}

/// The unit direction of the frame's constraint: the total of the contact forces, normalised;
/// `None` without a contact force.
pub fn constraint_direction<'a>(
    forces: impl IntoIterator<Item = &'a [f32; 3]>,
) -> Option<[f32; 3]> {
    let total = forces
        .into_iter()
        .fold([0.0f32; 3], |a, f| std::array::from_fn(|i| a[i] + f[i]));
    let n = (total[0] * total[0] + total[1] * total[1] + total[2] * total[2]).sqrt();
    (n > 0.0 && n.is_finite()).then(|| total.map(|x| x / n))
}

/// `v = s d + r` with `r` orthogonal to `d` (unit): `(s, r, |r|)`.
fn split(d: [f32; 3], v: [f32; 3]) -> (f32, [f32; 3], f32) {
    let s = v[0] * d[0] + v[1] * d[1] + v[2] * d[2];
    let r = [v[0] - s * d[0], v[1] - s * d[1], v[2] - s * d[2]];
    (s, r, (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]).sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The Chebyshev coefficients of `c0 + c1 x` on `[a, b]` (T0 = 1, T1 = the normalised x).
    fn line(c0: f64, c1: f64, [a, b]: [f64; 2]) -> TissueLaw {
        let mid = 0.5 * (a + b);
        let half = 0.5 * (b - a);
        TissueLaw::chebyshev(
            &[(c0 + c1 * mid) as f32, (c1 * half) as f32],
            [a as f32, b as f32],
        )
        .unwrap()
    }

    #[test]
    fn an_identity_law_is_no_correction() {
        for domain in [[0.0, 0.002], [0.0, 0.05], [1e-4, 3e-3]] {
            assert!(
                DisplayLaw::new(line(0.0, 1.0, domain)).is_none(),
                "{domain:?}"
            );
        }
        // Twice the radial displacement, or the identity shifted by 1 um, are corrections.
        assert!(DisplayLaw::new(line(0.0, 2.0, [0.0, 0.002])).is_some());
        assert!(DisplayLaw::new(line(1e-6, 1.0, [0.0, 0.002])).is_some());
    }

    /// `P(x) = 2 x` doubles the part orthogonal to the constraint and keeps the collinear part
    /// bit for bit (directions along an axis: no rounding in the split).
    #[test]
    fn the_orthogonal_part_follows_p_and_the_collinear_part_stays() {
        let p = DisplayLaw::new(line(0.0, 2.0, [0.0, 0.01])).unwrap();
        let mut u = vec![[0.001f32, 0.002, -0.004], [0.0, 0.0, -0.001], [0.0; 3]];
        let e = p.apply([0.0, 0.0, -1.0], &mut u);
        let close = |a: f32, b: f32| (a - b).abs() <= 1e-6 * b.abs().max(1e-9);
        assert!(close(u[0][0], 0.002) && close(u[0][1], 0.004), "{u:?}");
        assert_eq!(u[0][2], -0.004);
        assert_eq!(u[1], [0.0, 0.0, -0.001]);
        assert_eq!(u[2], [0.0; 3]);
        let r0 = (0.001f32.powi(2) + 0.002f32.powi(2)).sqrt();
        assert!(
            close(e.linear_m, r0) && close(e.displayed_m, 2.0 * r0),
            "{e:?}"
        );
    }

    /// A curved P in an oblique direction: each node's displayed displacement has the linear
    /// collinear component, a radial component parallel to the linear one, of amplitude
    /// `P(|u^r|) - P(0)` (computed here in f64 from the Chebyshev series by hand).
    #[test]
    fn a_curved_law_in_an_oblique_direction() {
        let domain = [0.0f64, 0.004];
        let coeffs = [2.1e-3f64, 2.0e-3, 1.5e-4];
        let law =
            TissueLaw::chebyshev(&coeffs.map(|c| c as f32), domain.map(|v| v as f32)).unwrap();
        let p = DisplayLaw::new(law).unwrap();
        let series = |x: f64| {
            let t = (2.0 * x - domain[0] - domain[1]) / (domain[1] - domain[0]);
            coeffs[0] + coeffs[1] * t + coeffs[2] * (2.0 * t * t - 1.0)
        };
        let d = {
            let v = [0.3f64, -0.4, 0.866];
            let n = v.iter().map(|x| x * x).sum::<f64>().sqrt();
            v.map(|x| x / n)
        };
        let df = d.map(|x| x as f32);
        let mut rng = crate::rng::SplitMix64::new(0x2545_f491_4f6c_dd1d);
        let mut next = || (rng.unit() - 0.5) * 0.004;
        let lin: Vec<[f32; 3]> = (0..200)
            .map(|_| [next(), next(), next()].map(|x| x as f32))
            .collect();
        let mut shown = lin.clone();
        p.apply(df, &mut shown);
        for (l, s) in lin.iter().zip(&shown) {
            let l = l.map(f64::from);
            let s = s.map(f64::from);
            let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
            let (ls, ss) = (dot(l, d), dot(s, d));
            let lr: [f64; 3] = std::array::from_fn(|i| l[i] - ls * d[i]);
            let sr: [f64; 3] = std::array::from_fn(|i| s[i] - ss * d[i]);
            let (la, sa) = (dot(lr, lr).sqrt(), dot(sr, sr).sqrt());
            assert!((ss - ls).abs() <= 2e-9, "collinear part {ls} -> {ss}");
            let want = (series(la) - series(0.0)).max(0.0);
            assert!(
                (sa - want).abs() <= 1e-8 + 1e-5 * want,
                "radial {la} -> {sa}, P says {want}"
            );
            // Parallel: the cross product of the two radial parts is ~0.
            let c = [
                lr[1] * sr[2] - lr[2] * sr[1],
                lr[2] * sr[0] - lr[0] * sr[2],
                lr[0] * sr[1] - lr[1] * sr[0],
            ];
            assert!(
                dot(c, c).sqrt() <= 1e-5 * la * sa + 1e-12,
                "{lr:?} vs {sr:?}"
            );
            assert!(dot(lr, sr) >= 0.0);
        }
    }

    #[test]
    fn the_constraint_is_the_total_contact_force() {
        let f = [[0.0f32, 0.0, 1.0], [0.0, 0.0, 2.0]];
        assert_eq!(constraint_direction(&f), Some([0.0, 0.0, 1.0]));
        assert_eq!(constraint_direction(&[[0.0f32; 3]]), None);
        assert_eq!(constraint_direction(&[[f32::NAN, 0.0, 0.0]]), None);
        let none: [[f32; 3]; 0] = [];
        assert_eq!(constraint_direction(&none), None);
    }
}
