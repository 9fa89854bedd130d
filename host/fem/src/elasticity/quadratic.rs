//! Quadratic (10-node) tetrahedra, for converged reference solutions.
//!
//! The same linear elasticity as the rest of the crate (eq. 1, `K u = f`), discretised with
//! the P2 tetrahedron: a node at each vertex and at each edge midpoint (straight edges: the
//! geometry stays the linear mesh's), shape functions `N_i = L_i (2 L_i - 1)` at the vertices
//! and `N_ij = 4 L_i L_j` at the edges (`L` the barycentric coordinates). Its strain is linear
//! in each element, so it represents bending and, with many more displacement dofs per
//! volumetric constraint, locks far less than P1 as nu -> 0.5. `K` is integrated exactly by the
//! 4-point Gauss rule (the integrand is quadratic).
//!
//! It is a reference, not an [`super::Element`] of banks: its edge nodes change the node set
//! that compliance blocks, banks, the firmware and the display index. The locking study
//! (`examples/punch.rs`, `docs/scenes-and-banks.md`'s table) and the cantilever tests compare
//! P1 and ANP with it.

use super::{
    Block3, Csr, FemError, FixedSet, Material, Stiffness, Tet, adjacency, assemble_upper,
    check_rigid_motions, gradient_block, incidence,
};
use crate::elasticity::DofMap;
use crate::mesh::TetMesh;
use faer::sparse::SparseColMat;
use rayon::prelude::*;
use std::collections::HashMap;

/// Edges of a tetrahedron, in the order of its edge nodes (local nodes 4..10).
pub const EDGES: [(usize, usize); 6] = [(0, 1), (1, 2), (0, 2), (0, 3), (1, 3), (2, 3)];

/// The 4-point Gauss rule on a tetrahedron (degree 2): barycentric coordinates, each point
/// weighted by a quarter of the volume.
pub(crate) const GAUSS: [[f64; 4]; 4] = {
    const A: f64 = 0.585_410_196_624_968_5; // (5 + 3 sqrt 5) / 20
    const B: f64 = 0.138_196_601_125_010_5; // (5 - sqrt 5) / 20
    [[A, B, B, B], [B, A, B, B], [B, B, A, B], [B, B, B, A]]
};

/// A body of 10-node tetrahedra built on a linear tetrahedral mesh.
#[derive(Debug, Clone)]
pub struct QuadraticBody {
    material: Material,
    /// The mesh's vertices, then one midpoint per edge.
    positions: Vec<[f64; 3]>,
    vertices: usize,
    /// Per element: its 4 vertices, then its 6 edge nodes in [`EDGES`] order.
    tets: Vec<[usize; 10]>,
    /// Barycentric gradients and volume of each (straight-sided) element.
    elements: Vec<Tet>,
    /// Edge `(a, b)` with `a < b` -> its midpoint node.
    edge_nodes: HashMap<(usize, usize), usize>,
    node_tets: Csr,
    node_adj: Csr,
}

impl QuadraticBody {
    /// Adds the edge nodes to `mesh` and precomputes the element geometry. Refuses elements of
    /// non-positive volume, like [`super::Elasticity::new`].
    pub fn new(mesh: &TetMesh, material: Material) -> Result<Self, FemError> {
        let elements = Tet::all(mesh)?;
        let mut positions = mesh.nodes.clone();
        let mut edge_nodes = HashMap::new();
        let tets: Vec<[usize; 10]> = mesh
            .tets
            .iter()
            .map(|v| {
                let mut t = [0; 10];
                t[..4].copy_from_slice(v);
                for (slot, &(a, b)) in t[4..].iter_mut().zip(&EDGES) {
                    let key = (v[a].min(v[b]), v[a].max(v[b]));
                    *slot = *edge_nodes.entry(key).or_insert_with(|| {
                        let (p, q) = (mesh.nodes[key.0], mesh.nodes[key.1]);
                        positions.push(std::array::from_fn(|c| 0.5 * (p[c] + q[c])));
                        positions.len() - 1
                    });
                }
                t
            })
            .collect();
        let node_tets = incidence(positions.len(), &tets);
        let node_adj = adjacency(&node_tets, &tets);
        Ok(Self {
            material,
            positions,
            vertices: mesh.nodes.len(),
            tets,
            elements,
            edge_nodes,
            node_tets,
            node_adj,
        })
    }

