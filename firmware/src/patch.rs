//! The finite tool radius: which nodes a tool tip of radius `r` presses, and with what weights.
//!
//! A point force on an elastic solid has unbounded displacement (Boussinesq), so with point
//! contact (the paper's section 5) a node's compliance grows as the mesh is refined and the
//! force for a given tool displacement falls: the result depends on the mesh. A real tip has a
//! radius; spreading the load over the patch under it makes the force converge (the
//! refinement series is `host bench refinement`).
//!
//! The model: the tip presses the surface with the parabolic pressure `p(rho) = 1 - rho^2 / r^2`
//! around the contact point (the anchor; `rho` the distance from it). The node loads are that
//! pressure's consistent load `integral p phi_k dA` (P1 shape functions `phi_k`), by quadrature:
//! [`QUADRATURE`] places 12 points on two rings in the contact triangle's plane (a Gauss rule
//! in the radius for the weight `rho (1 - rho^2 / r^2)`, six angles per ring), each point is
//! moved to the closest rest-surface point ([`SurfaceWalk`], a walk across edges from the
//! contact triangle) and its weight is spread over that triangle's vertices by barycentric
//! coordinates. When the tip is much smaller than the triangles every point falls in the
//! contact triangle and the weights are the anchor's barycentric coordinates (the paper's
//! point contact, exactly the consistent load of a pressure inside one triangle). Twelve points
//! are twelve point loads, though, which a fine mesh again resolves as singular; so once the
//! mesh resolves the tip ([`resolution`]: enough nodes under it) the weights blend into the
//! nodal quadrature `a_k p(rho_k)` (`a_k` the node's lumped area, a third of its triangles'),
//! which converges under refinement. As the anchor slides, the points, their barycentric
//! coordinates and the nodal pressures move continuously, and so does the force.
//!
//! Normalised to sum 1, these are the weights `w` of the energy-minimal solve
//! ([`crate::solve::WeightedSolve`]): `f_k = w_k f_tool` and the tool displacement is imposed on
//! `sum_k w_k u_k`. With `r = 0` the weights are the barycentric coordinates.
//!
//! At most [`MAX_CONTACT_NODES`] nodes are kept, the heaviest, and each must be coupled in the
//! bank to every heavier one kept (true whenever the bank's truncation radius exceeds `2 r` plus
//! an edge); the weight dropped is reported. The patch depends only on the anchor, so the loop
//! computes it when the contact starts or slides, not while it presses in place.

use bank_format::Bank;

use crate::contact::{BARY_TOL, SurfaceWalk, Walk, normalise, plane_bary, vertices};
use crate::solve::MAX_CONTACT_NODES;
use crate::vec3::{add, cross, dist2, dot, scale, sqrt, sub, unit};

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

/// The disk quadrature: `(rho / r, weight, angle)` for each point. Radii and weights are the
/// 2-point Gauss rule for `integral_0^1 f(s) s (1 - s^2) ds` (in `t = s^2`: Gauss-Jacobi with
/// weight `1 - t`, nodes `0.4 -+ sqrt(0.06)`), normalised to a total of 1 and split over six
/// angles per ring, the outer ring turned by 30 degrees.
pub const QUADRATURE: [(f32, f32, f32); 12] = {
    const S: [f32; 2] = [0.393_765_36, 0.803_087_3];
    const W: [f32; 2] = [0.636_082_06 / 6.0, 0.363_917_94 / 6.0];
    const D: f32 = core::f32::consts::PI / 180.0;
    [
        (S[0], W[0], 0.0),
        (S[0], W[0], 60.0 * D),
        (S[0], W[0], 120.0 * D),
        (S[0], W[0], 180.0 * D),
        (S[0], W[0], 240.0 * D),
        (S[0], W[0], 300.0 * D),
        (S[1], W[1], 30.0 * D),
        (S[1], W[1], 90.0 * D),
        (S[1], W[1], 150.0 * D),
        (S[1], W[1], 210.0 * D),
        (S[1], W[1], 270.0 * D),
        (S[1], W[1], 330.0 * D),
    ]
};

/// Cosine and sine of each [`QUADRATURE`] angle.
const DIRECTIONS: [(f32, f32); 12] = {
    const H: f32 = 0.866_025_4; // sqrt(3) / 2
    [
        (1.0, 0.0),
        (0.5, H),
        (-0.5, H),
        (-1.0, 0.0),
        (-0.5, -H),
        (0.5, -H),
        (H, 0.5),
        (0.0, 1.0),
        (-H, 0.5),
        (-H, -0.5),
        (0.0, -1.0),
        (H, -0.5),
    ]
};

