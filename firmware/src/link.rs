//! The host link between the tick and the link driver: two bounded single-producer,
//! single-consumer queues, so the tick never waits on I/O and never encodes or decodes a
//! frame.
//!
//! The tick ([`crate::app::App::tick`], high priority) owns a [`TickEnd`]: it pushes whole
//! messages (telemetry snapshots, faults, `Hello`), not yet encoded, and pops the host's
//! commands, already decoded. A lower-priority driver (a UART or USB CDC task, in thread mode)
//! owns the [`DriverEnd`]: it takes each message, encodes it as a link frame (postcard, CRC,
//! COBS: [`encode_frame`]) and hands out its bytes as fast as the wire accepts them, and feeds
//! the bytes it received to the command decoder ([`DriverEnd::put_rx`]), which queues each
//! valid command. Neither end ever blocks:
//!
//! - a message that finds the outgoing queue full is dropped whole and counted
//!   ([`TickEnd::send`] returns `false`; [`TickEnd::tx_dropped`], telemetry's `tx_dropped`); a
//!   message once queued goes out as one whole frame, so the host never sees a torn frame (a
//!   message that would not encode, which the bounded message set cannot produce, is dropped
//!   and counted the same way);
//! - periodic telemetry ([`TickEnd::send_periodic`]) leaves the last [`TX_RESERVED`] slots
//!   free, so a host that stops reading fills the queue with telemetry but a fault raised
//!   meanwhile (or a reply) still finds room and reaches the host once it reads again;
//! - a received frame that does not decode (CRC, COBS, too short or long, not a command) is
//!   dropped and counted ([`RxCounts::errors`], telemetry's `rx_errors`); a decoded command
//!   that finds the incoming queue full is dropped and counted ([`RxCounts::dropped`],
//!   telemetry's `rx_dropped`);
//! - two commands never take a queue slot, so a flood cannot shed them: a `Heartbeat` only
//!   says the host is there, which the count of valid frames ([`RxCounts::frames`]) carries;
//!   a `Disarm` is counted ([`RxCounts::disarms`]) and the tick looks at that count before
//!   its queue every tick ([`TickEnd::poll`]), so a `Disarm` takes effect at the first tick
//!   after it arrived whatever the queue holds. Each queued command carries the count of
//!   `Disarm`s received before it, which keeps the host's order: an `Arm` sent before a
//!   `Disarm` that is already applied is skipped, and a command sent after a `Disarm` the tick
//!   has not applied yet comes out after that `Disarm` ([`TickEnd::receive`]);
//! - a new connection ([`DriverEnd::connected`], the board's USB task calls it when the
//!   host's serial port opens) starts clean: the decoder drops a frame torn by the
//!   disconnect, and the messages queued for the previous connection (stale telemetry,
//!   replies, faults) are dropped and counted (`tx_dropped`). What they said is not lost: the
//!   latched fault is in every telemetry frame (`state`, `fault`), and the host's `Hello`
//!   gets the identity and the reset cause again. The host leads every connection with a
//!   0x00, which ends whatever the device's decoder holds, so its `Hello` decodes either way.
//!
//! The queues are lock-free (heapless `spsc`) and the counters atomic, so the two ends may
//! live at different interrupt priorities on one core. Encoding and decoding in the driver
//! keep postcard, the CRC, COBS and the frame buffers out of the tick: the tick only moves a
//! message (a few hundred bytes) into its queue slot and takes at most
//! [`crate::app::MAX_COMMANDS_PER_TICK`] commands (about 20 bytes each) out of the other
//! (besides discarding, never applying, at most the queue's length of superseded `Arm`s), so
//! however the host's bytes bunch up (a burst after a stall, a flood of garbage), what the
//! link costs the tick is bounded by a few commands, not by the bytes that arrived.

use bank_format::{
    DeviceToHost, FRAME_CRC_LEN, FrameDecoder, HostToDevice, MAX_FRAME, cobs_max_len, encode_frame,
};
use core::sync::atomic::{AtomicU32, Ordering};
use heapless::spsc::{Consumer, Producer, Queue};

