//! The nodal model's contact patch (a bank without contact samples): the first contact tick's
//! solve on the contact triangle alone, the tip's weighted patch rebuilt over about a dozen
//! ticks in bounded stages while the held one renders ([`HapticLoop::tick`]'s module notes,
//! step 3), and the blend from the outgoing solve to the new one at a swap.

use bank_format::Bank;

use super::sampled::TriangleShares;
use super::{HapticLoop, PatchOrigin};
use crate::patch::PatchBuild;
use crate::solve::{SolveError, WeightedFill, WeightedSolve};
use crate::vec3::dist2;

/// A sliding contact keeps its patch (weights and factored solve) until the anchor has moved
/// this fraction of the tip radius from where the patch was built: the displacement still
/// follows the anchor every tick, and rebuilding the patch (quadrature points located on the
/// surface, a new factor) costs far more than a tick should.
pub const REPATCH_FRACTION: f32 = 0.1;

/// The factored contact solve of the anchor it was built at (reused while the contact presses
/// in place or slides less than [`REPATCH_FRACTION`] of the tip radius).
#[derive(Clone, Copy, Debug)]
pub(super) struct Held {
    pub(super) origin: PatchOrigin,
    pub(super) solve: WeightedSolve,
    /// The patch's [`crate::patch::Patch::dropped`].
    pub(super) dropped: f32,
}

/// Ticks over which the rendered force passes from the outgoing patch's solve to the new one's
/// after a swap (`Blend`): without it, each swap of a sliding contact is a step in the force
/// (both patches see the same displacement, but their compliances differ by the anchor's slide
/// since the last rebuild began). A patch that is ready waits for the blend before it is
/// swapped in, so a blend always starts from a single patch.
pub const BLEND_TICKS: u32 = 6;

/// The outgoing patch's solve after a swap, and the ticks its share has left: the tool force is
/// `f_new + s (f_old - f_new)` with `s = left / (BLEND_TICKS + 1)`, both at this tick's
/// displacement, spread over the new patch's nodes by their weights.
#[derive(Clone, Copy, Debug)]
pub(super) struct Blend {
    pub(super) solve: WeightedSolve,
    pub(super) left: u32,
}

/// Quadrature points of a patch being rebuilt that one tick locates on the surface
/// ([`PatchBuild::locate`]): the 12 take six ticks of a rebuild of about fourteen (start, six of
/// locating, the merge, the node choice, the fill, the factor), so no tick pays for a whole
/// patch. More ticks would make each cheaper but let the patch lag further behind a fast
/// slide (`tests/tests/loop_trajectories.rs`: at 58 mm/s each swap is a step in the force,
/// which the swap's blend smooths).
pub const POINTS_PER_TICK: usize = 2;

/// Surface-walk steps (one plane test and at most one edge crossing each,
/// [`crate::contact::SurfaceWalk`]) a rebuild takes per tick while locating its points: a
/// point's walk that needs more goes on the next tick. Points 3 mm apart on the shipped liver's
/// 7.7 mm triangles land in one or two steps; without the budget a tick's two points could
/// take up to [`crate::contact::MAX_SLIDE_STEPS`] steps each on a mesh of slivers.
pub const WALK_STEPS_PER_TICK: u32 = 4;

/// Candidate nodes a rebuild examines per tick while choosing the patch's nodes (each one a scan
/// of the loads and a coupling check against the nodes kept).
pub const CHOICES_PER_TICK: usize = 3;

/// Blocks of `B C_SS B^T` a rebuild adds per tick ([`WeightedFill::step`]): a full 8-node patch
/// (36 blocks) takes three ticks, and the factor one more.
pub const BLOCKS_PER_TICK: usize = 15;

/// A patch being rebuilt over several ticks, while the held one renders (`origin` is `None`
/// when no rebuild is in progress). Kept in place: the build is large, and moving it costs
/// more than a step of it.
#[derive(Clone, Debug)]
pub(super) struct Pending {
    pub(super) origin: Option<PatchOrigin>,
    pub(super) build: PatchBuild,
    pub(super) stage: Stage,
    /// Where the last rebuild that failed was started: the next starts only once the anchor
    /// has slid [`REPATCH_FRACTION`] of the tip radius from there (not every few ticks at the
    /// same spot). `None` when the last one succeeded, or the contact ended since.
    pub(super) failed_at: Option<[f32; 3]>,
}

