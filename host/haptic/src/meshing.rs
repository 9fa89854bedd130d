//! From a closed surface to a tetrahedral mesh (`host mesh`, [`mesh_surface`]): units, surface
//! checks and repairs, the size field near the tool's reach, and Gmsh (its Python module,
//! pinned to 4.15.2 and installed by `scripts/test-all.sh`) as the mesher.
//!
//! Why Gmsh through Python: Gmsh is the project's mesher already (`scripts/gen_meshes.py`
//! makes every shipped mesh with the same pinned module), its pip wheel carries the whole
//! library (no system package has 4.15.2), and its STL remeshing (`classifySurfaces`,
//! `createGeometry`) and optimisers (Gmsh's and Netgen's) are what a segmented surface needs.
//! The script (`scripts/mesh_surface.py`) is embedded in the binary and run with `python3`
//! (or `$HOST_PYTHON`); the surface and the reachable points go to it as files, the mesh
//! comes back as a temporary MSH file that is validated here before anything is written.

use crate::kinematics::Workspace;
use crate::scene::Scene;
use crate::units::{Units, guess_units, largest_side, scale_mesh};
use anyhow::{Context, Result, bail};
use fem::mesh::TetMesh;
use fem::surface::{CheckOptions, TriSurface, read_surface};
use std::path::PathBuf;
use std::process::Command;
use std::time::Instant;

/// The meshing script, run by [`run_gmsh`].
const SCRIPT: &str = include_str!("../../../scripts/mesh_surface.py");

/// The units of the file `name` (a surface or a tetrahedral mesh) whose bounding box's largest
/// side is `side` in file units: `given` when there is one, else the guess of [`guess_units`],
/// with the line that says so (to print); no guess is an error that names the file and tells to
/// set `option` (`--units`, or a scene's `mesh_units`).
pub fn resolve_units(
    given: Option<Units>,
    side: f64,
    name: &str,
    option: &str,
) -> Result<(Units, Option<String>)> {
    if let Some(u) = given {
        return Ok((u, None));
    }
    let u = guess_units(side).map_err(|e| anyhow::anyhow!("{name}: {e}; set {option}"))?;
    let note = format!(
        "units: {} (guessed: the largest side is {side:.4}, {:.3} m in {}; {option} overrides)",
        u.name(),
        side * u.to_metres(),
        u.name()
    );
    Ok((u, Some(note)))
}

/// Reads the tetrahedral mesh file `path` (any format of [`fem::mesh::read_counted`]) in
/// `given` units or, without them, the units [`resolve_units`] guesses (the guess's line is
/// printed to stderr), scales it to metres and validates it; returns the mesh, the skipped
/// lower-dimensional elements and the units. `option` names how to give the units.
pub fn load_mesh_in_units(
    path: &std::path::Path,
    given: Option<Units>,
    option: &str,
) -> Result<(TetMesh, fem::mesh::Ignored, Units)> {
    let (mut mesh, ignored) = fem::mesh::read_counted(path)?;
    let name = path.display().to_string();
    let (units, note) = resolve_units(given, largest_side(mesh.bounding_box()), &name, option)?;
    if let Some(n) = note {
        eprintln!("{name}: {n}");
    }
    scale_mesh(&mut mesh, units);
    fem::mesh::validate(&mesh).map_err(|e| e.with_path(path))?;
    Ok((mesh, ignored, units))
}

/// Whether `path` names a tetrahedral mesh rather than a surface: `.msh`, `.mesh` or `.vtu`,
/// or a legacy `.vtk` whose header (its first 1 KiB) declares an `UNSTRUCTURED_GRID`.
pub fn is_volume_mesh(path: &std::path::Path) -> bool {
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    match ext.as_str() {
        "msh" | "mesh" | "vtu" => true,
        "vtk" => {
            use std::io::Read;
            let mut head = Vec::new();
            std::fs::File::open(path)
                .and_then(|f| f.take(1024).read_to_end(&mut head))
                .is_ok_and(|_| {
                    head.windows(b"UNSTRUCTURED_GRID".len())
                        .any(|w| w.eq_ignore_ascii_case(b"UNSTRUCTURED_GRID"))
                })
        }
        _ => false,
    }
}

