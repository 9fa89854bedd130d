//! `host specimen`: a compression experiment marker by marker ([`haptic::specimen`]): the
//! predicted marker positions and the platen force at each nominal strain, as text or as one
//! JSON object (`{"levels": [{"strain": S, "markers": [[x, y, z], ...], ...}, ...], ...}`).

use crate::cmd::units_arg::UnitsArg;
use anyhow::{Result, bail};
use bank_format::TissueLaw;
use haptic::fsio::write_atomic;
use haptic::scene::Scene;
use haptic::specimen::measured::{self, Comparison};
use haptic::specimen::{
    self, Axis, End, Geometry, Model, Platens, SpecimenConfig, SpecimenReport, parse_numbers,
};
use haptic::units::Units;
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
    /// The paper's model with the display law P (from --scene or --display-law) on the
    /// markers' radial displacement.
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
    /// A tetrahedral mesh of the specimen (.msh, .mesh, .vtu, .vtk), solved whole at its own
    /// resolution (no convergence series); the platen faces are its nodes at the min and max
    /// of the axis.
    #[arg(long, conflicts_with = "cylinder")]
    mesh: Option<PathBuf>,
    /// A cylinder R,H whose axis is --axis through the origin, base at 0, top at H (in
    /// --units), meshed by Gmsh.
    #[arg(long, value_name = "R,H")]
    cylinder: Option<String>,
    /// Units of the geometry, the markers and the predicted positions (m by default; with
    /// --mesh, guessed from the mesh's size when not given).
    #[arg(long, value_enum)]
    units: Option<UnitsArg>,
    /// A fixed mesh level instead of the convergence series: cells along the longest side of
    /// the part solved (the eighth: half the specimen's longest side; box: cubes of six 10-node
    /// tetrahedra, cylinder: Gmsh elements of that side / N).
    #[arg(long, value_name = "N")]
    cells: Option<usize>,
    /// The convergence series stops when the largest change of a marker's displacement at the
    /// largest strain between two successive levels is at most this (in --units); default 1 %
    /// of the platen travel at the largest strain.
    #[arg(long, value_name = "LENGTH")]
    tolerance: Option<f64>,
    /// Solve the whole box or cylinder instead of the eighth cut by its symmetry planes (the
    /// same answer, about eight times the work; for checking).
    #[arg(long)]
    no_symmetry: bool,
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
    /// Measured marker positions to compare with: one CSV, header x,y,z (in --units), one row
    /// per marker and level, level by level in the --strain order, the markers in the
    /// --markers file's order (markers x levels rows). Adds each level's RMS and largest
    /// marker error and every marker's error.
    #[arg(long)]
    measured: Option<PathBuf>,
    /// With --measured: an SVG of the predicted and measured displacements on a slice through
    /// the axis, one panel per level.
    #[arg(long, value_name = "FILE.svg", requires = "measured")]
    plot: Option<PathBuf>,
    /// The material model.
    #[arg(long, value_enum)]
    model: ModelArg,
    /// For --model linear-p: the scene whose [display_law] table is P.
    #[arg(long, conflicts_with = "display_law")]
    scene: Option<PathBuf>,
    /// For --model linear-p: a TOML file holding a [display_law] table alone (kind =
    /// "chebyshev", coeffs, domain_m: the scene's keys) as P.
    #[arg(long, value_name = "FILE")]
    display_law: Option<PathBuf>,
    /// Print one JSON object instead of the text table.
    #[arg(long)]
    json: bool,
}

/// The library's configuration of parsed arguments.
fn config(a: &Args) -> Result<SpecimenConfig> {
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
        (None, Some(path), _) => Geometry::Mesh {
            path: path.clone(),
            guess_units: a.units.is_none(),
        },
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
        units: a.units.map_or(Units::M, Units::from),
        cells: a.cells,
        tolerance: a.tolerance,
        symmetry: !a.no_symmetry,
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
        display_law: display_law(a)?,
    })
}

/// P from `--scene` (its `[display_law]`, refused when it has none) or `--display-law`.
fn display_law(a: &Args) -> Result<Option<TissueLaw>> {
    if let Some(path) = &a.scene {
        let scene = Scene::load(path)?;
        let Some(law) = scene.display_law else {
            bail!(
                "--scene {}: the scene has no [display_law] table (P); fit one with \
                 `host calibrate tissue --law P` or give --display-law FILE",
                path.display()
            );
        };
        return Ok(Some(law));
    }
    a.display_law
        .as_deref()
        .map(specimen::linear_p::read)
        .transpose()
}

/// The JSON output: the report, with the comparison when measured positions are given.
#[derive(serde::Serialize)]
struct Output<'a> {
    #[serde(flatten)]
    report: &'a SpecimenReport,
    #[serde(skip_serializing_if = "Option::is_none")]
    measured: Option<Comparison>,
}

/// Runs `host specimen`.
pub fn run(a: Args) -> Result<()> {
    let config = config(&a)?;
    // The measured file is checked before the solves, which may take minutes.
    let given = match &a.measured {
        Some(path) => {
            let points = specimen::markers::read(&config.markers)?.points;
            let m = measured::read(path, points.len(), config.strains.len())?;
            Some((path, points, m))
        }
        None => None,
    };
    let report = specimen::run_with_progress(&config, &mut |line| eprintln!("specimen: {line}"))?;
    let mut comparison = None;
    if let Some((path, points, m)) = &given {
        let c = measured::compare(&report.levels, report.units, m, config.units.to_metres());
        if let Some(out) = &a.plot {
            let svg = specimen::plot::svg(points, &report.levels, m, config.axis, report.units);
            write_atomic(out, svg.as_bytes(), &[&config.markers, path])?;
        }
        comparison = Some(c);
    }
    if a.json {
        let out = Output {
            report: &report,
            measured: comparison,
        };
        println!("{}", serde_json::to_string(&out)?);
    } else {
        print_text(&report);
        if let Some(c) = &comparison {
            print_comparison(c);
        }
    }
    Ok(())
}

fn print_comparison(c: &Comparison) {
    println!("against {}:", c.file);
    for l in &c.levels {
        println!(
            "strain {}: marker error RMS {:.6} {u}, largest {:.6} {u} (marker {}, line {})",
            l.strain,
            l.rms,
            l.max,
            l.max_marker,
            l.max_line,
            u = c.units
        );
    }
}

fn print_text(r: &SpecimenReport) {
    println!(
        "model {:?} ({} volumetric), {} nodes on the {}{}, length {} {}, solved in {:.2} s",
        r.model,
        r.volumetric,
        r.nodes,
        if r.symmetry {
            "eighth"
        } else {
            "whole specimen"
        },
        r.cells.map_or(String::new(), |c| format!(" at {c} cells")),
        r.length,
        r.units,
        r.solve_seconds
    );
    let c = &r.convergence;
    match c.tolerance {
        Some(t) => println!(
            "mesh levels ({}; tolerance {t:.4} {}): {}",
            c.criterion,
            r.units,
            if c.converged {
                "converged"
            } else {
                "NOT converged"
            }
        ),
        None => println!("mesh level fixed (no convergence series)"),
    }
    for l in &c.levels {
        println!(
            "  {:>6}  {:>7} nodes  {:>7.1} s  change {}",
            l.cells.map_or("file".to_string(), |c| format!("{c} cells")),
            l.nodes,
            l.seconds,
            l.change
                .map_or("-".to_string(), |x| format!("{x:.4} {}", r.units))
        );
    }
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