/// The weighted patch under a tip of radius `radius_m` (m) touching `triangle` (index into
/// `bank.triangles()`, nodes `nodes`) at the rest-surface point `anchor` with barycentric
/// coordinates `bary`. A zero, negative or non-finite radius, or a degenerate triangle, gives
/// the barycentric weights. The same as a [`PatchBuild`] run to its end in one go.
pub fn tool_patch(
    bank: &Bank,
    triangle: u32,
    nodes: [u16; 3],
    bary: [f32; 3],
    anchor: [f32; 3],
    radius_m: f32,
) -> Patch {
    let mut build = PatchBuild::new();
    build.start(bank, triangle, nodes, bary, anchor, radius_m);
    while !build.locate(bank, QUADRATURE.len(), u32::MAX) {}
    build.finish(bank)
}

/// [`tool_patch`] in steps, so that the loop can spread it over several ticks: [`start`]
/// (tangent basis, nodal pressures, the contact triangle's frame), [`locate`] (some of the 12
/// quadrature points onto the surface), [`finish`] (merge, choose the heaviest mutually
/// coupled nodes). The arithmetic is the same in whatever steps it is run, so the result is
/// bit for bit [`tool_patch`]'s.
///
/// [`start`]: PatchBuild::start
/// [`locate`]: PatchBuild::locate
/// [`finish`]: PatchBuild::finish
#[derive(Clone, Debug)]
pub struct PatchBuild {
    triangle: u32,
    nodes: [u16; 3],
    bary: [f32; 3],
    anchor: [f32; 3],
    radius_m: f32,
    /// Tangent basis of the contact triangle; `None`: barycentric weights only.
    basis: Option<([f32; 3], [f32; 3])>,
    /// See [`contact_frame`].
    frame: Option<[[f32; 3]; 3]>,
    theta: f32,
    acc: Accumulator,
    quad: Accumulator,
    /// Quadrature weight landed in the contact triangle, per vertex (added to `quad` at the
    /// end: one merge instead of three per point).
    in_contact: [f32; 3],
    next: usize,
    /// Where the next point's surface walk starts: the triangle the last point outside the
    /// contact triangle landed on (the points go round their ring, so it is near), else the
    /// contact triangle.
    walk_from: (u32, [u16; 3]),
    /// The walk of point `next`, when a [`PatchBuild::locate`] ran out of steps during it.
    walk: Option<SurfaceWalk>,
    /// The node choice so far ([`PatchBuild::choose_step`]).
    choice: Choice,
}

impl Default for PatchBuild {
    fn default() -> PatchBuild {
        PatchBuild::new()
    }
}

impl PatchBuild {
    /// An idle build (barycentric weights of node 0 until [`PatchBuild::start`]).
    pub fn new() -> PatchBuild {
        PatchBuild {
            triangle: 0,
            nodes: [0; 3],
            bary: [1.0, 0.0, 0.0],
            anchor: [0.0; 3],
            radius_m: 0.0,
            basis: None,
            frame: None,
            theta: 1.0,
            acc: Accumulator::default(),
            quad: Accumulator::default(),
            in_contact: [0.0; 3],
            next: QUADRATURE.len(),
            walk_from: (0, [0; 3]),
            walk: None,
            choice: Choice::new(0.0),
        }
    }

    /// (Re)starts the build in place for a new contact point: the first step, the tangent
    /// basis, the nodal pressures (they say how far the mesh resolves the tip; the costly parts
    /// are skipped when their share is zero) and the contact triangle's frame.
    pub fn start(
        &mut self,
        bank: &Bank,
        triangle: u32,
        nodes: [u16; 3],
        bary: [f32; 3],
        anchor: [f32; 3],
        radius_m: f32,
    ) {
        // The basis (two square roots) only for a tip with a radius.
        let basis = if radius_m > 0.0 && radius_m.is_finite() {
            tangent_basis(bank, nodes)
        } else {
            None
        };
        self.triangle = triangle;
        self.nodes = nodes;
        self.bary = bary;
        self.anchor = anchor;
        self.radius_m = radius_m;
        self.basis = basis;
        self.frame = None;
        self.theta = 1.0;
        self.acc.clear();
        self.quad.clear();
        self.in_contact = [0.0; 3];
        self.next = QUADRATURE.len();
        self.walk_from = (triangle, nodes);
        self.walk = None;
        let Some((e1, e2)) = basis else {
            self.acc.add_bary(nodes, bary, 1.0);
            return;
        };
        let (mut nodal, n_eff) = nodal_pressures(bank, nodes, bary, anchor, radius_m);
        self.theta = resolution(n_eff);
        if self.theta > 0.0 {
            nodal.weight_by_lumped_area(bank);
            self.acc.merge_scaled(&nodal, self.theta);
        }
        if self.theta < 1.0 {
            self.frame = contact_frame(bank, triangle, nodes, anchor, e1, e2, radius_m);
            self.next = 0;
        }
    }

