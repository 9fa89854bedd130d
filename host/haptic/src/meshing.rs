//! From a closed surface to a tetrahedral mesh (`host mesh`): units, the size field near the
//! tool's reach, and Gmsh (its Python module, pinned to 4.15.2 and installed by
//! `scripts/test-all.sh`) as the mesher.
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
use fem::surface::TriSurface;
use std::process::Command;

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
    let out = dir.path().join("volume.msh");
    let script = dir.path().join("mesh_surface.py");
    let job = dir.path().join("job.json");
    std::fs::write(&stl, surface.to_stl_binary())?;
    std::fs::write(&script, SCRIPT)?;
    let (fine, gradient) = sizes.fine.unzip();
    let job_json = serde_json::json!({
        "surface": stl,
        "output": out,
        "size": sizes.size,
        "fine": fine,
        "gradient": gradient,
        "reach_points": sizes.reach,
    });
    std::fs::write(&job, job_json.to_string())?;
    let python = std::env::var("HOST_PYTHON").unwrap_or_else(|_| "python3".into());
    let status = Command::new(&python)
        .arg(&script)
        .arg(&job)
        .status()
        .with_context(|| {
            format!(
                "cannot run {python} for Gmsh (install Python 3 and `pip install gmsh==4.15.2 \
                 numpy`; scripts/test-all.sh does)"
            )
        })?;
    if !status.success() {
        bail!(
            "Gmsh failed ({status}; its messages are above). If the module is missing: `pip \
             install gmsh==4.15.2 numpy`"
        );
    }
    let mesh = fem::mesh::read(&out).context("reading Gmsh's mesh")?;
    let mesh = compact(mesh);
    fem::mesh::validate(&mesh).context("Gmsh's mesh fails validation")?;
    Ok(mesh)
}

/// The mesh without the nodes no tetrahedron uses (Gmsh may keep some of the input
/// surface's), the others in their original order.
fn compact(mesh: TetMesh) -> TetMesh {
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
