//! `host demo`: the default liver scene in the browser, the firmware's loop on the PC
//! ([`haptic::demo::run`]). Prints the preparation's figures and the viewer's address, then
//! runs until `--seconds` pass or Ctrl-C, and prints the loop and display figures. With
//! `--headless --script ...` it runs a scripted hand motion without a browser.

use super::script_arg::ScriptArg;
use anyhow::{Context, Result};
use fem::progress::Progress;
use haptic::demo::{self, DemoConfig, DemoSummary, Frontend};
use haptic::display::DisplayStats;
use haptic::display::source::SourceSpec;
use haptic::trajectory::Script;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

/// Arguments of `host demo`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Scene file (default: the embedded host/scenes/liver.toml).
    #[arg(long)]
    scene: Option<PathBuf>,
    /// Use this organ mesh instead of the scene's (.msh v1/v2/v4.1, .vtu, .vtk, .mesh),
    /// e.g. host/meshes/liver-10k.msh. The scene's [contact] stays (a sampled scene's FEM mesh
    /// is its own organ's): for another organ, make a scene with `host scene new`.
    #[arg(long)]
    mesh: Option<PathBuf>,
    /// Units of --mesh's coordinates; default: guessed from its bounding box (an organ is 4 to
    /// 40 cm across) and printed, refused when no unit fits.
    #[arg(long, value_enum, requires = "mesh")]
    units: Option<crate::cmd::units_arg::UnitsArg>,
    /// Telemetry source: `virtual` (the firmware loop on this PC), `sil` (the QEMU image) or
    /// `serial:<port>` (a device).
    #[arg(long, default_value = "virtual")]
    source: SourceSpec,
    /// Serial baud rate for `--source serial:<port>`.
    #[arg(long, default_value_t = 921_600)]
    baud: u32,
    /// Port of the viewer on 127.0.0.1 (0: any free port); default 8080, or any free port when
    /// headless (so several headless runs can go at once).
    #[arg(long)]
    port: Option<u16>,
    /// Open the page in the default browser (xdg-open).
    #[arg(long)]
    open: bool,
    /// Run without a browser: a scripted hand motion (default `press`), then print figures.
    #[arg(long)]
    headless: bool,
    /// Stop after this many seconds of the loop, counted from its first sample (a SIL image's
    /// boot is not counted; default: run until stopped; 10 when headless).
    #[arg(long)]
    seconds: Option<f64>,
    /// Scripted hand motion (virtual source: the mouse's stand-in; sil: the plant's hand).
    #[arg(long, value_enum)]
    script: Option<ScriptArg>,
    /// Print the figures as one JSON object.
    #[arg(long)]
    json: bool,
    /// Display frame rate, Hz.
    #[arg(long, default_value_t = 60.0)]
    fps: f64,
    /// Record the deformation as a ParaView series (demo.pvd + frame_NNNNNN.vtu) in this
    /// directory.
    #[arg(long)]
    record: Option<PathBuf>,
    /// Contact nodes whose compliance columns are kept in memory.
    #[arg(long, default_value_t = 256)]
    cache_nodes: usize,
}

/// The terminal side of a demo run: notes and progress bars on stderr, the viewer's address
/// on stdout (stderr with --json, whose stdout is one JSON object), opened with --open.
struct Terminal {
    json: bool,
    open: bool,
}

/// A progress bar that clears itself when the computation ends.
struct Clearing(crate::progress::Bar);

impl Progress for Clearing {
    fn start(&self, total: u64) {
        self.0.start(total);
    }

    fn advance(&self, steps: u64) {
        self.0.advance(steps);
    }
}

impl Drop for Clearing {
    fn drop(&mut self) {
        self.0.finish();
    }
}

impl Frontend for Terminal {
    fn note(&self, line: &str) {
        eprintln!("{line}");
    }

    fn progress(&self, what: &str) -> Box<dyn Progress + '_> {
        Box::new(Clearing(crate::progress::Bar::new(what)))
    }

    fn viewer(&self, url: &str) {
        if self.json {
            // With --json, stdout carries exactly one JSON object.
            eprintln!("viewer    {url}");
        } else {
            println!("viewer    {url}");
        }
        if self.open {
            let _ = std::process::Command::new("xdg-open").arg(url).spawn();
        }
    }
}

