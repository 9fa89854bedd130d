//! Contact detection and tracking for the 1 kHz loop (paper section 5), `no_std`, f32, no heap.
//!
//! The tool tip is a point. While free, each tick tests the segment `[prev_tip, tip]` against the
//! triangles of R found through the bank's bucket grid ([`detect`]); while touching, the contact
//! point sticks to the tip and the imposed displacement is `tip - anchor` ([`ContactTracker`]).
//!
//! # Detection
//!
//! The bank's grid carries per-cell certificates, built and checked when the bank is built and
//! checked again by [`Bank::parse`] (`SPEC.md`, "cell clearance" and "cell candidates"): a
//! clearance (every cell a triangle occupies is at least that many cells away) and the list of
//! candidate triangles a path piece of at most [`PIECE_CELLS`] cells starting in the cell can
//! cross. [`detect`] cuts the segment `[prev_tip, tip]` into such pieces, skips a piece that
//! starts at clearance >= 2 after one cell lookup, and otherwise tests the cell's candidates
//! with a plane-crossing test equivalent to Moller-Trumbore: only *entering* crossings count
//! (the segment goes from the outer side, `(p0 - a) . n >= 0`, to the inner side,
//! `(p1 - a) . n <= 0`, against the outward normal), motions within [`PARALLEL_TOL`] of the
//! plane are grazing and ignored, and the crossing point's barycentric coordinates are accepted
//! within [`BARY_TOL`] of the triangle and then clamped to `[0, 1]` and renormalised. The plane
//! test reads only the triangle's stored plane (`SPEC.md`, "triangle planes": `m = n / |n|^2`,
//! `off = m . a`, so the plane value `m . p - off` has the sign of `(p - a) . n`): four loads
//! and two dot products per candidate. Only candidates whose plane the segment crosses load
//! their vertices, for the barycentric coordinates, which the plane gives without a division
//! (`plane_bary`); a path entering a convex part of the surface also crosses the planes of the
//! triangles around its crossing, up to the cell's whole candidate list (`docs/known-gaps.md`,
//! "Tick budget"). A hit
//! exactly on an edge or a vertex is accepted by every triangle around it; the first hit along
//! the segment wins, ties going to the lowest triangle index, so it is reported once and
//! deterministically. The lists are complete for any cell size (the rule is structural, not a
//! search radius), so no grid can miss a triangle; the cell size only trades bank bytes
//! against the candidates tested per tick.
//!
//! # Tracking and sliding (a stick cone)
//!
//! While touching, the anchor (the rest-surface point the tool holds) sticks to the tip and
//! `displacement = tip - anchor`, as long as the displacement stays inside the stick cone
//! around the contact triangle's inward normal: tangential part at most [`STICK_SLOPE`] times
//! the normal part (a Coulomb-like friction cone, on displacements). When the tip leaves the
//! cone, the contact slides: the anchor moves along the surface just far enough to put the
//! displacement back on the cone (the normal is the stored plane's `m / |m|`, so a press in
//! place loads no vertex and takes no square root; the target point is found on the rest
//! surface by a [`SurfaceWalk`] across edges from the current triangle), so the tangential
//! force is bounded by the slope and changes continuously, with no saw-tooth at triangle
//! edges. Contact ends when `(tip - anchor) . n > 0` for the contact triangle's outward rest
//! normal `n` (the contact would pull), checked before and after any slide.
//!
//! A tick's slide takes at most [`SLIDE_STEPS_PER_TICK`] steps of its walk: a slide within the
//! anchor's triangle takes one, across an edge two. A walk that needs more (past a vertex,
//! where the walk goes round the vertex's triangles, or over slivers) goes on at the next tick
//! from the triangle it reached, towards that tick's target (or is dropped when the tip has
//! come back inside the cone). Until it lands the anchor is the target itself, in the plane of
//! the triangle the slide started on, with that triangle and its barycentric coordinates: the
//! displacement stays on the cone (the force of the whole walk, to the surface's curvature
//! over a tick's motion), and the contact's `W` or patch is the start point's, less than a
//! tick's motion away (0.45 mm at the shipped scene's 0.45 m/s). A slide that crosses at most
//! one edge a tick is tracked exactly as by the whole walk.

// `!(x > 0.0)` is deliberate throughout: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use crate::vec3::{add, cross, dot, scale, sqrt, sub};
use bank_format::{Bank, PIECE_CELLS, TrianglePlane};

/// Grazing threshold: a segment whose direction makes `|cos| <= PARALLEL_TOL` with a triangle's
/// normal is treated as parallel to it (no hit).
pub const PARALLEL_TOL: f32 = 1.0e-4;
/// Barycentric tolerance: a crossing point whose smallest barycentric coordinate is at least
/// `-BARY_TOL` is inside the triangle (edges and vertices are shared by their triangles).
pub const BARY_TOL: f32 = 1.0e-5;
/// Cap on the triangle-to-triangle steps of one walk ([`SurfaceWalk`]; a slide's walk may span
/// ticks, [`SLIDE_STEPS_PER_TICK`]).
pub const MAX_SLIDE_STEPS: u32 = 32;
/// Steps of a [`SurfaceWalk`] a sliding contact takes per tick (each a plane test and at most
/// one edge crossing, or the closest point of the triangle where the walk stops): one for a
/// slide within the anchor's triangle, two across an edge. Under QEMU on the shipped liver a
/// held contact's tracking costs about 200 instructions while it sticks, 520 with one step and
/// up to 810 with two (three or four steps, which a slide at 0.45 m/s past a vertex needs, cost
/// 930 to 1,400); with the rest of a contact tick (about 2,160) two steps keep the loop body
/// under 3,000.
pub const SLIDE_STEPS_PER_TICK: u32 = 2;
/// Most path pieces [`detect`] cuts a tick's path into: the loop shortens a longer path to its
/// last [`max_path_m`] before detecting ([`path_tail`]). With at most
/// [`bank_format::MAX_CELL_CANDIDATES`] candidates a cell (`Bank::parse` refuses more), a
/// tick's detection tests at most `MAX_DETECT_PIECES * MAX_CELL_CANDIDATES` = 384 candidates,
/// whatever the bank and the motion: see `SPEC.md`, "Limits the tick's cost rests on", for the
/// budget derived from it. Three pieces are 1.35 cells: the whole tick of a tip at the
/// overspeed threshold (1 mm at 1 m/s) is swept on any grid of cells from 0.75 mm.
pub const MAX_DETECT_PIECES: u32 = 3;

/// The longest tip path (m) a tick sweeps for contacts on `bank`, for a tip-speed threshold of
/// `max_tip_speed_m_s` over ticks of `tick_s`: what the overspeed check lets through while
/// armed (a longer step is an `Overspeed` fault that very tick, with zero current), and at
/// most [`MAX_DETECT_PIECES`] pieces of the bank's grid (so a bank with a huge threshold or
/// tiny cells cannot raise the cost).
pub fn max_path_m(bank: &Bank, max_tip_speed_m_s: f32, tick_s: f32) -> f32 {
    // 0.99: the pieces' count is `floor(length / piece) + 1`.
    let pieces = 0.99 * MAX_DETECT_PIECES as f32 * PIECE_CELLS * bank.grid().cell_size_m();
    let speed = max_tip_speed_m_s * tick_s;
    // A NaN threshold falls back to the pieces (`min` returns the number).
    speed.min(pieces)
}