/// Outgoing messages the queue holds (minus one: heapless keeps a slot free). At 100 Hz
/// telemetry this is 70 ms of messages for a host that stopped reading.
pub const TX_FRAMES: usize = 8;
/// Incoming commands the queue holds (minus one): heartbeats and `Disarm` never take a slot,
/// and a host sends a command now and then; 15 hold a burst of them while the tick takes
/// [`crate::app::MAX_COMMANDS_PER_TICK`] a tick.
pub const RX_COMMANDS: usize = 16;
/// Outgoing slots periodic telemetry never takes ([`TickEnd::send_periodic`]): room for a
/// latched fault and a reply (an arm refusal, a `Hello`) while a host that stopped reading has
/// let telemetry fill the rest.
pub const TX_RESERVED: usize = 2;
/// The largest host-to-device message, postcard bytes: `Plant { tick, encoder_counts }`, a
/// variant index and four varints of at most 5 bytes (`SetMode(ConstantCurrent)`, the largest
/// command, is 14).
pub const MAX_COMMAND_MESSAGE: usize = 21;
/// The largest host-to-device frame, its 0x00 included: what the driver's command decoder
/// holds. A longer frame is dropped as oversize without being decoded, so the decoding work at
/// a delimiter is bounded by this, not by [`MAX_FRAME`] (263).
pub const MAX_COMMAND_FRAME: usize = cobs_max_len(MAX_COMMAND_MESSAGE + FRAME_CRC_LEN) + 1;

/// What the driver's end has received, all wrapping: written by the driver, read by the tick.
pub struct RxCounts {
    bytes: AtomicU32,
    frames: AtomicU32,
    errors: AtomicU32,
    dropped: AtomicU32,
    disarms: AtomicU32,
}

impl RxCounts {
    const fn new() -> RxCounts {
        RxCounts {
            bytes: AtomicU32::new(0),
            frames: AtomicU32::new(0),
            errors: AtomicU32::new(0),
            dropped: AtomicU32::new(0),
            disarms: AtomicU32::new(0),
        }
    }

    /// Bytes received: the tick's evidence of link activity while a frame is still arriving.
    pub fn bytes(&self) -> u32 {
        self.bytes.load(Ordering::Relaxed)
    }

    /// Frames that decoded to a command (telemetry's `rx_frames`): the tick's evidence that
    /// the host is there.
    pub fn frames(&self) -> u32 {
        self.frames.load(Ordering::Relaxed)
    }

    /// `Disarm` commands received (counted here, never queued).
    pub fn disarms(&self) -> u32 {
        self.disarms.load(Ordering::Relaxed)
    }

    /// Frames dropped: CRC, COBS, too short, oversize or not a command (telemetry's
    /// `rx_errors`).
    pub fn errors(&self) -> u32 {
        self.errors.load(Ordering::Relaxed)
    }

    /// Decoded commands dropped because the incoming queue was full (telemetry's
    /// `rx_dropped`); never a heartbeat or a `Disarm`, which take no slot.
    pub fn dropped(&self) -> u32 {
        self.dropped.load(Ordering::Relaxed)
    }
}

/// A queued command and the number of `Disarm`s received before it (wrapping).
struct Queued {
    disarms_before: u32,
    cmd: HostToDevice,
}

/// The link's queues; [`Link::split`] hands out the two ends.
pub struct Link {
    tx: Queue<DeviceToHost, TX_FRAMES>,
    rx: Queue<Queued, RX_COMMANDS>,
    rx_counts: RxCounts,
    tx_dropped: AtomicU32,
}

impl Default for Link {
    fn default() -> Link {
        Link::new()
    }
}

impl Link {
    /// Empty queues (usable in a `static`).
    pub const fn new() -> Link {
        Link {
            tx: Queue::new(),
            rx: Queue::new(),
            rx_counts: RxCounts::new(),
            tx_dropped: AtomicU32::new(0),
        }
    }

