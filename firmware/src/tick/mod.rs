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

use bank_format::{Bank, Contact, Counters, MAX_CONTACTS, Mode, PhaseCycles, Telemetry, heapless};

use crate::contact::{ContactState, ContactTracker, max_path_m, path_tail};
use crate::device::{Device, Joints, sin_cos, transpose_mul};
use crate::hal::{CycleCounter, Interlocks};
use crate::patch::PatchBuild;
use crate::relax::Qlv;
use crate::safety::{ArmRefused, Fault, SafetyConfig, State, Supervisor, TickInput};
use crate::solve::{SolveError, WeightedFill, WeightedSolve, apply_tissue_law};
use crate::vec3::dist2;

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

/// A sliding contact keeps its patch (weights and factored solve) until the anchor has moved
/// this fraction of the tip radius from where the patch was built: the displacement still
/// follows the anchor every tick, and rebuilding the patch (quadrature points located on the
/// surface, a new factor) costs far more than a tick should.
pub const REPATCH_FRACTION: f32 = 0.1;

/// The factored contact solve of the anchor it was built at (reused while the contact presses
/// in place or slides less than [`REPATCH_FRACTION`] of the tip radius).
#[derive(Clone, Copy, Debug)]
struct Held {
    origin: PatchOrigin,
    solve: WeightedSolve,
    /// The patch's [`crate::patch::Patch::dropped`].
    dropped: f32,
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
struct Blend {
    solve: WeightedSolve,
    left: u32,
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
struct Pending {
    origin: Option<PatchOrigin>,
    build: PatchBuild,
    stage: Stage,
    /// Where the last rebuild that failed was started: the next starts only once the anchor
    /// has slid [`REPATCH_FRACTION`] of the tip radius from there (not every few ticks at the
    /// same spot). `None` when the last one succeeded, or the contact ended since.
    failed_at: Option<[f32; 3]>,
}

/// How far a [`Pending`] rebuild has come: one step a tick, each bounded ([`PatchBuild`],
/// [`WeightedFill`]).
#[derive(Clone, Copy, Debug)]
enum Stage {
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

/// The sampled contact at barycentric point `bary` of `triangle`: the bank's patch compliance
/// `W` there ([`bank_format::Samples::interpolate`]), and the triangle's vertices with positive
/// coordinates, weighted by them (normalised), to spread the tool force over for telemetry's
/// node forces. The rendered force is `W^-1 d`: the paper's eq. 8 for one rigid tool in
/// compliance form.
fn sampled_compliance(
    samples: &bank_format::Samples<'_>,
    triangle: u32,
    nodes: [u16; 3],
    bary: [f32; 3],
) -> Result<([f32; 6], TriangleShares), SolveError> {
    let w = samples
        .interpolate(triangle as usize, bary)
        .ok_or(SolveError::NonFinite)?;
    let shares = TriangleShares::of(nodes, bary).ok_or(SolveError::BadWeights)?;
    Ok((w, shares))
}

/// A contact triangle's vertices with a positive barycentric coordinate and their shares of
/// the tool force ([`sampled_compliance`], [`triangle_solve`]).
struct TriangleShares {
    nodes: [u16; 3],
    weights: [f32; 3],
    len: usize,
}

impl TriangleShares {
    /// The vertices of `nodes` with a positive (finite) barycentric coordinate, weighted by it,
    /// normalised to sum 1; `None` when none is positive.
    fn of(nodes: [u16; 3], bary: [f32; 3]) -> Option<TriangleShares> {
        let mut shares = TriangleShares {
            nodes: [0; 3],
            weights: [0.0; 3],
            len: 0,
        };
        for (&k, &b) in nodes.iter().zip(&bary) {
            if b > 0.0
                && b.is_finite()
                && let (Some(nk), Some(wk)) = (
                    shares.nodes.get_mut(shares.len),
                    shares.weights.get_mut(shares.len),
                )
            {
                (*nk, *wk) = (k, b);
                shares.len += 1;
            }
        }
        let kept: f32 = shares.weights.iter().sum();
        if shares.len == 0 || !(kept > 0.0 && kept.is_finite()) {
            return None;
        }
        for x in shares.weights.iter_mut() {
            *x /= kept;
        }
        Some(shares)
    }

