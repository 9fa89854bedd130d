//! The finite tool radius: which nodes a tool tip of radius `r` presses, and with what weights.
//!
//! A point force on an elastic solid has unbounded displacement (Boussinesq), so with point
//! contact (the paper's section 5) a node's compliance grows as the mesh is refined and the
//! force for a given tool displacement falls: the result depends on the mesh. A real tip has a
//! radius; spreading the load over the patch under it makes the force converge (design notes,
//! "a trap worth knowing"; the refinement series is `host bench refinement`).
//!
//! The model: the tip presses the surface with the parabolic pressure `p(rho) = 1 - rho^2 / r^2`
//! around the contact point (the anchor; `rho` its distance), whose total is `pi r^2 / 2`. The
//! node loads are that pressure's consistent load `integral p phi_k dA` (P1 shape functions
//! `phi_k`), approximated in two parts that together stay continuous as the anchor moves:
//!
//! - nodal quadrature: node `k` within `r` of the anchor gets `a_k p(rho_k)`, with `a_k` its
//!   lumped area (a third of its triangles' areas);
//! - the rest of the total, `max(0, pi r^2 / 2 - sum_k a_k p(rho_k))` (all of it when the tip is
//!   smaller than the triangles, none once the patch is resolved), goes to the contact
//!   triangle's vertices by the anchor's barycentric coordinates: the exact consistent load of a
//!   pressure that lies inside one triangle.
//!
//! Normalised to sum 1, these are the weights `w` of the energy-minimal solve
//! ([`crate::solve::WeightedSolve`]): `f_k = w_k f_tool` and the tool displacement is imposed on
//! `sum_k w_k u_k`. A node enters or leaves the patch with zero pressure, so sliding changes the
//! force continuously. With `r = 0` the weights are the barycentric coordinates (point contact).
//!
//! Candidates are the bank's neighbours (coupled nodes) of the contact triangle's vertex nearest
//! the anchor, so every kept pair is coupled whenever the bank's truncation radius exceeds `2 r`
//! (checked pair by pair regardless: a node not coupled to a heavier one is dropped). At most
//! [`MAX_CONTACT_NODES`] nodes are kept, the heaviest; the weight dropped is reported.

#![deny(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing,
    clippy::unreachable,
    clippy::todo
)]

use bank_format::Bank;
use nalgebra::ComplexField;

use crate::solve::MAX_CONTACT_NODES;

/// The weighted contact set of one tool press.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Patch {
    nodes: [u16; MAX_CONTACT_NODES],
    weights: [f32; MAX_CONTACT_NODES],
    len: usize,
    /// Share of the load on nodes that could not be kept (more than [`MAX_CONTACT_NODES`], or
    /// not coupled in the bank), before renormalising: 0 when nothing was dropped.
    pub dropped: f32,
}

impl Patch {
    /// The contact nodes, heaviest first.
    pub fn nodes(&self) -> &[u16] {
        self.nodes.get(..self.len).unwrap_or(&[])
    }

    /// Their weights (each `> 0`, sum 1).
    pub fn weights(&self) -> &[f32] {
        self.weights.get(..self.len).unwrap_or(&[])
    }
}

