//! `host demo`: the default liver scene in the browser, the firmware's loop on the PC.
//!
//! Builds the scene's bank in memory (as `host bank build` does) and keeps the factorised
//! compliance for the display; starts the source (by default the virtual device: the firmware's
//! `HapticLoop` at 1 kHz in its own thread); serves the viewer on 127.0.0.1 and prints its
//! address; then produces display frames (surface displacement `u = C[:, S] f_S`) until
//! `--seconds` pass or the process is stopped. With `--headless --script ...` it runs a
//! scripted hand motion without a browser and prints the loop and display figures.

use super::script_arg::ScriptArg;
use anyhow::{Context, Result, bail};
use bank_format::{AlignedBytes, Bank};
use haptic::bank::{BuiltBank, Prepared};
use haptic::deform::Deformer;
use haptic::display::law::DisplayLaw;
use haptic::display::server::{Server, SteerFn};
use haptic::display::source::{LoopStats, SerialSource, Source, SourceSpec};
use haptic::display::{DisplayMesh, DisplayStats, Pipeline, SurfaceModel, surface_neighbours};
use haptic::kinematics::Workspace;
use haptic::organ::Organ;
use haptic::record::{Recorded, Recorder};
use haptic::scene::{MeshSource, Scene};
use haptic::script::{Scripted, aim_joints, press_point};
use haptic::sil::source::SilSource;
use haptic::trajectory::Script;
use haptic::virtual_device::VirtualDevice;
use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

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

