//! Host side of the haptic soft-tissue simulator (Cotin, Delingette & Ayache, IEEE TVCG 1999).
//!
//! Pipeline, in module order: [`mesh`] (read and validate a tetrahedral organ), [`fem`] (P1 linear
//! elasticity, the paper's section 3), [`compliance`] (the "elementary deformations" of section 6
//! as compliance blocks C_nk, and the imposed-displacement solve of eq. 2 / appendix A); [`scene`]
//! (scene files) and [`reach`] (the region the tool can touch) feed the bank builder. The
//! display side: [`source`] (telemetry from the [`virtual_device`] or a real one), [`deform`]
//! (surface displacement from the contact forces), [`display`] (frames and the browser viewer),
//! [`record`] (ParaView series) and [`script`] (aiming and scripted hand motions).

pub mod bank;
pub mod calibrate;
pub mod contact;
pub mod deform;
pub mod display;
pub mod fsio;
pub mod kinematics;
pub mod progress;
pub mod reach;
pub mod record;
pub mod scene;
pub mod script;
pub mod sil;
pub mod source;
pub mod virtual_device;
