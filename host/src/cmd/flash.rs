//! `host flash`: the board image and a bank onto the STM32F405 through a debug probe (crate
//! [`flash`], probe-rs as a library), checked before (bank, image, layout) and after (the
//! device's `Hello` reports the bank written); `--set-bor` instead programs the option bytes'
//! brown-out reset level 3, checked and confirmed. Either way a connected device is sent
//! `Disarm` first ([`haptic::link::disarm_connected`]).

use crate::progress::Bar;
use anyhow::{Context, Result, bail};
use bank_format::region::BANK_LEN;
use fem::progress::Progress as _;
use flash::{Layout, Part, Phase, Plan, Progress, What};
use haptic::link::{Disarmed, await_identity, check_identity, disarm_connected, open_device_port};
use std::path::{Path, PathBuf};
use std::time::Duration;

/// Arguments of `host flash`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Build the bank of this scene file in memory (as `host bank build` does) and write it.
    #[arg(long, conflicts_with = "bank")]
    scene: Option<PathBuf>,
    /// Write this bank file.
    #[arg(long)]
    bank: Option<PathBuf>,
    /// The firmware image (ELF). Default: build firmware/board (`cargo build --release`
    /// there) and take its release image.
    #[arg(long, conflicts_with = "bank_only")]
    elf: Option<PathBuf>,
    /// Rewrite the bank region only; the firmware's sectors are not touched.
    #[arg(long)]
    bank_only: bool,
    /// The probe, as `VID:PID[:SERIAL]` (hex ids; see --list), when several are attached.
    #[arg(long)]
    probe: Option<String>,
    /// List the debug probes attached and exit.
    #[arg(long, conflicts_with_all = ["scene", "bank", "elf", "bank_only", "dry_run", "set_bor"])]
    list: bool,
    /// Program brown-out reset level 3 into the chip's option bytes (FLASH_OPTCR's BOR_LEV =
    /// 00, every other bit kept; read protection never written, refused unless it is level
    /// 0) instead of writing firmware and bank: the firmware refuses to arm below level 3.
    /// Shows the word read and the word to write and asks before writing (--yes: without
    /// asking); reads it back after the write and after a reset.
    #[arg(long, conflicts_with_all = ["scene", "bank", "elf", "bank_only", "json"])]
    set_bor: bool,
    /// With --set-bor: write without asking.
    #[arg(long, requires = "set_bor")]
    yes: bool,
    /// Print the plan (sectors erased, ranges programmed) and exit; needs no probe.
    #[arg(long)]
    dry_run: bool,
    /// With --dry-run: the plan as one JSON object.
    #[arg(long, requires = "dry_run")]
    json: bool,
    /// The device's USB serial port, for the `Disarm` sent before the probe opens and the
    /// `Hello` check after flashing (default: the port with the board's USB id,
    /// firmware/board/src/board.rs `usb_vid_pid`).
    #[arg(long)]
    port: Option<String>,
    /// Seconds to wait for the device's USB port and its `Hello` after the reset.
    #[arg(long, default_value_t = 10.0)]
    hello_timeout: f64,
}