    /// Locates up to `points` more quadrature points, taking at most `steps` surface-walk steps
    /// in all; `true` once all are located. The points lie in the contact triangle's plane,
    /// where the barycentric coordinates are affine: a point inside the contact triangle costs
    /// six multiply-adds (its affine frame); only the points outside it walk the surface
    /// ([`SurfaceWalk`]), each from where the last one landed. A walk the steps do not finish
    /// resumes at the next call (before any new point), so a call costs at most `points` frame
    /// tests and `steps` walk steps, wherever the points fall on the mesh.
    pub fn locate(&mut self, bank: &Bank, points: usize, steps: u32) -> bool {
        let Some((e1, e2)) = self.basis else {
            return true;
        };
        let mut begun = 0;
        let mut steps = steps;
        while let (Some(&(s, w, _)), Some(&(c, sn))) =
            (QUADRATURE.get(self.next), DIRECTIONS.get(self.next))
        {
            let (u, v) = (s * c, s * sn);
            if self.walk.is_none() {
                if begun == points {
                    break;
                }
                begun += 1;
                if let Some(k) = self.inside(u, v) {
                    for (acc, kv) in self.in_contact.iter_mut().zip(k) {
                        *acc += w * kv;
                    }
                    self.next += 1;
                    continue;
                }
            }
            let (t, n) = self.walk_from;
            let walk = self.walk.get_or_insert(SurfaceWalk::new(t, n));
            let r = self.radius_m;
            let q = add(add(self.anchor, scale(e1, r * u)), scale(e2, r * v));
            match walk.advance(bank, q, &mut steps) {
                Walk::Walking => break,
                Walk::Landed(sp) => {
                    self.quad.add_bary(sp.nodes, sp.bary, w);
                    self.walk_from = (sp.triangle, sp.nodes);
                }
                Walk::Lost => self.quad.add_bary(self.nodes, self.bary, w),
            }
            self.walk = None;
            self.next += 1;
        }
        self.next >= QUADRATURE.len()
    }

    /// The barycentric coordinates of the point `(u, v)` (tip radii along the tangent basis
    /// from the anchor) in the contact triangle, if it lies inside (its affine frame).
    fn inside(&self, u: f32, v: f32) -> Option<[f32; 3]> {
        let [k0, g1, g2] = self.frame?;
        let k = [
            k0[0] + u * g1[0] + v * g2[0],
            k0[1] + u * g1[1] + v * g2[1],
            k0[2] + u * g1[2] + v * g2[2],
        ];
        k.iter()
            .all(|&x| x >= -BARY_TOL)
            .then(|| normalise(k))
            .flatten()
    }

    /// The last steps at once: [`PatchBuild::merge`], then [`PatchBuild::choose_step`] until
    /// done (call after [`PatchBuild::locate`] returned `true`; points not yet located are
    /// missing from the load). Works in place (the build is large); call it once.
    pub fn finish(&mut self, bank: &Bank) -> Patch {
        self.merge();
        loop {
            if let Some(patch) = self.choose_step(bank, CANDIDATES) {
                return patch;
            }
        }
    }

    /// The quadrature's loads merged with the nodal ones (once, after the last point), and the
    /// node choice started.
    pub fn merge(&mut self) {
        if self.basis.is_some() && self.theta < 1.0 {
            self.quad.add_bary(self.nodes, self.in_contact, 1.0);
            self.acc.merge_scaled(&self.quad, 1.0 - self.theta);
        }
        self.choice = Choice::new(self.acc.total());
    }

