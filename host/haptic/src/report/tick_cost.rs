//! The firmware's instructions per tick, from the QEMU image (`firmware/qemu`) over the SIL
//! scripts (press, slide, strike), through [`crate::sil::harness`] as `host bench sil` runs
//! it: a histogram of the loop body's instructions per tick, the worst case by phase of a
//! contact (free, first contact, held, release), and a histogram and the worst case per phase
//! of the code (kinematics, detection, patch, solve, law, supervisor: the loop body split at
//! `firmware::tick`'s phase boundaries, which the image reports per tick; and link, the whole
//! tick less the body: plant exchange, link queues, executor).

use super::{HardCase, Knob, Point, Series, Verdict};
use crate::sil::cost::{
    CODE_PHASES, CodePhaseStats, CostStats, NODAL_BODY_GOAL, NODAL_TICK_GOAL, PhaseMax, Phases,
    by_contact_nodes_of_runs, code_phase_samples_of_runs,
};
use crate::sil::harness::{INSTRUCTIONS_PER_TICK, Setup, TickRecord};
use crate::trajectory::Script;
use anyhow::Result;
use bank_format::Bank;
use std::collections::BTreeMap;

/// Histogram bins.
const BINS: usize = 12;

/// The ticks of each script.
pub struct SilRuns {
    /// `(script, its ticks)`.
    pub runs: Vec<(Script, Vec<TickRecord>)>,
    /// Faults the image reported over all runs.
    pub faults: usize,
    /// Overruns over all runs.
    pub overruns: u32,
}

impl SilRuns {
    /// Every tick of every run, grouped by contact-set size.
    pub fn by_contact_nodes(&self) -> BTreeMap<u8, CostStats> {
        by_contact_nodes_of_runs(self.runs.iter().map(|(_, ticks)| &ticks[..]))
    }
}

/// Runs the three scripts ([`crate::bench::sil::SCRIPTS`]) for `seconds` each on the image.
pub fn measure(setup: &Setup, bank: &Bank, seconds: f64, step: &dyn Fn(&str)) -> Result<SilRuns> {
    let mut out = SilRuns {
        runs: Vec::new(),
        faults: 0,
        overruns: 0,
    };
    let say = |script: Script| {
        step(&format!(
            "firmware: {script:?} for {seconds} s on the QEMU image"
        ))
    };
    for (script, run) in crate::bench::sil::run_scripts(setup, bank, seconds, true, &say)? {
        out.faults += run.faults().len();
        out.overruns += run.overruns();
        out.runs.push((script, run.ticks));
    }
    Ok(out)
}

