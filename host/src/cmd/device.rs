//! `host device check`: live joint angles, tip and state of a device on a serial port, from its
//! telemetry, so that encoder directions and zeroing can be checked by hand at bring-up.

use anyhow::{Context, Result, bail};
use bank_format::{AlignedBytes, Bank};
use host::kinematics::{Workspace, counts_for};
use host::source::{SerialSource, Source};
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// Device subcommands.
#[derive(clap::Subcommand, Debug)]
pub enum DeviceCmd {
    /// Print the device's joint angles (pitch, yaw in degrees; insertion in mm), tip (mm),
    /// the encoder counts those joints mean, and its state, about ten times a second. The
    /// joints are the inverse kinematics of the telemetry's tip with the bank's calibration
    /// (`host::kinematics`), so the device must run that bank (checked from its Hello).
    Check(CheckArgs),
}

/// Arguments of `host device check`.
#[derive(clap::Args, Debug)]
pub struct CheckArgs {
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

/// Runs a device subcommand.
pub fn run(cmd: DeviceCmd) -> Result<()> {
    match cmd {
        DeviceCmd::Check(a) => check(a),
    }
}

fn check(args: CheckArgs) -> Result<()> {
    let (bytes, name) = match (&args.scene, &args.bank) {
        (Some(scene), None) => (
            host::bank::scene_bank(scene)?,
            format!("the bank of {}", scene.display()),
        ),
        (None, Some(bank)) => (
            std::fs::read(bank)
                .with_context(|| format!("cannot read the bank {}", bank.display()))?,
            bank.display().to_string(),
        ),
        _ => bail!("give the bank the device runs: --scene S or --bank F"),
    };
    let aligned = AlignedBytes::new(&bytes);
    let bank = Bank::parse(&aligned).map_err(|e| anyhow::anyhow!("{name}: invalid bank: {e}"))?;
    let cal = *bank.device();
    let workspace = Workspace::from_device(&cal);
    let mut source = SerialSource::open(&args.port, args.baud, bank.crc(), &name)?;
    if !args.json {
        eprintln!(
            "device on {}: {name}; move each joint by hand: pitch and yaw in degrees, insertion \
             in mm, counts from the home pose (Ctrl-C ends)",
            args.port
        );
    }
    let period = Duration::from_secs_f64(1.0 / args.rate.clamp(0.1, 1000.0));
    let end = Instant::now() + Duration::from_secs_f64(args.seconds.max(0.0));
    let mut next = Instant::now();
    let mut newest = None;
    while Instant::now() < end {
        if let Some(s) = source.latest(Duration::from_millis(50))? {
            newest = Some(s);
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