    /// Examines up to `candidates` more of the merged loads' nodes, heaviest first, keeping
    /// each one coupled with all kept so far, until [`MAX_CONTACT_NODES`] are kept or none is
    /// left; then the patch, normalised (`None` while not done). After
    /// [`PatchBuild::merge`]; each call costs at most `candidates` scans of the loads and
    /// coupling checks against the kept nodes.
    pub fn choose_step(&mut self, bank: &Bank, candidates: usize) -> Option<Patch> {
        for _ in 0..candidates {
            if self.choice.patch.len >= MAX_CONTACT_NODES {
                break;
            }
            match self.acc.take_heaviest() {
                Some((k, q)) => self.choice.consider(bank, k, q),
                None => return Some(self.choice.finish()),
            }
        }
        (self.choice.patch.len >= MAX_CONTACT_NODES).then(|| self.choice.finish())
    }
}

/// The contact triangle's barycentric coordinates at `anchor` and their change per tip radius
/// along `e1` and `e2` (both in the triangle's plane): `k(anchor + r (u e1 + v e2)) =
/// k0 + u g1 + v g2` (from the triangle's stored plane, [`plane_bary`]). `None` for a triangle
/// or node out of range.
fn contact_frame(
    bank: &Bank,
    triangle: u32,
    nodes: [u16; 3],
    anchor: [f32; 3],
    e1: [f32; 3],
    e2: [f32; 3],
    radius_m: f32,
) -> Option<[[f32; 3]; 3]> {
    let [a, b, c] = vertices(bank.positions(), nodes)?;
    let m = bank.triangle_planes().get(triangle as usize)?.m;
    let k0 = plane_bary(a, b, c, m, anchor);
    let k1 = plane_bary(a, b, c, m, add(anchor, scale(e1, radius_m)));
    let k2 = plane_bary(a, b, c, m, add(anchor, scale(e2, radius_m)));
    Some([k0, sub(k1, k0), sub(k2, k0)])
}

/// How well the mesh resolves the tip, from `n_eff = sum_k (1 - rho_k^2 / r^2)` over the nodes
/// within `r` of the anchor (continuous as the anchor moves: nodes enter at zero): the share
/// `theta` of the nodal quadrature in the weights. 0 up to [`RESOLVED_FROM`] (the 12 points
/// carry the load), rising linearly to 1 at [`RESOLVED_AT`] (the nodes do).
pub fn resolution(n_eff: f32) -> f32 {
    ((n_eff - RESOLVED_FROM) / (RESOLVED_AT - RESOLVED_FROM)).clamp(0.0, 1.0)
}

/// Below this `n_eff` the disk quadrature alone gives the weights.
pub const RESOLVED_FROM: f32 = 2.0;
/// From this `n_eff` the nodal quadrature alone gives the weights.
pub const RESOLVED_AT: f32 = 6.0;

/// The pressures `1 - rho_k^2 / r^2` at the nodes within `r` of the anchor, among the bank's
/// neighbours of the contact triangle's vertex nearest to it, and their sum `n_eff` (see
/// [`resolution`]).
fn nodal_pressures(
    bank: &Bank,
    nodes: [u16; 3],
    bary: [f32; 3],
    anchor: [f32; 3],
    radius_m: f32,
) -> (Accumulator, f32) {
    let mut acc = Accumulator::default();
    let r2 = radius_m * radius_m;
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
    let neighbours = bank.neighbours(usize::from(nearest));
    let mut n_eff = 0.0f32;
    for &k in core::iter::once(&nearest).chain(neighbours) {
        let Some(&x) = bank.positions().get(usize::from(k)) else {
            continue;
        };
        let rho2 = dist2(x, anchor);
        if rho2 < r2 {
            let p = 1.0 - rho2 / r2;
            n_eff += p;
            acc.add(k, p);
        }
    }
    (acc, n_eff)
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
        let [a, b, c] = tri.map(|i| p.get(usize::from(i)).copied().unwrap_or([0.0; 3]));
        let n = cross(sub(b, a), sub(c, a));
        twice += sqrt(dot(n, n));
    }
    twice / 6.0
}

/// Orthonormal `(e1, e2)` spanning the plane of triangle `nodes`, with `e1` the projection of a
/// fixed axis (x, or y where the plane is nearly normal to x), so that neighbouring triangles
/// orient the quadrature alike and the weights stay continuous when the anchor changes
/// triangle.
fn tangent_basis(bank: &Bank, nodes: [u16; 3]) -> Option<([f32; 3], [f32; 3])> {
    let p = bank.positions();
    let [a, b, c] = nodes.map(|i| p.get(usize::from(i)).copied());
    let (a, b, c) = (a?, b?, c?);
    let n = unit(cross(sub(b, a), sub(c, a)))?;
    let axis = if n[0].abs() < 0.9 {
        [1.0, 0.0, 0.0]
    } else {
        [0.0, 1.0, 0.0]
    };
    let e1 = unit(sub(axis, scale(n, dot(axis, n))))?;
    Some((e1, cross(n, e1)))
}