/// Runs `host flash`.
pub fn run(args: Args) -> Result<()> {
    if args.list {
        let probes = flash::list_probes();
        if probes.is_empty() {
            eprintln!("no debug probe found (check the cable, `lsusb`, and probe-rs's udev rules)");
        }
        for p in probes {
            let access = if p.accessible {
                ""
            } else {
                "  (no permission: USB permissions / udev rules)"
            };
            println!("{}  {}{access}", p.selector, p.name);
        }
        return Ok(());
    }
    let selector = args
        .probe
        .as_deref()
        .map(|s| {
            s.parse::<flash::DebugProbeSelector>()
                .map_err(|e| anyhow::anyhow!("--probe {s:?}: {e} (want VID:PID[:SERIAL], hex)"))
        })
        .transpose()?;
    if args.set_bor {
        return set_bor(&args, selector.as_ref());
    }
    // Everything that can be checked without the chip, before any probe is opened.
    let layout = Layout::new()?;
    let (bank, bank_name) = bank_bytes(&args)?;
    let crc = flash::check_bank(&bank, BANK_LEN as u64)
        .map_err(|e| anyhow::anyhow!("{bank_name}: {e}"))?;
    let mut parts = Vec::new();
    if !args.bank_only {
        let elf = match &args.elf {
            Some(p) => p.clone(),
            None => build_board_image()?,
        };
        let bytes = std::fs::read(&elf)
            .with_context(|| format!("cannot read the firmware image {}", elf.display()))?;
        parts.extend(
            flash::firmware_segments(&bytes, &layout.firmware_region())
                .map_err(|e| anyhow::anyhow!("{}: {e}", elf.display()))?,
        );
    }
    parts.push(Part {
        what: What::Bank,
        address: layout.bank_region().start,
        data: bank,
    });
    if args.dry_run {
        let plan = layout.plan(&parts)?;
        if args.json {
            println!("{}", plan_json(&plan));
        } else {
            print!("{}", plan_text(&plan, crc));
            println!("{}", disarm_plan(args.port.as_deref()));
        }
        return Ok(());
    }
    disarm(args.port.as_deref())?;
    let bars = [
        (Phase::Erase, Bar::new("bytes erased")),
        (Phase::Program, Bar::new("bytes programmed")),
        (Phase::Verify, Bar::new("bytes verified")),
    ];
    let bar = |p: Phase| bars.iter().find(|(q, _)| *q == p).map(|(_, b)| b);
    let plan = flash::flash(
        &layout,
        &parts,
        selector.as_ref(),
        &mut |event| match event {
            Progress::Total(p, n) => bar(p).into_iter().for_each(|b| b.start(n)),
            Progress::Advance(p, n) => bar(p).into_iter().for_each(|b| b.advance(n)),
            Progress::Done(p) => bar(p).into_iter().for_each(Bar::finish),
        },
    )?;
    bars.iter().for_each(|(_, b)| b.finish());
    eprint!("{}", plan_text(&plan, crc));
    eprintln!("written and verified; the core was reset. Waiting for the device's Hello ...");
    let timeout = Duration::from_secs_f64(args.hello_timeout.max(0.0));
    let (mut port, name) = open_device_port(args.port.as_deref(), timeout)?;
    let hello = await_identity(&mut *port, &name, timeout)?;
    check_identity(&hello, crc, &bank_name)?;
    println!(
        "device on {name}: protocol {}, bank {crc:#010x} ({} nodes): as written",
        hello.protocol, hello.node_count
    );
    Ok(())
}

/// What the dry run says of the `Disarm` step ([`disarm`]), which it does not take.
fn disarm_plan(port: Option<&str>) -> String {
    let at = port.map_or_else(
        || "the port with the board's USB id".to_string(),
        |p| p.to_string(),
    );
    format!("disarm    first: Disarm to the device on {at}, if one is connected")
}

/// Sends `Disarm` to a connected device before the probe halts its chip, and says what it did.
fn disarm(port: Option<&str>) -> Result<()> {
    match disarm_connected(port, Duration::from_secs(1))? {
        Disarmed::NoDevice(why) => {
            eprintln!("no device connected to disarm ({why}); going on");
        }
        Disarmed::Sent {
            port,
            state: Some(state),
        } => {
            eprintln!("sent Disarm to the device on {port}: it reports {state:?}");
        }
        Disarmed::Sent { port, state: None } => {
            eprintln!(
                "sent Disarm to the device on {port}: no telemetry confirmed it within 1 s (a \
                 firmware of another protocol, or none running); the probe halts the chip next"
            );
        }
    }
    Ok(())
}

/// `host flash --set-bor`: brown-out reset level 3 into the option bytes ([`flash::set_bor_level3`]).
fn set_bor(args: &Args, selector: Option<&flash::DebugProbeSelector>) -> Result<()> {
    if args.dry_run {
        print!("{}", bor_plan_text()?);
        println!("{}", disarm_plan(args.port.as_deref()));
        return Ok(());
    }
    super::confirm::require_terminal_or_yes(
        args.yes,
        "the option-byte write (brown-out reset level 3)",
    )?;
    disarm(args.port.as_deref())?;
    let mut answer: Result<()> = Ok(());
    let outcome = flash::set_bor_level3(selector, &mut |change| {
        eprintln!(
            "FLASH_OPTCR {:#010x} -> {:#010x}: brown-out reset {} -> {}",
            change.old,
            change.new,
            flash::bor_level_name(change.old),
            flash::bor_level_name(change.new)
        );
        match super::confirm::ask(args.yes, "Write the option bytes?") {
            Ok(yes) => yes,
            Err(e) => {
                answer = Err(e);
                false
            }
        }
    })?;
    answer?;
    match outcome {
        flash::BorOutcome::AlreadySet(word) => println!(
            "FLASH_OPTCR {word:#010x}: brown-out reset is at level 3 already; nothing written"
        ),
        flash::BorOutcome::Declined(change) => bail!(
            "not confirmed: nothing written (FLASH_OPTCR stays {:#010x}, brown-out reset {}); \
             the device refuses to arm until it is at level 3",
            change.old,
            flash::bor_level_name(change.old)
        ),
        flash::BorOutcome::Written(change) => println!(
            "FLASH_OPTCR {:#010x} -> {:#010x}: brown-out reset level 3, read back after the \
             write and after a reset of the chip",
            change.old, change.new
        ),
    }
    Ok(())
}

