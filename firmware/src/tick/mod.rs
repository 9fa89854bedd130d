//! One tick of the 1 kHz haptic loop ([`HapticLoop::tick`]), assembled from the crate's
//! pieces. Portable: no hardware, no heap, no panics, f32.
//!
//! Per tick, in this order:
//!
//! 1. encoder counts (minus the offset set by [`HapticLoop::zero_encoders`]) -> joints
//!    ([`Device::joints`]) -> tip and Jacobian ([`Device::tip_and_jacobian`]);
//! 2. contact update on the segment `[previous tip, tip]` ([`ContactTracker::update`]; the
//!    first tick, and the first after zeroing the encoders, use a zero-length segment, so a
//!    pose jump is never swept for contacts); an encoder jump (the supervisor's check, asked
//!    here first) drops the contact and sweeps nothing, and a path longer than the overspeed
//!    threshold allows is swept over its last part only ([`crate::contact::path_tail`]), so
//!    no bank and no motion makes the detection cost more than
//!    [`crate::contact::MAX_DETECT_PIECES`] pieces;
//! 3. when touching, on a bank with contact samples (bank format 6, `SPEC.md` "contact
//!    samples", the shipped scene's): the tool's patch compliance `W` at the anchor,
//!    interpolated from the samples ([`bank_format::Samples::interpolate`]) and factored every
//!    tick, the tool force `W^-1 d` (the paper's eq. 8 for one rigid tool) spread over the
//!    contact triangle's vertices by their barycentric weights for telemetry; no patch, no
//!    rebuild, no blend (`W` is continuous as the anchor slides). On a bank without samples
//!    (the nodal model):
//!    the weighted patch under the tool tip ([`tool_patch`](crate::patch::tool_patch), radius from the
//!    bank's device calibration; the contact triangle's barycentric coordinates when the radius
//!    is zero or smaller than the triangles) and the **energy-minimal** solve on it
//!    ([`WeightedSolve`]): `f_tool = (B C_SS B^T)^-1 d` with `B = [w_1 I, ..., w_n I]`,
//!    `d = tip - anchor`, `f_k = w_k f_tool`. It is chosen over the paper's alpha form because
//!    it is the better-conditioned one: it factors the 3 x 3 matrix `B C_SS B^T` (a weighted
//!    average of the patch's blocks, about as well conditioned as one `C_kk`) and never needs
//!    `C_SS^-1`, so close or nearly dependent contact nodes do not hurt it. The patch and the
//!    factor depend only on the anchor, so they are kept while the contact presses in place
//!    (one 3 x 3 solve a tick) and rebuilt when it has slid [`REPATCH_FRACTION`] of the tip
//!    radius; the first tick of a contact, which also ran the detection, solves on the contact
//!    triangle alone (the displacement, hence the force, is still tiny then). A rebuild is
//!    spread over about twelve ticks, one bounded step each (`Stage`: start,
//!    [`POINTS_PER_TICK`] quadrature points a tick, the merge, [`CHOICES_PER_TICK`] candidate
//!    nodes a tick, [`BLOCKS_PER_TICK`] blocks of `B C_SS B^T` a tick and the factor), while
//!    the held patch keeps rendering, so no tick pays for a whole patch; the patch in use lags
//!    the anchor by [`REPATCH_FRACTION`] of the tip radius plus the rebuild's ticks of sliding.
//!    At a swap the force passes from the outgoing solve's to the new one's over
//!    [`BLEND_TICKS`] (`Blend`), so a sliding contact's force has no step at swaps. The node
//!    forces `f_S` (on the tissue, linear model) are what telemetry reports, so the host's
//!    `u = C f_S` displays the surface under the tip;
//! 4. the tissue law Q on the tool force ([`apply_tissue_law`], bank's law), except in
//!    [`Mode::LinearLaw`]; the force on the tool is the *opposite* of the force on the tissue
//!    (sign convention of [`crate::device`]); on a bank with the optional viscoelastic
//!    relaxation (format 7, `SPEC.md` "viscoelastic relaxation") the force on the tissue is
//!    then Fung's QLV response to it ([`Qlv`]: `g_inf Q_e + sum_k h_k`, the `h_k` updated
//!    every tick, touching or not, in `Render`; the elastic force unchanged in the other
//!    modes, whose ticks feed the relaxation a zero force); without the section this step is
//!    skipped and the force is the elastic one, bit for bit; the force is capped by
//!    [`Device::limit_force`];
//! 5. `tau = J^T F + tau_g(q)`, requested currents ([`Device::requested_currents`]); `tau_g`
//!    is the feed-forward for the instrument's own weight from the bank's optional gravity
//!    section ([`gravity_efforts`]; zero without it), added in every mode but
//!    `ConstantCurrent`, with or without contact, so the supervisor clamps and faults on the
//!    sum as on any request; for [`RAMP_IN_TICKS`] after each arm, `F` and `tau_g` are scaled
//!    by a ramp from 0 to 1 (the telemetry's tool force is the ramped one);
//! 6. [`Supervisor::tick`]: the hardware interlocks (e-stop, amplifier faults), NaN, encoder
//!    jumps, overspeed (the tip's and the joints' change since the previous tick against the
//!    bank's thresholds), joint and current limits, link silence, overruns and a failed solve
//!    end at zero current with the fault latched; otherwise the clamped currents are applied
//!    (only when armed).
//!
//! A solve or law error (not positive definite, ill-conditioned, missing coupling, non-finite)
//! is reported as [`FaultReason::SolveFailed`](bank_format::FaultReason::SolveFailed): the force
//! and currents of that tick are zero and the supervisor latches the fault.
//!
//! Modes ([`HapticLoop::set_mode`]): `Render` (the above), `LinearLaw` (Q bypassed),
//! `Transparent` (tracking and telemetry, zero force) and `ConstantCurrent` (the given currents,
//! under the supervisor, which faults `BadCommand` on one that is not finite or over its limit
//! rather than clamping it). The mode is set only while not armed ([`HapticLoop::set_mode`]).

