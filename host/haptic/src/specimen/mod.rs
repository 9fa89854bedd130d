//! A compression experiment marker by marker (`host specimen`): a specimen between two
//! platens along one axis, compressed to a list of nominal strains; the predicted position of
//! every marker (a point inside the specimen, e.g. a bead seen in CT) at each strain and the
//! platen force.
//!
//! **Loading**: the face at the moving end of the axis travels towards the other, which is
//! held; nominal strain = platen travel / specimen length along the axis. `Bonded` platens hold
//! both faces' lateral motion (all three components prescribed). `Frictionless` platens
//! prescribe only the axial component on both faces and leave them free to slide; on the
//! whole specimen the rigid lateral motions are removed by holding the held face's node
//! nearest its centre laterally and, in the second lateral direction, a second node of the
//! held face on the same line through that centre along the first lateral direction. These
//! two supports carry no load when the deformation is symmetric about the centre (a
//! homogeneous field has zero lateral displacement there), so the lateral displacement is
//! measured from the held face's centre. On the symmetric eighth the rollers of its symmetry
//! planes remove those motions (`solve.rs`).
//!
//! **Models**, all on the 10-node tetrahedra of
//! [`QuadraticBody`](fem::elasticity::quadratic::QuadraticBody) (the mesh's vertices and edge
//! midpoints, 4-point Gauss rule) with the same prescribed displacements:
//! - `Linear`: the linear elasticity of the paper (section 3, eq. 1: `K u = f`) with the
//!   volumetric term at the quadrature points; one solve for a unit travel, scaled to each
//!   strain (the response is linear in the travel).
//! - `LinearP`: `Linear` with the display law P on each marker's radial displacement
//!   ([`linear_p`]: the paper's eq. 4 with the compression axis as the constraint).
//! - `Large`: the compressible neo-Hookean reference [`fem::hyperelastic`] with the same Lamé
//!   parameters, solved along one continuation path from rest through the strains in
//!   increasing order ([`fem::hyperelastic::solve_path`]); the volumetric energy on the
//!   element mean ([`fem::hyperelastic::Volumetric::ElementMean`]) when `nu > 0.45` (the
//!   pointwise integration locks, see docs/large-deformation.md), at the quadrature points
//!   otherwise.
//!
//! At `nu > 0.45` the two models therefore differ in their volumetric integration as well as
//! in their kinematics; docs/specimen.md measures both parts.
//!
//! **Markers** are displaced by the quadratic shape functions of the element that contains
//! them ([`markers::displacement`]); [`measured`] compares them with measured positions and
//! [`plot`] draws both on a slice.
//!
//! **Symmetry**: a box or a cylinder is solved on the part cut by its three symmetry planes
//! (an eighth; [`geometry`], the reason it is exact in `solve.rs`) unless `symmetry` is off,
//! when the whole specimen is solved on that part's mirror image (the same resolution).
//!
//! **Mesh convergence**: without a fixed level a box or a cylinder is meshed at a sequence of
//! levels, `n` cells (or elements of size 1/n) along the part's longest side,
//! `n = 2, 3, 4, 6, 9, 13` (`n_{k+1} = floor(1.5 n_k)`), solved with the model asked for, until
//! the largest change of a marker's displacement at the largest strain between two successive
//! levels is at most the tolerance (default [`DEFAULT_TOLERANCE`] of the platen travel at the
//! largest strain); the last level's answer is reported with the series ([`Convergence`]).

pub mod geometry;
pub mod linear_p;
pub mod markers;
pub mod measured;
pub mod plot;
mod solve;

use crate::units::Units;
use anyhow::{Context, Result, bail};
use bank_format::TissueLaw;
use fem::elasticity::Material;
use fem::hyperelastic::{Prescribed, Volumetric};
use serde::Serialize;
use solve::Problem;
use std::path::PathBuf;
use std::time::Instant;

/// Poisson's ratio above which the `Large` model integrates the volumetric energy on the
/// element mean.
pub const ELEMENT_MEAN_ABOVE_NU: f64 = 0.45;