/// The part of the tick's path `[prev_tip, tip]` that detection sweeps: all of it when at most
/// `max_m` long ([`max_path_m`]), else its last `max_m`, ending at `tip`. A longer step is
/// faster than the armed device may move (it faults `Overspeed`) or a move while disarmed; a
/// surface crossing before its last `max_m` is missed as after a pose jump (the tip is then
/// under the surface untracked, and renders nothing until it leaves and enters again).
pub fn path_tail(prev_tip: [f32; 3], tip: [f32; 3], max_m: f32) -> [f32; 3] {
    let d = sub(tip, prev_tip);
    let l2 = dot(d, d);
    // Written so that NaN keeps the path (detection refuses a non-finite one).
    if !(l2 > max_m * max_m) {
        return prev_tip;
    }
    sub(tip, scale(d, max_m / sqrt(l2)))
}

/// The stick cone: while touching, the tangential displacement may reach this many times the
/// normal displacement before the contact slides (about the friction coefficient of an
/// instrument on wet tissue).
pub const STICK_SLOPE: f32 = 0.2;

/// What the contact solve needs this tick.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ContactState {
    /// No contact: no force.
    Free,
    /// The tip presses on the surface.
    Touching {
        /// Index into `bank.triangles()`.
        triangle: u32,
        /// The triangle's nodes (same order as `bary`).
        nodes: [u16; 3],
        /// Barycentric coordinates of `anchor` in the triangle: each in `[0, 1]`, sum 1 (while
        /// a slide's walk is under way, those of the point the slide started from).
        bary: [f32; 3],
        /// The rest-surface point the tip holds, m (while a slide's walk is under way, the
        /// slide's target in the plane of `triangle`, less than the walk's ticks of motion
        /// outside it).
        anchor: [f32; 3],
        /// `tip - anchor`, m: the displacement imposed on the contact point.
        displacement: [f32; 3],
    },
}

/// A segment-surface crossing found by [`detect`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Index into `bank.triangles()`.
    pub triangle: u32,
    /// The triangle's nodes.
    pub nodes: [u16; 3],
    /// Parameter along the segment, `0..=1`.
    pub t: f32,
    /// Crossing point on the triangle (from the clamped barycentric coordinates), m.
    pub point: [f32; 3],
    /// Barycentric coordinates of `point`, each in `[0, 1]`, sum 1.
    pub bary: [f32; 3],
}

/// The contact state kept between ticks.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ContactTracker {
    /// The anchor: the rest-surface point the tool holds.
    active: Option<SurfacePoint>,
    /// A slide's walk that ran out of its tick's [`SLIDE_STEPS_PER_TICK`], resumed the next
    /// tick.
    slide: Option<SurfaceWalk>,
}

impl ContactTracker {
    /// A free tracker (the bank's grid holds everything detection needs).
    pub const fn new() -> ContactTracker {
        ContactTracker {
            active: None,
            slide: None,
        }
    }

    /// Whether a contact is held (the next [`ContactTracker::update`] tracks it and does not
    /// read its path).
    pub fn touching(&self) -> bool {
        self.active.is_some()
    }

    /// Drop any contact (e.g. after a fault or a bank change).
    pub fn reset(&mut self) {
        self.active = None;
        self.slide = None;
    }

    /// One tick: the tip moved from `prev_tip` to `tip` (m, bank frame). A non-finite tip drops
    /// the contact and reports [`ContactState::Free`].
    pub fn update(&mut self, bank: &Bank, prev_tip: [f32; 3], tip: [f32; 3]) -> ContactState {
        if !finite(tip) {
            self.reset();
            return ContactState::Free;
        }
        if let Some(active) = self.active {
            self.active = track(bank, active, &mut self.slide, tip);
        } else if let Some(hit) = detect(bank, prev_tip, tip) {
            self.active = Some(SurfacePoint {
                triangle: hit.triangle,
                nodes: hit.nodes,
                bary: hit.bary,
                point: hit.point,
            });
        }
        match self.active {
            Some(a) => ContactState::Touching {
                triangle: a.triangle,
                nodes: a.nodes,
                bary: a.bary,
                anchor: a.point,
                displacement: sub(tip, a.point),
            },
            None => ContactState::Free,
        }
    }
}

/// The first entering crossing of the segment `[p0, p1]` with R's surface, if any.
///
/// The segment is clipped to the grid box and cut into `n` equal pieces of Chebyshev length at
/// most [`PIECE_CELLS`] cells, processed in order. A piece whose start lies in a cell of
/// clearance >= 2 cannot reach the surface (every occupied cell is at least two cells away,
/// more than the piece's length) and costs one cell lookup. Otherwise the cell's candidate
/// triangles, which hold every triangle a piece starting in the cell can cross, are tested
/// against the whole segment (`intersect`: the stored plane first, the vertices only for a
/// crossing); a hit at `t` up to the piece's end is final (an earlier crossing
/// would lie in this or an earlier piece, whose candidates hold its triangle). The first piece
/// with a hit gives the answer: the smallest `t`, ties going to the lowest triangle index.
pub fn detect(bank: &Bank, p0: [f32; 3], p1: [f32; 3]) -> Option<Hit> {
    if !finite(p0) || !finite(p1) {
        return None;
    }
    let grid = bank.grid();
    let h = grid.cell_size_m();
    let origin = grid.origin_m();
    let dims = grid.dims();
    let dir = sub(p1, p0);
    // Clip to the grid box (padded by a hundredth of a cell).
    let pad = 0.01 * h;
    let (mut ta, mut tb) = (0.0f32, 1.0f32);
    for (((&o, &n), &p), &d) in origin.iter().zip(&dims).zip(&p0).zip(&dir) {
        let lo = o - pad;
        let hi = o + f32::from(n) * h + pad;
        if d == 0.0 {
            if p < lo || p > hi {
                return None;
            }
        } else {
            let (u, v) = ((lo - p) / d, (hi - p) / d);
            let (near, far) = if u < v { (u, v) } else { (v, u) };
            ta = larger(ta, near);
            tb = smaller(tb, far);
        }
    }
    if !(ta <= tb) {
        return None;
    }
    let cheb = dir.iter().fold(0.0f32, |m, v| larger(m, v.abs())) * (tb - ta);
    // The clipped segment spans at most 65535 cells per axis: n <= 145,635.
    let q = cheb / (h * PIECE_CELLS);
    let n = if q < 1.0e6 { q as u32 + 1 } else { 1_000_000 };
    let positions = bank.positions();
    let triangles = bank.triangles();
    let planes = bank.triangle_planes();
    let span = tb - ta;
    for i in 0..n {
        let t0 = ta + span * (i as f32 / n as f32);
        let Some(index) = grid
            .clamped_cell(add(p0, scale(dir, t0)))
            .and_then(|c| grid.cell_index(c))
        else {
            continue;
        };
        if grid.clearance(index) >= 2 {
            continue;
        }
        let t1 = ta + span * ((i + 1) as f32 / n as f32);
        let last = i + 1 == n;
        let mut best: Option<Hit> = None;
        for &ti in grid.cell_triangles(index) {
            // Candidates ascend, so on equal t the first one found has the lower index.
            let keep = |t: f32| (last || t <= t1) && best.is_none_or(|b| t < b.t);
            if let Some(hit) = intersect(planes, triangles, positions, ti, p0, p1, keep) {
                best = Some(hit);
            }
        }
        if best.is_some() {
            return best;
        }
    }
    None
}

