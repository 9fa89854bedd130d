//! The device application around the loop, the same on every platform: per tick it latches the
//! encoders and the interlocks, applies the host's link commands, runs [`HapticLoop::tick`],
//! drives the motors (or puts them in their safe state) and queues faults and decimated
//! telemetry. The hardware comes in through [`crate::hal`]; the host link through the tick's
//! end of [`crate::link`]'s queues, so a tick never waits on I/O and never encodes: it queues
//! the message (a telemetry snapshot, a fault), the link driver encodes it outside the tick,
//! and a message that finds the queue full is dropped whole and counted (telemetry's
//! `tx_dropped`).
//!
//! A bank that fails validation leaves no loop to run: the application then keeps the motors at
//! zero current, reports [`FaultReason::InvalidBank`] with the [`BankError::code`] as detail at
//! boot and on every arm attempt, and answers `Hello` with `bank_crc: None`.
//!
//! The interlocks ([`crate::hal::Interlocks`]: e-stop, amplifier fault outputs) go to the
//! supervisor every tick, with or without a bank: an active one latches
//! [`FaultReason::EStop`] or [`FaultReason::AmplifierFault`] and disables the motors, and an
//! arm command is refused (the latched fault re-sent) while one is active.

use bank_format::{
    Bank, BankError, Counters, DeviceToHost, FaultReason, HostToDevice, Mode, PROTOCOL_VERSION,
    PhaseCycles, ResetCause, State, Telemetry, heapless,
};

use crate::hal::{CycleCounter, Plant};
use crate::link::TickEnd;
use crate::safety::{ArmRefused, Fault, SafetyConfig, Supervisor, TickInput};
use crate::tick::{HapticLoop, LoopInput, PhaseMarks};

/// Telemetry goes out every this many ticks (100 Hz at 1 kHz).
pub const TELEMETRY_EVERY_TICKS: u32 = 10;
/// At most this many received commands are applied per tick, so a burst of them (a host that
/// stalled, then sent its backlog) cannot stretch a tick: the link's driver decodes them
/// outside the tick ([`crate::link`]), and taking one out of the queue costs the tick a
/// copy of about 20 bytes and the command itself. 4 is more than a host sends in a tick (a
/// command now and then; heartbeats and `Disarm` take no queue slot); a backlog waits in the
/// link's queue ([`crate::link::RX_COMMANDS`]). (The tick used to decode up to 32 received
/// bytes itself, about 1,600 instructions when a burst landed.)
pub const MAX_COMMANDS_PER_TICK: usize = 4;

/// What one tick did, for the caller (the software-in-the-loop image reports it to its
/// harness; a board ignores it).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TickReport {
    /// The tick's number.
    pub tick: u32,
    /// Motor currents commanded, A (zero unless armed).
    pub currents_a: [f32; 3],
    /// Force rendered on the tool, N.
    pub force_n: [f32; 3],
    /// Safety state after the tick.
    pub state: State,
    /// Contact nodes this tick.
    pub contact_nodes: u8,
    /// Cost of this tick's loop body, cycles ([`CycleCounter`]).
    pub body_cycles: u32,
    /// Cost of the whole previous tick, cycles.
    pub tick_cycles: u32,
    /// `body_cycles` split at the loop's phase boundaries ([`HapticLoop::tick_marked`]): the
    /// parts sum to `body_cycles`. Without a bank the body is all supervisor.
    pub phase_cycles: PhaseCycles,
}

/// What runs the ticks: the loop over a valid bank, or the zero-current stand-in without one.
// The loop is the common, long-lived variant: boxing it would need a heap.
#[allow(clippy::large_enum_variant)]
enum Core<'b> {
    Loop(HapticLoop<'b>),
    NoBank {
        supervisor: Supervisor,
        code: u32,
        tick: u32,
        counters: Counters,
    },
}

/// The application state (no heap: the link's queues are fixed-size).
pub struct App<'b, 'q> {
    core: Core<'b>,
    link: TickEnd<'q>,
    /// The link's received-byte count when the tick last looked.
    rx_bytes_seen: u32,
    ticks_since_host_frame: u32,
    ticks_since_host_byte: u32,
    link_grace_ticks: u32,
    last_tick_cycles: u32,
    reset_cause: Option<ResetCause>,
    /// A fault of the hardware's configuration found at boot ([`App::check_amplifiers`],
    /// [`App::check_brown_out`]): every arm is refused with it.
    configuration: Option<Fault>,
}

impl<'b, 'q> App<'b, 'q> {
    /// The application over the result of validating the bank region ([`Bank::parse`]),
    /// talking to the host through `link`; queues the boot `Hello`.
    ///
    /// `link_grace_ticks`: for how many ticks past the last valid frame received bytes alone
    /// still count as link activity. 0 on a board, whose link carries
    /// a whole frame within a tick: then only valid frames count, and a link that delivers
    /// only garbage faults `LinkSilent` as soon as a silent one does (the supervisor's
    /// timeout, 10 ticks). A slow link (QEMU's USART, a few bytes a tick) needs a grace of
    /// about as many ticks as its longest frame takes.
    pub fn new(
        bank: Result<&'b Bank<'b>, BankError>,
        link: TickEnd<'q>,
        link_grace_ticks: u32,
    ) -> App<'b, 'q> {
        let core = match bank {
            Ok(bank) => Core::Loop(HapticLoop::new(bank)),
            Err(e) => Core::NoBank {
                supervisor: Supervisor::new(no_bank_config()),
                code: u32::from(e.code()),
                tick: 0,
                counters: Counters::default(),
            },
        };
        let mut app = App {
            core,
            link,
            rx_bytes_seen: 0,
            ticks_since_host_frame: 0,
            ticks_since_host_byte: 0,
            link_grace_ticks,
            last_tick_cycles: 0,
            reset_cause: None,
            configuration: None,
        };
        app.queue(app.hello());
        app
    }

    /// Why the chip started ([`crate::reset::cause_from_rcc_csr`] on a board): reported now,
    /// after the boot `Hello`, and again after every `Hello` reply, so a host that connects
    /// later still learns it. A watchdog reset is also latched as
    /// [`FaultReason::WatchdogReset`] ([`crate::reset::latched_fault`]) and reported once,
    /// before the first tick, so a device that hung or locked up mid-session stays at zero
    /// current until the host clears the fault explicitly. Whatever the cause, the encoders
    /// start unreferenced ([`HapticLoop::zero_encoders`]). Call right after [`App::new`].
    pub fn reset(&mut self, cause: ResetCause) {
        self.reset_cause = Some(cause);
        self.queue(DeviceToHost::Reset { cause });
        let Some((reason, detail)) = crate::reset::latched_fault(cause) else {
            return;
        };
        let latched = match &mut self.core {
            Core::Loop(lp) => lp.raise(reason, detail),
            Core::NoBank { supervisor, .. } => supervisor.raise(reason, detail),
        };
        if latched {
            self.queue(DeviceToHost::Fault {
                tick: self.tick_count(),
                reason,
                detail,
            });
        }
    }

