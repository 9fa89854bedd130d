//! Bench calibration (issue 8): the tissue force law Q and the display law P (paper, section
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

pub mod cheb;
pub mod csv;
pub mod fit;
pub mod gravity;
pub mod motor;
pub mod plot;
pub mod relaxation;
pub mod scene_edit;
pub mod specimen;