/// The `Large` model's volumetric integration for Poisson's ratio `nu`: the element mean above
/// [`ELEMENT_MEAN_ABOVE_NU`], the quadrature points otherwise.
pub fn large_volumetric(nu: f64) -> Volumetric {
    if nu > ELEMENT_MEAN_ABOVE_NU {
        Volumetric::ElementMean
    } else {
        Volumetric::Pointwise
    }
}

/// Nodes of a mesh file within this fraction of its length along the axis from its min (max)
/// coordinate there lie on the min (max) platen face.
pub const PLATEN_TOLERANCE: f64 = 1e-6;

/// How far below zero a marker's smallest barycentric coordinate in its element may be (round
/// off of a marker written on the specimen's surface) before it counts as outside.
pub const MARKER_TOLERANCE: f64 = 1e-9;

/// Largest marker change between two mesh levels, as a fraction of the platen travel at the
/// largest strain, below which the markers count as converged when no tolerance is given.
pub const DEFAULT_TOLERANCE: f64 = 0.01;

/// The finest level of the convergence series: cells (or elements) along the part's longest
/// side.
pub const FINEST_LEVEL: usize = 13;

/// The specimen's shape, in the configuration's units.
#[derive(Debug, Clone, PartialEq)]
pub enum Geometry {
    /// The box `[lo, hi]`, meshed structurally ([`geometry::box_part`]).
    Box {
        /// Smallest corner.
        lo: [f64; 3],
        /// Largest corner.
        hi: [f64; 3],
    },
    /// A tetrahedral mesh file (any format of [`fem::mesh::read`]), solved whole at its own
    /// resolution (no convergence series).
    Mesh {
        /// The file.
        path: PathBuf,
        /// Guess the file's units from its size ([`crate::meshing::resolve_units`]) instead
        /// of the configuration's; the guessed units then apply to the markers and the output.
        guess_units: bool,
    },
    /// A cylinder of radius and height whose axis is the compression axis through the origin,
    /// base at 0 and top at the height, meshed by Gmsh ([`geometry::cylinder_part`]).
    Cylinder {
        /// Radius.
        radius: f64,
        /// Height.
        height: f64,
    },
}

/// The compression axis.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Axis {
    /// x.
    X,
    /// y.
    Y,
    /// z.
    Z,
}

impl Axis {
    /// 0, 1 or 2.
    pub fn index(self) -> usize {
        match self {
            Axis::X => 0,
            Axis::Y => 1,
            Axis::Z => 2,
        }
    }
}

/// Which end of the axis moves.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum End {
    /// The face at the smallest coordinate moves up the axis.
    Min,
    /// The face at the largest coordinate moves down the axis.
    Max,
}

/// How the platens hold the faces they touch.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Platens {
    /// No lateral motion of either face.
    Bonded,
    /// Both faces slide freely (axial displacement only prescribed).
    Frictionless,
}

/// The material model.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Model {
    /// Linear elasticity on 10-node tetrahedra.
    Linear,
    /// The paper's model with a display law P on the markers' radial displacement.
    LinearP,
    /// The neo-Hookean large-deformation reference.
    Large,
}

/// What `host specimen` computes: its options.
#[derive(Debug, Clone, PartialEq)]
pub struct SpecimenConfig {
    /// The specimen, in `units`.
    pub geometry: Geometry,
    /// Units of the geometry, the markers and the output positions.
    pub units: Units,
    /// A fixed mesh level instead of the convergence series: cells of the structured box mesh
    /// along the longest side of the part solved (half the box's longest side; the other sides
    /// get the nearest count of cells of the same size, at least one), or for a cylinder
    /// elements of size (part's longest side) / cells.
    pub cells: Option<usize>,
    /// The convergence series' tolerance on the largest marker change, in `units`; `None`:
    /// [`DEFAULT_TOLERANCE`] of the platen travel at the largest strain.
    pub tolerance: Option<f64>,
    /// Solve a box or a cylinder on its symmetric part (an eighth); `false` solves the whole
    /// specimen (for checking: same answer).
    pub symmetry: bool,
    /// Young's modulus, Pa.
    pub young_pa: f64,
    /// Poisson's ratio.
    pub poisson: f64,
    /// Compression axis.
    pub axis: Axis,
    /// The moving face.
    pub moving: End,
    /// Platen contact.
    pub platens: Platens,
    /// Nominal strains (fractions in (0, 1)).
    pub strains: Vec<f64>,
    /// Markers CSV (header `x,y,z`, in `units`).
    pub markers: PathBuf,
    /// The material model.
    pub model: Model,
    /// The display law P (m -> m) of `LinearP`; required by it, refused with another model.
    pub display_law: Option<TissueLaw>,
}

