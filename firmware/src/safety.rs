//! The safety supervisor: part of every tick, it decides which motor currents are applied.
//!
//! States: [`State::Disarmed`] (zero current, waiting for an arm command), [`State::Armed`] (the
//! loop drives the motors) and [`State::Fault`] (zero current, the reason kept until the host
//! clears it). Every fault path ends at zero current with its [`FaultReason`] and a detail
//! (bank error code, joint or motor index, 3 for the tool tip, else 0); a fault is latched: the
//! first reason stays, later ones do not overwrite it, and the state leaves `Fault` only on
//! [`Supervisor::clear_fault`] (to `Disarmed`, never straight to `Armed`: re-arming is an
//! explicit `Arm` after it).
//!
//! Checks per tick ([`Supervisor::tick`]), in this order (the first failing one is reported):
//!
//! | check | reason | detail | in |
//! | --- | --- | --- | --- |
//! | the emergency stop is pressed (or its loop open) | `EStop` | 0 | Disarmed, Armed |
//! | an amplifier reports a fault (lowest motor first) | `AmplifierFault` | motor | Disarmed, Armed |
//! | bank failed validation | `InvalidBank` | `BankError::code()` | Disarmed, Armed |
//! | the previous tick overran | `Overrun` | 0 | Armed |
//! | no valid host frame for more than `link_timeout_ticks` ticks | `LinkSilent` | ticks | Armed |
//! | an encoder moved more than `max_counts_per_tick` since the last tick | `EncoderJump` | joint | Disarmed, Armed |
//! | a host's `ConstantCurrent` current not finite or over its limit | `BadCommand` | motor | Disarmed, Armed |
//! | NaN or infinity in joints, tip, force or requested currents | `Nan` | 0 | Disarmed, Armed |
//! | the contact solve failed | `SolveFailed` | 0 | Disarmed, Armed |
//! | the tip moved faster than `max_tip_speed_m_s` over the last tick | `Overspeed` | 3 | Armed |
//! | a joint moved faster than its `max_joint_speed` over the last tick | `Overspeed` | joint | Armed |
//! | a joint outside its range by more than `joint_limit_margin` | `JointLimit` | joint | Armed |
//! | a requested current over `current_fault_ratio` x its limit | `CurrentLimit` | motor | Armed |
//!
//! **Interlocks first**: the hardware says stop, whatever else is wrong. They are checked in
//! every state, so a pressed e-stop also latches while disarmed, and [`Supervisor::arm`] is
//! refused while the interlocks the last tick read are active (one pressed since is caught by
//! the next tick's check, before any current is driven).
//!
//! Link silence, overruns, overspeed, joint and current limits only matter while the motors are
//! driven, so they are checked only when armed: a device waiting for its host on boot does not
//! fault.
//!
//! **Overspeed and encoder jumps.** As on Force Dimension's controllers, above a programmed
//! speed the forces are disabled: the bank's [`DeviceCalibration::max_tip_speed_m_s`] and
//! [`DeviceCalibration::max_joint_speed`] (the scene's choice) against the change of the
//! forward-kinematics tip and of the joints over one tick ([`SafetyConfig::tick_s`]). The tip
//! is checked first (detail 3), then the joints (detail = joint). `EncoderJump` is a separate
//! check for what no hand can do, a counter glitch or miscount, in counts per tick from
//! [`DEFAULT_JUMP_SPEED`]; its limit must stay above the overspeed thresholds, so that a fast
//! but real move is reported as `Overspeed` and only a glitch as `EncoderJump` (the host's
//! scene parser refuses joint thresholds at or above it).
//!
//! **Current limit: clamp or fault.** The loop caps the tip force at `max_force_n` before
//! `J^T`, so a correct calibration asks for at most about the limit; a request somewhat over it
//! (up to `current_fault_ratio`, default 1.25) is clamped to the limit and reported in
//! [`Output::clamped`]. A request beyond that means a wrong calibration, a diverging solve or a
//! bad host command, so it is a `CurrentLimit` fault and the motors go to zero and the fault
//! is reported. A host's
//! `ConstantCurrent` command ([`TickInput::host_currents`]) has no such tolerance: it reaches
//! the supervisor unclamped, and any current over its limit, or not finite, is a `BadCommand`
//! fault naming the motor.

use crate::device::clamp_symmetric;
use crate::hal::Interlocks;
use crate::vec3::dist2;
use bank_format::{DeviceCalibration, FaultReason};
use core::f32::consts::PI;

/// The supervisor's state.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum State {
    /// Zero current; waiting for an arm command.
    Disarmed,
    /// The loop drives the motors.
    Armed,
    /// Zero current until the fault is cleared; the first reason is kept.
    Fault(FaultReason),
}

impl State {
    /// The state as the link reports it (telemetry's `state`).
    pub fn wire(self) -> bank_format::State {
        match self {
            State::Disarmed => bank_format::State::Disarmed,
            State::Armed => bank_format::State::Armed,
            State::Fault(_) => bank_format::State::Fault,
        }
    }

    /// The fault reason, if any.
    pub fn fault(self) -> Option<FaultReason> {
        match self {
            State::Fault(r) => Some(r),
            _ => None,
        }
    }
}

/// A fault and its detail (for the link's `Fault { tick, reason, detail }`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Fault {
    /// Why.
    pub reason: FaultReason,
    /// Bank error code, joint or motor index, ticks of link silence; else 0.
    pub detail: u32,
}

/// Default encoder-jump speeds for [`SafetyConfig::from_calibration`]: rad/s, rad/s, m/s (far
/// above what a hand does; an encoder glitch or a miscount is much faster). They must stay
/// above the bank's overspeed thresholds (see the module notes).
pub const DEFAULT_JUMP_SPEED: [f32; 3] = [20.0, 20.0, 2.0];
/// Default ratio of requested current to limit beyond which clamping becomes a fault.
pub const DEFAULT_CURRENT_FAULT_RATIO: f32 = 1.25;
/// Default tolerance outside the calibrated joint ranges: rad, rad, m.
pub const DEFAULT_JOINT_LIMIT_MARGIN: [f32; 3] = [0.05, 0.05, 0.005];

