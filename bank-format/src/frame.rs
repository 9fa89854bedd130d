//! Host-device link frames: postcard-encoded messages, a CRC-32, COBS framing, 0x00 delimiter.
//!
//! A frame on the wire is `COBS(postcard(msg) ++ crc32_le(postcard(msg))) ++ [0x00]`, where the
//! CRC is [`crate::CRC32`] (the same CRC-32 as the bank) over the postcard bytes. The receiver
//! ([`FrameDecoder`]) collects bytes up to each 0x00, so it resynchronises on the next delimiter
//! after any corruption; empty frames (repeated delimiters) are ignored, so a sender may also
//! send a 0x00 *before* a frame to flush a half-received one. See `SPEC.md`, "Link frames".

use crate::layout::CRC32;
use core::marker::PhantomData;
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

/// Version of the message set below; the device reports it in [`DeviceToHost::Hello`].
pub const PROTOCOL_VERSION: u16 = 7;
/// Most contact nodes one telemetry message carries.
pub const MAX_CONTACTS: usize = 8;
/// Upper bound on a postcard-encoded message, bytes (the largest, a full telemetry message, is
/// at most 241).
pub const MAX_MESSAGE: usize = 256;
/// Bytes of CRC after the message.
pub const FRAME_CRC_LEN: usize = 4;
/// Upper bound on an encoded frame including its 0x00 delimiter: COBS adds one byte per 254
/// started bytes plus one.
pub const MAX_FRAME: usize = cobs_max_len(MAX_MESSAGE + FRAME_CRC_LEN) + 1;

/// Largest COBS encoding of `n` bytes (without delimiter).
pub const fn cobs_max_len(n: usize) -> usize {
    n + n / 254 + 1
}

/// The device's safety state.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum State {
    /// Motors at zero current; waiting for [`HostToDevice::Arm`].
    Disarmed,
    /// The loop drives the motors.
    Armed,
    /// A fault forced zero current; [`HostToDevice::ClearFault`] returns to `Disarmed`.
    Fault,
}

/// What the armed loop renders.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum Mode {
    /// Tissue forces through the law Q (normal operation).
    Render,
    /// Tissue forces from the linear model, Q bypassed (for fitting Q on a bench).
    LinearLaw,
    /// Contact tracking and telemetry only, zero current (free motion).
    Transparent,
    /// Constant motor currents, A (motor constant calibration against a load cell). Never
    /// clamped: a current that is not finite or over its motor's limit is a
    /// [`FaultReason::BadCommand`] fault (zero current).
    ConstantCurrent {
        /// Commanded currents per motor, A.
        currents_a: [f32; 3],
    },
}

