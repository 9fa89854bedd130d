//! `host device`: a device on a serial port at bring-up. `check` prints its live joint angles,
//! tip and state from its telemetry, so that encoder directions and zeroing can be checked by
//! hand; `arm` selects a mode (the tissue law, the linear law, transparent, or constant motor
//! currents for the load-cell calibration), arms it, prints what it does and disarms it at the
//! end or on Ctrl-C.

use anyhow::{Context, Result, bail};
use bank_format::{HostToDevice, Mode};
use haptic::device::{BankSource, ExpectedBank, Session};
use haptic::display::source::{Sample, Source};
use haptic::kinematics::{Workspace, counts_for};
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// Device subcommands.
#[derive(clap::Subcommand, Debug)]
pub enum DeviceCmd {
    /// Print the device's joint angles (pitch, yaw in degrees; insertion in mm), tip (mm),
    /// the encoder counts those joints mean, and its state, about ten times a second. The
    /// joints are the inverse kinematics of the telemetry's tip with the bank's calibration
    /// (`haptic::kinematics`), so the device must run that bank (checked from its Hello).
    Check(CheckArgs),
    /// Select a mode, arm the device and print its state, currents and rendered force about
    /// ten times a second; disarm after --seconds or on Ctrl-C. If this host dies instead, the
    /// device faults `LinkSilent` within 10 ms (zero current). Refuses a device that is armed
    /// already or in a fault (unless --clear-fault), and currents over the bank's limits. The
    /// device itself refuses to arm until it has been homed (`zero`) since it started.
    Arm(ArmArgs),
    /// Declare the device's current pose its calibration's home pose: asks you to confirm
    /// that the instrument is in its homing fixture (--yes: you checked it already; without a
    /// terminal, --yes is required), then sends ZeroEncoders and waits for the device to apply
    /// it. This homing references the encoders, which the device needs before it arms, after
    /// every reset. Only you can check the pose: the device takes whatever pose it stands in
    /// as home.
    Zero(ZeroArgs),
}

/// Arguments of `host device zero`.
#[derive(clap::Args, Debug)]
pub struct ZeroArgs {
    #[command(flatten)]
    device: DeviceArgs,
    /// The instrument is in its homing fixture: zero without asking (for scripts).
    #[arg(long)]
    yes: bool,
}

/// Which device and bank (`host device check` and `arm`).
#[derive(clap::Args, Debug)]
pub struct DeviceArgs {
    /// The device's serial port (e.g. /dev/ttyACM0).
    #[arg(long)]
    port: String,
    /// The scene whose bank the device runs (built in memory, as `host bank build` does).
    #[arg(long, conflicts_with = "bank")]
    scene: Option<PathBuf>,
    /// The bank file the device runs.
    #[arg(long)]
    bank: Option<PathBuf>,
    /// Baud rate (ignored by USB CDC ports).
    #[arg(long, default_value_t = 115_200)]
    baud: u32,
}

/// Arguments of `host device check`.
#[derive(clap::Args, Debug)]
pub struct CheckArgs {
    #[command(flatten)]
    device: DeviceArgs,
    /// Stop after this many seconds.
    #[arg(long, default_value_t = 600.0)]
    seconds: f64,
    /// Print lines per second.
    #[arg(long, default_value_t = 10.0)]
    rate: f64,
    /// One JSON object per line instead of text.
    #[arg(long)]
    json: bool,
}

/// The modes of `host device arm` (the link's [`Mode`]).
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
enum ModeArg {
    /// Tissue forces through the law Q (normal operation).
    Render,
    /// Tissue forces from the linear model, Q bypassed (fitting Q on a bench).
    LinearLaw,
    /// Contact tracking only, zero current.
    Transparent,
    /// Constant motor currents (--currents), for the load-cell calibration.
    Current,
}

/// Arguments of `host device arm`.
#[derive(clap::Args, Debug)]
pub struct ArmArgs {
    #[command(flatten)]
    device: DeviceArgs,
    /// What the armed device renders.
    #[arg(long, value_enum, default_value_t = ModeArg::Render)]
    mode: ModeArg,
    /// Motor currents for --mode current, A, per motor (pitch, yaw, insertion): e.g. 0.2,0,0.
    /// Each must be within the bank's `current_limit_a`.
    #[arg(long, value_delimiter = ',', value_name = "A,B,C")]
    currents: Option<Vec<f32>>,
    /// Clear a latched fault first (the device refuses if its cause remains).
    #[arg(long)]
    clear_fault: bool,
    /// Disarm after this many seconds.
    #[arg(long, default_value_t = 10.0)]
    seconds: f64,
    /// Print lines per second.
    #[arg(long, default_value_t = 10.0)]
    rate: f64,
    /// One JSON object per line instead of text.
    #[arg(long)]
    json: bool,
}

