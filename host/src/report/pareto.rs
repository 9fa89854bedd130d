//! Where the knobs combine: every (mesh, contact model) pair measured by [`super::scale`],
//! with its force error against the most converged answer this run has (the finest mesh's
//! tool patch at the scene's tip radius), its bank's bytes, and the MCU's worst loop-body
//! instructions at its contact-set size (QEMU, [`super::firmware`]). The front is the set of
//! pairs no other pair beats on all three. The bank's truncation and storage precision are not
//! among the knobs yet (they come with `host bank sweep`).
//!
//! The instruction count is the one measured on the scene's own bank: the tick's cost depends
//! on the contact-set size (patch, solve) and on the bank's local density (detection), not on
//! the mesh's size, which is an assumption of this plot, not a measurement.

use super::scale::MeshRun;
use super::{Knob, Point, Series};

/// One combination.
#[derive(Debug, Clone)]
struct Combo {
    label: String,
    error: f64,
    bytes: f64,
    instructions: f64,
    chosen: bool,
}

/// The knob, or `None` when there is no reference or no instruction count.
pub fn section(runs: &[MeshRun], instructions: &dyn Fn(usize) -> Option<f64>) -> Option<Knob> {
    let finest = runs.last()?;
    let scene_model = finest
        .forces
        .iter()
        .position(|f| f.model.starts_with("tool patch"))?;
    let reference = finest.forces[scene_model].force_n;
    let mut combos = Vec::new();
    for (m, run) in runs.iter().enumerate() {
        for (i, f) in run.forces.iter().enumerate() {
            if m + 1 == runs.len() && i == scene_model {
                continue; // the reference itself
            }
            combos.push(Combo {
                label: format!("{} / {}", run.name, f.model),
                error: ((f.force_n - reference) / reference).abs().max(1e-6),
                bytes: run.bank_bytes as f64,
                instructions: instructions(f.nodes)?,
                chosen: m == 0 && i == scene_model,
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
        label: format!("{}, {:.0} instructions", c.label, c.instructions),
    };
    let chosen = combos.iter().find(|c| c.chosen);
    let on_front = chosen.is_some_and(|c| front.iter().any(|f| f.label == c.label));
    let mut series = vec![Series {
        name: "every mesh x contact model".into(),
        points: combos.iter().map(point).collect(),
    }];
    let front_text: Vec<String> = front
        .iter()
        .map(|c| format!("{} ({:.1} %)", c.label, 100.0 * c.error))
        .collect();
    if front.len() >= 3 {
        series.push(Series {
            name: "Pareto front (error, bytes, instructions)".into(),
            points: front.iter().map(|c| point(c)).collect(),
        });
    }
    Some(Knob {
        id: "pareto".into(),
        title: "Pareto front: force error against bank bytes and MCU instructions".into(),
        x_label: "bank bytes".into(),
        y_label: format!(
            "force error against {} / {}",
            finest.name, finest.forces[scene_model].model
        ),
        log_x: true,
        log_y: true,
        series,
        chosen: chosen.map(point),
        finding: format!(
            "{} combinations; the front (no other is better in error, bytes and instructions \
             at once): {}. The scene's choice ({}) is {}on the front. The bank's couplings \
             (their own plot) are not combined here, and only f32 storage exists",
            combos.len(),
            front_text.join(", "),
            chosen.map_or("not measured".into(), |c| c.label.clone()),
            if on_front { "" } else { "NOT " }
        ),
    })
}
