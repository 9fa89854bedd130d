//! A compression experiment marker by marker (`host specimen`): a specimen between two
//! platens along one axis, compressed to a list of nominal strains; the predicted position of
//! every marker (a point inside the specimen, e.g. a bead seen in CT) at each strain and the
//! platen force.
//!
//! **Loading**: the face at the moving end of the axis travels towards the other, which is
//! held; nominal strain = platen travel / specimen length along the axis. `Bonded` platens hold
//! both faces' lateral motion (all three components prescribed). `Frictionless` platens
//! prescribe only the axial component on both faces and leave them free to slide; the rigid
//! lateral motions are removed by holding the held face's node nearest its centre laterally
//! and, in the second lateral direction, a second node of the held face on the same line
//! through that centre along the first lateral direction. These two supports carry no load
//! when the deformation is symmetric about the centre (a homogeneous field has zero lateral
//! displacement there), so the lateral displacement is measured from the held face's centre.
//!
//! **Models**, all on the 10-node tetrahedra of [`QuadraticBody`] (the mesh's vertices and
//! edge midpoints, 4-point Gauss rule) with the same prescribed displacements:
//! - `Linear`: the linear elasticity of the paper (section 3, eq. 1: `K u = f`) with the
//!   volumetric term at the quadrature points; one solve for a unit travel, scaled to each
//!   strain (the response is linear in the travel).
//! - `LinearP`: `Linear` with the display law P on each marker's radial displacement
//!   ([`linear_p`]: the paper's eq. 4 with the compression axis as the constraint).
//! - `Large`: the compressible neo-Hookean reference [`fem::hyperelastic`] with the same Lamé
//!   parameters, solved from rest to each strain; the volumetric energy on the element mean
//!   ([`Volumetric::ElementMean`]) when `nu > 0.45` (the pointwise integration locks, see
//!   docs/large-deformation.md), at the quadrature points otherwise.
//!
//! At `nu > 0.45` the two models therefore differ in their volumetric integration as well as
//! in their kinematics; docs/specimen.md measures both parts.
//!
//! **Markers** are displaced by the quadratic shape functions of the element that contains
//! them ([`markers::displacement`]); [`measured`] compares them with measured positions and
//! [`plot`] draws both on a slice.

pub mod linear_p;
pub mod markers;
pub mod measured;
pub mod plot;

use crate::display::law::DisplayLaw;
use crate::units::Units;
use anyhow::{Context, Result, bail};
use bank_format::TissueLaw;
use fem::compliance::solve_prescribed;
use fem::elasticity::Material;
use fem::elasticity::quadratic::QuadraticBody;
use fem::hyperelastic::{HyperelasticBody, NewtonOptions, Prescribed, Volumetric, solve};
use fem::mesh::TetMesh;
use fem::mesh::structured::box_mesh;
use serde::Serialize;
use std::path::PathBuf;
use std::time::Instant;

/// Poisson's ratio above which the `Large` model integrates the volumetric energy on the
/// element mean.
pub const ELEMENT_MEAN_ABOVE_NU: f64 = 0.45;

/// How far below zero a marker's smallest barycentric coordinate in its element may be (round
/// off of a marker written on the specimen's surface) before it counts as outside.
pub const MARKER_TOLERANCE: f64 = 1e-9;