    /// The tick's end and the driver's end.
    pub fn split(&mut self) -> (TickEnd<'_>, DriverEnd<'_>) {
        let (tx_in, tx_out) = self.tx.split();
        let (rx_in, rx_out) = self.rx.split();
        let (rx_counts, tx_dropped) = (&self.rx_counts, &self.tx_dropped);
        (
            TickEnd {
                tx: tx_in,
                rx: rx_out,
                rx_counts,
                tx_dropped,
                frames_seen: 0,
                disarms_seen: 0,
            },
            DriverEnd {
                tx: tx_out,
                rx: rx_in,
                rx_counts,
                tx_dropped,
                decoder: FrameDecoder::new(),
                frame: [0; MAX_FRAME],
                len: 0,
                sent: 0,
            },
        )
    }
}

/// What arrived since the tick last looked ([`TickEnd::poll`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Arrivals {
    /// At least one valid frame: the host is there.
    pub frame: bool,
    /// At least one `Disarm`: apply it before anything else.
    pub disarm: bool,
}

/// The tick's end: queue messages, take received commands. Every method returns at once.
pub struct TickEnd<'q> {
    tx: Producer<'q, DeviceToHost>,
    rx: Consumer<'q, Queued>,
    rx_counts: &'q RxCounts,
    tx_dropped: &'q AtomicU32,
    /// [`RxCounts::frames`] and [`RxCounts::disarms`] when the tick last looked.
    frames_seen: u32,
    disarms_seen: u32,
}

impl TickEnd<'_> {
    /// Queue `msg` whole; `false` (the message dropped and counted in
    /// [`TickEnd::tx_dropped`]) when the queue is full.
    pub fn send(&mut self, msg: DeviceToHost) -> bool {
        let queued = self.tx.enqueue(msg).is_ok();
        if !queued {
            self.tx_dropped.fetch_add(1, Ordering::Relaxed);
        }
        queued
    }

    /// Queue periodic `msg` (telemetry) whole, leaving the last [`TX_RESERVED`] slots to
    /// [`TickEnd::send`]; `false` (dropped and counted like a full queue's) when only those
    /// are left.
    pub fn send_periodic(&mut self, msg: DeviceToHost) -> bool {
        if self.tx.len() + TX_RESERVED >= self.tx.capacity() {
            self.tx_dropped.fetch_add(1, Ordering::Relaxed);
            return false;
        }
        self.send(msg)
    }

    /// Whether a valid frame, and whether a `Disarm`, arrived since the last call: one atomic
    /// load when nothing did (a `Disarm` is counted before the frame that carried it, so the
    /// frame count always moves with it). Call before [`TickEnd::receive`], every tick.
    pub fn poll(&mut self) -> Arrivals {
        let frames = self.rx_counts.frames.load(Ordering::Acquire);
        if frames == self.frames_seen {
            return Arrivals::default();
        }
        self.frames_seen = frames;
        let disarms = self.rx_counts.disarms.load(Ordering::Relaxed);
        let disarm = disarms != self.disarms_seen;
        self.disarms_seen = disarms;
        Arrivals {
            frame: true,
            disarm,
        }
    }

    /// The next command the host sent, if any, in the host's order with its `Disarm`s: an
    /// `Arm` the host sent before a `Disarm` already applied is skipped (the `Disarm`
    /// supersedes it), and a command the host sent after a `Disarm` not yet applied comes
    /// after a `Disarm` returned here first. Skips at most the queue's length.
    pub fn receive(&mut self) -> Option<HostToDevice> {
        loop {
            let stamp = self.rx.peek()?.disarms_before;
            // Wrapping order: the queue holds far fewer than 2^31 commands.
            let ahead = stamp.wrapping_sub(self.disarms_seen) as i32;
            if ahead > 0 {
                self.disarms_seen = stamp;
                return Some(HostToDevice::Disarm);
            }
            let queued = self.rx.dequeue()?;
            if ahead < 0 && matches!(queued.cmd, HostToDevice::Arm) {
                continue;
            }
            return Some(queued.cmd);
        }
    }

    /// What the driver has received so far.
    pub fn rx_counts(&self) -> &RxCounts {
        self.rx_counts
    }

    /// Outgoing messages dropped whole, the queue being full (or, at the driver, the message
    /// not encoding) (wrapping).
    pub fn tx_dropped(&self) -> u32 {
        self.tx_dropped.load(Ordering::Relaxed)
    }
}

