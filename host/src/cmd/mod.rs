//! Subcommands.

pub mod bank;
pub mod bench;
pub mod bench_heartbeat;
pub mod bench_law;
pub mod calibrate;
pub mod compliance;
pub mod confirm;
pub mod contact;
pub mod demo;
pub mod device;
pub mod fixing;
pub mod flash;
pub mod mesh;
pub mod organ;
pub mod refinement;
pub mod report;
pub mod scene;
pub mod script_arg;
pub mod sil;
pub mod specimen;
pub mod units_arg;