/// Node loads gathered before selection: merges repeated nodes.
#[derive(Clone, Debug)]
struct Accumulator {
    nodes: [u16; CANDIDATES],
    loads: [f32; CANDIDATES],
    len: usize,
    overflow: f32,
}

/// Candidates kept before choosing the heaviest [`MAX_CONTACT_NODES`] (loads beyond them are
/// counted in [`Patch::dropped`]; the shipped liver's patches have at most 7, the 100k liver's
/// 5 mm patches 39).
const CANDIDATES: usize = 48;

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
    /// Empties it (only the used entries are ever read).
    fn clear(&mut self) {
        self.len = 0;
        self.overflow = 0.0;
    }

    /// Nodal pressures to the nodal quadrature's loads `a_k p_k`.
    fn weight_by_lumped_area(&mut self, bank: &Bank) {
        for (&k, q) in self.nodes.iter().zip(self.loads.iter_mut()).take(self.len) {
            *q *= lumped_area(bank, k);
        }
    }

    /// Adds `other`'s loads, normalised to sum `s`.
    fn merge_scaled(&mut self, other: &Accumulator, s: f32) {
        let total = other.loads.iter().take(other.len).sum::<f32>() + other.overflow;
        if !(s > 0.0 && total > 0.0) {
            return;
        }
        for (&k, &q) in other.nodes.iter().zip(&other.loads).take(other.len) {
            self.add(k, s * q / total);
        }
        self.overflow += s * other.overflow / total;
    }

    /// Adds `w` spread over triangle `nodes` by barycentric coordinates `bary`.
    fn add_bary(&mut self, nodes: [u16; 3], bary: [f32; 3], w: f32) {
        for (&k, &b) in nodes.iter().zip(&bary) {
            if b > 0.0 && b.is_finite() {
                self.add(k, w * b);
            }
        }
    }

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

    /// The sum of the loads, kept and overflowed.
    fn total(&self) -> f32 {
        self.loads.iter().take(self.len).sum::<f32>() + self.overflow
    }

    /// The heaviest remaining candidate (ties: the first) and its load, removed (its load set to
    /// 0); `None` when no load is left.
    fn take_heaviest(&mut self) -> Option<(u16, f32)> {
        let (i, &q) = self
            .loads
            .iter()
            .take(self.len)
            .enumerate()
            .filter(|&(_, &q)| q > 0.0)
            .fold(None, |best: Option<(usize, &f32)>, c| match best {
                Some(b) if *b.1 >= *c.1 => Some(b),
                _ => Some(c),
            })?;
        let k = self.nodes.get(i).copied()?;
        if let Some(l) = self.loads.get_mut(i) {
            *l = 0.0;
        }
        Some((k, q))
    }
}

/// A node choice in progress ([`PatchBuild::choose_step`]): the nodes kept so far with their
/// loads, and the total load they are chosen from.
#[derive(Clone, Copy, Debug)]
struct Choice {
    patch: Patch,
    kept: f32,
    total: f32,
}

impl Choice {
    fn new(total: f32) -> Choice {
        Choice {
            patch: Patch {
                nodes: [0; MAX_CONTACT_NODES],
                weights: [0.0; MAX_CONTACT_NODES],
                len: 0,
                dropped: 0.0,
            },
            kept: 0.0,
            total,
        }
    }

    /// Keeps node `k` with load `q` if the bank couples it with every node kept so far
    /// (membership in the neighbour index is enough: kept nodes differ from k).
    fn consider(&mut self, bank: &Bank, k: u16, q: f32) {
        let p = &mut self.patch;
        let coupled = p
            .nodes()
            .iter()
            .all(|&n| bank.neighbours(usize::from(n)).binary_search(&k).is_ok());
        if !coupled {
            return;
        }
        if let (Some(n), Some(w)) = (p.nodes.get_mut(p.len), p.weights.get_mut(p.len)) {
            *n = k;
            *w = q;
            p.len += 1;
            self.kept += q;
        }
    }