/// One strain level.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Level {
    /// Nominal strain (platen travel / length).
    pub strain: f64,
    /// Predicted marker positions, in the markers' units, in the file's order.
    pub markers: Vec<[f64; 3]>,
    /// Force of the moving platen on the specimen along its travel, N (positive in
    /// compression).
    pub platen_force_n: f64,
}

/// What `host specimen` reports.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SpecimenReport {
    /// One entry per strain, in the order given.
    pub levels: Vec<Level>,
    /// The model.
    pub model: Model,
    /// The volumetric integration of the `large` model (`pointwise` or `element-mean`), or
    /// `pointwise` for the linear one.
    pub volumetric: &'static str,
    /// Units of the positions.
    pub units: &'static str,
    /// Specimen length along the axis, in `units`.
    pub length: f64,
    /// Whether the symmetric part (an eighth) was solved rather than the whole specimen.
    pub symmetry: bool,
    /// The mesh level reported: cells along the part's longest side (`None` for a mesh file).
    pub cells: Option<usize>,
    /// Nodes of the 10-node mesh solved on.
    pub nodes: usize,
    /// The mesh levels solved and the markers' change between them.
    pub convergence: Convergence,
    /// Wall time of the meshing and solves of every level, s.
    pub solve_seconds: f64,
}

/// The mesh levels solved, at the largest strain.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Convergence {
    /// What is compared.
    pub criterion: &'static str,
    /// The tolerance on the largest marker change, in the report's units (`None` for a fixed
    /// level).
    pub tolerance: Option<f64>,
    /// Whether the last level's change is within the tolerance (`false` for a fixed level).
    pub converged: bool,
    /// The levels, coarsest first.
    pub levels: Vec<MeshLevel>,
}

/// One mesh level of the series.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MeshLevel {
    /// Cells (or elements) along the part's longest side (`None` for a mesh file).
    pub cells: Option<usize>,
    /// Nodes of the 10-node mesh solved on.
    pub nodes: usize,
    /// Largest distance between a marker's displacement here and at the previous level, at
    /// the largest strain, in the report's units (`None` at the first level).
    pub change: Option<f64>,
    /// Wall time of this level, s.
    pub seconds: f64,
}

/// Parses a comma-separated list of finite numbers for the option `option` (named in errors
/// with the item's position).
pub fn parse_numbers(option: &str, text: &str) -> Result<Vec<f64>> {
    text.split(',')
        .enumerate()
        .map(|(i, item)| {
            let item = item.trim();
            match item.parse::<f64>() {
                Ok(v) if v.is_finite() => Ok(v),
                _ => bail!(
                    "{option} {text:?}: item {} ({item:?}) is not a finite number",
                    i + 1
                ),
            }
        })
        .collect()
}

/// Checks a strain list: at least one, each in (0, 1) (a travel of the whole length is not a
/// compression the specimen survives); errors name the item.
pub fn check_strains(strains: &[f64]) -> Result<()> {
    if strains.is_empty() {
        bail!("--strain: no strain given");
    }
    for (i, &s) in strains.iter().enumerate() {
        if !(s > 0.0 && s < 1.0) {
            bail!(
                "--strain: item {} is {s}: a nominal strain is a fraction strictly between 0 \
                 and 1 (0.1 for 10 %)",
                i + 1
            );
        }
    }
    Ok(())
}

