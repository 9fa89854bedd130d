//! The device application around the loop, the same on every platform: per tick it latches the
//! encoders, applies the host's link commands, runs [`HapticLoop::tick`], drives the motors and
//! sends faults and decimated telemetry. The hardware comes in through [`crate::hal`].
//!
//! A bank that fails validation leaves no loop to run: the application then keeps the motors at
//! zero current, reports [`FaultReason::InvalidBank`] with the [`BankError::code`] as detail at
//! boot and on every arm attempt, and answers `Hello` with `bank_crc: None`.

use bank_format::{
    Bank, BankError, Counters, DeviceToHost, FaultReason, FrameDecoder, HostToDevice, MAX_FRAME,
    Mode, PROTOCOL_VERSION, Telemetry, encode_frame, heapless,
};

use crate::hal::{Actuation, CycleCounter, LinkPort, Plant};
use crate::safety::{Fault, SafetyConfig, Supervisor, TickInput};
use crate::tick::{HapticLoop, LoopInput};

/// Telemetry goes out every this many ticks (100 Hz at 1 kHz).
pub const TELEMETRY_EVERY_TICKS: u32 = 10;
/// At most this many link bytes are read at each of the two link polls of a tick, so a flood
/// cannot stretch a tick.
pub const MAX_RX_BYTES_PER_POLL: usize = 64;
/// A link that delivers bytes but no valid frame for this many ticks more than the supervisor's
/// link timeout counts as silent too (a host sending only garbage is as good as none). Bytes
/// alone keep the link alive for that long because a slow UART (QEMU's carries about two bytes
/// a tick) needs several ticks for one frame.
pub const GARBLED_LINK_GRACE_TICKS: u32 = 90;
/// Outgoing bytes buffered per tick (a message that does not fit is dropped).
const TX_CAPACITY: usize = 3 * MAX_FRAME;

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

/// The application state (no heap: frame buffers are fixed-size).
pub struct App<'b> {
    core: Core<'b>,
    rx: FrameDecoder<HostToDevice>,
    ticks_since_host_frame: u32,
    ticks_since_host_byte: u32,
    last_tick_cycles: u32,
    tx: heapless::Vec<u8, TX_CAPACITY>,
}

