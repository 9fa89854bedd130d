//! The boundary between the portable firmware and the hardware: encoders in, motor currents
//! out, link bytes both ways, and a cycle counter. An image implements these traits for its
//! platform (the QEMU software-in-the-loop image: a lockstep plant channel, USART1 and SysTick;
//! a board: timer-capture encoders, PWM current drivers, a UART and DWT) and hands them to
//! [`crate::app::App::tick`], which holds everything else.

use bank_format::State;

/// What a tick asks of the motor drivers, with the tick's outcome (a board's driver uses only
/// `currents_a`; the software-in-the-loop plant reports the rest to its harness).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Actuation {
    /// Tick the currents belong to.
    pub tick: u32,
    /// Motor currents to apply, A (zero unless armed).
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
}

/// The gimbal's encoders and motor drivers.
pub trait Plant {
    /// Why the plant could not be read or written (the image stops the loop on it).
    type Error;

    /// Latch the encoder counts (pitch, yaw, insertion) for tick `tick`.
    fn read_encoders(&mut self, tick: u32) -> Result<[i32; 3], Self::Error>;

    /// Drive the motors with `out.currents_a`.
    fn actuate(&mut self, out: &Actuation) -> Result<(), Self::Error>;
}

/// The host link's byte stream (a UART).
pub trait LinkPort {
    /// One received byte, if any is waiting (never blocks).
    fn read_byte(&mut self) -> Option<u8>;

    /// Send `bytes` (may block until they are out).
    fn write(&mut self, bytes: &[u8]);
}

/// A free-running cycle counter (wrapping): CPU cycles on a board, instructions under QEMU.
pub trait CycleCounter {
    /// The counter now.
    fn cycles(&self) -> u32;
}
