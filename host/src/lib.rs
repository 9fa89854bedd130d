//! Host side of the haptic soft-tissue simulator (Cotin, Delingette & Ayache, IEEE TVCG 1999).
//!
//! Pipeline, in module order: [`mesh`] (read and validate a tetrahedral organ), [`fem`] (P1 linear
//! elasticity, the paper's section 3), [`compliance`] (the "elementary deformations" of section 6
//! as compliance blocks C_nk, and the imposed-displacement solve of eq. 2 / appendix A); [`scene`]
//! (scene files) and [`reach`] (the region the tool can touch) feed the bank builder.

pub mod calibrate;
pub mod compliance;
pub mod contact;
pub mod fem;
pub mod mesh;
pub mod ordering;
pub mod reach;
pub mod scene;
pub mod sil;
pub mod vec3;