/// Why the device went to [`State::Fault`]. The variant order is the wire protocol: new
/// reasons go at the end.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum FaultReason {
    /// A NaN or infinity appeared in the loop.
    Nan,
    /// The bank failed validation (`detail` = [`crate::BankError::code`]).
    InvalidBank,
    /// No valid frame from the host within the timeout.
    LinkSilent,
    /// A tick overran its period.
    Overrun,
    /// An encoder moved more than physically possible in one tick (`detail` = joint).
    EncoderJump,
    /// A commanded current exceeded its limit before clamping (`detail` = motor).
    CurrentLimit,
    /// A joint left its calibrated range (`detail` = joint).
    JointLimit,
    /// The contact solve failed (C_SS not positive definite).
    SolveFailed,
    /// The emergency stop is pressed (or its loop is open).
    EStop,
    /// A motor amplifier reports a fault on its fault output (`detail` = motor).
    AmplifierFault,
    /// The armed device moved faster than the bank's speed thresholds over one tick (`detail`
    /// = joint 0..2, or 3 for the tool tip).
    Overspeed,
    /// A host command that cannot be applied safely (added in protocol 4): a `ConstantCurrent`
    /// current that is not finite or over its motor's limit (`detail` = motor 0..2, checked
    /// every tick of that mode, armed or not), or `SetMode` while armed (`detail` = 3; the
    /// mode is kept).
    BadCommand,
    /// The chip restarted from a watchdog reset (added in protocol 5; `detail` = 0 for the
    /// independent watchdog, 1 for the window watchdog): a tick hung, or the core locked up
    /// (e.g. a stack overflow). Latched at boot, so a device that reset mid-session cannot be
    /// re-armed without an explicit `ClearFault`.
    WatchdogReset,
    /// `Arm` refused: the encoders have not been referenced since the chip started (added in
    /// protocol 6). Only `ZeroEncoders` at the home pose references them; every reset (and an
    /// `EncoderJump`) loses the reference, since the counters restart from wherever the
    /// mechanism then stands.
    NotReferenced,
    /// A motor's current limit in the bank is outside what its amplifier's set-value range
    /// can deliver (added in protocol 6; `detail` = motor): checked at boot, every `Arm`
    /// refused with it, since the amplifier would clamp such a current silently.
    AmplifierRange,
    /// The chip's brown-out reset is below level 3 (added in protocol 7; `detail` = the
    /// level the option bytes set: 0 for BOR off, 1 or 2): at 168 MHz the STM32F405 needs
    /// 2.7 V, and a lower threshold lets it run on below that. Found at boot from
    /// `FLASH_OPTCR`, every `Arm` refused with it until `host flash --set-bor` programs
    /// level 3.
    BrownOutLevel,
}

/// Why the chip last started, as its reset flags tell it (added in protocol 6; on the STM32F4
/// RCC_CSR, read and cleared at boot). One cause per boot: the flags a reset sets as a side
/// effect (the pin flag of every internal reset, the brown-out flag of a power-on reset) yield
/// to the cause itself.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum ResetCause {
    /// Power-on or power-down reset (POR/PDR).
    PowerOn,
    /// The reset pin (NRST: a reset button, a debug probe).
    Pin,
    /// The supply dipped below the brown-out threshold (BOR).
    BrownOut,
    /// Software reset (`SYSRESETREQ`, e.g. after flashing).
    Software,
    /// The independent watchdog (a hung tick, a locked-up core).
    IndependentWatchdog,
    /// The window watchdog.
    WindowWatchdog,
    /// Low-power management reset (entering Standby or Stop with the option bytes' reset).
    LowPower,
    /// No flag set (or no reset-flag register, as under QEMU).
    Unknown,
}

/// One contact node and the force on it.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Contact {
    /// Node index in the bank's R.
    pub node: u16,
    /// Force applied to the tissue at the node, N (scene frame).
    pub force_n: [f32; 3],
}

/// Where the tool touches the collision surface (protocol 6): the bank triangle (`Bank::
/// triangles`, the sampled contact's lattice numbering) and the barycentric coordinates of the
/// contact point in it (sum 1). A display evaluates the fine mesh's surface displacement there
/// (`u = U(p) F`, `F` the sum of the contact forces) without a solve.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ContactPoint {
    /// Triangle index in the bank.
    pub triangle: u32,
    /// Barycentric coordinates of the contact point in the triangle.
    pub bary: [f32; 3],
}

/// Device-side counters, all wrapping.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Counters {
    /// Valid frames received.
    pub rx_frames: u32,
    /// Frames dropped (CRC, COBS, oversize, undecodable).
    pub rx_errors: u32,
    /// Ticks that overran.
    pub overruns: u32,
    /// Longest tick so far, in CPU cycles (or instructions under QEMU).
    pub max_tick_cycles: u32,
    /// Outgoing frames dropped because the link's queue was full (the host read too slowly).
    pub tx_dropped: u32,
    /// Received commands (decoded frames) dropped because the link's incoming queue was full.
    pub rx_dropped: u32,
    /// Ticks whose contact patch dropped load (protocol 4): nodes beyond the
    /// [`MAX_CONTACTS`] the solve carries, or not coupled in the bank.
    pub capped_ticks: u32,
    /// Background patch rebuilds dropped because a step failed (protocol 6): the held patch
    /// kept rendering instead of faulting `SolveFailed`.
    pub rebuilds_failed: u32,
}

