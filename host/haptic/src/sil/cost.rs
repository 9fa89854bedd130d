//! Where the instructions go under QEMU: per-tick costs of a run grouped by contact-set size,
//! by phase of a contact ([`Phases`]) and by phase of the code ([`CODE_PHASES`]) (the
//! image's flash and RAM use: [`crate::mcu::image_size`]).

use super::harness::TickRecord;
use bank_format::{PhaseCycles, State};
use std::collections::BTreeMap;

/// Instruction counts of one group of ticks.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct CostStats {
    /// Ticks in the group.
    pub ticks: usize,
    /// Mean loop-body instructions.
    pub body_mean: f64,
    /// Median loop-body instructions.
    pub body_p50: u32,
    /// 99th percentile of loop-body instructions.
    pub body_p99: u32,
    /// Largest loop-body instructions.
    pub body_max: u32,
    /// Mean whole-tick instructions (executor, link and plant I/O included).
    pub tick_mean: f64,
    /// Largest whole-tick instructions.
    pub tick_max: u32,
}

impl CostStats {
    /// The statistics of `(record, its whole-tick instructions)` pairs.
    pub fn of<'a>(records: impl Iterator<Item = (&'a TickRecord, u32)>) -> CostStats {
        let mut s = CostStats::default();
        let (mut body, mut tick) = (0.0, 0.0);
        let mut bodies = Vec::new();
        for (r, whole) in records {
            bodies.push(r.body_instructions);
            s.ticks += 1;
            body += f64::from(r.body_instructions);
            tick += f64::from(whole);
            s.body_max = s.body_max.max(r.body_instructions);
            s.tick_max = s.tick_max.max(whole);
        }
        if s.ticks > 0 {
            s.body_mean = body / s.ticks as f64;
            s.tick_mean = tick / s.ticks as f64;
            bodies.sort_unstable();
            let at = |q: f64| bodies[((bodies.len() - 1) as f64 * q).round() as usize];
            (s.body_p50, s.body_p99) = (at(0.5), at(0.99));
        }
        s
    }
}

/// The loop's instruction budget with the sampled contact model: every tick's loop body at most this many instructions on the MCU image...
pub const BODY_GOAL: u32 = 3_000;
/// ...and every whole tick (executor, link and plant I/O included) at most this many, which leaves room to run the same loop at 20 kHz (6,250 a period at 125 MIPS).
pub const TICK_GOAL: u32 = 6_000;

/// The nodal contact model's budget, kept for the nodal banks measured for
/// comparison (the report's scene bank): loop body at most this many instructions...
pub const NODAL_BODY_GOAL: u32 = 5_000;
/// ...and whole tick at most this many.
pub const NODAL_TICK_GOAL: u32 = 8_000;

/// The largest loop body and whole tick over `records`, every tick (armed or not), and whether
/// both are within [`BODY_GOAL`] and [`TICK_GOAL`].
pub fn against_goal(records: &[TickRecord]) -> (u32, u32, bool) {
    let body = records
        .iter()
        .map(|r| r.body_instructions)
        .max()
        .unwrap_or(0);
    let tick = records
        .iter()
        .map(|r| r.tick_instructions)
        .max()
        .unwrap_or(0);
    (body, tick, body <= BODY_GOAL && tick <= TICK_GOAL)
}

/// Costs of armed ticks grouped by contact nodes (0 = idle, free motion). A record's
/// `tick_instructions` belongs to the tick before it, so each tick's whole cost is read from
/// its successor.
pub fn by_contact_nodes(records: &[TickRecord]) -> BTreeMap<u8, CostStats> {
    by_contact_nodes_of_runs([records])
}

/// [`by_contact_nodes`] over several runs, together (each tick's whole cost from its successor
/// in its own run).
pub fn by_contact_nodes_of_runs<'a>(
    runs: impl IntoIterator<Item = &'a [TickRecord]>,
) -> BTreeMap<u8, CostStats> {
    let mut groups: BTreeMap<u8, Vec<(&TickRecord, u32)>> = BTreeMap::new();
    for w in runs.into_iter().flat_map(|r| r.windows(2)) {
        if w[0].state == State::Armed {
            groups
                .entry(w[0].contact_nodes)
                .or_default()
                .push((&w[0], w[1].tick_instructions));
        }
    }
    groups
        .into_iter()
        .map(|(k, v)| (k, CostStats::of(v.into_iter())))
        .collect()
}

/// The largest costs of one phase of a run.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct PhaseMax {
    /// Ticks in the phase.
    pub ticks: usize,
    /// Largest loop-body instructions.
    pub max_body_instructions: u32,
    /// Largest whole-tick instructions (read from the successor, as in [`by_contact_nodes`]).
    pub max_tick_instructions: u32,
}

/// Per-phase maxima of a run, every tick (armed or not: the loop runs the same contact work
/// either way), classified by its contact set and the previous tick's.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct Phases {
    /// No contact, and none in the previous tick either (free motion, near the surface or not).
    pub free: PhaseMax,
    /// The first tick of a contact (the detection found one; the previous tick was free).
    pub first_contact: PhaseMax,
    /// A contact held from the previous tick (pressing, sliding, patch rebuilds).
    pub contact: PhaseMax,
    /// The first free tick after a contact.
    pub release: PhaseMax,
}

