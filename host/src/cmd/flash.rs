//! `host flash`: the board image and a bank onto the STM32F405 through a debug probe (crate
//! [`flash`], probe-rs as a library), checked before (bank, image, layout) and after (the
//! device's `Hello` reports the bank written).

use anyhow::{Context, Result, bail};
use bank_format::region::BANK_LEN;
use fem::progress::Progress as _;
use flash::{Layout, Part, Phase, Plan, Progress, What};
use host::link::{await_identity, check_identity, open_device_port};
use host::progress::Bar;
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
    #[arg(long, conflicts_with_all = ["scene", "bank", "elf", "bank_only", "dry_run"])]
    list: bool,
    /// Print the plan (sectors erased, ranges programmed) and exit; needs no probe.
    #[arg(long)]
    dry_run: bool,
    /// With --dry-run: the plan as one JSON object.
    #[arg(long, requires = "dry_run")]
    json: bool,
    /// The device's USB serial port for the `Hello` check after flashing (default: the port
    /// with the board's USB id, firmware/board/src/board.rs `usb_vid_pid`).
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
        }
        return Ok(());
    }
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

/// The bank's bytes and a name for messages.
fn bank_bytes(args: &Args) -> Result<(Vec<u8>, String)> {
    match (&args.scene, &args.bank) {
        (Some(scene), None) => Ok((
            host::bank::scene_bank(scene)?,
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
    let dir = host::mcu::repo_root().join("firmware/board");
    eprintln!("building the board image in {} ...", dir.display());
    host::mcu::build_image(&dir, "the board image", " (or pass --elf F)")?;
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
