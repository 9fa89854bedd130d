//! The bank: the compact, precomputed compliance data the MCU reads in place, and the
//! host-device link frames. `no_std`, no allocation.
//!
//! The layout and its written specification arrive with the scenes-and-banks issue; until then
//! this crate only fixes the units and constants both sides agree on.
#![no_std]

/// Every quantity crossing the host-device boundary is SI: metres, newtons, pascals, seconds,
/// amperes. Compliance blocks are therefore in metres per newton.
pub const UNITS: &str = "SI: m, N, Pa, s, A; compliance in m/N";
