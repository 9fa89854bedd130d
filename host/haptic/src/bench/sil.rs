//! `host bench sil`: instructions per tick of the firmware image under QEMU (idle and per
//! contact-set size, loop body and whole tick, and per code phase) along the press, slide and
//! strike scripts, the worst loop body over them and over seeded `wander` paths
//! ([`crate::sil::wander`]), against the goal, and the image's flash and static RAM.

use crate::mcu::ImageSize;
use crate::sil::cost::{
    CODE_PHASES, CodePhaseStats, CostStats, against_goal, by_contact_nodes_of_runs,
    code_phase_samples_of_runs,
};
use crate::sil::harness::{self, Session, Setup};
use crate::sil::script::Trajectory;
use crate::trajectory::Script;
use anyhow::{Result, bail};
use bank_format::Bank;
use bank_format::region::{RAM_LEN, RAM_ORIGIN};
use std::collections::BTreeMap;

/// The scripts each run measures, in order.
pub const SCRIPTS: [Script; 3] = [Script::Press, Script::Slide, Script::Strike];

/// One script's run.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ScriptRun {
    /// The script.
    pub script: Script,
    /// Ticks run.
    pub ticks: usize,
    /// Ticks that overran their period.
    pub overruns: u32,
    /// Faults the image reported.
    pub faults: usize,
    /// Wall time of the run, s.
    pub wall_s: f64,
}

/// One `wander` seed's run.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct WanderRun {
    /// The seed.
    pub seed: u64,
    /// Ticks run.
    pub ticks: usize,
    /// The largest loop body, every tick (armed or not), instructions.
    pub max_body_instructions: u32,
    /// The largest whole tick, instructions.
    pub max_tick_instructions: u32,
    /// Ticks that overran their period.
    pub overruns: u32,
    /// Faults the image reported.
    pub faults: usize,
}

