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

/// Smallest Cholesky pivot (`L_ii^2`) the loop's f32 contact solve accepts, relative to the
/// largest diagonal entry of the matrix factored: below it an f32 solve loses more than about
/// two significant digits, so the tick reports an ill-conditioned solve instead of forces. The
/// one margin of the sampled contact: the tick applies it to the interpolated `W` it factors
/// (firmware `solve::Factor::check`), and the reader refuses samples that could bring some
/// point of a triangle under it ([`ill_conditioned_sample`]).
pub const MIN_PIVOT_REL: f32 = 1.0e-5;

/// A lower bound on the smallest eigenvalue of the symmetric 3 x 3 matrix `w` (xx, xy, xz, yy,
/// yz, zz), in f64: `4 det / trace^2`, since `lambda_min = det / (lambda_2 lambda_3)` and
/// `lambda_2 lambda_3 <= (trace / 2)^2`. Within a factor of about 2 to 5 of `lambda_min` for
/// the patch compliances of tissue (eigenvalues within a factor of a few of each other); 0 or
/// less when `w` is not positive definite.
pub fn min_eigenvalue_bound(w: &[f32; 6]) -> f64 {
    let [xx, xy, xz, yy, yz, zz] = w.map(f64::from);
    let det = xx * (yy * zz - yz * yz) - xy * (xy * zz - yz * xz) + xz * (xy * yz - yy * xz);
    let trace = xx + yy + zz;
    if !(trace > 0.0) {
        return 0.0;
    }
    4.0 * det / (trace * trace)
}