/// Runs a device subcommand.
pub fn run(cmd: DeviceCmd) -> Result<()> {
    match cmd {
        DeviceCmd::Check(a) => check(a),
        DeviceCmd::Arm(a) => arm(a),
        DeviceCmd::Zero(a) => zero(a),
    }
}

/// The bank the device should run ([`ExpectedBank`]), from --scene or --bank.
fn bank(args: &DeviceArgs) -> Result<ExpectedBank> {
    let source = match (&args.scene, &args.bank) {
        (Some(scene), None) => BankSource::Scene(scene.clone()),
        (None, Some(bank)) => BankSource::File(bank.clone()),
        _ => bail!("give the bank the device runs: --scene S or --bank F"),
    };
    ExpectedBank::load(&source)
}

/// Opens the link to the device, its identity checked against the bank ([`bank`]).
fn open(args: &DeviceArgs, bank: &ExpectedBank) -> Result<Session> {
    Session::open(&args.port, args.baud, bank)
}

fn check(args: CheckArgs) -> Result<()> {
    let bank = bank(&args.device)?;
    let (cal, name) = (bank.calibration, &bank.name);
    let mut session = open(&args.device, &bank)?;
    let source = session.source();
    let workspace = Workspace::from_device(&cal);
    if !args.json {
        eprintln!(
            "device on {}: {name}; move each joint by hand: pitch and yaw in degrees, insertion \
             in mm, counts from the home pose (Ctrl-C ends)",
            args.device.port
        );
    }
    // The device answers Hello with its reset cause too (the one after the greeting of
    // `open` may have gone with it).
    source.command(HostToDevice::Hello)?;
    let mut reset_reported = false;
    let period = Duration::from_secs_f64(1.0 / args.rate.clamp(0.1, 1000.0));
    let end = Instant::now() + Duration::from_secs_f64(args.seconds.max(0.0));
    let mut next = Instant::now();
    let mut newest = None;
    while Instant::now() < end {
        if let Some(s) = source.latest(Duration::from_millis(50))? {
            newest = Some(s);
        }
        if let (false, Some(cause)) = (reset_reported, source.stats().reset_cause) {
            reset_reported = true;
            if args.json {
                println!(
                    "{}",
                    serde_json::json!({ "reset_cause": format!("{cause:?}") })
                );
            } else {
                println!("the device last started from a reset: {cause:?}");
            }
        }
        if Instant::now() < next {
            continue;
        }
        next += period;
        let Some(s) = newest.take() else { continue };
        let tip = s.tip_m.map(f64::from);
        let q = workspace.joints_for_tip(tip);
        let counts = counts_for(&cal, q);
        if args.json {
            println!(
                "{}",
                serde_json::json!({
                    "tick": s.tick,
                    "state": format!("{:?}", s.state),
                    "fault": s.fault.map(|f| format!("{f:?}")),
                    "pitch_rad": q[0],
                    "yaw_rad": q[1],
                    "insertion_m": q[2],
                    "tip_m": tip,
                    "counts": counts,
                })
            );
        } else {
            let fault = s.fault.map_or_else(String::new, |f| format!(" ({f:?})"));
            println!(
                "tick {:>9}  {:?}{fault}  pitch {:+8.3} deg  yaw {:+8.3} deg  insertion \
                 {:7.2} mm  tip [{:+8.2}, {:+8.2}, {:+8.2}] mm  counts [{}, {}, {}]",
                s.tick,
                s.state,
                q[0].to_degrees(),
                q[1].to_degrees(),
                q[2] * 1e3,
                tip[0] * 1e3,
                tip[1] * 1e3,
                tip[2] * 1e3,
                counts[0],
                counts[1],
                counts[2]
            );
        }
    }
    Ok(())
}

