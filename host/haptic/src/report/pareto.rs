//! Where the knobs combine: the scene's mesh with each contact model ([`super::scale`]) and
//! each swept bank ([`super::couplings`]: truncation rule, radius and storage precision),
//! against force error, bank bytes and the MCU's worst loop-body instructions measured on that
//! very bank (QEMU, [`super::tick_cost`]). The front is the set of combinations no other beats
//! on all three.
//!
//! **Error.** The reference is the most converged answer this run has: the finest mesh's
//! tool patch at the scene's tip radius (f64, untruncated). A combination's error is bounded
//! by the triangle inequality, `e <= e_model + e_bank (1 + e_model)`: `e_model` the contact
//! model's error on the scene's mesh at the report's press (f64, untruncated), `e_bank` the
//! firmware's worst f32 error on that bank against the untruncated solve over the swept sites
//! (tool-patch error for the tool patch; the barycentric point contact's for the one- and
//! three-node models, which use only blocks every bank keeps). The tool patch at twice the
//! radius is left out: the sweep measures the bank at the scene's radius only.
//!
//! **Finer meshes** are plotted beside them with their discretisation error alone (f64,
//! untruncated; their bank's bytes at the scene's truncation, and whether it fits the MCU's
//! bank region). They are not run on the image and not on the front: their instruction counts
//! and truncation errors are not measured here.

use super::scale::MeshRun;
use super::{Knob, Point, Series};
use crate::bank::sweep::SweepRow;
use crate::sil::cost::CostStats;
use bank_format::region::BANK_LEN;
use std::collections::BTreeMap;

/// A swept bank the firmware ran on.
pub struct RunBank {
    /// The sweep's row for it.
    pub row: SweepRow,
    /// Its ticks on the QEMU image, by contact-set size.
    pub costs: BTreeMap<u8, CostStats>,
}

/// One combination.
#[derive(Debug, Clone)]
struct Combo {
    label: String,
    error: f64,
    bytes: f64,
    instructions: f64,
    chosen: bool,
}

/// Error below this is drawn at it (log axis).
const FLOOR: f64 = 1e-6;

/// The series of the front: points of the combinations' series, chosen by comparing their
/// instruction counts (which vary by a few between runs, so the front's membership can too).
pub const FRONT: &str = "Pareto front (error, bytes, instructions)";

/// How a combination's point label ends: `, <worst loop-body instructions> instructions`.
const INSTRUCTIONS: &str = " instructions";

/// A point label of this knob split into the combination and the worst loop-body instructions
/// it ends with (`None` for a label without them: the finer meshes', not run on the image).
/// The figures file keys a point by the combination and checks the instructions as a figure.
pub fn split_instructions(label: &str) -> Option<(&str, f64)> {
    let (combo, n) = label.rsplit_once(", ")?;
    Some((combo, n.strip_suffix(INSTRUCTIONS)?.parse().ok()?))
}

