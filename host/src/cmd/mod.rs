//! Subcommands.

pub mod bank;
pub mod bench;
pub mod calibrate;
pub mod compliance;
pub mod demo;
pub mod fixing;
