//! `host scene new`: a complete, commented scene for a tetrahedral organ mesh.

use anyhow::{Context, Result, bail};
use haptic::scene_new::{NewScene, Support, Tissue, relative_to, scene_text};
use haptic::units::Units;
use std::path::PathBuf;

/// `host scene` subcommands.
#[derive(clap::Subcommand, Debug)]
pub enum SceneCmd {
    /// Write a scene for a mesh: the device aimed from the trocar at the organ, supports, a
    /// tissue preset; checked by loading it as any scene, ready for `host bank build` and
    /// `host demo --scene`.
    New(NewArgs),
}

/// Tissue presets.
#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub enum TissueArg {
    /// Liver parenchyma (the default scene's 3 kPa, within published ex vivo figures).
    Liver,
    /// Kidney cortex (5.25 kPa from an ex vivo swine shear-wave figure; in vivo is stiffer).
    Kidney,
    /// Brain (3 x 842 Pa, the shear parameter attributed to Miller and Chinzei 2002; the
    /// figure is not verified against the paper).
    Brain,
}

/// Arguments of `host scene new`.
#[derive(clap::Args, Debug)]
#[command(allow_negative_numbers = true)]
pub struct NewArgs {
    /// Tetrahedral mesh (.msh v1/v2/v4.1, .vtu, .vtk, .mesh): e.g. the output of `host mesh`.
    #[arg(long)]
    mesh: PathBuf,
    /// Units of the mesh's coordinates (written to the scene as mesh_units); default: guessed
    /// from the bounding box (an organ is 4 to 40 cm across) and printed, refused when no unit
    /// fits. The trocar and supports are in metres whatever the mesh's units.
    #[arg(long, value_enum)]
    units: Option<crate::cmd::units_arg::UnitsArg>,
    /// The trocar (the gimbal's fulcrum), m: `X,Y,Z`, outside the organ.
    #[arg(long, value_name = "X,Y,Z")]
    trocar: String,
    /// Hold every node at or below this height (m).
    #[arg(
        long,
        value_name = "Z",
        conflicts_with = "fix_box",
        required_unless_present = "fix_box"
    )]
    fix_below: Option<f64>,
    /// Hold the nodes in this box (m): `XMIN,YMIN,ZMIN,XMAX,YMAX,ZMAX`.
    #[arg(long, value_name = "X0,Y0,Z0,X1,Y1,Z1")]
    fix_box: Option<String>,
    /// A finer tetrahedral mesh of the same organ, in the same units (e.g. `host mesh SURFACE
    /// --refine-near <a scene of --mesh> -o fine.msh`): the scene then renders the converged
    /// force, the tool's patch compliance sampled on it with 10-node tetrahedra ([contact]
    /// model "sampled"; building its bank takes minutes). Without it: the nodal model on --mesh.
    #[arg(long, value_name = "MESH")]
    fem_mesh: Option<PathBuf>,
    /// Material preset (Young's modulus, Poisson's ratio; sources in the scene's comments).
    #[arg(long, value_enum, default_value = "liver")]
    tissue: TissueArg,
    /// Output scene file (TOML), written atomically.
    #[arg(short, long)]
    output: PathBuf,
}

/// Runs the command.
pub fn run(cmd: SceneCmd) -> Result<()> {
    match cmd {
        SceneCmd::New(a) => new(a),
    }
}

fn numbers<const N: usize>(s: &str, what: &str) -> Result<[f64; N]> {
    let v: Vec<f64> = s
        .split(',')
        .map(|t| t.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .with_context(|| format!("{what} {s:?}: expected {N} comma-separated numbers"))?;
    let arr: [f64; N] = v.try_into().map_err(|v: Vec<f64>| {
        anyhow::anyhow!("{what} {s:?}: {} numbers, expected {N}", v.len())
    })?;
    if arr.iter().any(|x| !x.is_finite()) {
        bail!("{what} {s:?}: not finite");
    }
    Ok(arr)
}

fn new(a: NewArgs) -> Result<()> {
    let (mesh, ignored, units) =
        haptic::meshing::load_mesh_in_units(&a.mesh, a.units.map(Into::into), "--units")?;
    let skipped = if ignored.total() > 0 {
        format!(" (skipped: {ignored})")
    } else {
        String::new()
    };
    eprintln!(
        "{}: {} nodes, {} tetrahedra{skipped}",
        a.mesh.display(),
        mesh.nodes.len(),
        mesh.tets.len()
    );
    if let Some(f) = &a.fem_mesh {
        check_same_organ(&mesh, f, units)?;
    }
    let trocar = numbers::<3>(&a.trocar, "--trocar")?;
    let support = match (a.fix_below, &a.fix_box) {
        (Some(z), _) => Support::Below(z),
        (None, Some(b)) => Support::Box(numbers::<6>(b, "--fix-box")?),
        (None, None) => bail!("give --fix-below or --fix-box"),
    };
    let tissue = match a.tissue {
        TissueArg::Liver => Tissue::Liver,
        TissueArg::Kidney => Tissue::Kidney,
        TissueArg::Brain => Tissue::Brain,
    };
    let dir = a
        .output
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(std::path::Path::new("."));
    let spec = NewScene {
        mesh_path: relative_to(&a.mesh, dir),
        mesh_units: units,
        trocar,
        support,
        tissue,
        fem_mesh: a.fem_mesh.as_deref().map(|f| relative_to(f, dir)),
    };
    let (text, reachable, warnings) = scene_text(&mesh, &spec, &a.output)?;
    warnings.iter().for_each(|w| eprintln!("{w}"));
    eprintln!(
        "warning: --tissue {}: {}; measure the tissue and fit the law with `host calibrate \
         tissue` before trusting the force",
        tissue.name(),
        tissue.caveat()
    );
    let mut inputs = vec![a.mesh.as_path()];
    inputs.extend(a.fem_mesh.as_deref());
    haptic::fsio::write_atomic(&a.output, text.as_bytes(), &inputs)?;
    println!(
        "{}: scene for {} ({} tissue); the tool reaches {reachable} surface nodes",
        a.output.display(),
        a.mesh.display(),
        tissue.name()
    );
    Ok(())
}

/// `--fem-mesh`: read in the mesh's units, valid, and of the same organ (its bounding box within
/// 5 % of the largest side of --mesh's).
fn check_same_organ(
    mesh: &fem::mesh::TetMesh,
    fem_mesh: &std::path::Path,
    units: Units,
) -> Result<()> {
    let (fine, _, _) = haptic::meshing::load_mesh_in_units(fem_mesh, Some(units), "--units")?;
    let ((lo, hi), (flo, fhi)) = (mesh.bounding_box(), fine.bounding_box());
    let side = haptic::units::largest_side((lo, hi));
    let off = (0..3)
        .map(|i| (lo[i] - flo[i]).abs().max((hi[i] - fhi[i]).abs()))
        .fold(0.0f64, f64::max);
    if off > 0.05 * side {
        bail!(
            "--fem-mesh {}: its bounding box [{:.4}, {:.4}, {:.4}] to [{:.4}, {:.4}, {:.4}] m is \
             {off:.4} m from --mesh's (largest side {side:.4} m): not the same organ in the same \
             units ({})",
            fem_mesh.display(),
            flo[0],
            flo[1],
            flo[2],
            fhi[0],
            fhi[1],
            fhi[2],
            units.name()
        );
    }
    eprintln!(
        "{}: {} nodes, {} tetrahedra (the FEM mesh of the sampled contact)",
        fem_mesh.display(),
        fine.nodes.len(),
        fine.tets.len()
    );
    Ok(())
}