/// Periodic device status.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Telemetry {
    /// Tick number (1 kHz; wraps after 49.7 days).
    pub tick: u32,
    /// Safety state.
    pub state: State,
    /// Rendering mode.
    pub mode: Mode,
    /// Latched fault, if any.
    pub fault: Option<FaultReason>,
    /// Tool tip position, m (scene frame).
    pub tip_m: [f32; 3],
    /// The contact set S and f_S (empty without contact).
    pub contacts: heapless::Vec<Contact, MAX_CONTACTS>,
    /// Where the contact is on the collision surface (protocol 6), `None` without a rendered
    /// contact.
    pub contact_point: Option<ContactPoint>,
    /// Motor currents commanded this tick, A.
    pub currents_a: [f32; 3],
    /// The force rendered on the tool this tick, N (protocol 4): after the law Q and the
    /// force cap, opposite to the force on the tissue; what the motors produce when armed
    /// (zero without contact, in `Transparent` and `ConstantCurrent`, and after a failed
    /// solve).
    pub tool_force_n: [f32; 3],
    /// Share of the tool patch's load on nodes the patch could not keep (protocol 4): the
    /// kept weights are renormalised, so `contacts` carries the whole force and the rendered
    /// force is that of the narrower patch; 0 when nothing was dropped.
    pub dropped_load: f32,
    /// Counters.
    pub counters: Counters,
}

/// The loop body of one tick split at the code's phase boundaries (same unit as the body's
/// count: CPU cycles, or instructions under QEMU); the parts sum to the body.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct PhaseCycles {
    /// Encoder counts to joints, tip and Jacobian.
    pub kinematics: u32,
    /// The contact tracker's update on the tip's path (detection, or following the anchor).
    pub detection: u32,
    /// Keeping the contact patch: its nodes and weights and the factored `B C B^T`.
    pub patch: u32,
    /// The tick's 3 x 3 solve and the node forces.
    pub solve: u32,
    /// The tissue law Q, the force cap and the requested currents (`J^T F` plus gravity).
    pub law: u32,
    /// The safety supervisor and the tick's outputs.
    pub supervisor: u32,
}

impl PhaseCycles {
    /// Number of phases.
    pub const COUNT: usize = 6;

    /// The phases' names, in order (the fields' names).
    pub const NAMES: [&'static str; Self::COUNT] = [
        "kinematics",
        "detection",
        "patch",
        "solve",
        "law",
        "supervisor",
    ];

    /// The parts in order ([`PhaseCycles::NAMES`]): kinematics, detection, patch, solve, law,
    /// supervisor.
    pub fn to_array(&self) -> [u32; Self::COUNT] {
        [
            self.kinematics,
            self.detection,
            self.patch,
            self.solve,
            self.law,
            self.supervisor,
        ]
    }

    /// The parts from an array in [`PhaseCycles::to_array`]'s order.
    pub fn from_array(p: [u32; Self::COUNT]) -> Self {
        let [kinematics, detection, patch, solve, law, supervisor] = p;
        PhaseCycles {
            kinematics,
            detection,
            patch,
            solve,
            law,
            supervisor,
        }
    }

    /// The sum of the parts (wrapping, as the counts are).
    pub fn total(&self) -> u32 {
        self.to_array().iter().fold(0, |a, &b| a.wrapping_add(b))
    }
}

