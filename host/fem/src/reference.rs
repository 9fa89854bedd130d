//! Reference problems of the locking study, shared by `examples/punch.rs`, the tests
//! and the reports: a frictionless flat punch pressed into the top of an organ, and uniform
//! 1:8 refinement of a tetrahedral mesh.

use crate::compliance::{ComplianceError, solve_prescribed};
use crate::elasticity::quadratic::QuadraticBody;
use crate::elasticity::{FemError, FixedSet, Stiffness};
use crate::mesh::{Surface, TetMesh};
use std::collections::HashMap;

/// Height of the fixed bed above the organ's lowest point, m.
pub const PUNCH_BED_M: f64 = 0.01;
/// Punch radius (horizontal, around the organ's highest vertex), m.
pub const PUNCH_RADIUS_M: f64 = 0.01;
/// Punch indentation, m.
pub const PUNCH_DEPTH_M: f64 = 0.005;

/// The flat punch: the bed `z <= z_min + 10 mm` fixed; the boundary nodes of the upper half
/// (`z > z_mid`) within 10 mm horizontally of the highest vertex take `u_z = -5 mm`, free in
/// `x` and `y` (frictionless). The force is minus the sum of their `z` reactions.
#[derive(Debug, Clone)]
pub struct Punch {
    /// The fixed bed.
    pub bed: FixedSet,
    /// The punched nodes.
    pub contact: Vec<usize>,
}

impl Punch {
    /// The punch on the nodes of `mesh` (P1 and ANP bodies); `surface` is its boundary.
    pub fn on_vertices(mesh: &TetMesh, surface: &Surface) -> Result<Self, FemError> {
        Self::new(mesh, surface, &mesh.nodes, |_, _| None)
    }

    /// The punch on the nodes of a 10-node body built on `mesh`: the boundary triangles'
    /// vertices and edge nodes.
    pub fn on_quadratic(
        mesh: &TetMesh,
        surface: &Surface,
        body: &QuadraticBody,
    ) -> Result<Self, FemError> {
        Self::new(mesh, surface, body.positions(), |a, b| body.edge_node(a, b))
    }

    fn new(
        mesh: &TetMesh,
        surface: &Surface,
        positions: &[[f64; 3]],
        edge_node: impl Fn(usize, usize) -> Option<usize>,
    ) -> Result<Self, FemError> {
        let (lo, hi) = mesh.bounding_box();
        let mut bed = FixedSet::none(positions.len());
        for (i, p) in positions.iter().enumerate() {
            if p[2] <= lo[2] + PUNCH_BED_M {
                bed.fix_node(i)?;
            }
        }
        let mut on_surface = vec![false; positions.len()];
        for t in &surface.triangles {
            for k in 0..3 {
                on_surface[t[k]] = true;
                if let Some(m) = edge_node(t[k], t[(k + 1) % 3]) {
                    on_surface[m] = true;
                }
            }
        }
        let apex = mesh
            .nodes
            .iter()
            .copied()
            .max_by(|a, b| a[2].total_cmp(&b[2]));
        let Some(c) = apex else {
            return Err(FemError::Material(
                "the punch needs a non-empty mesh".into(),
            ));
        };
        let mid = 0.5 * (lo[2] + hi[2]);
        let contact = (0..positions.len())
            .filter(|&i| {
                let p = positions[i];
                on_surface[i] && p[2] > mid && (p[0] - c[0]).hypot(p[1] - c[1]) <= PUNCH_RADIUS_M
            })
            .collect();
        Ok(Self { bed, contact })
    }

    /// The punch force (N) on `body`, whose nodes must be the ones this punch was built on.
    pub fn force(&self, body: &impl Stiffness) -> Result<f64, ComplianceError> {
        let mut held = self.bed.clone();
        let mut u_held = vec![0.0; 3 * body.nodes()];
        for &i in &self.contact {
            held.fix_component(i, 2)?;
            u_held[3 * i + 2] = -PUNCH_DEPTH_M;
        }
        let (_, f) = solve_prescribed(body, &held, &u_held)?;
        Ok(-self.contact.iter().map(|&i| f[3 * i + 2]).sum::<f64>())
    }
}