//! The parts, in the tick's order: this file (`tick/mod.rs`) holds the loop, its inputs and
//! outputs and the per-tick sequence (kinematics, detection, the patch phase's dispatch, the
//! solve and law phases, the supervisor); `tick/sampled.rs` the sampled render of a bank with
//! contact samples (`W` at the anchor); `tick/nodal.rs` the nodal model's patch (the first
//! tick's contact triangle, the rebuild in bounded stages, the blend at a swap);
//! `tick/gravity.rs` the feed-forward `tau_g(q)`; `tick/phases.rs` the phase marks
//! ([`PhaseMarks`]) the SIL image times the tick with.

mod gravity;
mod nodal;
mod phases;
mod sampled;

#[cfg(test)]
mod rig;
#[cfg(test)]
mod tests;

pub use gravity::gravity_efforts;
pub use nodal::{
    BLEND_TICKS, BLOCKS_PER_TICK, CHOICES_PER_TICK, POINTS_PER_TICK, REPATCH_FRACTION,
    WALK_STEPS_PER_TICK,
};
pub use phases::PhaseMarks;

use bank_format::{Bank, Contact, Counters, MAX_CONTACTS, Mode, Telemetry, heapless};

use crate::contact::{ContactState, ContactTracker, max_path_m, path_tail};
use crate::device::{Device, transpose_mul};
use crate::hal::{CycleCounter, Interlocks};
use crate::patch::PatchBuild;
use crate::relax::Qlv;
use crate::safety::{ArmRefused, Fault, SafetyConfig, State, Supervisor, TickInput};
use crate::solve::{SolveError, WeightedSolve, apply_tissue_law};
use nodal::{Blend, Held, Pending, Stage, triangle_solve};
use phases::NoCounter;
use sampled::sampled_compliance;

/// The contact set and its forces, as sent in telemetry.
pub type Contacts = heapless::Vec<Contact, MAX_CONTACTS>;

/// What the hardware (or the plant simulator) gives one tick.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LoopInput {
    /// Raw encoder counts (pitch, yaw, insertion).
    pub encoder_counts: [i32; 3],
    /// Whether the previous tick overran its period.
    pub overrun: bool,
    /// How long the host link has been silent, in ticks (the application's measure: since the
    /// last byte, or since the last valid frame less a grace for a garbled link).
    pub link_silence_ticks: u32,
    /// The hardware interlock inputs (e-stop, amplifier fault outputs) read this tick.
    pub interlocks: Interlocks,
}