/// Messages from the device.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum DeviceToHost {
    /// Identity, sent at boot and on [`HostToDevice::Hello`].
    Hello {
        /// [`PROTOCOL_VERSION`].
        protocol: u16,
        /// CRC of the valid bank in flash (its identity), `None` if the bank is invalid.
        bank_crc: Option<u32>,
        /// The bank's scene id (0 without a valid bank).
        scene_id: u64,
        /// Nodes in the bank's R (0 without a valid bank).
        node_count: u16,
    },
    /// Periodic status.
    Telemetry(Telemetry),
    /// Software-in-the-loop: what the firmware commands this tick (the motor currents), with
    /// the tick's outcome for the harness (sent over the lockstep plant channel, not the link).
    Plant {
        /// Tick the currents belong to.
        tick: u32,
        /// Motor currents, A (zero unless armed).
        currents_a: [f32; 3],
        /// Force rendered on the tool this tick, N (produced by the motors only when armed).
        force_n: [f32; 3],
        /// Safety state after this tick.
        state: State,
        /// Contact nodes this tick (0 when free).
        contact_nodes: u8,
        /// Cost of this tick's loop body (encoders in to currents out), in CPU cycles (or
        /// instructions under QEMU).
        body_cycles: u32,
        /// Cost of the whole previous tick (executor, link and plant I/O included), same unit.
        tick_cycles: u32,
        /// `body_cycles` split at the loop's phase boundaries (protocol 5): the six parts sum
        /// to `body_cycles`.
        phase_cycles: PhaseCycles,
    },
    /// Sent once when a fault is latched.
    Fault {
        /// Tick of the fault.
        tick: u32,
        /// Why.
        reason: FaultReason,
        /// Reason-specific detail (bank error code, joint or motor index), else 0.
        detail: u32,
    },
    /// Why the chip last started (protocol 6): sent after the boot `Hello` and after every
    /// `Hello` reply.
    Reset {
        /// The reset cause.
        cause: ResetCause,
    },
}

/// Messages from the host.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum HostToDevice {
    /// Ask for [`DeviceToHost::Hello`].
    Hello,
    /// Keep-alive; the device faults with [`FaultReason::LinkSilent`] without frames.
    Heartbeat,
    /// Enable the motors (only from `Disarmed`).
    Arm,
    /// Zero current, back to `Disarmed`.
    Disarm,
    /// Select the rendering mode.
    SetMode(Mode),
    /// Declare the current pose the calibration's home pose.
    ZeroEncoders,
    /// Leave `Fault` for `Disarmed` (if the cause is gone).
    ClearFault,
    /// Software-in-the-loop: the plant's encoder counts for a tick.
    Plant {
        /// Tick the counts belong to.
        tick: u32,
        /// Encoder counts per joint (pitch, yaw, insertion).
        encoder_counts: [i32; 3],
    },
}

/// Why a frame could not be encoded or decoded.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FrameError {
    /// Encoding: the message does not fit in [`MAX_MESSAGE`] bytes.
    MessageTooLarge,
    /// Encoding: the output buffer is too small for the frame (use [`MAX_FRAME`]).
    BufferTooSmall,
    /// Decoding: more bytes than the decoder's buffer before a delimiter; dropped.
    Oversize,
    /// Decoding: not valid COBS.
    Cobs,
    /// Decoding: shorter than a CRC plus one byte (a truncated frame).
    TooShort,
    /// Decoding: CRC mismatch.
    Crc,
    /// Decoding: CRC fine but not a message of the expected type (or bytes left over).
    Malformed,
}

impl core::fmt::Display for FrameError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            FrameError::MessageTooLarge => "message larger than MAX_MESSAGE",
            FrameError::BufferTooSmall => "frame buffer too small",
            FrameError::Oversize => "frame longer than the decoder buffer",
            FrameError::Cobs => "invalid COBS encoding",
            FrameError::TooShort => "frame too short",
            FrameError::Crc => "frame CRC mismatch",
            FrameError::Malformed => "frame does not decode to a message",
        })
    }
}

impl core::error::Error for FrameError {}

