//! `host mesh`: a closed surface (STL, OBJ, PLY, VTK polydata, VTP) to a tetrahedral mesh for the
//! FEM, through Gmsh ([`haptic::meshing::mesh_surface`]: units, surface checks and opt-in
//! repairs, a size field fine where the scene's tool reaches, an atomic write); prints its
//! steps, the mesh and its quality.

use anyhow::{Result, bail};
use fem::mesh::quality::{QualitySummary, SLIVER_DIHEDRAL_DEG};
use haptic::meshing::{self, MeshConfig, MeshOutcome};
use std::path::PathBuf;

/// Arguments of `host mesh`.
#[derive(clap::Args, Debug)]
#[command(
    after_help = "The surface is checked before meshing, each problem an error naming \
the faces or vertices (0-based, file order), counts and a location: duplicate vertices, \
degenerate faces, non-manifold edges and vertices, several shells, holes, inconsistent \
orientation, self-intersections. Faces that all point inward are flipped (and said). Gmsh: the \
pinned Python module gmsh==4.15.2 (scripts/test-all.sh installs it)."
)]
pub struct Args {
    /// Closed triangulated surface: .stl (ASCII or binary), .obj, .ply, .vtk (POLYDATA), .vtp.
    /// With --check also a tetrahedral mesh (.msh versions 1, 2 and 4.1, Medit .mesh, .vtu,
    /// .vtk UNSTRUCTURED_GRID): read in its units, validated, its quality printed.
    surface: PathBuf,
    /// Output tetrahedral mesh (.msh, Gmsh 4.1 ASCII, metres), written atomically.
    #[arg(short, long, required_unless_present = "check")]
    output: Option<PathBuf>,
    /// Units of the surface's coordinates; default: guessed from the bounding box (an organ is
    /// 4 to 40 cm across) and printed, refused when no unit fits.
    #[arg(long, value_enum)]
    units: Option<crate::cmd::units_arg::UnitsArg>,
    /// Element size in metres (away from the reach with --refine-near); default: the largest
    /// side of the bounding box / 15.
    #[arg(long, value_name = "M")]
    size: Option<f64>,
    /// A scene whose tool reach (trocar, joint ranges, tip radius + reach margin) gets the
    /// fine size --fine, growing by --gradient per metre away from it.
    #[arg(long, value_name = "SCENE")]
    refine_near: Option<PathBuf>,
    /// Element size where the tool reaches, metres (with --refine-near); default --size / 3.
    #[arg(long, value_name = "M")]
    fine: Option<f64>,
    /// Growth of the element size per metre of distance from the reach (with --refine-near).
    #[arg(long, default_value_t = 0.3)]
    gradient: f64,
    /// Safe repairs, each reported: merge duplicate vertices (--merge-tolerance), drop faces
    /// that use a vertex twice, make the orientation consistent, fill holes of at most
    /// --fill-holes edges.
    #[arg(long)]
    repair: bool,
    /// Largest hole --repair fills, in boundary edges (at most 1000): by the least-area
    /// triangulation of its boundary loop.
    #[arg(long, default_value_t = 32, value_name = "N")]
    fill_holes: usize,
    /// Vertices closer than this fraction of the bounding-box diagonal are duplicates.
    #[arg(long, default_value_t = 1e-7, value_name = "FRACTION")]
    merge_tolerance: f64,
    /// Keep the largest shell (by area) when the surface has several, instead of refusing.
    #[arg(long)]
    largest: bool,
    /// Check (and repair) the surface and print the units and sizes, without meshing.
    #[arg(long)]
    check: bool,
}

/// Runs the command.
pub fn run(a: Args) -> Result<()> {
    if meshing::is_volume_mesh(&a.surface) {
        if !a.check {
            bail!(
                "{}: a tetrahedral mesh, not a surface: `host mesh` meshes surfaces; check this \
                 one with --check, or give it to `host scene new --mesh` or a scene's `mesh`",
                a.surface.display()
            );
        }
        return check_volume(&a);
    }
    let config = MeshConfig {
        surface: a.surface.clone(),
        output: a.output.clone(),
        units: a.units.map(Into::into),
        size: a.size,
        refine_near: a.refine_near.clone(),
        fine: a.fine,
        gradient: a.gradient,
        repair: a.repair,
        fill_holes: a.fill_holes,
        merge_tolerance: a.merge_tolerance,
        largest: a.largest,
        check: a.check,
    };
    match meshing::mesh_surface(&config, &mut |line| eprintln!("{line}"))? {
        MeshOutcome::Checked => eprintln!("--check: the surface passes; not meshed"),
        MeshOutcome::Meshed {
            output,
            mesh,
            volume_m3,
            surface_volume_m3,
            seconds,
        } => {
            println!(
                "{}: {} nodes, {} tetrahedra, volume {:.4e} m^3 ({:+.2}% of the surface's), \
                 {seconds:.1} s",
                output.display(),
                mesh.nodes.len(),
                mesh.tets.len(),
                volume_m3,
                100.0 * (volume_m3 / surface_volume_m3 - 1.0),
            );
            print_quality(&mesh, " after Gmsh's and Netgen's optimisation");
        }
    }
    Ok(())
}

/// `--check` on a tetrahedral mesh file: what it holds, its volume and boundary, its quality;
/// slivers are a warning (the FEM takes them, with a worse conditioned stiffness).
fn check_volume(a: &Args) -> Result<()> {
    let name = a.surface.display();
    let c = meshing::check_volume(&a.surface, a.units.map(Into::into))?;
    let skipped = if c.ignored.total() > 0 {
        format!(" (skipped: {})", c.ignored)
    } else {
        String::new()
    };
    println!(
        "{name}: tetrahedral mesh, {} nodes, {} tetrahedra{skipped}; units {}; volume {:.4e} m^3 \
         ({:.1} cm^3), largest side {:.4} m; boundary closed and manifold, {} faces on {} nodes",
        c.mesh.nodes.len(),
        c.mesh.tets.len(),
        c.units.name(),
        c.volume_m3,
        c.volume_m3 * 1e6,
        haptic::units::largest_side(c.mesh.bounding_box()),
        c.boundary.0,
        c.boundary.1
    );
    if let Some(q) = print_quality(&c.mesh, "")
        && q.slivers > 0
    {
        eprintln!(
            "warning: {name}: {} slivers (worst dihedral angle {:.2} deg, tetrahedron {}); \
             remesh, or improve it with Gmsh's optimiser",
            q.slivers, q.min_dihedral_deg.0, q.min_dihedral_deg.1
        );
    }
    eprintln!("--check: the tetrahedral mesh passes");
    Ok(())
}

/// Prints the quality line of `mesh` (`after` ends its sentence), and returns the summary.
fn print_quality(mesh: &fem::mesh::TetMesh, after: &str) -> Option<QualitySummary> {
    let q = mesh.quality_summary()?;
    println!(
        "quality: worst dihedral angle {:.2} deg (tetrahedron {}), largest {:.1} deg; radius \
         ratio min {:.3} (tetrahedron {}), mean {:.3}; {} slivers (a dihedral angle below \
         {SLIVER_DIHEDRAL_DEG} deg){after}",
        q.min_dihedral_deg.0,
        q.min_dihedral_deg.1,
        q.max_dihedral_deg,
        q.min_radius_ratio.0,
        q.min_radius_ratio.1,
        q.mean_radius_ratio,
        q.slivers
    );
    Some(q)
}