/// Runs the command.
pub fn run(args: Args) -> Result<()> {
    if !(args.fps.is_finite() && args.fps > 0.0 && args.fps <= 1000.0) {
        bail!("--fps must lie in (0, 1000], got {}", args.fps);
    }
    if let Some(s) = args.seconds
        && !(s.is_finite() && s > 0.0)
    {
        bail!("--seconds must be a positive number, got {s}");
    }
    let script_arg = args.script.map(Script::from);
    let mut scene = Scene::load_or_default(args.scene.as_deref())?;
    if let Some(m) = &args.mesh {
        if !m.is_file() {
            bail!("--mesh {}: no such file", m.display());
        }
        let mesh = fem::mesh::read(m)?;
        let side = haptic::meshing::largest_side(mesh.bounding_box());
        let (units, note) = haptic::meshing::resolve_units(
            args.units.map(Into::into),
            side,
            &m.display().to_string(),
            "--units",
        )?;
        if let Some(n) = note {
            eprintln!("{}: {n}", m.display());
        }
        scene.mesh = MeshSource::File(m.clone());
        scene.mesh_units = Some(units);
    }
    let t = Instant::now();
    eprintln!(
        "preparing the scene (compliance factorisation, bank; a sampled scene's first run computes its \
         patch compliance, about a minute, then it is cached) ..."
    );
    let prep = Prepared::from_scene(scene)?;
    prep.organ.warnings.iter().for_each(|w| eprintln!("{w}"));
    let (
        BuiltBank {
            bytes: bank_bytes,
            pairs,
            ..
        },
        cached,
    ) = {
        let progress = crate::progress::Bar::new("patch compliance chunks");
        let built = haptic::bank::cache::scene_bank_cached(&prep, Some(&progress))?;
        progress.finish();
        built
    };
    eprintln!(
        "scene     {}: {} nodes, {} surface nodes; bank {} reachable nodes, {pairs} coupled \
         pairs, {:.1} KiB, {} in {:.2} s",
        prep.organ.mesh_name,
        prep.organ.mesh.nodes.len(),
        prep.organ.surface.nodes.len(),
        prep.region.len(),
        bank_bytes.len() as f64 / 1024.0,
        if cached { "from the cache" } else { "built" },
        t.elapsed().as_secs_f64()
    );
    if bank_bytes.len() > bank_format::region::BANK_LEN {
        eprintln!(
            "note      this bank is larger than the MCU's 768 KiB bank region: fine for the \
             virtual device, too big for the board"
        );
    }
    let aligned = AlignedBytes::new(&bank_bytes);
    let bank = Bank::parse(&aligned).map_err(|e| anyhow::anyhow!("built bank invalid: {e}"))?;
    let bank_to_mesh: Vec<usize> = bank.mesh_ids().iter().map(|&k| k as usize).collect();
    let cal = *bank.device();
    let workspace = Workspace::from_device(&cal);

    // A sampled scene shows its fine FEM surface under precomputed fields; a nodal one its
    // collision mesh with columns solved on demand.
    // The name the viewer shows for the displayed surface: a sampled scene's FEM mesh.
    let display_name = match &prep.organ.scene.contact {
        haptic::scene::ContactModel::Sampled(spec) => spec.fem_mesh.file_name().map_or_else(
            || spec.fem_mesh.display().to_string(),
            |n| n.to_string_lossy().into(),
        ),
        haptic::scene::ContactModel::Nodal => prep.organ.mesh_name.clone(),
    };
    let fields = {
        let progress = crate::progress::Bar::new("display field chunks");
        let t = Instant::now();
        let fields = haptic::bank::cache::display_fields_cached(&prep, &bank, Some(&progress))?;
        progress.finish();
        if let Some((f, cached)) = &fields {
            eprintln!(
                "display   {} surface nodes of {}, {} fields ({:.1} MiB), {} in {:.2} s",
                f.mesh.rest.len(),
                match &prep.organ.scene.contact {
                    haptic::scene::ContactModel::Sampled(spec) =>
                        spec.fem_mesh.display().to_string(),
                    haptic::scene::ContactModel::Nodal => String::new(),
                },
                f.samples(),
                f.bytes() as f64 / (1 << 20) as f64,
                if *cached {
                    "from the cache"
                } else {
                    "computed"
                },
                t.elapsed().as_secs_f64()
            );
        }
        fields.map(|(f, _)| Arc::new(f))
    };
    let Prepared {
        organ:
            Organ {
                mesh,
                mesh_name,
                surface,
                ..
            },
        compliance,
        ..
    } = prep;
    let (display, neighbours) = match &fields {
        Some(f) => (f.mesh.clone(), HashMap::new()),
        None => (
            DisplayMesh::of_surface(&mesh.nodes, &surface),
            surface_neighbours(&surface.triangles),
        ),
    };
    let aim = press_point(&mesh, &surface.triangles)
        .context("the organ's surface has no point under its top centre")?;

    let mut sil_bank: Option<tempfile::NamedTempFile> = None;
    let mut source: Box<dyn Source> = match &args.source {
        SourceSpec::Virtual => Box::new(VirtualDevice::start(bank_bytes.clone())?),
        SourceSpec::Sil => {
            // The bank built above, loaded into QEMU's flash as the board's would be; the
            // image's hand follows the script (default press) for --seconds (default 60 s).
            let file = sil_bank.insert(tempfile::NamedTempFile::new()?);
            std::io::Write::write_all(file, &bank_bytes)?;
            let setup = haptic::sil::harness::Setup {
                qemu: PathBuf::from("qemu-system-arm"),
                image: haptic::mcu::build_qemu_image()?,
                bank: file.path().to_path_buf(),
            };
            let seconds = args
                .seconds
                .unwrap_or(if args.headless { 10.0 } else { 60.0 });
            let script = script_arg.unwrap_or(Script::Press);
            let session = haptic::sil::harness::Session::new(&bank, script, seconds + 1.0)?;
            Box::new(SilSource::start(setup, session)?)
        }
        SourceSpec::Serial(port) => Box::new(SerialSource::open(
            port,
            args.baud,
            bank.crc(),
            &format!(
                "the bank of {}",
                args.scene.as_deref().map_or_else(
                    || "host/scenes/liver.toml (embedded)".into(),
                    |p| p.display().to_string()
                )
            ),
        )?),
    };
    let steering = source.steering();
    let script = match (script_arg, args.headless) {
        (Some(s), _) => Some(s),
        (None, true) => Some(Script::Press),
        (None, false) => None,
    };
    if script_arg.is_some() && steering.is_none() && args.source != SourceSpec::Sil {
        bail!("--script needs a source that can be steered (--source virtual) or sil");
    }

    let (lo, hi) = display.bounding_box();
    let info = serde_json::json!({
        "mesh": display_name, "collision_mesh": mesh_name, "mesh_nodes": mesh.nodes.len(), "display_nodes": display.rest.len(),
        "triangles": display.triangles.len(), "fulcrum_m": cal.fulcrum_m,
        "tip_radius_m": cal.tip_radius_m, "max_force_n": cal.max_force_n,
        "bbox_min": lo, "bbox_max": hi, "press_point": aim,
        "source": format!("{:?}", args.source),
    });
    let steer_fn: Option<SteerFn> = steering.clone().map(|s| {
        let f: SteerFn = Arc::new(move |aim: [f64; 3], depth: f64| {
            s(aim_joints(&workspace, aim, depth));
        });
        f
    });
    let display_nodes = display.rest.len();
    let mesh_bytes = Arc::new(display);
    let port = args.port.unwrap_or(if args.headless { 0 } else { 8080 });
    let server = Server::start(port, mesh_bytes.encode(), info, steer_fn)?;
    let url = format!("http://{}/", server.addr);
    if args.json {
        // With --json, stdout carries exactly one JSON object.
        eprintln!("viewer    {url}");
    } else {
        println!("viewer    {url}");
    }
    if args.open {
        let _ = std::process::Command::new("xdg-open").arg(&url).spawn();
    }

    let stop = Arc::new(AtomicBool::new(false));
    let scripter = match (script, &steering) {
        (Some(s), Some(steer)) => {
            let scripted = Scripted::new(s, &workspace, &mesh.nodes, &surface.triangles, aim)
                .context("the scripted path misses the organ")?;
            let (steer, stop) = (Arc::clone(steer), Arc::clone(&stop));
            Some(std::thread::spawn(move || {
                let t0 = Instant::now();
                while !stop.load(Ordering::Relaxed) {
                    steer(scripted.joints(t0.elapsed().as_secs_f64()));
                    std::thread::sleep(Duration::from_millis(5));
                }
            }))
        }
        _ => None,
    };

    let seconds = args.seconds.or(args.headless.then_some(10.0));
    let run_for = seconds.map(Duration::from_secs_f64);
    let mesh = Arc::new(mesh);
    let compliance = Arc::new(compliance);
    let mut recorder = match &args.record {
        Some(dir) => {
            let what = if fields.is_some() {
                Recorded::Surface(Arc::clone(&mesh_bytes))
            } else {
                Recorded::Volume {
                    mesh: Arc::clone(&mesh),
                    compliance: Arc::clone(&compliance),
                }
            };
            Some(Recorder::start(dir, what)?)
        }
        None => None,
    };
    let surface_model = match fields {
        Some(f) => SurfaceModel::Sampled(f),
        None => SurfaceModel::Nodal {
            deformer: Box::new(Deformer::new(
                Arc::clone(&compliance),
                &mesh.nodes,
                surface.nodes.clone(),
                args.cache_nodes,
            )),
            neighbours,
        },
    };
    let mut pipeline = Pipeline {
        source: source.as_mut(),
        surface: surface_model,
        mesh: mesh_bytes,
        bank_to_mesh,
        hub: server.hub.clone(),
        fps: args.fps,
        display_law: prep.organ.scene.display_law.and_then(DisplayLaw::new),
    };
    let (display_stats, loop_stats) = pipeline.run(
        &stop,
        run_for,
        recorder
            .as_mut()
            .map(|r| r as &mut dyn haptic::display::FrameSink),
    )?;
    stop.store(true, Ordering::Relaxed);
    if let Some(t) = scripter {
        let _ = t.join();
    }
    let recorded = match recorder {
        Some(r) => Some(r.finish()?),
        None => None,
    };
    report(
        &args,
        &display_stats,
        &loop_stats,
        (recorded, display_nodes, aim),
    );
    Ok(())
}

/// Prints the figures of a run: `(recorded frames, display nodes, press point)` besides the
/// statistics.
fn report(
    args: &Args,
    d: &DisplayStats,
    l: &LoopStats,
    (recorded, nodes, press_point): (Option<usize>, usize, [f64; 3]),
) {
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
