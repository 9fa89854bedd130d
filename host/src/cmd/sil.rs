//! `host sil`: run the firmware image under QEMU against the simulated device for a scripted,
//! seeded random (`--script wander --seed N`) or recorded (`--trajectory FILE`) hand motion and
//! print a summary (one JSON object with `--json`).

use super::script_arg::ScriptArg;
use anyhow::{Context, Result, bail};
use bank_format::{AlignedBytes, Bank};
use haptic::fsio::write_atomic;
use haptic::sil::cost::{CodePhaseMax, Phases};
use haptic::sil::harness::{self, Run, Session, Setup};
use haptic::sil::script::Trajectory;
use haptic::trajectory::Script;
use std::path::{Path, PathBuf};

/// Arguments of `host sil`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The hand's scripted motion.
    #[arg(long, value_enum, default_value_t = SilScript::Press)]
    pub script: SilScript,
    /// The seed of `--script wander` (the same seed, the same path).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Replay a recorded hand motion instead of a script: a CSV file with a header, either
    /// `t_s,x_m,y_m,z_m` (tip targets, m, the bank's frame) or
    /// `t_s,pitch_rad,yaw_rad,insertion_m` (joints); `#` lines are comments. The hand blends
    /// from the home pose to the first sample in 0.5 s, then follows the samples.
    #[arg(long, conflicts_with = "script")]
    pub trajectory: Option<PathBuf>,
    /// Virtual seconds to run (1 kHz ticks); default 5 for a script, the recorded motion's
    /// length plus 0.2 s for a trajectory file.
    #[arg(long)]
    pub seconds: Option<f64>,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
    /// Also write every tick (counts, joints, currents, force, state, instructions) to this
    /// file as JSON lines.
    #[arg(long)]
    pub trace: Option<PathBuf>,
    #[command(flatten)]
    pub setup: SetupArgs,
}

/// `host sil --script`: the scripted hand motions ([`ScriptArg`]'s, with the SIL hand's
/// numbers) and `wander`.
#[derive(clap::ValueEnum, serde::Serialize, Clone, Copy, Debug, PartialEq, Eq)]
#[serde(rename_all = "kebab-case")]
pub enum SilScript {
    /// 6 mm in from 5 mm above, every 2.5 s.
    Press,
    /// 4 mm in, a pitch sweep of +-0.05 rad, every 3 s.
    Slide,
    /// From 10 mm above, 18 mm down in 20 ms (1.35 m/s peak), every 1.5 s.
    Strike,
    /// 5 mm in over 0.5 s, held 10 s, every 11.5 s.
    #[value(name = "press-hold")]
    PressHold,
    /// A seeded random path near and into the surface (presses, slides, leaving and
    /// re-entering, holds) at tip speeds up to 0.45 m/s; `--seed N` chooses it (default 0).
    Wander,
}

impl SilScript {
    /// The library's script, `None` for `wander`.
    fn script(self) -> Option<Script> {
        match self {
            SilScript::Press => Some(ScriptArg::Press.into()),
            SilScript::Slide => Some(ScriptArg::Slide.into()),
            SilScript::Strike => Some(ScriptArg::Strike.into()),
            SilScript::PressHold => Some(ScriptArg::PressHold.into()),
            SilScript::Wander => None,
        }
    }
}

/// Where the image, the bank and QEMU come from (shared with `host bench sil`).
#[derive(clap::Args, Debug)]
pub struct SetupArgs {
    /// Bank file to load at the bank region; default: built from --scene into
    /// target/sil/<scene>-<key>.bank, rebuilt when the scene, the bank format or the host
    /// changes.
    #[arg(long)]
    pub bank: Option<PathBuf>,
    /// Scene the default bank is built from.
    #[arg(long, default_value = "host/scenes/liver.toml")]
    pub scene: PathBuf,
    /// Firmware image (ELF); default: build firmware/qemu and use its release image.
    #[arg(long)]
    pub image: Option<PathBuf>,
    /// QEMU binary.
    #[arg(long, default_value = "qemu-system-arm")]
    pub qemu: PathBuf,
}

impl SetupArgs {
    /// The setup, building the image and the bank as needed, and the bank's bytes.
    pub fn resolve(&self) -> Result<(Setup, AlignedBytes)> {
        let image = match &self.image {
            Some(p) => p.clone(),
            None => haptic::mcu::build_qemu_image()?,
        };
        let bank = match &self.bank {
            Some(p) => p.clone(),
            None => haptic::sil::bank::cached(&self.scene)?,
        };
        let raw =
            std::fs::read(&bank).with_context(|| format!("cannot read {}", bank.display()))?;
        Ok((
            Setup {
                qemu: self.qemu.clone(),
                image,
                bank,
            },
            AlignedBytes::new(&raw),
        ))
    }
}

