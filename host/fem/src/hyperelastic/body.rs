//! The discretised neo-Hookean body: deformation gradients at the quadrature points, internal
//! forces and the consistent tangent (module docs of [`super`]).

use super::{NeoHookean, inverse, log_det};
use crate::elasticity::quadratic::{GAUSS, QuadraticBody};
use crate::elasticity::{Block3, DofMap, FemError, Material, assemble_upper};
use crate::mesh::TetMesh;
use faer::sparse::SparseColMat;
use rayon::prelude::*;

/// A neo-Hookean body of 10-node tetrahedra on a linear tetrahedral mesh (nodes and numbering
/// of [`QuadraticBody`]).
#[derive(Debug, Clone)]
pub struct HyperelasticBody {
    material: NeoHookean,
    quadratic: QuadraticBody,
    /// Per element and quadrature point: the material shape-function gradients `G_a`.
    grads: Vec<[[[f64; 3]; 10]; 4]>,
    /// Per element: the quadrature weight (a quarter of its volume), m^3.
    weight: Vec<f64>,
    volumetric: Volumetric,
}

/// How the volumetric term `lambda/2 (ln J)^2` of the strain energy is integrated.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Volumetric {
    /// At each of the 4 quadrature points, like the rest of the energy: at small strain the
    /// linear 10-node element of [`QuadraticBody`] exactly (4 volumetric constraints per
    /// element).
    #[default]
    Pointwise,
    /// On the element mean `theta_e = (1/4) sum_q ln J_q` (mean dilatation: one volumetric
    /// constraint per element, the P2/P0 pairing): `V_e lambda/2 theta_e^2`. Its force is
    /// `lambda theta_e sum_q w_q g_a(q)` and its tangent
    /// `V_e lambda gbar_a gbar_b^T - lambda theta_e sum_q w_q g_b g_a^T`,
    /// `gbar_a = (1/4) sum_q g_a(q)`. For nearly incompressible material where the pointwise
    /// constraint count locks.
    ElementMean,
}

/// The state at one quadrature point of a displacement field.
#[derive(Debug, Clone, Copy)]
pub(super) struct Point {
    /// `H = F - I`.
    h: [[f64; 3]; 3],
    /// `M = I - F^-1 = F^-1 H`.
    m: [[f64; 3]; 3],
    /// `ln J`.
    log_j: f64,
    /// Spatial gradients `g_a = F^-T G_a`.
    spatial: [[f64; 3]; 10],
}

/// The state of one element: its quadrature points, the volumetric strain its energy uses
/// at each point (`ln J_q`, or the element mean for [`Volumetric::ElementMean`]) and the mean
/// spatial gradients `gbar_a`.
#[derive(Debug, Clone, Copy)]
pub(super) struct ElementState {
    points: [Point; 4],
    volumetric: [f64; 4],
    mean_spatial: [[f64; 3]; 10],
}

/// The element states of a displacement field.
pub(super) struct State {
    elements: Vec<ElementState>,
}

impl HyperelasticBody {
    /// Builds the 10-node body on `mesh` with the neo-Hookean material of `material`'s Lamé
    /// parameters, volumetric energy at the quadrature points ([`Volumetric::Pointwise`]).
    /// Refuses elements of non-positive volume.
    pub fn new(mesh: &TetMesh, material: Material) -> Result<Self, FemError> {
        Self::with_volumetric(mesh, material, Volumetric::Pointwise)
    }

    /// [`HyperelasticBody::new`] with a chosen integration of the volumetric energy.
    pub fn with_volumetric(
        mesh: &TetMesh,
        material: Material,
        volumetric: Volumetric,
    ) -> Result<Self, FemError> {
        let quadratic = QuadraticBody::new(mesh, material)?;
        let grads = (0..mesh.tets.len())
            .map(|t| GAUSS.map(|l| quadratic.gradients(t, l)))
            .collect();
        let weight = (0..mesh.tets.len())
            .map(|t| quadratic.volume(t) / 4.0)
            .collect();
        Ok(Self {
            material: NeoHookean::new(material),
            quadratic,
            grads,
            weight,
            volumetric,
        })
    }

    /// The linear 10-node body on the same nodes (its small-strain limit).
    pub fn quadratic(&self) -> &QuadraticBody {
        &self.quadratic
    }

    /// How the volumetric energy is integrated.
    pub fn volumetric(&self) -> Volumetric {
        self.volumetric
    }

    /// The material.
    pub fn material(&self) -> NeoHookean {
        self.material
    }

    /// Node positions: mesh vertices, then edge midpoints (as [`QuadraticBody::positions`]).
    pub fn positions(&self) -> &[[f64; 3]] {
        self.quadratic.positions()
    }