/// Thresholds of the supervisor.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SafetyConfig {
    /// Largest encoder change per tick, counts, per joint; more is an `EncoderJump`.
    pub max_counts_per_tick: [u32; 3],
    /// Ticks without a valid host frame tolerated while armed; more is `LinkSilent`.
    pub link_timeout_ticks: u32,
    /// A requested current with `|i| > current_fault_ratio * limit` is a `CurrentLimit` fault;
    /// `limit < |i| <=` that is clamped. Values below 1 are treated as 1.
    pub current_fault_ratio: f32,
    /// Current limits per motor, A.
    pub current_limit_a: [f32; 3],
    /// Lower joint limits (pitch rad, yaw rad, insertion m).
    pub joint_min: [f32; 3],
    /// Upper joint limits.
    pub joint_max: [f32; 3],
    /// Tolerance outside `[joint_min, joint_max]` before a `JointLimit` fault.
    pub joint_limit_margin: [f32; 3],
    /// Largest tip speed while armed, m/s; faster over one tick is an `Overspeed` (detail 3).
    pub max_tip_speed_m_s: f32,
    /// Largest joint speeds while armed: pitch rad/s, yaw rad/s, insertion m/s; faster over one
    /// tick is an `Overspeed` (detail = joint).
    pub max_joint_speed: [f32; 3],
    /// The tick period the speeds are measured over, s.
    pub tick_s: f32,
}

impl SafetyConfig {
    /// Thresholds from a calibration: `max_counts_per_tick = jump_speed * tick * counts_per_rev *
    /// |transmission| / (2 pi)` (at least 1), `link_timeout_ticks` the calibration's
    /// `link_timeout_ms` in ticks of `tick_s` (rounded; at least 1), the overspeed thresholds,
    /// joint and current limits from the calibration, with the defaults above for the rest.
    pub fn from_calibration(
        cal: &DeviceCalibration,
        jump_speed: [f32; 3],
        tick_s: f32,
    ) -> SafetyConfig {
        let max_counts_per_tick = core::array::from_fn(|j| {
            let cpr = cal.counts_per_rev.get(j).copied().unwrap_or(1) as f32;
            let t = cal.transmission.get(j).copied().unwrap_or(1.0);
            let v = jump_speed.get(j).copied().unwrap_or(0.0);
            // `as` saturates (NaN -> 0), never panics.
            let n = (v * tick_s * cpr * if t < 0.0 { -t } else { t } / (2.0 * PI)) as u32;
            n.max(1)
        });
        // `as` saturates (NaN -> 0), never panics.
        let link_timeout_ticks = (cal.link_timeout_ms as f32 * 1e-3 / tick_s + 0.5) as u32;
        SafetyConfig {
            max_counts_per_tick,
            link_timeout_ticks: link_timeout_ticks.max(1),
            current_fault_ratio: DEFAULT_CURRENT_FAULT_RATIO,
            current_limit_a: cal.current_limit_a,
            joint_min: cal.joint_min,
            joint_max: cal.joint_max,
            joint_limit_margin: DEFAULT_JOINT_LIMIT_MARGIN,
            max_tip_speed_m_s: cal.max_tip_speed_m_s,
            max_joint_speed: cal.max_joint_speed,
            tick_s,
        }
    }

    /// [`SafetyConfig::from_calibration`] with [`DEFAULT_JUMP_SPEED`] at [`crate::TICK_HZ`].
    pub fn new(cal: &DeviceCalibration) -> SafetyConfig {
        SafetyConfig::from_calibration(cal, DEFAULT_JUMP_SPEED, crate::TICK_PERIOD_S)
    }
}

/// What the loop measured and computed this tick.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TickInput {
    /// `None` when the bank is valid, else its `BankError::code()`.
    pub bank_error: Option<u32>,
    /// Raw encoder counts.
    pub counts: [i32; 3],
    /// Joint values computed from the counts (pitch rad, yaw rad, insertion m).
    pub joints: [f32; 3],
    /// The tool tip from the joints (forward kinematics), m.
    pub tip_m: [f32; 3],
    /// The force rendered (on the tool), N.
    pub force_n: [f32; 3],
    /// Motor currents requested before clamping, A.
    pub requested_a: [f32; 3],
    /// Whether `requested_a` is a host's `ConstantCurrent` command rather than the loop's
    /// `J^T F + tau_g(q)`: then a current that is not finite or over its limit is a `BadCommand` fault
    /// (never clamped), checked in every state.
    pub host_currents: bool,
    /// Whether the previous tick overran its period.
    pub overrun: bool,
    /// How long the host link has been silent, in ticks (the application's measure: since the
    /// last byte, or since the last valid frame less a grace for a garbled link).
    pub link_silence_ticks: u32,
    /// Whether the contact solve failed this tick.
    pub solve_failed: bool,
    /// The hardware interlock inputs read this tick.
    pub interlocks: Interlocks,
}

impl TickInput {
    /// A quiet tick: valid bank, everything zero, host just heard, no interlock active.
    pub const fn quiet() -> TickInput {
        TickInput {
            bank_error: None,
            counts: [0; 3],
            joints: [0.0; 3],
            tip_m: [0.0; 3],
            force_n: [0.0; 3],
            requested_a: [0.0; 3],
            host_currents: false,
            overrun: false,
            link_silence_ticks: 0,
            solve_failed: false,
            interlocks: Interlocks {
                estop: false,
                amplifier_fault: [false; 3],
            },
        }
    }
}

/// The interlock fault `interlocks` call for, if any: the e-stop first, then the lowest
/// faulted amplifier.
pub fn interlock_fault(interlocks: &Interlocks) -> Option<Fault> {
    if interlocks.estop {
        return Some(Fault {
            reason: FaultReason::EStop,
            detail: 0,
        });
    }
    (0..3u32)
        .zip(&interlocks.amplifier_fault)
        .find(|&(_, &f)| f)
        .map(|(motor, _)| Fault {
            reason: FaultReason::AmplifierFault,
            detail: motor,
        })
}