/// A tetrahedral mesh file as `host mesh --check` reports it: read in its units, scaled to
/// metres, validated, its boundary closed and manifold.
pub struct VolumeCheck {
    /// The mesh, in metres.
    pub mesh: TetMesh,
    /// Lower-dimensional elements the file holds, skipped.
    pub ignored: fem::mesh::Ignored,
    /// The file's units (given or guessed).
    pub units: Units,
    /// The sum of the tetrahedra's volumes, m^3.
    pub volume_m3: f64,
    /// Faces and nodes of the boundary surface.
    pub boundary: (usize, usize),
}

/// Reads and checks the tetrahedral mesh file `path` ([`load_mesh_in_units`], then its boundary
/// surface, which must be closed and manifold).
pub fn check_volume(path: &std::path::Path, given: Option<Units>) -> Result<VolumeCheck> {
    let (mesh, ignored, units) = load_mesh_in_units(path, given, "--units")?;
    let surface = fem::mesh::boundary(&mesh).map_err(|e| e.with_path(path))?;
    let volume_m3 = (0..mesh.tets.len()).map(|t| mesh.signed_volume(t)).sum();
    Ok(VolumeCheck {
        boundary: (surface.triangles.len(), surface.nodes.len()),
        mesh,
        ignored,
        units,
        volume_m3,
    })
}

/// The points of `surface` (metres; vertices and face centroids) within the tip radius plus
/// the scene's reach margin of the scene's tool workspace ([`Workspace::reaches`], the test
/// the bank's reachable region uses).
pub fn reach_points(surface: &TriSurface, scene: &Scene) -> Vec<[f64; 3]> {
    let w = Workspace::from_device(&scene.device);
    let margin = scene.tip_radius_m + scene.bank.reach_margin_m;
    let centroids = surface.triangles.iter().map(|t| {
        let [a, b, c] = t.map(|v| surface.vertices[v]);
        [0, 1, 2].map(|k| (a[k] + b[k] + c[k]) / 3.0)
    });
    surface
        .vertices
        .iter()
        .copied()
        .chain(centroids)
        .filter(|&p| w.reaches(p, margin))
        .collect()
}

/// Sizes for [`run_gmsh`], metres.
#[derive(Debug, Clone)]
pub struct Sizes {
    /// Size away from the reach (everywhere without one).
    pub size: f64,
    /// Size at the reachable points, and its growth per metre of distance from them.
    pub fine: Option<(f64, f64)>,
    /// The reachable points.
    pub reach: Vec<[f64; 3]>,
}

/// Mesh the inside of `surface` (metres, checked: closed, oriented, one shell) with Gmsh; the
/// mesh is validated ([`fem::mesh::validate`]) and holds only the nodes its tetrahedra use.
pub fn run_gmsh(surface: &TriSurface, sizes: &Sizes) -> Result<TetMesh> {
    let dir = tempfile::tempdir().context("cannot make a temporary directory for Gmsh")?;
    let stl = dir.path().join("surface.stl");
    std::fs::write(&stl, surface.to_stl_binary())?;
    let (fine, gradient) = sizes.fine.unzip();
    let job = serde_json::json!({
        "surface": stl,
        "size": sizes.size,
        "fine": fine,
        "gradient": gradient,
        "reach_points": sizes.reach,
    });
    let mesh = run_gmsh_job(dir.path(), SCRIPT, job, "")?;
    fem::mesh::validate(&mesh).context("Gmsh's mesh fails validation")?;
    Ok(mesh)
}

