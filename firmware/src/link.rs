//! The host link between the tick and the link driver: two bounded single-producer,
//! single-consumer queues, so the tick never waits on I/O and never encodes a frame.
//!
//! The tick ([`crate::app::App::tick`], high priority) owns a [`TickEnd`]: it pushes whole
//! messages (telemetry snapshots, faults, `Hello`), not yet encoded, and pops the bytes the
//! host sent. A lower-priority driver (a UART or USB CDC task, in thread mode) owns the
//! [`DriverEnd`]: it takes each message, encodes it as a link frame (postcard, CRC, COBS:
//! [`encode_frame`]) and hands out its bytes as fast as the wire accepts them, and pushes what
//! it received. Neither end ever blocks:
//!
//! - a message that finds the outgoing queue full is dropped whole and counted
//!   ([`TickEnd::send`] returns `false`; [`TickEnd::tx_dropped`], telemetry's `tx_dropped`); a
//!   message once queued goes out as one whole frame, so the host never sees a torn frame (a
//!   message that would not encode, which the bounded message set cannot produce, is dropped
//!   and counted the same way);
//! - periodic telemetry ([`TickEnd::send_periodic`]) leaves the last [`TX_RESERVED`] slots
//!   free, so a host that stops reading fills the queue with telemetry but a fault raised
//!   meanwhile (or a reply) still finds room and reaches the host once it reads again;
//! - received bytes that find the incoming queue full are dropped and counted
//!   ([`DriverEnd::rx_dropped`]); the frame they belonged to then fails its CRC on the device
//!   and is counted there as an `rx_error`.
//!
//! The queues are lock-free (heapless `spsc`), so the two ends may live at different interrupt
//! priorities on one core. Encoding in the driver keeps postcard, the CRC, COBS and the
//! frame buffers out of the tick: the tick only moves the message (a few hundred bytes) into
//! its queue slot.

use bank_format::{DeviceToHost, FRAME_CRC_LEN, MAX_FRAME, cobs_max_len, encode_frame};
use core::sync::atomic::{AtomicU32, Ordering};
use heapless::spsc::{Consumer, Producer, Queue};

/// Outgoing messages the queue holds (minus one: heapless keeps a slot free). At 100 Hz
/// telemetry this is 70 ms of messages for a host that stopped reading.
pub const TX_FRAMES: usize = 8;
/// Incoming bytes the queue holds (minus one).
pub const RX_BYTES: usize = 512;
/// Outgoing slots periodic telemetry never takes ([`TickEnd::send_periodic`]): room for a
/// latched fault and a reply (an arm refusal, a `Hello`) while a host that stopped reading has
/// let telemetry fill the rest.
pub const TX_RESERVED: usize = 2;
/// The largest host-to-device message, postcard bytes: `Plant { tick, encoder_counts }`, a
/// variant index and four varints of at most 5 bytes (`SetMode(ConstantCurrent)`, the largest
/// command, is 14).
pub const MAX_COMMAND_MESSAGE: usize = 21;
/// The largest host-to-device frame, its 0x00 included: what the device's decoder holds
/// ([`crate::app::App`]). A longer frame is dropped as oversize without being decoded, so the
/// decoding work at a delimiter is bounded by this, not by [`MAX_FRAME`] (263): the
/// [`crate::app::MAX_RX_BYTES_PER_TICK`] bytes a tick takes cost at most that many bytes of
/// decoding, whatever their content.
pub const MAX_COMMAND_FRAME: usize = cobs_max_len(MAX_COMMAND_MESSAGE + FRAME_CRC_LEN) + 1;

/// The link's queues; [`Link::split`] hands out the two ends.
pub struct Link {
    tx: Queue<DeviceToHost, TX_FRAMES>,
    rx: Queue<u8, RX_BYTES>,
    rx_dropped: AtomicU32,
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
            rx_dropped: AtomicU32::new(0),
            tx_dropped: AtomicU32::new(0),
        }
    }

    /// The tick's end and the driver's end.
    pub fn split(&mut self) -> (TickEnd<'_>, DriverEnd<'_>) {
        let (tx_in, tx_out) = self.tx.split();
        let (rx_in, rx_out) = self.rx.split();
        let (rx_dropped, tx_dropped) = (&self.rx_dropped, &self.tx_dropped);
        (
            TickEnd {
                tx: tx_in,
                rx: rx_out,
                rx_dropped,
                tx_dropped,
            },
            DriverEnd {
                tx: tx_out,
                rx: rx_in,
                rx_dropped,
                tx_dropped,
                frame: [0; MAX_FRAME],
                len: 0,
                sent: 0,
            },
        )
    }
}

/// The tick's end: queue messages, take received bytes. Every method returns at once.
pub struct TickEnd<'q> {
    tx: Producer<'q, DeviceToHost>,
    rx: Consumer<'q, u8>,
    rx_dropped: &'q AtomicU32,
    tx_dropped: &'q AtomicU32,
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

    /// The next received byte, if any.
    pub fn receive(&mut self) -> Option<u8> {
        self.rx.dequeue()
    }

    /// Received bytes the driver dropped because the incoming queue was full (wrapping).
    pub fn rx_dropped(&self) -> u32 {
        self.rx_dropped.load(Ordering::Relaxed)
    }

    /// Outgoing messages dropped whole, the queue being full (or, at the driver, the message
    /// not encoding) (wrapping).
    pub fn tx_dropped(&self) -> u32 {
        self.tx_dropped.load(Ordering::Relaxed)
    }
}

/// The driver's end: outgoing frames' bytes in message order, received bytes in.
pub struct DriverEnd<'q> {
    tx: Consumer<'q, DeviceToHost>,
    rx: Producer<'q, u8>,
    rx_dropped: &'q AtomicU32,
    tx_dropped: &'q AtomicU32,
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

    /// Push received `bytes`; those that do not fit are dropped and counted.
    pub fn put_rx(&mut self, bytes: &[u8]) {
        for &b in bytes {
            if self.rx.enqueue(b).is_err() {
                self.rx_dropped.fetch_add(1, Ordering::Relaxed);
            }
        }
    }

    /// Received bytes dropped so far (wrapping).
    pub fn rx_dropped(&self) -> u32 {
        self.rx_dropped.load(Ordering::Relaxed)
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

    /// Every host message, at its largest, fits the command decoder, and a tick's share of
    /// received bytes holds the largest frame.
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
        const { assert!(MAX_COMMAND_FRAME <= crate::app::MAX_RX_BYTES_PER_TICK) };
    }

    fn postcard_len(msg: &bank_format::HostToDevice) -> usize {
        let mut frame = [0u8; MAX_FRAME];
        let encoded = encode_frame(msg, &mut frame).unwrap().len();
        // COBS adds one byte (below 254), the delimiter one, the CRC four.
        encoded - 2 - FRAME_CRC_LEN
    }

    #[test]
    fn received_bytes_arrive_in_order_and_overflow_is_counted() {
        let mut link = Link::new();
        let (mut tick, mut driver) = link.split();
        let bytes: Vec<u8> = (0..RX_BYTES + 9).map(|i| i as u8).collect();
        driver.put_rx(&bytes);
        assert_eq!(driver.rx_dropped(), 10);
        assert_eq!(tick.rx_dropped(), 10);
        let got: Vec<u8> = core::iter::from_fn(|| tick.receive()).collect();
        assert_eq!(got, bytes[..RX_BYTES - 1]);
    }
}