    /// The kept nodes, normalised, with the share of the load they leave out.
    fn finish(&self) -> Patch {
        let mut patch = self.patch;
        let (kept, total) = (self.kept, self.total);
        if kept > 0.0 && total > 0.0 {
            for w in patch.weights.iter_mut() {
                *w /= kept;
            }
            patch.dropped = (1.0 - kept / total).max(0.0);
        }
        patch
    }
}

#[cfg(test)]
#[allow(clippy::indexing_slicing, clippy::unwrap_used)]
mod tests {
    extern crate std;
    use super::*;
    use crate::fixtures::grid_patch;
    use std::vec;
    use std::vec::Vec;

    /// Node id of grid point (i, j) on an `n`-wide grid.
    fn id(n: usize, i: usize, j: usize) -> u16 {
        (i + n * j) as u16
    }

    /// The grid's triangle containing `(x, y)` (spacing `h`), its index in `grid_patch`'s
    /// order and the barycentric coordinates: square (i, j) is split into [a, b, c] (u >= v)
    /// and [a, c, d].
    fn locate(n: usize, h: f64, x: f64, y: f64) -> (u32, [u16; 3], [f64; 3]) {
        let (i, j) = ((x / h).floor() as usize, (y / h).floor() as usize);
        let (i, j) = (i.min(n - 2), j.min(n - 2));
        let (u, v) = (x / h - i as f64, y / h - j as f64);
        let square = (2 * (i + (n - 1) * j)) as u32;
        if u >= v {
            (
                square,
                [id(n, i, j), id(n, i + 1, j), id(n, i + 1, j + 1)],
                [1.0 - u, u - v, v],
            )
        } else {
            (
                square + 1,
                [id(n, i, j), id(n, i + 1, j + 1), id(n, i, j + 1)],
                [1.0 - v, u, v - u],
            )
        }
    }

    /// The weights on the flat grid, in f64, with the quadrature points located directly and
    /// the interior nodes' lumped area `h^2`.
    fn reference(n: usize, h: f64, x: f64, y: f64, r: f64) -> Vec<f64> {
        let mut quad = vec![0.0; n * n];
        for &(s, wq, angle) in &QUADRATURE {
            let (s, wq, angle) = (f64::from(s), f64::from(wq), f64::from(angle));
            // The fixture's normal is +z, so e1 = x and e2 = y.
            let (qx, qy) = (x + r * s * angle.cos(), y + r * s * angle.sin());
            let (_, tri, bary) = locate(n, h, qx, qy);
            for (k, b) in tri.iter().zip(bary) {
                quad[usize::from(*k)] += wq * b;
            }
        }
        let mut nodal = vec![0.0; n * n];
        for j in 0..n {
            for i in 0..n {
                let rho2 = (i as f64 * h - x).powi(2) + (j as f64 * h - y).powi(2);
                if rho2 < r * r {
                    assert!(i > 0 && j > 0 && i < n - 1 && j < n - 1, "interior only");
                    nodal[usize::from(id(n, i, j))] = 1.0 - rho2 / (r * r);
                }
            }
        }
        let n_eff: f64 = nodal.iter().sum();
        let theta = ((n_eff - 2.0) / 4.0).clamp(0.0, 1.0);
        quad.iter()
            .zip(&nodal)
            .map(|(q, p)| (1.0 - theta) * q + if n_eff > 0.0 { theta * p / n_eff } else { 0.0 })
            .collect()
    }

    fn dense(p: &Patch, n: usize) -> Vec<f64> {
        let mut w = vec![0.0; n * n];
        for (&k, &wk) in p.nodes().iter().zip(p.weights()) {
            w[usize::from(k)] = f64::from(wk);
        }
        w
    }

    fn patch_at(bank: &Bank, n: usize, h: f64, x: f64, y: f64, r: f64) -> Patch {
        let (t, tri, bary) = locate(n, h, x, y);
        tool_patch(
            bank,
            t,
            tri,
            bary.map(|b| b as f32),
            [x as f32, y as f32, 0.0],
            r as f32,
        )
    }

