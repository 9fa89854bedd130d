//! The demo (`host demo`): a scene in the browser, the firmware's loop on the PC.
//!
//! [`run`] builds the scene's bank in memory (as `host bank build` does) and keeps the
//! factorised compliance for the display; starts the source (by default the virtual device:
//! the firmware's `HapticLoop` at 1 kHz in its own thread); serves the viewer on 127.0.0.1 and
//! hands its address to the [`Frontend`]; then produces display frames (surface displacement
//! `u = C[:, S] f_S`) until [`DemoConfig::seconds`] pass or the caller's stop flag is set, and
//! returns the loop and display figures. Headless, a scripted hand motion steers the tool
//! instead of the viewer's mouse.

use crate::bank::{BuiltBank, Prepared};
use crate::deform::Deformer;
use crate::display::server::{Server, SteerFn};
use crate::display::source::{LoopStats, SerialSource, Source, SourceSpec};
use crate::display::{DisplayMesh, DisplayStats, Pipeline, SurfaceModel, surface_neighbours};
use crate::kinematics::Workspace;
use crate::organ::Organ;
use crate::record::{Recorded, Recorder};
use crate::scene::{ContactModel, MeshSource, Scene};
use crate::script::{Scripted, aim_joints, press_point};
use crate::sil::source::SilSource;
use crate::trajectory::Script;
use crate::units::Units;
use crate::virtual_device::VirtualDevice;
use anyhow::{Context, Result, bail};
use bank_format::{AlignedBytes, Bank};
use fem::progress::Progress;
use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// What a demo runs: the options of `host demo`, in SI units.
#[derive(Debug, Clone)]
pub struct DemoConfig {
    /// Scene file; `None`: the embedded host/scenes/liver.toml.
    pub scene: Option<PathBuf>,
    /// An organ mesh used instead of the scene's (the scene's `[contact]` stays).
    pub mesh: Option<PathBuf>,
    /// Units of [`DemoConfig::mesh`]'s coordinates; `None`: guessed from its bounding box.
    pub units: Option<Units>,
    /// Where the telemetry comes from.
    pub source: SourceSpec,
    /// Serial baud rate for a serial source.
    pub baud: u32,
    /// Port of the viewer on 127.0.0.1 (0: any free port).
    pub port: u16,
    /// No browser: a scripted hand motion ([`Script::Press`] unless [`DemoConfig::script`])
    /// steers the tool, and the run lasts 10 s unless [`DemoConfig::seconds`].
    pub headless: bool,
    /// How long the loop runs, s, counted from its first sample; `None`: until stopped (10 s
    /// headless).
    pub seconds: Option<f64>,
    /// Scripted hand motion (a virtual source's steering; a SIL plant's hand).
    pub script: Option<Script>,
    /// Display frame rate, Hz, in (0, 1000].
    pub fps: f64,
    /// Directory of a ParaView series of the deformation (demo.pvd + frame_NNNNNN.vtu).
    pub record: Option<PathBuf>,
    /// Contact nodes whose compliance columns are kept in memory (a nodal scene's display).
    pub cache_nodes: usize,
}

/// What a demo shows its user while it runs.
pub trait Frontend {
    /// A line about the run: preparation figures, warnings, notes.
    fn note(&self, line: &str);
    /// A progress report for a long computation counting `what`; dropped when it ends.
    fn progress(&self, what: &str) -> Box<dyn Progress + '_>;
    /// The viewer serves at `url`.
    fn viewer(&self, url: &str);
}

/// The figures of a demo run.
#[derive(Debug, Clone)]
pub struct DemoSummary {
    /// The display's frames and column solves.
    pub display: DisplayStats,
    /// The loop's rate, jitter, peak force and faults, as the source measured them.
    pub loop_stats: LoopStats,
    /// Frames recorded ([`DemoConfig::record`]).
    pub recorded: Option<usize>,
    /// Nodes of the displayed surface.
    pub display_nodes: usize,
    /// The point under the organ's top centre the scripted motions aim at, m.
    pub press_point: [f64; 3],
}