/// The knob, or `None` when there is no reference (one mesh only) or no bank was run.
/// `scene_bank` is the scene's own rule, radius (m) and storage precision.
pub fn section(runs: &[MeshRun], banks: &[RunBank], scene_bank: (&str, f64, &str)) -> Option<Knob> {
    let (coarse, finest) = (runs.first()?, runs.last()?);
    if runs.len() < 2 || banks.is_empty() {
        return None;
    }
    let tool_model = |r: &MeshRun| {
        r.forces
            .iter()
            .position(|f| f.model.starts_with("tool patch"))
    };
    let reference = finest.forces[tool_model(finest)?].force_n;
    let scene_model = tool_model(coarse)?;
    let relative = |f: f64| ((f - reference) / reference).abs();
    let mut combos = Vec::new();
    for (i, f) in coarse.forces.iter().enumerate() {
        if f.model.starts_with("tool patch") && i != scene_model {
            continue; // twice the radius: its truncation error is not swept
        }
        let e_model = relative(f.force_n);
        for b in banks.iter().filter(|b| b.row.fits_region) {
            let Some(worst) = super::tick_cost::body_worst(&b.costs, f.nodes) else {
                continue;
            };
            let e_bank = if i == scene_model {
                b.row.errors.patch_max
            } else {
                b.row.errors.point_max
            };
            let (rule, radius, precision) = (b.row.rule, b.row.radius_m, b.row.precision);
            combos.push(Combo {
                label: format!(
                    "{} / {} / {rule} {:.0} mm {precision} bank",
                    coarse.name,
                    f.model,
                    radius * 1e3
                ),
                error: (e_model + e_bank * (1.0 + e_model)).max(FLOOR),
                bytes: b.row.bank_bytes as f64,
                instructions: worst,
                chosen: i == scene_model
                    && rule == scene_bank.0
                    && (radius - scene_bank.1).abs() < 1e-9
                    && precision == scene_bank.2,
            });
        }
    }
    let beats = |a: &Combo, b: &Combo| {
        a.error <= b.error
            && a.bytes <= b.bytes
            && a.instructions <= b.instructions
            && (a.error < b.error || a.bytes < b.bytes || a.instructions < b.instructions)
    };
    let mut front: Vec<&Combo> = combos
        .iter()
        .filter(|c| !combos.iter().any(|o| beats(o, c)))
        .collect();
    front.sort_by(|a, b| {
        a.bytes
            .total_cmp(&b.bytes)
            .then(a.error.total_cmp(&b.error))
    });
    let point = |c: &Combo| Point {
        x: c.bytes,
        y: c.error,
        label: format!("{}, {:.0}{INSTRUCTIONS}", c.label, c.instructions),
    };
    // The finer meshes: discretisation error only, at the scene's truncation.
    let finer: Vec<(Point, bool)> = runs[1..]
        .iter()
        .flat_map(|r| {
            r.forces
                .iter()
                .enumerate()
                .filter(|&(i, _)| !(std::ptr::eq(r, finest) && Some(i) == tool_model(r)))
                .map(move |(_, f)| {
                    let fits = r.bank_bytes <= BANK_LEN;
                    let p = Point {
                        x: r.bank_bytes as f64,
                        y: relative(f.force_n).max(FLOOR),
                        label: format!(
                            "{} / {}: discretisation error only; bank {}",
                            r.name,
                            f.model,
                            if fits {
                                "fits the MCU"
                            } else {
                                "does NOT fit the MCU"
                            }
                        ),
                    };
                    (p, fits)
                })
        })
        .collect();
    let chosen = combos.iter().find(|c| c.chosen);
    let on_front = chosen.is_some_and(|c| front.iter().any(|f| f.label == c.label));
    let mut series = vec![Series {
        name: format!(
            "{}: contact model x bank (measured on the MCU image)",
            coarse.name
        ),
        points: combos.iter().map(point).collect(),
    }];
    if !finer.is_empty() {
        series.push(Series {
            name: "finer meshes: discretisation error alone (not run on the MCU)".into(),
            points: finer.iter().map(|(p, _)| p.clone()).collect(),
        });
    }
    if front.len() >= 3 {
        series.push(Series {
            name: FRONT.into(),
            points: front.iter().map(|c| point(c)).collect(),
        });
    }
    let front_text: Vec<String> = front
        .iter()
        .map(|c| {
            format!(
                "{} ({:.1} %, {:.0} B, {:.0} instructions)",
                c.label,
                100.0 * c.error,
                c.bytes,
                c.instructions
            )
        })
        .collect();
    let finer_fit = finer.iter().filter(|(_, fits)| *fits).count();
    Some(Knob {
        id: "pareto".into(),
        title: "Pareto front: force error against bank bytes and MCU instructions".into(),
        x_label: "bank bytes".into(),
        y_label: format!(
            "force error bound against {} / {}",
            finest.name,
            finest.forces[tool_model(finest)?].model
        ),
        log_x: true,
        log_y: true,
        series,
        chosen: chosen.map(point),
        finding: format!(
            "{} combinations of contact model and bank on {}, each bank run on the QEMU image; \
             the front (no other is better in error, bytes and instructions at once): {}. The \
             scene's choice ({}) is {}on the front. Finer meshes: {} of {} of their points \
             have a bank that fits the MCU's {} B bank region (the others cannot be chosen on \
             this MCU). The model errors come from one press, so a model's place here is that \
             site's (the refinement plot shows how far each model moves)",
            combos.len(),
            coarse.name,
            front_text.join(", "),
            chosen.map_or("not measured".into(), |c| c.label.clone()),
            if on_front { "" } else { "NOT " },
            finer_fit,
            finer.len(),
            BANK_LEN
        ),
    })
}
