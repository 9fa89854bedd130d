//! One mesh level of the experiment: the prescribed platen displacements, the linear or
//! neo-Hookean solve at every strain, the markers' displacements and the platen force, on the
//! whole specimen or on its symmetric part.
//!
//! **The symmetric part.** A box or a cylinder between two platens of the same kind is
//! symmetric under the mirrors across its two lateral mid-planes (through the compression
//! axis) and, once the rigid translation is taken out, across its axial mid-plane. Write the
//! whole specimen's travel `t` (the moving face's displacement `d t` along the axis, `d` = +1
//! when the min face moves, -1 when the max face does; the held face's 0) as the symmetric
//! loading (the max face at `-t/2`, the min face at `+t/2`) plus the rigid translation
//! `d t/2`. A rigid translation changes no deformation gradient (`F = I + grad u`, and the
//! gradient of a constant is zero), so with the neo-Hookean energy (which depends on `F`
//! only) and the linear one alike, the whole specimen's equilibrium is the symmetric
//! loading's plus `d t/2` along the axis. The symmetric loading's equilibrium is mirror
//! symmetric (taking the one equilibrium reached from rest: no buckling), so the displacement
//! normal to each symmetry plane vanishes there: the part `x_k >= c_k` with rollers on its
//! three plane faces (the normal component held, the others free), its platen face at `-t/2`
//! (bonded: the lateral components held as well), is the whole problem. A marker at `p` is
//! displaced as its mirror image in the part, with the reflected components' signs flipped,
//! plus the translation; the platen force is four times the part's (the part's platen face is
//! a quarter of the whole face). The part has no rigid motion left once the rollers hold it,
//! so the frictionless platens' extra supports of the whole specimen are not needed.

use super::geometry::reflect;
use super::{End, MARKER_TOLERANCE, Platens, SpecimenConfig, markers};
use crate::display::law::DisplayLaw;
use anyhow::{Context, Result, bail};
use fem::compliance::solve_prescribed;
use fem::elasticity::Material;
use fem::elasticity::quadratic::QuadraticBody;
use fem::hyperelastic::{HyperelasticBody, NewtonOptions, Prescribed, solve_path};
use fem::mesh::TetMesh;

/// The mesh solved on and what it represents.
pub struct Problem {
    /// The mesh, metres.
    pub mesh: TetMesh,
    /// `Some(centre)`: the mesh is the part `x_k >= centre_k` of a mirror-symmetric
    /// specimen; `None`: the whole specimen.
    pub centre: Option<[f64; 3]>,
    /// The specimen's length along the axis, metres.
    pub length: f64,
}

/// One level's answer.
pub struct Solved {
    /// Per strain (in the order given) the markers' displacements, metres.
    pub displacements: Vec<Vec<[f64; 3]>>,
    /// Per strain the moving platen's force along its travel, N (positive in compression).
    pub forces: Vec<f64>,
    /// Nodes of the 10-node mesh solved on.
    pub nodes: usize,
}

/// Nodes of `positions` at `x_axis = at` (within 1e-9 of the length `length`).
fn on_plane(positions: &[[f64; 3]], axis: usize, at: f64, length: f64) -> Vec<usize> {
    let tol = 1e-9 * length;
    (0..positions.len())
        .filter(|&i| (positions[i][axis] - at).abs() <= tol)
        .collect()
}

/// The part's supports for the symmetric loading of travel `travel` (m): rollers on the three
/// symmetry planes, the platen face (the part's max face along the axis) at `-travel / 2`,
/// laterally held when bonded; returns them and the platen face's nodes.
fn part_supports(
    positions: &[[f64; 3]],
    config: &SpecimenConfig,
    centre: [f64; 3],
    length: f64,
    travel: f64,
) -> Result<(Prescribed, Vec<usize>)> {
    let a = config.axis.index();
    let top = centre[a] + 0.5 * length;
    let mut p = Prescribed::none(positions.len());
    for (k, &c) in centre.iter().enumerate() {
        for n in on_plane(positions, k, c, length) {
            p.set(n, k, 0.0)?;
        }
    }
    let platen = on_plane(positions, a, top, length);
    if platen.len() < 3 {
        bail!(
            "the specimen's part has {} nodes on its platen face",
            platen.len()
        );
    }
    for &n in &platen {
        p.set(n, a, -0.5 * travel)?;
        if config.platens == Platens::Bonded {
            p.set(n, (a + 1) % 3, 0.0)?;
            p.set(n, (a + 2) % 3, 0.0)?;
        }
    }
    Ok((p, platen))
}