/// Encode `msg` as one frame (including the trailing 0x00) into `buf`; returns the frame.
/// A buffer of [`MAX_FRAME`] bytes always suffices.
pub fn encode_frame<'b, M: Serialize>(
    msg: &M,
    buf: &'b mut [u8],
) -> Result<&'b mut [u8], FrameError> {
    let mut scratch = [0u8; MAX_MESSAGE + FRAME_CRC_LEN];
    let (body, _) = scratch.split_at_mut(MAX_MESSAGE);
    let used = postcard::to_slice(msg, body)
        .map_err(|_| FrameError::MessageTooLarge)?
        .len();
    let crc = CRC32.checksum(scratch.get(..used).unwrap_or(&[]));
    let payload_len = used + FRAME_CRC_LEN;
    scratch
        .get_mut(used..payload_len)
        .ok_or(FrameError::MessageTooLarge)?
        .copy_from_slice(&crc.to_le_bytes());
    let payload = scratch.get(..payload_len).unwrap_or(&[]);
    let n = cobs::try_encode(payload, buf).map_err(|_| FrameError::BufferTooSmall)?;
    *buf.get_mut(n).ok_or(FrameError::BufferTooSmall)? = 0;
    buf.get_mut(..=n).ok_or(FrameError::BufferTooSmall)
}

/// Encode a plant-channel message (`SPEC.md`, "Plant channel"): `len: u8 ++ postcard(msg)`,
/// no CRC, no COBS (the lockstep pipes of software in the loop neither lose nor corrupt bytes).
/// Returns the bytes written into `buf`.
pub fn encode_plant<'b, M: Serialize>(msg: &M, buf: &'b mut [u8]) -> Result<&'b [u8], FrameError> {
    let (len, body) = buf.split_first_mut().ok_or(FrameError::BufferTooSmall)?;
    let used = postcard::to_slice(msg, body)
        .map_err(|_| FrameError::BufferTooSmall)?
        .len();
    *len = u8::try_from(used).map_err(|_| FrameError::MessageTooLarge)?;
    buf.get(..=used).ok_or(FrameError::BufferTooSmall)
}

/// Decode a plant-channel message from `body`, the `len` bytes that followed its length byte
/// ([`encode_plant`]): they must decode to exactly one message.
pub fn decode_plant<M: DeserializeOwned>(body: &[u8]) -> Result<M, FrameError> {
    if body.is_empty() {
        return Err(FrameError::TooShort);
    }
    match postcard::take_from_bytes(body) {
        Ok((msg, [])) => Ok(msg),
        _ => Err(FrameError::Malformed),
    }
}

/// Decode one complete frame held in `frame` (COBS bytes, with or without the trailing 0x00;
/// decoded in place, so `frame` is overwritten).
pub fn decode_frame<M: DeserializeOwned>(frame: &mut [u8]) -> Result<M, FrameError> {
    let body_end = frame.iter().position(|&b| b == 0).unwrap_or(frame.len());
    let body = frame.get_mut(..body_end).unwrap_or(&mut []);
    if body.is_empty() {
        return Err(FrameError::TooShort);
    }
    let len = cobs::decode_in_place(body).map_err(|_| FrameError::Cobs)?;
    let payload = body.get(..len).ok_or(FrameError::Cobs)?;
    if payload.len() <= FRAME_CRC_LEN {
        return Err(FrameError::TooShort);
    }
    let (msg, crc) = payload.split_at(payload.len() - FRAME_CRC_LEN);
    let stored = <[u8; 4]>::try_from(crc).map_err(|_| FrameError::TooShort)?;
    if CRC32.checksum(msg) != u32::from_le_bytes(stored) {
        return Err(FrameError::Crc);
    }
    match postcard::take_from_bytes::<M>(msg) {
        Ok((m, [])) => Ok(m),
        _ => Err(FrameError::Malformed),
    }
}

