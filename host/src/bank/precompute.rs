//! What a sampled scene's precompute costs (`host bench precompute`, issue 26): the bank (FEM
//! factor and `W` at every sample, with its Richardson partner) and the display fields, timed
//! and with the process's peak memory, without the cache; then the start of a run that finds
//! both in the cache (read and validate the bank, read the fields).

use super::{BuiltBank, Prepared};
use crate::display::fields::DisplayFields;
use crate::scene::{ContactModel, FemElement, Scene};
use anyhow::{Context, Result, bail};
use bank_format::{AlignedBytes, Bank};
use fem::progress::Progress;
use std::path::PathBuf;
use std::time::Instant;

/// Changes to the scene's `[contact]` for a measurement (e.g. a larger FEM mesh).
#[derive(Debug, Clone, Default)]
pub struct Overrides {
    /// Another FEM mesh for the samples and the display fields.
    pub fem_mesh: Option<PathBuf>,
    /// Another element.
    pub element: Option<FemElement>,
    /// Drop the Richardson extrapolation.
    pub no_richardson: bool,
}

/// The figures (module notes).
#[derive(Debug, Clone, serde::Serialize)]
pub struct Figures {
    /// The FEM mesh.
    pub fem_mesh: String,
    /// Its element.
    pub element: String,
    /// The Richardson partner mesh, if any.
    pub richardson_mesh: Option<String>,
    /// FEM vertices and body nodes (P2: with edge nodes).
    pub fem_vertices: usize,
    /// Body nodes.
    pub fem_nodes: usize,
    /// Contact samples.
    pub samples: usize,
    /// Bank bytes.
    pub bank_bytes: usize,
    /// Seconds to prepare the scene (collision mesh, its factor, the reach).
    pub prepare_s: f64,
    /// Seconds to build the bank (FEM factors and `W`).
    pub bank_s: f64,
    /// Seconds for the display fields.
    pub fields_s: f64,
    /// Display nodes (the FEM mesh's surface).
    pub display_nodes: usize,
    /// Memory the display fields hold, bytes.
    pub fields_bytes: usize,
    /// Peak resident memory of the whole precompute, MiB.
    pub peak_rss_mib: f64,
    /// Seconds to start from the cache: prepare the scene, read and validate the bank, read
    /// the fields.
    pub cached_start_s: f64,
}

/// Measures the precompute of the sampled scene `scene` with `overrides` (module notes).
pub fn measure(
    scene: Scene,
    overrides: &Overrides,
    progress: Option<&dyn Progress>,
) -> Result<Figures> {
    let mut scene = scene;
    let ContactModel::Sampled(spec) = &mut scene.contact else {
        bail!(
            "{}: the scene's contact model is nodal; the precompute benchmark measures a \
             sampled scene ([contact] model = \"sampled\")",
            scene.path.display()
        );
    };
    if let Some(m) = &overrides.fem_mesh {
        if !m.is_file() {
            bail!("--fem-mesh {}: no such file", m.display());
        }
        spec.fem_mesh = m.clone();
    }
    if let Some(e) = overrides.element {
        spec.element = e;
    }
    if overrides.no_richardson {
        spec.richardson = None;
    }
    let spec = spec.clone();
    crate::rss::reset_peak();
    let t0 = Instant::now();
    let prep = Prepared::from_scene(scene.clone())?;
    let prepare_s = t0.elapsed().as_secs_f64();
    let t1 = Instant::now();
    let BuiltBank { bytes, sampled, .. } = prep.build_bank(progress)?;
    let bank_s = t1.elapsed().as_secs_f64();
    let aligned = AlignedBytes::new(&bytes);
    let bank = Bank::parse(&aligned).map_err(|e| anyhow::anyhow!("built bank invalid: {e}"))?;
    let t2 = Instant::now();
    let fields = DisplayFields::for_bank(&prep, &bank, progress)?
        .context("the sampled bank has no samples")?;
    let fields_s = t2.elapsed().as_secs_f64();
    let peak_rss_mib = crate::rss::peak_mib();
    let stats = sampled.context("the sampled bank's statistics are missing")?;

    // The cached start, from files as the cache holds them.
    let dir = tempfile::tempdir().context("cannot create a temporary directory")?;
    let (bank_file, fields_file) = (dir.path().join("bank.bin"), dir.path().join("fields.bin"));
    std::fs::write(&bank_file, &bytes)?;
    std::fs::write(&fields_file, fields.encode())?;
    drop((prep, aligned));
    let t3 = Instant::now();
    let prep = Prepared::from_scene(scene)?;
    let read = std::fs::read(&bank_file)?;
    let aligned = AlignedBytes::new(&read);
    Bank::parse(&aligned).map_err(|e| anyhow::anyhow!("cached bank invalid: {e}"))?;
    let cached = DisplayFields::decode(&std::fs::read(&fields_file)?)?;
    let cached_start_s = t3.elapsed().as_secs_f64();
    drop((prep, cached));

    Ok(Figures {
        fem_mesh: spec.fem_mesh.display().to_string(),
        element: spec.element.name().to_string(),
        richardson_mesh: spec.richardson.map(|r| r.mesh.display().to_string()),
        fem_vertices: stats.fem_vertices,
        fem_nodes: stats.fem_nodes,
        samples: stats.samples,
        bank_bytes: bytes.len(),
        prepare_s,
        bank_s,
        fields_s,
        display_nodes: fields.mesh.rest.len(),
        fields_bytes: fields.bytes(),
        peak_rss_mib,
        cached_start_s,
    })
}
