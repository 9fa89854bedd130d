//! The host link between the tick and the link driver: two bounded single-producer,
//! single-consumer queues, so the tick never waits on I/O.
//!
//! The tick ([`crate::app::App::tick`], high priority) owns a [`TickEnd`]: it pushes whole
//! encoded frames (telemetry, faults, `Hello`) and pops the bytes the host sent. A lower-priority
//! driver (a UART or USB CDC task) owns the [`DriverEnd`]: it takes outgoing bytes as fast as the
//! wire accepts them and pushes what it received. Neither end ever blocks:
//!
//! - a frame that finds the outgoing queue full is dropped whole and counted
//!   ([`TickEnd::send`] returns `false`, the application counts it in telemetry's
//!   `tx_dropped`); a frame once queued goes out whole, so the host never sees a torn frame;
//! - received bytes that find the incoming queue full are dropped and counted
//!   ([`DriverEnd::rx_dropped`]); the frame they belonged to then fails its CRC on the device
//!   and is counted there as an `rx_error`.
//!
//! The queues are lock-free (heapless `spsc`), so the two ends may live at different interrupt
//! priorities on one core.

use bank_format::MAX_FRAME;
use core::sync::atomic::{AtomicU32, Ordering};
use heapless::spsc::{Consumer, Producer, Queue};

/// One encoded link frame (COBS, CRC, 0x00 delimiter).
pub type Frame = heapless::Vec<u8, MAX_FRAME>;

/// Outgoing frames the queue holds (minus one: heapless keeps a slot free). At 100 Hz
/// telemetry this is 70 ms of frames for a host that stopped reading.
pub const TX_FRAMES: usize = 8;
/// Incoming bytes the queue holds (minus one).
pub const RX_BYTES: usize = 512;

/// The link's queues; [`Link::split`] hands out the two ends.
pub struct Link {
    tx: Queue<Frame, TX_FRAMES>,
    rx: Queue<u8, RX_BYTES>,
    rx_dropped: AtomicU32,
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
        }
    }

    /// The tick's end and the driver's end.
    pub fn split(&mut self) -> (TickEnd<'_>, DriverEnd<'_>) {
        let (tx_in, tx_out) = self.tx.split();
        let (rx_in, rx_out) = self.rx.split();
        let dropped = &self.rx_dropped;
        (
            TickEnd {
                tx: tx_in,
                rx: rx_out,
                rx_dropped: dropped,
            },
            DriverEnd {
                tx: tx_out,
                rx: rx_in,
                rx_dropped: dropped,
                sending: None,
            },
        )
    }
}

/// The tick's end: queue frames, take received bytes. Every method returns at once.
pub struct TickEnd<'q> {
    tx: Producer<'q, Frame>,
    rx: Consumer<'q, u8>,
    rx_dropped: &'q AtomicU32,
}

impl TickEnd<'_> {
    /// Queue `frame` whole; `false` (the frame dropped) when the queue is full.
    pub fn send(&mut self, frame: &[u8]) -> bool {
        let Ok(frame) = Frame::from_slice(frame) else {
            return false;
        };
        self.tx.enqueue(frame).is_ok()
    }

    /// The next received byte, if any.
    pub fn receive(&mut self) -> Option<u8> {
        self.rx.dequeue()
    }

    /// Received bytes the driver dropped because the incoming queue was full (wrapping).
    pub fn rx_dropped(&self) -> u32 {
        self.rx_dropped.load(Ordering::Relaxed)
    }
}

/// The driver's end: outgoing bytes in frame order, received bytes in.
pub struct DriverEnd<'q> {
    tx: Consumer<'q, Frame>,
    rx: Producer<'q, u8>,
    rx_dropped: &'q AtomicU32,
    /// The frame being sent and how much of it is out.
    sending: Option<(Frame, usize)>,
}

impl DriverEnd<'_> {
    /// Copy the next outgoing bytes into `out` (at most `out.len()`, frames back to back);
    /// returns how many. The caller must send all of them: a frame is never taken back.
    pub fn take_tx(&mut self, out: &mut [u8]) -> usize {
        let mut n = 0;
        while n < out.len() {
            if self.sending.is_none() {
                match self.tx.dequeue() {
                    Some(f) => self.sending = Some((f, 0)),
                    None => break,
                }
            }
            let Some((frame, sent)) = &mut self.sending else {
                break;
            };
            let rest = frame.get(*sent..).unwrap_or(&[]);
            let k = rest.len().min(out.len() - n);
            if let (Some(dst), Some(src)) = (out.get_mut(n..n + k), rest.get(..k)) {
                dst.copy_from_slice(src);
            }
            n += k;
            *sent += k;
            if *sent >= frame.len() {
                self.sending = None;
            }
        }
        n
    }

    /// Whether there is anything to send.
    pub fn has_tx(&self) -> bool {
        self.sending.is_some() || self.tx.ready()
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
mod tests {
    extern crate std;
    use super::*;
    use std::vec::Vec;

    #[test]
    fn frames_go_out_whole_in_order_and_overflow_is_refused() {
        let mut link = Link::new();
        let (mut tick, mut driver) = link.split();
        let frames: Vec<Vec<u8>> = (0..TX_FRAMES as u8)
            .map(|i| (0..=i * 30).map(|b| b.wrapping_add(i)).collect())
            .collect();
        let mut queued = Vec::new();
        for f in &frames {
            if tick.send(f) {
                queued.push(f.clone());
            }
        }
        // heapless keeps one slot free: the last frame was refused, not torn.
        assert_eq!(queued.len(), TX_FRAMES - 1);
        assert!(driver.has_tx());
        // A driver that takes 7 bytes at a time gets exactly the queued frames back to back.
        let mut got = Vec::new();
        let mut buf = [0u8; 7];
        loop {
            let n = driver.take_tx(&mut buf);
            if n == 0 {
                break;
            }
            got.extend_from_slice(&buf[..n]);
        }
        assert_eq!(got, queued.concat());
        assert!(!driver.has_tx());
        // Oversize frames are refused too.
        assert!(!tick.send(&[0u8; MAX_FRAME + 1]));
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