/// The result of one tick.
#[derive(Clone, Debug, PartialEq)]
pub struct LoopOutput {
    /// Tick number (1 for the first tick; wraps).
    pub tick: u32,
    /// Motor currents to write, A: zero unless armed and no fault.
    pub currents_a: [f32; 3],
    /// Which motors were clamped to their limit.
    pub clamped: [bool; 3],
    /// Safety state after this tick.
    pub state: State,
    /// Tool tip, m (bank frame).
    pub tip_m: [f32; 3],
    /// The contact tracker's state this tick.
    pub contact: ContactState,
    /// How many contact nodes carry a force ([`HapticLoop::contacts`]); 0 when free or when
    /// the solve failed.
    pub contact_nodes: usize,
    /// The force rendered on the tool (what the user feels when armed), N: opposite to the
    /// force on the tissue, after the law Q and [`Device::limit_force`]. The motors produce it
    /// only when `state` is `Armed`; zero after a solve error.
    pub tool_force_n: [f32; 3],
    /// The latched fault, if in `Fault`.
    pub fault: Option<Fault>,
    /// A fault raised by this tick (send `DeviceToHost::Fault` once).
    pub new_fault: Option<Fault>,
    /// The solve or law error of this tick, if any (it raised `SolveFailed`).
    pub solve_error: Option<SolveError>,
    /// Where the contact patch in use was built, when touching.
    pub patch: Option<PatchOrigin>,
    /// Share of the patch's load on nodes it could not keep ([`crate::patch::Patch::dropped`]:
    /// more than the solve carries, or not coupled in the bank), 0 when nothing was dropped or
    /// when free. The kept weights are renormalised, so `contacts` and `tool_force_n` are
    /// those of the narrower patch; telemetry reports the share and counts such ticks
    /// (`Counters::capped_ticks`).
    pub dropped_load: f32,
}

/// What the last tick produced, kept for [`HapticLoop::telemetry`].
#[derive(Clone, Debug)]
struct Last {
    tip_m: [f32; 3],
    contacts: Contacts,
    contact_point: Option<bank_format::ContactPoint>,
    currents_a: [f32; 3],
    tool_force_n: [f32; 3],
    dropped_load: f32,
}

/// The portable haptic loop over one validated bank.
#[derive(Clone, Debug)]
pub struct HapticLoop<'b> {
    bank: &'b Bank<'b>,
    device: Device,
    supervisor: Supervisor,
    tracker: ContactTracker,
    mode: Mode,
    encoder_offset: [i32; 3],
    last_raw_counts: Option<[i32; 3]>,
    prev_tip: Option<[f32; 3]>,
    tick: u32,
    counters: Counters,
    last: Last,
    /// The solve the contact renders with, while `holding`. Kept between contacts as storage
    /// that a sampled bank's next contact refactors in place: writing a new `Held`, some 140
    /// bytes, cost the first contact tick about 120 instructions.
    held: Held,
    holding: bool,
    blend: Option<Blend>,
    /// The contact was detected at an earlier tick (its force starts the tick after).
    detected: bool,
    pending: Pending,
    /// The encoders were referenced ([`HapticLoop::zero_encoders`]) since this loop started.
    referenced: bool,
    /// Armed ticks since the last arm, up to [`RAMP_IN_TICKS`] (the ramp-in is over then).
    ramp_ticks: u32,
    /// The longest path a tick sweeps for contacts ([`crate::contact::max_path_m`]).
    max_path_m: f32,
    /// The tissue's viscoelastic memory, on a bank with a relaxation section.
    qlv: Option<Qlv>,
}

/// Ticks over which the loop's output (the rendered force and the gravity feed-forward) rises
/// linearly from zero after each `Arm`, a fault's `ClearFault` + `Arm` included: 300 ms at
/// 1 kHz. An arm with the tip inside the tissue (pressed while disarmed, or held there through
/// a fault) would otherwise apply the whole penetration force, up to `max_force_n`, plus the
/// instrument's weight compensation in one step under the user's hand. Ramping rather than
/// refusing to arm in contact: refusing would leave the gravity step, and a device that may
/// only be armed away from the organ cannot recover from a fault while the instrument is in
/// it. A firmware constant, not a scene field: a field would need a bank format change for a
/// value no scene has needed to differ; a few hundred ms is short against a hand's reaction
/// and long against the loop's stiffness. A host's `ConstantCurrent` is not ramped: those are
/// currents it measures with, commanded and checked as sent.
pub const RAMP_IN_TICKS: u32 = 300;

