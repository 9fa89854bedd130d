//! Host side of the haptic soft-tissue simulator (Cotin, Delingette & Ayache, IEEE TVCG 1999),
//! around the FEM engine (crate [`fem`]: mesh I/O, P1 elasticity, orderings, compliance).
//!
//! Pipeline, in module order: [`scene`] (scene files), [`kinematics`] (the gimbal on the host)
//! and [`reach`] (the region the tool can touch) feed [`bank`], the bank stage (scene ->
//! reachable region -> compliance -> bank bytes); [`contact`] is the tool patch in f64, the
//! reference for the firmware's. The display side: [`display`] (its sources of telemetry, from
//! the [`virtual_device`] or a real one, frames and the browser viewer), [`deform`] (surface
//! displacement from the contact forces), [`record`] (ParaView series) and [`script`] (aiming
//! and the scripted hand motions, on [`trajectory`]'s tool paths); [`demo`] runs them together.
//! [`link`] is the client of a device's serial link (port, frames, greeting), [`device`] a
//! bring-up session on it (check, zero, arm with a guard that disarms when dropped). [`sil`] runs the firmware image under QEMU,
//! [`calibrate`] fits the tissue laws and the motor constants; [`mod@bench`] measures;
//! [`large`] presses the organ in the large-deformation reference.
//! Leaves the others share: [`units`] (mesh units), [`cache`] (the on-disk cache and FNV-1a),
//! [`linalg`] (3 x 3 blocks) and [`realtime`] (thread scheduling).

pub mod bank;
pub mod bench;
pub mod cache;
pub mod calibrate;
pub mod contact;
pub mod deform;
pub mod demo;
pub mod device;
pub mod display;
pub mod fsio;
pub mod kinematics;
pub mod large;
pub mod linalg;
pub mod link;
pub mod mcu;
pub mod meshing;
pub mod organ;
pub mod probe;
pub mod reach;
pub mod realtime;
pub mod record;
pub mod report;
pub mod rng;
pub mod rss;
pub mod scene;
pub mod scene_new;
pub mod script;
pub mod sil;
pub mod specimen;
pub mod study;
pub mod trajectory;
pub mod units;
pub mod virtual_device;