/// The weighted patch under a tip of radius `radius_m` (m) touching triangle `nodes` at the
/// rest-surface point `anchor` with barycentric coordinates `bary`. Non-finite or negative input
/// falls back to the triangle's barycentric weights.
pub fn tool_patch(
    bank: &Bank,
    nodes: [u16; 3],
    bary: [f32; 3],
    anchor: [f32; 3],
    radius_m: f32,
) -> Patch {
    let mut acc = Accumulator::default();
    let r2 = radius_m * radius_m;
    let mut resolved = 0.0f32;
    if r2 > 0.0 && r2.is_finite() && anchor.iter().all(|v| v.is_finite()) {
        let nearest = nodes
            .iter()
            .zip(bary)
            .fold(
                (nodes[0], -1.0f32),
                |best, (&k, b)| {
                    if b > best.1 { (k, b) } else { best }
                },
            )
            .0;
        let (neighbours, _) = bank.neighbours(usize::from(nearest));
        for &k in core::iter::once(&nearest).chain(neighbours) {
            let Some(&x) = bank.positions().get(usize::from(k)) else {
                continue;
            };
            let rho2 = dist2(x, anchor);
            if rho2 < r2 {
                let q = lumped_area(bank, k) * (1.0 - rho2 / r2);
                if q > 0.0 && q.is_finite() {
                    acc.add(k, q);
                    resolved += q;
                }
            }
        }
    }
    // The pressure's total is pi r^2 / 2; with nothing resolved (r = 0, a tip smaller than the
    // triangles, or bad input) the barycentric part is all there is, of any positive size.
    let rest = if resolved > 0.0 {
        (0.5 * core::f32::consts::PI * r2 - resolved).max(0.0)
    } else {
        1.0
    };
    for (&k, &b) in nodes.iter().zip(&bary) {
        if b > 0.0 && b.is_finite() {
            acc.add(k, rest * b);
        }
    }
    acc.finish(bank)
}

/// Node loads gathered before selection: merges repeated nodes.
struct Accumulator {
    nodes: [u16; CANDIDATES],
    loads: [f32; CANDIDATES],
    len: usize,
    overflow: f32,
}

/// Candidates kept before choosing the heaviest [`MAX_CONTACT_NODES`].
const CANDIDATES: usize = 4 * MAX_CONTACT_NODES;

impl Default for Accumulator {
    fn default() -> Accumulator {
        Accumulator {
            nodes: [0; CANDIDATES],
            loads: [0.0; CANDIDATES],
            len: 0,
            overflow: 0.0,
        }
    }
}

impl Accumulator {
    fn add(&mut self, k: u16, q: f32) {
        let len = self.len;
        if let Some(i) = self.nodes.iter().take(len).position(|&n| n == k) {
            if let Some(l) = self.loads.get_mut(i) {
                *l += q;
            }
        } else if let (Some(n), Some(l)) = (self.nodes.get_mut(len), self.loads.get_mut(len)) {
            *n = k;
            *l = q;
            self.len += 1;
        } else {
            self.overflow += q;
        }
    }

    /// The heaviest nodes, mutually coupled, normalised.
    fn finish(mut self, bank: &Bank) -> Patch {
        let total = self.loads.iter().take(self.len).sum::<f32>() + self.overflow;
        let mut patch = Patch {
            nodes: [0; MAX_CONTACT_NODES],
            weights: [0.0; MAX_CONTACT_NODES],
            len: 0,
            dropped: 0.0,
        };
        let mut kept = 0.0f32;
        while patch.len < MAX_CONTACT_NODES {
            // Heaviest remaining candidate (ties: the first).
            let Some((i, &q)) = self
                .loads
                .iter()
                .take(self.len)
                .enumerate()
                .filter(|&(_, &q)| q > 0.0)
                .fold(None, |best: Option<(usize, &f32)>, c| match best {
                    Some(b) if *b.1 >= *c.1 => Some(b),
                    _ => Some(c),
                })
            else {
                break;
            };
            let k = self.nodes.get(i).copied().unwrap_or(0);
            if let Some(l) = self.loads.get_mut(i) {
                *l = 0.0;
            }
            let coupled = patch
                .nodes()
                .iter()
                .all(|&n| bank.coupling(usize::from(n), usize::from(k)).is_some());
            if !coupled {
                continue;
            }
            if let (Some(n), Some(w)) = (
                patch.nodes.get_mut(patch.len),
                patch.weights.get_mut(patch.len),
            ) {
                *n = k;
                *w = q;
            }
            patch.len += 1;
            kept += q;
        }
        if kept > 0.0 && total > 0.0 {
            for w in patch.weights.iter_mut() {
                *w /= kept;
            }
            patch.dropped = (1.0 - kept / total).max(0.0);
        }
        patch
    }
}