/// The supervisor's decision for a tick.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Output {
    /// State after this tick.
    pub state: State,
    /// Currents to write, A: zero unless armed and no fault this tick.
    pub currents_a: [f32; 3],
    /// Which motors were clamped to their limit (only when armed).
    pub clamped: [bool; 3],
    /// The fault raised this tick, if any (report it to the host once).
    pub new_fault: Option<Fault>,
}

/// Why an arm command was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ArmRefused {
    /// Arming is only possible from `Disarmed`; this is the current state.
    NotDisarmed(State),
    /// The bank failed validation.
    InvalidBank,
    /// A hardware interlock was active at the last tick (the fault it raises).
    Interlock(Fault),
    /// The encoders were not referenced since the chip started (no `ZeroEncoders` at the
    /// home pose): latched as [`FaultReason::NotReferenced`].
    NotReferenced,
}

/// What the last tick measured, for the encoder-jump and overspeed checks.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Previous {
    counts: [i32; 3],
    joints: [f32; 3],
    tip_m: [f32; 3],
}

/// The state machine.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Supervisor {
    config: SafetyConfig,
    state: State,
    detail: u32,
    previous: Option<Previous>,
    interlocks: Interlocks,
}

impl Supervisor {
    /// Disarmed, with no encoder history and no interlock seen.
    pub const fn new(config: SafetyConfig) -> Supervisor {
        Supervisor {
            config,
            state: State::Disarmed,
            detail: 0,
            previous: None,
            interlocks: TickInput::quiet().interlocks,
        }
    }

    /// The thresholds.
    pub fn config(&self) -> &SafetyConfig {
        &self.config
    }

    /// The current state.
    pub fn state(&self) -> State {
        self.state
    }

    /// The latched fault and its detail, if in `Fault`.
    pub fn fault(&self) -> Option<Fault> {
        self.state.fault().map(|reason| Fault {
            reason,
            detail: self.detail,
        })
    }

    /// Arm: only from `Disarmed`, with no interlock active at the last tick, with a valid
    /// bank and with the encoders `referenced` (homed since the chip started: the pose, the
    /// organ, the joint limits and the gravity feed-forward all rest on it). The last refusal
    /// latches [`FaultReason::NotReferenced`], so the host sees why in the fault report and in
    /// telemetry.
    pub fn arm(&mut self, bank_valid: bool, referenced: bool) -> Result<(), ArmRefused> {
        if self.state != State::Disarmed {
            return Err(ArmRefused::NotDisarmed(self.state));
        }
        if let Some(f) = interlock_fault(&self.interlocks) {
            return Err(ArmRefused::Interlock(f));
        }
        if !bank_valid {
            return Err(ArmRefused::InvalidBank);
        }
        if !referenced {
            self.raise(FaultReason::NotReferenced, 0);
            return Err(ArmRefused::NotReferenced);
        }
        self.state = State::Armed;
        Ok(())
    }

    /// Disarm: `Armed` -> `Disarmed`. A fault stays latched (clear it instead). Returns whether
    /// the state changed.
    pub fn disarm(&mut self) -> bool {
        if self.state == State::Armed {
            self.state = State::Disarmed;
            true
        } else {
            false
        }
    }

    /// Clear a fault: `Fault` -> `Disarmed`. Returns whether there was a fault. If the cause
    /// persists, a later tick faults again.
    pub fn clear_fault(&mut self) -> bool {
        if let State::Fault(_) = self.state {
            self.state = State::Disarmed;
            self.detail = 0;
            true
        } else {
            false
        }
    }

    /// Forget the encoder and motion history (after zeroing the encoders, so the reset is
    /// neither a jump nor a move).
    pub fn rebase_encoders(&mut self) {
        self.previous = None;
    }

    /// Enter `Fault` from any state (e.g. a fault found outside the tick's inputs). A latched
    /// fault is kept; returns whether this one was latched.
    pub fn raise(&mut self, reason: FaultReason, detail: u32) -> bool {
        if let State::Fault(_) = self.state {
            return false;
        }
        self.state = State::Fault(reason);
        self.detail = detail;
        true
    }

    /// The first joint whose encoder moved more than `max_counts_per_tick` since the last
    /// tick's `counts`, if any: what the tick's `EncoderJump` check finds. The loop asks before
    /// any geometry, so that a glitch is never swept for contacts.
    pub fn encoder_jump(&self, counts: &[i32; 3]) -> Option<u32> {
        let prev = self.previous.as_ref()?;
        (0..3u32)
            .zip(prev.counts.iter().zip(counts))
            .find(|(j, (p, n))| {
                let max = self.config.max_counts_per_tick.get(*j as usize);
                max.is_none_or(|&m| n.abs_diff(**p) > m)
            })
            .map(|(j, _)| j)
    }

    /// Run the checks for one tick and decide the currents (see the module notes).
    pub fn tick(&mut self, input: &TickInput) -> Output {
        let found = self.check(input);
        self.previous = Some(Previous {
            counts: input.counts,
            joints: input.joints,
            tip_m: input.tip_m,
        });
        self.interlocks = input.interlocks;
        let new_fault = found.filter(|f| self.raise(f.reason, f.detail));
        let mut out = Output {
            state: self.state,
            currents_a: [0.0; 3],
            clamped: [false; 3],
            new_fault,
        };
        if self.state == State::Armed {
            for (((a, c), &r), &lim) in out
                .currents_a
                .iter_mut()
                .zip(out.clamped.iter_mut())
                .zip(&input.requested_a)
                .zip(&self.config.current_limit_a)
            {
                (*a, *c) = clamp_symmetric(r, lim);
            }
        }
        out
    }

