//! The contact samples (`SPEC.md`, "contact samples", 6.0): the scene's tool's patch compliance
//! `W(p) = B(p) C B(p)^T`, the 3 x 3 compliance of the whole pressure patch of a tip centred at
//! surface point `p` (the rigid-tool form of the paper's eq. 8 for one tool), sampled on a
//! lattice over each triangle of R and interpolated linearly between lattice points.
//!
//! Lattice: a triangle `(v0, v1, v2)` with `level = n` holds the points of barycentric
//! coordinates `((n - i - j) / n, i / n, j / n)`, `i, j >= 0`, `i + j <= n`, numbered
//! [`lattice_index`]`(i, j, n)` (row `j` after row `j - 1`, `i` ascending in a row). They cut the
//! triangle into `n^2` small triangles; a point's `W` is the barycentric interpolation of the
//! three samples of the small triangle holding it. Every sample is symmetric positive definite
//! and the weights are non-negative and sum to 1, so the interpolated `W` is too (a convex
//! combination of SPD matrices). Neighbouring triangles share the samples of their common
//! edge (the reader checks it), so `W` is continuous as a contact slides across an edge.

use crate::layout::SampleHeader;

/// Lattice points of a triangle at `level` steps per side: `(level + 1) (level + 2) / 2`.
pub const fn lattice_len(level: u32) -> usize {
    let n = level as usize;
    (n + 1) * (n + 2) / 2
}

/// The number of lattice point `(i, j)` (`i` steps towards the triangle's second vertex, `j`
/// towards its third, `i + j <= level`) in a triangle's list of samples.
pub const fn lattice_index(i: u32, j: u32, level: u32) -> usize {
    let (i, j, n) = (i as usize, j as usize, level as usize);
    // Rows 0..j hold (n + 1) + n + ... + (n + 2 - j) points.
    j * (2 * n + 3 - j) / 2 + i
}

/// The barycentric coordinates of lattice point `(i, j)` at `level` ([`lattice_index`]).
pub fn lattice_bary(i: u32, j: u32, level: u32) -> [f64; 3] {
    let n = f64::from(level.max(1));
    let (a, b) = (f64::from(i) / n, f64::from(j) / n);
    [1.0 - a - b, a, b]
}

/// The contact samples of a bank ([`crate::Bank::samples`]), validated.
#[derive(Clone, Copy, Debug)]
pub struct Samples<'a> {
    pub(crate) header: &'a SampleHeader,
    /// Per triangle, [`lattice_len`] sample indices.
    pub(crate) ids: &'a [u16],
    /// `W` per sample: xx, xy, xz, yy, yz, zz, m/N.
    pub(crate) w: &'a [[f32; 6]],
}

impl<'a> Samples<'a> {
    /// Lattice steps per triangle side.
    pub fn level(&self) -> u32 {
        self.header.level
    }

    /// The tool radius the samples were computed for, m.
    pub fn tip_radius_m(&self) -> f32 {
        self.header.tip_radius_m
    }

    /// Number of distinct samples.
    pub fn count(&self) -> usize {
        self.w.len()
    }

    /// Sample `s`'s `W` (xx, xy, xz, yy, yz, zz, m/N).
    pub fn sample(&self, s: usize) -> Option<[f32; 6]> {
        self.w.get(s).copied()
    }

    /// Triangle `t`'s sample indices, [`lattice_index`] order (empty for `t` out of range).
    pub fn triangle_samples(&self, t: usize) -> &'a [u16] {
        let len = lattice_len(self.header.level);
        t.checked_mul(len)
            .and_then(|a| self.ids.get(a..a.checked_add(len)?))
            .unwrap_or(&[])
    }

    /// The patch compliance at barycentric point `bary` of triangle `t` (xx, xy, xz, yy, yz,
    /// zz, m/N): the barycentric interpolation of the three samples around it ([`Self::corners`],
    /// module notes). `None` for a triangle out of range or a coordinate that is not finite. A
    /// few dozen f32 operations, no loop over the lattice.
    pub fn interpolate(&self, t: usize, bary: [f32; 3]) -> Option<[f32; 6]> {
        let (ids, weights) = self.corners(t, bary)?;
        let mut out = [0.0f32; 6];
        for (&s, &wt) in ids.iter().zip(&weights) {
            let w = self.w.get(usize::from(s))?;
            for (o, v) in out.iter_mut().zip(w) {
                *o += wt * v;
            }
        }
        Some(out)
    }

    /// The three samples around barycentric point `bary` of triangle `t` (the corners of the
    /// small lattice triangle that holds it) and their barycentric weights (sum 1): any field
    /// given per sample (`W` here; a display's surface displacement fields on the host) is
    /// interpolated with them. `bary` is clamped into the triangle (negative coordinates to 0,
    /// then the second and third scaled so that they sum to at most 1); `None` for a triangle
    /// out of range or a coordinate that is not finite. No division but the clamp's.
    pub fn corners(&self, t: usize, bary: [f32; 3]) -> Option<([u16; 3], [f32; 3])> {
        lattice_corners(self.triangle_samples(t), self.header.level, bary)
    }
}