    /// Number of nodes.
    pub fn nodes(&self) -> usize {
        self.quadratic.positions().len()
    }

    /// Number of elements.
    pub fn elements(&self) -> usize {
        self.grads.len()
    }

    /// The quadrature-point states of the node-major displacement field `u`, or the lowest id
    /// of an element with `J <= 0` at a quadrature point.
    pub(super) fn evaluate(&self, u: &[f64]) -> Result<State, usize> {
        let tets = self.quadratic.tets();
        let points: Vec<Option<ElementState>> = (0..tets.len())
            .into_par_iter()
            .map(|t| {
                let nodes = tets[t];
                let mut out = [None; 4];
                for (slot, g) in out.iter_mut().zip(&self.grads[t]) {
                    // H = F - I = sum_a u_a G_a^T, kept apart from I so that nothing cancels at
                    // small strain.
                    let mut h = [[0.0; 3]; 3];
                    for (n, ga) in nodes.iter().zip(g) {
                        for (i, row) in h.iter_mut().enumerate() {
                            let ui = u[3 * n + i];
                            for (x, gj) in row.iter_mut().zip(ga) {
                                *x += ui * gj;
                            }
                        }
                    }
                    let log_j = log_det(h)?;
                    let f: [[f64; 3]; 3] = std::array::from_fn(|i| {
                        std::array::from_fn(|j| h[i][j] + if i == j { 1.0 } else { 0.0 })
                    });
                    let inv = inverse(f)?;
                    // M = I - F^-1 = F^-1 H, so F^-T G = G - M^T G.
                    let m: [[f64; 3]; 3] = std::array::from_fn(|i| {
                        std::array::from_fn(|j| (0..3).map(|k| inv[i][k] * h[k][j]).sum())
                    });
                    let spatial = g.map(|ga| {
                        std::array::from_fn(|i| {
                            ga[i] - (0..3).map(|j| m[j][i] * ga[j]).sum::<f64>()
                        })
                    });
                    *slot = Some(Point {
                        h,
                        m,
                        log_j,
                        spatial,
                    });
                }
                let points = out.map(|p| p.expect("filled above"));
                let theta = points.iter().map(|p| p.log_j).sum::<f64>() / 4.0;
                let volumetric = match self.volumetric {
                    Volumetric::Pointwise => points.map(|p| p.log_j),
                    Volumetric::ElementMean => [theta; 4],
                };
                let mean_spatial = std::array::from_fn(|a| {
                    std::array::from_fn(|i| {
                        points.iter().map(|p| p.spatial[a][i]).sum::<f64>() / 4.0
                    })
                });
                Some(ElementState {
                    points,
                    volumetric,
                    mean_spatial,
                })
            })
            .collect();
        match points.iter().position(Option::is_none) {
            Some(t) => Err(t),
            None => Ok(State {
                elements: points.into_iter().flatten().collect(),
            }),
        }
    }

    /// Internal nodal forces `f_a = sum_q w_q P(F_q) G_a(q)`, node-major, N.
    pub(super) fn forces(&self, state: &State) -> Vec<f64> {
        let NeoHookean { lambda, mu } = self.material;
        let tets = self.quadratic.tets();
        (0..self.nodes())
            .into_par_iter()
            .flat_map_iter(|m| {
                let mut out = [0.0; 3];
                for &t in self.quadratic.node_tets(m) {
                    let a = tets[t].iter().position(|&v| v == m).expect("incident");
                    let w = self.weight[t];
                    let e = &state.elements[t];
                    for ((p, g), v) in e.points.iter().zip(&self.grads[t]).zip(e.volumetric) {
                        let (ga, sa) = (g[a], p.spatial[a]);
                        for (i, o) in out.iter_mut().enumerate() {
                            // (F - F^-T) G = H G + M^T G.
                            let d: f64 = (0..3).map(|j| (p.h[i][j] + p.m[j][i]) * ga[j]).sum();
                            *o += w * (mu * d + lambda * v * sa[i]);
                        }
                    }
                }
                out
            })
            .collect()
    }

    /// Stored energy `sum_q w_q W(F_q)`, J.
    pub fn energy(&self, u: &[f64]) -> Result<f64, usize> {
        let NeoHookean { lambda, mu } = self.material;
        let state = self.evaluate(u)?;
        Ok(state
            .elements
            .iter()
            .zip(&self.weight)
            .map(|(e, w)| {
                e.points
                    .iter()
                    .zip(e.volumetric)
                    .map(|(p, v)| {
                        // I1 - 3 = 2 tr H + |H|^2.
                        let tr = p.h[0][0] + p.h[1][1] + p.h[2][2];
                        let hh: f64 = p.h.iter().flatten().map(|x| x * x).sum();
                        w * (0.5 * mu * (2.0 * tr + hh) - mu * p.log_j + 0.5 * lambda * v * v)
                    })
                    .sum::<f64>()
            })
            .sum())
    }

