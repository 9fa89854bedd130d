//! The project's one seeded stream ([`SplitMix64`], from the workspace crate `splitmix`): the
//! bank sweep's sites, the readers' mutation fuzz, the calibration tests' synthetic noise.

pub use splitmix::SplitMix64;
