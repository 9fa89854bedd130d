//! The tissue law's degree: held-out fit error of Q (paper section 4, a polynomial force law
//! fitted to bench data) against MCU instructions per evaluation. Data: the bench compression
//! data in `host/data/` (model-generated, see its header); error: the 10-fold interleaved
//! cross-validation of [`crate::calibrate::fit::cross_validate`]; instructions: the path of one
//! in-domain evaluation of `TissueLaw::eval` in the thumbv7em disassembly
//! ([`crate::mcu::law_cost`]).

use super::{Knob, Point, Series};
use crate::calibrate::fit;
use crate::mcu::law_cost::EvalCost;
use anyhow::{Result, anyhow};

/// The knob from data `(x, y)` (linear model force, measured force) and the evaluation cost.
pub fn section(x: &[f64], y: &[f64], cost: &EvalCost) -> Result<Knob> {
    let rows = fit::survey(x, y, fit::AUTO_DEGREES)?;
    let mut points = Vec::new();
    for row in &rows {
        let instructions = cost.instructions_for_degree(row.degree).ok_or_else(|| {
            anyhow!(
                "TissueLaw::eval has no evaluation path for degree {}",
                row.degree
            )
        })?;
        points.push(Point {
            x: instructions as f64,
            y: 100.0 * row.cv_rms_rel,
            label: format!(
                "degree {}{}",
                row.degree,
                if row.monotone { "" } else { " (not monotone)" }
            ),
        });
    }
    let auto = fit::choose(&rows, fit::DEFAULT_TARGET_RMS);
    let chosen = auto.and_then(|d| {
        rows.iter()
            .position(|r| r.degree == d)
            .map(|i| points[i].clone())
    });
    let finding = match (auto, &chosen) {
        (Some(d), Some(p)) => format!(
            "`calibrate tissue --degree auto` picks degree {d}: {:.2} % held-out RMS error for \
             {} instructions per evaluation",
            p.y, p.x
        ),
        _ => "no increasing fit meets the target".to_string(),
    };
    Ok(Knob {
        id: "law-degree".into(),
        title: "Tissue law degree".into(),
        x_label: "MCU instructions per evaluation of Q".into(),
        y_label: "held-out RMS error, % of full scale".into(),
        log_x: false,
        log_y: true,
        series: vec![Series {
            name: "Chebyshev Q, brain compression data".into(),
            points,
        }],
        chosen,
        finding,
    })
}