/// [`Samples::corners`] on one triangle's sample ids `ids` ([`lattice_index`] order) at
/// `level`, for a host that holds the ids itself.
pub fn lattice_corners(ids: &[u16], level: u32, bary: [f32; 3]) -> Option<([u16; 3], [f32; 3])> {
    if !(bary[1].is_finite() && bary[2].is_finite()) {
        return None;
    }
    let n = level as f32;
    // Comparisons, not `f32::max`: a libm call on the M4F (both are finite here).
    let positive = |b: f32| if b > 0.0 { b } else { 0.0 };
    let (mut b1, mut b2) = (positive(bary[1]), positive(bary[2]));
    let s = b1 + b2;
    if s > 1.0 {
        (b1, b2) = (b1 / s, b2 / s);
    }
    let (x, y) = (b1 * n, b2 * n);
    // The small triangle's lower-left lattice point (i0, j0), i0 + j0 <= level - 1.
    let top = level.saturating_sub(1);
    let i0 = (x as u32).min(top);
    let j0 = (y as u32).min(top - i0);
    let (fx, fy) = (x - i0 as f32, y - j0 as f32);
    let (corners, weights) = if fx + fy <= 1.0 {
        (
            [(i0, j0), (i0 + 1, j0), (i0, j0 + 1)],
            [1.0 - fx - fy, fx, fy],
        )
    } else {
        (
            [(i0 + 1, j0 + 1), (i0, j0 + 1), (i0 + 1, j0)],
            [fx + fy - 1.0, 1.0 - fx, 1.0 - fy],
        )
    };
    let mut out = [0u16; 3];
    for (o, &(i, j)) in out.iter_mut().zip(&corners) {
        *o = *ids.get(lattice_index(i, j, level))?;
    }
    Some((out, weights))
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::indexing_slicing)]
mod tests {
    use super::*;
    extern crate alloc;
    use alloc::vec::Vec;

    #[test]
    fn lattice_numbering_is_row_by_row() {
        for level in 1..=8 {
            let mut k = 0;
            for j in 0..=level {
                for i in 0..=level - j {
                    assert_eq!(lattice_index(i, j, level), k, "level {level} ({i}, {j})");
                    k += 1;
                }
            }
            assert_eq!(k, lattice_len(level));
        }
    }

    /// Samples whose W is a linear function of the lattice coordinates are reproduced exactly
    /// at every point (barycentric interpolation is exact for linear fields), and a point on a
    /// lattice point gets that sample.
    #[test]
    fn interpolation_is_exact_for_linear_fields() {
        let level = 3;
        let header = SampleHeader {
            level,
            tip_radius_m: 0.003,
            reserved: [0; 2],
        };
        let field = |b: [f64; 3]| -> [f32; 6] {
            [
                (1.0 + b[1] + 2.0 * b[2]) as f32,
                0.1,
                (0.2 * b[1]) as f32,
                (2.0 - b[2]) as f32,
                0.0,
                (3.0 + b[0]) as f32,
            ]
        };
        let mut w = Vec::new();
        let mut ids = Vec::new();
        for j in 0..=level {
            for i in 0..=level - j {
                ids.push(w.len() as u16);
                w.push(field(lattice_bary(i, j, level)));
            }
        }
        let s = Samples {
            header: &header,
            ids: &ids,
            w: &w,
        };
        for (b1, b2) in [
            (0.0, 0.0),
            (1.0, 0.0),
            (0.0, 1.0),
            (0.5, 0.5),
            (0.2, 0.3),
            (0.34, 0.33),
            (0.9, 0.05),
            (1.0 / 3.0, 2.0 / 3.0),
        ] {
            let got = s.interpolate(0, [1.0 - b1 - b2, b1, b2]).unwrap();
            let want = field([1.0 - f64::from(b1) - f64::from(b2), b1.into(), b2.into()]);
            for (g, e) in got.iter().zip(&want) {
                assert!((g - e).abs() < 1e-6, "({b1}, {b2}): {got:?} vs {want:?}");
            }
        }
        // Clamped: a point outside the triangle takes the nearest edge's value.
        assert_eq!(
            s.interpolate(0, [0.5, -0.2, 0.7]),
            s.interpolate(0, [0.3, 0.0, 0.7])
        );
        assert!(s.interpolate(1, [1.0, 0.0, 0.0]).is_none());
        assert!(s.interpolate(0, [f32::NAN, 0.5, 0.5]).is_some());
        assert!(s.interpolate(0, [0.0, f32::NAN, 0.5]).is_none());
    }
}