/// A third of the area of the bank's triangles around node `k`, m^2.
fn lumped_area(bank: &Bank, k: u16) -> f32 {
    let p = bank.positions();
    let tris = bank.triangles();
    let mut twice = 0.0f32;
    for &t in bank.node_triangles(usize::from(k)) {
        let Some(tri) = tris.get(t as usize) else {
            continue;
        };
        let v = tri.map(|i| p.get(usize::from(i)).copied().unwrap_or([0.0; 3]));
        let e1 = sub(v[1], v[0]);
        let e2 = sub(v[2], v[0]);
        let c = [
            e1[1] * e2[2] - e1[2] * e2[1],
            e1[2] * e2[0] - e1[0] * e2[2],
            e1[0] * e2[1] - e1[1] * e2[0],
        ];
        twice += ComplexField::sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2]);
    }
    twice / 6.0
}

fn sub(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn dist2(a: [f32; 3], b: [f32; 3]) -> f32 {
    let d = sub(a, b);
    d[0] * d[0] + d[1] * d[1] + d[2] * d[2]
}

#[cfg(test)]
#[allow(clippy::indexing_slicing, clippy::unwrap_used)]
mod tests {
    extern crate std;
    use super::*;
    use crate::fixtures::grid_patch;
    use std::vec::Vec;

    /// Node id of grid point (i, j) on an `n`-wide grid.
    fn id(n: usize, i: usize, j: usize) -> u16 {
        (i + n * j) as u16
    }

    fn weight_of(p: &Patch, k: u16) -> f32 {
        p.nodes()
            .iter()
            .zip(p.weights())
            .find(|&(&n, _)| n == k)
            .map_or(0.0, |(_, &w)| w)
    }

    #[test]
    fn zero_radius_gives_the_barycentric_weights() {
        let bytes = grid_patch(5, 0.01, 0.06);
        let bank = Bank::parse(bytes.as_slice()).unwrap();
        let tri = [id(5, 1, 1), id(5, 2, 1), id(5, 2, 2)];
        let bary = [0.5, 0.3, 0.2];
        let p = tool_patch(&bank, tri, bary, [0.017, 0.012, 0.0], 0.0);
        assert_eq!(p.nodes().len(), 3);
        for (k, b) in tri.iter().zip(bary) {
            assert!((weight_of(&p, *k) - b).abs() < 1e-6, "{p:?}");
        }
        assert_eq!(p.dropped, 0.0);
        // A vertex hit: one node.
        let p = tool_patch(&bank, tri, [1.0, 0.0, 0.0], [0.01, 0.01, 0.0], 0.0);
        assert_eq!(p.nodes(), &[tri[0]]);
        assert_eq!(p.weights(), &[1.0]);
    }

    /// Hand-computed: 1 mm grid, r = 1.2 mm, anchor on node c. Lumped areas are h^2 = 1e-6 m^2.
    /// c gets h^2 * 1; its four edge neighbours (rho = 1 mm) h^2 (1 - 1/1.44); the diagonal
    /// ones are outside. The rest of pi r^2 / 2 goes to c (barycentric (1, 0, 0)).
    #[test]
    fn resolved_patch_matches_the_hand_computation() {
        let n = 9;
        let bytes = grid_patch(n, 0.001, 0.004);
        let bank = Bank::parse(bytes.as_slice()).unwrap();
        let c = id(n, 4, 4);
        let tri = [c, id(n, 5, 4), id(n, 5, 5)];
        let p = tool_patch(&bank, tri, [1.0, 0.0, 0.0], [0.004, 0.004, 0.0], 0.0012);
        let h2 = 1.0e-6f64;
        let ring = h2 * (1.0 - 1.0 / 1.44);
        let total = 0.5 * core::f64::consts::PI * 1.44e-6;
        let rest = total - h2 - 4.0 * ring;
        assert!(rest > 0.0);
        let want_c = (h2 + rest) / total;
        let want_ring = ring / total;
        assert_eq!(p.nodes().len(), 5, "{p:?}");
        assert!((f64::from(weight_of(&p, c)) - want_c).abs() < 1e-5, "{p:?}");
        for k in [id(n, 3, 4), id(n, 5, 4), id(n, 4, 3), id(n, 4, 5)] {
            assert!(
                (f64::from(weight_of(&p, k)) - want_ring).abs() < 1e-5,
                "{p:?}"
            );
        }
        assert_eq!(p.dropped, 0.0);
    }

    /// The weights change continuously as the anchor slides: nodes enter and leave the patch
    /// with zero pressure, and the barycentric rest blends in.
    #[test]
    fn weights_are_continuous_along_a_slide() {
        let n = 9;
        let h = 0.001f32;
        let bytes = grid_patch(n, f64::from(h), 0.004);
        let bank = Bank::parse(bytes.as_slice()).unwrap();
        let r = 0.0011f32;
        let steps = 2000;
        let mut prev: Option<Vec<f32>> = None;
        let mut max_jump = 0.0f32;
        for s in 0..=steps {
            // Along y = 4.3 mm from x = 3.1 mm to 4.9 mm: within the squares of row j = 4.
            let x = 0.0031 + 0.0018 * s as f32 / steps as f32;
            let y = 0.0043f32;
            let (i, j) = (3 + usize::from(x > 0.004), 4);
            let (u, v) = (x / h - i as f32, y / h - j as f32);
            // Square (i, j) split along its diagonal: [a, b, c] below it (u >= v), [a, c, d].
            let (tri, bary) = if u >= v {
                (
                    [id(n, i, j), id(n, i + 1, j), id(n, i + 1, j + 1)],
                    [1.0 - u, u - v, v],
                )
            } else {
                (
                    [id(n, i, j), id(n, i + 1, j + 1), id(n, i, j + 1)],
                    [1.0 - v, u, v - u],
                )
            };
            let p = tool_patch(&bank, tri, bary, [x, y, 0.0], r);
            assert!((p.weights().iter().sum::<f32>() - 1.0).abs() < 1e-5);
            let dense: Vec<f32> = (0..(n * n) as u16).map(|k| weight_of(&p, k)).collect();
            if let Some(q) = &prev {
                let jump = dense
                    .iter()
                    .zip(q)
                    .map(|(a, b)| (a - b).abs())
                    .fold(0.0, f32::max);
                max_jump = max_jump.max(jump);
            }
            prev = Some(dense);
        }
        // 2000 steps of 0.9 um: a continuous weight moves by ~1e-3 per step at most.
        assert!(max_jump < 5e-3, "largest weight jump {max_jump}");
    }

    #[test]
    fn too_many_or_uncoupled_nodes_are_dropped_and_reported() {
        // r = 3 mm on a 1 mm grid: 29 nodes inside, 8 kept.
        let n = 9;
        let bytes = grid_patch(n, 0.001, 0.007);
        let bank = Bank::parse(bytes.as_slice()).unwrap();
        let c = id(n, 4, 4);
        let tri = [c, id(n, 5, 4), id(n, 5, 5)];
        let p = tool_patch(&bank, tri, [1.0, 0.0, 0.0], [0.004, 0.004, 0.0], 0.003);
        assert_eq!(p.nodes().len(), MAX_CONTACT_NODES);
        assert_eq!(p.nodes()[0], c);
        assert!(p.dropped > 0.3 && p.dropped < 1.0, "{p:?}");
        // Truncation 1.5 mm: the nodes 2 mm apart are not coupled; no kept pair is uncoupled.
        let bytes = grid_patch(n, 0.001, 0.0015);
        let bank = Bank::parse(bytes.as_slice()).unwrap();
        let p = tool_patch(&bank, tri, [1.0, 0.0, 0.0], [0.004, 0.004, 0.0], 0.0012);
        for &a in p.nodes() {
            for &b in p.nodes() {
                assert!(bank.coupling(usize::from(a), usize::from(b)).is_some());
            }
        }
        assert!(p.dropped > 0.0, "{p:?}");
    }
}