/// Uniform refinement, each tetrahedron into 8: four corner tetrahedra at the edge midpoints
/// and the inner octahedron cut along the diagonal between the midpoints of edges 0-2 and
/// 1-3. The geometry stays the coarse mesh's, so this is a discretisation reference for
/// that shape.
pub fn split_1_to_8(mesh: &TetMesh) -> TetMesh {
    let mut nodes = mesh.nodes.clone();
    let mut mids: HashMap<(usize, usize), usize> = HashMap::new();
    let mut mid = |a: usize, b: usize, nodes: &mut Vec<[f64; 3]>| {
        let key = (a.min(b), a.max(b));
        *mids.entry(key).or_insert_with(|| {
            let (p, q) = (nodes[a], nodes[b]);
            nodes.push(std::array::from_fn(|c| 0.5 * (p[c] + q[c])));
            nodes.len() - 1
        })
    };
    let mut tets = Vec::with_capacity(8 * mesh.tets.len());
    for &[v0, v1, v2, v3] in &mesh.tets {
        let m01 = mid(v0, v1, &mut nodes);
        let m02 = mid(v0, v2, &mut nodes);
        let m03 = mid(v0, v3, &mut nodes);
        let m12 = mid(v1, v2, &mut nodes);
        let m13 = mid(v1, v3, &mut nodes);
        let m23 = mid(v2, v3, &mut nodes);
        tets.extend([
            [v0, m01, m02, m03],
            [m01, v1, m12, m13],
            [m02, m12, v2, m23],
            [m03, m13, m23, v3],
            [m01, m02, m03, m13],
            [m01, m02, m13, m12],
            [m02, m03, m13, m23],
            [m02, m12, m23, m13],
        ]);
    }
    let mut fine = TetMesh { nodes, tets };
    // Orient every child positively.
    for t in 0..fine.tets.len() {
        if fine.signed_volume(t) < 0.0 {
            fine.tets[t].swap(2, 3);
        }
    }
    fine
}

/// Free-slip uniaxial compression of a box, whose exact solution is linear: what
/// [`box_compression`] measures against it.
#[derive(Debug, Clone, Copy)]
pub struct BoxCompression {
    /// Largest nodal displacement error, relative to the imposed displacement.
    pub displacement_error: f64,
    /// Relative error of the compressing force against `E A strain`.
    pub force_error: f64,
}

/// The box `size` (meshed `cells`, structured) on free-slip supports (bottom `u_z = 0`, one
/// bottom edge and corner held against rigid motion only) compressed by `strain` on its top:
/// exact `u = (nu e x, nu e y, -e z)` and force `E A e`, for any element that passes the patch
/// test, near incompressibility included.
pub fn box_compression(
    body: &impl Stiffness,
    mesh: &TetMesh,
    young: f64,
    nu: f64,
    size: [f64; 3],
    strain: f64,
) -> Result<BoxCompression, ComplianceError> {
    let mut held = FixedSet::none(mesh.nodes.len());
    let mut u_held = vec![0.0; 3 * mesh.nodes.len()];
    let mut top = Vec::new();
    let tol = 1e-9 * size.iter().fold(0.0f64, |m, &s| m.max(s));
    for (i, p) in mesh.nodes.iter().enumerate() {
        if p[2] < tol {
            held.fix_component(i, 2)?;
        }
        if p[2] > size[2] - tol {
            held.fix_component(i, 2)?;
            u_held[3 * i + 2] = -strain * size[2];
            top.push(i);
        }
        if p[0] < tol && p[1] < tol {
            held.fix_component(i, 0)?;
            held.fix_component(i, 1)?;
        }
        if p[0] > size[0] - tol && p[1] < tol {
            held.fix_component(i, 1)?;
        }
    }
    let (u, f) = solve_prescribed(body, &held, &u_held)?;
    let mut displacement_error = 0.0f64;
    for (i, p) in mesh.nodes.iter().enumerate() {
        let exact = [nu * strain * p[0], nu * strain * p[1], -strain * p[2]];
        for c in 0..3 {
            displacement_error =
                displacement_error.max((u[3 * i + c] - exact[c]).abs() / (strain * size[2]));
        }
    }
    let force: f64 = top.iter().map(|&i| f[3 * i + 2]).sum();
    let expected = -young * size[0] * size[1] * strain;
    Ok(BoxCompression {
        displacement_error,
        force_error: ((force - expected) / expected).abs(),
    })
}