/// The two knobs (histogram; by contact-set size) and the worst-case row.
pub fn section(sil: &SilRuns) -> (Vec<Knob>, HardCase) {
    let bodies = || {
        sil.runs
            .iter()
            .flat_map(|(_, t)| t.iter().map(|r| r.body_instructions))
    };
    let lo = bodies().min().unwrap_or(0);
    let hi = bodies().max().unwrap_or(1).max(lo + 1);
    let histogram = sil
        .runs
        .iter()
        .map(|(script, ticks)| {
            let body: Vec<u32> = ticks.iter().map(|r| r.body_instructions).collect();
            histogram(format!("{script:?}").to_lowercase(), &body, (lo, hi), "")
        })
        .collect();
    let groups = sil.by_contact_nodes();
    let worst_body = groups.values().map(|g| g.body_max).max().unwrap_or(0);
    let worst_tick = groups.values().map(|g| g.tick_max).max().unwrap_or(0);
    let share = |n: u32| 100.0 * f64::from(n) / f64::from(INSTRUCTIONS_PER_TICK);
    let ticks: usize = sil.runs.iter().map(|r| r.1.len()).sum();
    let hist = Knob {
        id: "firmware-histogram".into(),
        title: "Firmware: loop-body instructions per tick (QEMU image, SIL scripts)".into(),
        x_label: "instructions in the loop body".into(),
        y_label: "share of the script's ticks, %".into(),
        log_x: false,
        log_y: false,
        series: histogram,
        chosen: None,
        finding: format!(
            "{ticks} ticks of press, slide and strike: the body takes {lo}-{hi} instructions \
             over all ticks (armed or not); armed, at worst {worst_body} ({:.1} % of the \
             {INSTRUCTIONS_PER_TICK} per 1 ms period at 125 MIPS) and the whole tick at worst \
             {worst_tick} ({:.1} %); {} overruns, {} faults",
            share(worst_body),
            share(worst_tick),
            sil.overruns,
            sil.faults
        ),
    };
    // Per phase of a contact (cost::Phases, per run, worst over the runs).
    let mut phases = [PhaseMax::default(); 4];
    for (_, ticks) in &sil.runs {
        let p = Phases::of(ticks);
        for (acc, m) in phases
            .iter_mut()
            .zip([p.free, p.first_contact, p.contact, p.release])
        {
            acc.ticks += m.ticks;
            acc.max_body_instructions = acc.max_body_instructions.max(m.max_body_instructions);
            acc.max_tick_instructions = acc.max_tick_instructions.max(m.max_tick_instructions);
        }
    }
    let names = [
        "free motion",
        "first contact tick",
        "held contact",
        "release tick",
    ];
    let phase_series = |name: &str, f: fn(&PhaseMax) -> u32| Series {
        name: name.into(),
        points: phases
            .iter()
            .zip(names)
            .enumerate()
            .map(|(i, (m, n))| Point {
                x: i as f64,
                y: f64::from(f(m)),
                label: format!("{n} ({} ticks)", m.ticks),
            })
            .collect(),
    };
    let series = vec![
        phase_series("loop body, worst", |m| m.max_body_instructions),
        phase_series("whole tick (executor, link, plant I/O), worst", |m| {
            m.max_tick_instructions
        }),
    ];
    let by_nodes: Vec<String> = groups
        .iter()
        .map(|(k, g)| {
            format!(
                "{k} nodes: body mean {:.0}, p99 {}, worst {}",
                g.body_mean, g.body_p99, g.body_max
            )
        })
        .collect();
    let idle = groups.get(&0).copied().unwrap_or_default();
    let by = Knob {
        id: "firmware-phases".into(),
        title: "Firmware: worst instructions per tick by phase of a contact (QEMU image)".into(),
        x_label: "phase: 0 free, 1 first contact, 2 held contact, 3 release".into(),
        y_label: "instructions per tick".into(),
        log_x: false,
        log_y: false,
        series,
        chosen: None,
        finding: format!(
            "free motion takes {:.0} instructions on average, the link, executor and plant \
             I/O {:.0} more per tick; by contact-set size: {}",
            idle.body_mean,
            idle.tick_mean - idle.body_mean,
            by_nodes.join("; ")
        ),
    };
    let (code_hist, code_worst) = code_phase_knobs(sil);
    let row = HardCase {
        case: "worst-case tick on the MCU (QEMU)".into(),
        measurement: format!(
            "worst loop body {worst_body}, whole tick {worst_tick} instructions over {ticks} \
             ticks; {} overruns",
            sil.overruns
        ),
        reference: format!(
            "the nodal model's goal: body <= {NODAL_BODY_GOAL}, whole tick <= \
             {NODAL_TICK_GOAL} (of the {INSTRUCTIONS_PER_TICK} a 1 ms period holds)"
        ),
        verdict: if worst_body <= NODAL_BODY_GOAL
            && worst_tick <= NODAL_TICK_GOAL
            && sil.overruns == 0
        {
            Verdict::Bounded
        } else {
            Verdict::Weakness
        },
        value: Some(f64::from(worst_tick)),
        reference_value: Some(f64::from(NODAL_TICK_GOAL)),
    };
    (vec![hist, by, code_hist, code_worst], row)
}