/// Runs the Gmsh Python script `script` (its text, embedded in the binary) with `python3` (or
/// `$HOST_PYTHON`) on `job`, a JSON object written to a file in `dir` whose `"output"` is set
/// here to the MSH file the script must write there; reads that mesh back without the nodes no
/// tetrahedron uses ([`compact`]). `what` prefixes the error messages (e.g. `"--cylinder: "`).
pub(crate) fn run_gmsh_job(
    dir: &std::path::Path,
    script: &str,
    mut job: serde_json::Value,
    what: &str,
) -> Result<TetMesh> {
    let script_path = dir.join("gmsh_job.py");
    let job_path = dir.join("job.json");
    let out = dir.join("volume.msh");
    std::fs::write(&script_path, script)?;
    job["output"] = serde_json::json!(out);
    std::fs::write(&job_path, job.to_string())?;
    let python = std::env::var("HOST_PYTHON").unwrap_or_else(|_| "python3".into());
    let status = Command::new(&python)
        .arg(&script_path)
        .arg(&job_path)
        .status()
        .with_context(|| {
            format!(
                "{what}cannot run {python} for Gmsh (install Python 3 and `pip install \
                 gmsh==4.15.2 numpy`; scripts/test-all.sh does)"
            )
        })?;
    if !status.success() {
        bail!(
            "{what}Gmsh failed ({status}; its messages are above). If the module is missing: \
             `pip install gmsh==4.15.2 numpy`"
        );
    }
    let mesh = fem::mesh::read(&out).with_context(|| format!("{what}reading Gmsh's mesh"))?;
    Ok(compact(mesh))
}

/// The mesh without the nodes no tetrahedron uses (Gmsh may keep some of the input
/// surface's), the others in their original order.
pub(crate) fn compact(mesh: TetMesh) -> TetMesh {
    let mut used = vec![false; mesh.nodes.len()];
    for t in &mesh.tets {
        for &v in t {
            if let Some(u) = used.get_mut(v) {
                *u = true;
            }
        }
    }
    let mut new_id = vec![usize::MAX; mesh.nodes.len()];
    let mut nodes = Vec::new();
    for (i, p) in mesh.nodes.iter().enumerate() {
        if used[i] {
            new_id[i] = nodes.len();
            nodes.push(*p);
        }
    }
    let tets = mesh
        .tets
        .iter()
        .map(|t| t.map(|v| new_id.get(v).copied().unwrap_or(usize::MAX)))
        .collect();
    TetMesh { nodes, tets }
}

/// Where an element's size is measured: its longest edge, against the distance of its
/// centroid from the nearest of `points`. For the size-against-reach report.
pub fn size_against_distance(mesh: &TetMesh, points: &[[f64; 3]]) -> Vec<(f64, f64)> {
    mesh.tets
        .iter()
        .map(|t| {
            let p = t.map(|v| mesh.nodes[v]);
            let mut longest: f64 = 0.0;
            for i in 0..4 {
                for j in i + 1..4 {
                    longest = longest.max(fem::vec3::norm(fem::vec3::sub(p[i], p[j])));
                }
            }
            let c = [0, 1, 2].map(|k| (p[0][k] + p[1][k] + p[2][k] + p[3][k]) / 4.0);
            let d = points
                .iter()
                .map(|&q| fem::vec3::dist2(c, q))
                .fold(f64::INFINITY, f64::min)
                .sqrt();
            (d, longest)
        })
        .collect()
}

/// Largest [`MeshConfig::fill_holes`].
pub const MAX_FILL_HOLES: usize = 1000;