impl<'b> App<'b> {
    /// The application over the result of validating the bank region
    /// ([`Bank::parse`]); queues the boot `Hello` (and the `InvalidBank` fault without a bank).
    pub fn new(bank: Result<&'b Bank<'b>, BankError>) -> App<'b> {
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
            rx: FrameDecoder::new(),
            ticks_since_host_frame: 0,
            ticks_since_host_byte: 0,
            last_tick_cycles: 0,
            tx: heapless::Vec::new(),
        };
        app.queue(&app.hello());
        app
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

    /// One tick: encoders, link commands, the loop, motors, faults and telemetry. `overrun`
    /// says whether the previous tick overran its period. Only a plant error stops it.
    pub fn tick<P: Plant, L: LinkPort, C: CycleCounter>(
        &mut self,
        plant: &mut P,
        link: &mut L,
        clock: &C,
        overrun: bool,
    ) -> Result<Actuation, P::Error> {
        let tick = self.tick_count().wrapping_add(1);
        let counts = plant.read_encoders(tick)?;
        self.poll_link(link);
        let start = clock.cycles();
        let input = LoopInput {
            encoder_counts: counts,
            overrun,
            link_silence_ticks: self.link_silence(),
        };
        let (out, new_fault) = match &mut self.core {
            Core::Loop(lp) => {
                let out = lp.tick(input);
                let act = Actuation {
                    tick: out.tick,
                    currents_a: out.currents_a,
                    force_n: out.tool_force_n,
                    state: out.state.wire(),
                    contact_nodes: out.contacts.len() as u8,
                    body_cycles: 0,
                    tick_cycles: self.last_tick_cycles,
                };
                (act, out.new_fault)
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
                    ..TickInput::quiet()
                });
                let act = Actuation {
                    tick: *tick,
                    currents_a: s.currents_a,
                    force_n: [0.0; 3],
                    state: s.state.wire(),
                    contact_nodes: 0,
                    body_cycles: 0,
                    tick_cycles: self.last_tick_cycles,
                };
                (act, s.new_fault)
            }
        };
        let out = Actuation {
            body_cycles: clock.cycles().wrapping_sub(start),
            ..out
        };
        self.ticks_since_host_frame = self.ticks_since_host_frame.saturating_add(1);
        self.ticks_since_host_byte = self.ticks_since_host_byte.saturating_add(1);
        plant.actuate(&out)?;
        // Again after the plant exchange: a UART holding one byte at a time (QEMU's) may have
        // received another meanwhile; what arrives now applies from the next tick.
        self.poll_link(link);
        if let Some(f) = new_fault {
            self.queue(&DeviceToHost::Fault {
                tick: out.tick,
                reason: f.reason,
                detail: f.detail,
            });
        }
        if out.tick.is_multiple_of(TELEMETRY_EVERY_TICKS) {
            self.queue(&DeviceToHost::Telemetry(self.telemetry()));
        }
        link.write(&self.tx);
        self.tx.clear();
        Ok(out)
    }

    /// Read and apply what the link has received, at most [`MAX_RX_BYTES_PER_POLL`] bytes.
    fn poll_link<L: LinkPort>(&mut self, link: &mut L) {
        for _ in 0..MAX_RX_BYTES_PER_POLL {
            let Some(byte) = link.read_byte() else { break };
            self.receive(byte);
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
                currents_a: [0.0; 3],
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
    /// the last byte, or since the last valid frame less [`GARBLED_LINK_GRACE_TICKS`].
    fn link_silence(&self) -> u32 {
        self.ticks_since_host_byte.max(
            self.ticks_since_host_frame
                .saturating_sub(GARBLED_LINK_GRACE_TICKS),
        )
    }

    /// Feed one link byte; apply the command it completes, count it or the dropped frame.
    fn receive(&mut self, byte: u8) {
        self.ticks_since_host_byte = 0;
        match self.rx.feed(byte) {
            None => {}
            Some(Err(_)) => {
                let c = self.counters_mut();
                c.rx_errors = c.rx_errors.wrapping_add(1);
            }
            Some(Ok(cmd)) => {
                let c = self.counters_mut();
                c.rx_frames = c.rx_frames.wrapping_add(1);
                self.ticks_since_host_frame = 0;
                self.command(cmd);
            }
        }
    }

    fn command(&mut self, cmd: HostToDevice) {
        match cmd {
            HostToDevice::Hello => self.queue(&self.hello()),
            HostToDevice::Arm => self.arm(),
            HostToDevice::Disarm => {
                if let Core::Loop(lp) = &mut self.core {
                    lp.disarm();
                }
            }
            HostToDevice::SetMode(mode) => {
                if let Core::Loop(lp) = &mut self.core {
                    lp.set_mode(mode);
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

    /// Arm, or say why not: a refusal re-sends the latched fault (the invalid bank's code).
    fn arm(&mut self) {
        let tick = self.tick_count();
        let refused = match &mut self.core {
            Core::Loop(lp) => match lp.arm() {
                Ok(()) => None,
                Err(_) => lp.supervisor().fault(),
            },
            Core::NoBank {
                supervisor, code, ..
            } => {
                // Always refused (`bank_valid: false`); the reason is the bank.
                let _ = supervisor.arm(false);
                Some(Fault {
                    reason: FaultReason::InvalidBank,
                    detail: *code,
                })
            }
        };
        if let Some(f) = refused {
            self.queue(&DeviceToHost::Fault {
                tick,
                reason: f.reason,
                detail: f.detail,
            });
        }
    }

    /// Encode `msg` into the outgoing buffer; dropped when it does not fit this tick.
    fn queue(&mut self, msg: &DeviceToHost) {
        let mut buf = [0u8; MAX_FRAME];
        if let Ok(frame) = encode_frame(msg, &mut buf) {
            let _ = self.tx.extend_from_slice(frame);
        }
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
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::indexing_slicing, clippy::panic)]
mod tests {
    extern crate std;
    use super::*;
    use crate::fixtures::flat_patch;
    use bank_format::{FrameDecoder, State as WireState};
    use std::vec::Vec;

    /// Encoders from a list (then held), currents recorded.
    struct FakePlant {
        counts: [i32; 3],
        out: Vec<Actuation>,
        fail_at: Option<u32>,
    }

    impl Plant for FakePlant {
        type Error = u32;
        fn read_encoders(&mut self, tick: u32) -> Result<[i32; 3], u32> {
            match self.fail_at {
                Some(t) if t == tick => Err(tick),
                _ => Ok(self.counts),
            }
        }
        fn actuate(&mut self, out: &Actuation) -> Result<(), u32> {
            self.out.push(*out);
            Ok(())
        }
    }

    #[derive(Default)]
    struct FakeLink {
        rx: Vec<u8>,
        tx: FrameDecoder<DeviceToHost>,
        sent: Vec<DeviceToHost>,
    }

    impl FakeLink {
        fn send(&mut self, cmd: &HostToDevice) {
            let mut buf = [0u8; MAX_FRAME];
            self.rx
                .extend_from_slice(encode_frame(cmd, &mut buf).unwrap());
        }
    }

    impl LinkPort for FakeLink {
        fn read_byte(&mut self) -> Option<u8> {
            (!self.rx.is_empty()).then(|| self.rx.remove(0))
        }
        fn write(&mut self, bytes: &[u8]) {
            for r in self.tx.feed_slice(bytes) {
                self.sent.push(r.unwrap());
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

    fn rig() -> (FakePlant, FakeLink, FakeClock) {
        let plant = FakePlant {
            counts: [0, 0, 0],
            out: Vec::new(),
            fail_at: None,
        };
        (
            plant,
            FakeLink::default(),
            FakeClock(core::cell::Cell::new(0)),
        )
    }

    #[test]
    fn commands_arm_and_telemetry_flows() {
        let bytes = flat_patch();
        let bank = Bank::parse(bytes.as_slice()).unwrap();
        let mut app = App::new(Ok(&bank));
        let (mut plant, mut link, clock) = rig();
        link.send(&HostToDevice::Hello);
        link.send(&HostToDevice::Arm);
        // A corrupt frame between them is dropped and counted.
        link.rx.extend_from_slice(&[0x03, 0x11, 0x22, 0x00]);
        link.send(&HostToDevice::SetMode(Mode::Transparent));
        for _ in 0..20 {
            app.tick(&mut plant, &mut link, &clock, false).unwrap();
            link.send(&HostToDevice::Heartbeat);
        }
        let hello = DeviceToHost::Hello {
            protocol: PROTOCOL_VERSION,
            bank_crc: Some(bank.crc()),
            scene_id: bank.scene_id(),
            node_count: bank.node_count() as u16,
        };
        // Boot Hello, the requested Hello, telemetry at ticks 10 and 20.
        assert_eq!(link.sent[..2], [hello.clone(), hello]);
        let tel: Vec<_> = link.sent[2..]
            .iter()
            .map(|m| match m {
                DeviceToHost::Telemetry(t) => t.clone(),
                other => panic!("{other:?}"),
            })
            .collect();
        assert_eq!(tel.iter().map(|t| t.tick).collect::<Vec<_>>(), [10, 20]);
        assert_eq!(tel[1].state, WireState::Armed);
        assert_eq!(tel[1].mode, Mode::Transparent);
        // Hello, Arm, SetMode and the 19 heartbeats read so far.
        assert_eq!(tel[1].counters.rx_frames, 3 + 19);
        assert_eq!(tel[1].counters.rx_errors, 1);
        assert_eq!(plant.out.len(), 20);
        assert!(plant.out.iter().all(|a| a.state == WireState::Armed));
        // The body was measured between two readings of the clock.
        assert!(plant.out.iter().all(|a| a.body_cycles == 100));
    }

    #[test]
    fn silence_while_armed_faults_and_reports_once() {
        let bytes = flat_patch();
        let bank = Bank::parse(bytes.as_slice()).unwrap();
        let mut app = App::new(Ok(&bank));
        let (mut plant, mut link, clock) = rig();
        link.send(&HostToDevice::Arm);
        for _ in 0..30 {
            app.tick(&mut plant, &mut link, &clock, false).unwrap();
        }
        let faults: Vec<_> = link
            .sent
            .iter()
            .filter(|m| matches!(m, DeviceToHost::Fault { .. }))
            .collect();
        // The frame arrived at tick 1; tick 12 is the 11th without one.
        assert_eq!(
            faults,
            [&DeviceToHost::Fault {
                tick: 12,
                reason: FaultReason::LinkSilent,
                detail: 11
            }]
        );
        assert!(plant.out[11..].iter().all(|a| a.currents_a == [0.0; 3]));
        // A plant error stops the tick and is returned.
        plant.fail_at = Some(31);
        assert_eq!(app.tick(&mut plant, &mut link, &clock, false), Err(31));
    }

    /// A slow link (one byte a tick, so a frame takes several ticks) is not silent; a link
    /// that delivers only garbage is, once the garbled-link grace has run out.
    #[test]
    fn slow_link_stays_alive_and_garbage_alone_is_silence() {
        let bytes = flat_patch();
        let bank = Bank::parse(bytes.as_slice()).unwrap();
        let mut app = App::new(Ok(&bank));
        let (mut plant, mut link, clock) = rig();
        link.send(&HostToDevice::Arm);
        app.tick(&mut plant, &mut link, &clock, false).unwrap();
        // Heartbeats trickled one byte per tick: never 10 ticks without a byte.
        let mut buf = [0u8; MAX_FRAME];
        let beat = encode_frame(&HostToDevice::Heartbeat, &mut buf)
            .unwrap()
            .to_vec();
        let mut slow = SlowLink::default();
        for _ in 0..200 {
            if slow.queue.is_empty() {
                slow.queue.extend_from_slice(&beat);
            }
            app.tick(&mut plant, &mut slow, &clock, false).unwrap();
        }
        assert!(plant.out.iter().all(|a| a.state == WireState::Armed));
        assert!(app.telemetry().counters.rx_frames > 20);
        // Now one garbage byte a tick (after what is left of a heartbeat): alive for the
        // grace, then silent.
        let mut states = Vec::new();
        for _ in 0..200u32 {
            slow.queue.push(0x55);
            app.tick(&mut plant, &mut slow, &clock, false).unwrap();
            states.push(plant.out.last().unwrap().state);
        }
        let limit = (GARBLED_LINK_GRACE_TICKS + firmware_link_timeout()) as usize;
        assert!(states[..limit - 1].iter().all(|&s| s == WireState::Armed));
        // The partial heartbeat may complete up to a frame's length into the garbage.
        assert!(
            states[limit + beat.len()..]
                .iter()
                .all(|&s| s == WireState::Fault)
        );
        assert_eq!(app.telemetry().fault, Some(FaultReason::LinkSilent));
    }

    fn firmware_link_timeout() -> u32 {
        crate::safety::DEFAULT_LINK_TIMEOUT_TICKS
    }

    /// Delivers one queued byte per call of a tick (two reads per tick: the second finds none).
    #[derive(Default)]
    struct SlowLink {
        queue: Vec<u8>,
        read_this_tick: bool,
    }

    impl LinkPort for SlowLink {
        fn read_byte(&mut self) -> Option<u8> {
            if self.read_this_tick || self.queue.is_empty() {
                self.read_this_tick = false;
                return None;
            }
            self.read_this_tick = true;
            Some(self.queue.remove(0))
        }
        fn write(&mut self, _: &[u8]) {}
    }

    #[test]
    fn invalid_bank_refuses_to_arm_and_says_why() {
        let mut app = App::new(Err(BankError::BadMagic));
        assert!(app.haptic_loop().is_none());
        let (mut plant, mut link, clock) = rig();
        link.send(&HostToDevice::Arm);
        link.send(&HostToDevice::Hello);
        for _ in 0..3 {
            app.tick(&mut plant, &mut link, &clock, false).unwrap();
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
        assert_eq!(link.sent, [no_bank.clone(), fault(0), no_bank, fault(1)]);
        assert!(plant.out.iter().all(|a| a.currents_a == [0.0; 3]));
        assert!(plant.out.iter().all(|a| a.state == WireState::Fault));
        assert_eq!(app.telemetry().fault, Some(FaultReason::InvalidBank));
    }
}