/// The sample of one triangle's lattice (`ids` into `w`, [`lattice_index`] order) that could
/// make the interpolated `W` at some point of the triangle too ill-conditioned for the tick
/// ([`MIN_PIVOT_REL`]), if any: the one with the smallest [`min_eigenvalue_bound`].
///
/// Every interpolated `W` is a convex combination of the triangle's samples, so its smallest
/// eigenvalue is at least the smallest of theirs (concavity of `lambda_min`) and its diagonal
/// at most their largest; a Cholesky pivot is at least `lambda_min`. The triangle passes when
/// the smallest bound is at least twice [`MIN_PIVOT_REL`] times the largest diagonal entry:
/// the factor 2 covers the f32 rounding of the interpolation and of the tick's factor (a few
/// `1e-7` of the diagonal, against a margin of `1e-5`). A sample not found in `w` is returned
/// as is (the reader's index check reports it first).
pub fn ill_conditioned_sample(w: &[[f32; 6]], ids: &[u16]) -> Option<u16> {
    let (mut lowest, mut worst, mut max_diag) = (f64::INFINITY, None, 0.0f64);
    for &s in ids {
        let Some(m) = w.get(usize::from(s)) else {
            return Some(s);
        };
        let bound = min_eigenvalue_bound(m);
        if bound < lowest {
            (lowest, worst) = (bound, Some(s));
        }
        for d in [m[0], m[3], m[5]] {
            max_diag = max_diag.max(f64::from(d));
        }
    }
    if lowest >= 2.0 * f64::from(MIN_PIVOT_REL) * max_diag {
        None
    } else {
        worst
    }
}

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
    // The upper small triangle, corner (i0 + 1, j0 + 1), exists only off the lattice's last
    // row of small triangles (i0 + j0 + 2 <= level). On that row (or where a clamp moved the
    // corner) the point is in the lower one: x + y <= level gives fx + fy <= 1 exactly, and
    // the little f32 rounding can add (a point on the v1-v2 edge) is taken off by projecting
    // onto the small triangle's far edge, so the weights stay non-negative and sum to 1.
    let (corners, weights) = if fx + fy > 1.0 && i0 + j0 + 2 <= level {
        (
            [(i0 + 1, j0 + 1), (i0, j0 + 1), (i0 + 1, j0)],
            [fx + fy - 1.0, 1.0 - fx, 1.0 - fy],
        )
    } else {
        let s = fx + fy;
        let (fx, fy) = if s > 1.0 { (fx / s, fy / s) } else { (fx, fy) };
        (
            [(i0, j0), (i0 + 1, j0), (i0, j0 + 1)],
            [positive(1.0 - fx - fy), fx, fy],
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

    /// The lattice point `(i, j)` each id names, with ids numbered as [`lattice_index`].
    fn lattice_points(level: u32) -> Vec<(u32, u32)> {
        let mut points = Vec::new();
        for j in 0..=level {
            for i in 0..=level - j {
                points.push((i, j));
            }
        }
        points
    }

    /// Checks [`lattice_corners`] at `bary`: three lattice points forming one small triangle of
    /// the lattice, weights non-negative summing to 1, and the weighted corners reproducing the
    /// point the module notes say is interpolated (`bary` clamped into the triangle).
    fn check_corners(level: u32, bary: [f32; 3], ids: &[u16], points: &[(u32, u32)]) {
        let (c, w) = lattice_corners(ids, level, bary)
            .unwrap_or_else(|| panic!("level {level}, {bary:?}: no corners"));
        let mut ij = c.map(|id| points[usize::from(id)]);
        ij.sort_unstable();
        // Sorted, a lower small triangle is (i, j), (i, j + 1), (i + 1, j) with
        // i + j + 1 <= level; an upper one (i, j + 1), (i + 1, j), (i + 1, j + 1) with
        // i + j + 2 <= level.
        let (i, j) = ij[0];
        let lower = ij == [(i, j), (i, j + 1), (i + 1, j)] && i + j < level;
        let upper = j > 0 && ij == [(i, j), (i + 1, j - 1), (i + 1, j)] && i + j < level;
        assert!(lower || upper, "level {level}, {bary:?}: corners {ij:?}");
        assert!(
            w.iter().all(|&x| x >= 0.0),
            "level {level}, {bary:?}: {w:?}"
        );
        let sum: f32 = w.iter().sum();
        assert!(
            (sum - 1.0).abs() <= 4.0 * f32::EPSILON,
            "level {level}: {sum}"
        );
        let (b1, b2) = (f64::from(bary[1].max(0.0)), f64::from(bary[2].max(0.0)));
        let s = (b1 + b2).max(1.0);
        let (mut x, mut y) = (0.0, 0.0);
        for (&id, &wt) in c.iter().zip(&w) {
            let (pi, pj) = points[usize::from(id)];
            x += f64::from(wt) * f64::from(pi) / f64::from(level);
            y += f64::from(wt) * f64::from(pj) / f64::from(level);
        }
        assert!(
            (x - b1 / s).abs() < 1e-5 && (y - b2 / s).abs() < 1e-5,
            "level {level}, {bary:?}: ({x}, {y}) for ({}, {})",
            b1 / s,
            b2 / s
        );
    }

    /// f32 points on the v1-v2 edge, at the vertices and sliding along the triangle's edges
    /// (the coordinates a contact on the boundary computes, one ulp either side included), and
    /// a dense set inside, at every lattice level a bank may have: always corners of one small
    /// triangle of the lattice (never an aliased or missing sample, which faulted the loop
    /// `SolveFailed`), weights non-negative summing to 1, the point reproduced.
    #[test]
    fn corners_are_a_small_triangle_at_every_level_on_edges_and_vertices() {
        let ulps = |v: f32| {
            [
                f32::from_bits(v.to_bits() - 1),
                v,
                f32::from_bits(v.to_bits() + 1),
            ]
        };
        for level in 1..=crate::MAX_SAMPLE_LEVEL {
            let points = lattice_points(level);
            let ids: Vec<u16> = (0..points.len() as u16).collect();
            let steps = 3_000;
            for k in 1..steps {
                let t = k as f32 / steps as f32;
                for b2 in ulps(1.0 - t) {
                    // The v1-v2 edge, as a contact's barycentric coordinates give it.
                    check_corners(level, [1.0 - t - b2, t, b2], &ids, &points);
                    // The v0-v1 and v0-v2 edges, the other coordinate zero or a rounding's
                    // width outside.
                    for z in [0.0, -1e-9, 1e-9] {
                        check_corners(level, [b2, t, z], &ids, &points);
                        check_corners(level, [b2, z, t], &ids, &points);
                    }
                }
            }
            for v in [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]] {
                for a in ulps(1.0) {
                    for e in [0.0, 1e-9, -1e-9] {
                        let b = v.map(|x: f32| if x == 1.0 { a } else { e });
                        check_corners(level, b, &ids, &points);
                    }
                }
            }
            for j in 0..=200 {
                for i in 0..=200 - j {
                    let (b1, b2) = (i as f32 / 200.0, j as f32 / 200.0);
                    check_corners(level, [1.0 - b1 - b2, b1, b2], &ids, &points);
                }
            }
        }
    }

    /// `W` is continuous across the small triangles' edges: along lines through the lattice in
    /// steps of 1e-4 (barycentric), samples of an arbitrary (non-linear) field interpolate to
    /// values that change by at most the field's lattice gradient times the step, never by a
    /// jump of the order of the samples themselves.
    #[test]
    fn interpolation_is_continuous_across_small_triangle_edges() {
        for level in 1..=crate::MAX_SAMPLE_LEVEL {
            let points = lattice_points(level);
            let ids: Vec<u16> = (0..points.len() as u16).collect();
            // Deterministic values in [0, 1), one per sample.
            let mut rng = crate::fixtures::SplitMix64::new(12_345 + u64::from(level));
            let field: Vec<f32> = points.iter().map(|_| rng.unit_f32()).collect();
            let value = |b: [f32; 3]| {
                let (c, w) = lattice_corners(&ids, level, b).unwrap();
                c.iter()
                    .zip(&w)
                    .map(|(&id, &wt)| wt * field[usize::from(id)])
                    .sum::<f32>()
            };
            let h = 1e-4f32;
            // Lines: along the v1-v2 edge, parallel to each side, and a skew one.
            let lines: [([f32; 2], [f32; 2]); 4] = [
                ([1.0, 0.0], [0.0, 1.0]),
                ([0.0, 0.3], [0.7, 0.3]),
                ([0.37, 0.0], [0.37, 0.63]),
                ([0.05, 0.11], [0.61, 0.38]),
            ];
            // Each step crosses at most two small triangles' edges; the slope of a linear
            // piece is at most 2 level (values within [0, 1)) per unit of barycentric length.
            for (a, b) in lines {
                let len = ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2)).sqrt();
                let n = (len / h) as usize;
                let at = |k: usize| {
                    let t = k as f32 / n as f32;
                    let (b1, b2) = (a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1]));
                    [1.0 - b1 - b2, b1, b2]
                };
                let bound = 4.0 * level as f32 * h + 1e-5;
                for k in 0..n {
                    let (p, q) = (value(at(k)), value(at(k + 1)));
                    assert!(
                        (p - q).abs() <= bound,
                        "level {level}, step {k}: {p} -> {q}"
                    );
                }
            }
        }
    }
}