/// [`FaultReason::BadCommand`](bank_format::FaultReason::BadCommand)'s detail for a `SetMode`
/// refused while armed (0..2 name the motor of a bad `ConstantCurrent`).
pub const BAD_COMMAND_SET_MODE_ARMED: u32 = 3;

/// Where the current contact patch was built ([`crate::patch::tool_patch`]'s arguments): the
/// contact triangle and the rest-surface point, which lags the anchor by less than
/// [`REPATCH_FRACTION`] of the tip radius while the contact slides.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PatchOrigin {
    /// Index into `bank.triangles()`.
    pub triangle: u32,
    /// The triangle's nodes.
    pub nodes: [u16; 3],
    /// Barycentric coordinates of `anchor` in the triangle.
    pub bary: [f32; 3],
    /// The point, m.
    pub anchor: [f32; 3],
    /// The tip radius the patch was built for, m: the bank's, or 0 on the first tick of a
    /// contact (the contact triangle alone; see [`HapticLoop::tick`]).
    pub radius_m: f32,
}

impl<'b> HapticLoop<'b> {
    /// A disarmed loop with the bank's device calibration and the default safety thresholds
    /// ([`SafetyConfig::new`]).
    pub fn new(bank: &'b Bank<'b>) -> HapticLoop<'b> {
        HapticLoop::with_config(bank, SafetyConfig::new(bank.device()))
    }

    /// A disarmed loop with explicit safety thresholds.
    pub fn with_config(bank: &'b Bank<'b>, config: SafetyConfig) -> HapticLoop<'b> {
        let max_path_m = max_path_m(bank, config.max_tip_speed_m_s, config.tick_s);
        HapticLoop {
            bank,
            device: Device::new(bank.device()),
            supervisor: Supervisor::new(config),
            tracker: ContactTracker::new(),
            mode: Mode::Render,
            encoder_offset: [0; 3],
            last_raw_counts: None,
            prev_tip: None,
            tick: 0,
            counters: Counters::default(),
            last: Last {
                tip_m: [0.0; 3],
                contacts: Contacts::new(),
                contact_point: None,
                currents_a: [0.0; 3],
                tool_force_n: [0.0; 3],
                dropped_load: 0.0,
            },
            held: Held {
                origin: PatchOrigin {
                    triangle: 0,
                    nodes: [0; 3],
                    bary: [0.0; 3],
                    anchor: [0.0; 3],
                    radius_m: 0.0,
                },
                solve: WeightedSolve::UNIT,
                dropped: 0.0,
            },
            holding: false,
            blend: None,
            detected: false,
            pending: Pending {
                origin: None,
                build: PatchBuild::new(),
                stage: Stage::Locating,
                failed_at: None,
            },
            referenced: false,
            ramp_ticks: RAMP_IN_TICKS,
            max_path_m,
            qlv: bank.relaxation().map(|r| Qlv::new(r, config.tick_s)),
        }
    }

    /// The bank.
    pub fn bank(&self) -> &'b Bank<'b> {
        self.bank
    }

    /// The gimbal model.
    pub fn device(&self) -> &Device {
        &self.device
    }

    /// The safety supervisor.
    pub fn supervisor(&self) -> &Supervisor {
        &self.supervisor
    }

    /// The safety state.
    pub fn state(&self) -> State {
        self.supervisor.state()
    }

    /// The rendering mode.
    pub fn mode(&self) -> Mode {
        self.mode
    }

    /// Ticks run so far (wraps).
    pub fn tick_count(&self) -> u32 {
        self.tick
    }

    /// The counters sent in telemetry.
    pub fn counters(&self) -> Counters {
        self.counters
    }

    /// The counters, for the application to update `max_tick_cycles` (the loop itself counts
    /// `overruns`; the link's counters are the link's own, [`crate::link::RxCounts`]).
    pub fn counters_mut(&mut self) -> &mut Counters {
        &mut self.counters
    }

    /// Arm (host command): only from `Disarmed`, with no interlock active at the last tick and
    /// with the encoders referenced since the loop started ([`HapticLoop::zero_encoders`];
    /// refused otherwise with [`FaultReason::NotReferenced`](bank_format::FaultReason)
    /// latched); the bank was validated when parsed. The loop's output then ramps in over
    /// [`RAMP_IN_TICKS`].
    pub fn arm(&mut self) -> Result<(), ArmRefused> {
        self.supervisor.arm(true, self.referenced)?;
        self.ramp_ticks = 0;
        Ok(())
    }

    /// Whether the encoders are referenced: a [`HapticLoop::zero_encoders`] since the loop
    /// started (the chip's last reset), and no encoder jump since.
    pub fn referenced(&self) -> bool {
        self.referenced
    }

    /// Disarm (host command): `Armed` -> `Disarmed`; returns whether the state changed.
    pub fn disarm(&mut self) -> bool {
        self.supervisor.disarm()
    }

    /// Clear a latched fault (host command): `Fault` -> `Disarmed`; returns whether there was
    /// one.
    pub fn clear_fault(&mut self) -> bool {
        self.supervisor.clear_fault()
    }

    /// Latch a fault found outside the tick's inputs (e.g. the reset cause at boot); returns
    /// whether it was latched (an earlier fault is kept).
    pub fn raise(&mut self, reason: bank_format::FaultReason, detail: u32) -> bool {
        self.supervisor.raise(reason, detail)
    }

    /// Select the rendering mode (host command), effective from the next tick. Refused while
    /// armed: the mode is kept and a [`FaultReason::BadCommand`](bank_format::FaultReason)
    /// fault (detail [`BAD_COMMAND_SET_MODE_ARMED`]) is latched and returned, for the caller to
    /// report (the ticks do not report it again). A mode change under the user's hand would
    /// bypass what the supervisor let through so far.
    pub fn set_mode(&mut self, mode: Mode) -> Result<(), Fault> {
        if self.supervisor.state() == State::Armed {
            let fault = Fault {
                reason: bank_format::FaultReason::BadCommand,
                detail: BAD_COMMAND_SET_MODE_ARMED,
            };
            self.supervisor.raise(fault.reason, fault.detail);
            return Err(fault);
        }
        self.mode = mode;
        Ok(())
    }

    /// Declare the current pose (the last tick's raw counts; encoder zero before the first
    /// tick) the calibration's home pose (host command, with the instrument in its home
    /// fixture): the explicit homing that references the encoders, which arming requires. The
    /// encoder counters restart from wherever the mechanism stands at every reset (power,
    /// brown-out, reset pin, watchdog), so nothing else can tell the pose. Refused (returns
    /// `false`) while armed, since the tip would jump under the user's hand. Rebases the
    /// supervisor's jump and overspeed checks and drops any contact; the next tick does not
    /// sweep the jump for contacts.
    pub fn zero_encoders(&mut self) -> bool {
        if self.supervisor.state() == State::Armed {
            return false;
        }
        if let Some(raw) = self.last_raw_counts {
            self.encoder_offset = raw;
        }
        self.supervisor.rebase_encoders();
        self.tracker.reset();
        self.prev_tip = None;
        self.referenced = true;
        true
    }

    /// One tick (see the module notes). Never panics.
    pub fn tick(&mut self, input: LoopInput) -> LoopOutput {
        self.tick_marked(input, &NoCounter).0
    }

    /// [`HapticLoop::tick`], reading `clock` at the ends of its first five phases
    /// ([`PhaseMarks`]: kinematics, detection, patch, solve, law; the supervisor's phase ends
    /// where the caller stops timing). Five counter reads a tick, nothing else changes.
    pub fn tick_marked<C: CycleCounter>(
        &mut self,
        input: LoopInput,
        clock: &C,
    ) -> (LoopOutput, PhaseMarks) {
        self.tick = self.tick.wrapping_add(1);
        if input.overrun {
            self.counters.overruns = self.counters.overruns.wrapping_add(1);
        }
        self.last_raw_counts = Some(input.encoder_counts);
        let counts = sub_wrapping(input.encoder_counts, self.encoder_offset);
        let q = self.device.joints(counts);
        let (tip, jac) = self.device.tip_and_jacobian(&q);
        let kinematics = clock.cycles();
        // An encoder jump (a glitch; the supervisor faults on it below) is never swept for
        // contacts, and a path is swept over at most its last `max_path_m`, before any
        // geometry: the bank cannot make a tick's detection longer than that. Counts that
        // jumped cannot tell the pose any more: the reference is dropped whatever the
        // supervisor reports this tick (an interlock or a fault latched earlier hides the
        // jump's own `EncoderJump`), so no `ClearFault` + `Arm` renders from a misplaced pose.
        let contact = if self.supervisor.encoder_jump(&counts).is_some() {
            self.referenced = false;
            self.tracker.reset();
            ContactState::Free
        } else {
            // A held contact tracks the tip alone: only detection reads the path.
            let prev = match self.prev_tip {
                Some(p) if !self.tracker.touching() => path_tail(p, tip, self.max_path_m),
                _ => tip,
            };
            self.tracker.update(self.bank, prev, tip)
        };
        self.prev_tip = Some(tip);
        let detection = clock.cycles();

        let touching = self.contact_solve(&contact);
        let patch = clock.cycles();
        // The solve to render is the held one (`contact_solve` has just kept or replaced it).
        // The node forces go straight into `last.contacts` (telemetry's): no copy of the set.
        self.last.contacts.clear();
        let linear = touching.and_then(|d| match (d, self.holding.then_some(&self.held)) {
            (Some(d), Some(held)) => {
                let tool = tool_force(&held.solve, self.blend.as_ref(), d)?;
                Ok(Some((
                    node_forces(&held.solve, tool, &mut self.last.contacts),
                    d,
                )))
            }
            _ => Ok(None),
        });
        let solved = clock.cycles();
        let rendered = linear.and_then(|l| match l {
            None => Ok([0.0; 3]),
            Some((f, d)) => self.law(f, d),
        });
        // A tick that rendered no relaxed contact force feeds the relaxation a zero one.
        if let Some(qlv) = &mut self.qlv {
            qlv.end_tick();
        }
        let (force_on_tool, solve_error) = match rendered {
            Ok(on_tissue) => (self.device.limit_force(on_tissue.map(|f| -f)), None),
            Err(e) => {
                self.last.contacts.clear();
                ([0.0; 3], Some(e))
            }
        };
        let dropped_load = match self.holding.then_some(&self.held) {
            Some(h) if solve_error.is_none() => h.dropped,
            _ => 0.0,
        };
        if dropped_load > 0.0 {
            self.counters.capped_ticks = self.counters.capped_ticks.wrapping_add(1);
        }
        // The ramp-in after an arm scales the rendered force and the gravity feed-forward.
        let ramp = self.ramp_in();
        let force_on_tool = if ramp < 1.0 {
            force_on_tool.map(|f| ramp * f)
        } else {
            force_on_tool
        };
        // A host's constant currents go to the supervisor as sent: it faults on one that is
        // not finite or over its limit instead of clamping it.
        let requested_a = match self.mode {
            Mode::ConstantCurrent { currents_a } => currents_a,
            _ if solve_error.is_some() => [0.0; 3],
            _ => {
                let [fp, fy, fi] = transpose_mul(&jac, force_on_tool);
                let [gp, gy, gi] = gravity_efforts(self.bank, &q);
                let g = if ramp < 1.0 {
                    [ramp * gp, ramp * gy, ramp * gi]
                } else {
                    [gp, gy, gi]
                };
                self.device
                    .requested_currents([fp + g[0], fy + g[1], fi + g[2]])
            }
        };
        let law = clock.cycles();
        let out = self.supervisor.tick(&TickInput {
            bank_error: None,
            counts,
            joints: q.to_array(),
            tip_m: tip,
            force_n: force_on_tool,
            requested_a,
            host_currents: matches!(self.mode, Mode::ConstantCurrent { .. }),
            overrun: input.overrun,
            link_silence_ticks: input.link_silence_ticks,
            solve_failed: solve_error.is_some(),
            interlocks: input.interlocks,
        });
        self.last.tip_m = tip;
        self.last.contact_point = match contact {
            ContactState::Touching { triangle, bary, .. } if !self.last.contacts.is_empty() => {
                Some(bank_format::ContactPoint { triangle, bary })
            }
            _ => None,
        };
        self.last.currents_a = out.currents_a;
        self.last.tool_force_n = force_on_tool;
        self.last.dropped_load = dropped_load;
        let output = LoopOutput {
            tick: self.tick,
            currents_a: out.currents_a,
            clamped: out.clamped,
            state: out.state,
            tip_m: tip,
            contact,
            contact_nodes: self.last.contacts.len(),
            tool_force_n: force_on_tool,
            fault: self.supervisor.fault(),
            new_fault: out.new_fault,
            solve_error,
            patch: self.holding.then_some(self.held.origin),
            dropped_load,
        };
        let marks = PhaseMarks {
            kinematics,
            detection,
            patch,
            solve: solved,
            law,
        };
        (output, marks)
    }

    /// The last tick's contact nodes and the (linear-model) forces on the tissue at them, N;
    /// empty when free or when the solve failed.
    pub fn contacts(&self) -> &Contacts {
        &self.last.contacts
    }

    /// Where the last tick's rendered contact is on the collision surface (telemetry's
    /// `contact_point`); `None` without one.
    pub fn contact_point(&self) -> Option<bank_format::ContactPoint> {
        self.last.contact_point
    }

    /// Telemetry of the last tick (for decimated sending).
    pub fn telemetry(&self) -> Telemetry {
        Telemetry {
            tick: self.tick,
            state: self.supervisor.state().wire(),
            mode: self.mode,
            fault: self.supervisor.state().fault(),
            tip_m: self.last.tip_m,
            contacts: self.last.contacts.clone(),
            contact_point: self.last.contact_point,
            currents_a: self.last.currents_a,
            tool_force_n: self.last.tool_force_n,
            dropped_load: self.last.dropped_load,
            counters: self.counters,
        }
    }

    /// The patch phase: holds the factored contact solve to render with this tick (the first
    /// tick's contact triangle, or [`Self::maintain_patch`]) and returns the tip's
    /// displacement, when touching (the solve is then `self.held`'s).
    fn contact_solve(&mut self, contact: &ContactState) -> Result<Option<[f32; 3]>, SolveError> {
        let ContactState::Touching {
            triangle,
            nodes,
            bary,
            anchor,
            displacement,
        } = *contact
        else {
            self.holding = false;
            self.blend = None;
            self.pending.origin = None;
            self.pending.failed_at = None;
            self.detected = false;
            return Ok(None);
        };
        // The tick that detects a contact renders none: its displacement is under one tick of
        // motion, and detection with a hit is the costliest phase of all; the contact
        // triangle's solve comes the next tick, while detection only tracks.
        if !self.holding && !self.detected {
            self.detected = true;
            return Ok(None);
        }
        if let Some(samples) = self.bank.samples() {
            // The sampled patch compliance (`SPEC.md`, "contact samples"): `W` at the anchor,
            // interpolated and factored every tick; no patch, no rebuild, no blend (`W` is
            // continuous as the anchor slides).
            let origin = PatchOrigin {
                triangle,
                nodes,
                bary,
                anchor,
                radius_m: samples.tip_radius_m(),
            };
            // Refactored in place, the first tick of a contact too (`held` is its storage): the
            // held solve is a few hundred bytes to move. On an error `held` is unchanged.
            let (w, shares) = sampled_compliance(&samples, triangle, nodes, bary)?;
            let (n, wt) = shares.split();
            self.held.solve.refactor(w, n, wt)?;
            self.held.origin = origin;
            self.held.dropped = 0.0;
            self.holding = true;
            return Ok(Some(displacement));
        }
        if let Some(b) = &mut self.blend {
            b.left = b.left.saturating_sub(1);
            if b.left == 0 {
                self.blend = None;
            }
        }
        let tip_radius = self.bank.device().tip_radius_m;
        let repatch = REPATCH_FRACTION * tip_radius;
        let origin = PatchOrigin {
            triangle,
            nodes,
            bary,
            anchor,
            radius_m: tip_radius,
        };
        if self.holding {
            self.maintain_patch(self.held.origin, origin, repatch);
        } else {
            // The first tick of a contact's force solves on the contact triangle alone (the
            // tip's displacement is still tiny, so is the force); the tip's patch is built
            // over the next ticks.
            self.pending.origin = None;
            let (solve, dropped) = match triangle_solve(self.bank, nodes, bary) {
                Some(solve) => (solve, 0.0),
                None => {
                    // A vertex pair the bank does not couple (or a failing solve): the
                    // patch rule's choice, `tool_patch(.., 0.0)`, in the idle rebuild's
                    // place (no large temporary).
                    let build = &mut self.pending.build;
                    build.start(self.bank, triangle, nodes, bary, anchor, 0.0);
                    let patch = build.finish(self.bank);
                    let solve = WeightedSolve::new(self.bank, patch.nodes(), patch.weights())?;
                    (solve, patch.dropped)
                }
            };
            self.held = Held {
                origin: PatchOrigin {
                    radius_m: 0.0,
                    ..origin
                },
                solve,
                dropped,
            };
            self.holding = true;
        }
        Ok(Some(displacement))
    }

    /// This tick's share of the loop's output during the ramp-in after an arm
    /// ([`RAMP_IN_TICKS`]): `k / RAMP_IN_TICKS` on the k-th armed tick, 1 once it is over and
    /// whenever the tick starts unarmed (what telemetry reports then is the force the loop
    /// computes).
    fn ramp_in(&mut self) -> f32 {
        if self.supervisor.state() != State::Armed || self.ramp_ticks >= RAMP_IN_TICKS {
            return 1.0;
        }
        self.ramp_ticks += 1;
        self.ramp_ticks as f32 / RAMP_IN_TICKS as f32
    }

    /// The force on the tissue for the mode from the linear model's tool force `f` at
    /// displacement `d` (the law phase): Q in `Render`, then the bank's viscoelastic
    /// relaxation if it has one ([`Qlv::press`]); `f` itself in `LinearLaw`, none in the modes
    /// that render no contact (the relaxation then sees a zero force, [`Qlv::end_tick`]).
    fn law(&mut self, f: [f32; 3], d: [f32; 3]) -> Result<[f32; 3], SolveError> {
        match self.mode {
            Mode::Render => {
                let q = apply_tissue_law(self.bank.tissue_law(), f, d)?;
                match &mut self.qlv {
                    Some(qlv) => qlv.press(q),
                    None => Ok(q),
                }
            }
            Mode::LinearLaw => Ok(f),
            Mode::Transparent | Mode::ConstantCurrent { .. } => Ok([0.0; 3]),
        }
    }
}

