//! `host specimen`: a compression experiment marker by marker ([`haptic::specimen`]): the
//! predicted marker positions and the platen force at each nominal strain, as text or as one
//! JSON object (`{"levels": [{"strain": S, "markers": [[x, y, z], ...], ...}, ...], ...}`).

use crate::cmd::units_arg::UnitsArg;
use anyhow::{Result, bail};
use haptic::specimen::{
    self, Axis, End, Geometry, Model, Platens, SpecimenConfig, SpecimenReport, parse_numbers,
};
use std::path::PathBuf;

/// Compression axis.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum AxisArg {
    /// x.
    X,
    /// y.
    Y,
    /// z.
    Z,
}

/// The moving face.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum EndArg {
    /// The face at the smallest coordinate along the axis.
    Min,
    /// The face at the largest coordinate along the axis.
    Max,
}

/// Platen contact.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum PlatensArg {
    /// The faces cannot move laterally.
    Bonded,
    /// The faces slide freely.
    Frictionless,
}

/// The material model.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum ModelArg {
    /// Linear elasticity (the paper's model) on 10-node tetrahedra.
    Linear,
    /// The paper's model with a display law P (not yet supported).
    LinearP,
    /// The neo-Hookean large-deformation reference on the same elements.
    Large,
}

/// Arguments of `host specimen`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// A box specimen: XMIN,YMIN,ZMIN,XMAX,YMAX,ZMAX in --units.
    #[arg(long = "box", value_name = "XMIN,YMIN,ZMIN,XMAX,YMAX,ZMAX", conflicts_with_all = ["mesh", "cylinder"], required_unless_present_any = ["mesh", "cylinder"])]
    box_: Option<String>,
    /// A tetrahedral mesh of the specimen (not yet supported: use --box).
    #[arg(long, conflicts_with = "cylinder")]
    mesh: Option<PathBuf>,
    /// A cylinder R,H along the axis (not yet supported: use --box).
    #[arg(long, value_name = "R,H")]
    cylinder: Option<String>,
    /// Units of the geometry, the markers and the predicted positions.
    #[arg(long, value_enum, default_value = "m")]
    units: UnitsArg,
    /// Cells of the structured box mesh along its longest side (six 10-node tetrahedra each;
    /// the other sides get cells of about the same size).
    #[arg(long, default_value_t = 8)]
    cells: usize,
    /// Young's modulus of the material, Pa.
    #[arg(long)]
    young: f64,
    /// Poisson's ratio of the material.
    #[arg(long)]
    poisson: f64,
    /// Compression axis.
    #[arg(long, value_enum)]
    axis: AxisArg,
    /// The face that moves towards the other (which is held).
    #[arg(long, value_enum)]
    moving: EndArg,
    /// Bonded platens hold the faces' lateral motion, frictionless ones let them slide.
    #[arg(long, value_enum)]
    platens: PlatensArg,
    /// Nominal strains S1,S2,... (platen travel / length, fractions in (0, 1)).
    #[arg(long, value_name = "S1,S2,...")]
    strain: String,
    /// Markers CSV: a header row with columns x, y, z (in --units), one marker per row.
    #[arg(long)]
    markers: PathBuf,
    /// Measured marker positions to compare with (not yet supported).
    #[arg(long)]
    measured: Option<PathBuf>,
    /// The material model.
    #[arg(long, value_enum)]
    model: ModelArg,
    /// Print one JSON object instead of the text table.
    #[arg(long)]
    json: bool,
}

/// The library's configuration of parsed arguments.
fn config(a: &Args) -> Result<SpecimenConfig> {
    if let Some(path) = &a.measured {
        bail!(
            "--measured {}: not yet supported; compare the predicted positions (--json) with \
             the measured ones outside host",
            path.display()
        );
    }
    let geometry = match (&a.box_, &a.mesh, &a.cylinder) {
        (Some(text), _, _) => {
            let v = parse_numbers("--box", text)?;
            if v.len() != 6 {
                bail!(
                    "--box {text:?}: {} numbers given, need 6: XMIN,YMIN,ZMIN,XMAX,YMAX,ZMAX",
                    v.len()
                );
            }
            Geometry::Box {
                lo: [v[0], v[1], v[2]],
                hi: [v[3], v[4], v[5]],
            }
        }
        (None, Some(path), _) => Geometry::Mesh(path.clone()),
        (None, None, Some(text)) => {
            let v = parse_numbers("--cylinder", text)?;
            if v.len() != 2 {
                bail!(
                    "--cylinder {text:?}: {} numbers given, need 2: R,H",
                    v.len()
                );
            }
            Geometry::Cylinder {
                radius: v[0],
                height: v[1],
            }
        }
        (None, None, None) => bail!("give the specimen: --box, --mesh or --cylinder"),
    };
    Ok(SpecimenConfig {
        geometry,
        units: a.units.into(),
        cells: a.cells,
        young_pa: a.young,
        poisson: a.poisson,
        axis: match a.axis {
            AxisArg::X => Axis::X,
            AxisArg::Y => Axis::Y,
            AxisArg::Z => Axis::Z,
        },
        moving: match a.moving {
            EndArg::Min => End::Min,
            EndArg::Max => End::Max,
        },
        platens: match a.platens {
            PlatensArg::Bonded => Platens::Bonded,
            PlatensArg::Frictionless => Platens::Frictionless,
        },
        strains: parse_numbers("--strain", &a.strain)?,
        markers: a.markers.clone(),
        model: match a.model {
            ModelArg::Linear => Model::Linear,
            ModelArg::LinearP => Model::LinearP,
            ModelArg::Large => Model::Large,
        },
    })
}

/// Runs `host specimen`.
pub fn run(a: Args) -> Result<()> {
    let report = specimen::run(&config(&a)?)?;
    if a.json {
        println!("{}", serde_json::to_string(&report)?);
    } else {
        print_text(&report);
    }
    Ok(())
}

fn print_text(r: &SpecimenReport) {
    println!(
        "model {:?} ({} volumetric), {} nodes on {}x{}x{} cells, length {} {}, solved in {:.2} s",
        r.model,
        r.volumetric,
        r.nodes,
        r.cells[0],
        r.cells[1],
        r.cells[2],
        r.length,
        r.units,
        r.solve_seconds
    );
    for level in &r.levels {
        println!(
            "strain {}: platen force {:.6} N (positive in compression)",
            level.strain, level.platen_force_n
        );
        println!("  marker  x  y  z ({})", r.units);
        for (i, m) in level.markers.iter().enumerate() {
            println!("  {:>5}  {:.6}  {:.6}  {:.6}", i + 1, m[0], m[1], m[2]);
        }
    }
}