/// Entering crossing of `[p0, p1]` with triangle `ti` (`SPEC.md`, "triangle planes"), if the
/// caller would `keep` a hit at its `t`.
///
/// The plane first, from the stored plane alone: the plane values `s0 = m . p0 - off` and
/// `s1 = m . p1 - off` have the signs of `(p0 - a) . n` and `(p1 - a) . n`, and the segment
/// enters when `s0 >= 0`, `s1 <= 0` and `s0 > s1`, at `t = s0 / (s0 - s1)`. A tick's short
/// segment away from the surface crosses no candidate's plane, so each stops after `s0` or
/// `s1`. For a
/// crossing the caller keeps, and only then, the vertices: the crossing point's barycentric
/// coordinates (`plane_bary`'s, each tested as soon as it is known), then not grazing
/// (`(m . d)^2 > PARALLEL_TOL^2 (d . d) (m . m)` for `d = p1 - p0`: the cosine test on `n`).
/// The tests are a conjunction, so their order changes no result; it puts the cheap ones and
/// those that reject most (a crossing of a candidate's plane mostly misses the triangle) first.
#[inline(always)]
fn intersect(
    planes: &[TrianglePlane],
    triangles: &[[u16; 3]],
    positions: &[[f32; 3]],
    ti: u16,
    p0: [f32; 3],
    p1: [f32; 3],
    keep: impl Fn(f32) -> bool,
) -> Option<Hit> {
    let plane = planes.get(usize::from(ti))?;
    let s0 = plane.value(p0);
    if !(s0 >= 0.0) {
        return None;
    }
    let s1 = plane.value(p1);
    if !(s1 <= 0.0 && s0 > s1) {
        return None;
    }
    // In [0, 1] without a clamp: 0 <= s0 <= s0 - s1 (s1 <= 0; rounding is monotone).
    let t = s0 / (s0 - s1);
    if !keep(t) {
        return None;
    }
    let m = plane.m;
    let dir = sub(p1, p0);
    let x = add(p0, scale(dir, t));
    // plane_bary's coordinates, each vertex loaded when first needed.
    let tri = *triangles.get(usize::from(ti))?;
    let [ia, ib, ic] = tri.map(usize::from);
    let (a, c) = (*positions.get(ia)?, *positions.get(ic)?);
    let xa = sub(x, a);
    let k1 = dot(cross(xa, sub(c, a)), m);
    if !(k1 >= -BARY_TOL) {
        return None;
    }
    let b = *positions.get(ib)?;
    let k2 = dot(cross(sub(b, a), xa), m);
    let k = [1.0 - k1 - k2, k1, k2];
    if !(k2 >= -BARY_TOL && k[0] >= -BARY_TOL) {
        return None;
    }
    // Entering only, and not grazing.
    let dm = dot(dir, m);
    if !(dm < 0.0) || dm * dm <= PARALLEL_TOL * PARALLEL_TOL * dot(dir, dir) * dot(m, m) {
        return None;
    }
    let bary = normalise(k)?;
    Some(Hit {
        triangle: u32::from(ti),
        nodes: tri,
        t,
        point: combine(a, b, c, bary),
        bary,
    })
}

/// Next tracking state, `None` when the contact is released.
///
/// From the contact triangle's stored plane `m` (parallel to the outward normal n, `SPEC.md`
/// "triangle planes"): the contact pulls when `d . m > 0` (`d = tip - anchor`); the inward
/// depth is `-(d . m) / |m|` and the tangential part `dt = d - m (d . m) / (m . m)`. The stick
/// test `|dt| <= STICK_SLOPE depth` is compared squared, so a press in place takes no square
/// root and loads no vertex; only a slide does. A slide walks towards its target for at most
/// [`SLIDE_STEPS_PER_TICK`] steps, resuming `slide` (the last tick's unfinished walk) when there
/// is one; a walk still under way is left in `slide` and the anchor is the target, on the held
/// triangle (see the module notes).
fn track(
    bank: &Bank,
    active: SurfacePoint,
    slide: &mut Option<SurfaceWalk>,
    tip: [f32; 3],
) -> Option<SurfacePoint> {
    let planes = bank.triangle_planes();
    let m = planes.get(active.triangle as usize)?.m;
    let mm = dot(m, m);
    let d = sub(tip, active.point);
    let dm = dot(d, m);
    if !(mm > 0.0) || dm > 0.0 {
        *slide = None;
        return None;
    }
    // Normal (inward, >= 0: depth^2 = dm^2 / mm) and tangential parts of the displacement.
    let dt = sub(d, scale(m, dm / mm));
    let t2 = dot(dt, dt);
    if !(t2 > STICK_SLOPE * STICK_SLOPE * (dm * dm / mm)) {
        *slide = None;
        return Some(active);
    }
    // Slide: move the anchor along the tangential displacement onto the cone's edge.
    let t = sqrt(t2);
    let allowed = STICK_SLOPE * (-dm / sqrt(mm));
    let target = add(active.point, scale(dt, 1.0 - allowed / t));
    let walk = slide.get_or_insert_with(|| SurfaceWalk::new(active.triangle, active.nodes));
    let mut steps = SLIDE_STEPS_PER_TICK;
    let near = match walk.advance(bank, target, &mut steps) {
        // Under way: for this tick the anchor is the target itself, in the held triangle's
        // plane, so the displacement stays on the cone; the triangle and its coordinates are
        // the held ones until the walk lands.
        Walk::Walking => {
            return Some(SurfacePoint {
                point: target,
                ..active
            });
        }
        Walk::Landed(near) => near,
        Walk::Lost => {
            *slide = None;
            return None;
        }
    };
    *slide = None;
    let m = planes.get(near.triangle as usize)?.m;
    if dot(sub(tip, near.point), m) > 0.0 {
        return None;
    }
    Some(near)
}

/// A point of R's rest surface where a [`SurfaceWalk`] landed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfacePoint {
    /// Index into `bank.triangles()`.
    pub triangle: u32,
    /// The triangle's nodes.
    pub nodes: [u16; 3],
    /// Barycentric coordinates of `point`, each in `[0, 1]`, sum 1.
    pub bary: [f32; 3],
    /// The point, m.
    pub point: [f32; 3],
}

/// A walk across R's edges to the rest-surface point under a point `p` near the surface, which
/// can stop and resume: each step projects `p` onto the current triangle's plane (its
/// barycentric coordinates from the stored plane, `plane_bary`); if the projection lies inside,
/// that is the point; otherwise the walk crosses the edge opposite the most negative
/// barycentric coordinate into the neighbouring triangle. After [`MAX_SLIDE_STEPS`] steps in
/// all, at a boundary edge of R, or when the walk would step straight back (over a ridge, where
/// `p` projects outside both triangles), the walk stops, and its answer is the closest point of
/// the current triangle, one step more. A local search, about a hundred operations per step:
/// it follows the surface around `start`, never jumping to a fold elsewhere. A caller with a
/// per-tick budget (a slide, [`SLIDE_STEPS_PER_TICK`]; a patch rebuild,
/// [`crate::patch::PatchBuild::locate`]) takes a few steps a tick; for a fixed `p` the point it
/// lands on does not depend on how the steps were split. A slide resumes its walk towards the
/// next tick's target, from where it stopped.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfaceWalk {
    triangle: u32,
    nodes: [u16; 3],
    came_from: Option<u32>,
    /// Steps taken; [`MAX_SLIDE_STEPS`] once the walk has stopped on `triangle` (what is left
    /// is its closest point).
    taken: u32,
}

