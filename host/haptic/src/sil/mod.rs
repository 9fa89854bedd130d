//! Software in the loop: the real firmware image (`firmware/qemu`) under QEMU against a
//! simulated haptic device. [`plant`] is the gimbal (rigid joints, motors, the user's hand),
//! [`script`] the hand's scripted motions ([`wander`] the seeded random one) and [`harness`] starts QEMU, exchanges encoder counts
//! and currents with the image every tick over a lockstep channel and collects its link
//! traffic; [`cost`] groups instruction counts per tick (the image's size is
//! [`crate::mcu::image_size`]'s); [`source`] shows a run in the display; [`bank`] builds and
//! caches the bank a run loads.

pub mod bank;
pub mod cost;
pub mod harness;
pub mod plant;
pub mod script;
pub mod source;
pub mod wander;