/// Solves `problem` at every strain of `config` for the markers `points` (metres, in the
/// whole specimen): `Linear` once for a unit travel and scaled; `Large` along one
/// continuation path from rest through the strains in increasing order. The whole specimen
/// is held by [`super::platens`], the part by rollers and its platen face. `outside` makes
/// the error for the marker of that index when it lies outside the specimen.
pub fn solve(
    problem: &Problem,
    config: &SpecimenConfig,
    points: &[[f64; 3]],
    outside: &dyn Fn(usize) -> anyhow::Error,
) -> Result<Solved> {
    let material = Material::new(config.young_pa, config.poisson)
        .context("--young/--poisson: the material")?;
    let a = config.axis.index();
    let direction = match config.moving {
        End::Min => 1.0,
        End::Max => -1.0,
    };
    // Points located in the mesh (their mirror images in the part) and the signs back.
    let (located_at, signs): (Vec<[f64; 3]>, Vec<[f64; 3]>) = match problem.centre {
        Some(c) => points.iter().map(|&p| reflect(p, c)).unzip(),
        None => (points.to_vec(), vec![[1.0; 3]; points.len()]),
    };
    let located = markers::locate(&problem.mesh, &located_at, MARKER_TOLERANCE).map_err(outside)?;
    let supports = |positions: &[[f64; 3]], travel: f64| match problem.centre {
        Some(c) => part_supports(positions, config, c, problem.length, travel),
        None => super::platens(positions, config, travel),
    };
    // Force along the moving platen's travel from the reaction sum on the supported face, and
    // the markers' displacements from the mesh's field.
    let force = |reaction: f64| match problem.centre {
        Some(_) => -4.0 * reaction,
        None => direction * reaction,
    };
    let shift = |travel: f64| match problem.centre {
        Some(_) => direction * 0.5 * travel,
        None => 0.0,
    };
    let field = |body: &QuadraticBody, u: &[f64], travel: f64| {
        located
            .iter()
            .zip(&signs)
            .map(|(at, s)| {
                let d = markers::displacement(&problem.mesh, body, u, at)?;
                let mut out: [f64; 3] = std::array::from_fn(|k| s[k] * d[k]);
                out[a] += shift(travel);
                Ok(out)
            })
            .collect::<Result<Vec<[f64; 3]>>>()
    };
    let strains = &config.strains;
    let mut displacements = vec![Vec::new(); strains.len()];
    let mut forces = vec![0.0; strains.len()];
    let nodes;
    match config.model {
        super::Model::Large => {
            let volumetric = super::large_volumetric(config.poisson);
            let body = HyperelasticBody::with_volumetric(&problem.mesh, material, volumetric)?;
            nodes = body.nodes();
            // One load path through the distinct strains in increasing order: the prescribed
            // displacements are proportional to the travel, so stop k is at load factor
            // `s_k / s_max` of the largest travel's.
            let mut distinct = strains.clone();
            distinct.sort_by(f64::total_cmp);
            distinct.dedup();
            let largest = distinct.last().copied().unwrap_or(0.0);
            let (p, moving) = supports(body.positions(), largest * problem.length)?;
            let stops: Vec<f64> = distinct.iter().map(|s| s / largest).collect();
            let solutions =
                solve_path(&body, &p, &stops, &NewtonOptions::default(), &mut |_| {})
                    .with_context(|| format!("--model large on the path to strain {largest}"))?;
            for (i, &s) in strains.iter().enumerate() {
                let k = distinct.partition_point(|&x| x < s);
                let sol = &solutions[k];
                forces[i] = force(sol.reaction(moving.iter().copied(), a));
                displacements[i] = field(body.quadratic(), &sol.u, s * problem.length)?;
            }
        }
        _ => {
            let body = QuadraticBody::new(&problem.mesh, material)?;
            nodes = body.positions().len();
            let (p, moving) = supports(body.positions(), problem.length)?;
            let (u, f) = solve_prescribed(&body, &p.fixed_set(), &p.field())?;
            let reaction: f64 = moving.iter().map(|&n| f[3 * n + a]).sum();
            let unit = field(&body, &u, problem.length)?;
            // `LinearP`: P on the radial part of each scaled displacement; an identity P is
            // `None` (the linear markers bit for bit).
            let law = config.display_law.and_then(DisplayLaw::new);
            for (i, &s) in strains.iter().enumerate() {
                displacements[i] = unit
                    .iter()
                    .map(|d| {
                        let d = d.map(|x| s * x);
                        match &law {
                            Some(p) => super::linear_p::apply(p, config.axis, d),
                            None => d,
                        }
                    })
                    .collect();
                forces[i] = s * force(reaction);
            }
        }
    }
    Ok(Solved {
        displacements,
        forces,
        nodes,
    })
}