/// Where a [`SurfaceWalk::advance`] ended.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Walk {
    /// At the point.
    Landed(SurfacePoint),
    /// The budget ran out first: call `advance` again with the same `p`.
    Walking,
    /// The bank's indices do not hold (a triangle or node out of range).
    Lost,
}

impl SurfaceWalk {
    /// A walk starting on triangle `triangle` (nodes `nodes`).
    pub fn new(triangle: u32, nodes: [u16; 3]) -> SurfaceWalk {
        SurfaceWalk {
            triangle,
            nodes,
            came_from: None,
            taken: 0,
        }
    }

    /// Takes steps towards the point under `p` while `budget` lasts, one off it per step (the
    /// closing closest point of a stopped walk included).
    pub fn advance(&mut self, bank: &Bank, p: [f32; 3], budget: &mut u32) -> Walk {
        let positions = bank.positions();
        let planes = bank.triangle_planes();
        loop {
            if *budget == 0 {
                return Walk::Walking;
            }
            *budget -= 1;
            if self.taken >= MAX_SLIDE_STEPS {
                break;
            }
            self.taken += 1;
            let (Some([a, b, c]), Some(plane)) = (
                vertices(positions, self.nodes),
                planes.get(self.triangle as usize),
            ) else {
                return Walk::Lost;
            };
            let k = plane_bary(a, b, c, plane.m, p);
            let (i, low) =
                k.iter().enumerate().fold(
                    (0, f32::INFINITY),
                    |m, (i, &v)| if v < m.1 { (i, v) } else { m },
                );
            if low >= -BARY_TOL {
                return match normalise(k) {
                    Some(bary) => Walk::Landed(SurfacePoint {
                        triangle: self.triangle,
                        nodes: self.nodes,
                        bary,
                        point: combine(a, b, c, bary),
                    }),
                    None => Walk::Lost,
                };
            }
            // The edge opposite vertex i.
            let n = self.nodes;
            let [u, v] = match i {
                0 => [n[1], n[2]],
                1 => [n[2], n[0]],
                _ => [n[0], n[1]],
            };
            match neighbour_across(bank, self.triangle, u, v) {
                Some((t, tri)) if Some(t) != self.came_from => {
                    self.came_from = Some(self.triangle);
                    self.triangle = t;
                    self.nodes = tri;
                }
                _ => self.taken = MAX_SLIDE_STEPS,
            }
        }
        let Some([a, b, c]) = vertices(positions, self.nodes) else {
            return Walk::Lost;
        };
        match closest_on_triangle(p, a, b, c) {
            Some((point, bary, _)) => Walk::Landed(SurfacePoint {
                triangle: self.triangle,
                nodes: self.nodes,
                bary,
                point,
            }),
            None => Walk::Lost,
        }
    }
}

/// The triangle other than `t` with edge `(u, v)`, if R has one: the first triangle of both
/// `u`'s and `v`'s lists other than `t`, by merging the two lists (each strictly ascending and
/// exactly the node's triangles, `SPEC.md` "Node-triangle adjacency"), so only the triangle
/// found is loaded: at most 32 comparisons with [`bank_format::MAX_NODE_TRIANGLES`] a node.
fn neighbour_across(bank: &Bank, t: u32, u: u16, v: u16) -> Option<(u32, [u16; 3])> {
    let mut a = bank.node_triangles(usize::from(u)).iter();
    let mut b = bank.node_triangles(usize::from(v)).iter();
    let (mut x, mut y) = (*a.next()?, *b.next()?);
    loop {
        if x < y {
            x = *a.next()?;
        } else if y < x {
            y = *b.next()?;
        } else if u32::from(x) != t {
            let tri = *bank.triangles().get(usize::from(x))?;
            return Some((u32::from(x), tri));
        } else {
            (x, y) = (*a.next()?, *b.next()?);
        }
    }
}

/// Closest point of triangle `abc` to `p` (Ericson, Real-Time Collision Detection 5.1.5): the
/// point, its barycentric coordinates, and the squared distance.
fn closest_on_triangle(
    p: [f32; 3],
    a: [f32; 3],
    b: [f32; 3],
    c: [f32; 3],
) -> Option<([f32; 3], [f32; 3], f32)> {
    let ab = sub(b, a);
    let ac = sub(c, a);
    let ap = sub(p, a);
    let d1 = dot(ab, ap);
    let d2 = dot(ac, ap);
    let bp = sub(p, b);
    let d3 = dot(ab, bp);
    let d4 = dot(ac, bp);
    let cp = sub(p, c);
    let d5 = dot(ab, cp);
    let d6 = dot(ac, cp);
    let vc = d1 * d4 - d3 * d2;
    let vb = d5 * d2 - d1 * d6;
    let va = d3 * d6 - d5 * d4;
    let k = if d1 <= 0.0 && d2 <= 0.0 {
        [1.0, 0.0, 0.0]
    } else if d3 >= 0.0 && d4 <= d3 {
        [0.0, 1.0, 0.0]
    } else if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = ratio(d1, d1 - d3);
        [1.0 - v, v, 0.0]
    } else if d6 >= 0.0 && d5 <= d6 {
        [0.0, 0.0, 1.0]
    } else if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = ratio(d2, d2 - d6);
        [1.0 - w, 0.0, w]
    } else if va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0 {
        let w = ratio(d4 - d3, (d4 - d3) + (d5 - d6));
        [0.0, 1.0 - w, w]
    } else {
        let s = va + vb + vc;
        if !(s > 0.0) {
            return None;
        }
        [va / s, vb / s, vc / s]
    };
    let k = normalise(k)?;
    let q = combine(a, b, c, k);
    let d = sub(p, q);
    let d2 = dot(d, d);
    d2.is_finite().then_some((q, k, d2))
}

/// `num / den` clamped to `[0, 1]`, 0 when `den` is not positive.
fn ratio(num: f32, den: f32) -> f32 {
    if den > 0.0 {
        (num / den).clamp(0.0, 1.0)
    } else {
        0.0
    }
}

/// Barycentric coordinates of `x`'s projection onto the plane of `abc`, from the triangle's
/// stored `m = n / |n|^2` (`SPEC.md`, "triangle planes"): `k1 = ((x - a) x (c - a)) . m`,
/// `k2 = ((b - a) x (x - a)) . m`, `k0 = 1 - k1 - k2`. Two triple products, no division.
pub(crate) fn plane_bary(
    a: [f32; 3],
    b: [f32; 3],
    c: [f32; 3],
    m: [f32; 3],
    x: [f32; 3],
) -> [f32; 3] {
    let xa = sub(x, a);
    let k1 = dot(cross(xa, sub(c, a)), m);
    let k2 = dot(cross(sub(b, a), xa), m);
    [1.0 - k1 - k2, k1, k2]
}

/// Clamp to `[0, 1]` and rescale to sum 1; `None` for NaN or an all-zero input.
pub(crate) fn normalise(k: [f32; 3]) -> Option<[f32; 3]> {
    let [k0, k1, k2] = k.map(|v| v.clamp(0.0, 1.0));
    let s = k0 + k1 + k2;
    if !(s > 0.0) || !s.is_finite() {
        return None;
    }
    let (k0, k1, k2) = (k0 / s, k1 / s, k2 / s);
    // Put the rounding residue on the largest coordinate (the first of equals).
    let rest = |x: f32, y: f32| (1.0 - (x + y)).clamp(0.0, 1.0);
    Some(if k0 >= k1 && k0 >= k2 {
        [rest(k1, k2), k1, k2]
    } else if k1 >= k2 {
        [k0, rest(k0, k2), k2]
    } else {
        [k0, k1, rest(k0, k1)]
    })
}