/// What `--set-bor --dry-run` prints: the rule, and what it makes of the factory option bytes.
fn bor_plan_text() -> Result<String> {
    let factory = flash::bor_level3(flash::OPTCR_FACTORY)?.new;
    Ok(format!(
        "chip      {}\n\
         option    FLASH_OPTCR 0x40023c14: BOR_LEV (bits 3:2) := 00, brown-out reset level 3 \
         (reset below about 2.7 V); every other bit kept as read; RDP (bits 15:8) never \
         written, and the step is refused unless it reads 0xaa (level 0)\n\
         example   {:#010x} -> {factory:#010x} (factory option bytes: brown-out reset {} -> {})\n\
         the run   reads the chip's word, shows it old -> new and asks before writing (--yes: \
         without asking); nothing is written at level 3 already; after the write it reads the \
         word back, resets the chip and reads it again\n",
        flash::CHIP,
        flash::OPTCR_FACTORY,
        flash::bor_level_name(flash::OPTCR_FACTORY),
        flash::bor_level_name(factory),
    ))
}

/// The bank's bytes and a name for messages.
fn bank_bytes(args: &Args) -> Result<(Vec<u8>, String)> {
    match (&args.scene, &args.bank) {
        (Some(scene), None) => Ok((
            haptic::bank::scene_bank(scene)?,
            format!("the bank of {}", scene.display()),
        )),
        (None, Some(bank)) => Ok((
            std::fs::read(bank)
                .with_context(|| format!("cannot read the bank {}", bank.display()))?,
            bank.display().to_string(),
        )),
        _ => bail!("give the bank to write: --scene S (built in memory) or --bank F"),
    }
}

/// `cargo build --release` in firmware/board (its own workspace; a no-op when up to date) and
/// the path of its release image.
fn build_board_image() -> Result<PathBuf> {
    let dir = haptic::mcu::repo_root().join("firmware/board");
    eprintln!("building the board image in {} ...", dir.display());
    haptic::mcu::build_image(&dir, "the board image", " (or pass --elf F)")?;
    Ok(board_image(&dir))
}

fn board_image(dir: &Path) -> PathBuf {
    dir.join("target/thumbv7em-none-eabihf/release/firmware-board")
}

/// The plan as the JSON object of `--dry-run --json`.
fn plan_json(plan: &Plan) -> serde_json::Value {
    serde_json::json!({
        "chip": plan.chip,
        "erase": plan.erase.iter().map(|s| serde_json::json!({
            "address": s.address, "size": s.size,
        })).collect::<Vec<_>>(),
        "program": plan.program.iter().map(|p| serde_json::json!({
            "address": p.address, "size": p.size, "what": p.what.name(),
        })).collect::<Vec<_>>(),
    })
}

/// The plan as text.
fn plan_text(plan: &Plan, bank_crc: u32) -> String {
    let erased: u64 = plan.erase.iter().map(|s| s.size).sum();
    let mut s = format!(
        "chip      {}\nerase     {} sectors, {erased} bytes\n",
        plan.chip,
        plan.erase.len()
    );
    for e in &plan.erase {
        s += &format!(
            "  sector  {:#010x}..{:#010x}  {:>7} bytes\n",
            e.address,
            e.address + e.size,
            e.size
        );
    }
    let programmed: u64 = plan.program.iter().map(|p| p.size).sum();
    s += &format!(
        "program   {} ranges, {programmed} bytes\n",
        plan.program.len()
    );
    for p in &plan.program {
        s += &format!(
            "  {:<9}{:#010x}..{:#010x}  {:>7} bytes\n",
            p.what.name(),
            p.address,
            p.address + p.size,
            p.size
        );
    }
    s += &format!("bank crc  {bank_crc:#010x}\n");
    s
}
