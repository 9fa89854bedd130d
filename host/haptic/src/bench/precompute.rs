//! What a sampled scene's precompute costs (`host bench precompute`): the bank (FEM
//! factor and `W` at every sample, with its Richardson partner) and the display fields, timed
//! and with the process's peak memory, without the cache; then the start of a run that finds
//! both in the cache (read and validate the bank, read the fields). And the patch compliance's
//! two methods side by side (`host bench patch`, [`patch_methods`]).

use crate::bank::sampled::{SampledFem, lattice_points};
use crate::bank::{BankSpec, BuiltBank, Prepared};
use crate::display::fields::DisplayFields;
use crate::organ::Organ;
use crate::reach::Region;
use crate::scene::{ContactModel, FemElement, SampledContact, Scene};
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

impl Overrides {
    /// Applies the overrides to the sampled `scene`'s `[contact]`; its contact spec after them.
    /// A nodal scene or a missing `fem_mesh` is an error.
    fn apply(&self, scene: &mut Scene) -> Result<SampledContact> {
        let path = scene.path.display().to_string();
        let ContactModel::Sampled(spec) = &mut scene.contact else {
            bail!(
                "{path}: the scene's contact model is nodal; this benchmark measures a sampled \
                 scene ([contact] model = \"sampled\")"
            );
        };
        if let Some(m) = &self.fem_mesh {
            if !m.is_file() {
                bail!("--fem-mesh {}: no such file", m.display());
            }
            spec.fem_mesh = m.clone();
        }
        if let Some(e) = self.element {
            spec.element = e;
        }
        if self.no_richardson {
            spec.richardson = None;
        }
        Ok(spec.clone())
    }
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
    let spec = overrides.apply(&mut scene)?;
    crate::rss::reset_peak();
    let t0 = Instant::now();
    let prep = Prepared::from_scene(scene.clone())?;
    let prepare_s = t0.elapsed().as_secs_f64();
    let t1 = Instant::now();
    let BuiltBank { bytes, sampled, .. } = prep.bank(&BankSpec::Scene { progress })?;
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

/// The patch compliance of tool loads on a sampled scene's FEM by the two methods of
/// `fem::compliance::patch` (`host bench patch`).
#[derive(Debug, Clone, serde::Serialize)]
pub struct PatchMethods {
    /// The FEM mesh.
    pub fem_mesh: String,
    /// Its element.
    pub element: String,
    /// Free dofs of `K_ff`.
    pub free_dofs: usize,
    /// Entries of its Cholesky factor.
    pub nnz_l: usize,
    /// Seconds to read, assemble and factorise.
    pub factor_s: f64,
    /// Tool loads (evenly spread over the scene's samples).
    pub loads: usize,
    /// Largest number of FEM nodes one load touches.
    pub widest: usize,
    /// Seconds for `W` by the sparse forward substitution (what banks use).
    pub forward_s: f64,
    /// Seconds for `W` by full solves.
    pub full_s: f64,
    /// Largest difference of an entry of `W` between the two, relative to that `W`'s largest
    /// diagonal entry.
    pub max_difference: f64,
}

/// Times [`fem::compliance::Compliance::patch_compliances`] against
/// [`fem::compliance::Compliance::patch_compliances_by_full_solves`] for `loads` of the
/// sampled `scene`'s samples (with `overrides`) on its FEM; `loads` 0 means all.
pub fn patch_methods(scene: Scene, overrides: &Overrides, loads: usize) -> Result<PatchMethods> {
    let mut scene = scene;
    let spec = overrides.apply(&mut scene)?;
    let organ = Organ::from_scene(scene)?;
    let region = Region::of(&organ)?;
    let (_, points) = lattice_points(&region.positions, &region.triangles, spec.level);
    let take = if loads == 0 {
        points.len()
    } else {
        loads.min(points.len())
    };
    let chosen: Vec<[f64; 3]> = (0..take).map(|i| points[i * points.len() / take]).collect();
    let fem = SampledFem::load(&organ.scene, &spec.fem_mesh, spec.element)?;
    let (tool_loads, _) = fem.tool_loads(&chosen, organ.scene.tip_radius_m)?;
    let t = Instant::now();
    let forward = fem.compliance.patch_compliances(&tool_loads, None)?;
    let forward_s = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let full = fem
        .compliance
        .patch_compliances_by_full_solves(&tool_loads, None)?;
    let full_s = t.elapsed().as_secs_f64();
    let max_difference = fem::compliance::largest_difference(&forward, &full);
    let stats = fem.compliance.stats();
    Ok(PatchMethods {
        fem_mesh: spec.fem_mesh.display().to_string(),
        element: spec.element.name().to_string(),
        free_dofs: stats.free_dofs,
        nnz_l: stats.nnz_l,
        factor_s: fem.factor_s,
        loads: tool_loads.len(),
        widest: tool_loads.iter().map(Vec::len).max().unwrap_or(0),
        forward_s,
        full_s,
        max_difference,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `host bench patch`'s two methods agree to rounding on the default scene's FEM (P1 here,
    /// for speed), over the loads asked for.
    #[test]
    fn the_patch_methods_agree_on_the_default_scene() {
        let scene = Scene::load_or_default(None).unwrap();
        let overrides = Overrides {
            element: Some(FemElement::Linear(fem::elasticity::Element::P1)),
            no_richardson: true,
            ..Overrides::default()
        };
        let m = patch_methods(scene, &overrides, 5).unwrap();
        assert_eq!((m.loads, m.element.as_str()), (5, "p1"));
        assert!(m.free_dofs > 30_000 && m.widest >= 3, "{m:?}");
        assert!(m.max_difference < 1e-10, "{m:?}");
        let nodal = Scene::load(std::path::Path::new(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../scenes/liver-nodal.toml"
        )))
        .unwrap();
        let err = patch_methods(nodal, &overrides, 5).unwrap_err().to_string();
        assert!(err.contains("nodal"), "{err}");
    }
}