/// The box's corners in metres, checked.
fn box_metres(lo: [f64; 3], hi: [f64; 3], units: Units) -> Result<([f64; 3], [f64; 3])> {
    let size: [f64; 3] = std::array::from_fn(|k| hi[k] - lo[k]);
    if let Some(k) = (0..3).find(|&k| !(size[k] > 0.0 && size[k].is_finite())) {
        bail!(
            "--box: the {} extent is {} {} (max {} - min {}): it must be positive",
            ["x", "y", "z"][k],
            size[k],
            units.name(),
            hi[k],
            lo[k]
        );
    }
    let s = units.to_metres();
    Ok((lo.map(|x| x * s), hi.map(|x| x * s)))
}

/// The problem at mesh level `cells` of a box or a cylinder (metres).
fn level_problem(config: &SpecimenConfig, cells: usize) -> Result<Problem> {
    let a = config.axis.index();
    let s = config.units.to_metres();
    let (part, centre, length) = match &config.geometry {
        Geometry::Box { lo, hi } => {
            let (lo, hi) = box_metres(*lo, *hi, config.units)?;
            let centre = std::array::from_fn(|k| 0.5 * (lo[k] + hi[k]));
            (geometry::box_part(lo, hi, cells).0, centre, hi[a] - lo[a])
        }
        Geometry::Cylinder { radius, height } => {
            if !(*radius > 0.0 && radius.is_finite() && *height > 0.0 && height.is_finite()) {
                bail!(
                    "--cylinder: radius {radius} and height {height} {}: both must be positive",
                    config.units.name()
                );
            }
            let (r, h) = (radius * s, height * s);
            let size = r.max(0.5 * h) / cells as f64;
            let mut centre = [0.0; 3];
            centre[a] = 0.5 * h;
            (geometry::cylinder_part(r, h, a, size)?, centre, h)
        }
        Geometry::Mesh { path, .. } => {
            bail!("--mesh {}: a mesh file has no mesh levels", path.display())
        }
    };
    Ok(if config.symmetry {
        Problem {
            mesh: part,
            centre: Some(centre),
            length,
        }
    } else {
        Problem {
            mesh: geometry::whole(&part, centre),
            centre: None,
            length,
        }
    })
}

/// A marker outside the specimen, named by its file line.
fn outside(
    config: &SpecimenConfig,
    file: &markers::MarkerFile,
    units: Units,
    i: usize,
) -> anyhow::Error {
    let p = file.points[i];
    anyhow::anyhow!(
        "{}: line {}: marker ({}, {}, {}) {} lies outside the specimen",
        config.markers.display(),
        file.lines[i],
        p[0],
        p[1],
        p[2],
        units.name()
    )
}

/// Largest distance between two lists of displacements.
fn largest_change(a: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (0..3).map(|k| (x[k] - y[k]).powi(2)).sum::<f64>().sqrt())
        .fold(0.0, f64::max)
}

/// Runs the experiment ([`run_with_progress`] without progress lines).
pub fn run(config: &SpecimenConfig) -> Result<SpecimenReport> {
    run_with_progress(config, &mut |_| {})
}