/// The link [`Mode`] of the arguments; currents are refused unless finite and within `limit`
/// (the device would fault `BadCommand` on them).
fn mode(mode: ModeArg, currents: Option<&[f32]>, limit: [f32; 3]) -> Result<Mode> {
    match (mode, currents) {
        (ModeArg::Current, None) => bail!("--mode current needs --currents A,B,C (amperes)"),
        (ModeArg::Current, Some(c)) => {
            let currents_a: [f32; 3] = c
                .try_into()
                .map_err(|_| anyhow::anyhow!("--currents takes 3 values, got {}", c.len()))?;
            for (k, (i, max)) in currents_a.iter().zip(limit).enumerate() {
                if !i.is_finite() || i.abs() > max {
                    bail!(
                        "--currents: motor {k} ({}) {i} A is outside the bank's current limit \
                         of {max} A",
                        ["pitch", "yaw", "insertion"][k]
                    );
                }
            }
            Ok(Mode::ConstantCurrent { currents_a })
        }
        (_, Some(_)) => bail!("--currents is only for --mode current"),
        (ModeArg::Render, None) => Ok(Mode::Render),
        (ModeArg::LinearLaw, None) => Ok(Mode::LinearLaw),
        (ModeArg::Transparent, None) => Ok(Mode::Transparent),
    }
}

fn arm(args: ArmArgs) -> Result<()> {
    // Bad currents are refused before the port is opened.
    let bank = bank(&args.device)?;
    let mode = mode(
        args.mode,
        args.currents.as_deref(),
        bank.calibration.current_limit_a,
    )?;
    let mut session = open(&args.device, &bank)?;
    session.ready_to_arm(args.clear_fault)?;
    let stop = Arc::new(AtomicBool::new(false));
    let flag = Arc::clone(&stop);
    ctrlc::set_handler(move || flag.store(true, Ordering::Relaxed))
        .context("cannot install the Ctrl-C handler")?;
    let port = args.device.port.clone();
    let mut armed = session.arm(mode)?;
    if !args.json {
        eprintln!(
            "device on {port}: {}; armed in mode {mode:?} for {} s (Ctrl-C disarms)",
            bank.name, args.seconds
        );
    }
    let period = Duration::from_secs_f64(1.0 / args.rate.clamp(0.1, 1000.0));
    let end = Instant::now() + Duration::from_secs_f64(args.seconds.max(0.0));
    let mut next = Instant::now();
    while Instant::now() < end && !stop.load(Ordering::Relaxed) && armed.is_armed() {
        let Some(s) = armed.latest(Duration::from_millis(20))? else {
            continue;
        };
        if Instant::now() < next {
            continue;
        }
        next += period;
        print_armed(&s, args.json);
    }
    armed.disarm()?;
    if !args.json {
        eprintln!("disarmed");
    }
    Ok(())
}

/// One line of `host device arm`'s output.
fn print_armed(s: &Sample, json: bool) {
    let f = s.tool_force_n;
    let force = f.iter().map(|x| x * x).sum::<f32>().sqrt();
    if json {
        println!(
            "{}",
            serde_json::json!({
                "tick": s.tick,
                "state": format!("{:?}", s.state),
                "mode": format!("{:?}", s.mode),
                "currents_a": s.currents_a,
                "tool_force_n": f,
                "contacts": s.contacts.len(),
            })
        );
    } else {
        println!(
            "tick {:>9}  {:?}  currents [{:+6.3}, {:+6.3}, {:+6.3}] A  force {force:6.3} N  \
             contacts {}",
            s.tick,
            s.state,
            s.currents_a[0],
            s.currents_a[1],
            s.currents_a[2],
            s.contacts.len()
        );
    }
}

fn zero(args: ZeroArgs) -> Result<()> {
    let bank = bank(&args.device)?;
    let fixture = "that the instrument is in its homing fixture";
    super::confirm::require_terminal_or_yes(args.yes, fixture)?;
    let mut session = open(&args.device, &bank)?;
    session.ready_to_zero()?;
    let home = bank.home_tip();
    if !super::confirm::ask(
        args.yes,
        "The device takes the pose it stands in as its home pose. Is the instrument held in \
         its homing fixture?",
    )? {
        bail!(
            "{}: not zeroed (nothing sent): put the instrument in its homing fixture and \
             run `host device zero` again",
            args.device.port
        );
    }
    session.zero(home)?;
    let how = if args.yes {
        "--yes said so"
    } else {
        "you confirmed it"
    };
    println!(
        "zeroed: the device applied ZeroEncoders; its tip now reads the home pose \
         [{:+.2}, {:+.2}, {:+.2}] mm\n\
         checked: the device received and applied the command (it reads the home pose \
         after any zeroing, wherever the instrument stands, so this says nothing of the \
         pose)\n\
         not checked: that the instrument is in its homing fixture ({how}); if it was \
         not, the organ, the joint limits and the gravity feed-forward are misplaced \
         until the next zero",
        home[0] * 1e3,
        home[1] * 1e3,
        home[2] * 1e3
    );
    Ok(())
}