/// The figures of [`run`].
#[derive(Clone, Debug, PartialEq)]
pub struct Figures {
    /// Every tick of every run, grouped by contact-set size (0: idle).
    pub by_contact_nodes: BTreeMap<u8, CostStats>,
    /// Per code phase ([`CODE_PHASES`]) over every tick of every run.
    pub code_phases: Vec<(&'static str, CodePhaseStats)>,
    /// The largest loop body of any group, instructions.
    pub worst_body: u32,
    /// The largest whole tick of any group, instructions.
    pub worst_tick: u32,
    /// The largest loop body over every tick (armed or not) of every run, the scripts' and
    /// the `wander` seeds', instructions ([`against_goal`]).
    pub goal_body: u32,
    /// The largest whole tick over every tick (armed or not), instructions.
    pub goal_tick: u32,
    /// Whether both are within the goal ([`crate::sil::cost::BODY_GOAL`],
    /// [`crate::sil::cost::TICK_GOAL`]).
    pub met: bool,
    /// The image's flash and static RAM.
    pub size: ImageSize,
    /// The runs, one per script of [`SCRIPTS`].
    pub runs: Vec<ScriptRun>,
    /// The `wander` runs, one per seed.
    pub wander: Vec<WanderRun>,
}

/// Runs each of [`SCRIPTS`] for `seconds` (virtual) on the image and bank of `setup` (`bank`
/// parsed), telling `step` which script starts; with `at_once` side by side
/// ([`harness::run_all`]: the same script and costs, but each run's wall time is shared), else one after
/// the other. A run the image stops early is an error.
pub fn run_scripts(
    setup: &Setup,
    bank: &Bank,
    seconds: f64,
    at_once: bool,
    step: &dyn Fn(Script),
) -> Result<Vec<(Script, harness::Run)>> {
    let jobs = SCRIPTS
        .iter()
        .map(|&script| Ok((setup, Session::new(bank, script, seconds)?)))
        .collect::<Result<Vec<_>>>()?;
    let runs = if at_once {
        SCRIPTS.iter().for_each(|&s| step(s));
        harness::run_all(&jobs)
    } else {
        SCRIPTS
            .iter()
            .zip(&jobs)
            .map(|(&script, (setup, session))| {
                step(script);
                harness::run(setup, session)
            })
            .collect()
    };
    SCRIPTS
        .iter()
        .zip(runs)
        .map(|(&script, run)| {
            let run = run?;
            if let Some(why) = &run.stopped {
                bail!("{script:?}: the image stopped early: {why}\n{}", run.stderr);
            }
            Ok((script, run))
        })
        .collect()
}

/// The `wander` path of each of `seeds` for `seconds` (virtual) on the image and bank of
/// `setup` (`bank` parsed), side by side ([`harness::run_all`]: only their instructions
/// count). A run the image stops early is an error.
pub fn run_wander(
    setup: &Setup,
    bank: &Bank,
    seconds: f64,
    seeds: std::ops::Range<u64>,
) -> Result<Vec<(u64, harness::Run)>> {
    let jobs = seeds
        .clone()
        .map(|seed| {
            let path = Trajectory::wander(bank, seed, seconds)?;
            Ok((setup, Session::with_trajectory(bank, path, seconds)?))
        })
        .collect::<Result<Vec<_>>>()?;
    seeds
        .zip(harness::run_all(&jobs))
        .map(|(seed, run)| {
            let run = run?;
            if let Some(why) = &run.stopped {
                bail!(
                    "wander seed {seed}: the image stopped early: {why}\n{}",
                    run.stderr
                );
            }
            Ok((seed, run))
        })
        .collect()
}

/// [`run_scripts`] one after the other and [`run_wander`] over `seeds`, measured, and the
/// image sized. The groups by contact-set size and by code phase are the scripts'; the goal is
/// checked over every run.
pub fn run(
    setup: &Setup,
    bank: &Bank,
    seconds: f64,
    seeds: std::ops::Range<u64>,
) -> Result<Figures> {
    let mut records = Vec::new();
    let mut runs = Vec::new();
    for (script, run) in run_scripts(setup, bank, seconds, false, &|_| {})? {
        runs.push(ScriptRun {
            script,
            ticks: run.ticks.len(),
            overruns: run.overruns(),
            faults: run.faults().len(),
            wall_s: run.wall_s,
        });
        records.push(run.ticks);
    }
    let mut wander = Vec::new();
    let mut wander_records = Vec::new();
    for (seed, run) in run_wander(setup, bank, seconds, seeds)? {
        let (body, tick, _) = against_goal(&run.ticks);
        wander.push(WanderRun {
            seed,
            ticks: run.ticks.len(),
            max_body_instructions: body,
            max_tick_instructions: tick,
            overruns: run.overruns(),
            faults: run.faults().len(),
        });
        wander_records.push(run.ticks);
    }
    let all = [records.concat(), wander_records.concat()].concat();
    // Each run's whole-tick costs from its own ticks (a run's last tick has no successor).
    let groups = by_contact_nodes_of_runs(records.iter().map(Vec::as_slice));
    let samples = code_phase_samples_of_runs(records.iter().map(Vec::as_slice));
    let code_phases = CODE_PHASES
        .iter()
        .zip(&samples)
        .map(|(&n, v)| (n, CodePhaseStats::of(v)))
        .collect();
    let size = crate::mcu::image_size(&setup.image, RAM_ORIGIN, RAM_LEN as u32)?;
    let worst_body = groups.values().map(|g| g.body_max).max().unwrap_or(0);
    let worst_tick = groups.values().map(|g| g.tick_max).max().unwrap_or(0);
    let (goal_body, goal_tick, met) = against_goal(&all);
    Ok(Figures {
        by_contact_nodes: groups,
        code_phases,
        worst_body,
        worst_tick,
        goal_body,
        goal_tick,
        met,
        size,
        runs,
        wander,
    })
}
