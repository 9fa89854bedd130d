//! Bench calibration: the tissue force law Q and the display law P (paper, section
//! 3-4, fig. 9) fitted to compression curves, and the motor torque constants fitted to
//! load-cell measurements.
//!
//! One job per module: [`csv`] reads bench files and names the line of every bad value,
//! [`cheb`] is the Chebyshev basis on the data interval, [`fit`] the least-squares fit (QR),
//! the degree choice by cross-validation and the monotonicity check, [`motor`] the per-axis
//! torque-constant fit, [`scene_edit`] writes results into a scene file without disturbing its
//! comments, [`specimen`] computes the linear model's prediction for a compression specimen, and
//! [`plot`] draws data, fit and residuals (PNG and SVG); [`gravity`] fits the feed-forward for
//! the instrument's own weight to the currents that hold it at a few poses; [`relaxation`] fits
//! Fung's quasi-linear viscoelasticity (Prony terms and the instantaneous elastic law) to a
//! ramp-and-hold test. (What evaluating a fitted law costs on the MCU is
//! [`crate::mcu::law_cost`]'s.)
//!
//! Each `host calibrate` command is one `run(&Config) -> Result<Report>` here: [`tissue::run`],
//! [`motor::run`], [`gravity::run`], [`specimen::run`], [`relaxation::run`]; it reads the bench
//! file, fits, writes the plots and the scene, and returns a report the CLI prints (as text or
//! as the report's JSON).

pub mod cheb;
pub mod csv;
pub mod fit;
pub mod gravity;
pub mod motor;
pub mod plot;
pub mod relaxation;
pub mod scene_edit;
pub mod specimen;
pub mod tissue;

use anyhow::{Context, Result};
use std::path::Path;

/// Edits the scene file `path` in place: `edit` turns its text into the new text, which is
/// written atomically (through a link to it, with its mode kept).
fn write_scene(path: &Path, edit: impl FnOnce(&str) -> Result<String>) -> Result<()> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("{}: cannot read the scene", path.display()))?;
    let new = edit(&text)?;
    crate::fsio::write_atomic(path, new.as_bytes(), &[])
        .with_context(|| format!("writing {}", path.display()))
}