/// How far a [`Pending`] rebuild has come: one step a tick, each bounded ([`PatchBuild`],
/// [`WeightedFill`]).
#[derive(Clone, Copy, Debug)]
pub(super) enum Stage {
    /// Quadrature points still to locate, [`POINTS_PER_TICK`] a tick.
    Locating,
    /// All located: next, merge the quadrature's loads with the nodal ones.
    Located,
    /// Choosing the nodes, [`CHOICES_PER_TICK`] candidates a tick.
    Choosing,
    /// Assembling `B C_SS B^T` (about [`BLOCKS_PER_TICK`] blocks a tick); the chosen patch's
    /// dropped share.
    Filling(WeightedFill, f32),
    /// Assembled: next, the factor.
    Filled(WeightedFill, f32),
    /// Factored, waiting for the last swap's `Blend` to end.
    Ready(WeightedSolve, f32),
}

/// The first tick's solve on the contact triangle alone: its vertices with a positive
/// barycentric coordinate, weighted by it (normalised). The same weights as the patch rule at
/// radius 0 ([`PatchBuild`]: one load per vertex, no quadrature) without building a patch;
/// `None` when the bank does not couple two of the vertices or the solve fails, for the
/// caller to take the patch rule's path (which drops an uncoupled vertex).
pub(super) fn triangle_solve(
    bank: &Bank,
    nodes: [u16; 3],
    bary: [f32; 3],
) -> Option<WeightedSolve> {
    let shares = TriangleShares::of(nodes, bary)?;
    let (n, w) = shares.split();
    WeightedSolve::new(bank, n, w).ok()
}

impl HapticLoop<'_> {
    /// One step of keeping the patch under the tip: start a rebuild when the held patch is the
    /// first tick's (radius 0) or its anchor has slid [`REPATCH_FRACTION`] of the tip radius,
    /// else advance the rebuild in progress by one bounded step (`Stage`), swapping it in
    /// when it is ready and no `Blend` is running. The solve to render with this tick is
    /// then `self.held`'s (`held` is where it was built).
    ///
    /// A rebuild step that fails (a patch whose `B C_SS B^T` does not factor, a coupling
    /// missing) drops that rebuild: the held patch, which solved, keeps rendering, the failure
    /// is counted (`Counters::rebuilds_failed`) and the next rebuild waits for the anchor to
    /// slide on from where this one started. It is not a fault: the force rendered is the held
    /// patch's, as it is for the ticks of any rebuild. (Returning the error, as before, left
    /// the rebuild pending: every later contact tick retried the failing step and latched
    /// `SolveFailed`, again right after each re-arm.)
    pub(super) fn maintain_patch(&mut self, held: PatchOrigin, origin: PatchOrigin, repatch: f32) {
        let p = &mut self.pending;
        let Some(building) = p.origin else {
            let h = held;
            let slid = |from: [f32; 3]| {
                from != origin.anchor && dist2(from, origin.anchor) >= repatch * repatch
            };
            let stale =
                (h.radius_m != origin.radius_m || slid(h.anchor)) && p.failed_at.is_none_or(slid);
            if stale {
                let o = origin;
                p.build
                    .start(self.bank, o.triangle, o.nodes, o.bary, o.anchor, o.radius_m);
                p.origin = Some(origin);
                p.stage = Stage::Locating;
            }
            return;
        };
        if self.advance_rebuild(building).is_err() {
            self.pending.failed_at = Some(building.anchor);
            self.pending.origin = None;
            self.counters.rebuilds_failed = self.counters.rebuilds_failed.wrapping_add(1);
        }
    }

    /// One bounded step of the rebuild started at `building` ([`Self::maintain_patch`]).
    fn advance_rebuild(&mut self, building: PatchOrigin) -> Result<(), SolveError> {
        let p = &mut self.pending;
        match p.stage {
            Stage::Locating => {
                if p.build
                    .locate(self.bank, POINTS_PER_TICK, WALK_STEPS_PER_TICK)
                {
                    p.stage = Stage::Located;
                }
            }
            Stage::Located => {
                p.build.merge();
                p.stage = Stage::Choosing;
            }
            Stage::Choosing => {
                if let Some(patch) = p.build.choose_step(self.bank, CHOICES_PER_TICK) {
                    let fill = WeightedFill::new(patch.nodes(), patch.weights())?;
                    p.stage = Stage::Filling(fill, patch.dropped);
                }
            }
            Stage::Filling(ref mut fill, dropped) => {
                if fill.step(self.bank, BLOCKS_PER_TICK)? {
                    p.stage = Stage::Filled(*fill, dropped);
                }
            }
            Stage::Filled(fill, dropped) => {
                p.stage = Stage::Ready(fill.factor()?, dropped);
            }
            // Swapped in once the last swap's blend is over.
            Stage::Ready(..) if self.blend.is_some() => {}
            Stage::Ready(solve, dropped) => {
                p.origin = None;
                p.failed_at = None;
                self.blend = self.holding.then_some(Blend {
                    solve: self.held.solve,
                    left: BLEND_TICKS,
                });
                self.held = Held {
                    origin: building,
                    solve,
                    dropped,
                };
                self.holding = true;
            }
        }
        Ok(())
    }
}