/// The driver's end: outgoing frames' bytes in message order, received bytes decoded into
/// commands.
pub struct DriverEnd<'q> {
    tx: Consumer<'q, DeviceToHost>,
    rx: Producer<'q, Queued>,
    rx_counts: &'q RxCounts,
    tx_dropped: &'q AtomicU32,
    /// The command decoder: holds at most the largest command frame.
    decoder: FrameDecoder<HostToDevice, MAX_COMMAND_FRAME>,
    /// The frame being sent (`frame[..len]`) and how much of it is out (`sent`; none is being
    /// sent when `sent == len`).
    frame: [u8; MAX_FRAME],
    len: usize,
    sent: usize,
}

impl DriverEnd<'_> {
    /// Copy the next outgoing bytes into `out` (at most `out.len()`, frames back to back),
    /// encoding each queued message when its turn comes; returns how many. The caller must
    /// send all of them: a frame is never taken back.
    pub fn take_tx(&mut self, out: &mut [u8]) -> usize {
        let mut n = 0;
        while n < out.len() {
            if self.sent >= self.len && !self.next_frame() {
                break;
            }
            let rest = self.frame.get(self.sent..self.len).unwrap_or(&[]);
            let k = rest.len().min(out.len() - n);
            if let (Some(dst), Some(src)) = (out.get_mut(n..n + k), rest.get(..k)) {
                dst.copy_from_slice(src);
            }
            n += k;
            self.sent += k;
        }
        n
    }

    /// Encode the next queued message into the frame buffer; `false` when there is none. A
    /// message that does not encode is dropped and counted.
    fn next_frame(&mut self) -> bool {
        while let Some(msg) = self.tx.dequeue() {
            match encode_frame(&msg, &mut self.frame) {
                Ok(frame) => {
                    (self.len, self.sent) = (frame.len(), 0);
                    return true;
                }
                Err(_) => {
                    self.tx_dropped.fetch_add(1, Ordering::Relaxed);
                }
            }
        }
        (self.len, self.sent) = (0, 0);
        false
    }

    /// Whether there is anything to send.
    pub fn has_tx(&self) -> bool {
        self.sent < self.len || self.tx.ready()
    }

    /// Take received `bytes`: decode them ([`FrameDecoder`], resynchronising on each 0x00) and
    /// queue every command they complete, except a `Heartbeat` (counted as a frame only) and a
    /// `Disarm` (counted in [`RxCounts::disarms`]); a frame that does not decode, or a command
    /// that finds the queue full, is dropped and counted ([`RxCounts`]).
    pub fn put_rx(&mut self, bytes: &[u8]) {
        let counts = self.rx_counts;
        counts.bytes.fetch_add(
            u32::try_from(bytes.len()).unwrap_or(u32::MAX),
            Ordering::Relaxed,
        );
        for result in self.decoder.feed_slice(bytes) {
            let cmd = match result {
                Ok(cmd) => cmd,
                Err(_) => {
                    counts.errors.fetch_add(1, Ordering::Relaxed);
                    continue;
                }
            };
            match cmd {
                HostToDevice::Heartbeat => {}
                HostToDevice::Disarm => {
                    counts.disarms.fetch_add(1, Ordering::Relaxed);
                }
                cmd => {
                    let queued = Queued {
                        disarms_before: counts.disarms.load(Ordering::Relaxed),
                        cmd,
                    };
                    if self.rx.enqueue(queued).is_err() {
                        counts.dropped.fetch_add(1, Ordering::Relaxed);
                    }
                }
            }
            // After the disarm count and the queue: a tick that sees this frame counted sees
            // them too ([`TickEnd::poll`]).
            counts.frames.fetch_add(1, Ordering::Release);
        }
    }

    /// A new connection (the host opened its serial port): drop the frame the decoder holds
    /// (torn by the disconnect) and every message queued for the previous connection,
    /// counting them in `tx_dropped`, so the new connection's first frames are the host's own
    /// and the device's first are current. Commands already queued stay: the tick applies
    /// them within [`RX_COMMANDS`] / [`crate::app::MAX_COMMANDS_PER_TICK`] ticks, long
    /// before a reconnection completes.
    pub fn connected(&mut self) {
        self.decoder.reset();
        let mut stale = u32::from(self.sent < self.len);
        while self.tx.dequeue().is_some() {
            stale = stale.wrapping_add(1);
        }
        (self.len, self.sent) = (0, 0);
        self.tx_dropped.fetch_add(stale, Ordering::Relaxed);
    }

    /// What has been received so far.
    pub fn rx_counts(&self) -> &RxCounts {
        self.rx_counts
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    extern crate std;
    use super::*;
    use std::vec::Vec;

    #[test]
    fn messages_go_out_as_whole_frames_in_order_and_overflow_is_refused() {
        let mut link = Link::new();
        let (mut tick, mut driver) = link.split();
        let msgs: Vec<DeviceToHost> = (0..TX_FRAMES as u32)
            .map(|i| DeviceToHost::Fault {
                tick: i * 1000,
                reason: bank_format::FaultReason::Overrun,
                detail: i,
            })
            .collect();
        let mut queued = Vec::new();
        for m in &msgs {
            if tick.send(m.clone()) {
                queued.push(m.clone());
            }
        }
        // heapless keeps one slot free: the last message was refused whole and counted.
        assert_eq!(queued.len(), TX_FRAMES - 1);
        assert_eq!(tick.tx_dropped(), 1);
        assert!(driver.has_tx());
        // A driver that takes 7 bytes at a time gets exactly the queued messages' frames
        // (encoded here independently) back to back.
        let mut want = Vec::new();
        for m in &queued {
            let mut buf = [0u8; MAX_FRAME];
            want.extend_from_slice(encode_frame(m, &mut buf).unwrap());
        }
        let mut got = Vec::new();
        let mut buf = [0u8; 7];
        loop {
            let n = driver.take_tx(&mut buf);
            if n == 0 {
                break;
            }
            got.extend_from_slice(&buf[..n]);
        }
        assert_eq!(got, want);
        assert!(!driver.has_tx());
        assert_eq!(tick.tx_dropped(), 1);
    }

    /// Telemetry stops at the reserve; what must not be lost still finds room, and every
    /// refusal is counted.
    #[test]
    fn periodic_messages_leave_the_reserve_to_faults() {
        let mut link = Link::new();
        let (mut tick, mut driver) = link.split();
        let telemetry = || DeviceToHost::Hello {
            protocol: 0,
            bank_crc: None,
            scene_id: 0,
            node_count: 0,
        };
        let periodic = (0..20).filter(|_| tick.send_periodic(telemetry())).count();
        assert_eq!(periodic, TX_FRAMES - 1 - TX_RESERVED);
        assert_eq!(tick.tx_dropped(), 20 - periodic as u32);
        let fault = DeviceToHost::Fault {
            tick: 7,
            reason: bank_format::FaultReason::EStop,
            detail: 0,
        };
        for _ in 0..TX_RESERVED {
            assert!(tick.send(fault.clone()));
        }
        assert!(!tick.send(fault.clone()), "the queue is full now");
        let mut rx = bank_format::FrameDecoder::<DeviceToHost>::new();
        let mut buf = [0u8; 64];
        let mut got = Vec::new();
        loop {
            let n = driver.take_tx(&mut buf);
            if n == 0 {
                break;
            }
            got.extend(rx.feed_slice(&buf[..n]).map(Result::unwrap));
        }
        assert_eq!(got.len(), TX_FRAMES - 1);
        assert_eq!(got[TX_FRAMES - 2], fault);
    }

    /// Every host message, at its largest, fits the command decoder.
    #[test]
    fn every_host_message_fits_the_command_frame() {
        use bank_format::{HostToDevice, Mode};
        let largest = [
            HostToDevice::Plant {
                tick: u32::MAX,
                encoder_counts: [i32::MIN, i32::MAX, i32::MIN],
            },
            HostToDevice::SetMode(Mode::ConstantCurrent {
                currents_a: [f32::MAX; 3],
            }),
            HostToDevice::ClearFault,
        ];
        for msg in &largest {
            let body = postcard_len(msg);
            assert!(body <= MAX_COMMAND_MESSAGE, "{msg:?}: {body}");
            let mut buf = [0u8; MAX_FRAME];
            let frame = encode_frame(msg, &mut buf).unwrap();
            assert!(frame.len() <= MAX_COMMAND_FRAME, "{msg:?}: {}", frame.len());
        }
        assert_eq!(postcard_len(&largest[0]), MAX_COMMAND_MESSAGE);
    }

    fn postcard_len(msg: &bank_format::HostToDevice) -> usize {
        let mut frame = [0u8; MAX_FRAME];
        let encoded = encode_frame(msg, &mut frame).unwrap().len();
        // COBS adds one byte (below 254), the delimiter one, the CRC four.
        encoded - 2 - FRAME_CRC_LEN
    }

    fn frame(cmd: &HostToDevice) -> Vec<u8> {
        let mut buf = [0u8; MAX_FRAME];
        encode_frame(cmd, &mut buf).unwrap().to_vec()
    }

    /// Commands come out decoded and in order, however the bytes were split; garbage, a torn
    /// frame and an oversize frame are counted as errors (the oversize one undecoded: the
    /// decoder holds the largest command frame, not the 263 bytes of the largest telemetry),
    /// and decoding resumes at the next delimiter.
    #[test]
    fn received_bytes_decode_into_commands_and_bad_frames_are_counted() {
        use bank_format::HostToDevice::{Arm, ClearFault, Heartbeat};
        let mut link = Link::new();
        let (mut tick, mut driver) = link.split();
        let mut bytes = frame(&Arm);
        bytes.extend([0x55, 0x13, 0x00]); // garbage
        let torn = frame(&ClearFault);
        bytes.extend(&torn[..torn.len() / 2]);
        bytes.push(0); // the torn frame ends early
        bytes.extend([0x11; 3 * MAX_COMMAND_FRAME]);
        bytes.push(0); // oversize
        bytes.extend(frame(&Heartbeat));
        bytes.extend(frame(&ClearFault));
        for chunk in bytes.chunks(5) {
            driver.put_rx(chunk);
        }
        let got: Vec<HostToDevice> = core::iter::from_fn(|| tick.receive()).collect();
        // The heartbeat counts as a frame; it takes no queue slot.
        assert_eq!(got, [Arm, ClearFault]);
        let counts = tick.rx_counts();
        assert_eq!(counts.bytes(), bytes.len() as u32);
        assert_eq!(
            (counts.frames(), counts.errors(), counts.dropped()),
            (3, 3, 0)
        );
        assert_eq!(driver.decoder.stats().oversize, 1);
    }

    /// A full incoming queue drops whole commands and counts them; the queued ones stay in
    /// order.
    #[test]
    fn commands_beyond_the_queue_are_dropped_and_counted() {
        let mut link = Link::new();
        let (mut tick, mut driver) = link.split();
        let clear = frame(&HostToDevice::ClearFault);
        for _ in 0..RX_COMMANDS + 4 {
            driver.put_rx(&clear);
        }
        assert_eq!(
            core::iter::from_fn(|| tick.receive()).count(),
            RX_COMMANDS - 1
        );
        let counts = driver.rx_counts();
        assert_eq!(counts.frames(), RX_COMMANDS as u32 + 4);
        assert_eq!(counts.dropped(), 5);
        assert_eq!(counts.errors(), 0);
    }

    /// A flood (200 heartbeats, 30 commands) then `Disarm`: the `Disarm` is seen at the next
    /// poll whatever the queue holds; heartbeats take no slot, so only the 30 - 15 commands
    /// beyond the queue are shed.
    #[test]
    fn a_flood_sheds_commands_but_never_a_disarm() {
        let mut link = Link::new();
        let (mut tick, mut driver) = link.split();
        for i in 0..230 {
            driver.put_rx(&frame(if i % 23 == 0 || i % 23 == 11 || i % 23 == 17 {
                &HostToDevice::ClearFault
            } else {
                &HostToDevice::Heartbeat
            }));
        }
        driver.put_rx(&frame(&HostToDevice::Disarm));
        assert_eq!(
            tick.poll(),
            Arrivals {
                frame: true,
                disarm: true
            }
        );
        let counts = driver.rx_counts();
        assert_eq!(
            (counts.frames(), counts.dropped(), counts.disarms()),
            (231, 15, 1)
        );
        let queued: Vec<_> = core::iter::from_fn(|| tick.receive()).collect();
        assert_eq!(
            queued,
            [const { HostToDevice::ClearFault }; RX_COMMANDS - 1]
        );
        assert_eq!(tick.poll(), Arrivals::default());
    }

    /// The tick's view keeps the host's order around a `Disarm`: an `Arm` sent before an
    /// applied `Disarm` is skipped, other commands before it still come out, and a command
    /// sent after a `Disarm` the tick has not polled yet comes out after that `Disarm`, which
    /// the next poll does not repeat.
    #[test]
    fn disarm_keeps_the_hosts_order() {
        use bank_format::HostToDevice::{Arm, ClearFault, Disarm, Hello, ZeroEncoders};
        let mut link = Link::new();
        let (mut tick, mut driver) = link.split();
        for cmd in [ClearFault, Arm, Disarm, ZeroEncoders, Arm] {
            driver.put_rx(&frame(&cmd));
        }
        assert!(tick.poll().disarm);
        let got: Vec<_> = core::iter::from_fn(|| tick.receive()).collect();
        assert_eq!(got, [ClearFault, ZeroEncoders, Arm]);

        driver.put_rx(&frame(&Hello));
        assert_eq!(
            tick.poll(),
            Arrivals {
                frame: true,
                disarm: false
            }
        );
        for cmd in [Disarm, Arm] {
            driver.put_rx(&frame(&cmd));
        }
        let got: Vec<_> = core::iter::from_fn(|| tick.receive()).collect();
        assert_eq!(got, [Hello, Disarm, Arm]);
        assert_eq!(
            tick.poll(),
            Arrivals {
                frame: true,
                disarm: false
            }
        );
    }

    /// A reconnection: the device's decoder holds half a frame from before the disconnect and
    /// the outgoing queue holds messages for the old connection, one of them half sent. After
    /// [`DriverEnd::connected`] the host's `Hello` (sent without a leading delimiter) decodes,
    /// nothing stale goes out (the four stale messages are counted as dropped), and the first
    /// bytes out are the frame of the first message queued after it.
    #[test]
    fn a_new_connection_drops_the_torn_frame_and_the_stale_messages() {
        let mut link = Link::new();
        let (mut tick, mut driver) = link.split();
        let stale = |i: u32| DeviceToHost::Fault {
            tick: i,
            reason: bank_format::FaultReason::LinkSilent,
            detail: 11,
        };
        for i in 0..4 {
            assert!(tick.send(stale(i)));
        }
        let mut part = [0u8; 5];
        assert_eq!(driver.take_tx(&mut part), 5);
        let torn = frame(&HostToDevice::ClearFault);
        driver.put_rx(&torn[..torn.len() / 2]);

        driver.connected();
        assert!(!driver.has_tx());
        assert_eq!(tick.tx_dropped(), 4);
        driver.put_rx(&frame(&HostToDevice::Hello));
        assert_eq!(tick.receive(), Some(HostToDevice::Hello));
        assert_eq!(driver.rx_counts().errors(), 0);

        let fresh = DeviceToHost::Hello {
            protocol: bank_format::PROTOCOL_VERSION,
            bank_crc: Some(0x1234_5678),
            scene_id: 9,
            node_count: 3,
        };
        assert!(tick.send(fresh.clone()));
        let mut buf = [0u8; MAX_FRAME];
        let n = driver.take_tx(&mut buf);
        let mut want = [0u8; MAX_FRAME];
        assert_eq!(&buf[..n], encode_frame(&fresh, &mut want).unwrap());
    }
}
