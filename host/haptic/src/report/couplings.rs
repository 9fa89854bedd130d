//! The bank's couplings: which compliance blocks `C_ij` it keeps (the superposition of
//! elementary deformations, paper section 3.2, and the mutual-influence solve of several
//! contact nodes, eq. 2, need the block of every pair in one contact set) against the force
//! error and the bank's bytes. Measured by [`crate::bank::sweep`] (the same code as `host bank
//! sweep`): contact sites spread over the reachable region by area, each pressed along the
//! normal, the firmware's own point and tool-patch solves on each bank against the f64 solve on
//! the untruncated compliance.

use super::{HardCase, Knob, Point, Series, Verdict};
use crate::bank::Prepared;
use crate::bank::sweep::{self, SweepConfig, SweepRow};
use crate::scene::Couplings;
use anyhow::Result;
use bank_format::Precision;

/// The sweep the report runs: radius rule over a few radii, and the tool rule alone and with
/// two radii's pairs added (three points per series).
pub fn measure(prep: &Prepared, quick: bool) -> Result<Vec<SweepRow>> {
    let config = SweepConfig {
        radii: if quick {
            vec![0.0, 0.006, 0.012, 0.02]
        } else {
            vec![0.0, 0.004, 0.008, 0.012, 0.02, 0.03]
        },
        tool_radii: vec![0.0, 0.006, 0.012],
        sites: if quick { 300 } else { 1000 },
        depth_m: 0.005,
        seed: 1,
        precisions: vec![Precision::F32, Precision::Bfp16],
    };
    sweep::run(prep, &config, None)
}

/// Error below this is drawn at it (log axis).
const FLOOR: f64 = 1e-12;

/// The knob (error against bytes) and the hard-case rows (the tool rule against 1e-4, the
/// scene's own bank as it is).
pub fn section(rows: &[SweepRow], prep: &Prepared) -> (Knob, Vec<HardCase>) {
    let point = |r: &SweepRow, y: f64| Point {
        x: r.bank_bytes as f64,
        y: y.max(FLOOR),
        label: format!("{} {:.0} mm {}", r.rule, r.radius_m * 1e3, r.precision),
    };
    let series = |rule: &str, precision: Precision, name: &str, y: fn(&SweepRow) -> f64| Series {
        name: name.into(),
        points: rows
            .iter()
            .filter(|r| r.rule == rule && r.precision == precision.name())
            .map(|r| point(r, y(r)))
            .collect(),
    };
    let f32 = Precision::F32.name();
    let bank = &prep.organ.scene.bank;
    let (rule, radius) = match bank.couplings {
        Couplings::Radius => ("radius", bank.truncation_radius_m),
        Couplings::Tool => ("tool", bank.truncation_radius_m),
    };
    let own = rows.iter().find(|r| {
        r.rule == rule && (r.radius_m - radius).abs() < 1e-9 && r.precision == bank.precision.name()
    });
    let tool = rows.iter().find(|r| r.rule == "tool" && r.precision == f32);
    let tool16 = rows
        .iter()
        .find(|r| r.rule == "tool" && r.precision == Precision::Bfp16.name());
    let sites = rows.first().map_or(0, |r| r.sites);
    let finding = match (own, tool) {
        (Some(o), Some(t)) => format!(
            "the scene's bank ({} rule, {:.0} mm, {}): {} B, worst tool-patch error {:.1e} over \
             {} sites; the tool rule keeps the pairs one tool patch can load together: {} B, \
             worst {:.1e}{}{}",
            o.rule,
            o.radius_m * 1e3,
            o.precision,
            o.bank_bytes,
            o.errors.patch_max,
            sites,
            t.bank_bytes,
            t.errors.patch_max,
            if t.bank_bytes > DEMO_BUDGET {
                " (over the demo's 128 KiB budget)"
            } else {
                ""
            },
            tool16.map_or(String::new(), |h| format!(
                "; with 16-bit blocks (bfp16) {} B, worst {:.1e}",
                h.bank_bytes, h.errors.patch_max
            ))
        ),
        _ => "the scene's own bank is not among the swept rows".into(),
    };
    let knob = Knob {
        id: "bank-couplings".into(),
        title:
            "Bank couplings: truncation rule and storage precision against force error and bytes"
                .into(),
        x_label: "bank bytes".into(),
        y_label: "relative force error over the reachable region (worst; mean where named)".into(),
        log_x: true,
        log_y: true,
        series: vec![
            series("radius", Precision::F32, "radius rule, tool patch", |r| {
                r.errors.patch_max
            }),
            series(
                "radius",
                Precision::F32,
                "radius rule, tool patch, mean",
                |r| r.errors.patch_mean,
            ),
            series(
                "radius",
                Precision::F32,
                "radius rule, point contact",
                |r| r.errors.point_max,
            ),
            series(
                "radius",
                Precision::Bfp16,
                "storage precision bfp16: radius rule, tool patch",
                |r| r.errors.patch_max,
            ),
            series(
                "tool",
                Precision::F32,
                "tool rule (+ radius), tool patch",
                |r| r.errors.patch_max,
            ),
            series(
                "tool",
                Precision::Bfp16,
                "storage precision bfp16: tool rule (+ radius), tool patch",
                |r| r.errors.patch_max,
            ),
        ],
        chosen: own.map(|o| point(o, o.errors.patch_max)),
        finding,
    };
    // Each row: the firmware's worst tool-patch force on that bank against the 1e-4 bound.
    let row = |case: String, r: &SweepRow| HardCase {
        case,
        measurement: format!(
            "firmware f32 tool-patch force on a {} B bank ({} blocks), worst over {} sites",
            r.bank_bytes, r.precision, r.sites
        ),
        reference: "f64 solve on the untruncated compliance, bound 1e-4".into(),
        verdict: if r.errors.patch_max <= 1e-4 {
            Verdict::MatchesReference
        } else {
            Verdict::Weakness
        },
        value: Some(r.errors.patch_max),
        reference_value: Some(1e-4),
    };
    let mut cases = Vec::new();
    if let Some(t) = tool {
        cases.push(row("every contact the tool can make (tool rule)".into(), t));
    }
    if let Some(o) = own {
        cases.push(row(
            format!(
                "the scene's bank ({} rule, {:.0} mm)",
                o.rule,
                o.radius_m * 1e3
            ),
            o,
        ));
    }
    (knob, cases)
}

/// The demo bank's size budget: 128 KiB.
const DEMO_BUDGET: usize = 128 * 1024;
