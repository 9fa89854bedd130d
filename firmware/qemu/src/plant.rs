//! The plant channel of software in the loop: on a board the encoders and motor drivers are
//! peripherals; here they are the host's plant simulator, reached through two named pipes that
//! QEMU's semihosting opens in its working directory: `sil-plant-in` (host -> image,
//! `HostToDevice::Plant { tick, encoder_counts }`) and `sil-plant-out` (image -> host,
//! `DeviceToHost::Plant { tick, currents_a, .. }`), both as plant-channel messages (a length
//! byte and postcard, `SPEC.md` "Plant channel": the pipes need no CRC and no COBS, which cost
//! the tick about 1,000 instructions).
//!
//! Semihosting calls stop the virtual CPU, so virtual time (`-icount`) stands still while the
//! host computes the next encoder counts: the exchange is lockstep and runs are deterministic.

use crate::systick::instructions;
use bank_format::{
    DeviceToHost, FrameError, HostToDevice, PhaseCycles, decode_plant, encode_plant,
};
use core::fmt;
use firmware::app::TickReport;
use firmware::hal::Plant;
use semihosting::fs::File;
use semihosting::io::{Read, Write};

/// Pipe the host writes encoder frames to.
const IN_PATH: &core::ffi::CStr = c"sil-plant-in";
/// Pipe the host reads current frames from.
const OUT_PATH: &core::ffi::CStr = c"sil-plant-out";

/// Why the plant exchange failed.
#[derive(Debug)]
pub enum PlantError {
    /// The host closed the channel (end of the run).
    Closed,
    /// A semihosting call failed.
    Io(semihosting::io::Error),
    /// A message from the host did not decode (or one to it did not encode).
    Frame(FrameError),
    /// The host answered for another tick or with another message (a missed plant frame).
    Unexpected {
        /// The tick the image asked for.
        expected: u32,
    },
}

impl fmt::Display for PlantError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            PlantError::Closed => f.write_str("closed by the host"),
            PlantError::Io(e) => write!(f, "semihosting I/O: {e:?}"),
            PlantError::Frame(e) => write!(f, "bad plant message: {e}"),
            PlantError::Unexpected { expected } => {
                write!(f, "expected the encoder frame of tick {expected}")
            }
        }
    }
}

/// The two pipes, a receive buffer, and the tick the channel is at.
pub struct PlantChannel {
    rx: File,
    tx: File,
    buf: [u8; 64],
    pos: usize,
    len: usize,
    /// The tick whose encoder frame was read last.
    tick: u32,
}

impl PlantChannel {
    /// Open the pipes: the image's output first (the host opens them in the same order).
    pub fn open() -> Result<PlantChannel, PlantError> {
        let tx = File::create(OUT_PATH).map_err(PlantError::Io)?;
        let rx = File::open(IN_PATH).map_err(PlantError::Io)?;
        Ok(PlantChannel {
            rx,
            tx,
            buf: [0; 64],
            pos: 0,
            len: 0,
            tick: 0,
        })
    }

    /// The next byte from the host (blocking; virtual time stands still meanwhile).
    fn next_byte(&mut self) -> Result<u8, PlantError> {
        loop {
            if let Some(&b) = self.buf.get(self.pos).filter(|_| self.pos < self.len) {
                self.pos += 1;
                return Ok(b);
            }
            let n = self.rx.read(&mut self.buf).map_err(PlantError::Io)?;
            if n == 0 {
                return Err(PlantError::Closed);
            }
            (self.pos, self.len) = (0, n);
        }
    }

    /// The next message from the host: its length byte, then its postcard bytes.
    fn next_message(&mut self) -> Result<HostToDevice, PlantError> {
        let len = usize::from(self.next_byte()?);
        let mut body = [0u8; MAX_FROM_HOST];
        let body = body
            .get_mut(..len)
            .ok_or(PlantError::Frame(FrameError::Oversize))?;
        for b in body.iter_mut() {
            *b = self.next_byte()?;
        }
        decode_plant(body).map_err(PlantError::Frame)
    }
}

/// The largest plant message the host sends (`Plant { tick, encoder_counts }` takes at most
/// 21 postcard bytes).
const MAX_FROM_HOST: usize = 32;
/// Room for the image's `Plant` reply (at most 72 postcard bytes: `bank-format/tests/frames.rs`) and
/// its length byte.
const MAX_TO_HOST: usize = 128;

impl PlantChannel {
    /// Answer the host with the tick's outcome: the currents (zero unless armed) and what the
    /// harness records.
    pub fn reply(&mut self, out: &TickReport) -> Result<(), PlantError> {
        // The report counts virtual core cycles (`InstructionCounter`); the harness gets
        // instructions. Each phase ends where the cumulative count since the body's start
        // does, so the converted phases still sum to the converted body.
        let mut at = 0u32;
        let ends = out.phase_cycles.to_array().map(|part| {
            at = at.wrapping_add(part);
            instructions(at)
        });
        let mut start = 0u32;
        let phase_cycles = PhaseCycles::from_array(ends.map(|end| {
            let part = end.wrapping_sub(start);
            start = end;
            part
        }));
        let msg = DeviceToHost::Plant {
            tick: out.tick,
            currents_a: out.currents_a,
            force_n: out.force_n,
            state: out.state,
            contact_nodes: out.contact_nodes,
            body_cycles: instructions(out.body_cycles),
            tick_cycles: out.tick_cycles,
            phase_cycles,
        };
        let mut buf = [0u8; MAX_TO_HOST];
        let bytes = encode_plant(&msg, &mut buf).map_err(PlantError::Frame)?;
        self.tx.write_all(bytes).map_err(PlantError::Io)
    }
}

/// The host's plant is the motors: what the loop drives goes back in [`PlantChannel::reply`]
/// (the tick report carries the same currents), so driving and disabling need no I/O here.
impl Plant for PlantChannel {
    type Error = PlantError;

    fn read_encoders(&mut self) -> Result<[i32; 3], PlantError> {
        let tick = self.tick.wrapping_add(1);
        match self.next_message()? {
            HostToDevice::Plant {
                tick: t,
                encoder_counts,
            } if t == tick => {
                self.tick = tick;
                Ok(encoder_counts)
            }
            _ => Err(PlantError::Unexpected { expected: tick }),
        }
    }

    fn drive(&mut self, _currents_a: [f32; 3]) -> Result<(), PlantError> {
        Ok(())
    }

    fn disable(&mut self) {}
}
