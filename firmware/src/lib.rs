//! The portable 1 kHz haptic loop. It holds no hardware: the same code will run in the QEMU
//! software-in-the-loop image, on the board and inside the host's virtual device.
//!
//! One tick ([`tick::HapticLoop::tick`]), following the paper's pipeline: encoder counts ->
//! gimbal forward kinematics ([`device`]) -> contact detection and tracking on the bank's
//! reachable surface ([`contact`], paper section 5) -> contact solve in compliance form and the
//! tissue law Q ([`solve`], eqs. 3-8) -> the bank's optional viscoelastic relaxation
//! ([`relax`], Fung's QLV) -> `J^T F`, plus the bank's feed-forward for the
//! instrument's weight ([`tick::gravity_efforts`]) -> motor currents -> limits and the safety
//! supervisor ([`safety`]). `no_std`, no heap, f32.
//!
//! Around the loop, [`app`] is the device application (link commands, faults, telemetry) and
//! [`hal`] the trait boundary an image implements for its hardware; the QEMU
//! software-in-the-loop image lives in `firmware/qemu/`, the STM32F405 board image in
//! `firmware/board/`. For the images: [`deadline`] (tick overruns on a cycle counter),
//! [`reset`] (the reset cause from the reset flags), [`brownout`] (the brown-out level from the
//! option bytes) and [`stm32_gpio`] (GPIO register words for the panic path).
#![no_std]
// No panic paths in the firmware: every module the tick calls is checked (tests may unwrap).
#![cfg_attr(
    not(test),
    deny(
        clippy::unwrap_used,
        clippy::expect_used,
        clippy::panic,
        clippy::indexing_slicing,
        clippy::unreachable,
        clippy::todo
    )
)]

/// Rate of the force loop, Hz: the one place it is written (the images' tickers, the host's
/// virtual device and SIL plant derive from it).
pub const TICK_HZ: u32 = 1_000;

/// Tick period of the force loop, in seconds.
pub const TICK_PERIOD_S: f32 = 1.0 / TICK_HZ as f32;

pub mod amplifier;
pub mod app;
pub mod brownout;
pub mod cholesky;
pub mod contact;
pub mod deadline;
pub mod device;
pub mod encoder;
#[cfg(any(test, feature = "test-fixtures"))]
pub mod fixtures;
pub mod hal;
pub mod link;
pub mod patch;
pub mod relax;
pub mod reset;
pub mod safety;
pub mod solve;
pub mod stm32_gpio;
pub mod tick;
mod vec3;