    /// Check at boot that the amplifiers can deliver the bank's current limits
    /// ([`crate::amplifier::out_of_range`]); if a motor's cannot, latch and report
    /// [`FaultReason::AmplifierRange`] (detail the motor) and refuse every arm with it, however
    /// often the fault is cleared: the bank (`current_limit_a`) or the amplifier's scaling (and
    /// the board file that mirrors it) must change. Without a valid bank there is nothing to
    /// check (nothing is ever driven). Call right after [`App::new`].
    pub fn check_amplifiers(&mut self, amplifiers: &[crate::amplifier::Amplifier; 3]) {
        let Core::Loop(lp) = &mut self.core else {
            return;
        };
        let Some(motor) =
            crate::amplifier::out_of_range(amplifiers, lp.bank().device().current_limit_a)
        else {
            return;
        };
        let fault = Fault {
            reason: FaultReason::AmplifierRange,
            detail: motor,
        };
        self.configuration = Some(fault);
        if lp.raise(fault.reason, fault.detail) {
            self.queue(DeviceToHost::Fault {
                tick: self.tick_count(),
                reason: fault.reason,
                detail: fault.detail,
            });
        }
    }

    /// Check at boot that the chip's brown-out reset is at level 3 (`optcr` the value of
    /// `FLASH_OPTCR`, [`crate::brownout`]); below it, latch and report
    /// [`FaultReason::BrownOutLevel`] (detail the level, 0 for BOR off) and refuse every arm
    /// with it, however often the fault is cleared: the option bytes must change (`host flash
    /// --set-bor`). As with [`App::check_amplifiers`], without a valid bank there is nothing
    /// to check, and the first configuration fault found is the one every arm re-sends. Call
    /// right after [`App::new`].
    pub fn check_brown_out(&mut self, optcr: u32) {
        let Core::Loop(lp) = &mut self.core else {
            return;
        };
        let Some((reason, detail)) =
            crate::brownout::fault(crate::brownout::level_from_optcr(optcr))
        else {
            return;
        };
        self.configuration.get_or_insert(Fault { reason, detail });
        if lp.raise(reason, detail) {
            self.queue(DeviceToHost::Fault {
                tick: self.tick_count(),
                reason,
                detail,
            });
        }
    }

    /// The loop, when the bank is valid.
    pub fn haptic_loop(&self) -> Option<&HapticLoop<'b>> {
        match &self.core {
            Core::Loop(lp) => Some(lp),
            Core::NoBank { .. } => None,
        }
    }

    /// Record the cost of the whole tick that just ended (reported with the next tick and as
    /// telemetry's `max_tick_cycles`).
    pub fn record_tick_cycles(&mut self, cycles: u32) {
        self.last_tick_cycles = cycles;
        let c = self.counters_mut();
        c.max_tick_cycles = c.max_tick_cycles.max(cycles);
    }

    /// One tick: encoders and interlocks, link commands, the loop, motors, faults and
    /// telemetry. `overrun` says whether the previous tick overran its period. Returns at once
    /// whatever the link does; only a plant error stops it (the motors are then disabled).
    pub fn tick<P: Plant, C: CycleCounter>(
        &mut self,
        plant: &mut P,
        clock: &C,
        overrun: bool,
    ) -> Result<TickReport, P::Error> {
        let counts = match plant.read_encoders() {
            Ok(c) => c,
            Err(e) => {
                plant.disable();
                return Err(e);
            }
        };
        let interlocks = plant.interlocks();
        self.poll_link();
        let start = clock.cycles();
        let input = LoopInput {
            encoder_counts: counts,
            overrun,
            link_silence_ticks: self.link_silence(),
            interlocks,
        };
        let (out, new_fault, marks) = match &mut self.core {
            Core::Loop(lp) => {
                let (out, marks) = lp.tick_marked(input, clock);
                let report = TickReport {
                    tick: out.tick,
                    currents_a: out.currents_a,
                    force_n: out.tool_force_n,
                    state: out.state.wire(),
                    contact_nodes: out.contact_nodes as u8,
                    body_cycles: 0,
                    tick_cycles: self.last_tick_cycles,
                    phase_cycles: PhaseCycles::default(),
                };
                (report, out.new_fault, marks)
            }
            Core::NoBank {
                supervisor,
                code,
                tick,
                counters,
            } => {
                *tick = tick.wrapping_add(1);
                if overrun {
                    counters.overruns = counters.overruns.wrapping_add(1);
                }
                let s = supervisor.tick(&TickInput {
                    bank_error: Some(*code),
                    counts,
                    interlocks,
                    ..TickInput::quiet()
                });
                let report = TickReport {
                    tick: *tick,
                    currents_a: s.currents_a,
                    force_n: [0.0; 3],
                    state: s.state.wire(),
                    contact_nodes: 0,
                    body_cycles: 0,
                    tick_cycles: self.last_tick_cycles,
                    phase_cycles: PhaseCycles::default(),
                };
                let marks = PhaseMarks {
                    kinematics: start,
                    detection: start,
                    patch: start,
                    solve: start,
                    law: start,
                };
                (report, s.new_fault, marks)
            }
        };
        let end = clock.cycles();
        let out = TickReport {
            body_cycles: end.wrapping_sub(start),
            phase_cycles: marks.phases(start, end),
            ..out
        };
        self.ticks_since_host_frame = self.ticks_since_host_frame.saturating_add(1);
        self.ticks_since_host_byte = self.ticks_since_host_byte.saturating_add(1);
        let driven = if out.state == State::Armed {
            plant.drive(out.currents_a)
        } else {
            plant.disable();
            Ok(())
        };
        if let Err(e) = driven {
            plant.disable();
            return Err(e);
        }
        if let Some(f) = new_fault {
            self.queue(DeviceToHost::Fault {
                tick: out.tick,
                reason: f.reason,
                detail: f.detail,
            });
        }
        if out.tick.is_multiple_of(TELEMETRY_EVERY_TICKS) {
            // Periodic: it leaves room for faults when the host has stopped reading.
            let _ = self
                .link
                .send_periodic(DeviceToHost::Telemetry(self.telemetry()));
        }
        Ok(out)
    }

    /// Apply what the link has received: first a `Disarm` that arrived since the last tick
    /// (never queued, so never shed: [`crate::link`]), then at most
    /// [`MAX_COMMANDS_PER_TICK`] queued commands; note whether any byte and any valid frame
    /// arrived since the last tick (activity, for [`App::link_silence`]).
    fn poll_link(&mut self) {
        let bytes = self.link.rx_counts().bytes();
        if bytes != self.rx_bytes_seen {
            self.rx_bytes_seen = bytes;
            self.ticks_since_host_byte = 0;
        }
        let arrived = self.link.poll();
        if arrived.frame {
            self.ticks_since_host_frame = 0;
        }
        if arrived.disarm {
            self.command(HostToDevice::Disarm);
        }
        for _ in 0..MAX_COMMANDS_PER_TICK {
            let Some(cmd) = self.link.receive() else {
                break;
            };
            self.command(cmd);
        }
    }

    /// Ticks run so far.
    pub fn tick_count(&self) -> u32 {
        match &self.core {
            Core::Loop(lp) => lp.tick_count(),
            Core::NoBank { tick, .. } => *tick,
        }
    }

    /// The telemetry of the last tick.
    pub fn telemetry(&self) -> Telemetry {
        let mut t = self.core_telemetry();
        let rx = self.link.rx_counts();
        t.counters.rx_frames = rx.frames();
        t.counters.rx_errors = rx.errors();
        t.counters.rx_dropped = rx.dropped();
        t.counters.tx_dropped = self.link.tx_dropped();
        t
    }

    fn core_telemetry(&self) -> Telemetry {
        match &self.core {
            Core::Loop(lp) => lp.telemetry(),
            Core::NoBank {
                supervisor,
                tick,
                counters,
                ..
            } => Telemetry {
                tick: *tick,
                state: supervisor.state().wire(),
                mode: Mode::Render,
                fault: supervisor.state().fault(),
                tip_m: [0.0; 3],
                contacts: heapless::Vec::new(),
                contact_point: None,
                currents_a: [0.0; 3],
                tool_force_n: [0.0; 3],
                dropped_load: 0.0,
                counters: *counters,
            },
        }
    }

    fn counters_mut(&mut self) -> &mut Counters {
        match &mut self.core {
            Core::Loop(lp) => lp.counters_mut(),
            Core::NoBank { counters, .. } => counters,
        }
    }

    fn hello(&self) -> DeviceToHost {
        match &self.core {
            Core::Loop(lp) => DeviceToHost::Hello {
                protocol: PROTOCOL_VERSION,
                bank_crc: Some(lp.bank().crc()),
                scene_id: lp.bank().scene_id(),
                node_count: u16::try_from(lp.bank().node_count()).unwrap_or(u16::MAX),
            },
            Core::NoBank { .. } => DeviceToHost::Hello {
                protocol: PROTOCOL_VERSION,
                bank_crc: None,
                scene_id: 0,
                node_count: 0,
            },
        }
    }

    /// How long the host has been silent, in ticks, for the supervisor's link timeout: since
    /// the last valid frame less the link grace ([`App::new`]), and never less than since the
    /// last byte (bytes count as activity only within the grace; with none, only valid frames
    /// count).
    fn link_silence(&self) -> u32 {
        self.ticks_since_host_byte.max(
            self.ticks_since_host_frame
                .saturating_sub(self.link_grace_ticks),
        )
    }

    fn command(&mut self, cmd: HostToDevice) {
        match cmd {
            HostToDevice::Hello => {
                self.queue(self.hello());
                if let Some(cause) = self.reset_cause {
                    self.queue(DeviceToHost::Reset { cause });
                }
            }
            HostToDevice::Arm => self.arm(),
            HostToDevice::Disarm => {
                if let Core::Loop(lp) = &mut self.core {
                    lp.disarm();
                }
            }
            HostToDevice::SetMode(mode) => {
                if let Core::Loop(lp) = &mut self.core
                    && let Err(f) = lp.set_mode(mode)
                {
                    let tick = lp.tick_count();
                    self.queue(DeviceToHost::Fault {
                        tick,
                        reason: f.reason,
                        detail: f.detail,
                    });
                }
            }
            HostToDevice::ZeroEncoders => {
                if let Core::Loop(lp) = &mut self.core {
                    lp.zero_encoders();
                }
            }
            HostToDevice::ClearFault => match &mut self.core {
                Core::Loop(lp) => {
                    lp.clear_fault();
                }
                Core::NoBank { supervisor, .. } => {
                    supervisor.clear_fault();
                }
            },
            // Keep-alive only; plant frames belong to the plant channel, not the link.
            HostToDevice::Heartbeat | HostToDevice::Plant { .. } => {}
        }
    }

    /// Arm, or say why not: a refusal re-sends the latched fault (the invalid bank's code, the
    /// amplifier range), or the fault of the interlock that is still active.
    fn arm(&mut self) {
        let tick = self.tick_count();
        let configuration = self.configuration;
        let refused = match (&mut self.core, configuration) {
            (Core::Loop(lp), Some(f)) => {
                // Latched again if cleared: the motors stay off.
                lp.raise(f.reason, f.detail);
                Some(f)
            }
            (Core::Loop(lp), None) => match lp.arm() {
                Ok(()) => None,
                Err(ArmRefused::Interlock(f)) => Some(f),
                Err(_) => lp.supervisor().fault(),
            },
            (
                Core::NoBank {
                    supervisor, code, ..
                },
                _,
            ) => {
                // Always refused (`bank_valid: false`); the reason is the bank.
                let _ = supervisor.arm(false, false);
                Some(Fault {
                    reason: FaultReason::InvalidBank,
                    detail: *code,
                })
            }
        };
        if let Some(f) = refused {
            self.queue(DeviceToHost::Fault {
                tick,
                reason: f.reason,
                detail: f.detail,
            });
        }
    }

    /// Queue `msg` for the link driver, which encodes it outside the tick; dropped whole and
    /// counted ([`TickEnd::tx_dropped`]) when the queue is full.
    fn queue(&mut self, msg: DeviceToHost) {
        // A refusal is counted by the queue itself.
        let _ = self.link.send(msg);
    }
}