#[cfg(test)]
#[allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing,
    clippy::needless_range_loop
)]
mod tests {
    extern crate std;
    use bank_format::{AlignedBytes, DeviceCalibration, MAX_CONTACTS, Mode};
    use std::vec::Vec;

    use super::super::rig::{Rig, input, norm, parse};
    use super::*;
    use crate::contact::ContactState;
    use crate::fixtures::{flat_patch, patch_device};
    use crate::safety::State;

    #[test]
    fn the_first_ticks_triangle_solve_is_the_patch_rules_at_radius_zero() {
        let bytes = flat_patch();
        let bank = parse(&bytes);
        let mut build = PatchBuild::new();
        let d = [1.0e-4, -2.0e-4, -5.0e-4];
        for (ti, &tri) in bank.triangles().iter().enumerate().take(8) {
            for bary in [[0.2, 0.3, 0.5], [0.0, 0.25, 0.75], [1.0, 0.0, 0.0]] {
                let direct = triangle_solve(&bank, tri, bary).unwrap().forces(d).unwrap();
                build.start(&bank, ti as u32, tri, bary, [0.0; 3], 0.0);
                let patch = build.finish(&bank);
                let rule = WeightedSolve::new(&bank, patch.nodes(), patch.weights())
                    .unwrap()
                    .forces(d)
                    .unwrap();
                let (f, g) = (direct.tool_force_n, rule.tool_force_n);
                let err = norm([f[0] - g[0], f[1] - g[1], f[2] - g[2]]);
                assert!(err <= 1e-5 * norm(g), "{ti} {bary:?}: {f:?} vs {g:?}");
                // The same nodes carry the load (the order may differ).
                let mut a: Vec<u16> = direct.nodes().to_vec();
                let mut b: Vec<u16> = rule.nodes().to_vec();
                a.sort_unstable();
                b.sort_unstable();
                assert_eq!(a, b);
            }
        }
    }

    /// A 3 mm tip on a 1 mm grid loads about 28 nodes, more than the 8 the solve carries: the
    /// patch keeps the heaviest 8, renormalised, and the loss is not silent: every such tick
    /// reports its dropped share, telemetry carries it and counts the ticks, and the rendered
    /// force is that of the kept patch (node forces `w_k f_tool` summing to the tool force).
    #[test]
    fn a_patch_over_the_node_cap_reports_the_dropped_load() {
        let bytes = crate::fixtures::grid_patch_with(
            9,
            0.001,
            0.02,
            DeviceCalibration {
                fulcrum_m: [0.004, 0.004, 0.1],
                ..patch_device()
            },
        );
        let bank = parse(&bytes);
        assert!(bank.device().tip_radius_m >= 0.003);
        let mut lp = Rig::new(&bank).homed().in_mode(Mode::LinearLaw).armed();
        lp.ramped(lp.counts(0.099));
        let (mut capped, mut touching, mut first) = (0, 0, 0);
        for t in 0..=80 {
            let out = lp.at(0.099 + 0.03e-3 * t as f32);
            assert_eq!(out.state, State::Armed, "{out:?}");
            let tel = lp.telemetry();
            assert_eq!(tel.dropped_load, out.dropped_load);
            assert_eq!(tel.tool_force_n, out.tool_force_n);
            if !matches!(out.contact, ContactState::Touching { .. }) {
                assert_eq!(out.dropped_load, 0.0);
                continue;
            }
            touching += 1;
            let radius = out.patch.map_or(0.0, |p| p.radius_m);
            if radius == 0.0 {
                // The first ticks of a contact, until the tip's patch is built: none (the
                // detecting tick), then the contact triangle alone, nothing dropped.
                assert_eq!(out.dropped_load, 0.0, "{out:?}");
                first += 1;
                continue;
            }
            assert_eq!(out.contact_nodes, MAX_CONTACTS);
            assert!(out.dropped_load > 0.2 && out.dropped_load < 1.0, "{out:?}");
            capped += 1;
            // Linear law: the node forces on the tissue sum to minus the tool force.
            for i in 0..3 {
                let sum: f32 = lp.contacts().iter().map(|c| c.force_n[i]).sum();
                assert!(
                    (sum + out.tool_force_n[i]).abs() <= 1e-5 * norm(out.tool_force_n),
                    "{out:?}"
                );
            }
            assert_eq!(lp.counters().capped_ticks, capped);
        }
        assert!(
            touching > 30 && first < 20 && capped == touching - first,
            "{touching} {capped} {first}"
        );
        assert_eq!(lp.telemetry().counters.capped_ticks, capped);
    }