/// What `host mesh` does with a surface: its options, in SI units.
#[derive(Debug, Clone)]
pub struct MeshConfig {
    /// The closed triangulated surface file (.stl, .obj, .ply, .vtk polydata, .vtp).
    pub surface: PathBuf,
    /// Where the tetrahedral mesh goes (Gmsh 4.1 ASCII, metres, written atomically); `None`
    /// or [`MeshConfig::check`]: check only.
    pub output: Option<PathBuf>,
    /// Units of the surface's coordinates; `None`: guessed from its bounding box.
    pub units: Option<Units>,
    /// Element size away from the reach, m; `None`: the largest side of the bounding box / 15.
    pub size: Option<f64>,
    /// A scene whose tool reach gets the fine size.
    pub refine_near: Option<PathBuf>,
    /// Element size where the tool reaches, m; `None`: the size / 3.
    pub fine: Option<f64>,
    /// Growth of the element size per metre away from the reach.
    pub gradient: f64,
    /// Make the safe repairs ([`fem::surface::check`]).
    pub repair: bool,
    /// Largest hole the repairs fill, in boundary edges (at most [`MAX_FILL_HOLES`]).
    pub fill_holes: usize,
    /// Vertices closer than this fraction of the bounding-box diagonal are duplicates.
    pub merge_tolerance: f64,
    /// Keep the largest shell instead of refusing several.
    pub largest: bool,
    /// Check (and repair) the surface without meshing.
    pub check: bool,
}

/// What [`mesh_surface`] made.
pub enum MeshOutcome {
    /// [`MeshConfig::check`] (or no output): the surface passed its checks, nothing meshed.
    Checked,
    /// The mesh, written to `output`.
    Meshed {
        /// Where it was written.
        output: PathBuf,
        /// The mesh, metres.
        mesh: TetMesh,
        /// The sum of the tetrahedra's volumes, m^3.
        volume_m3: f64,
        /// The checked surface's enclosed volume, m^3.
        surface_volume_m3: f64,
        /// Time from the start of [`mesh_surface`] to the mesh written, s.
        seconds: f64,
    },
}