/// Thresholds without a bank: nothing is ever driven (every limit is zero).
fn no_bank_config() -> SafetyConfig {
    SafetyConfig {
        max_counts_per_tick: [u32::MAX; 3],
        link_timeout_ticks: u32::MAX,
        current_fault_ratio: 1.0,
        current_limit_a: [0.0; 3],
        joint_min: [0.0; 3],
        joint_max: [0.0; 3],
        joint_limit_margin: [0.0; 3],
        max_tip_speed_m_s: 0.0,
        max_joint_speed: [0.0; 3],
        tick_s: crate::TICK_PERIOD_S,
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::indexing_slicing, clippy::panic)]
mod tests {
    extern crate std;
    use super::*;
    use crate::fixtures::flat_patch;
    use crate::hal::Interlocks;
    use crate::link::{DriverEnd, Link};
    use bank_format::{AlignedBytes, FrameDecoder, MAX_FRAME, State as WireState, encode_frame};
    use std::vec::Vec;

    /// Encoders and interlocks held (set them between ticks), what was driven recorded.
    struct FakePlant {
        counts: [i32; 3],
        interlocks: Interlocks,
        fail_at: Option<u32>,
        reads: u32,
        driven: Vec<Option<[f32; 3]>>,
    }

    impl Plant for FakePlant {
        type Error = u32;
        fn read_encoders(&mut self) -> Result<[i32; 3], u32> {
            self.reads += 1;
            match self.fail_at {
                Some(t) if t == self.reads => Err(t),
                _ => Ok(self.counts),
            }
        }
        fn drive(&mut self, currents_a: [f32; 3]) -> Result<(), u32> {
            self.driven.push(Some(currents_a));
            Ok(())
        }
        fn disable(&mut self) {
            self.driven.push(None);
        }
        fn interlocks(&mut self) -> Interlocks {
            self.interlocks
        }
    }