    /// The tangent block `K_ab` (row components at `a`, columns at `b`) of element `t`: the
    /// sum over its quadrature points of
    /// `w [mu (G_a . G_b) I + (mu - lambda v) g_b g_a^T]` (`v` the volumetric strain of the
    /// point) plus the volumetric term `w lambda g_a g_b^T` per point, or
    /// `V_e lambda gbar_a gbar_b^T` on the element mean.
    fn block(&self, state: &State, t: usize, a: usize, b: usize) -> Block3 {
        let NeoHookean { lambda, mu } = self.material;
        let e = &state.elements[t];
        let w = self.weight[t];
        let mut k = [[0.0; 3]; 3];
        for q in 0..4 {
            let p = &e.points[q];
            let (ga, gb) = (self.grads[t][q][a], self.grads[t][q][b]);
            let (sa, sb) = (p.spatial[a], p.spatial[b]);
            let gg: f64 = (0..3).map(|j| ga[j] * gb[j]).sum();
            let c = mu - lambda * e.volumetric[q];
            let own = match self.volumetric {
                Volumetric::Pointwise => lambda,
                Volumetric::ElementMean => 0.0,
            };
            for (i, row) in k.iter_mut().enumerate() {
                for (j, x) in row.iter_mut().enumerate() {
                    let diag = if i == j { mu * gg } else { 0.0 };
                    *x += w * (diag + c * sb[i] * sa[j] + own * sa[i] * sb[j]);
                }
            }
        }
        if self.volumetric == Volumetric::ElementMean {
            let (ma, mb) = (e.mean_spatial[a], e.mean_spatial[b]);
            for (i, row) in k.iter_mut().enumerate() {
                for (j, x) in row.iter_mut().enumerate() {
                    *x += 4.0 * w * lambda * ma[i] * mb[j];
                }
            }
        }
        k
    }

    /// The blocks `K_mp` of column node `p` for the sorted `rows`.
    fn column_blocks(&self, state: &State, p: usize, rows: &[usize]) -> Vec<Block3> {
        let tets = self.quadratic.tets();
        let mut blocks = vec![[[0.0; 3]; 3]; rows.len()];
        for &t in self.quadratic.node_tets(p) {
            let b = tets[t].iter().position(|&v| v == p).expect("incident");
            for (a, m) in tets[t].iter().enumerate() {
                let Ok(slot) = rows.binary_search(m) else {
                    continue;
                };
                let k = self.block(state, t, a, b);
                for (acc, kr) in blocks[slot].iter_mut().zip(k) {
                    for (x, y) in acc.iter_mut().zip(kr) {
                        *x += y;
                    }
                }
            }
        }
        blocks
    }

    /// The upper triangle of the free-dof tangent `K_ff` in CSC form (the pattern of
    /// [`QuadraticBody`]'s `K_ff` for the same `dofs`).
    pub(super) fn tangent(&self, state: &State, dofs: &DofMap) -> SparseColMat<usize, f64> {
        use crate::elasticity::Stiffness;
        assemble_upper(
            dofs,
            |node| self.quadratic.neighbours(node),
            |node, rows| self.column_blocks(state, node, rows),
        )
    }