impl Phases {
    /// The phases of `records` (in tick order). The last record has no successor, so its whole
    /// tick is not known: it counts with whole-tick cost 0.
    pub fn of(records: &[TickRecord]) -> Phases {
        let mut p = Phases::default();
        for (i, r) in records.iter().enumerate() {
            let before = i.checked_sub(1).and_then(|j| records.get(j));
            let was_touching = before.is_some_and(|b| b.contact_nodes > 0);
            let phase = match (was_touching, r.contact_nodes > 0) {
                (false, false) => &mut p.free,
                (false, true) => &mut p.first_contact,
                (true, true) => &mut p.contact,
                (true, false) => &mut p.release,
            };
            let whole = records.get(i + 1).map_or(0, |n| n.tick_instructions);
            phase.ticks += 1;
            phase.max_body_instructions = phase.max_body_instructions.max(r.body_instructions);
            phase.max_tick_instructions = phase.max_tick_instructions.max(whole);
        }
        p
    }
}

/// The code phases of a tick, in order: the loop body's ([`PhaseCycles::NAMES`],
/// `firmware::tick`'s phase boundaries) and `link`, the rest of the whole tick (the plant
/// exchange, the link queues and the executor: whole tick less body).
pub const CODE_PHASES: [&str; PhaseCycles::COUNT + 1] = {
    let mut names = ["link"; PhaseCycles::COUNT + 1];
    let mut i = 0;
    while i < PhaseCycles::COUNT {
        names[i] = PhaseCycles::NAMES[i];
        i += 1;
    }
    names
};

/// Instructions per tick of each code phase, in [`CODE_PHASES`] order.
pub type CodePhaseSamples = [Vec<u32>; CODE_PHASES.len()];

/// Instructions of each code phase ([`CODE_PHASES`]) over every tick of `records` (in tick
/// order, armed or not). A record's whole tick is read from its successor, so the last record
/// has no `link` sample.
pub fn code_phase_samples(records: &[TickRecord]) -> CodePhaseSamples {
    let mut out = CodePhaseSamples::default();
    for (i, r) in records.iter().enumerate() {
        for (v, x) in out.iter_mut().zip(r.phase_instructions.to_array()) {
            v.push(x);
        }
        if let Some(next) = records.get(i + 1) {
            out[PhaseCycles::COUNT]
                .push(next.tick_instructions.saturating_sub(r.body_instructions));
        }
    }
    out
}

/// [`code_phase_samples`] over several runs, together (each run's `link` samples from its own
/// ticks).
pub fn code_phase_samples_of_runs<'a>(
    runs: impl IntoIterator<Item = &'a [TickRecord]>,
) -> CodePhaseSamples {
    let mut out = CodePhaseSamples::default();
    for run in runs {
        for (all, v) in out.iter_mut().zip(code_phase_samples(run)) {
            all.extend(v);
        }
    }
    out
}

/// Statistics of one code phase's instructions per tick.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct CodePhaseStats {
    /// Ticks measured.
    pub ticks: usize,
    /// Mean instructions.
    pub mean: f64,
    /// Median.
    pub p50: u32,
    /// 99th percentile.
    pub p99: u32,
    /// Largest.
    pub max: u32,
}

impl CodePhaseStats {
    /// The statistics of `samples`.
    pub fn of(samples: &[u32]) -> CodePhaseStats {
        let mut v = samples.to_vec();
        v.sort_unstable();
        let Some(&max) = v.last() else {
            return CodePhaseStats::default();
        };
        let at = |q: f64| v[((v.len() - 1) as f64 * q).round() as usize];
        CodePhaseStats {
            ticks: v.len(),
            mean: v.iter().map(|&x| f64::from(x)).sum::<f64>() / v.len() as f64,
            p50: at(0.5),
            p99: at(0.99),
            max,
        }
    }
}

/// The largest instructions of each code phase in a run (`host sil --json`'s `code_phases`:
/// one object, the body's phases then `link`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct CodePhaseMax {
    /// The loop body's phases.
    #[serde(flatten)]
    pub body: PhaseCycles,
    /// Whole tick less body: plant exchange, link queues, executor.
    pub link: u32,
}