pub(crate) fn vertices(positions: &[[f32; 3]], tri: [u16; 3]) -> Option<[[f32; 3]; 3]> {
    Some([
        *positions.get(usize::from(tri[0]))?,
        *positions.get(usize::from(tri[1]))?,
        *positions.get(usize::from(tri[2]))?,
    ])
}

fn combine(a: [f32; 3], b: [f32; 3], c: [f32; 3], k: [f32; 3]) -> [f32; 3] {
    let [k0, k1, k2] = k;
    let mut out = [0.0; 3];
    for (((o, &x), &y), &z) in out.iter_mut().zip(&a).zip(&b).zip(&c) {
        *o = k0 * x + k1 * y + k2 * z;
    }
    out
}

/// The larger of `a` and `b`, by one comparison (`f32::max` is a library call on the MCU); the
/// callers' values are never NaN.
fn larger(a: f32, b: f32) -> f32 {
    if a > b { a } else { b }
}

/// The smaller of `a` and `b` (see [`larger`]).
fn smaller(a: f32, b: f32) -> f32 {
    if a < b { a } else { b }
}

fn finite(p: [f32; 3]) -> bool {
    p.iter().all(|v| v.is_finite())
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use bank_format::AlignedBytes;
    use std::vec::Vec;

    const SPACING: f64 = 0.01;

    /// A flat 5 x 5 patch at z = 0, 1 cm spacing, outward normal +z.
    fn patch() -> AlignedBytes {
        patch_with_cell(SPACING)
    }

    /// The patch with grid cells of `cell` m, its nodes lifted by `bump(x, y)` (a curved
    /// surface, so triangles are not coplanar).
    fn patch_with_cell(cell: f64) -> AlignedBytes {
        patch_shaped(cell, |_, _| 0.0)
    }

    fn patch_shaped(cell: f64, bump: impl Fn(f64, f64) -> f64) -> AlignedBytes {
        patch_placed(cell, [0.0; 3], bump)
    }

    /// [`patch_shaped`] moved by `offset` (m).
    fn patch_placed(cell: f64, offset: [f64; 3], bump: impl Fn(f64, f64) -> f64) -> AlignedBytes {
        let mut p = Vec::new();
        for j in 0..5 {
            for i in 0..5 {
                let (x, y) = (SPACING * i as f64, SPACING * j as f64);
                p.push([x + offset[0], y + offset[1], bump(x, y) + offset[2]]);
            }
        }
        let id = |i: u32, j: u32| i + 5 * j;
        let mut triangles = Vec::new();
        for j in 0..4 {
            for i in 0..4 {
                let (a, b, c, d) = (id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
                triangles.push([a, b, c]);
                triangles.push([a, c, d]);
            }
        }
        let b = crate::fixtures::surface_builder(
            p,
            triangles,
            0.015,
            cell,
            crate::fixtures::bench_device([0.02, 0.02, 0.1]),
        );
        AlignedBytes::new(&b.build().unwrap())
    }

    fn assert_valid(state: &ContactState, tip: [f32; 3]) {
        if let ContactState::Touching {
            bary,
            anchor,
            displacement,
            ..
        } = *state
        {
            assert!(bary.iter().all(|&k| (-1.0e-6..=1.0 + 1.0e-6).contains(&k)));
            assert!((bary[0] + bary[1] + bary[2] - 1.0).abs() < 1.0e-5);
            assert!(finite(anchor) && finite(displacement));
            for i in 0..3 {
                assert!((displacement[i] - (tip[i] - anchor[i])).abs() < 1.0e-7);
            }
        }
    }

    /// Run a polyline of tips from `start`; returns the states.
    fn run(
        bank: &Bank,
        tr: &mut ContactTracker,
        start: [f32; 3],
        tips: &[[f32; 3]],
    ) -> Vec<ContactState> {
        let mut prev = start;
        let mut out = Vec::new();
        for &tip in tips {
            let s = tr.update(bank, prev, tip);
            assert_valid(&s, tip);
            out.push(s);
            prev = tip;
        }
        out
    }

    fn touching(s: &ContactState) -> bool {
        matches!(s, ContactState::Touching { .. })
    }

    #[test]
    fn press_and_release() {
        let bytes = patch();
        let bank = Bank::parse(&bytes).unwrap();
        let mut tr = ContactTracker::new();
        let (x, y) = (0.013f32, 0.017f32);
        let zs = [
            0.003, 0.001, -0.001, -0.002, -0.003, -0.001, 0.0, 0.0005, 0.002, -0.0005,
        ];
        let tips: Vec<[f32; 3]> = zs.iter().map(|&z| [x, y, z]).collect();
        let states = run(&bank, &mut tr, [x, y, 0.005], &tips);
        let t: Vec<bool> = states.iter().map(touching).collect();
        assert_eq!(
            t,
            [
                false, false, true, true, true, true, true, false, false, true
            ]
        );
        for (s, tip) in states.iter().zip(&tips) {
            if let ContactState::Touching {
                anchor,
                displacement,
                nodes,
                triangle,
                ..
            } = *s
            {
                assert!((anchor[0] - x).abs() < 1.0e-6 && (anchor[1] - y).abs() < 1.0e-6);
                assert_eq!(anchor[2], 0.0);
                assert!((displacement[2] - tip[2]).abs() < 1.0e-7);
                assert_eq!(bank.triangles()[triangle as usize], nodes);
            }
        }
    }

    fn single_hit(bank: &Bank, from: [f32; 3], to: [f32; 3]) -> ([f32; 3], [f32; 3]) {
        let mut tr = ContactTracker::new();
        match tr.update(bank, from, to) {
            ContactState::Touching { bary, anchor, .. } => {
                assert!(bary.iter().all(|k| k.is_finite()));
                assert!((bary.iter().sum::<f32>() - 1.0).abs() < 1.0e-6);
                (bary, anchor)
            }
            ContactState::Free => panic!("no hit from {from:?} to {to:?}"),
        }
    }

    /// Also with the patch 17 cm from the origin, where the plane values `m . p - off` are
    /// evaluated from the points' absolute coordinates (`SPEC.md`, "triangle planes": their
    /// rounding is a few ulp of `|p|`), an edge or vertex hit is still on the edge or vertex.
    #[test]
    fn hits_on_edges_and_vertices_count_once() {
        for o in [[0.0f32; 3], [0.12, -0.08, 0.1]] {
            let bytes = patch_placed(SPACING, o.map(f64::from), |_, _| 0.0);
            let bank = Bank::parse(&bytes).unwrap();
            // Axis edge, diagonal edge, interior vertex, boundary vertex; vertical and slanted.
            for (x, y) in [
                (0.015f32, 0.01f32),
                (0.015, 0.015),
                (0.01, 0.01),
                (0.0, 0.0),
                (0.02, 0.04),
            ] {
                for (dx, dy) in [(0.0f32, 0.0f32), (0.003, -0.002)] {
                    let from = [x + dx + o[0], y + dy + o[1], 0.002 + o[2]];
                    let to = [x - 0.5 * dx + o[0], y - 0.5 * dy + o[1], -0.001 + o[2]];
                    let (bary, anchor) = single_hit(&bank, from, to);
                    let hit = detect(&bank, from, to).unwrap();
                    assert_eq!(hit.bary, bary);
                    assert!((anchor[0] - (x + o[0])).abs() < 1.0e-6, "{anchor:?}");
                    assert!((anchor[1] - (y + o[1])).abs() < 1.0e-6, "{anchor:?}");
                    assert!(bary.iter().any(|&k| k < 1.0e-5), "on an edge: {bary:?}");
                }
            }
            let (x, y, z) = (0.01 + o[0], 0.01 + o[1], o[2]);
            let (bary, _) = single_hit(&bank, [x, y, z + 0.002], [x, y, z - 0.002]);
            assert!(
                bary.iter().any(|&k| k > 1.0 - 1.0e-5),
                "on a vertex: {bary:?}"
            );
        }
    }

    /// The division-free barycentric coordinates from the stored plane are those of the point's
    /// projection (an f64 reference), on the curved patch's differently tilted triangles, for
    /// points inside and outside the triangle and off its plane.
    #[test]
    fn plane_barycentric_coordinates_are_the_projections() {
        let bytes = patch_shaped(SPACING, |x, y| 0.2 * (x - 0.02) * (y - 0.015) + 3.0 * x * x);
        let bank = Bank::parse(&bytes).unwrap();
        for (tri, plane) in bank.triangles().iter().zip(bank.triangle_planes()) {
            let [a, b, c] = vertices(bank.positions(), *tri).unwrap();
            let [a64, b64, c64] = [a, b, c].map(|v| v.map(f64::from));
            let (u, v) = (
                [0, 1, 2].map(|i| b64[i] - a64[i]),
                [0, 1, 2].map(|i| c64[i] - a64[i]),
            );
            let n = [
                u[1] * v[2] - u[2] * v[1],
                u[2] * v[0] - u[0] * v[2],
                u[0] * v[1] - u[1] * v[0],
            ];
            let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
            for (k, h) in [
                ([0.2, 0.3, 0.5], 0.0),
                ([0.6, -0.1, 0.5], 0.002),
                ([1.0, 0.0, 0.0], -0.001),
                ([-0.5, 0.75, 0.75], 0.004),
            ] {
                let x = [0, 1, 2].map(|i| {
                    (k[0] * a64[i] + k[1] * b64[i] + k[2] * c64[i] + h * n[i] / len) as f32
                });
                let got = plane_bary(a, b, c, plane.m, x);
                for i in 0..3 {
                    assert!(
                        (f64::from(got[i]) - k[i]).abs() < 1.0e-5,
                        "{got:?} vs {k:?}"
                    );
                }
            }
        }
    }

    /// The stick cone on a tilted plane (normal `(-0.3, -0.2, 1)`, neither an axis nor the same
    /// scale in `m` per component): a tangential displacement within the cone keeps the anchor,
    /// one beyond it slides the anchor until the displacement is on the cone's edge.
    #[test]
    fn stick_cone_on_a_tilted_plane() {
        let bytes = patch_shaped(SPACING, |x, y| 0.3 * x + 0.2 * y);
        let bank = Bank::parse(&bytes).unwrap();
        let n = {
            let (x, y, z) = (-0.3f32, -0.2f32, 1.0f32);
            let l = (x * x + y * y + z * z).sqrt();
            [x / l, y / l, z / l]
        };
        // A unit tangent.
        let e = {
            let (x, y, z) = (1.0f32, 0.0f32, 0.3f32);
            let l = (x * x + y * y + z * z).sqrt();
            [x / l, y / l, z / l]
        };
        let on = [0.021f32, 0.018, 0.3 * 0.021 + 0.2 * 0.018];
        let depth = 0.002f32;
        for (share, slides) in [(0.9f32, false), (1.5, true)] {
            let mut tr = ContactTracker::new();
            let above = add(on, scale(n, 0.001));
            let below = add(on, scale(n, -0.0001));
            let ContactState::Touching { anchor, .. } = tr.update(&bank, above, below) else {
                panic!("no contact");
            };
            let tip = add(
                add(anchor, scale(n, -depth)),
                scale(e, share * STICK_SLOPE * depth),
            );
            let ContactState::Touching {
                anchor: held,
                displacement,
                ..
            } = tr.update(&bank, below, tip)
            else {
                panic!("released at {tip:?}");
            };
            let normal = -dot(displacement, n);
            let tangential = sub(displacement, scale(n, -normal));
            let t = sqrt(dot(tangential, tangential));
            assert!((normal - depth).abs() < 1.0e-6, "{normal}");
            if slides {
                assert_ne!(held, anchor);
                assert!((t - STICK_SLOPE * depth).abs() < 1.0e-3 * t, "{t}");
            } else {
                assert_eq!(held, anchor);
                assert!((t - share * STICK_SLOPE * depth).abs() < 1.0e-3 * t, "{t}");
            }
        }
    }

    /// The first entering crossing over *every* triangle, by brute force: the reference the
    /// grid's certificates must reproduce.
    fn brute_force(bank: &Bank, p0: [f32; 3], p1: [f32; 3]) -> Option<Hit> {
        let (planes, triangles, positions) =
            (bank.triangle_planes(), bank.triangles(), bank.positions());
        let mut best: Option<Hit> = None;
        for ti in 0..triangles.len() as u16 {
            let keep = |t: f32| best.is_none_or(|b| t < b.t);
            if let Some(hit) = intersect(planes, triangles, positions, ti, p0, p1, keep) {
                best = Some(hit);
            }
        }
        best
    }

    /// Detection through the per-cell clearance and candidate lists finds exactly the
    /// brute-force first crossing, for cells far smaller than the triangles (where the old
    /// node-radius search could not guarantee completeness), equal to them and larger, on a
    /// curved surface, for short ticks near the surface and long strikes.
    #[test]
    fn detection_equals_brute_force_for_any_cell_size() {
        let mut rng = crate::fixtures::SplitMix64::new(0x2545_f491_4f6c_dd1d);
        let mut next = move || rng.unit();
        for cell in [0.0021, 0.004, 0.01, 0.031] {
            let bytes = patch_shaped(cell, |x, y| 0.2 * (x - 0.02) * (y - 0.015) + 3.0 * x * x);
            let bank = Bank::parse(&bytes).unwrap();
            let (mut hits, mut trials) = (0, 0);
            for _ in 0..3000 {
                let p0 = [
                    -0.005 + 0.05 * next(),
                    -0.005 + 0.05 * next(),
                    -0.004 + 0.012 * next(),
                ];
                // Mostly short moves (a tick at up to 1 m/s), some strikes of several cm.
                let len = if next() < 0.8 { 0.002 } else { 0.06 };
                let p1 = [0, 1, 2].map(|i| p0[i] + len * (2.0 * next() - 1.0));
                let (p0, p1) = (p0.map(|v| v as f32), p1.map(|v| v as f32));
                let want = brute_force(&bank, p0, p1);
                assert_eq!(detect(&bank, p0, p1), want, "cell {cell}: {p0:?} -> {p1:?}");
                trials += 1;
                hits += usize::from(want.is_some());
            }
            assert!(
                hits > trials / 50,
                "cell {cell}: only {hits} hits in {trials}"
            );
        }
    }

    #[test]
    fn grazing_motion_makes_no_contact() {
        let bytes = patch();
        let bank = Bank::parse(&bytes).unwrap();
        for z in [1.0e-6f32, 0.0] {
            let mut tr = ContactTracker::new();
            let tips: Vec<[f32; 3]> = (0..60)
                .map(|i| [-0.005 + 0.001 * i as f32, 0.013, z])
                .collect();
            let states = run(&bank, &mut tr, [-0.006, 0.013, z], &tips);
            assert!(states.iter().all(|s| *s == ContactState::Free), "z = {z}");
            // One long tick along the plane too.
            assert_eq!(
                tr.update(&bank, [-0.01, 0.02, z], [0.05, 0.021, z]),
                ContactState::Free
            );
        }
    }

    #[test]
    fn fast_strike_does_not_tunnel() {
        let bytes = patch();
        let bank = Bank::parse(&bytes).unwrap();
        // 5 cm in one tick, ending just below the surface, and straight through it.
        for (from, to) in [
            ([0.021f32, 0.018, 0.05], [0.019f32, 0.022, -0.001]),
            ([0.005, 0.035, 0.03], [0.035, 0.005, -0.03]),
            ([-0.02, 0.02, 0.045], [0.03, 0.02, -0.005]),
        ] {
            let mut tr = ContactTracker::new();
            let s = tr.update(&bank, from, to);
            let ContactState::Touching { anchor, .. } = s else {
                panic!("tunnelled from {from:?} to {to:?}");
            };
            assert_valid(&s, to);
            let t = from[2] / (from[2] - to[2]);
            for i in 0..2 {
                let want = from[i] + t * (to[i] - from[i]);
                assert!((anchor[i] - want).abs() < 1.0e-5, "{anchor:?}");
            }
            assert_eq!(anchor[2], 0.0);
        }
        // Fully outside the grid: no contact, no panic.
        let mut tr = ContactTracker::new();
        assert_eq!(
            tr.update(&bank, [1.0, 1.0, 1.0], [2.0, -3.0, 0.5]),
            ContactState::Free
        );
        assert_eq!(
            tr.update(&bank, [0.01, 0.01, 0.01], [f32::NAN, 0.0, 0.0]),
            ContactState::Free
        );
    }

    #[test]
    fn slide_across_many_triangles() {
        let bytes = patch();
        let bank = Bank::parse(&bytes).unwrap();
        let mut tr = ContactTracker::new();
        let depth = -0.002f32;
        let mut tips = std::vec![[0.004f32, 0.006, 0.001], [0.004, 0.006, depth]];
        for i in 1..=70 {
            let u = i as f32 / 70.0;
            tips.push([0.004 + 0.032 * u, 0.006 + 0.012 * u, depth]);
        }
        let states = run(&bank, &mut tr, [0.004, 0.006, 0.004], &tips);
        assert_eq!(states[0], ContactState::Free);
        let mut seen = Vec::new();
        for (s, tip) in states.iter().zip(&tips).skip(1) {
            let ContactState::Touching {
                triangle,
                anchor,
                displacement,
                ..
            } = *s
            else {
                panic!("contact lost at {tip:?}");
            };
            assert_eq!(anchor[2], 0.0);
            assert!((displacement[2] - depth).abs() < 1.0e-7);
            // Tangential displacement stays within the stick cone.
            let dt = (displacement[0].powi(2) + displacement[1].powi(2)).sqrt();
            assert!(dt <= STICK_SLOPE * -depth * 1.001, "{dt}");
            if seen.last() != Some(&triangle) {
                seen.push(triangle);
            }
        }
        assert!(seen.len() >= 6, "{seen:?}");
        // Lifting the tip releases the contact.
        assert_eq!(
            tr.update(&bank, [0.036, 0.018, depth], [0.036, 0.018, 0.0001]),
            ContactState::Free
        );
    }

    /// The rest-surface point under `p` (a point near the surface), by a walk from triangle
    /// `start` (nodes `start_nodes`) run to its end: [`SurfaceWalk`] with all its steps at once
    /// ([`MAX_SLIDE_STEPS`] and the closing closest point). `None` only for a bank whose indices
    /// do not hold.
    fn closest_surface_point(
        bank: &Bank,
        start: u32,
        start_nodes: [u16; 3],
        p: [f32; 3],
    ) -> Option<SurfacePoint> {
        let mut budget = MAX_SLIDE_STEPS + 1;
        match SurfaceWalk::new(start, start_nodes).advance(bank, p, &mut budget) {
            Walk::Landed(sp) => Some(sp),
            Walk::Walking | Walk::Lost => None,
        }
    }

    /// The tracking of a slide with its whole walk in one tick (no per-tick budget): the
    /// reference for [`track`]. Returns the next anchor and the walk's steps.
    fn whole_walk_track(bank: &Bank, active: SurfacePoint, tip: [f32; 3]) -> (SurfacePoint, u32) {
        let m = bank.triangle_planes()[active.triangle as usize].m;
        let (mm, d) = (dot(m, m), sub(tip, active.point));
        let dm = dot(d, m);
        assert!(dm <= 0.0, "released at {tip:?}");
        let dt = sub(d, scale(m, dm / mm));
        let t2 = dot(dt, dt);
        if !(t2 > STICK_SLOPE * STICK_SLOPE * (dm * dm / mm)) {
            return (active, 0);
        }
        let t = sqrt(t2);
        let allowed = STICK_SLOPE * (-dm / sqrt(mm));
        let target = add(active.point, scale(dt, 1.0 - allowed / t));
        let mut all = u32::MAX;
        let walk = SurfaceWalk::new(active.triangle, active.nodes).advance(bank, target, &mut all);
        let Walk::Landed(near) = walk else {
            panic!("no landing at {target:?}");
        };
        (near, u32::MAX - all)
    }

    /// The anchor of a touching state.
    fn anchor_of(s: &ContactState) -> SurfacePoint {
        let ContactState::Touching {
            triangle,
            nodes,
            bary,
            anchor,
            ..
        } = *s
        else {
            panic!("not touching: {s:?}");
        };
        SurfacePoint {
            triangle,
            nodes,
            bary,
            point: anchor,
        }
    }

    /// A slide whose anchor crosses at most one edge a tick (here 20 um a tick, 2 mm deep,
    /// across the patch's triangles) is tracked with [`SLIDE_STEPS_PER_TICK`] steps a tick
    /// exactly as with the whole walk in every tick: the same anchor, bit for bit, so the same
    /// displacement and force.
    #[test]
    fn a_slow_slide_is_tracked_as_by_the_whole_walk() {
        let bytes = patch();
        let bank = Bank::parse(&bytes).unwrap();
        let mut tr = ContactTracker::new();
        let depth = -0.002f32;
        let mut tips = std::vec![[0.004f32, 0.006, 0.001], [0.004, 0.006, depth]];
        for i in 1..=1600 {
            let u = i as f32 / 1600.0;
            tips.push([0.004 + 0.032 * u, 0.006 + 0.012 * u, depth]);
        }
        let states = run(&bank, &mut tr, [0.004, 0.006, 0.004], &tips);
        let mut reference = anchor_of(&states[1]);
        let (mut edges, mut most) = (0, 0);
        for (s, &tip) in states.iter().zip(&tips).skip(2) {
            let (next, steps) = whole_walk_track(&bank, reference, tip);
            edges += usize::from(next.triangle != reference.triangle);
            most = most.max(steps);
            reference = next;
            assert_eq!(anchor_of(s), reference, "at {tip:?}");
        }
        assert!(
            edges >= 6 && most == 2,
            "{edges} edges, {most} steps at most"
        );
    }

    /// A fast slide (0.45 mm a tick) whose anchor passes a vertex 20 um away: there the whole
    /// walk takes more than [`SLIDE_STEPS_PER_TICK`] steps in a tick. The budgeted walk goes
    /// on at the next tick; meanwhile the anchor is the target on the held triangle's plane,
    /// which on this flat patch is where the whole walk lands: every tick's anchor point (so
    /// displacement and force) is the whole walk's to f32 rounding, only the contact triangle
    /// lags for a tick or two.
    #[test]
    fn a_slide_past_a_vertex_keeps_the_whole_walks_anchor() {
        let bytes = patch();
        let bank = Bank::parse(&bytes).unwrap();
        let mut tr = ContactTracker::new();
        let depth = -0.002f32;
        // Along (1, -1) through (0.02, 0.02) shifted by 20 um: across the diagonal split.
        let at = |s: f32| [0.02 + s + 2.0e-5, 0.02 - s, depth];
        let mut tips = std::vec![[0.012f32, 0.028, 0.001], at(-0.008)];
        let step = 0.00045 / core::f32::consts::SQRT_2;
        for i in 1..=36 {
            tips.push(at(-0.008 + step * i as f32));
        }
        let states = run(&bank, &mut tr, [0.012, 0.028, 0.004], &tips);
        let mut reference = anchor_of(&states[1]);
        let (mut lagged, mut most) = (0, 0);
        for (s, &tip) in states.iter().zip(&tips).skip(2) {
            let (next, steps) = whole_walk_track(&bank, reference, tip);
            most = most.max(steps);
            reference = next;
            let got = anchor_of(s);
            for i in 0..3 {
                assert!(
                    (got.point[i] - next.point[i]).abs() < 1.0e-7,
                    "{got:?} vs {next:?}"
                );
            }
            lagged += usize::from(got.triangle != next.triangle);
            if got.triangle == next.triangle {
                reference = got;
            }
        }
        assert!(most > SLIDE_STEPS_PER_TICK, "{most}");
        assert!((1..=2).contains(&lagged), "{lagged}");
    }

    /// A walk advanced one step a call lands where the whole walk does, after as many calls
    /// as the whole walk takes steps; a walk stops at the overall cap either way.
    #[test]
    fn a_walk_resumed_step_by_step_lands_where_the_whole_walk_does() {
        let bytes = patch();
        let bank = Bank::parse(&bytes).unwrap();
        let nodes = bank.triangles()[0];
        for p in [
            [0.036f32, 0.018, 0.0],
            [0.031, 0.039, -0.001],
            [0.001, 0.002, 0.0],
        ] {
            let whole = closest_surface_point(&bank, 0, nodes, p).unwrap();
            let mut all = u32::MAX;
            let Walk::Landed(same) = SurfaceWalk::new(0, nodes).advance(&bank, p, &mut all) else {
                panic!("no landing at {p:?}");
            };
            assert_eq!(same, whole);
            let taken = u32::MAX - all;
            let mut walk = SurfaceWalk::new(0, nodes);
            let mut calls = 0;
            let landed = loop {
                calls += 1;
                let mut one = 1;
                match walk.advance(&bank, p, &mut one) {
                    Walk::Landed(sp) => break sp,
                    Walk::Walking => assert_eq!(one, 0),
                    Walk::Lost => panic!("lost at {p:?}"),
                }
            };
            assert_eq!(landed, whole, "{p:?}");
            assert_eq!(calls, taken, "{p:?}");
            assert!(taken <= MAX_SLIDE_STEPS + 1);
        }
        // Across the 5 x 5 patch from its first triangle: several steps.
        let mut all = u32::MAX;
        SurfaceWalk::new(0, nodes).advance(&bank, [0.036, 0.018, 0.0], &mut all);
        assert!(u32::MAX - all >= 4, "{}", u32::MAX - all);
    }

    #[test]
    fn no_contact_from_behind() {
        let bytes = patch();
        let bank = Bank::parse(&bytes).unwrap();
        let mut tr = ContactTracker::new();
        let tips = [
            [0.013f32, 0.017, 0.002],
            [0.013, 0.017, 0.004],
            [0.02, 0.02, -0.001],
        ];
        let states = run(&bank, &mut tr, [0.013, 0.017, -0.002], &tips);
        // Exiting from behind is ignored; coming back down from above is a contact.
        let t: Vec<bool> = states.iter().map(touching).collect();
        assert_eq!(t, [false, false, true]);
        // Moving around below the surface.
        let mut tr = ContactTracker::new();
        let tips = [[0.02f32, 0.02, -0.003], [0.03, 0.01, -0.001]];
        let states = run(&bank, &mut tr, [0.013, 0.017, -0.002], &tips);
        assert!(states.iter().all(|s| *s == ContactState::Free));
    }

    /// `normalise` gives, bit for bit, what its earlier form (residue put through an iterator
    /// sum over the other two coordinates) gave, on random inputs, ties and edge values.
    #[test]
    fn normalise_is_its_earlier_form() {
        fn earlier(k: [f32; 3]) -> Option<[f32; 3]> {
            let k = k.map(|v| v.clamp(0.0, 1.0));
            let s = k[0] + k[1] + k[2];
            if !(s > 0.0) || !s.is_finite() {
                return None;
            }
            let mut out = k.map(|v| v / s);
            let big = if out[0] >= out[1] && out[0] >= out[2] {
                0
            } else if out[1] >= out[2] {
                1
            } else {
                2
            };
            let rest: f32 = (0..3).filter(|&i| i != big).map(|i| out[i]).sum();
            out[big] = (1.0 - rest).clamp(0.0, 1.0);
            Some(out)
        }
        let mut rng = crate::fixtures::SplitMix64::new(0x9e37_79b9_7f4a_7c15);
        let mut next = move || rng.unit_f32() * 1.4 - 0.2;
        let mut cases = std::vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.5, 0.5, 0.0],
            [1.0 / 3.0; 3],
            [-1.0e-6, 0.5, 0.5],
            [f32::NAN, 0.2, 0.3],
            [f32::INFINITY, 0.0, 0.0],
            [-0.0, 0.0, 1.0],
        ];
        for _ in 0..20_000 {
            cases.push([next(), next(), next()]);
        }
        for k in cases {
            let (got, want) = (normalise(k), earlier(k));
            assert_eq!(
                got.map(|v| v.map(f32::to_bits)),
                want.map(|v| v.map(f32::to_bits))
            );
        }
    }

    #[test]
    fn closest_point_and_normalise() {
        let (a, b, c) = ([0.0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]);
        let (q, k, d2) = closest_on_triangle([2.0, -1.0, 0.5], a, b, c).unwrap();
        assert_eq!(q, b);
        assert_eq!(k, [0.0, 1.0, 0.0]);
        assert!((d2 - 2.25).abs() < 1.0e-6);
        let (q, _, _) = closest_on_triangle([0.2, 0.3, -1.0], a, b, c).unwrap();
        assert!((q[0] - 0.2).abs() < 1.0e-6 && (q[1] - 0.3).abs() < 1.0e-6);
        assert!(closest_on_triangle([0.0; 3], a, a, a).is_some());
        assert_eq!(normalise([f32::NAN, 0.0, 0.0]), None);
        assert_eq!(normalise([0.0, 0.0, 0.0]), None);
        let k = normalise([-1.0e-7, 0.5, 0.5]).unwrap();
        assert_eq!(k[0] + k[1] + k[2], 1.0);
    }
}