    /// The full tangent applied to a node-major field `v`: `K v`, element by element.
    pub(super) fn tangent_apply(&self, state: &State, v: &[f64]) -> Vec<f64> {
        let tets = self.quadratic.tets();
        (0..self.nodes())
            .into_par_iter()
            .flat_map_iter(|m| {
                let mut out = [0.0; 3];
                for &t in self.quadratic.node_tets(m) {
                    let a = tets[t].iter().position(|&x| x == m).expect("incident");
                    for (b, &n) in tets[t].iter().enumerate() {
                        let k = self.block(state, t, a, b);
                        for (o, kr) in out.iter_mut().zip(k) {
                            *o += (0..3).map(|c| kr[c] * v[3 * n + c]).sum::<f64>();
                        }
                    }
                }
                out
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::elasticity::Stiffness;
    use crate::mesh::structured::distorted_box_mesh;

    fn body() -> HyperelasticBody {
        bodies().swap_remove(0)
    }

    /// The same distorted box with each volumetric integration.
    fn bodies() -> Vec<HyperelasticBody> {
        let mesh = distorted_box_mesh([0.02, 0.03, 0.025], [2, 2, 2], 0.3, 7).unwrap();
        let material = Material::new(5000.0, 0.45).unwrap();
        [Volumetric::Pointwise, Volumetric::ElementMean]
            .map(|v| HyperelasticBody::with_volumetric(&mesh, material, v).unwrap())
            .into()
    }

    /// A smooth displacement field of a few percent strain.
    fn field(body: &HyperelasticBody, scale: f64) -> Vec<f64> {
        body.positions()
            .iter()
            .flat_map(|p| {
                [
                    scale * (0.3 * p[1] + 2.0 * p[0] * p[2] / 0.03),
                    scale * (-0.2 * p[2] + p[0] * p[0] / 0.02),
                    scale * (0.25 * p[0] - 0.1 * p[2] + p[1] * p[1] / 0.03),
                ]
            })
            .collect()
    }

    #[test]
    fn forces_are_the_energy_gradient() {
        for b in bodies() {
            forces_are_the_energy_gradient_of(&b);
        }
    }

    fn forces_are_the_energy_gradient_of(b: &HyperelasticBody) {
        let u = field(b, 0.1);
        let f = b.forces(&b.evaluate(&u).unwrap());
        let h = 1e-7;
        let scale = f.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        for d in (0..u.len()).step_by(7) {
            let (mut up, mut um) = (u.clone(), u.clone());
            up[d] += h;
            um[d] -= h;
            let fd = (b.energy(&up).unwrap() - b.energy(&um).unwrap()) / (2.0 * h);
            assert!(
                (fd - f[d]).abs() < 1e-6 * scale,
                "dof {d}: {fd} vs {}",
                f[d]
            );
        }
    }

    #[test]
    fn tangent_is_the_force_derivative() {
        for b in bodies() {
            tangent_is_the_force_derivative_of(&b);
        }
    }

    fn tangent_is_the_force_derivative_of(b: &HyperelasticBody) {
        let u = field(b, 0.1);
        let state = b.evaluate(&u).unwrap();
        let v = field(b, 1.0).iter().map(|x| x.sin()).collect::<Vec<_>>();
        let kv = b.tangent_apply(&state, &v);
        let h = 1e-6;
        let plus: Vec<f64> = u.iter().zip(&v).map(|(a, b)| a + h * b).collect();
        let minus: Vec<f64> = u.iter().zip(&v).map(|(a, b)| a - h * b).collect();
        let fp = b.forces(&b.evaluate(&plus).unwrap());
        let fm = b.forces(&b.evaluate(&minus).unwrap());
        let scale = kv.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        for d in 0..u.len() {
            let fd = (fp[d] - fm[d]) / (2.0 * h);
            assert!(
                (fd - kv[d]).abs() < 1e-6 * scale,
                "dof {d}: {fd} vs {}",
                kv[d]
            );
        }
    }

    #[test]
    fn tangent_at_rest_is_the_linear_stiffness() {
        let b = body();
        let state = b.evaluate(&vec![0.0; 3 * b.nodes()]).unwrap();
        let v = field(&b, 1.0);
        let kv = b.tangent_apply(&state, &v);
        let linear = b.quadratic().apply(&v);
        let scale = linear.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        for (x, y) in kv.iter().zip(&linear) {
            assert!((x - y).abs() < 1e-12 * scale);
        }
    }

    #[test]
    fn assembled_tangent_matches_its_application() {
        for b in bodies() {
            assembled_tangent_matches_its_application_of(&b);
        }
    }

    fn assembled_tangent_matches_its_application_of(b: &HyperelasticBody) {
        let u = field(b, 0.1);
        let state = b.evaluate(&u).unwrap();
        let dofs = DofMap::new(&crate::elasticity::FixedSet::none(b.nodes()));
        let k = b.tangent(&state, &dofs);
        let v = field(b, 1.0);
        let kv = b.tangent_apply(&state, &v);
        // Symmetric product from the upper triangle.
        let mut y = vec![0.0; v.len()];
        let (cols, rows, vals) = (k.col_ptr(), k.row_idx(), k.val());
        for c in 0..v.len() {
            for idx in cols[c]..cols[c + 1] {
                let r = rows[idx];
                y[r] += vals[idx] * v[c];
                if r != c {
                    y[c] += vals[idx] * v[r];
                }
            }
        }
        let scale = kv.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        for (x, z) in kv.iter().zip(&y) {
            assert!((x - z).abs() < 1e-11 * scale);
        }
    }

    #[test]
    fn an_inverted_element_is_named() {
        let b = body();
        let mut u = vec![0.0; 3 * b.nodes()];
        // Push vertex 0 (a box corner) far through its elements.
        u[0] = 0.1;
        u[1] = 0.1;
        u[2] = 0.1;
        let t = b.evaluate(&u).err().expect("inverted");
        assert!(b.quadratic().tets()[t].contains(&0));
    }
}