    fn check(&self, input: &TickInput) -> Option<Fault> {
        let armed = self.state == State::Armed;
        let fault = |reason, detail| Some(Fault { reason, detail });
        if let Some(f) = interlock_fault(&input.interlocks) {
            return Some(f);
        }
        if let Some(code) = input.bank_error {
            return fault(FaultReason::InvalidBank, code);
        }
        if armed && input.overrun {
            return fault(FaultReason::Overrun, 0);
        }
        if armed && input.link_silence_ticks > self.config.link_timeout_ticks {
            return fault(FaultReason::LinkSilent, input.link_silence_ticks);
        }
        if let Some(j) = self.encoder_jump(&input.counts) {
            return fault(FaultReason::EncoderJump, j);
        }
        if input.host_currents {
            // Written so that NaN (in the request or the limit) counts as over.
            let bad = (0..3u32)
                .zip(input.requested_a.iter().zip(&self.config.current_limit_a))
                .find(|(_, (i, lim))| !(i.is_finite() && i.abs() <= **lim));
            if let Some((motor, _)) = bad {
                return fault(FaultReason::BadCommand, motor);
            }
        }
        let finite = |v: &[f32; 3]| v.iter().all(|x| x.is_finite());
        if !(finite(&input.joints)
            && finite(&input.tip_m)
            && finite(&input.force_n)
            && finite(&input.requested_a))
        {
            return fault(FaultReason::Nan, 0);
        }
        if input.solve_failed {
            return fault(FaultReason::SolveFailed, 0);
        }
        if !armed {
            return None;
        }
        if let Some(detail) = self
            .previous
            .as_ref()
            .and_then(|p| self.overspeed(p, input))
        {
            return fault(FaultReason::Overspeed, detail);
        }
        let c = &self.config;
        for (j, (((&q, &lo), &hi), &m)) in (0..3u32).zip(
            input
                .joints
                .iter()
                .zip(&c.joint_min)
                .zip(&c.joint_max)
                .zip(&c.joint_limit_margin),
        ) {
            if !(q >= lo - m && q <= hi + m) {
                return fault(FaultReason::JointLimit, j);
            }
        }
        let ratio = if c.current_fault_ratio >= 1.0 {
            c.current_fault_ratio
        } else {
            1.0
        };
        for (j, (&i, &lim)) in (0..3u32).zip(input.requested_a.iter().zip(&c.current_limit_a)) {
            // Written so that NaN (in the request or the limit) counts as over.
            let within = matches!(
                i.abs().partial_cmp(&(ratio * lim)),
                Some(core::cmp::Ordering::Less | core::cmp::Ordering::Equal)
            );
            if !within {
                return fault(FaultReason::CurrentLimit, j);
            }
        }
        None
    }