    #[test]
    fn quadrature_integrates_the_parabolic_pressure() {
        // Total 1; exact for 1, rho^2 and rho^4 (moments of the pressure-weighted disk).
        let total: f32 = QUADRATURE.iter().map(|q| q.1).sum();
        assert!((total - 1.0).abs() < 1e-6);
        for (m, want) in [(2, 1.0 / 3.0), (4, 1.0 / 6.0)] {
            let got: f64 = QUADRATURE
                .iter()
                .map(|&(s, w, _)| f64::from(w) * f64::from(s).powi(m))
                .sum();
            // int_0^1 s^m s (1 - s^2) ds / (1/4)
            assert!((got - want).abs() < 1e-6, "moment {m}: {got}");
        }
        // First moments vanish: the load's centre is the anchor.
        let (cx, cy) = QUADRATURE
            .iter()
            .zip(&DIRECTIONS)
            .fold((0.0, 0.0), |a, (q, d)| {
                (a.0 + q.0 * q.1 * d.0, a.1 + q.0 * q.1 * d.1)
            });
        assert!(cx.abs() < 1e-7 && cy.abs() < 1e-7);
    }

    #[test]
    fn zero_or_small_radius_gives_the_barycentric_weights() {
        let (n, h) = (5, 0.01);
        let bytes = grid_patch(n, h, 0.06);
        let bank = Bank::parse(bytes.as_slice()).unwrap();
        let (x, y) = (0.0172, 0.0121);
        let (_, tri, bary) = locate(n, h, x, y);
        for r in [0.0, 0.0005] {
            let p = patch_at(&bank, n, h, x, y, r);
            assert_eq!(p.nodes().len(), 3, "{p:?}");
            let w = dense(&p, n);
            for (k, b) in tri.iter().zip(bary) {
                assert!((w[usize::from(*k)] - b).abs() < 1e-6, "r {r}: {p:?}");
            }
            assert_eq!(p.dropped, 0.0);
        }
        // A vertex hit with r = 0: one node.
        let p = tool_patch(&bank, 0, [0, 1, 6], [1.0, 0.0, 0.0], [0.0, 0.0, 0.0], 0.0);
        assert_eq!(p.nodes(), &[0]);
        assert_eq!(p.weights(), &[1.0]);
    }

    /// Against the same quadrature located directly on the flat grid, in f64.
    #[test]
    fn weights_match_the_directly_located_quadrature() {
        let (n, h) = (9, 0.001);
        let bytes = grid_patch(n, h, 0.008);
        let bank = Bank::parse(bytes.as_slice()).unwrap();
        for (x, y, r) in [
            (0.00405, 0.00395, 0.0009),
            (0.0043, 0.0037, 0.0015),
            (0.0041, 0.0046, 0.0008),
            (0.0045, 0.0042, 0.0004),
        ] {
            let p = patch_at(&bank, n, h, x, y, r);
            let mut want = reference(n, h, x, y, r);
            // The heaviest MAX_CONTACT_NODES, renormalised (every pair is coupled here).
            let mut order: Vec<usize> = (0..want.len()).collect();
            order.sort_by(|&a, &b| want[b].total_cmp(&want[a]));
            let kept: f64 = order.iter().take(MAX_CONTACT_NODES).map(|&k| want[k]).sum();
            for &k in order.iter().skip(MAX_CONTACT_NODES) {
                want[k] = 0.0;
            }
            let got = dense(&p, n);
            for (k, (g, w)) in got.iter().zip(&want).enumerate() {
                assert!(
                    (g - w / kept).abs() < 2e-6,
                    "({x}, {y}, {r}) node {k}: {g} vs {w}"
                );
            }
            assert!((f64::from(p.dropped) - (1.0 - kept)).abs() < 1e-5, "{p:?}");
        }
    }