/// The JSON summary of a run.
#[derive(serde::Serialize)]
pub struct Summary {
    /// The script (`null` for a recorded trajectory).
    script: Option<SilScript>,
    /// The seed of `wander` (`null` otherwise).
    seed: Option<u64>,
    /// The recorded trajectory file, if one was replayed.
    trajectory: Option<String>,
    virtual_s: f64,
    ticks: usize,
    missed_plant_frames: u32,
    overruns: u32,
    /// Whole tick (executor, link and plant I/O included), instructions.
    max_instructions_per_tick: u32,
    /// Loop body only, instructions.
    max_body_instructions: u32,
    /// Whole tick, instructions (the same as `max_instructions_per_tick`).
    max_tick_instructions: u32,
    /// Per-phase maxima: free motion, the first tick of a contact, a held contact, the first
    /// free tick after one ([`Phases`]).
    phases: Phases,
    /// Per-code-phase maxima over every tick: kinematics, detection, patch, solve, law,
    /// supervisor (the loop body's parts) and link (whole tick less body) ([`CodePhaseMax`]).
    code_phases: CodePhaseMax,
    peak_force_n: f32,
    faults: Vec<FaultJson>,
    final_state: String,
    rx_frames: u32,
    rx_errors: u32,
    telemetry_messages: usize,
    wall_s: f64,
    virtual_over_wall: f64,
    exit_code: Option<i32>,
    stopped: Option<String>,
}

#[derive(serde::Serialize)]
struct FaultJson {
    tick: u32,
    reason: String,
    detail: u32,
}

impl Summary {
    /// Condense `run` of `script` (`wander`'s `seed`), or of the recorded `trajectory` file.
    pub fn new(
        script: Option<SilScript>,
        seed: Option<u64>,
        trajectory: Option<&Path>,
        run: &Run,
    ) -> Summary {
        let last = run
            .telemetry()
            .last()
            .map(|t| t.counters)
            .unwrap_or_default();
        let virtual_s = run.ticks.len() as f64 * 1e-3;
        let max_tick = run
            .ticks
            .iter()
            .map(|t| t.tick_instructions)
            .max()
            .unwrap_or(0);
        Summary {
            script,
            seed,
            trajectory: trajectory.map(|p| p.display().to_string()),
            virtual_s,
            ticks: run.ticks.len(),
            missed_plant_frames: run.missed_plant_frames(),
            overruns: run.overruns(),
            max_instructions_per_tick: max_tick,
            max_body_instructions: run
                .ticks
                .iter()
                .map(|t| t.body_instructions)
                .max()
                .unwrap_or(0),
            max_tick_instructions: max_tick,
            phases: Phases::of(&run.ticks),
            code_phases: CodePhaseMax::of(&run.ticks),
            peak_force_n: run.peak_force_n(),
            faults: run
                .faults()
                .into_iter()
                .map(|(tick, reason, detail)| FaultJson {
                    tick,
                    reason: format!("{reason:?}"),
                    detail,
                })
                .collect(),
            final_state: run
                .ticks
                .last()
                .map_or_else(|| "none".into(), |t| format!("{:?}", t.state)),
            rx_frames: last.rx_frames,
            rx_errors: last.rx_errors,
            telemetry_messages: run.telemetry().len(),
            wall_s: run.wall_s,
            virtual_over_wall: virtual_s / run.wall_s.max(1e-9),
            exit_code: run.exit_code,
            stopped: run.stopped.clone(),
        }
    }
}

/// Runs `host sil`.
pub fn run(args: Args) -> Result<()> {
    if args.seed.is_some() && args.script != SilScript::Wander {
        bail!("--seed chooses a wander path: use it with --script wander");
    }
    let (setup, bytes) = args.setup.resolve()?;
    let bank = Bank::parse(&bytes)
        .map_err(|e| anyhow::anyhow!("{}: invalid bank: {e}", setup.bank.display()))?;
    let seconds = args.seconds.unwrap_or(5.0);
    let seed = (args.script == SilScript::Wander && args.trajectory.is_none())
        .then(|| args.seed.unwrap_or(0));
    let session = match &args.trajectory {
        Some(path) => {
            let trajectory = Trajectory::from_csv(&bank, path)?;
            let seconds = args
                .seconds
                .unwrap_or(trajectory.recorded_end_s().unwrap_or(0.0) + 0.2);
            Session::with_trajectory(&bank, trajectory, seconds)?
        }
        None => match (args.script.script(), seed) {
            (Some(script), _) => Session::new(&bank, script, seconds)?,
            (None, seed) => Session::with_trajectory(
                &bank,
                Trajectory::wander(&bank, seed.unwrap_or(0), seconds)?,
                seconds,
            )?,
        },
    };
    let run = harness::run(&setup, &session)?;
    if let Some(path) = &args.trace {
        let mut text = String::new();
        for t in &run.ticks {
            text.push_str(&serde_json::to_string(t)?);
            text.push('\n');
        }
        write_atomic(
            path,
            text.as_bytes(),
            &[&args.setup.scene, &setup.bank, &setup.image],
        )?;
    }
    let script = args.trajectory.is_none().then_some(args.script);
    let s = Summary::new(script, seed, args.trajectory.as_deref(), &run);
    if args.json {
        println!("{}", serde_json::to_string(&s)?);
    } else {
        println!("{}", serde_json::to_string_pretty(&s)?);
    }
    if let Some(why) = &run.stopped {
        bail!("the image stopped early: {why}\n{}", run.stderr);
    }
    Ok(())
}