    /// A background rebuild that fails does not fault: a 1 mm grid whose every coupling
    /// pulls the other way along z (`C_kl,zz = -0.3 C_kk,zz`: each pair's 6 x 6 compliance
    /// is SPD, and so is a contact triangle's `B C_SS B^T`, but not that of the tip's 8-node
    /// patch, whose nodes share the load about equally), so every rebuild fails at its factor.
    /// The contact triangle's solve of the first contact tick keeps rendering, armed, through
    /// the whole press and slide; each failed rebuild is counted in telemetry, and retried
    /// only once the anchor has slid on. (Before, the failing step stayed pending and latched
    /// `SolveFailed`, again right after each re-arm.)
    #[test]
    fn a_failed_patch_rebuild_keeps_the_held_patch() {
        let xs: Vec<f64> = (0..9).map(|i| 0.001 * i as f64).collect();
        let mut b = crate::fixtures::grid_builder(
            &xs,
            &xs,
            0.02,
            DeviceCalibration {
                fulcrum_m: [0.004, 0.0043, 0.1],
                ..patch_device()
            },
        );
        let c = 1.0e-3;
        let diag = |v: f64| -> [[f64; 3]; 3] {
            core::array::from_fn(|i| core::array::from_fn(|j| if i == j { v } else { 0.0 }))
        };
        b.c_kk = std::vec![diag(c); b.positions_m.len()];
        for (_, _, block) in &mut b.couplings {
            *block = [[0.0; 3]; 3];
            block[2][2] = -0.3 * c;
        }
        let bytes = AlignedBytes::new(&b.build().unwrap());
        let bank = parse(&bytes);
        assert!(bank.samples().is_none() && bank.device().tip_radius_m >= 0.003);
        let mut lp = Rig::new(&bank).homed().armed();
        let (mut touching, mut failed) = (0, 0);
        for t in 0..=600 {
            let mut counts = lp.counts(0.099 + 0.02e-3 * t.min(150) as f32);
            // Then slide sideways, 1.5 um a tick.
            counts[0] += (t.max(300) - 300) / 4;
            let out = lp.tick(input(counts));
            assert_eq!(out.state, State::Armed, "tick {t}: {out:?}");
            assert!(out.solve_error.is_none(), "tick {t}: {out:?}");
            if out.contact_nodes > 0 {
                touching += 1;
                // The contact triangle's solve, never a patch.
                assert_eq!(out.patch.map(|p| p.radius_m), Some(0.0), "{out:?}");
                assert!(out.tool_force_n[2] > 0.0, "{out:?}");
            }
            let now = lp.counters().rebuilds_failed;
            assert!(now <= failed + 1);
            failed = now;
        }
        assert!(touching > 400, "{touching}");
        // One at the press, a few more as the slide moves the anchor on: not one every few
        // ticks.
        assert!((2..40).contains(&failed), "{failed}");
        assert_eq!(lp.telemetry().counters.rebuilds_failed, failed);
    }
}