impl CodePhaseMax {
    /// The maxima over `records` (in tick order).
    pub fn of(records: &[TickRecord]) -> CodePhaseMax {
        let m = code_phase_samples(records).map(|v| v.into_iter().max().unwrap_or(0));
        CodePhaseMax {
            body: PhaseCycles::from_array(std::array::from_fn(|i| m[i])),
            link: m[PhaseCycles::COUNT],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rec(tick: u32, nodes: u8, body: u32, prev_tick: u32, state: State) -> TickRecord {
        TickRecord {
            tick,
            encoder_counts: [0; 3],
            joints: [0.0; 3],
            currents_a: [0.0; 3],
            force_n: [0.0; 3],
            state,
            contact_nodes: nodes,
            body_instructions: body,
            tick_instructions: prev_tick,
            phase_instructions: PhaseCycles {
                supervisor: body,
                ..PhaseCycles::default()
            },
        }
    }

    #[test]
    fn groups_by_contact_nodes_with_the_successors_tick_cost() {
        let r = [
            rec(1, 0, 500, 0, State::Disarmed),
            rec(2, 0, 1000, 9, State::Armed),
            rec(3, 3, 4000, 3000, State::Armed),
            rec(4, 3, 6000, 7000, State::Armed),
            rec(5, 0, 1200, 9000, State::Armed),
        ];
        let g = by_contact_nodes(&r);
        assert_eq!(g.len(), 2);
        let idle = g[&0];
        // Tick 1 is disarmed, tick 5 has no successor: only tick 2 counts.
        assert_eq!((idle.ticks, idle.body_max, idle.tick_max), (1, 1000, 3000));
        let three = g[&3];
        assert_eq!(three.ticks, 2);
        assert_eq!(three.body_mean, 5000.0);
        assert_eq!(
            (three.body_p50, three.body_p99, three.body_max),
            (6000, 6000, 6000)
        );
        assert_eq!((three.tick_mean, three.tick_max), (8000.0, 9000));
        // Two runs, split after tick 3: tick 3 has no successor in its run (its whole cost is
        // not tick 4's), so only tick 4 has three nodes.
        let split = by_contact_nodes_of_runs([&r[..3], &r[3..]]);
        assert_eq!(split[&3].ticks, 1);
        assert_eq!((split[&3].body_p50, split[&3].tick_max), (6000, 9000));
        assert_eq!(split[&0].ticks, 1);
    }

    #[test]
    fn phases_follow_the_contact_set_and_take_the_successors_tick_cost() {
        let r = [
            rec(1, 0, 500, 0, State::Disarmed),
            rec(2, 0, 900, 100, State::Armed),
            rec(3, 3, 8000, 200, State::Armed),
            rec(4, 4, 4000, 9000, State::Armed),
            rec(5, 3, 4500, 7000, State::Armed),
            rec(6, 0, 1500, 7500, State::Armed),
            rec(7, 0, 600, 3000, State::Armed),
        ];
        let p = Phases::of(&r);
        let m = |ticks, body, tick| PhaseMax {
            ticks,
            max_body_instructions: body,
            max_tick_instructions: tick,
        };
        // Ticks 1, 2 and 7 are free; 7 is last, so its whole tick is unknown (0).
        assert_eq!(p.free, m(3, 900, 200));
        assert_eq!(p.first_contact, m(1, 8000, 9000));
        assert_eq!(p.contact, m(2, 4500, 7500));
        assert_eq!(p.release, m(1, 1500, 3000));
    }

    #[test]
    fn code_phases_take_the_link_from_the_successors_whole_tick() {
        let split = PhaseCycles::from_array;
        let mut r = [
            rec(1, 0, 1000, 0, State::Armed),
            rec(2, 3, 6000, 4000, State::Armed),
            rec(3, 3, 3000, 9000, State::Armed),
        ];
        r[0].phase_instructions = split([300, 400, 0, 0, 0, 300]);
        r[1].phase_instructions = split([300, 3000, 1500, 400, 300, 500]);
        r[2].phase_instructions = split([300, 900, 600, 400, 300, 500]);
        let s = code_phase_samples(&r);
        assert_eq!(s[1], [400, 3000, 900]);
        // Tick 1's whole tick is 4000 (tick 2's report), its body 1000; tick 2's 9000 - 6000;
        // tick 3 has no successor.
        assert_eq!(s[PhaseCycles::COUNT], [3000, 3000]);
        let m = CodePhaseMax::of(&r);
        assert_eq!(m.body.to_array(), [300, 3000, 1500, 400, 300, 500]);
        assert_eq!(m.link, 3000);
        // `host sil --json`'s object: the body's phases, then link, flat.
        assert_eq!(
            serde_json::to_value(m).unwrap(),
            serde_json::json!({
                "kinematics": 300, "detection": 3000, "patch": 1500, "solve": 400,
                "law": 300, "supervisor": 500, "link": 3000
            })
        );
        assert_eq!(
            CODE_PHASES,
            [
                "kinematics",
                "detection",
                "patch",
                "solve",
                "law",
                "supervisor",
                "link"
            ]
        );
        let two = code_phase_samples_of_runs([&r[..2], &r[2..]]);
        assert_eq!(two[1], [400, 3000, 900]);
        assert_eq!(two[PhaseCycles::COUNT], [3000]);
        let d = CodePhaseStats::of(&s[1]);
        assert_eq!((d.ticks, d.p50, d.max), (3, 900, 3000));
        assert!((d.mean - 4300.0 / 3.0).abs() < 1e-9);
        assert_eq!(CodePhaseStats::of(&[]), CodePhaseStats::default());
    }
}