/// The specimen's shape, in the configuration's units.
#[derive(Debug, Clone, PartialEq)]
pub enum Geometry {
    /// The box `[lo, hi]`, meshed structurally ([`box_mesh`]).
    Box {
        /// Smallest corner.
        lo: [f64; 3],
        /// Largest corner.
        hi: [f64; 3],
    },
    /// A tetrahedral mesh file (not yet supported).
    Mesh(PathBuf),
    /// A cylinder of radius and height along the axis (not yet supported).
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
    /// Cells of the structured mesh along the box's longest side (the other sides get the
    /// nearest count of cells of the same size, at least one).
    pub cells: usize,
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
    /// Cells of the structured mesh along x, y and z (six tetrahedra each).
    pub cells: [usize; 3],
    /// Nodes of the 10-node mesh.
    pub nodes: usize,
    /// Wall time of the solves, s.
    pub solve_seconds: f64,
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

/// The specimen mesh in metres and its cell counts.
fn mesh(config: &SpecimenConfig) -> Result<(TetMesh, [usize; 3])> {
    let (lo, hi) = match &config.geometry {
        Geometry::Box { lo, hi } => (*lo, *hi),
        Geometry::Mesh(path) => bail!(
            "--mesh {}: not yet supported; describe the specimen with --box",
            path.display()
        ),
        Geometry::Cylinder { .. } => {
            bail!("--cylinder: not yet supported; describe the specimen with --box")
        }
    };
    let size: [f64; 3] = std::array::from_fn(|k| hi[k] - lo[k]);
    if let Some(k) = (0..3).find(|&k| !(size[k] > 0.0 && size[k].is_finite())) {
        bail!(
            "--box: the {} extent is {} {} (max {} - min {}): it must be positive",
            ["x", "y", "z"][k],
            size[k],
            config.units.name(),
            hi[k],
            lo[k]
        );
    }
    if config.cells == 0 {
        bail!("--cells: at least 1 cell along the longest side");
    }
    let longest = size.iter().copied().fold(0.0, f64::max);
    let cells = size.map(|s| ((config.cells as f64 * s / longest).round() as usize).max(1));
    let scale = config.units.to_metres();
    let mut mesh = box_mesh(size.map(|s| s * scale), cells);
    for p in &mut mesh.nodes {
        for k in 0..3 {
            p[k] += lo[k] * scale;
        }
    }
    Ok((mesh, cells))
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
    let tol = 1e-9 * (hi - lo);
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

/// Runs the experiment: meshes the box, reads and locates the markers (a marker outside the
/// specimen is refused with its line), solves the model at each strain.
pub fn run(config: &SpecimenConfig) -> Result<SpecimenReport> {
    let display_law = match (config.model, config.display_law) {
        (Model::LinearP, Some(law)) => DisplayLaw::new(law),
        (Model::LinearP, None) => bail!(
            "--model linear-p needs a display law P: give --scene FILE (its [display_law]) or \
             --display-law FILE"
        ),
        (_, None) => None,
        (model, Some(_)) => bail!(
            "a display law P is given but the model is {}: P applies to --model linear-p only",
            if model == Model::Large {
                "large"
            } else {
                "linear"
            }
        ),
    };
    let material = Material::new(config.young_pa, config.poisson)
        .context("--young/--poisson: the material")?;
    check_strains(&config.strains)?;
    let (mesh, cells) = mesh(config)?;
    let scale = config.units.to_metres();
    let file = markers::read(&config.markers)?;
    let points: Vec<[f64; 3]> = file.points.iter().map(|p| p.map(|x| x * scale)).collect();
    let located = markers::locate(&mesh, &points, MARKER_TOLERANCE).map_err(|i| {
        let p = file.points[i];
        anyhow::anyhow!(
            "{}: line {}: marker ({}, {}, {}) {} lies outside the specimen",
            config.markers.display(),
            file.lines[i],
            p[0],
            p[1],
            p[2],
            config.units.name()
        )
    })?;
    let (lo, hi) = mesh.bounding_box();
    let a = config.axis.index();
    let length = hi[a] - lo[a];
    let direction = match config.moving {
        End::Min => 1.0,
        End::Max => -1.0,
    };
    let level = |body: &QuadraticBody, strain: f64, u: &[f64], reaction: f64| {
        let markers = points
            .iter()
            .zip(&located)
            .map(|(p, at)| {
                let mut d = markers::displacement(&mesh, body, u, at)?;
                if let Some(p) = &display_law {
                    d = linear_p::apply(p, config.axis, d);
                }
                Ok(std::array::from_fn(|k| (p[k] + d[k]) / scale))
            })
            .collect::<Result<Vec<[f64; 3]>>>()?;
        Ok::<_, anyhow::Error>(Level {
            strain,
            markers,
            platen_force_n: direction * reaction,
        })
    };
    let start = Instant::now();
    let (levels, nodes, volumetric) = match config.model {
        Model::Linear | Model::LinearP => {
            let body = QuadraticBody::new(&mesh, material)?;
            let (p, moving) = platens(body.positions(), config, length)?;
            let (u, forces) = solve_prescribed(&body, &p.fixed_set(), &p.field())?;
            let reaction: f64 = moving.iter().map(|&n| forces[3 * n + a]).sum();
            let levels = config
                .strains
                .iter()
                .map(|&s| {
                    let us: Vec<f64> = u.iter().map(|x| s * x).collect();
                    level(&body, s, &us, s * reaction)
                })
                .collect::<Result<Vec<Level>>>()?;
            (levels, body.positions().len(), "pointwise")
        }
        Model::Large => {
            let (volumetric, name) = if config.poisson > ELEMENT_MEAN_ABOVE_NU {
                (Volumetric::ElementMean, "element-mean")
            } else {
                (Volumetric::Pointwise, "pointwise")
            };
            let body = HyperelasticBody::with_volumetric(&mesh, material, volumetric)?;
            let mut levels = Vec::new();
            for &s in &config.strains {
                let (p, moving) = platens(body.positions(), config, s * length)?;
                let sol = solve(&body, &p, &NewtonOptions::default(), &mut |_| {})
                    .with_context(|| format!("--model large at strain {s}"))?;
                let reaction = sol.reaction(moving.iter().copied(), a);
                levels.push(level(body.quadratic(), s, &sol.u, reaction)?);
            }
            (levels, body.nodes(), name)
        }
    };
    let solve_seconds = start.elapsed().as_secs_f64();
    Ok(SpecimenReport {
        levels,
        model: config.model,
        volumetric,
        units: config.units.name(),
        length: length / scale,
        cells,
        nodes,
        solve_seconds,
    })
}