    /// Node positions: the mesh's vertices (same ids), then the edge midpoints.
    pub fn positions(&self) -> &[[f64; 3]] {
        &self.positions
    }

    /// Number of mesh vertices; nodes `vertices()..` are edge nodes.
    pub fn vertices(&self) -> usize {
        self.vertices
    }

    /// The midpoint node of the mesh edge between vertices `a` and `b`, if it is an edge.
    pub fn edge_node(&self, a: usize, b: usize) -> Option<usize> {
        self.edge_nodes.get(&(a.min(b), a.max(b))).copied()
    }

    /// The elements: 4 vertices, then 6 edge nodes in [`EDGES`] order.
    pub(crate) fn tets(&self) -> &[[usize; 10]] {
        &self.tets
    }

    /// Volume of (straight-sided) element `t`, m^3.
    pub(crate) fn volume(&self, t: usize) -> f64 {
        self.elements[t].volume
    }

    /// Elements incident to `node`.
    pub(crate) fn node_tets(&self, node: usize) -> &[usize] {
        self.node_tets.row(node)
    }

    /// Shape-function gradients of element `t` at barycentric point `l`:
    /// `(4 L_i - 1) grad L_i` at the vertices, `4 (L_i grad L_j + L_j grad L_i)` at the edges.
    pub(crate) fn gradients(&self, t: usize, l: [f64; 4]) -> [[f64; 3]; 10] {
        let g = self.elements[t].grad;
        std::array::from_fn(|k| {
            if k < 4 {
                g[k].map(|x| (4.0 * l[k] - 1.0) * x)
            } else {
                let (i, j) = EDGES[k - 4];
                std::array::from_fn(|c| 4.0 * (l[i] * g[j][c] + l[j] * g[i][c]))
            }
        })
    }

    /// The blocks `K_mp` of column node `p` for the sorted `rows` (entries outside skipped).
    fn column_blocks(&self, p: usize, rows: &[usize]) -> Vec<Block3> {
        let (lambda, mu) = self.material.lame();
        let mut blocks = vec![[[0.0; 3]; 3]; rows.len()];
        for &t in self.node_tets.row(p) {
            let tet = &self.tets[t];
            let b = tet.iter().position(|&v| v == p).expect("incident element");
            let weight = self.elements[t].volume / 4.0;
            for l in GAUSS {
                let grads = self.gradients(t, l);
                for (a, &m) in tet.iter().enumerate() {
                    if let Ok(slot) = rows.binary_search(&m) {
                        let k = gradient_block(grads[a], grads[b], lambda, mu, weight);
                        for (acc, kr) in blocks[slot].iter_mut().zip(k) {
                            for (x, y) in acc.iter_mut().zip(kr) {
                                *x += y;
                            }
                        }
                    }
                }
            }
        }
        blocks
    }
}

impl Stiffness for QuadraticBody {
    fn nodes(&self) -> usize {
        self.positions.len()
    }

    fn neighbours(&self, node: usize) -> &[usize] {
        self.node_adj.row(node)
    }

    fn stiffness(&self, dofs: &DofMap) -> SparseColMat<usize, f64> {
        assemble_upper(
            dofs,
            |node| self.node_adj.row(node),
            |node, rows| self.column_blocks(node, rows),
        )
    }

    fn apply(&self, u: &[f64]) -> Vec<f64> {
        (0..self.positions.len())
            .into_par_iter()
            .flat_map_iter(|m| {
                let all = self.node_adj.row(m);
                let blocks = self.column_blocks(m, all);
                // K is symmetric: (K u)_m = sum_p K_mp u_p = sum_p K_pm^T u_p.
                let mut f = [0.0; 3];
                for (&p, k) in all.iter().zip(&blocks) {
                    for (i, fi) in f.iter_mut().enumerate() {
                        *fi += (0..3).map(|c| k[c][i] * u[3 * p + c]).sum::<f64>();
                    }
                }
                f
            })
            .collect()
    }

    fn check_rigid_motions(&self, fixed: &FixedSet) -> Result<(), FemError> {
        check_rigid_motions(
            &self.positions,
            |i| self.node_adj.row(i),
            |i| !self.node_tets.row(i).is_empty(),
            fixed,
        )
    }
}