/// Meshes the surface of `config`: reads it, resolves its units, checks (and with
/// [`MeshConfig::repair`] repairs) it, sets the sizes (fine within the reach of
/// [`MeshConfig::refine_near`]'s tool, [`reach_points`]), runs Gmsh ([`run_gmsh`]) and writes
/// the mesh atomically. Each step's figures go to `note` as a line of text, as they are known.
pub fn mesh_surface(config: &MeshConfig, note: &mut dyn FnMut(&str)) -> Result<MeshOutcome> {
    let t0 = Instant::now();
    let a = config;
    let surface = read_surface(&a.surface)?;
    let name = a.surface.display().to_string();
    note(&format!(
        "{name}: {} vertices, {} faces",
        surface.vertices.len(),
        surface.triangles.len()
    ));
    let (units, guessed) = resolve_units(
        a.units,
        largest_side(surface.bounding_box()),
        &name,
        "--units",
    )?;
    if let Some(n) = guessed {
        note(&n);
    }
    // The least-area filling is O(n^3) in time and O(n^2) in memory: 1,000 edges take about
    // 10^8 steps and 16 MB.
    if a.fill_holes > MAX_FILL_HOLES {
        bail!(
            "--fill-holes {}: at most {MAX_FILL_HOLES} edges (a larger hole is no small defect: \
             close it where the surface was made)",
            a.fill_holes
        );
    }
    if !(a.merge_tolerance >= 0.0 && a.merge_tolerance < 0.01) {
        bail!(
            "--merge-tolerance {}: must be in [0, 0.01)",
            a.merge_tolerance
        );
    }
    let opts = CheckOptions {
        repair: a.repair,
        merge_tolerance: a.merge_tolerance,
        fill_holes: a.fill_holes,
        largest: a.largest,
    };
    let (checked, repairs) =
        fem::surface::check(&surface, opts).with_context(|| format!("{name}: refused"))?;
    for n in &repairs {
        note(&format!("repaired: {n}"));
    }
    let surface_m = checked.scaled(units.to_metres());
    // The default size is the kept surface's (--largest may have dropped a far shell).
    let side_m = largest_side(surface_m.bounding_box());
    let volume = surface_m.signed_volume();
    note(&format!(
        "surface: closed, {} faces, volume {:.4e} m^3 ({:.1} cm^3), largest side {:.4} m",
        surface_m.triangles.len(),
        volume,
        volume * 1e6,
        side_m
    ));
    let size = a.size.unwrap_or(side_m / 15.0);
    if !(size > 0.0 && size.is_finite()) {
        bail!("--size {size}: must be a positive length in metres");
    }
    let mut sizes = Sizes {
        size,
        fine: None,
        reach: Vec::new(),
    };
    if let Some(scene_path) = &a.refine_near {
        let scene = Scene::load(scene_path)?;
        let fine = a.fine.unwrap_or(size / 3.0);
        if !(fine > 0.0 && fine <= size) {
            bail!("--fine {fine}: must be positive and at most the size {size} m");
        }
        if !(a.gradient > 0.0 && a.gradient.is_finite()) {
            bail!("--gradient {}: must be positive", a.gradient);
        }
        sizes.reach = reach_points(&surface_m, &scene);
        if sizes.reach.is_empty() {
            bail!(
                "{}: the tool reaches no point of {name} (in {}): is the organ where the scene's \
                 trocar and insertion range expect it?",
                scene_path.display(),
                units.name()
            );
        }
        note(&format!(
            "reach: {} surface points within the tool's reach ({}); size {fine:.4} m there, \
             growing by {} per m to {size:.4} m",
            sizes.reach.len(),
            scene_path.display(),
            a.gradient
        ));
        sizes.fine = Some((fine, a.gradient));
    } else {
        note(&format!("size: {size:.4} m everywhere"));
    }
    let Some(output) = a.output.as_ref().filter(|_| !a.check) else {
        return Ok(MeshOutcome::Checked);
    };
    let mesh = run_gmsh(&surface_m, &sizes)?;
    let mut bytes = Vec::new();
    mesh.write_msh4_ascii(&mut bytes)?;
    crate::fsio::write_atomic(output, &bytes, &[&a.surface])?;
    let volume_m3 = (0..mesh.tets.len()).map(|t| mesh.signed_volume(t)).sum();
    Ok(MeshOutcome::Meshed {
        output: output.clone(),
        mesh,
        volume_m3,
        surface_volume_m3: volume,
        seconds: t0.elapsed().as_secs_f64(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn units_are_guessed_from_an_organs_size() {
        assert_eq!(guess_units(0.14), Ok(Units::M));
        assert_eq!(guess_units(14.0), Ok(Units::Cm));
        assert_eq!(guess_units(140.0), Ok(Units::Mm));
        // Between the ranges (1 m or 1 mm?) and outside them: refused.
        assert!(
            guess_units(1.0)
                .unwrap_err()
                .contains("no unit makes that an organ's")
        );
        let e = resolve_units(None, 1.0, "a.msh", "--units").unwrap_err();
        assert!(e.to_string().starts_with("a.msh: ") && e.to_string().ends_with("set --units"));
        let (u, note) = resolve_units(None, 140.0, "a.msh", "--units").unwrap();
        assert_eq!(u, Units::Mm);
        assert!(note.unwrap().contains("units: mm (guessed"));
        assert_eq!(
            resolve_units(Some(Units::M), 1.0, "a", "--units").unwrap(),
            (Units::M, None)
        );
        assert_eq!("cm".parse::<Units>(), Ok(Units::Cm));
        assert!("inch".parse::<Units>().is_err());
        assert!(guess_units(5000.0).is_err());
        assert!(guess_units(0.001).is_err());
    }

    #[test]
    fn compact_drops_unused_nodes_keeping_the_order() {
        let m = TetMesh {
            nodes: vec![
                [9.0; 3],
                [0.0; 3],
                [1.0, 0.0, 0.0],
                [0.0, 1.0, 0.0],
                [0.0, 0.0, 1.0],
            ],
            tets: vec![[1, 2, 3, 4]],
        };
        let c = compact(m);
        assert_eq!(c.nodes.len(), 4);
        assert_eq!(c.tets, vec![[0, 1, 2, 3]]);
        assert_eq!(c.nodes[0], [0.0; 3]);
    }
}