    /// The host's side of the link: sends commands into the driver end, decodes what the
    /// driver takes out, `per_tick` bytes at a time.
    struct FakeHost<'q> {
        driver: DriverEnd<'q>,
        rx: FrameDecoder<DeviceToHost>,
        sent: Vec<DeviceToHost>,
        per_tick: usize,
    }

    impl<'q> FakeHost<'q> {
        fn new(driver: DriverEnd<'q>) -> FakeHost<'q> {
            FakeHost {
                driver,
                rx: FrameDecoder::new(),
                sent: Vec::new(),
                per_tick: usize::MAX,
            }
        }

        fn send(&mut self, cmd: &HostToDevice) {
            let mut buf = [0u8; MAX_FRAME];
            self.driver.put_rx(encode_frame(cmd, &mut buf).unwrap());
        }

        /// What the link driver does between ticks: take up to `per_tick` bytes and deliver them.
        fn pump(&mut self) {
            let mut left = self.per_tick;
            let mut buf = [0u8; 64];
            while left > 0 {
                let n = self.driver.take_tx(&mut buf[..left.min(64)]);
                if n == 0 {
                    break;
                }
                left -= n;
                for r in self.rx.feed_slice(&buf[..n]) {
                    self.sent.push(r.unwrap());
                }
            }
        }
    }

    /// Advances 100 cycles per reading.
    struct FakeClock(core::cell::Cell<u32>);

    impl CycleCounter for FakeClock {
        fn cycles(&self) -> u32 {
            self.0.set(self.0.get() + 100);
            self.0.get()
        }
    }

    fn plant() -> FakePlant {
        FakePlant {
            counts: [0, 0, 0],
            interlocks: Interlocks::default(),
            fail_at: None,
            reads: 0,
            driven: Vec::new(),
        }
    }

    fn clock() -> FakeClock {
        FakeClock(core::cell::Cell::new(0))
    }

    /// The bank in a fixture's `bytes`.
    fn parse(bytes: &AlignedBytes) -> Bank<'_> {
        Bank::parse(bytes.as_slice()).unwrap()
    }

    /// The device under test and what surrounds it: an [`App`] on a bank (or the stand-in for
    /// an invalid one), the [`FakeHost`] at the other end of its link (the caller's: both ends
    /// borrow it), a fresh [`FakePlant`] and [`FakeClock`].
    struct Rig<'b, 'q> {
        app: App<'b, 'q>,
        host: FakeHost<'q>,
        plant: FakePlant,
        clock: FakeClock,
    }

    impl<'b, 'q> Rig<'b, 'q> {
        /// With the board's link grace (none).
        fn new(bank: Result<&'b Bank<'b>, BankError>, link: &'q mut Link) -> Rig<'b, 'q> {
            Rig::with_grace(bank, link, 0)
        }

        /// With `grace` ticks of link grace ([`App::new`]).
        fn with_grace(
            bank: Result<&'b Bank<'b>, BankError>,
            link: &'q mut Link,
            grace: u32,
        ) -> Rig<'b, 'q> {
            let (tick_end, driver) = link.split();
            Rig {
                app: App::new(bank, tick_end, grace),
                host: FakeHost::new(driver),
                plant: plant(),
                clock: clock(),
            }
        }

        /// The encoders referenced at encoder zero, as a host's `ZeroEncoders` taken before
        /// the first tick would (sent over the link, it would push a test's other commands
        /// past the first tick's share, [`MAX_COMMANDS_PER_TICK`]). No loop without a bank.
        fn homed(mut self) -> Rig<'b, 'q> {
            if let Core::Loop(lp) = &mut self.app.core {
                assert!(lp.zero_encoders());
            }
            self
        }

        /// Booted after a reset with `cause` ([`App::reset`]).
        fn after_reset(mut self, cause: ResetCause) -> Rig<'b, 'q> {
            self.app.reset(cause);
            self
        }

        /// One tick (the last one on time); its report.
        fn tick(&mut self) -> TickReport {
            self.app.tick(&mut self.plant, &self.clock, false).unwrap()
        }

        /// One tick of a live host: the tick, then the host reads what came out and sends a
        /// heartbeat.
        fn step(&mut self) -> TickReport {
            let r = self.tick();
            self.host.pump();
            self.host.send(&HostToDevice::Heartbeat);
            r
        }

        /// A boot check's latched `fault` (`detail`) holds: reported at boot, and three times
        /// over, `ClearFault`, the `also` commands and `Arm` give a tick in `Fault` at zero
        /// current with the fault reported again; no motor was ever driven.
        fn refuses_every_arm(&mut self, fault: FaultReason, detail: u32, also: &[HostToDevice]) {
            let reported = |tick| DeviceToHost::Fault {
                tick,
                reason: fault,
                detail,
            };
            self.host.pump();
            assert_eq!(self.host.sent[1], reported(0));
            for _ in 0..3 {
                self.host.send(&HostToDevice::ClearFault);
                also.iter().for_each(|c| self.host.send(c));
                self.host.send(&HostToDevice::Arm);
                let r = self.tick();
                assert_eq!((r.state, r.currents_a), (WireState::Fault, [0.0; 3]));
                self.host.pump();
                assert_eq!(self.host.sent.last(), Some(&reported(r.tick - 1)));
            }
            assert!(self.plant.driven.iter().all(Option::is_none));
            assert_eq!(self.app.telemetry().fault, Some(fault));
        }

        /// The `Fault` frames the host has received.
        fn faults(&self) -> Vec<DeviceToHost> {
            self.host
                .sent
                .iter()
                .filter(|m| matches!(m, DeviceToHost::Fault { .. }))
                .cloned()
                .collect()
        }
    }

    #[test]
    fn commands_arm_and_telemetry_flows() {
        let bytes = flat_patch();
        let bank = parse(&bytes);
        let mut link = Link::new();
        let mut rig = Rig::new(Ok(&bank), &mut link).homed();
        rig.host.send(&HostToDevice::Hello);
        rig.host.send(&HostToDevice::SetMode(Mode::Transparent));
        // A corrupt frame between them is dropped and counted.
        rig.host.driver.put_rx(&[0x03, 0x11, 0x22, 0x00]);
        rig.host.send(&HostToDevice::Arm);
        let mut reports = Vec::new();
        for _ in 0..20 {
            reports.push(rig.step());
        }
        let hello = DeviceToHost::Hello {
            protocol: PROTOCOL_VERSION,
            bank_crc: Some(bank.crc()),
            scene_id: bank.scene_id(),
            node_count: bank.node_count() as u16,
        };
        // Boot Hello, the requested Hello, telemetry at ticks 10 and 20.
        assert_eq!(rig.host.sent[..2], [hello.clone(), hello]);
        let tel: Vec<_> = rig.host.sent[2..]
            .iter()
            .map(|m| match m {
                DeviceToHost::Telemetry(t) => t.clone(),
                other => panic!("{other:?}"),
            })
            .collect();
        assert_eq!(tel.iter().map(|t| t.tick).collect::<Vec<_>>(), [10, 20]);
        assert_eq!(tel[1].state, WireState::Armed);
        assert_eq!(tel[1].mode, Mode::Transparent);
        // Hello, SetMode, Arm and the 19 heartbeats read so far.
        assert_eq!(tel[1].counters.rx_frames, 3 + 19);
        assert_eq!(tel[1].counters.rx_errors, 1);
        assert_eq!(tel[1].counters.tx_dropped, 0);
        assert_eq!(reports.len(), 20);
        assert!(reports.iter().all(|a| a.state == WireState::Armed));
        // Armed: every tick drove the motors.
        assert!(rig.plant.driven.iter().all(Option::is_some));
        // The body was measured between two readings of the clock around the loop, which
        // read it five more times (the ends of its first five phases): six phases of 100
        // cycles each, which sum to the body.
        for r in &reports {
            assert_eq!(r.body_cycles, 600);
            assert_eq!(r.phase_cycles.to_array(), [100; 6]);
            assert_eq!(r.phase_cycles.total(), r.body_cycles);
        }
    }

    #[test]
    fn silence_while_armed_faults_and_reports_once() {
        let bytes = flat_patch();
        let bank = parse(&bytes);
        let mut link = Link::new();
        let mut rig = Rig::new(Ok(&bank), &mut link);
        rig.host.send(&HostToDevice::ZeroEncoders);
        rig.host.send(&HostToDevice::Arm);
        let mut reports = Vec::new();
        for _ in 0..30 {
            reports.push(rig.tick());
            rig.host.pump();
        }
        // The frame arrived at tick 1; tick 12 is the 11th without one.
        assert_eq!(
            rig.faults(),
            [DeviceToHost::Fault {
                tick: 12,
                reason: FaultReason::LinkSilent,
                detail: 11
            }]
        );
        assert!(reports[11..].iter().all(|a| a.currents_a == [0.0; 3]));
        // From the fault on, the motors are disabled, not driven with zero.
        assert!(rig.plant.driven[11..].iter().all(Option::is_none));
        // A plant error stops the tick, disables the motors and is returned.
        rig.plant.fail_at = Some(31);
        let before = rig.plant.driven.len();
        assert_eq!(rig.app.tick(&mut rig.plant, &rig.clock, false), Err(31));
        assert_eq!(rig.plant.driven[before..], [None]);
    }

    /// An e-stop pressed while armed and driving: from that tick the motors are disabled (not
    /// driven with zero) and exactly one Fault frame goes out; arming is refused while it is
    /// pressed, and works again once it is released and the fault cleared.
    #[test]
    fn an_estop_mid_run_disables_the_motors_and_reports_once() {
        let bytes = flat_patch();
        let bank = parse(&bytes);
        let mut link = Link::new();
        let mut rig = Rig::new(Ok(&bank), &mut link).homed();
        let drive = [0.5, -0.25, 0.0];
        rig.host.send(&HostToDevice::SetMode(Mode::ConstantCurrent {
            currents_a: drive,
        }));
        rig.host.send(&HostToDevice::Arm);
        let mut reports = Vec::new();
        for t in 1..=40 {
            rig.plant.interlocks.estop = t >= 21;
            reports.push(rig.step());
        }
        assert!(reports[..20].iter().all(|r| r.state == WireState::Armed));
        assert!(reports[..20].iter().all(|r| r.currents_a == drive));
        assert_eq!(rig.plant.driven[..20], [Some(drive); 20]);
        assert!(reports[20..].iter().all(|r| r.state == WireState::Fault));
        assert!(reports[20..].iter().all(|r| r.currents_a == [0.0; 3]));
        assert_eq!(rig.plant.driven[20..], [None; 20]);
        let e_stop = |tick| DeviceToHost::Fault {
            tick,
            reason: FaultReason::EStop,
            detail: 0,
        };
        assert_eq!(rig.faults(), [e_stop(21)]);
        assert_eq!(rig.app.telemetry().fault, Some(FaultReason::EStop));
        // Cleared and armed while still pressed: the arm is refused with the e-stop (queued
        // before tick 41 runs), and tick 41 latches it again.
        rig.host.send(&HostToDevice::ClearFault);
        rig.host.send(&HostToDevice::Arm);
        let r = rig.step();
        assert_eq!((r.state, r.currents_a), (WireState::Fault, [0.0; 3]));
        assert_eq!(rig.plant.driven.last(), Some(&None));
        assert_eq!(rig.faults(), [e_stop(21), e_stop(40), e_stop(41)]);
        // Released: still latched until cleared; then arming drives the motors again.
        rig.plant.interlocks.estop = false;
        let r = rig.step();
        assert_eq!(
            (r.state, rig.plant.driven.last()),
            (WireState::Fault, Some(&None))
        );
        rig.host.send(&HostToDevice::ClearFault);
        rig.host.send(&HostToDevice::Arm);
        let r = rig.step();
        assert_eq!((r.state, r.currents_a), (WireState::Armed, drive));
        assert_eq!(rig.plant.driven.last(), Some(&Some(drive)));
        assert_eq!(rig.faults().len(), 3);
    }

    /// `SetMode` while armed: refused (the mode stays), one `BadCommand` Fault frame (detail
    /// 3) at once, the motors disabled from the next tick.
    #[test]
    fn set_mode_while_armed_is_refused_with_a_fault_frame() {
        let bytes = flat_patch();
        let bank = parse(&bytes);
        let mut link = Link::new();
        let mut rig = Rig::new(Ok(&bank), &mut link);
        rig.host.send(&HostToDevice::ZeroEncoders);
        rig.host.send(&HostToDevice::Arm);
        for _ in 0..5 {
            assert_eq!(rig.step().state, WireState::Armed);
        }
        rig.host.send(&HostToDevice::SetMode(Mode::ConstantCurrent {
            currents_a: [1.0; 3],
        }));
        let r = rig.tick();
        rig.host.pump();
        assert_eq!((r.state, r.currents_a), (WireState::Fault, [0.0; 3]));
        assert_eq!(rig.plant.driven.last(), Some(&None));
        assert_eq!(
            rig.faults(),
            [DeviceToHost::Fault {
                tick: 5,
                reason: FaultReason::BadCommand,
                detail: crate::tick::BAD_COMMAND_SET_MODE_ARMED,
            }]
        );
        assert_eq!(rig.app.telemetry().mode, Mode::Render);
    }

    /// After a watchdog reset the device boots latched in `WatchdogReset`, reported once
    /// after the boot `Hello` and its reset cause: arming is refused (zero current) until
    /// `ClearFault`.
    #[test]
    fn a_watchdog_reset_is_latched_until_cleared() {
        let bytes = flat_patch();
        let bank = parse(&bytes);
        let mut link = Link::new();
        let mut rig = Rig::new(Ok(&bank), &mut link).after_reset(ResetCause::IndependentWatchdog);
        rig.host.send(&HostToDevice::ZeroEncoders);
        rig.host.send(&HostToDevice::Arm);
        for _ in 0..3 {
            let r = rig.tick();
            assert_eq!((r.state, r.currents_a), (WireState::Fault, [0.0; 3]));
            rig.host.pump();
            rig.host.send(&HostToDevice::Heartbeat);
        }
        assert!(rig.plant.driven.iter().all(Option::is_none));
        let watchdog = DeviceToHost::Fault {
            tick: 0,
            reason: FaultReason::WatchdogReset,
            detail: 0,
        };
        assert!(matches!(rig.host.sent[0], DeviceToHost::Hello { .. }));
        // At boot, then as the refusal of the Arm (applied before the first tick).
        let faults = rig.faults();
        assert_eq!(
            rig.host.sent[1],
            DeviceToHost::Reset {
                cause: ResetCause::IndependentWatchdog
            }
        );
        assert_eq!(rig.host.sent[2], watchdog);
        assert_eq!(faults, [watchdog.clone(), watchdog]);
        assert_eq!(rig.app.telemetry().fault, Some(FaultReason::WatchdogReset));
        rig.host.send(&HostToDevice::ClearFault);
        rig.host.send(&HostToDevice::Arm);
        let r = rig.tick();
        assert_eq!(r.state, WireState::Armed);
    }

    /// An amplifier's fault output latches `AmplifierFault` with the motor as detail, with or
    /// without a valid bank, ahead of the invalid bank's own fault.
    #[test]
    fn an_amplifier_fault_names_the_motor() {
        let bytes = flat_patch();
        let bank = parse(&bytes);
        for bank in [Ok(&bank), Err(BankError::BadMagic)] {
            let mut link = Link::new();
            let mut rig = Rig::new(bank, &mut link).homed();
            rig.plant.interlocks.amplifier_fault = [false, false, true];
            rig.host.send(&HostToDevice::Arm);
            let r = rig.tick();
            rig.host.pump();
            assert_eq!((r.state, r.currents_a), (WireState::Fault, [0.0; 3]));
            assert_eq!(rig.plant.driven, [None]);
            let last = rig.host.sent.last().cloned();
            assert_eq!(
                last,
                Some(DeviceToHost::Fault {
                    tick: 1,
                    reason: FaultReason::AmplifierFault,
                    detail: 2
                })
            );
        }
    }

    /// A slow link (one byte a tick, so a frame takes several ticks) is not silent; a link
    /// that delivers only garbage is, once the link grace (30 ticks here) has run out.
    #[test]
    fn slow_link_stays_alive_and_garbage_alone_is_silence() {
        const GRACE: u32 = 30;
        let bytes = flat_patch();
        let bank = parse(&bytes);
        let mut link = Link::new();
        let mut rig = Rig::with_grace(Ok(&bank), &mut link, GRACE);
        let mut buf = [0u8; MAX_FRAME];
        rig.host
            .driver
            .put_rx(encode_frame(&HostToDevice::ZeroEncoders, &mut buf).unwrap());
        rig.host
            .driver
            .put_rx(encode_frame(&HostToDevice::Arm, &mut buf).unwrap());
        rig.tick();
        // Heartbeats trickled one byte per tick: never 10 ticks without a byte.
        let beat = encode_frame(&HostToDevice::Heartbeat, &mut buf)
            .unwrap()
            .to_vec();
        let mut trickle: Vec<u8> = Vec::new();
        let mut states = Vec::new();
        for _ in 0..200 {
            if trickle.is_empty() {
                trickle.extend_from_slice(&beat);
            }
            rig.host.driver.put_rx(&[trickle.remove(0)]);
            states.push(rig.tick().state);
        }
        assert!(states.iter().all(|&s| s == WireState::Armed));
        assert!(rig.app.telemetry().counters.rx_frames > 20);
        // Now one garbage byte a tick (after what is left of a heartbeat): alive for the
        // grace, then silent.
        let mut states = Vec::new();
        for _ in 0..200u32 {
            trickle.push(0x55);
            rig.host.driver.put_rx(&[trickle.remove(0)]);
            states.push(rig.tick().state);
        }
        let limit = (GRACE + firmware_link_timeout()) as usize;
        assert!(states[..limit - 1].iter().all(|&s| s == WireState::Armed));
        // The partial heartbeat may complete up to a frame's length into the garbage.
        assert!(
            states[limit + beat.len()..]
                .iter()
                .all(|&s| s == WireState::Fault)
        );
        assert_eq!(rig.app.telemetry().fault, Some(FaultReason::LinkSilent));
    }

    /// With the board's grace (none: only valid frames count as link activity), a link that
    /// delivers only garbage, a byte every tick, keeps the device armed for at most the
    /// bank's link timeout after the last valid frame, as a silent one does.
    #[test]
    fn garbage_only_link_faults_within_the_timeout_with_the_board_grace() {
        let bytes = flat_patch();
        let bank = parse(&bytes);
        for garbage in [true, false] {
            let mut link = Link::new();
            let mut rig = Rig::new(Ok(&bank), &mut link);
            let mut buf = [0u8; MAX_FRAME];
            rig.host
                .driver
                .put_rx(encode_frame(&HostToDevice::ZeroEncoders, &mut buf).unwrap());
            rig.host
                .driver
                .put_rx(encode_frame(&HostToDevice::Arm, &mut buf).unwrap());
            assert_eq!(rig.tick().state, WireState::Armed);
            let mut armed = 0;
            for _ in 0..200 {
                if garbage {
                    rig.host.driver.put_rx(&[0x55, 0x13, 0x00]);
                }
                if rig.tick().state == WireState::Armed {
                    armed += 1;
                }
            }
            assert!(
                armed <= firmware_link_timeout(),
                "garbage {garbage}: {armed}"
            );
            assert_eq!(rig.app.telemetry().fault, Some(FaultReason::LinkSilent));
        }
    }

    /// The flat patch's link timeout in ticks (1 kHz).
    fn firmware_link_timeout() -> u32 {
        crate::fixtures::FIXTURE_LINK_TIMEOUT_MS
    }

    /// A link that carries only one byte per tick (a tenth of a telemetry frame): the ticks
    /// are exactly those of a fast link (the tick never waits for it), the frames that do not
    /// fit are dropped whole and counted, and every frame the host receives decodes whole.
    #[test]
    fn a_one_byte_per_tick_link_costs_the_tick_nothing_and_loses_only_whole_frames() {
        let bytes = flat_patch();
        let bank = parse(&bytes);
        let run = |per_tick: usize| {
            let mut link = Link::new();
            let mut rig = Rig::new(Ok(&bank), &mut link);
            rig.host.per_tick = per_tick;
            rig.host.send(&HostToDevice::ZeroEncoders);
            rig.host.send(&HostToDevice::Arm);
            let mut reports = Vec::new();
            for t in 0..3000 {
                // Heartbeats stay in the incoming direction, which is not throttled.
                if t % 2 == 0 {
                    rig.host.send(&HostToDevice::Heartbeat);
                }
                rig.plant.counts = [t / 3, -(t / 5), t / 7];
                reports.push(rig.tick());
                rig.host.pump();
            }
            (reports, rig.host.sent, rig.app.telemetry().counters)
        };
        let (fast, fast_sent, fast_counters) = run(usize::MAX);
        let (slow, slow_sent, slow_counters) = run(1);
        // Ticks identical, cycle counts included: the link's speed does not reach the tick.
        assert_eq!(fast, slow);
        assert_eq!(fast_counters.tx_dropped, 0);
        // Boot Hello + 300 telemetry frames queued; the fast host got them all.
        assert_eq!(fast_sent.len(), 301);
        // The slow one got whole frames only (the decoder would have failed on a torn one),
        // and what it did not get was counted as dropped.
        assert!(slow_counters.tx_dropped > 200, "{slow_counters:?}");
        let got = slow_sent.len() as u32;
        // The last telemetry frame counts frames dropped before it; frames still queued or
        // being sent when the run ends are neither received nor dropped (at most TX_FRAMES).
        let dropped = slow_counters.tx_dropped;
        assert!(got + dropped <= 301 && got + dropped + crate::link::TX_FRAMES as u32 >= 301);
        assert!(
            slow_sent
                .iter()
                .skip(1)
                .all(|m| matches!(m, DeviceToHost::Telemetry(_)))
        );
    }

    /// A backlog of commands (a host that stalled, then sent them at once) is applied at most
    /// [`MAX_COMMANDS_PER_TICK`] a tick, in order: the last of ten lands in the third tick.
    #[test]
    fn a_burst_of_commands_is_applied_a_few_a_tick_in_order() {
        let bytes = flat_patch();
        let bank = parse(&bytes);
        let mut link = Link::new();
        let mut rig = Rig::new(Ok(&bank), &mut link).homed();
        for _ in 0..9 {
            rig.host.send(&HostToDevice::ClearFault);
        }
        rig.host.send(&HostToDevice::Arm);
        let states: Vec<WireState> = (0..4).map(|_| rig.tick().state).collect();
        assert_eq!(
            states,
            [
                WireState::Disarmed,
                WireState::Disarmed,
                WireState::Armed,
                WireState::Armed
            ]
        );
        assert_eq!(rig.app.telemetry().counters.rx_frames, 10);
    }

    /// A flooding host (200 heartbeats and 40 commands, an `Arm` among them, in one burst
    /// between two ticks) then `Disarm`: the next tick runs disarmed, and so does every tick
    /// while the backlog drains (the `Arm` sent before the `Disarm` is superseded). Heartbeats
    /// took no queue slot, so what was shed is exactly the commands beyond the queue's 15.
    #[test]
    fn a_flooding_hosts_disarm_takes_effect_at_the_next_tick() {
        let bytes = flat_patch();
        let bank = parse(&bytes);
        let mut link = Link::new();
        let mut rig = Rig::new(Ok(&bank), &mut link).homed();
        rig.host.send(&HostToDevice::Arm);
        assert_eq!(rig.tick().state, WireState::Armed);
        for i in 0..240 {
            rig.host.send(&match i % 6 {
                0 if i == 6 => HostToDevice::Arm,
                0 => HostToDevice::ClearFault,
                _ => HostToDevice::Heartbeat,
            });
        }
        rig.host.send(&HostToDevice::Disarm);
        for t in 0..10 {
            let report = rig.tick();
            assert_eq!(
                report.state,
                WireState::Disarmed,
                "tick {t} after the Disarm"
            );
            assert!(report.currents_a.iter().all(|&i| i == 0.0));
        }
        let c = rig.app.telemetry().counters;
        // Arm, 240 flood frames, Disarm; 40 commands of which 15 fit the queue.
        assert_eq!(c.rx_frames, 1 + 240 + 1);
        assert_eq!(c.rx_dropped, 40 - 15);
        assert_eq!(c.rx_errors, 0);
    }

    /// A host that stopped reading lets telemetry fill the outgoing queue; a fault raised
    /// meanwhile still reaches it once it reads again.
    #[test]
    fn a_fault_raised_while_the_host_is_not_reading_is_not_lost() {
        let bytes = flat_patch();
        let bank = parse(&bytes);
        let mut link = Link::new();
        let mut rig = Rig::new(Ok(&bank), &mut link);
        rig.host.send(&HostToDevice::ZeroEncoders);
        rig.host.send(&HostToDevice::Arm);
        // 200 ticks unread (the host's commands still arrive: the incoming side is apart).
        for _ in 0..200 {
            rig.host.send(&HostToDevice::Heartbeat);
            rig.tick();
        }
        assert!(rig.app.telemetry().counters.tx_dropped > 10);
        rig.plant.interlocks.estop = true;
        let r = rig.tick();
        assert_eq!(r.state, WireState::Fault);
        rig.host.pump();
        let e_stop = DeviceToHost::Fault {
            tick: r.tick,
            reason: FaultReason::EStop,
            detail: 0,
        };
        assert!(rig.host.sent.contains(&e_stop), "{:?}", rig.host.sent);
    }

    /// The board's tick sequence (`firmware/board/src/main.rs`, `haptic`): wait for the
    /// ticker, `TickWatch::begin`, `App::tick` with the last tick's overrun, `TickWatch::end`,
    /// and on an overrun the ticker restarted from now (`Ticker::reset`, modelled here). One
    /// wake 1.2 periods late among on-time ticks is exactly one overrun: the armed device
    /// faults `Overrun` once, and after `ClearFault` and `Arm` it stays armed.
    #[test]
    fn the_boards_tick_sequence_recovers_from_one_late_wake() {
        use crate::deadline::TickWatch;
        const P: u32 = 168_000;
        /// A cycle counter the test sets.
        struct Counter(core::cell::Cell<u32>);
        impl CycleCounter for Counter {
            fn cycles(&self) -> u32 {
                self.0.get()
            }
        }
        let bytes = flat_patch();
        let bank = parse(&bytes);
        let mut link = Link::new();
        let mut rig = Rig::new(Ok(&bank), &mut link);
        let clock = Counter(core::cell::Cell::new(0));
        rig.host.send(&HostToDevice::ZeroEncoders);
        rig.host.send(&HostToDevice::Arm);
        let mut watch = TickWatch::new(P);
        let (mut expiry, mut overrun) = (u32::MAX - 500 * P, false);
        let mut states = Vec::new();
        for k in 0..3_000u32 {
            let latency = if k == 1_000 { 6 * P / 5 } else { 40 };
            let wake = expiry.wrapping_add(latency);
            clock.0.set(wake);
            watch.begin(clock.cycles());
            states.push(rig.app.tick(&mut rig.plant, &clock, overrun).unwrap().state);
            let end = wake.wrapping_add(20_000);
            clock.0.set(end);
            let timing = watch.end(clock.cycles());
            rig.app.record_tick_cycles(timing.cycles);
            overrun = timing.overrun;
            expiry = expiry.wrapping_add(P);
            if overrun {
                expiry = end.wrapping_add(30 + P);
            }
            rig.host.pump();
            rig.host.send(&HostToDevice::Heartbeat);
            if k == 1_500 {
                rig.host.send(&HostToDevice::ClearFault);
                rig.host.send(&HostToDevice::Arm);
            }
        }
        assert_eq!(rig.app.telemetry().counters.overruns, 1);
        // Tick 1,001 woke late; tick 1,002 is told and faults; from tick 1,502 (after the
        // commands sent at tick 1,501) it runs armed again.
        assert!(states[..1_001].iter().all(|&s| s == WireState::Armed));
        assert!(states[1_001..1_501].iter().all(|&s| s == WireState::Fault));
        assert!(states[1_501..].iter().all(|&s| s == WireState::Armed));
        assert_eq!(
            rig.faults(),
            [DeviceToHost::Fault {
                tick: 1_002,
                reason: FaultReason::Overrun,
                detail: 0
            }]
        );
    }

    /// `Arm` before any `ZeroEncoders` is refused with `NotReferenced` (latched, reported,
    /// zero current); after homing, `ClearFault` and `Arm`, the motors are driven. Every reset
    /// cause is reported after the boot `Hello` and after each `Hello` reply; only the
    /// watchdogs latch a fault.
    #[test]
    fn arming_needs_homing_and_every_reset_cause_is_reported() {
        let bytes = flat_patch();
        let bank = parse(&bytes);
        let mut link = Link::new();
        let mut rig = Rig::new(Ok(&bank), &mut link).after_reset(ResetCause::BrownOut);
        let drive = [0.5, -0.25, 0.0];
        rig.host.send(&HostToDevice::SetMode(Mode::ConstantCurrent {
            currents_a: drive,
        }));
        rig.host.send(&HostToDevice::Arm);
        for _ in 0..3 {
            let r = rig.step();
            assert_eq!((r.state, r.currents_a), (WireState::Fault, [0.0; 3]));
        }
        let reset = DeviceToHost::Reset {
            cause: ResetCause::BrownOut,
        };
        assert!(matches!(rig.host.sent[0], DeviceToHost::Hello { .. }));
        assert_eq!(rig.host.sent[1], reset);
        assert_eq!(
            rig.host.sent[2],
            DeviceToHost::Fault {
                tick: 0,
                reason: FaultReason::NotReferenced,
                detail: 0
            }
        );
        assert_eq!(rig.app.telemetry().fault, Some(FaultReason::NotReferenced));
        rig.host.send(&HostToDevice::Hello);
        rig.step();
        let n = rig.host.sent.len();
        assert!(matches!(rig.host.sent[n - 2], DeviceToHost::Hello { .. }));
        assert_eq!(rig.host.sent[n - 1], reset);
        rig.host.send(&HostToDevice::ClearFault);
        rig.host.send(&HostToDevice::ZeroEncoders);
        rig.host.send(&HostToDevice::Arm);
        let r = rig.step();
        assert_eq!((r.state, r.currents_a), (WireState::Armed, drive));
    }

    /// Whatever the chip's reset cause, the encoders start unreferenced: `ClearFault` and `Arm`
    /// right after boot are refused with `NotReferenced`; after homing the device arms.
    #[test]
    fn no_reset_cause_arms_without_homing() {
        for cause in [
            ResetCause::PowerOn,
            ResetCause::BrownOut,
            ResetCause::Pin,
            ResetCause::Software,
            ResetCause::IndependentWatchdog,
            ResetCause::WindowWatchdog,
            ResetCause::LowPower,
            ResetCause::Unknown,
        ] {
            let bytes = flat_patch();
            let bank = parse(&bytes);
            let mut link = Link::new();
            let mut rig = Rig::new(Ok(&bank), &mut link).after_reset(cause);
            rig.tick();
            rig.host.send(&HostToDevice::ClearFault);
            rig.host.send(&HostToDevice::Arm);
            let r = rig.tick();
            assert_eq!(r.state, WireState::Fault, "{cause:?}");
            assert_eq!(
                rig.app.telemetry().fault,
                Some(FaultReason::NotReferenced),
                "{cause:?}"
            );
            rig.host.send(&HostToDevice::ClearFault);
            rig.host.send(&HostToDevice::ZeroEncoders);
            rig.host.send(&HostToDevice::Arm);
            let r = rig.tick();
            assert_eq!(r.state, WireState::Armed, "{cause:?}");
        }
    }

    /// A bank whose current limit the board's amplifiers cannot deliver (2 A against an
    /// amplifier scaled to 1.5 A on motor 2): `AmplifierRange` naming the motor at boot, and
    /// every arm refused with it, cleared or not; amplifiers that can deliver it arm.
    #[test]
    fn a_current_limit_over_the_amplifier_range_refuses_to_arm() {
        use crate::amplifier::Amplifier;
        let bytes = flat_patch();
        let bank = parse(&bytes);
        assert_eq!(bank.device().current_limit_a, [2.0; 3]);
        let amps = |last: f32| {
            [
                Amplifier::escon(3.0, false),
                Amplifier::escon(3.0, false),
                Amplifier::escon(last, false),
            ]
        };
        let mut link = Link::new();
        let mut rig = Rig::new(Ok(&bank), &mut link).homed();
        rig.app.check_amplifiers(&amps(1.5));
        rig.refuses_every_arm(FaultReason::AmplifierRange, 2, &[]);

        let mut link = Link::new();
        let mut rig = Rig::new(Ok(&bank), &mut link).homed();
        rig.app.check_amplifiers(&amps(2.0));
        rig.host.send(&HostToDevice::Arm);
        let r = rig.tick();
        assert_eq!(r.state, WireState::Armed);
    }

    /// A chip whose option bytes leave brown-out reset off (FLASH_OPTCR's reset value,
    /// 0x0FFF_AAED: `BOR_LEV` = 11): `BrownOutLevel` (detail 0) at boot, and every arm refused
    /// with it, cleared or not, homed or not; the same word with `BOR_LEV` = 00 (level 3)
    /// arms once homed.
    #[test]
    fn brown_out_below_level_3_refuses_to_arm() {
        let bytes = flat_patch();
        let bank = parse(&bytes);
        let mut link = Link::new();
        let mut rig = Rig::new(Ok(&bank), &mut link).homed();
        rig.app.check_brown_out(0x0FFF_AAED);
        rig.refuses_every_arm(FaultReason::BrownOutLevel, 0, &[HostToDevice::ZeroEncoders]);

        // Level 3: no fault at boot; not homed, Arm is refused NotReferenced; after
        // ZeroEncoders it arms.
        let mut link = Link::new();
        let mut rig = Rig::new(Ok(&bank), &mut link);
        rig.app.check_brown_out(0x0FFF_AAE1);
        rig.host.pump();
        assert_eq!(rig.host.sent.len(), 1, "{:?}", rig.host.sent);
        rig.host.send(&HostToDevice::Arm);
        let r = rig.tick();
        assert_eq!(r.state, WireState::Fault);
        assert_eq!(rig.app.telemetry().fault, Some(FaultReason::NotReferenced));
        rig.host.send(&HostToDevice::ClearFault);
        rig.host.send(&HostToDevice::ZeroEncoders);
        rig.host.send(&HostToDevice::Arm);
        let r = rig.tick();
        assert_eq!(r.state, WireState::Armed);
    }

    #[test]
    fn invalid_bank_refuses_to_arm_and_says_why() {
        let mut link = Link::new();
        let mut rig = Rig::new(Err(BankError::BadMagic), &mut link);
        assert!(rig.app.haptic_loop().is_none());
        rig.host.send(&HostToDevice::Arm);
        rig.host.send(&HostToDevice::Hello);
        let mut reports = Vec::new();
        for _ in 0..3 {
            reports.push(rig.tick());
            rig.host.pump();
        }
        let code = u32::from(BankError::BadMagic.code());
        let no_bank = DeviceToHost::Hello {
            protocol: PROTOCOL_VERSION,
            bank_crc: None,
            scene_id: 0,
            node_count: 0,
        };
        let fault = |tick| DeviceToHost::Fault {
            tick,
            reason: FaultReason::InvalidBank,
            detail: code,
        };
        // Boot Hello; the arm refusal (before tick 1 ran); the Hello reply; the tick-1 fault.
        assert_eq!(
            rig.host.sent,
            [no_bank.clone(), fault(0), no_bank, fault(1)]
        );
        assert!(reports.iter().all(|a| a.currents_a == [0.0; 3]));
        assert!(reports.iter().all(|a| a.state == WireState::Fault));
        assert!(rig.plant.driven.iter().all(Option::is_none));
        assert_eq!(rig.app.telemetry().fault, Some(FaultReason::InvalidBank));
        // No loop: the body (two clock readings, 100 cycles apart) is all supervisor.
        for r in &reports {
            assert_eq!(r.body_cycles, 100);
            assert_eq!(r.phase_cycles.to_array(), [0, 0, 0, 0, 0, 100]);
        }
    }
}
