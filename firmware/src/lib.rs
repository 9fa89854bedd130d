//! The portable 1 kHz haptic loop. It holds no hardware: the same code will run in the QEMU
//! software-in-the-loop image, on the board and inside the host's virtual device.
//!
//! The loop itself arrives with the portable-loop issue; this crate currently only builds for
//! the host and for `thumbv7em-none-eabihf` so the workspace layout is fixed from day one.
#![no_std]

/// Tick period of the force loop, in seconds (1 kHz).
pub const TICK_PERIOD_S: f32 = 1.0e-3;

pub mod contact;
pub mod device;
pub mod safety;
pub mod solve;