    /// A build whose points' walks are cut into budgets of one, two or three steps a call
    /// lands every point where the whole walks do: bit for bit [`tool_patch`]'s patch, on a
    /// grid of sliver rows where a point's walk crosses many triangles.
    #[test]
    fn a_build_in_walk_budgets_is_the_whole_build() {
        // 4 mm squares, and 10 rows 100 um apart above y = 8 mm: the tip (3 mm at (14, 6) mm)
        // covers few nodes, so the quadrature carries the load, and its points above y = 8 mm
        // walk across the sliver rows. (As slivery as the bank's limits allow: 20 rows put
        // 144 candidates in a 4 mm cell, more than `MAX_CELL_CANDIDATES`; pairs coupled within
        // 8 mm keep the neighbours under `MAX_NODE_NEIGHBOURS`.)
        let xs: Vec<f64> = (0..9).map(|i| 0.004 * f64::from(i)).collect();
        let mut ys: Vec<f64> = (0..3).map(|j| 0.004 * f64::from(j)).collect();
        ys.extend((1..=10).map(|j| 0.008 + 0.000_1 * f64::from(j)));
        ys.extend((3..9).map(|j| 0.004 * f64::from(j)));
        let bytes = crate::fixtures::grid_patch_at(&xs, &ys, 0.008);
        let bank = Bank::parse(bytes.as_slice()).unwrap();
        let (x, y) = (0.014f32, 0.006f32);
        let (t, nodes, bary) = bank
            .triangles()
            .iter()
            .enumerate()
            .find_map(|(t, &tri)| {
                let [a, b, c] = vertices(bank.positions(), tri)?;
                let m = bank.triangle_planes()[t].m;
                let k = plane_bary(a, b, c, m, [x, y, 0.0]);
                k.iter().all(|&v| v >= 0.0).then_some((t as u32, tri, k))
            })
            .unwrap();
        let whole = tool_patch(&bank, t, nodes, bary, [x, y, 0.0], 0.003);
        for (points, steps) in [(1, 1), (2, 1), (2, 2), (2, 3), (12, 1)] {
            let mut build = PatchBuild::new();
            build.start(&bank, t, nodes, bary, [x, y, 0.0], 0.003);
            let mut calls = 0;
            while !build.locate(&bank, points, steps) {
                calls += 1;
                assert!(calls < 1000);
            }
            let got = build.finish(&bank);
            assert_eq!(got.nodes(), whole.nodes(), "{points} points, {steps} steps");
            assert_eq!(
                got.weights(),
                whole.weights(),
                "{points} points, {steps} steps"
            );
            if steps == 1 {
                // Walks of several steps were cut: more calls than points to locate.
                assert!(calls + 1 > 12usize.div_ceil(points) + 4, "{calls} calls");
            }
        }
    }

    /// The weights change continuously as the anchor slides across triangles (while no node is
    /// dropped for want of room: a node swapped out of a full patch is a jump).
    #[test]
    fn weights_are_continuous_along_a_slide() {
        let (n, h) = (9, 0.001);
        let bytes = grid_patch(n, h, 0.008);
        let bank = Bank::parse(bytes.as_slice()).unwrap();
        let steps = 2000;
        let mut prev: Option<Vec<f64>> = None;
        let mut max_jump = 0.0f64;
        let mut full = 0;
        for s in 0..=steps {
            // 1.8 mm along a skew line through several triangles.
            let t = s as f64 / steps as f64;
            let (x, y) = (0.0031 + 0.0018 * t, 0.0035 + 0.0011 * t);
            let p = patch_at(&bank, n, h, x, y, 0.0006);
            assert!((p.weights().iter().sum::<f32>() - 1.0).abs() < 1e-5);
            let w = dense(&p, n);
            if let Some(q) = &prev {
                let jump = w
                    .iter()
                    .zip(q)
                    .map(|(a, b)| (a - b).abs())
                    .fold(0.0, f64::max);
                max_jump = max_jump.max(jump);
            }
            prev = (p.dropped == 0.0).then_some(w);
            full += usize::from(p.dropped > 0.0);
        }
        // 0.9 um steps on a 1 mm grid: a continuous weight moves by ~1e-3 per step at most.
        assert!(max_jump < 3e-3, "largest weight jump {max_jump}");
        assert!(full < steps / 4, "{full} of {steps} patches were full");
    }

    #[test]
    fn too_many_or_uncoupled_nodes_are_dropped_and_reported() {
        // r = 3 mm on a 1 mm grid: far more than 8 nodes loaded, the 8 heaviest kept.
        let (n, h) = (9, 0.001);
        let bytes = grid_patch(n, h, 0.007);
        let bank = Bank::parse(bytes.as_slice()).unwrap();
        let p = patch_at(&bank, n, h, 0.004, 0.004, 0.003);
        assert_eq!(p.nodes().len(), MAX_CONTACT_NODES);
        assert!(p.dropped > 0.2 && p.dropped < 1.0, "{p:?}");
        // Truncation 1.5 mm: nodes 2 mm apart are not coupled; no kept pair is uncoupled.
        let bytes = grid_patch(n, h, 0.0015);
        let bank = Bank::parse(bytes.as_slice()).unwrap();
        let p = patch_at(&bank, n, h, 0.004, 0.004, 0.0015);
        for &a in p.nodes() {
            for &b in p.nodes() {
                assert!(bank.coupling(usize::from(a), usize::from(b)).is_some());
            }
        }
        assert!(p.dropped > 0.0, "{p:?}");
    }
}