    /// The kept vertices and their weights.
    fn split(&self) -> (&[u16], &[f32]) {
        (
            self.nodes.get(..self.len).unwrap_or(&[]),
            self.weights.get(..self.len).unwrap_or(&[]),
        )
    }
}

/// The first tick's solve on the contact triangle alone: its vertices with a positive
/// barycentric coordinate, weighted by it (normalised). The same weights as the patch rule at
/// radius 0 ([`PatchBuild`]: one load per vertex, no quadrature) without building a patch;
/// `None` when the bank does not couple two of the vertices or the solve fails, for the
/// caller to take the patch rule's path (which drops an uncoupled vertex).
fn triangle_solve(bank: &Bank, nodes: [u16; 3], bary: [f32; 3]) -> Option<WeightedSolve> {
    let shares = TriangleShares::of(nodes, bary)?;
    let (n, w) = shares.split();
    WeightedSolve::new(bank, n, w).ok()
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

/// Counter readings at the ends of a tick's first five phases
/// ([`HapticLoop::tick_marked`]); the caller's readings before and after the tick bound the
/// first and the last (supervisor) phase.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PhaseMarks {
    /// After encoder counts to joints, tip and Jacobian.
    pub kinematics: u32,
    /// After the contact tracker's update.
    pub detection: u32,
    /// After the patch (and its factored solve) for this tick.
    pub patch: u32,
    /// After the 3 x 3 solve and the node forces.
    pub solve: u32,
    /// After the law, the force cap and the requested currents.
    pub law: u32,
}

impl PhaseMarks {
    /// The phases' lengths between `start` (read before the tick) and `end` (after it),
    /// wrapping: they sum to `end - start`.
    pub fn phases(&self, start: u32, end: u32) -> PhaseCycles {
        PhaseCycles {
            kinematics: self.kinematics.wrapping_sub(start),
            detection: self.detection.wrapping_sub(self.kinematics),
            patch: self.patch.wrapping_sub(self.detection),
            solve: self.solve.wrapping_sub(self.patch),
            law: self.law.wrapping_sub(self.solve),
            supervisor: end.wrapping_sub(self.law),
        }
    }
}

/// The counter of an untimed tick ([`HapticLoop::tick`]): always 0, compiled away.
struct NoCounter;

impl CycleCounter for NoCounter {
    fn cycles(&self) -> u32 {
        0
    }
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
    fn maintain_patch(&mut self, held: PatchOrigin, origin: PatchOrigin, repatch: f32) {
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

/// `a - b` per joint, wrapping (encoder counters wrap).
/// The joint efforts that hold the instrument still against its own weight at `q` (pitch N m,
/// yaw N m, insertion N): `tau_g(q) = dV/dq` of the bank's gravity section
/// ([`GravityCompensation::efforts`](bank_format::GravityCompensation::efforts), `SPEC.md`
/// "gravity"), zero when the bank has none.
pub fn gravity_efforts(bank: &Bank<'_>, q: &Joints) -> [f32; 3] {
    match bank.gravity() {
        Some(g) => g.efforts(sin_cos(q.pitch), sin_cos(q.yaw), q.insertion),
        None => [0.0; 3],
    }
}

fn sub_wrapping(a: [i32; 3], b: [i32; 3]) -> [i32; 3] {
    let mut out = a;
    for (o, &x) in out.iter_mut().zip(&b) {
        *o = o.wrapping_sub(x);
    }
    out
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
    use super::*;
    use crate::device::Joints;
    use crate::fixtures::{flat_patch, patch_device};
    use bank_format::{AlignedBytes, BankBuilder, DeviceCalibration, FaultReason, TissueLaw};
    use std::vec::Vec;

    /// Encoder counts for insertion `s` (m) straight down from the rest pose.
    fn counts_for_insertion(dev: &Device, s: f32) -> [i32; 3] {
        let k = dev.joint_per_count()[2];
        [0, 0, ((s - 0.05) / k).round() as i32]
    }

    /// A loop on `bank` referenced at encoder zero, the home pose (a host's `ZeroEncoders`
    /// before the first tick).
    fn homed<'b>(bank: &'b Bank<'b>) -> HapticLoop<'b> {
        homed_with(bank, SafetyConfig::new(bank.device()))
    }

    /// [`homed`] with explicit safety thresholds.
    fn homed_with<'b>(bank: &'b Bank<'b>, config: SafetyConfig) -> HapticLoop<'b> {
        let mut lp = HapticLoop::with_config(bank, config);
        assert!(lp.zero_encoders());
        lp
    }

    /// Ticks at `counts` until the ramp-in after the last arm is over; the last tick's output
    /// (the first with the loop's whole output).
    fn ramped_in(lp: &mut HapticLoop, counts: [i32; 3]) -> LoopOutput {
        let mut out = lp.tick(input(counts));
        for _ in 1..RAMP_IN_TICKS {
            out = lp.tick(input(counts));
        }
        out
    }

    fn input(counts: [i32; 3]) -> LoopInput {
        LoopInput {
            encoder_counts: counts,
            overrun: false,
            link_silence_ticks: 0,
            interlocks: Interlocks::default(),
        }
    }

    fn norm(v: [f32; 3]) -> f32 {
        v.iter().map(|x| x * x).sum::<f32>().sqrt()
    }

    /// Invariants of every tick.
    fn check(out: &LoopOutput, cal: &DeviceCalibration) {
        for (i, &lim) in out.currents_a.iter().zip(&cal.current_limit_a) {
            assert!(i.is_finite() && i.abs() <= lim, "{out:?}");
        }
        assert!(out.tip_m.iter().all(|x| x.is_finite()), "{out:?}");
        assert!(out.tool_force_n.iter().all(|x| x.is_finite()), "{out:?}");
        assert!(norm(out.tool_force_n) <= cal.max_force_n * (1.0 + 1e-5));
        if out.state != State::Armed {
            assert_eq!(out.currents_a, [0.0; 3]);
        }
    }

    #[test]
    fn the_first_ticks_triangle_solve_is_the_patch_rules_at_radius_zero() {
        let bytes = flat_patch();
        let bank = Bank::parse(bytes.as_slice()).unwrap();
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

    /// On a bank with contact samples the tick renders `W(anchor)^-1 d` every contact tick
    /// (after the detecting one), whatever the anchor: checked in f64 against the fixture's `W`
    /// field along a press and slide, with the node forces the contact triangle's barycentric
    /// shares of it.
    #[test]
    fn a_sampled_bank_renders_w_inverse_d_at_the_anchor() {
        let bytes = crate::fixtures::sampled_patch();
        let bank = Bank::parse(bytes.as_slice()).unwrap();
        assert!(bank.samples().is_some());
        let mut lp = homed(&bank);
        lp.set_mode(Mode::LinearLaw).unwrap();
        let dev = *lp.device();
        let ws = |s: f32| counts_for_insertion(&dev, s);
        let mut checked = 0;
        for t in 0..=400 {
            let s = 0.095 + 0.03e-3 * t.min(300) as f32;
            let mut counts = ws(s);
            // Slide sideways once in.
            counts[0] += (t.max(250) - 250) * 3;
            let out = lp.tick(input(counts));
            let (
                ContactState::Touching {
                    anchor,
                    displacement,
                    bary,
                    ..
                },
                Some(origin),
            ) = (out.contact, out.patch)
            else {
                continue;
            };
            if out.contact_nodes == 0 {
                continue;
            }
            assert_eq!(origin.anchor, anchor);
            // Telemetry names the contact point for a display's fields.
            assert_eq!(
                lp.telemetry().contact_point,
                Some(bank_format::ContactPoint {
                    triangle: origin.triangle,
                    bary
                })
            );
            let w = crate::fixtures::sampled_w(anchor.map(f64::from));
            let want = crate::fixtures::gauss(
                w.iter().map(|r| r.to_vec()).collect(),
                displacement.iter().map(|&v| f64::from(v)).collect(),
            );
            // The force on the tool is minus the force on the tissue.
            let got = out.tool_force_n.map(|f| -f);
            let err = crate::fixtures::rel_err(&[got], &want);
            assert!(err < 1e-4, "tick {t}: {got:?} vs {want:?} ({err})");
            let mut sum = [0.0f32; 3];
            for c in lp.contacts() {
                let k = bank.triangles()[origin.triangle as usize]
                    .iter()
                    .position(|&v| v == c.node)
                    .unwrap();
                for i in 0..3 {
                    sum[i] += c.force_n[i];
                    assert!((c.force_n[i] - bary[k] * -out.tool_force_n[i]).abs() < 1e-6);
                }
            }
            assert!(crate::fixtures::rel_err(&[sum], &want) < 1e-4);
            checked += 1;
        }
        assert!(checked > 150, "{checked} contact ticks");
    }

    #[test]
    fn press_and_release() {
        let bytes = flat_patch();
        let bank = Bank::parse(bytes.as_slice()).unwrap();
        let cal = patch_device();
        let mut lp = homed(&bank);
        assert_eq!(lp.arm(), Ok(()));
        let dev = *lp.device();
        // Down from 5 mm above the surface to 4 mm deep, 0.05 mm per tick, and back up.
        let down: Vec<f32> = (0..=180).map(|t| 0.095 + 0.05e-3 * t as f32).collect();
        let path: Vec<f32> = down.iter().chain(down.iter().rev()).copied().collect();
        let mut fz = Vec::new();
        for &s in &path {
            let out = lp.tick(input(counts_for_insertion(&dev, s)));
            check(&out, &cal);
            assert_eq!(out.state, State::Armed, "{out:?}");
            let depth = -out.tip_m[2];
            if depth > 1e-4 {
                assert!(
                    matches!(out.contact, ContactState::Touching { .. }),
                    "{out:?}"
                );
                // Pressed at a node of the 1 cm grid with a 3 mm tip: the node and its ring of
                // six carry it, once the patch is built (under 16 ticks, 0.8 mm, after
                // contact; the contact triangle carries it before).
                let n = out.contact_nodes;
                assert!(n == 7 || (n <= 3 && depth < 0.8e-3), "{out:?}");
                // The tool is pushed back up, out of the tissue.
                assert!(out.tool_force_n[2] > 0.0, "{out:?}");
                // Insertion motor pushes the shaft back: negative effort along +insertion.
                assert!(out.currents_a[2] < 0.0, "{out:?}");
            }
            if depth < -1e-6 {
                assert_eq!(out.contact, ContactState::Free);
                assert_eq!(out.tool_force_n, [0.0; 3]);
                assert_eq!(out.currents_a, [0.0; 3]);
                assert!(out.contact_nodes == 0);
            }
            fz.push(out.tool_force_n[2]);
        }
        // Rises while pressing (monotone within rounding), peaks at the bottom, back to zero.
        let peak = fz.iter().copied().fold(0.0f32, f32::max);
        assert!(peak > 0.5 && peak <= cal.max_force_n, "peak {peak}");
        for w in fz[..down.len()].windows(2) {
            assert!(w[1] >= w[0] - 1e-4, "{w:?}");
        }
        assert_eq!(*fz.last().unwrap(), 0.0);
        let tel = lp.telemetry();
        assert_eq!(tel.tick, path.len() as u32);
        assert_eq!(tel.state, bank_format::State::Armed);
        assert!(tel.contacts.is_empty());
    }

    /// The flat patch with the relaxation `g`, `tau_s` (s), or elastic.
    fn relaxing_patch(g: &[f32], tau_s: &[f32]) -> AlignedBytes {
        let side: Vec<f64> = (0..crate::fixtures::PATCH_SIDE)
            .map(|i| crate::fixtures::PATCH_SPACING_M * i as f64)
            .collect();
        let mut b = crate::fixtures::grid_builder(&side, &side, 0.06, patch_device());
        if !g.is_empty() {
            let mut r = bank_format::Relaxation {
                count: g.len() as u32,
                reserved: 0,
                g: [0.0; 4],
                tau_s: [0.0; 4],
            };
            r.g[..g.len()].copy_from_slice(g);
            r.tau_s[..tau_s.len()].copy_from_slice(tau_s);
            b.relaxation = Some(r);
        }
        AlignedBytes::new(&b.build().unwrap())
    }

    /// A press (3 mm at 10 mm/s), a 2 s hold and a release on a bank with a two-term
    /// relaxation: every tick's force is the QLV convolution (`firmware::relax`, (1)) of the
    /// elastic bank's force on the same path, evaluated independently of the recursion as
    /// the direct sum over the history's segments (each segment's integral in closed form,
    /// f64); nothing after the release; and in `LinearLaw` the relaxed bank renders the elastic
    /// force bit for bit.
    #[test]
    fn a_relaxing_bank_renders_the_qlv_convolution_of_the_elastic_force() {
        let (g, tau) = ([0.4f64, 0.25], [0.05f64, 0.8]);
        let elastic = relaxing_patch(&[], &[]);
        let relaxing = relaxing_patch(&[0.4, 0.25], &[0.05, 0.8]);
        let elastic = Bank::parse(elastic.as_slice()).unwrap();
        let relaxing = Bank::parse(relaxing.as_slice()).unwrap();
        let dev = Device::new(&patch_device());
        let mut path: Vec<f32> = (0..=400).map(|t| 0.097 + 0.01e-3 * t as f32).collect();
        path.extend(std::iter::repeat_n(0.101, 2000));
        path.extend((0..=400).rev().map(|t| 0.097 + 0.01e-3 * t as f32));
        let run = |bank: &Bank, mode: Mode| -> Vec<[f32; 3]> {
            let mut lp = homed(bank);
            lp.set_mode(mode).unwrap();
            path.iter()
                .map(|&s| lp.tick(input(counts_for_insertion(&dev, s))).tool_force_n)
                .collect()
        };
        let q = run(&elastic, Mode::Render);
        let f = run(&relaxing, Mode::Render);
        assert_eq!(
            run(&relaxing, Mode::LinearLaw),
            run(&elastic, Mode::LinearLaw)
        );
        let peak = q.iter().map(|v| norm(*v)).fold(0.0, f32::max);
        assert!(
            peak > 0.3 && peak < patch_device().max_force_n * 0.9,
            "{peak}"
        );
        let g_inf = 1.0 - g.iter().sum::<f64>();
        let dt = 1.0e-3;
        let mut worst = 0.0f64;
        let release = 400 + 2000;
        for n in 0..release {
            for i in 0..3 {
                // F(n) = g_inf Q(n) + sum_k g_k sum_j e^{-(n-j) dt/tau} (tau/dt)(1 - e^{-dt/tau})
                // (Q(j) - Q(j-1)): the convolution (1) of the linear interpolation of Q.
                let qi = |j: usize| if j == 0 { 0.0 } else { f64::from(q[j - 1][i]) };
                let mut want = g_inf * qi(n + 1);
                for (gk, tk) in g.iter().zip(tau) {
                    let seg = tk / dt * (1.0 - (-dt / tk).exp());
                    for j in 1..=n + 1 {
                        let age = (n + 1 - j) as f64 * dt;
                        want += gk * seg * (-age / tk).exp() * (qi(j) - qi(j - 1));
                    }
                }
                worst = worst.max((f64::from(f[n][i]) - want).abs() / f64::from(peak));
            }
        }
        assert!(worst < 1e-5, "worst {worst:e} of the peak");
        // Relaxed in the hold: at its end (2 s) the 50 ms term is gone and the 0.8 s one has
        // e^-2.5 of its share left: the force is g_inf of the elastic one plus under 0.025.
        let end = release - 1;
        let excess = f64::from(f[end][2] / q[end][2]) - g_inf;
        assert!((0.0..0.025).contains(&excess), "{excess}");
        // Out of contact: nothing.
        assert_eq!(*f.last().unwrap(), [0.0; 3]);
        for (a, b) in f.iter().zip(&q).skip(release) {
            if *b == [0.0; 3] {
                assert_eq!(*a, [0.0; 3]);
            }
        }
    }

    /// Pressed 3 mm into the tissue while disarmed, then armed: the rendered force and the
    /// currents rise from zero over `RAMP_IN_TICKS`, in equal steps, instead of the whole
    /// force in the first armed tick; the same after a fault's `ClearFault` + `Arm`. The
    /// gravity feed-forward ramps with them.
    #[test]
    fn the_force_ramps_in_after_each_arm() {
        let bytes = flat_patch();
        let bank = Bank::parse(bytes.as_slice()).unwrap();
        let mut lp = homed(&bank);
        let dev = *lp.device();
        let mut out = lp.tick(input(counts_for_insertion(&dev, 0.095)));
        for t in 1..=160 {
            out = lp.tick(input(counts_for_insertion(
                &dev,
                0.095 + 0.05e-3 * t as f32,
            )));
        }
        let s = counts_for_insertion(&dev, 0.103);
        assert_eq!(out.state, State::Disarmed);
        let full = out.tool_force_n;
        assert!(norm(full) > 0.5, "{out:?}");
        let check_ramp = |lp: &mut HapticLoop| {
            let mut currents = Vec::new();
            for k in 1..=RAMP_IN_TICKS {
                let out = lp.tick(input(s));
                assert_eq!(out.state, State::Armed);
                let share = k as f32 / RAMP_IN_TICKS as f32;
                for i in 0..3 {
                    assert!(
                        (out.tool_force_n[i] - share * full[i]).abs() <= 1e-5 * norm(full),
                        "tick {k}: {out:?}"
                    );
                }
                currents.push(out.currents_a[2]);
            }
            // The insertion current falls (pushes back) in equal steps to its full value.
            let step = currents[RAMP_IN_TICKS as usize - 1] / RAMP_IN_TICKS as f32;
            assert!(step < 0.0);
            for (k, c) in currents.iter().enumerate() {
                assert!(
                    (c - step * (k + 1) as f32).abs() <= 1e-4 * step.abs(),
                    "{k}"
                );
            }
            assert_eq!(lp.tick(input(s)).tool_force_n, full);
        };
        lp.arm().unwrap();
        check_ramp(&mut lp);
        // A fault while pressed (the host went silent), cleared and armed again: from zero.
        let out = lp.tick(LoopInput {
            link_silence_ticks: 11,
            ..input(s)
        });
        assert_eq!(out.state, State::Fault(FaultReason::LinkSilent));
        assert!(lp.clear_fault());
        lp.arm().unwrap();
        check_ramp(&mut lp);

        // The gravity feed-forward: a third of it a third of the way in.
        let g = bank_format::GravityCompensation {
            coeffs: [0.05, -0.02, 0.03, 0.4, 0.1, -0.3, 0.02, -0.01],
        };
        let with = gravity_bank(Some(g));
        let bank = Bank::parse(with.as_slice()).unwrap();
        let counts = [2000, -1500, 300];
        let mut lp = homed(&bank);
        lp.arm().unwrap();
        let third: Vec<[f32; 3]> = (0..RAMP_IN_TICKS / 3)
            .map(|_| lp.tick(input(counts)).currents_a)
            .collect();
        let whole = ramped_in(&mut lp, counts).currents_a;
        for j in 0..3 {
            let got = third.last().unwrap()[j];
            assert!((got - whole[j] / 3.0).abs() <= 1e-5 * whole[j].abs(), "{j}");
            assert!(third[0][j].abs() <= whole[j].abs() / RAMP_IN_TICKS as f32 * 1.0001);
        }
    }

    /// Arming needs the encoders referenced (a `ZeroEncoders` since the loop started, i.e.
    /// since the chip's reset): refused and latched `NotReferenced` before; an encoder jump
    /// loses the reference again.
    #[test]
    fn arming_needs_a_reference_which_an_encoder_jump_loses() {
        let bytes = flat_patch();
        let bank = Bank::parse(bytes.as_slice()).unwrap();
        let mut lp = HapticLoop::new(&bank);
        assert!(!lp.referenced());
        lp.tick(input([0, 0, 0]));
        assert_eq!(lp.arm(), Err(ArmRefused::NotReferenced));
        let out = lp.tick(input([0, 0, 0]));
        assert_eq!(
            (out.state, out.currents_a),
            (State::Fault(FaultReason::NotReferenced), [0.0; 3])
        );
        assert!(lp.clear_fault());
        assert!(lp.zero_encoders());
        assert!(lp.referenced());
        lp.arm().unwrap();
        assert_eq!(lp.tick(input([0, 0, 0])).state, State::Armed);
        let out = lp.tick(input([0, 0, 100_000]));
        assert_eq!(out.state, State::Fault(FaultReason::EncoderJump));
        assert!(!lp.referenced());
        assert!(lp.clear_fault());
        assert_eq!(lp.arm(), Err(ArmRefused::NotReferenced));
    }

    /// A jump loses the reference whatever the supervisor reports for the tick: while another
    /// fault is latched (`LinkSilent`, which `raise` keeps over the jump's `EncoderJump`) and
    /// in the same tick as an interlock (reported before jumps). Both end with `Arm` refused
    /// `NotReferenced` after `ClearFault`, and arm again once homed.
    #[test]
    fn a_jump_hidden_by_another_fault_still_loses_the_reference() {
        let bytes = flat_patch();
        let bank = Bank::parse(bytes.as_slice()).unwrap();
        let jump = [0, 0, 100_000];

        // LinkSilent latched, then the jump while it is.
        let mut lp = homed(&bank);
        lp.tick(input([0; 3]));
        lp.arm().unwrap();
        let out = lp.tick(LoopInput {
            link_silence_ticks: 1_000,
            ..input([0; 3])
        });
        assert_eq!(out.state, State::Fault(FaultReason::LinkSilent));
        let out = lp.tick(input(jump));
        assert_eq!(out.state, State::Fault(FaultReason::LinkSilent));
        assert_eq!(out.new_fault, None);
        assert!(!lp.referenced());
        assert!(lp.clear_fault());
        assert_eq!(lp.arm(), Err(ArmRefused::NotReferenced));
        // Homed again where the counts now stand, it arms.
        assert!(lp.clear_fault());
        assert!(lp.zero_encoders());
        assert_eq!(lp.tick(input(jump)).state, State::Disarmed);
        assert_eq!(lp.arm(), Ok(()));

        // An amplifier fault in the same tick as the jump.
        let mut lp = homed(&bank);
        lp.tick(input([0; 3]));
        lp.arm().unwrap();
        let mut amp = Interlocks::default();
        amp.amplifier_fault[1] = true;
        let out = lp.tick(LoopInput {
            interlocks: amp,
            ..input(jump)
        });
        assert_eq!(out.state, State::Fault(FaultReason::AmplifierFault));
        assert_eq!(out.currents_a, [0.0; 3]);
        assert!(!lp.referenced());
        lp.tick(input(jump));
        assert!(lp.clear_fault());
        assert_eq!(lp.arm(), Err(ArmRefused::NotReferenced));
    }

    #[test]
    fn linear_law_and_transparent_modes() {
        let bytes = flat_patch();
        let bank = Bank::parse(bytes.as_slice()).unwrap();
        let mut lp = homed(&bank);
        lp.arm().unwrap();
        let dev = *lp.device();
        for t in 0..=100 {
            lp.tick(input(counts_for_insertion(
                &dev,
                0.099 + 0.03e-3 * t as f32,
            )));
        }
        let s = counts_for_insertion(&dev, 0.102);
        let render = ramped_in(&mut lp, s);
        let render_contacts = lp.contacts().clone();
        // The mode is set while disarmed.
        assert!(lp.disarm());
        lp.set_mode(Mode::LinearLaw).unwrap();
        lp.arm().unwrap();
        let linear = ramped_in(&mut lp, s);
        // The node forces (linear model) sum to minus the linear tool force.
        let sum: [f32; 3] =
            core::array::from_fn(|i| lp.contacts().iter().map(|c| c.force_n[i]).sum());
        for i in 0..3 {
            assert!(
                (sum[i] + linear.tool_force_n[i]).abs() < 1e-4,
                "{sum:?} {linear:?}"
            );
        }
        assert_eq!(&render_contacts, lp.contacts());
        assert!((render.tool_force_n[2] - linear.tool_force_n[2]).abs() > 1e-3);
        // The mode is set while disarmed.
        assert!(lp.disarm());
        lp.set_mode(Mode::Transparent).unwrap();
        lp.arm().unwrap();
        let out = lp.tick(input(s));
        assert_eq!(out.currents_a, [0.0; 3]);
        assert_eq!(out.contact_nodes, 7);
    }

    /// A host's `ConstantCurrent` command reaches the supervisor as sent: a current over its
    /// motor's limit (-9 A against 2 A) or a NaN is a `BadCommand` fault naming the motor, with
    /// zero current, not a request silently clamped to the limit (issue 15, item 4).
    #[test]
    fn constant_current_over_the_limit_or_not_finite_is_a_bad_command() {
        let bytes = flat_patch();
        let bank = Bank::parse(bytes.as_slice()).unwrap();
        let cal = patch_device();
        assert_eq!(cal.current_limit_a, [2.0; 3]);
        for (currents_a, motor) in [
            ([0.5, -9.0, 0.0], 1),
            ([0.5, 0.0, f32::NAN], 2),
            ([f32::INFINITY, 0.0, 0.0], 0),
            ([0.0, 2.0 + 1e-3, 0.0], 1),
        ] {
            let mut lp = homed(&bank);
            assert_eq!(lp.set_mode(Mode::ConstantCurrent { currents_a }), Ok(()));
            lp.arm().unwrap();
            let out = lp.tick(input([0, 0, 0]));
            let want = Fault {
                reason: FaultReason::BadCommand,
                detail: motor,
            };
            assert_eq!(out.new_fault, Some(want), "{currents_a:?}");
            assert_eq!(out.state, State::Fault(FaultReason::BadCommand));
            assert_eq!(out.currents_a, [0.0; 3]);
        }
        // Within the limits (the limit itself included) it is driven as given.
        let mut lp = homed(&bank);
        let ok = [0.5, -2.0, 2.0];
        lp.set_mode(Mode::ConstantCurrent { currents_a: ok })
            .unwrap();
        lp.arm().unwrap();
        let out = lp.tick(input([0, 0, 0]));
        assert_eq!((out.state, out.currents_a), (State::Armed, ok));
    }

    /// `SetMode` while armed is refused (the mode stays) and reported as a latched
    /// `BadCommand` (detail 3): a mode change under the user's hand, e.g. from rendering to
    /// constant currents, would bypass what the user was feeling.
    #[test]
    fn set_mode_while_armed_is_refused_and_reported() {
        let bytes = flat_patch();
        let bank = Bank::parse(bytes.as_slice()).unwrap();
        let mut lp = homed(&bank);
        lp.arm().unwrap();
        assert_eq!(lp.tick(input([0, 0, 0])).state, State::Armed);
        let want = Fault {
            reason: FaultReason::BadCommand,
            detail: BAD_COMMAND_SET_MODE_ARMED,
        };
        assert_eq!(
            lp.set_mode(Mode::ConstantCurrent {
                currents_a: [1.0; 3]
            }),
            Err(want)
        );
        assert_eq!(lp.mode(), Mode::Render);
        let out = lp.tick(input([0, 0, 0]));
        assert_eq!(
            (out.state, out.currents_a),
            (State::Fault(FaultReason::BadCommand), [0.0; 3])
        );
        // Reported by the refusal, not again by the tick.
        assert_eq!(out.new_fault, None);
        assert_eq!(out.fault, Some(want));
        // Disarmed (after clearing), the mode can be set.
        assert!(lp.clear_fault());
        assert_eq!(lp.set_mode(Mode::Transparent), Ok(()));
        assert_eq!(lp.mode(), Mode::Transparent);
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
        let bank = Bank::parse(bytes.as_slice()).unwrap();
        assert!(bank.device().tip_radius_m >= 0.003);
        let mut lp = homed(&bank);
        lp.set_mode(Mode::LinearLaw).unwrap();
        lp.arm().unwrap();
        let dev = *lp.device();
        ramped_in(&mut lp, counts_for_insertion(&dev, 0.099));
        let (mut capped, mut touching, mut first) = (0, 0, 0);
        for t in 0..=80 {
            let out = lp.tick(input(counts_for_insertion(
                &dev,
                0.099 + 0.03e-3 * t as f32,
            )));
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

    /// A 5 cm strike in one tick, from 2 cm above the patch to 3 cm into it. With the default
    /// thresholds it is an encoder jump: checked before any geometry, so the glitch is not
    /// swept for contacts (before, detection ran along the whole jump and found the surface).
    /// With the jump check relaxed, a 50 m/s move, over the 1 m/s overspeed threshold: only
    /// the last 1 mm of it is swept (`contact::path_tail`), under the surface, so no contact;
    /// `Overspeed`, zero current. With the overspeed check relaxed too, the sweep is still cut
    /// to `MAX_DETECT_PIECES` cells' pieces: the bank and the motion cannot lengthen the
    /// detection; a 12 mm strike through the surface, within that cap (13.4 mm), is found and
    /// rendered.
    #[test]
    fn strike_in_one_tick() {
        let bytes = flat_patch();
        let bank = Bank::parse(bytes.as_slice()).unwrap();
        let cal = patch_device();
        // Default thresholds: 5 cm in 1 ms is an encoder jump -> fault, zero current, no
        // contact.
        let mut lp = homed(&bank);
        lp.arm().unwrap();
        let dev = *lp.device();
        check(&lp.tick(input(counts_for_insertion(&dev, 0.08))), &cal);
        let out = lp.tick(input(counts_for_insertion(&dev, 0.13)));
        check(&out, &cal);
        assert_eq!(out.contact, ContactState::Free);
        assert_eq!(out.state, State::Fault(FaultReason::EncoderJump));
        assert_eq!(out.new_fault.unwrap().detail, 2);
        assert_eq!((out.currents_a, out.tool_force_n), ([0.0; 3], [0.0; 3]));
        // Held there, the tip is under the surface untracked: no contact, no force.
        let out = lp.tick(input(counts_for_insertion(&dev, 0.13)));
        assert_eq!(
            (out.contact, out.currents_a),
            (ContactState::Free, [0.0; 3])
        );

        // With the jump check relaxed, it is what it would physically be, a 50 m/s strike: the
        // tip's overspeed (threshold 1 m/s), zero current; only its last millimetre is swept.
        let mut config = SafetyConfig::new(&cal);
        config.max_counts_per_tick = [u32::MAX; 3];
        let mut lp = homed_with(&bank, config);
        lp.arm().unwrap();
        check(&lp.tick(input(counts_for_insertion(&dev, 0.08))), &cal);
        let out = lp.tick(input(counts_for_insertion(&dev, 0.13)));
        check(&out, &cal);
        assert_eq!(out.contact, ContactState::Free);
        assert_eq!(out.state, State::Fault(FaultReason::Overspeed));
        assert_eq!(out.new_fault.unwrap().detail, 3);
        assert_eq!(out.currents_a, [0.0; 3]);

        // With the overspeed check relaxed too: the sweep is cut to three pieces of the 10 mm
        // grid (13 mm), all under the surface here, so still no contact.
        config.max_tip_speed_m_s = f32::INFINITY;
        config.max_joint_speed = [f32::INFINITY; 3];
        let mut lp = homed_with(&bank, config);
        assert!((lp.max_path_m - 0.99 * 3.0 * 0.45 * 0.01).abs() < 1e-6);
        lp.arm().unwrap();
        check(&ramped_in(&mut lp, counts_for_insertion(&dev, 0.08)), &cal);
        let out = lp.tick(input(counts_for_insertion(&dev, 0.13)));
        assert_eq!((out.contact, out.state), (ContactState::Free, State::Armed));
        // A 12 mm strike through the surface, within the cap, is found and rendered.
        let mut lp = homed_with(&bank, config);
        lp.arm().unwrap();
        check(&ramped_in(&mut lp, counts_for_insertion(&dev, 0.095)), &cal);
        let out = lp.tick(input(counts_for_insertion(&dev, 0.107)));
        check(&out, &cal);
        assert!(matches!(out.contact, ContactState::Touching { .. }));
        assert_eq!(out.tool_force_n, [0.0; 3]);
        let out = lp.tick(input(counts_for_insertion(&dev, 0.107)));
        check(&out, &cal);
        assert_eq!(out.state, State::Armed, "{out:?}");
        assert!(out.tool_force_n[2] > 0.5, "{out:?}");
        assert!(out.currents_a[2] < 0.0);
    }

    /// The tip pressed into the patch and rendering, then driven down 1.2 mm in one tick
    /// (1.2 m/s, over the bank's 1 m/s but no encoder jump): `Overspeed` at the tip, zero current
    /// from that tick on, reported once; explicit clear and arm render again.
    #[test]
    fn overspeed_at_the_tip_zeroes_the_currents_from_that_tick_on() {
        let bytes = flat_patch();
        let bank = Bank::parse(bytes.as_slice()).unwrap();
        let cal = patch_device();
        assert_eq!(cal.max_tip_speed_m_s, 1.0);
        let mut lp = homed(&bank);
        lp.arm().unwrap();
        let dev = *lp.device();
        // 0.5 m/s down to 3 mm deep: fast, but under the threshold.
        let mut s = 0.095;
        while s < 0.103 {
            s += 0.5e-3;
            let out = lp.tick(input(counts_for_insertion(&dev, s)));
            check(&out, &cal);
            assert_eq!(out.state, State::Armed, "{out:?}");
        }
        let pressed = lp.tick(input(counts_for_insertion(&dev, s)));
        assert!(pressed.currents_a[2] < 0.0, "{pressed:?}");
        let out = lp.tick(input(counts_for_insertion(&dev, s + 1.2e-3)));
        check(&out, &cal);
        assert_eq!(out.state, State::Fault(FaultReason::Overspeed));
        assert_eq!(
            out.new_fault,
            Some(Fault {
                reason: FaultReason::Overspeed,
                detail: 3
            })
        );
        assert_eq!(out.currents_a, [0.0; 3]);
        // Still pressed, force computed, but nothing driven and nothing reported again.
        for k in 0..50 {
            let out = lp.tick(input(counts_for_insertion(
                &dev,
                s + 1.2e-3 - 1e-5 * k as f32,
            )));
            assert!(out.tool_force_n[2] > 0.0, "{out:?}");
            assert_eq!((out.currents_a, out.new_fault), ([0.0; 3], None));
            assert_eq!(out.fault.map(|f| f.reason), Some(FaultReason::Overspeed));
        }
        assert_eq!(lp.telemetry().fault, Some(FaultReason::Overspeed));
        assert!(lp.arm().is_err(), "re-arming needs the fault cleared first");
        assert!(lp.clear_fault());
        lp.arm().unwrap();
        let out = lp.tick(input(counts_for_insertion(&dev, s)));
        assert_eq!(out.state, State::Armed);
        assert!(out.currents_a[2] < 0.0, "{out:?}");
    }

    /// A fast pitch close to the fulcrum: 15 rad/s (threshold 10) moves the tip only 0.75 m/s,
    /// so the joint's own threshold trips (detail 0); the constant currents stop that tick.
    #[test]
    fn overspeed_of_a_joint_near_the_fulcrum() {
        let bytes = flat_patch();
        let bank = Bank::parse(bytes.as_slice()).unwrap();
        let cal = patch_device();
        let mut lp = homed(&bank);
        let per_rad = 1.0 / lp.device().joint_per_count()[0];
        lp.set_mode(Mode::ConstantCurrent {
            currents_a: [0.5, 0.5, 0.5],
        })
        .unwrap();
        lp.arm().unwrap();
        let pitch_counts = |q: f32| [(q * per_rad).round() as i32, 0, 0];
        // 5 rad/s for 20 ticks (0.25 m/s at the tip, 5 cm from the fulcrum).
        let mut q = 0.0f32;
        for _ in 0..20 {
            q += 0.005;
            let out = lp.tick(input(pitch_counts(q)));
            assert_eq!(out.currents_a, [0.5, 0.5, 0.5], "{out:?}");
        }
        q += 0.015;
        let out = lp.tick(input(pitch_counts(q)));
        check(&out, &cal);
        assert_eq!(
            out.new_fault,
            Some(Fault {
                reason: FaultReason::Overspeed,
                detail: 0
            })
        );
        assert_eq!(out.currents_a, [0.0; 3]);
        assert_eq!(lp.tick(input(pitch_counts(q))).currents_a, [0.0; 3]);
    }

    #[test]
    fn disarmed_gives_zero_current() {
        let bytes = flat_patch();
        let bank = Bank::parse(bytes.as_slice()).unwrap();
        let cal = patch_device();
        let mut lp = homed(&bank);
        let dev = *lp.device();
        for t in 0..200 {
            let out = lp.tick(LoopInput {
                encoder_counts: counts_for_insertion(&dev, 0.095 + 0.05e-3 * t as f32),
                overrun: false,
                // No host at all: not a fault while disarmed.
                link_silence_ticks: t,
                interlocks: Interlocks::default(),
            });
            check(&out, &cal);
            assert_eq!(out.state, State::Disarmed);
            assert_eq!(out.currents_a, [0.0; 3]);
        }
        // Pressed 5 mm: a force is computed but not applied.
        assert_eq!(lp.telemetry().contacts.len(), 7);
        assert_eq!(lp.telemetry().currents_a, [0.0; 3]);
        // Arm, then disarm: zero again.
        lp.arm().unwrap();
        let s = counts_for_insertion(&dev, 0.105);
        assert!(lp.tick(input(s)).currents_a[2] < 0.0);
        assert!(lp.disarm());
        assert_eq!(lp.tick(input(s)).currents_a, [0.0; 3]);
    }

    #[test]
    fn link_silence_faults() {
        let bytes = flat_patch();
        let bank = Bank::parse(bytes.as_slice()).unwrap();
        let mut lp = homed(&bank);
        lp.arm().unwrap();
        let dev = *lp.device();
        for t in 0..=100 {
            lp.tick(input(counts_for_insertion(
                &dev,
                0.098 + 0.05e-3 * t as f32,
            )));
        }
        let s = counts_for_insertion(&dev, 0.103);
        for silent in 0..=10 {
            let out = lp.tick(LoopInput {
                link_silence_ticks: silent,
                ..input(s)
            });
            assert_eq!(out.state, State::Armed);
            assert!(out.currents_a[2] < 0.0);
        }
        let out = lp.tick(LoopInput {
            link_silence_ticks: 11,
            ..input(s)
        });
        assert_eq!(out.state, State::Fault(FaultReason::LinkSilent));
        assert_eq!(out.new_fault.unwrap().reason, FaultReason::LinkSilent);
        assert_eq!(out.currents_a, [0.0; 3]);
        assert_eq!(lp.telemetry().fault, Some(FaultReason::LinkSilent));
        assert_eq!(lp.telemetry().state, bank_format::State::Fault);
        // Latched until cleared; then disarmed, and arming works again.
        assert_eq!(lp.tick(input(s)).currents_a, [0.0; 3]);
        assert_eq!(lp.tick(input(s)).new_fault, None);
        assert!(lp.clear_fault());
        assert_eq!(lp.tick(input(s)).state, State::Disarmed);
        lp.arm().unwrap();
        assert!(lp.tick(input(s)).currents_a[2] < 0.0);
    }

    #[test]
    fn encoder_jump_faults() {
        let bytes = flat_patch();
        let bank = Bank::parse(bytes.as_slice()).unwrap();
        let cal = patch_device();
        let mut lp = homed(&bank);
        lp.arm().unwrap();
        lp.tick(input([0, 0, 0]));
        let out = lp.tick(input([i32::MAX, i32::MIN, 0]));
        check(&out, &cal);
        assert_eq!(out.state, State::Fault(FaultReason::EncoderJump));
        assert_eq!(out.currents_a, [0.0; 3]);
        let out = lp.tick(input([0, 0, 0]));
        assert_eq!(out.currents_a, [0.0; 3]);
    }

    #[test]
    fn overrun_faults() {
        let bytes = flat_patch();
        let bank = Bank::parse(bytes.as_slice()).unwrap();
        let mut lp = homed(&bank);
        lp.arm().unwrap();
        let dev = *lp.device();
        let s = counts_for_insertion(&dev, 0.103);
        lp.tick(input(s));
        let out = lp.tick(LoopInput {
            overrun: true,
            ..input(s)
        });
        assert_eq!(out.state, State::Fault(FaultReason::Overrun));
        assert_eq!(out.currents_a, [0.0; 3]);
        assert_eq!(lp.counters().overruns, 1);
        assert_eq!(lp.telemetry().counters.overruns, 1);
    }

    #[test]
    fn zero_encoders_rebases() {
        let bytes = flat_patch();
        let bank = Bank::parse(bytes.as_slice()).unwrap();
        let mut lp = homed(&bank);
        lp.tick(input([100_000, 0, 5]));
        lp.arm().unwrap();
        assert!(!lp.zero_encoders(), "refused while armed");
        lp.disarm();
        assert!(lp.zero_encoders());
        // The same raw counts are now the home pose, and the re-zero is not a jump.
        let out = lp.tick(input([100_000, 0, 5]));
        assert_eq!(out.state, State::Disarmed);
        let home = lp
            .device()
            .tip(&Joints::from_array(patch_device().home_joint));
        assert_eq!(out.tip_m, home);
    }

    #[test]
    fn solve_failure_faults_with_zero_current() {
        // Every pair of nodes has an SPD 6 x 6 compliance (what the bank checks), but the
        // triangle's 9 x 9 `C_SS` (kernel [[1, -a, -a], [-a, 1, -a], [-a, -a, 1]], a = 0.6) is
        // indefinite: at the centroid `B C_SS B^T` is negative definite and the solve fails.
        let p = std::vec![[0.0, 0.0, 0.0], [0.01, 0.0, 0.0], [0.0, 0.01, 0.0]];
        let c = 1.0e-3;
        let diag = |v: f64| {
            core::array::from_fn(|i| core::array::from_fn(|j| if i == j { v } else { 0.0 }))
        };
        let b = BankBuilder {
            c_kk: std::vec![diag(c); 3],
            couplings: std::vec![
                (0, 1, diag(-0.6 * c)),
                (0, 2, diag(-0.6 * c)),
                (1, 2, diag(-0.6 * c)),
            ],
            mesh_ids: std::vec![0, 1, 2],
            triangles: std::vec![[0, 1, 2]],
            positions_m: p,
            grid_cell_size_m: 0.005,
            truncation_radius_m: 0.005,
            scene_id: 1,
            law: TissueLaw::chebyshev(&[2.6, 2.5, -0.1], [0.0, 5.0]).unwrap(),
            gravity: None,
            relaxation: None,
            samples: None,
            device: DeviceCalibration {
                fulcrum_m: [0.01 / 3.0, 0.01 / 3.0, 0.1],
                ..patch_device()
            },
        };
        let bytes = AlignedBytes::new(&b.build().unwrap());
        let bank = Bank::parse(bytes.as_slice()).unwrap();
        let cal = bank.device();
        let mut lp = homed(&bank);
        lp.arm().unwrap();
        let dev = *lp.device();
        let mut fault = None;
        for t in 0..=100 {
            let out = lp.tick(input(counts_for_insertion(
                &dev,
                0.098 + 0.04e-3 * t as f32,
            )));
            check(&out, cal);
            if matches!(out.contact, ContactState::Touching { .. }) {
                assert_eq!(out.tool_force_n, [0.0; 3]);
                assert_eq!(out.currents_a, [0.0; 3]);
                assert!(out.contact_nodes == 0);
                fault = fault.or(out.new_fault.map(|f| (f, out.solve_error)));
            }
        }
        let (f, e) = fault.expect("the press must fault");
        assert_eq!(f.reason, FaultReason::SolveFailed);
        assert!(
            matches!(
                e,
                Some(SolveError::NotPositiveDefinite | SolveError::IllConditioned { .. })
            ),
            "{e:?}"
        );
        assert_eq!(lp.telemetry().fault, Some(FaultReason::SolveFailed));
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
        let bank = Bank::parse(bytes.as_slice()).unwrap();
        assert!(bank.samples().is_none() && bank.device().tip_radius_m >= 0.003);
        let mut lp = homed(&bank);
        lp.arm().unwrap();
        let dev = *lp.device();
        let (mut touching, mut failed) = (0, 0);
        for t in 0..=600 {
            let mut counts = counts_for_insertion(&dev, 0.099 + 0.02e-3 * t.min(150) as f32);
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

    /// Presses and slides along the lattice's triangle edges never fault, at every lattice
    /// level a bank may have: the tip pressed (armed) onto points of the grid line x = 2 cm,
    /// which is the v1-v2 edge of a column of the patch's triangles and passes through their
    /// vertices, and slid along it at depth, renders `W(anchor)^-1 d` with the fixture's
    /// (linear, so exactly interpolated) `W` every contact tick, never `SolveFailed`.
    #[test]
    fn edge_and_vertex_contacts_render_at_every_lattice_level() {
        for level in 1..=bank_format::MAX_SAMPLE_LEVEL {
            let bytes = crate::fixtures::sampled_patch_at_level(level, crate::fixtures::sampled_w);
            let bank = Bank::parse(bytes.as_slice()).unwrap();
            let mut lp = homed(&bank);
            lp.set_mode(Mode::LinearLaw).unwrap();
            lp.tick(input([0; 3]));
            lp.arm().unwrap();
            let dev = *lp.device();
            // Tip at x = 2 cm + dx (yaw), y (pitch), insertion s; straight moves between
            // waypoints, 20 um a tick at most.
            let counts = |[dx, y, s]: [f32; 3]| {
                let mut c = counts_for_insertion(&dev, s);
                c[0] = ((y - 0.02) / 0.1 / dev.joint_per_count()[0]).round() as i32;
                c[1] = (-dx / 0.1 / dev.joint_per_count()[1]).round() as i32;
                c
            };
            let mut waypoints: Vec<[f32; 3]> = std::vec![[0.0, 0.02, 0.05]];
            // Presses 3 mm deep at vertices (y = 1, 2, 3 cm) of the grid line x = 2 cm, the
            // v1-v2 edge of a column of triangles, and between them on it.
            for y in [0.01, 0.0125, 0.02, 0.0233, 0.03, 0.0351] {
                waypoints.extend([[0.0, y, 0.097], [0.0, y, 0.103], [0.0, y, 0.097]]);
            }
            // A slide along that edge at 3 mm depth, through the vertices; then along the
            // patch's sides x = 0 and x = 4 cm (the latter the v1-v2 edges of its column of
            // triangles) with the tip 1 mm beyond, so that the anchor is held on the boundary.
            waypoints.extend([
                [0.0, 0.005, 0.097],
                [0.0, 0.005, 0.103],
                [0.0, 0.035, 0.103],
            ]);
            for dx in [-0.021, 0.021] {
                waypoints.extend([
                    [0.0, 0.035, 0.097],
                    [dx, 0.035, 0.097],
                    [dx, 0.035, 0.103],
                    [dx, 0.005, 0.103],
                    [dx, 0.005, 0.097],
                    [0.0, 0.005, 0.097],
                ]);
            }
            let mut contact_ticks = 0;
            for pair in waypoints.windows(2) {
                let (a, b) = (pair[0], pair[1]);
                let len = (0..3).map(|i| (b[i] - a[i]).abs()).fold(0.0, f32::max);
                let n = (len / 20e-6).ceil().max(1.0) as u32;
                for k in 1..=n {
                    let f = k as f32 / n as f32;
                    let out = lp.tick(input(counts(core::array::from_fn(|i| {
                        a[i] + f * (b[i] - a[i])
                    }))));
                    assert_eq!(
                        (out.state, out.new_fault, out.solve_error),
                        (State::Armed, None, None),
                        "level {level}: {out:?}"
                    );
                    let ContactState::Touching {
                        anchor,
                        displacement,
                        ..
                    } = out.contact
                    else {
                        continue;
                    };
                    if out.contact_nodes == 0 {
                        continue;
                    }
                    let w = crate::fixtures::sampled_w(anchor.map(f64::from));
                    let want = crate::fixtures::gauss(
                        w.iter().map(|r| r.to_vec()).collect(),
                        displacement.iter().map(|&v| f64::from(v)).collect(),
                    );
                    let got = out.tool_force_n.map(|f| -f);
                    let err = crate::fixtures::rel_err(&[got], &want);
                    assert!(err < 1e-4, "level {level}: {got:?} vs {want:?}");
                    contact_ticks += 1;
                }
            }
            assert!(contact_ticks > 3_000, "level {level}: {contact_ticks}");
        }
    }

    /// What the reader accepts, the tick can factor (`bank_format::MIN_PIVOT_REL`, one margin
    /// for both): a sampled bank whose `W` is SPD everywhere but, for y < 2 cm, too
    /// ill-conditioned for the tick's solve (pivot ratio 1e-6) is refused at parse, naming a
    /// triangle there and its sample; with the ratio at 2.5e-5 (within the reader's margin)
    /// presses and a slide over that side, armed, never fault and render `W^-1 d`.
    #[test]
    fn a_sampled_bank_the_reader_accepts_never_fails_the_solve() {
        let patch = |zz: f64| {
            crate::fixtures::sampled_patch_builder(2, move |x| {
                let zz = if x[1] < 0.02 { zz } else { 0.1 };
                [[0.05, 0.0, 0.0], [0.0, 0.05, 0.0], [0.0, 0.0, 0.05 * zz]]
            })
            .build()
        };
        // The first triangle (cell (0, 0)) is refused; its samples are all ill-conditioned.
        let refused = patch(1.0e-6).map(|_| ());
        assert!(
            matches!(
                refused,
                Err(bank_format::BuildError::Rejected(
                    bank_format::BankError::SampleIllConditioned { triangle: 0, .. }
                ))
            ),
            "{refused:?}"
        );
        let bytes = AlignedBytes::new(&patch(2.5e-5).unwrap());
        let bank = Bank::parse(bytes.as_slice()).unwrap();
        let mut lp = homed(&bank);
        lp.set_mode(Mode::LinearLaw).unwrap();
        lp.tick(input([0; 3]));
        lp.arm().unwrap();
        let dev = *lp.device();
        // The fulcrum is 10 cm above the patch's centre (y = 2 cm): pitch moves the tip along
        // y, about 0.1 m per rad.
        let at = |y: f32, s: f32| {
            let mut c = counts_for_insertion(&dev, s);
            c[0] = ((y - 0.02) / 0.1 / dev.joint_per_count()[0]).round() as i32;
            c
        };
        // Down from home to 3 mm above the patch, over to y = 1.2 cm, in, and a slide.
        let mut path: Vec<[i32; 3]> = (0..=2_350)
            .map(|t| at(0.02, 0.05 + 20.0e-6 * t as f32))
            .collect();
        path.extend((0..=400).map(|t| {
            at(
                0.012 * (t as f32 / 400.0) + 0.02 * (1.0 - t as f32 / 400.0),
                0.097,
            )
        }));
        path.extend((0..=120).map(|t| at(0.012, 0.097 + 0.05e-3 * t as f32)));
        path.extend((0..=900).map(|t| at(0.012 + 20.0e-6 * t as f32, 0.103)));
        let mut pressed = 0;
        for (t, &counts) in path.iter().enumerate() {
            let out = lp.tick(input(counts));
            assert_eq!(
                (out.state, out.new_fault, out.solve_error),
                (State::Armed, None, None),
                "{t}: {out:?}"
            );
            if out.contact_nodes > 0 && out.tool_force_n[2] > 0.0 {
                pressed += 1;
            }
        }
        assert!(pressed > 900, "{pressed}");
    }

    /// A 3-node bank far below the tool (no contact ever), with or without gravity.
    fn gravity_bank(gravity: Option<bank_format::GravityCompensation>) -> AlignedBytes {
        let c = 1.0e-3;
        let diag = |v: f64| {
            core::array::from_fn(|i| core::array::from_fn(|j| if i == j { v } else { 0.0 }))
        };
        let b = BankBuilder {
            c_kk: std::vec![diag(c); 3],
            couplings: std::vec![
                (0, 1, diag(0.1 * c)),
                (0, 2, diag(0.1 * c)),
                (1, 2, diag(0.1 * c))
            ],
            mesh_ids: std::vec![0, 1, 2],
            triangles: std::vec![[0, 1, 2]],
            positions_m: std::vec![[0.0, 0.0, 0.0], [0.01, 0.0, 0.0], [0.0, 0.01, 0.0]],
            grid_cell_size_m: 0.005,
            truncation_radius_m: 0.005,
            scene_id: 3,
            law: TissueLaw::linear(0.0, 1.0, [0.0, 5.0]).unwrap(),
            gravity,
            relaxation: None,
            samples: None,
            device: crate::fixtures::bench_device([0.0, 0.0, 0.3]),
        };
        AlignedBytes::new(&b.build().unwrap())
    }

    /// The tick adds exactly `tau_g(q)` (`SPEC.md` "gravity"), written out here in f64 from
    /// the potential's gradient, before the current mapping `i = tau / (transmission Kt)`:
    /// armed, no contact, in `Render` and `Transparent`; not in `ConstantCurrent`; and a bank
    /// without the section gives zero current away from the tissue.
    #[test]
    fn the_tick_adds_the_gravity_feed_forward() {
        let coeffs = [0.05f32, -0.02, 0.03, 0.4, 0.1, -0.3, 0.02, -0.01];
        let g = bank_format::GravityCompensation { coeffs };
        let with = gravity_bank(Some(g));
        let without = gravity_bank(None);
        let bank = Bank::parse(with.as_slice()).unwrap();
        let plain = Bank::parse(without.as_slice()).unwrap();
        assert_eq!(bank.gravity(), Some(&g));
        assert_eq!(plain.gravity(), None);
        let cal = *bank.device();
        let counts = [2000, -1500, 300];
        for mode in [Mode::Render, Mode::Transparent] {
            let mut lp = homed(&bank);
            lp.set_mode(mode).unwrap();
            lp.arm().unwrap();
            let q = lp.device().joints(counts);
            let out = ramped_in(&mut lp, counts);
            assert_eq!((out.state, out.contact), (State::Armed, ContactState::Free));
            // Hand-written tau_g = dV/dq in f64.
            let c = coeffs.map(f64::from);
            let (p, y, s) = (f64::from(q.pitch), f64::from(q.yaw), f64::from(q.insertion));
            let (sp, cp, sy, cy) = (p.sin(), p.cos(), y.sin(), y.cos());
            let (mc, ms, mp) = (c[0] + s * c[3], c[1] + s * c[4], c[2] + s * c[5]);
            let tau = [
                mc * sp * cy + ms * sp * sy - mp * cp,
                mc * cp * sy - ms * cp * cy + c[6] * sy - c[7] * cy,
                -(c[3] * cp * cy + c[4] * cp * sy + c[5] * sp),
            ];
            for j in 0..3 {
                let want = tau[j]
                    / (f64::from(cal.transmission[j]) * f64::from(cal.torque_constant_nm_per_a[j]));
                assert!(want.abs() > 0.01 && want.abs() < f64::from(cal.current_limit_a[j]));
                let got = f64::from(out.currents_a[j]);
                assert!(
                    (got - want).abs() <= 1e-5 * want.abs().max(1.0),
                    "{mode:?} {j}: {got} vs {want}"
                );
            }
        }
        let mut lp = homed(&bank);
        let currents_a = [0.1, -0.2, 0.3];
        lp.set_mode(Mode::ConstantCurrent { currents_a }).unwrap();
        lp.arm().unwrap();
        assert_eq!(lp.tick(input(counts)).currents_a, currents_a);
        let mut lp = homed(&plain);
        lp.arm().unwrap();
        assert_eq!(lp.tick(input(counts)).currents_a, [0.0; 3]);
    }
}
