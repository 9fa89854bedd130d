//! The bank and the link: the compact, precomputed compliance data the MCU reads in place, and
//! the host-device link frames. `no_std`, no allocation (the writer needs feature `alloc`).
//!
//! The byte layout, its versioning rules, the CRC and every validation rule are specified in
//! `SPEC.md` beside this crate's `Cargo.toml`; this documentation covers the API.
//!
//! # The bank
//!
//! A *scene* says what the tool can reach; the host keeps only the surface nodes in that
//! reachable region R and writes, for each node k of R: its position, `C_kk`, and `C_kl` for
//! the neighbours l within a truncation radius (the paper's `T^f_k = C_kk^-1` and mutual
//! influence `M = C_SS` follow from these), plus R's triangles, a bucket grid for collision,
//! the tissue force law Q and the device calibration. `BankBuilder` (feature `alloc`) writes
//! it; [`Bank::parse`] validates it completely (bounds, indices, finite values, SPD blocks,
//! symmetric couplings, monotone Q, CRC, ...) without copying, after which every accessor is
//! a plain slice access. Every failure is a distinct [`BankError`].
//!
//! # The link
//!
//! [`DeviceToHost`] and [`HostToDevice`] messages travel as frames
//! `COBS(postcard(msg) ++ crc32) ++ 0x00` ([`encode_frame`], [`FrameDecoder`]).
//!
//! # Example
//!
//! ```
//! use bank_format::{Bank, BankError, FrameDecoder, HostToDevice, MAX_FRAME, encode_frame};
//!
//! // Firmware at boot: validate the bank region once, then read it in place.
//! fn boot(bank_region: &'static [u8]) -> Result<f32, BankError> {
//!     let bank = Bank::parse(bank_region)?;
//!     let _c_01 = bank.neighbours(0).first().and_then(|&l| bank.coupling(0, usize::from(l)));
//!     Ok(bank.tissue_law().eval(1.0))
//! }
//! assert_eq!(boot(&[]), Err(BankError::TooShort { needed: 32, got: 0 }));
//!
//! // Link: encode a command, decode it from the byte stream.
//! let mut buf = [0u8; MAX_FRAME];
//! let frame = encode_frame(&HostToDevice::Arm, &mut buf).unwrap();
//! let mut rx = FrameDecoder::<HostToDevice>::new();
//! let got: Vec<_> = rx.feed_slice(frame).collect();
//! assert_eq!(got, [Ok(HostToDevice::Arm)]);
//! ```
//!
//! All quantities are SI ([`UNITS`]); the format is little-endian and this crate only builds
//! for little-endian targets (x86-64, Cortex-M).
#![no_std]
#![deny(missing_docs)]
// Validation writes `!(x > 0.0)` on purpose: the negated comparison also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

#[cfg(feature = "alloc")]
extern crate alloc;

#[cfg(target_endian = "big")]
compile_error!("bank-format reads the bank in place and assumes a little-endian target");

mod error;
#[cfg(any(test, feature = "test-fixtures"))]
pub mod fixtures;
mod frame;
mod law;
mod layout;
mod reader;
mod samples;
#[cfg(feature = "alloc")]
mod writer;

/// The STM32F405 flash map: where the firmware image and the bank live. Generated at build time
/// from the workspace's `memory.x`, the one place the map is written (the firmware links
/// against the same file).
pub mod region {
    include!(concat!(env!("OUT_DIR"), "/region.rs"));
}

pub use error::{BankError, DeviceField};
pub use frame::{
    Contact, ContactPoint, Counters, DeviceToHost, FRAME_CRC_LEN, FaultReason, FeedIter,
    FrameDecoder, FrameError, FrameStats, HostToDevice, MAX_CONTACTS, MAX_FRAME, MAX_MESSAGE, Mode,
    PROTOCOL_VERSION, PhaseCycles, ResetCause, State, Telemetry, cobs_max_len, decode_frame,
    decode_plant, encode_frame, encode_plant,
};
/// The `heapless` crate the message types use (telemetry's contact list), re-exported so the
/// firmware and host build `Telemetry` with the same version.
pub use heapless;
pub use law::{LAW_SAMPLES, LawKind, TissueLaw};
pub use layout::{
    BANK_ALIGN, BankHeader, BankMeta, CANDIDATE_WIDEN_CELLS, CKL16_EXP_MAX, CKL16_EXP_MIN,
    CRC_OFFSET, CRC32, Ckl16, DeviceCalibration, GRAVITY_COEFF_MAX, GRAVITY_COEFFS,
    GravityCompensation, GridHeader, HEADER_LEN, LAW_CHEBYSHEV, LAW_LINEAR, LawRecord, MAGIC,
    MAX_CELL_CANDIDATES, MAX_LAW_COEFFS, MAX_NODE_NEIGHBOURS, MAX_NODE_TRIANGLES, MAX_NODES,
    MAX_PRONY_TERMS, MAX_SAMPLE_LEVEL, MAX_SECTIONS, MAX_TRIANGLES, OCCUPIED_WIDEN_CELLS,
    PIECE_CELLS, PLANE_TOL, Precision, RELAXATION_TAU_MAX_S, RELAXATION_TAU_MIN_S, Relaxation,
    SECTION_ALIGN, SECTION_ENTRY_LEN, SampleHeader, SectionEntry, SectionKind, TrianglePlane,
    VERSION_MAJOR, VERSION_MINOR, bank_crc, reseal,
};
pub use layout::{DEFAULT_LINK_TIMEOUT_MS, LINK_TIMEOUT_MS_MAX, LINK_TIMEOUT_MS_MIN};
pub use reader::{Bank, Grid, SPD_PIVOT_REL, TRUNCATION_SLACK, UpperCouplings, validate_device};
pub use samples::{
    MIN_PIVOT_REL, Samples, ill_conditioned_sample, lattice_bary, lattice_corners, lattice_index,
    lattice_len, min_eigenvalue_bound,
};
#[cfg(feature = "alloc")]
pub use writer::{
    AlignedBytes, BankBuilder, BuildError, ContactSamples, INPUT_SYMMETRY_REL, SharedLattice,
    encode_ckl16, triangle_plane,
};

/// Every quantity crossing the host-device boundary is SI: metres, newtons, pascals, seconds,
/// amperes. Compliance blocks are therefore in metres per newton.
pub const UNITS: &str = "SI: m, N, Pa, s, A; compliance in m/N";