/// The solve phase: the tool force of `solve` at displacement `d` (blended with the outgoing
/// patch's, `Blend`), the linear model's.
fn tool_force(
    solve: &WeightedSolve,
    blend: Option<&Blend>,
    d: [f32; 3],
) -> Result<[f32; 3], SolveError> {
    let mut tool = solve.tool_force(d)?;
    if let Some(b) = blend {
        let old = b.solve.tool_force(d)?;
        let s = b.left as f32 / (BLEND_TICKS + 1) as f32;
        for (t, o) in tool.iter_mut().zip(old) {
            *t += s * (o - *t);
        }
    }
    Ok(tool)
}

/// The node forces `f_k = w_k tool` on `solve`'s nodes into `contacts` (telemetry's contact
/// set, empty on entry), returning their sum: the linear model's force on the tissue.
fn node_forces(solve: &WeightedSolve, tool: [f32; 3], contacts: &mut Contacts) -> [f32; 3] {
    let mut sum = [0.0f32; 3];
    for (node, w) in solve.shares() {
        let force_n = tool.map(|t| w * t);
        for (s, f) in sum.iter_mut().zip(force_n) {
            *s += f;
        }
        // MAX_CONTACTS == MAX_CONTACT_NODES: never full.
        if contacts.push(Contact { node, force_n }).is_err() {
            break;
        }
    }
    sum
}

/// `a - b` per joint, wrapping (encoder counters wrap).
fn sub_wrapping(a: [i32; 3], b: [i32; 3]) -> [i32; 3] {
    let mut out = a;
    for (o, &x) in out.iter_mut().zip(&b) {
        *o = o.wrapping_sub(x);
    }
    out
}