/// Runs the demo of `config` until its time is up or `stop` is set (the caller's Ctrl-C);
/// `ui` sees its progress and the viewer's address.
pub fn run(config: &DemoConfig, ui: &dyn Frontend, stop: &AtomicBool) -> Result<DemoSummary> {
    let args = config;
    if !(args.fps.is_finite() && args.fps > 0.0 && args.fps <= 1000.0) {
        bail!("--fps must lie in (0, 1000], got {}", args.fps);
    }
    if let Some(s) = args.seconds
        && !(s.is_finite() && s > 0.0)
    {
        bail!("--seconds must be a positive number, got {s}");
    }
    let script_arg = args.script;
    let mut scene = Scene::load_or_default(args.scene.as_deref())?;
    if let Some(m) = &args.mesh {
        if !m.is_file() {
            bail!("--mesh {}: no such file", m.display());
        }
        let mesh = fem::mesh::read(m)?;
        let side = crate::units::largest_side(mesh.bounding_box());
        let (units, note) =
            crate::meshing::resolve_units(args.units, side, &m.display().to_string(), "--units")?;
        if let Some(n) = note {
            ui.note(&format!("{}: {n}", m.display()));
        }
        scene.mesh = MeshSource::File(m.clone());
        scene.mesh_units = Some(units);
    }
    let t = Instant::now();
    ui.note(
        "preparing the scene (compliance factorisation, bank; a sampled scene's first run computes its \
         patch compliance, about a minute, then it is cached) ...",
    );
    let prep = Prepared::from_scene(scene)?;
    prep.organ.warnings.iter().for_each(|w| ui.note(w));
    let (
        BuiltBank {
            bytes: bank_bytes,
            pairs,
            ..
        },
        cached,
    ) = {
        let progress = ui.progress("patch compliance chunks");
        crate::bank::cache::scene_bank_cached(&prep, Some(&*progress))?
    };
    ui.note(&format!(
        "scene     {}: {} nodes, {} surface nodes; bank {} reachable nodes, {pairs} coupled \
         pairs, {:.1} KiB, {} in {:.2} s",
        prep.organ.mesh_name,
        prep.organ.mesh.nodes.len(),
        prep.organ.surface.nodes.len(),
        prep.region.len(),
        bank_bytes.len() as f64 / 1024.0,
        if cached { "from the cache" } else { "built" },
        t.elapsed().as_secs_f64()
    ));
    if bank_bytes.len() > bank_format::region::BANK_LEN {
        ui.note(
            "note      this bank is larger than the MCU's 768 KiB bank region: fine for the \
             virtual device, too big for the board",
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
        ContactModel::Sampled(spec) => spec.fem_mesh.file_name().map_or_else(
            || spec.fem_mesh.display().to_string(),
            |n| n.to_string_lossy().into(),
        ),
        ContactModel::Nodal => prep.organ.mesh_name.clone(),
    };
    let fields = {
        let t = Instant::now();
        let fields = {
            let progress = ui.progress("display field chunks");
            crate::display::fields::DisplayFields::cached(&prep, &bank, Some(&*progress))?
        };
        if let Some((f, cached)) = &fields {
            ui.note(&format!(
                "display   {} surface nodes of {}, {} fields ({:.1} MiB), {} in {:.2} s",
                f.mesh.rest.len(),
                match &prep.organ.scene.contact {
                    ContactModel::Sampled(spec) => spec.fem_mesh.display().to_string(),
                    ContactModel::Nodal => String::new(),
                },
                f.samples(),
                f.bytes() as f64 / (1 << 20) as f64,
                if *cached {
                    "from the cache"
                } else {
                    "computed"
                },
                t.elapsed().as_secs_f64()
            ));
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
            let setup = crate::sil::harness::Setup {
                qemu: PathBuf::from("qemu-system-arm"),
                image: crate::mcu::build_qemu_image()?,
                bank: file.path().to_path_buf(),
            };
            let seconds = args
                .seconds
                .unwrap_or(if args.headless { 10.0 } else { 60.0 });
            let script = script_arg.unwrap_or(Script::Press);
            let session = crate::sil::harness::Session::new(&bank, script, seconds + 1.0)?;
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
    let server = Server::start(args.port, mesh_bytes.encode(), info, steer_fn)?;
    ui.viewer(&format!("http://{}/", server.addr));

    // The scripted hand stops with the display loop, whatever ended it.
    let scripted_stop = Arc::new(AtomicBool::new(false));
    let scripter = match (script, &steering) {
        (Some(s), Some(steer)) => {
            let scripted = Scripted::new(s, &workspace, &mesh.nodes, &surface.triangles, aim)
                .context("the scripted path misses the organ")?;
            let (steer, stop) = (Arc::clone(steer), Arc::clone(&scripted_stop));
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
        display_law: prep
            .organ
            .scene
            .display_law
            .and_then(crate::display::law::DisplayLaw::new),
    };
    let ran = pipeline.run(
        stop,
        run_for,
        recorder
            .as_mut()
            .map(|r| r as &mut dyn crate::display::FrameSink),
    );
    scripted_stop.store(true, Ordering::Relaxed);
    if let Some(t) = scripter {
        let _ = t.join();
    }
    let (display_stats, loop_stats) = ran?;
    let recorded = match recorder {
        Some(r) => Some(r.finish()?),
        None => None,
    };
    Ok(DemoSummary {
        display: display_stats,
        loop_stats,
        recorded,
        display_nodes,
        press_point: aim,
    })
}