    /// The overspeed check against the last tick: 3 when the tip moved more than
    /// `max_tip_speed_m_s * tick_s`, else the first joint that moved more than its
    /// `max_joint_speed * tick_s`. A non-finite previous value (a tick that faulted `Nan`)
    /// compares as no move.
    fn overspeed(&self, prev: &Previous, input: &TickInput) -> Option<u32> {
        let c = &self.config;
        let tip_step = c.max_tip_speed_m_s * c.tick_s;
        if dist2(prev.tip_m, input.tip_m) > tip_step * tip_step {
            return Some(3);
        }
        (0..3u32)
            .zip(
                prev.joints
                    .iter()
                    .zip(&input.joints)
                    .zip(&c.max_joint_speed),
            )
            .find(|(_, ((p, q), v))| (**q - **p).abs() > **v * c.tick_s)
            .map(|(j, _)| j)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::device::{Device, Joints};
    use crate::fixtures::liver_device;

    /// A plausible tick at encoder zero (home pose, inside the ranges).
    fn ok_tick() -> TickInput {
        TickInput {
            joints: liver_device().home_joint,
            requested_a: [0.5, -0.5, 1.0],
            ..TickInput::quiet()
        }
    }

    fn armed() -> Supervisor {
        armed_at(liver_device().home_joint)
    }

    /// Armed, the last tick at `joints` (reached while disarmed, so not an overspeed).
    fn armed_at(joints: [f32; 3]) -> Supervisor {
        let mut s = Supervisor::new(SafetyConfig::new(&liver_device()));
        let at = TickInput {
            joints,
            ..ok_tick()
        };
        assert_eq!(s.tick(&at).state, State::Disarmed);
        assert_eq!(s.arm(true, true), Ok(()));
        let out = s.tick(&at);
        assert_eq!(out.state, State::Armed);
        s
    }

    fn estop() -> Interlocks {
        Interlocks {
            estop: true,
            amplifier_fault: [false; 3],
        }
    }

    fn amplifier(motor: usize) -> Interlocks {
        let mut i = Interlocks::default();
        i.amplifier_fault[motor] = true;
        i
    }

    #[test]
    fn config_from_calibration() {
        let c = SafetyConfig::new(&liver_device());
        // 20 rad/s * 1 ms * 4096 * 12 / 2 pi = 156.4; 2 m/s * 1 ms * 4096 * 400 / 2 pi = 521.5.
        assert_eq!(c.max_counts_per_tick, [156, 156, 521]);
        assert_eq!(c.link_timeout_ticks, 10);
        assert_eq!(c.max_tip_speed_m_s, liver_device().max_tip_speed_m_s);
        assert_eq!(c.max_joint_speed, liver_device().max_joint_speed);
        assert_eq!(c.tick_s, crate::TICK_PERIOD_S);
        let c = SafetyConfig::from_calibration(&liver_device(), [0.0, f32::NAN, -1.0], 1e-3);
        assert_eq!(c.max_counts_per_tick, [1, 1, 1]);
    }

    #[test]
    fn arm_disarm_clear_transitions() {
        let mut s = Supervisor::new(SafetyConfig::new(&liver_device()));
        assert_eq!(s.state(), State::Disarmed);
        // Disarmed: zero current whatever is requested.
        let out = s.tick(&ok_tick());
        assert_eq!(
            (out.state, out.currents_a, out.new_fault),
            (State::Disarmed, [0.0; 3], None)
        );
        // Arm refused with an invalid bank.
        assert_eq!(s.arm(false, true), Err(ArmRefused::InvalidBank));
        assert_eq!(s.state(), State::Disarmed);
        // Disarmed -> Armed: the requested currents are applied.
        assert_eq!(s.arm(true, true), Ok(()));
        let out = s.tick(&ok_tick());
        assert_eq!(out.state, State::Armed);
        assert_eq!(out.currents_a, [0.5, -0.5, 1.0]);
        // Arm again: refused, still armed.
        assert_eq!(
            s.arm(true, true),
            Err(ArmRefused::NotDisarmed(State::Armed))
        );
        // Armed -> Disarmed.
        assert!(s.disarm());
        assert!(!s.disarm());
        assert_eq!(s.tick(&ok_tick()).currents_a, [0.0; 3]);
        // Clear without a fault does nothing.
        assert!(!s.clear_fault());
        // Armed -> Fault -> (disarm and arm refused) -> clear -> Disarmed -> Armed.
        s.arm(true, true).unwrap();
        let out = s.tick(&TickInput {
            overrun: true,
            ..ok_tick()
        });
        assert_eq!(out.state, State::Fault(FaultReason::Overrun));
        assert!(!s.disarm());
        assert_eq!(
            s.arm(true, true),
            Err(ArmRefused::NotDisarmed(State::Fault(FaultReason::Overrun)))
        );
        assert_eq!(s.state().wire(), bank_format::State::Fault);
        assert!(s.clear_fault());
        assert_eq!(s.state(), State::Disarmed);
        assert_eq!(s.fault(), None);
        assert_eq!(s.arm(true, true), Ok(()));
        assert_eq!(s.tick(&ok_tick()).currents_a, [0.5, -0.5, 1.0]);
        assert_eq!(s.state().wire(), bank_format::State::Armed);
    }

    /// Without a reference the arm is refused and `NotReferenced` latched (zero current);
    /// once referenced, cleared and armed again, the currents flow.
    #[test]
    fn arming_unreferenced_is_refused_and_latched() {
        let mut s = Supervisor::new(SafetyConfig::new(&liver_device()));
        s.tick(&ok_tick());
        assert_eq!(s.arm(true, false), Err(ArmRefused::NotReferenced));
        assert_eq!(
            s.fault(),
            Some(Fault {
                reason: FaultReason::NotReferenced,
                detail: 0
            })
        );
        assert_eq!(s.tick(&ok_tick()).currents_a, [0.0; 3]);
        // The bank's refusal comes first.
        assert!(s.clear_fault());
        assert_eq!(s.arm(false, false), Err(ArmRefused::InvalidBank));
        assert_eq!(s.arm(true, true), Ok(()));
        assert_eq!(s.tick(&ok_tick()).currents_a, [0.5, -0.5, 1.0]);
    }

    /// Each fault input, armed: zero current this tick and after, the reason and detail kept.
    #[test]
    fn every_fault_reason_ends_at_zero_current() {
        let home = liver_device().home_joint;
        let cases: [(TickInput, FaultReason, u32); 16] = [
            (
                TickInput {
                    interlocks: Interlocks {
                        estop: true,
                        amplifier_fault: [false; 3],
                    },
                    ..ok_tick()
                },
                FaultReason::EStop,
                0,
            ),
            (
                TickInput {
                    interlocks: Interlocks {
                        estop: false,
                        amplifier_fault: [false, true, false],
                    },
                    ..ok_tick()
                },
                FaultReason::AmplifierFault,
                1,
            ),
            // 1.1 mm in one tick: 1.1 m/s at the tip, over the 1 m/s threshold.
            (
                TickInput {
                    tip_m: [0.0, 0.0011, 0.0],
                    ..ok_tick()
                },
                FaultReason::Overspeed,
                3,
            ),
            // 11 rad/s in pitch and yaw (threshold 10), 1.1 m/s in insertion (threshold 1).
            (
                TickInput {
                    joints: [home[0] + 0.011, home[1], home[2]],
                    ..ok_tick()
                },
                FaultReason::Overspeed,
                0,
            ),
            (
                TickInput {
                    joints: [home[0], home[1] - 0.011, home[2]],
                    ..ok_tick()
                },
                FaultReason::Overspeed,
                1,
            ),
            (
                TickInput {
                    joints: [home[0], home[1], home[2] + 0.0011],
                    ..ok_tick()
                },
                FaultReason::Overspeed,
                2,
            ),
            (
                TickInput {
                    bank_error: Some(7),
                    ..ok_tick()
                },
                FaultReason::InvalidBank,
                7,
            ),
            (
                TickInput {
                    overrun: true,
                    ..ok_tick()
                },
                FaultReason::Overrun,
                0,
            ),
            (
                TickInput {
                    link_silence_ticks: 11,
                    ..ok_tick()
                },
                FaultReason::LinkSilent,
                11,
            ),
            (
                TickInput {
                    counts: [0, -157, 0],
                    ..ok_tick()
                },
                FaultReason::EncoderJump,
                1,
            ),
            (
                TickInput {
                    joints: [0.0, 0.0, f32::NAN],
                    ..ok_tick()
                },
                FaultReason::Nan,
                0,
            ),
            (
                TickInput {
                    force_n: [f32::INFINITY, 0.0, 0.0],
                    ..ok_tick()
                },
                FaultReason::Nan,
                0,
            ),
            (
                TickInput {
                    requested_a: [0.0, f32::NAN, 0.0],
                    ..ok_tick()
                },
                FaultReason::Nan,
                0,
            ),
            (
                TickInput {
                    solve_failed: true,
                    ..ok_tick()
                },
                FaultReason::SolveFailed,
                0,
            ),
            (
                TickInput {
                    requested_a: [0.0, 0.0, -2.6],
                    ..ok_tick()
                },
                FaultReason::CurrentLimit,
                2,
            ),
            (
                TickInput {
                    requested_a: [100.0, 0.0, 0.0],
                    ..ok_tick()
                },
                FaultReason::CurrentLimit,
                0,
            ),
        ];
        for (input, reason, detail) in cases {
            let mut s = armed();
            let out = s.tick(&input);
            assert_eq!(out.state, State::Fault(reason), "{input:?}");
            assert_eq!(out.currents_a, [0.0; 3]);
            assert_eq!(out.new_fault, Some(Fault { reason, detail }));
            assert_eq!(s.fault(), Some(Fault { reason, detail }));
            // Latched: a good tick keeps zero current and the first reason; a second fault
            // does not overwrite it and is not reported again.
            let out = s.tick(&TickInput {
                overrun: true,
                counts: input.counts,
                ..ok_tick()
            });
            assert_eq!(out.state, State::Fault(reason));
            assert_eq!((out.currents_a, out.new_fault), ([0.0; 3], None));
            let out = s.tick(&TickInput {
                counts: input.counts,
                ..ok_tick()
            });
            assert_eq!(
                (out.state, out.currents_a),
                (State::Fault(reason), [0.0; 3])
            );
            assert_eq!(s.fault(), Some(Fault { reason, detail }));
        }
    }

    /// Joint limits, approached slowly enough not to be an overspeed.
    #[test]
    fn joint_limits_fault_when_armed() {
        for (before, at, joint) in [
            ([0.399, 0.0, 0.05], [0.405, 0.0, 0.05], 0),
            ([0.0, -0.399, 0.05], [0.0, -0.405, 0.05], 1),
            ([0.0, 0.0, 0.0252], [0.0, 0.0, 0.0249], 2),
        ] {
            let mut s = armed_at(before);
            let out = s.tick(&TickInput {
                joints: at,
                ..ok_tick()
            });
            let want = Fault {
                reason: FaultReason::JointLimit,
                detail: joint,
            };
            assert_eq!((out.new_fault, out.currents_a), (Some(want), [0.0; 3]));
        }
    }

    /// The e-stop and the amplifiers' fault outputs latch in every state, before any other
    /// check, and hold the motors at zero until cleared.
    #[test]
    fn interlocks_latch_in_every_state_and_come_first() {
        // Disarmed: a pressed e-stop latches too.
        let mut s = Supervisor::new(SafetyConfig::new(&liver_device()));
        let out = s.tick(&TickInput {
            interlocks: estop(),
            ..ok_tick()
        });
        let e_stop = Fault {
            reason: FaultReason::EStop,
            detail: 0,
        };
        assert_eq!(out.state, State::Fault(FaultReason::EStop));
        assert_eq!((out.new_fault, out.currents_a), (Some(e_stop), [0.0; 3]));
        // Armed: reported ahead of every other fault of the same tick, with zero current.
        for (interlocks, want) in [
            (estop(), e_stop),
            (
                amplifier(2),
                Fault {
                    reason: FaultReason::AmplifierFault,
                    detail: 2,
                },
            ),
            (
                Interlocks {
                    estop: false,
                    amplifier_fault: [false, true, true],
                },
                Fault {
                    reason: FaultReason::AmplifierFault,
                    detail: 1,
                },
            ),
        ] {
            let mut s = armed();
            let out = s.tick(&TickInput {
                interlocks,
                bank_error: Some(3),
                overrun: true,
                requested_a: [f32::NAN; 3],
                ..ok_tick()
            });
            assert_eq!(out.new_fault, Some(want));
            assert_eq!(
                (out.state, out.currents_a),
                (State::Fault(want.reason), [0.0; 3])
            );
            // Latched once the input is gone, until cleared.
            let out = s.tick(&ok_tick());
            assert_eq!((out.new_fault, out.currents_a), (None, [0.0; 3]));
            assert_eq!(s.fault(), Some(want));
            assert!(s.clear_fault());
            assert_eq!(s.tick(&ok_tick()).state, State::Disarmed);
        }
    }

    /// Arming is refused while the last tick saw an interlock, however the state got to
    /// `Disarmed`; it works again once the input is gone and the fault cleared.
    #[test]
    fn arm_is_refused_while_an_interlock_is_active() {
        let mut s = Supervisor::new(SafetyConfig::new(&liver_device()));
        let pressed = TickInput {
            interlocks: estop(),
            ..ok_tick()
        };
        s.tick(&pressed);
        assert_eq!(
            s.arm(true, true),
            Err(ArmRefused::NotDisarmed(State::Fault(FaultReason::EStop)))
        );
        // Cleared while still pressed: disarmed, but arming is refused and says why.
        assert!(s.clear_fault());
        assert_eq!(s.state(), State::Disarmed);
        let refused = Err(ArmRefused::Interlock(Fault {
            reason: FaultReason::EStop,
            detail: 0,
        }));
        assert_eq!(s.arm(true, true), refused);
        assert_eq!(s.state(), State::Disarmed);
        // The next tick latches it again.
        assert_eq!(
            s.tick(&pressed).new_fault.map(|f| f.reason),
            Some(FaultReason::EStop)
        );
        // An amplifier fault refuses arming the same way.
        assert!(s.clear_fault());
        s.tick(&TickInput {
            interlocks: amplifier(0),
            ..ok_tick()
        });
        assert!(s.clear_fault());
        assert_eq!(
            s.arm(true, true),
            Err(ArmRefused::Interlock(Fault {
                reason: FaultReason::AmplifierFault,
                detail: 0,
            }))
        );
        // Released: after one quiet tick (still disarmed, no fault), arming works and currents
        // flow.
        assert_eq!(s.tick(&ok_tick()).state, State::Disarmed);
        assert_eq!(s.arm(true, true), Ok(()));
        assert_eq!(s.tick(&ok_tick()).currents_a, [0.5, -0.5, 1.0]);
    }

    /// Overspeed, per joint and for the tip: at the threshold the loop runs on; beyond it zero
    /// current, latched until the host clears the fault and arms again.
    #[test]
    fn overspeed_per_joint_and_tip_is_latched_until_clear_and_arm() {
        let cal = liver_device();
        let home = cal.home_joint;
        let t = crate::TICK_PERIOD_S;
        // (direction per tick of a unit speed, threshold, detail): joints from the home pose,
        // the tip from the origin.
        for axis in 0..4usize {
            let limit = if axis == 3 {
                cal.max_tip_speed_m_s
            } else {
                cal.max_joint_speed[axis]
            };
            let at_speed = |v: f32, from: &TickInput| {
                let mut next = *from;
                if axis == 3 {
                    next.tip_m[1] += v * t;
                } else {
                    next.joints[axis] += v * t;
                }
                next
            };
            let mut s = armed();
            let mut now = ok_tick();
            // Just under the threshold, for a while (pitch and yaw stay inside their range).
            for _ in 0..20 {
                now = at_speed(0.98 * limit, &now);
                let out = s.tick(&now);
                assert_eq!(out.state, State::Armed, "axis {axis}: {now:?}");
                assert_eq!(out.currents_a, [0.5, -0.5, 1.0]);
            }
            // Over it: Overspeed, detail = joint or 3 for the tip, zero current.
            now = at_speed(1.05 * limit, &now);
            let out = s.tick(&now);
            let want = Fault {
                reason: FaultReason::Overspeed,
                detail: axis as u32,
            };
            assert_eq!(out.new_fault, Some(want), "axis {axis}");
            assert_eq!(out.currents_a, [0.0; 3]);
            // Latched, at rest too, and a later overspeed is not reported again.
            for v in [0.0, 2.0 * limit, 0.0] {
                now = at_speed(v, &now);
                let out = s.tick(&now);
                assert_eq!((out.new_fault, out.currents_a), (None, [0.0; 3]));
                assert_eq!(s.fault(), Some(want));
            }
            // Re-arming is explicit: clear (-> Disarmed, still zero), then arm.
            assert!(s.clear_fault());
            assert_eq!(s.tick(&now).currents_a, [0.0; 3]);
            assert_eq!(s.arm(true, true), Ok(()));
            let out = s.tick(&now);
            assert_eq!(
                (out.state, out.currents_a),
                (State::Armed, [0.5, -0.5, 1.0])
            );
        }
        // The same moves while disarmed are no fault (only a driven device can be too fast).
        let mut s = Supervisor::new(SafetyConfig::new(&cal));
        s.tick(&ok_tick());
        let out = s.tick(&TickInput {
            joints: [home[0] + 0.1, home[1] - 0.1, home[2] + 0.01],
            tip_m: [0.05, 0.0, 0.0],
            ..ok_tick()
        });
        assert_eq!((out.state, out.new_fault), (State::Disarmed, None));
    }

    /// A zeroing of the encoders is not a move, and a NaN tick leaves no speed behind.
    #[test]
    fn overspeed_forgets_rebased_and_non_finite_history() {
        let mut s = armed();
        s.rebase_encoders();
        let far = TickInput {
            joints: [0.3, -0.3, 0.1],
            tip_m: [0.02, -0.03, 0.05],
            ..ok_tick()
        };
        assert_eq!(s.tick(&far).state, State::Armed);
        // NaN faults as Nan, not as an overspeed; once cleared and re-armed, the next finite
        // tick is compared against the NaN one without faulting.
        let nan = TickInput {
            tip_m: [f32::NAN; 3],
            ..far
        };
        assert_eq!(s.tick(&nan).state, State::Fault(FaultReason::Nan));
        assert!(s.clear_fault());
        assert_eq!(s.arm(true, true), Ok(()));
        assert_eq!(s.tick(&far).state, State::Armed);
    }

    /// The encoder-jump limit stays above the overspeed thresholds of the shipped scene, so a
    /// real but fast move is an `Overspeed` and only a glitch an `EncoderJump`.
    #[test]
    #[allow(clippy::needless_range_loop)] // per joint across five arrays
    fn encoder_jump_limit_is_above_the_overspeed_thresholds() {
        let cal = liver_device();
        let c = SafetyConfig::new(&cal);
        for j in 0..3 {
            let per_count = 2.0 * PI / (cal.counts_per_rev[j] as f32 * cal.transmission[j].abs());
            let jump_speed = c.max_counts_per_tick[j] as f32 * per_count / c.tick_s;
            assert!(
                jump_speed > 1.5 * c.max_joint_speed[j],
                "joint {j}: jump {jump_speed} vs overspeed {}",
                c.max_joint_speed[j]
            );
            assert!(DEFAULT_JUMP_SPEED[j] > c.max_joint_speed[j]);
        }
        // A move between the two is an Overspeed, not an EncoderJump.
        let mut s = armed();
        let out = s.tick(&TickInput {
            counts: [0, 0, 400],
            joints: [0.0, 0.0, 0.03 + 400.0 * 2.0 * PI / (4096.0 * 400.0)],
            ..ok_tick()
        });
        assert_eq!(
            out.new_fault,
            Some(Fault {
                reason: FaultReason::Overspeed,
                detail: 2
            })
        );
    }

    #[test]
    fn slight_overcurrent_is_clamped_not_a_fault() {
        let mut s = armed();
        let out = s.tick(&TickInput {
            requested_a: [2.4, -2.5, 1.9],
            ..ok_tick()
        });
        assert_eq!(out.state, State::Armed);
        assert_eq!(out.currents_a, [2.0, -2.0, 1.9]);
        assert_eq!(out.clamped, [true, true, false]);
        assert_eq!(out.new_fault, None);
    }

    #[test]
    fn disarmed_checks_only_data_faults() {
        let mut s = Supervisor::new(SafetyConfig::new(&liver_device()));
        // Drive-only conditions while disarmed: no fault.
        let out = s.tick(&TickInput {
            overrun: true,
            link_silence_ticks: 1000,
            joints: [3.0, 0.0, 0.0],
            requested_a: [50.0, 0.0, 0.0],
            ..ok_tick()
        });
        assert_eq!((out.state, out.currents_a), (State::Disarmed, [0.0; 3]));
        // Data faults while disarmed: latched.
        let out = s.tick(&TickInput {
            bank_error: Some(3),
            ..ok_tick()
        });
        assert_eq!(out.state, State::Fault(FaultReason::InvalidBank));
        assert!(s.clear_fault());
        let out = s.tick(&TickInput {
            force_n: [f32::NAN; 3],
            ..ok_tick()
        });
        assert_eq!(out.state, State::Fault(FaultReason::Nan));
        assert!(s.clear_fault());
        let out = s.tick(&TickInput {
            counts: [0, 0, 100_000],
            ..ok_tick()
        });
        assert_eq!(out.state, State::Fault(FaultReason::EncoderJump));
        assert_eq!(s.fault().map(|f| f.detail), Some(2));
    }

    #[test]
    fn encoder_moves_within_the_limit_and_rebase() {
        let mut s = armed();
        // 156 counts per tick on pitch and yaw, 521 on insertion are allowed.
        let mut counts = [0i32; 3];
        for _ in 0..5 {
            counts = [counts[0] + 156, counts[1] - 156, counts[2] + 521];
            let out = s.tick(&TickInput {
                counts,
                ..ok_tick()
            });
            assert_eq!(out.state, State::Armed);
        }
        // Wrap-around of the i32 counter is a huge jump, not a small one.
        let mut s = armed();
        s.tick(&TickInput {
            counts: [i32::MAX, 0, 0],
            ..ok_tick()
        });
        assert!(s.clear_fault());
        let out = s.tick(&TickInput {
            counts: [i32::MIN, 0, 0],
            ..ok_tick()
        });
        assert_eq!(out.state, State::Fault(FaultReason::EncoderJump));
        // After zeroing the encoders, the reset is not a jump.
        let mut s = armed();
        s.tick(&TickInput {
            counts: [100, 100, 500],
            ..ok_tick()
        });
        s.rebase_encoders();
        s.tick(&TickInput {
            counts: [0, 0, 0],
            ..ok_tick()
        });
        s.tick(&TickInput {
            counts: [100, 100, 500],
            ..ok_tick()
        });
        s.rebase_encoders();
        let out = s.tick(&TickInput {
            counts: [-30_000, 30_000, 9],
            ..ok_tick()
        });
        assert_eq!(out.state, State::Armed);
    }

    /// The bank's link timeout, 37 ms at 1 kHz: armed through 37 silent ticks, `LinkSilent`
    /// (detail 38) at the 38th; at 2 kHz the same 37 ms are 74 ticks; the range's ends map to
    /// 5 and 100 ticks.
    #[test]
    fn link_timeout_boundary() {
        let cal = DeviceCalibration {
            link_timeout_ms: 37,
            ..liver_device()
        };
        let mut s = Supervisor::new(SafetyConfig::new(&cal));
        s.tick(&ok_tick());
        assert_eq!(s.arm(true, true), Ok(()));
        for silence in 1..=37 {
            let out = s.tick(&TickInput {
                link_silence_ticks: silence,
                ..ok_tick()
            });
            assert_eq!(out.state, State::Armed, "{silence} ticks");
        }
        let out = s.tick(&TickInput {
            link_silence_ticks: 38,
            ..ok_tick()
        });
        assert_eq!(out.state, State::Fault(FaultReason::LinkSilent));
        assert_eq!(
            out.new_fault,
            Some(Fault {
                reason: FaultReason::LinkSilent,
                detail: 38
            })
        );
        let at = |ms, tick_s| {
            let cal = DeviceCalibration {
                link_timeout_ms: ms,
                ..liver_device()
            };
            SafetyConfig::from_calibration(&cal, DEFAULT_JUMP_SPEED, tick_s).link_timeout_ticks
        };
        assert_eq!(at(37, 0.5e-3), 74);
        assert_eq!(at(bank_format::LINK_TIMEOUT_MS_MIN, 1e-3), 5);
        assert_eq!(at(bank_format::LINK_TIMEOUT_MS_MAX, 1e-3), 100);
    }

    #[test]
    fn raise_from_outside_the_tick() {
        let mut s = armed();
        assert!(s.raise(FaultReason::InvalidBank, 42));
        assert!(!s.raise(FaultReason::Nan, 0));
        assert_eq!(
            s.fault(),
            Some(Fault {
                reason: FaultReason::InvalidBank,
                detail: 42
            })
        );
        assert_eq!(s.tick(&ok_tick()).currents_a, [0.0; 3]);
    }

    /// The device model and the supervisor together: a hard press at full insertion asks for
    /// more than the pitch limit, which is clamped.
    #[test]
    fn device_and_supervisor_together() {
        let cal = liver_device();
        let dev = Device::new(&cal);
        let mut s = armed();
        let q = Joints::from_array([0.0, 0.0, 0.14]);
        let counts = [0, 0, ((0.14 - 0.03) / dev.joint_per_count()[2]) as i32];
        assert!((dev.joints(counts).insertion - 0.14).abs() < 1e-5);
        s.rebase_encoders();
        let f = dev.limit_force([0.0, 9.0, 0.0]);
        let c = dev.currents_for_force(&q, f);
        // 5 N * 0.14 m / (12 * 0.025) = 2.33 A: over the 2 A limit, under 1.25 x.
        assert!((c.requested_a[0] - 7.0 / 3.0).abs() < 1e-5);
        let out = s.tick(&TickInput {
            counts,
            joints: dev.joints(counts).to_array(),
            force_n: f,
            requested_a: c.requested_a,
            ..TickInput::quiet()
        });
        assert_eq!(out.state, State::Armed);
        assert_eq!(out.currents_a, c.applied_a);
        assert_eq!(out.clamped, [true, false, false]);
    }
}