/// What a [`FrameDecoder`] has seen, all wrapping.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FrameStats {
    /// Frames decoded.
    pub ok: u32,
    /// Frames dropped for a CRC mismatch.
    pub crc: u32,
    /// Frames dropped for invalid COBS.
    pub cobs: u32,
    /// Frames dropped for being too short.
    pub short: u32,
    /// Frames dropped for not decoding to a message.
    pub malformed: u32,
    /// Frames dropped for exceeding the buffer.
    pub oversize: u32,
}

impl FrameStats {
    /// All dropped frames.
    pub fn errors(&self) -> u32 {
        self.crc
            .wrapping_add(self.cobs)
            .wrapping_add(self.short)
            .wrapping_add(self.malformed)
            .wrapping_add(self.oversize)
    }
}

/// Streaming frame decoder for messages of type `M` with an `N`-byte buffer (no heap). Feed it
/// bytes as they arrive; at each 0x00 it yields the message or why the frame was dropped.
pub struct FrameDecoder<M, const N: usize = MAX_FRAME> {
    buf: [u8; N],
    len: usize,
    overflow: bool,
    stats: FrameStats,
    _msg: PhantomData<fn() -> M>,
}

impl<M: DeserializeOwned, const N: usize> Default for FrameDecoder<M, N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<M: DeserializeOwned, const N: usize> FrameDecoder<M, N> {
    /// An empty decoder.
    pub const fn new() -> Self {
        FrameDecoder {
            buf: [0; N],
            len: 0,
            overflow: false,
            stats: FrameStats {
                ok: 0,
                crc: 0,
                cobs: 0,
                short: 0,
                malformed: 0,
                oversize: 0,
            },
            _msg: PhantomData,
        }
    }

    /// Counters so far.
    pub fn stats(&self) -> FrameStats {
        self.stats
    }

    /// Drop any partial frame (e.g. after a link reset). Counters are kept.
    pub fn reset(&mut self) {
        self.len = 0;
        self.overflow = false;
    }

    /// Feed one byte; at a delimiter that ends a non-empty frame, the result for that frame.
    pub fn feed(&mut self, byte: u8) -> Option<Result<M, FrameError>> {
        if byte != 0 {
            match self.buf.get_mut(self.len) {
                Some(slot) if !self.overflow => {
                    *slot = byte;
                    self.len += 1;
                }
                _ => self.overflow = true,
            }
            return None;
        }
        let (len, overflow) = (self.len, self.overflow);
        self.reset();
        if overflow {
            self.stats.oversize = self.stats.oversize.wrapping_add(1);
            return Some(Err(FrameError::Oversize));
        }
        if len == 0 {
            return None;
        }
        let result = decode_frame::<M>(self.buf.get_mut(..len).unwrap_or(&mut []));
        let counter = match result {
            Ok(_) => &mut self.stats.ok,
            Err(FrameError::Crc) => &mut self.stats.crc,
            Err(FrameError::Cobs) => &mut self.stats.cobs,
            Err(FrameError::TooShort) => &mut self.stats.short,
            Err(_) => &mut self.stats.malformed,
        };
        *counter = counter.wrapping_add(1);
        Some(result)
    }

    /// Feed a slice; iterate over the results of the frames it completes. Bytes not consumed
    /// when the iterator is dropped are not fed.
    pub fn feed_slice<'s>(&'s mut self, bytes: &'s [u8]) -> FeedIter<'s, M, N> {
        FeedIter {
            decoder: self,
            bytes: bytes.iter(),
        }
    }
}

/// Iterator returned by [`FrameDecoder::feed_slice`].
pub struct FeedIter<'s, M, const N: usize> {
    decoder: &'s mut FrameDecoder<M, N>,
    bytes: core::slice::Iter<'s, u8>,
}

impl<M: DeserializeOwned, const N: usize> Iterator for FeedIter<'_, M, N> {
    type Item = Result<M, FrameError>;

    fn next(&mut self) -> Option<Self::Item> {
        for &b in self.bytes.by_ref() {
            if let Some(r) = self.decoder.feed(b) {
                return Some(r);
            }
        }
        None
    }
}
