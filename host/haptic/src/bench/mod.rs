//! Benchmarks (`host bench …`): each one function with a typed configuration that returns
//! typed figures, which the command prints. Speed is measured here, never asserted by tests;
//! tests check behaviour.
//!
//! [`compliance`]: the compliance precompute (assembly, factorisation, column solves, peak
//! memory) on a mesh; [`refinement`]: one tool press, point contact against the tool tip, on an
//! organ meshed at several sizes; [`sil`]: instructions per tick of the firmware image under
//! QEMU along the press, slide and strike scripts, and its flash and RAM; [`tick`]: the
//! firmware's loop run natively on a bank; [`precompute`]: a sampled scene's precompute (its
//! contact samples and display fields, [`precompute::measure`]) and the patch compliance's
//! methods ([`precompute::patch_methods`]).

pub mod compliance;
pub mod precompute;
pub mod refinement;
pub mod sil;
pub mod tick;