/// Runs the experiment: reads the markers, meshes the specimen (a mesh file as it is; a box or
/// a cylinder at the fixed level or along the convergence series), solves the model at each
/// strain (a marker outside the specimen is refused with its line) and reports the last
/// level. `note` hears one line per level solved (progress).
pub fn run_with_progress(
    config: &SpecimenConfig,
    note: &mut dyn FnMut(&str),
) -> Result<SpecimenReport> {
    match (config.model, config.display_law) {
        (Model::LinearP, None) => bail!(
            "--model linear-p needs a display law P: give --scene FILE (its [display_law]) or \
             --display-law FILE"
        ),
        (Model::Linear | Model::Large, Some(_)) => bail!(
            "a display law P is given but the model is {}: P applies to --model linear-p only",
            if config.model == Model::Large {
                "large"
            } else {
                "linear"
            }
        ),
        _ => {}
    }
    Material::new(config.young_pa, config.poisson).context("--young/--poisson: the material")?;
    check_strains(&config.strains)?;
    if let Some(t) = config.tolerance
        && !(t > 0.0 && t.is_finite())
    {
        bail!("--tolerance {t}: must be a positive length in --units");
    }
    if config.cells == Some(0) {
        bail!("--cells: at least 1 cell along the part's longest side");
    }
    let is_mesh = matches!(config.geometry, Geometry::Mesh { .. });
    if is_mesh && (config.cells.is_some() || config.tolerance.is_some()) {
        bail!(
            "--cells and --tolerance set the mesh of a box or a cylinder; a --mesh file is \
             solved at its own resolution"
        );
    }
    if config.cells.is_some() && config.tolerance.is_some() {
        bail!("--tolerance: not with --cells, which fixes one mesh level (no convergence series)");
    }
    let file = markers::read(&config.markers)?;
    let start = Instant::now();
    let largest = config.strains.iter().copied().fold(0.0, f64::max);
    let at_largest = config
        .strains
        .iter()
        .position(|&s| s == largest)
        .unwrap_or(0);
    // A mesh file: one level, solved whole.
    let (mut units, fixed) = (config.units, config.cells);
    let mut file_problem = None;
    if let Geometry::Mesh { path, guess_units } = &config.geometry {
        let given = (!guess_units).then_some(config.units);
        let (mesh, _, u) = crate::meshing::load_mesh_in_units(path, given, "--units")?;
        units = u;
        let (lo, hi) = mesh.bounding_box();
        let a = config.axis.index();
        file_problem = Some(Problem {
            length: hi[a] - lo[a],
            mesh,
            centre: None,
        });
    }
    let scale = units.to_metres();
    let points: Vec<[f64; 3]> = file.points.iter().map(|p| p.map(|x| x * scale)).collect();
    let mut levels: Vec<MeshLevel> = Vec::new();
    let mut last: Option<(solve::Solved, f64)> = None;
    let mut tolerance = None;
    let mut converged = false;
    let mut cells = fixed.unwrap_or(2);
    loop {
        let t = Instant::now();
        let problem = match file_problem.take() {
            Some(p) => p,
            None => level_problem(config, cells)?,
        };
        let length = problem.length;
        let solved = solve::solve(&problem, config, &points, &|i| {
            outside(config, &file, units, i)
        })?;
        let change = last.as_ref().map(|(prev, _)| {
            largest_change(
                &prev.displacements[at_largest],
                &solved.displacements[at_largest],
            ) / scale
        });
        let tol = config
            .tolerance
            .unwrap_or(DEFAULT_TOLERANCE * largest * length / scale);
        levels.push(MeshLevel {
            cells: (!is_mesh).then_some(cells),
            nodes: solved.nodes,
            change,
            seconds: t.elapsed().as_secs_f64(),
        });
        note(&format!(
            "level {}: {} nodes, {:.1} s{}",
            if is_mesh {
                "file".to_string()
            } else {
                format!("{cells} cells")
            },
            solved.nodes,
            t.elapsed().as_secs_f64(),
            change.map_or(String::new(), |c| format!(
                ", largest marker change {c:.4} {} (tolerance {tol:.4})",
                units.name()
            ))
        ));
        last = Some((solved, length));
        if is_mesh || fixed.is_some() {
            break;
        }
        tolerance = Some(tol);
        if change.is_some_and(|c| c <= tol) {
            converged = true;
            break;
        }
        if cells >= FINEST_LEVEL {
            note(&format!(
                "not converged at the finest level ({cells} cells): the markers' change is above \
                 the tolerance"
            ));
            break;
        }
        cells = cells * 3 / 2;
    }
    let (solved, length) = last.expect("at least one level is solved");
    let level_out = config
        .strains
        .iter()
        .enumerate()
        .map(|(i, &strain)| Level {
            strain,
            markers: points
                .iter()
                .zip(&solved.displacements[i])
                .map(|(p, d)| std::array::from_fn(|k| (p[k] + d[k]) / scale))
                .collect(),
            platen_force_n: solved.forces[i],
        })
        .collect();
    let volumetric = match (config.model, large_volumetric(config.poisson)) {
        (Model::Large, Volumetric::ElementMean) => "element-mean",
        _ => "pointwise",
    };
    Ok(SpecimenReport {
        levels: level_out,
        model: config.model,
        volumetric,
        units: units.name(),
        length: length / scale,
        symmetry: config.symmetry && !is_mesh,
        cells: levels.last().and_then(|l| l.cells),
        nodes: solved.nodes,
        convergence: Convergence {
            criterion: "largest distance between a marker's displacements at two successive \
                        mesh levels, at the largest strain",
            tolerance,
            converged,
            levels,
        },
        solve_seconds: start.elapsed().as_secs_f64(),
    })
}