/// Runs the command: the first Ctrl-C ends the run as `--seconds` would (figures printed, the
/// recording finished), a second one exits at once.
pub fn run(args: Args) -> Result<()> {
    let config = DemoConfig {
        scene: args.scene.clone(),
        mesh: args.mesh.clone(),
        units: args.units.map(Into::into),
        source: args.source.clone(),
        baud: args.baud,
        port: args.port.unwrap_or(if args.headless { 0 } else { 8080 }),
        headless: args.headless,
        seconds: args.seconds,
        script: args.script.map(Script::from),
        fps: args.fps,
        record: args.record.clone(),
        cache_nodes: args.cache_nodes,
    };
    let stop = Arc::new(AtomicBool::new(false));
    let flag = Arc::clone(&stop);
    ctrlc::set_handler(move || {
        if flag.swap(true, Ordering::Relaxed) {
            std::process::exit(130);
        }
    })
    .context("cannot install the Ctrl-C handler")?;
    let ui = Terminal {
        json: args.json,
        open: args.open,
    };
    let summary = demo::run(&config, &ui, &stop)?;
    report(&args, &summary);
    Ok(())
}

/// Prints the figures of a run.
fn report(args: &Args, summary: &DemoSummary) {
    let (d, l) = (&summary.display, &summary.loop_stats);
    let (recorded, nodes, press_point) =
        (summary.recorded, summary.display_nodes, summary.press_point);
    if args.json {
        let v = serde_json::json!({
            "tick_rate_hz": l.tick_rate_hz, "max_jitter_us": l.max_jitter_us,
            "p99_jitter_us": l.p99_jitter_us,
            "display_fps": d.display_fps, "peak_force_n": l.peak_force_n,
            "faults": l.faults, "realtime": l.realtime, "frames": d.frames, "mean_frame_ms": d.mean_frame_ms,
            "max_frame_ms": d.max_frame_ms, "approximate_frames": d.approximate_frames,
            "column_batches": d.columns.batches, "column_nodes": d.columns.nodes,
            "column_batch_mean_ms": mean_batch_ms(d),
            "column_batch_max_ms": d.columns.max_seconds * 1e3,
            "display_nodes": nodes, "recorded_frames": recorded, "press_point_m": press_point,
            "max_radial_linear_m": d.max_radial_linear_m,
            "max_radial_displayed_m": d.max_radial_displayed_m,
        });
        println!("{v}");
        return;
    }
    let jitter = match (l.max_jitter_us, l.p99_jitter_us) {
        (Some(m), Some(p)) => format!("{m:.0} us (p99 {p:.0} us)"),
        (Some(m), None) => format!("{m:.0} us"),
        _ => "unknown".to_string(),
    };
    println!(
        "loop      {:.1} Hz, max jitter {jitter}{}, {} faults, peak force {:.3} N",
        l.tick_rate_hz,
        if l.realtime { " (SCHED_FIFO)" } else { "" },
        l.faults,
        l.peak_force_n
    );
    println!(
        "display   {:.1} frames/s ({} frames of a {nodes}-node surface, {:.2} ms mean, {:.2} ms max \
         per frame, {} while columns were being solved)",
        d.display_fps, d.frames, d.mean_frame_ms, d.max_frame_ms, d.approximate_frames
    );
    println!(
        "radial    largest displacement orthogonal to the contact force {:.3} mm linear, {:.3} mm \
         displayed{}",
        d.max_radial_linear_m * 1e3,
        d.max_radial_displayed_m * 1e3,
        if d.max_radial_linear_m == d.max_radial_displayed_m {
            ""
        } else {
            " (the scene's display law P)"
        }
    );
    println!(
        "columns   {} contact nodes solved in {} batches, {:.1} ms mean, {:.1} ms max per batch",
        d.columns.nodes,
        d.columns.batches,
        mean_batch_ms(d),
        d.columns.max_seconds * 1e3
    );
    if let (Some(n), Some(dir)) = (recorded, &args.record) {
        println!("recorded  {n} frames in {}", dir.join("demo.pvd").display());
    }
}

fn mean_batch_ms(d: &DisplayStats) -> f64 {
    if d.columns.batches == 0 {
        0.0
    } else {
        d.columns.seconds * 1e3 / d.columns.batches as f64
    }
}