/// The share (%) of `values` in each of [`BINS`] equal bins over `lo..hi` (`lo < hi`; larger
/// values count in the last bin), drawn at the bins' centres, labelled `{prefix}{n} ticks`.
fn histogram(name: String, values: &[u32], (lo, hi): (u32, u32), prefix: &str) -> Series {
    let width = f64::from(hi - lo) / BINS as f64;
    let mut counts = [0usize; BINS];
    for &x in values {
        counts[((f64::from(x - lo) / width) as usize).min(BINS - 1)] += 1;
    }
    let total = values.len().max(1) as f64;
    Series {
        name,
        points: counts
            .iter()
            .enumerate()
            .map(|(b, &n)| Point {
                x: f64::from(lo) + width * (b as f64 + 0.5),
                y: 100.0 * n as f64 / total,
                label: format!("{prefix}{n} ticks"),
            })
            .collect(),
    }
}

/// Per code phase ([`CODE_PHASES`]) over every tick of every script: a histogram of each
/// phase's instructions per tick (its own bins between its least and largest, log axis) and
/// the worst, 99th percentile and mean per phase.
fn code_phase_knobs(sil: &SilRuns) -> (Knob, Knob) {
    let samples = code_phase_samples_of_runs(sil.runs.iter().map(|(_, ticks)| &ticks[..]));
    let histogram = CODE_PHASES
        .iter()
        .zip(&samples)
        .map(|(&name, v)| {
            let lo = v.iter().copied().min().unwrap_or(0);
            let hi = v.iter().copied().max().unwrap_or(1).max(lo + 1);
            histogram(name.into(), v, (lo, hi), &format!("{name}: "))
        })
        .collect();
    let stats: Vec<CodePhaseStats> = samples.iter().map(|v| CodePhaseStats::of(v)).collect();
    let worst_of = |f: fn(&CodePhaseStats) -> f64, name: &str| Series {
        name: name.into(),
        points: stats
            .iter()
            .zip(CODE_PHASES)
            .enumerate()
            .map(|(i, (c, n))| Point {
                x: i as f64,
                y: f(c),
                label: format!("{n} ({} ticks)", c.ticks),
            })
            .collect(),
    };
    let ticks: usize = sil.runs.iter().map(|r| r.1.len()).sum();
    let listed: Vec<String> = stats
        .iter()
        .zip(CODE_PHASES)
        .map(|(c, n)| format!("{n} {} (p99 {})", c.max, c.p99))
        .collect();
    let hist = Knob {
        id: "firmware-code-phase-histogram".into(),
        title: "Firmware: instructions per tick by code phase (QEMU image, SIL scripts)".into(),
        x_label: "instructions in the phase (log)".into(),
        y_label: "share of the ticks, %".into(),
        log_x: true,
        log_y: false,
        series: histogram,
        chosen: None,
        finding: format!(
            "{ticks} ticks of press, slide and strike, armed or not; each phase's own bins \
             between its least and largest count; the six body phases sum to the loop body \
             in every tick, link is the whole tick less the body"
        ),
    };
    let worst = Knob {
        id: "firmware-code-phases".into(),
        title: "Firmware: worst instructions per tick by code phase (QEMU image)".into(),
        x_label: format!(
            "code phase: {}",
            CODE_PHASES
                .iter()
                .enumerate()
                .map(|(i, n)| format!("{i} {n}"))
                .collect::<Vec<_>>()
                .join(", ")
        ),
        y_label: "instructions per tick".into(),
        log_x: false,
        log_y: false,
        series: vec![
            worst_of(|c| f64::from(c.max), "worst"),
            worst_of(|c| f64::from(c.p99), "99th percentile"),
            worst_of(|c| c.mean, "mean"),
        ],
        chosen: None,
        finding: format!("worst per phase over {ticks} ticks: {}", listed.join(", ")),
    };
    (hist, worst)
}

/// The worst body instructions of a tick with `nodes` contact nodes (the largest measured
/// group at most that size), for the contact-model and Pareto knobs.
pub fn body_worst(groups: &BTreeMap<u8, CostStats>, nodes: usize) -> Option<f64> {
    groups
        .iter()
        .rfind(|(k, _)| usize::from(**k) <= nodes)
        .map(|(_, g)| f64::from(g.body_max))
}