/// The platens' prescribed displacements for an axial travel `travel` (m, positive) and the
/// moving face's nodes.
fn platens(
    positions: &[[f64; 3]],
    config: &SpecimenConfig,
    travel: f64,
) -> Result<(Prescribed, Vec<usize>)> {
    let a = config.axis.index();
    let (lo, hi) = positions
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
            (lo.min(p[a]), hi.max(p[a]))
        });
    let tol = PLATEN_TOLERANCE * (hi - lo);
    let (moving_at, held_at, direction) = match config.moving {
        End::Min => (lo, hi, 1.0),
        End::Max => (hi, lo, -1.0),
    };
    let on = |at: f64| -> Vec<usize> {
        (0..positions.len())
            .filter(|&i| (positions[i][a] - at).abs() <= tol)
            .collect()
    };
    let (moving, held) = (on(moving_at), on(held_at));
    for (face, nodes, at) in [("moving", &moving, moving_at), ("held", &held, held_at)] {
        if nodes.len() < 3 {
            bail!(
                "the {face} platen face (the nodes at {} = {at} m, within {PLATEN_TOLERANCE} of \
                 the length) has {} node(s): a platen needs at least 3",
                ["x", "y", "z"][a],
                nodes.len()
            );
        }
    }
    let mut p = Prescribed::none(positions.len());
    let lateral = [(a + 1) % 3, (a + 2) % 3];
    for &n in &held {
        p.set(n, a, 0.0)?;
    }
    for &n in &moving {
        p.set(n, a, direction * travel)?;
    }
    match config.platens {
        Platens::Bonded => {
            for &n in held.iter().chain(&moving) {
                for &c in &lateral {
                    p.set(n, c, 0.0)?;
                }
            }
        }
        Platens::Frictionless => {
            let centre: [f64; 2] = lateral
                .map(|c| held.iter().map(|&n| positions[n][c]).sum::<f64>() / held.len() as f64);
            let off = |n: usize, k: usize| positions[n][lateral[k]] - centre[k];
            let Some(&pin) = held.iter().min_by(|&&m, &&n| {
                (off(m, 0).hypot(off(m, 1))).total_cmp(&off(n, 0).hypot(off(n, 1)))
            }) else {
                bail!("the held face has no node");
            };
            let width = held.iter().map(|&n| off(n, 0).abs()).fold(0.0, f64::max);
            let Some(&roller) = held
                .iter()
                .filter(|&&n| (off(n, 1) - off(pin, 1)).abs() <= 1e-9 * width)
                .max_by(|&&m, &&n| off(m, 0).total_cmp(&off(n, 0)))
                .filter(|&&n| n != pin)
            else {
                bail!(
                    "the held face has no node on the line through its centre node along the \
                     first lateral axis: its rotation about the compression axis cannot be held"
                );
            };
            p.set(pin, lateral[0], 0.0)?;
            p.set(pin, lateral[1], 0.0)?;
            p.set(roller, lateral[1], 0.0)?;
        }
    }
    Ok((p, moving))
}
