//! Linear elasticity on tetrahedra (the paper's section 3, eq. 1: `K u = f`): the paper's P1
//! element, or the average nodal pressure (ANP) element that does not lock as nu -> 0.5
//! ([`Element`]). Both have one node per mesh vertex.
//!
//! Displacements are numbered node-major: dof `3 i + c` is component `c` (x, y, z) of node `i`.
//! Fixed dofs (`u = 0`) are removed; the remaining *free* dofs keep node-major order, so `K_ff`
//! is assembled directly (upper triangle, CSC) in the layout the Cholesky factorisation wants.

pub mod quadratic;

use crate::mesh::TetMesh;
use crate::vec3::{add, cross, dot, norm, scale, sub};
use faer::sparse::{SparseColMat, SymbolicSparseColMat};
use rayon::prelude::*;

/// Errors of the finite element model.
#[derive(Debug, thiserror::Error)]
pub enum FemError {
    /// Young's modulus or Poisson's ratio outside the physical range.
    #[error("invalid material: {0}")]
    Material(String),
    /// A tetrahedron with non-positive volume reached the assembly (meshes are validated on load).
    #[error("tetrahedron {tet} has non-positive volume {volume:e} m^3")]
    BadElement {
        /// Tetrahedron id.
        tet: usize,
        /// Its signed volume.
        volume: f64,
    },
    /// A fixed node id is not in the mesh.
    #[error("fixed node {node} does not exist (the mesh has {nodes} nodes)")]
    NoSuchNode {
        /// The offending id.
        node: usize,
        /// Number of nodes in the mesh.
        nodes: usize,
    },
    /// The fixed set leaves a rigid-body motion free, so `K_ff` is singular.
    #[error(
        "the fixed set leaves rigid motions free, so K_ff is singular: {0}. Fix more nodes (a \
         box around a support) so every connected part is held in all 6 directions"
    )]
    RigidMotion(String),
    /// A fixed set built for a mesh with another number of nodes.
    #[error("the fixed set covers {fixed} nodes but the mesh has {nodes}")]
    FixedSetMismatch {
        /// Nodes covered by the fixed set.
        fixed: usize,
        /// Nodes of the mesh.
        nodes: usize,
    },
    /// A box that selects no node.
    #[error("fixed box {0:?} contains no node of the mesh")]
    EmptyBox([f64; 6]),
}

/// Isotropic linear elastic material in SI units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Material {
    /// Young's modulus E in pascals.
    pub young: f64,
    /// Poisson's ratio nu (dimensionless, -1 < nu < 0.5).
    pub poisson: f64,
}

impl Material {
    /// Checks `E > 0` and `-1 < nu < 0.5` (nu = 0.5 is incompressible: P1 cannot represent it).
    pub fn new(young: f64, poisson: f64) -> Result<Self, FemError> {
        if !(young.is_finite() && young > 0.0) {
            return Err(FemError::Material(format!(
                "Young's modulus must be a positive number of pascals, got {young}"
            )));
        }
        if !(poisson > -1.0 && poisson < 0.5) {
            return Err(FemError::Material(format!(
                "Poisson's ratio must lie in (-1, 0.5), got {poisson}"
            )));
        }
        Ok(Self { young, poisson })
    }

    /// Lamé parameters `(lambda, mu)` in pascals.
    pub fn lame(&self) -> (f64, f64) {
        let (e, nu) = (self.young, self.poisson);
        (
            e * nu / ((1.0 + nu) * (1.0 - 2.0 * nu)),
            e / (2.0 * (1.0 + nu)),
        )
    }
}

/// Which displacement components are held at zero. Builders add nodes, boxes or single
/// components; the set only grows.
#[derive(Debug, Clone, PartialEq)]
pub struct FixedSet {
    fixed: Vec<[bool; 3]>,
}

impl FixedSet {
    /// Nothing fixed, for a mesh of `nodes` nodes.
    pub fn none(nodes: usize) -> Self {
        Self {
            fixed: vec![[false; 3]; nodes],
        }
    }

    /// Fixes all three components of `node`.
    pub fn fix_node(&mut self, node: usize) -> Result<(), FemError> {
        self.fix_component(node, 0)?;
        self.fix_component(node, 1)?;
        self.fix_component(node, 2)
    }

    /// Fixes component `axis` (0 = x, 1 = y, 2 = z) of `node`, e.g. a slide-only support.
    pub fn fix_component(&mut self, node: usize, axis: usize) -> Result<(), FemError> {
        let nodes = self.fixed.len();
        let slot = self
            .fixed
            .get_mut(node)
            .ok_or(FemError::NoSuchNode { node, nodes })?;
        slot[axis.min(2)] = true;
        Ok(())
    }

    /// Fixes the given components of every node inside the closed box
    /// `[xmin, ymin, zmin, xmax, ymax, zmax]`; returns how many nodes it selected.
    pub fn fix_box(
        &mut self,
        mesh: &TetMesh,
        bounds: [f64; 6],
        components: [bool; 3],
    ) -> Result<usize, FemError> {
        let mut count = 0;
        for (p, slot) in mesh.nodes.iter().zip(&mut self.fixed) {
            if (0..3).all(|a| p[a] >= bounds[a] && p[a] <= bounds[a + 3]) {
                for a in 0..3 {
                    slot[a] |= components[a];
                }
                count += 1;
            }
        }
        if count == 0 {
            return Err(FemError::EmptyBox(bounds));
        }
        Ok(count)
    }

    /// Parses an axis list such as `"xz"` into a component mask for [`FixedSet::fix_box`].
    /// Errors: the first character that is not x, y or z, or an empty list.
    pub fn parse_axes(axes: &str) -> Result<[bool; 3], String> {
        let mut mask = [false; 3];
        for ch in axes.chars() {
            match ch {
                'x' => mask[0] = true,
                'y' => mask[1] = true,
                'z' => mask[2] = true,
                other => return Err(format!("unknown axis {other:?} (use x, y, z)")),
            }
        }
        if mask == [false; 3] {
            return Err("no axis given".into());
        }
        Ok(mask)
    }

    /// Whether component `axis` of `node` is fixed.
    pub fn is_fixed(&self, node: usize, axis: usize) -> bool {
        self.fixed[node][axis]
    }

    /// Number of nodes the set covers.
    pub fn nodes(&self) -> usize {
        self.fixed.len()
    }

    /// Number of fixed dofs.
    pub fn count(&self) -> usize {
        self.fixed.iter().flatten().filter(|&&f| f).count()
    }
}

/// Numbering of the free dofs, node-major, with fixed dofs removed.
#[derive(Debug, Clone)]
pub struct DofMap {
    index: Vec<u32>,
    free: usize,
}

const FIXED: u32 = u32::MAX;

impl DofMap {
    /// Numbers the dofs left free by `fixed`.
    pub fn new(fixed: &FixedSet) -> Self {
        let mut free = 0;
        let index = fixed
            .fixed
            .iter()
            .flatten()
            .map(|&f| {
                if f {
                    FIXED
                } else {
                    free += 1;
                    (free - 1) as u32
                }
            })
            .collect();
        Self { index, free }
    }

    /// Free-dof index of component `axis` of `node`, or `None` if it is fixed.
    pub fn free_dof(&self, node: usize, axis: usize) -> Option<usize> {
        let i = self.index[3 * node + axis];
        (i != FIXED).then_some(i as usize)
    }

    /// Number of free dofs (the order of `K_ff`).
    pub fn free_count(&self) -> usize {
        self.free
    }

    /// Number of nodes.
    pub fn nodes(&self) -> usize {
        self.index.len() / 3
    }

    /// Scatters a free-dof vector into a full node-major vector (zeros at fixed dofs).
    pub fn expand(&self, free: &[f64]) -> Vec<f64> {
        self.index
            .iter()
            .map(|&i| if i == FIXED { 0.0 } else { free[i as usize] })
            .collect()
    }
}

/// Shape-function gradients and volume of one P1 tetrahedron.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Tet {
    pub(crate) grad: [[f64; 3]; 4],
    pub(crate) volume: f64,
}

impl Tet {
    /// The geometry of every tetrahedron of `mesh`; refuses one of non-positive volume.
    pub(crate) fn all(mesh: &TetMesh) -> Result<Vec<Tet>, FemError> {
        let elements: Vec<Tet> = mesh
            .tets
            .par_iter()
            .map(|t| Tet::new(t.map(|i| mesh.nodes[i])))
            .collect();
        match elements
            .iter()
            .enumerate()
            .find(|(_, e)| !(e.volume > 0.0 && e.volume.is_finite()))
        {
            Some((tet, e)) => Err(FemError::BadElement {
                tet,
                volume: e.volume,
            }),
            None => Ok(elements),
        }
    }

    pub(crate) fn new(x: [[f64; 3]; 4]) -> Self {
        // Columns of J are the edge vectors from vertex 0; rows of J^-1 are grad N1..N3.
        let e = [sub(x[1], x[0]), sub(x[2], x[0]), sub(x[3], x[0])];
        let det = dot(e[0], cross(e[1], e[2]));
        let rows =
            [cross(e[1], e[2]), cross(e[2], e[0]), cross(e[0], e[1])].map(|r| scale(r, 1.0 / det));
        let g0 = [
            -(rows[0][0] + rows[1][0] + rows[2][0]),
            -(rows[0][1] + rows[1][1] + rows[2][1]),
            -(rows[0][2] + rows[1][2] + rows[2][2]),
        ];
        Self {
            grad: [g0, rows[0], rows[1], rows[2]],
            volume: det / 6.0,
        }
    }

    /// The 3x3 block `K_ab` of the element stiffness `V B^T D B`, row index = component at `a`:
    /// `V (lambda g_a g_b^T + mu g_b g_a^T + mu (g_a . g_b) I)`.
    fn block(&self, a: usize, b: usize, lambda: f64, mu: f64) -> Block3 {
        gradient_block(self.grad[a], self.grad[b], lambda, mu, self.volume)
    }
}

/// A 3x3 block of `K`, row index = component at the row node.
pub(crate) type Block3 = [[f64; 3]; 3];

/// `v (lambda g_a g_b^T + mu g_b g_a^T + mu (g_a . g_b) I)`: the stiffness block between two
/// shape functions with gradients `g_a`, `g_b` at one point, weighted by the volume `v` it
/// stands for (the integrand of `B^T D B`, eq. 1).
pub(crate) fn gradient_block(ga: [f64; 3], gb: [f64; 3], lambda: f64, mu: f64, v: f64) -> Block3 {
    let gg = dot(ga, gb);
    std::array::from_fn(|i| {
        std::array::from_fn(|j| {
            let diag = if i == j { mu * gg } else { 0.0 };
            v * (lambda * ga[i] * gb[j] + mu * gb[i] * ga[j] + diag)
        })
    })
}

/// The discretised elastic body: element data and the node graph, ready to assemble `K_ff`
/// for any fixed set or to apply the full `K` to a displacement field.
#[derive(Debug, Clone)]
pub struct Elasticity {
    material: Material,
    positions: Vec<[f64; 3]>,
    tets: Vec<[usize; 4]>,
    elements: Vec<Tet>,
    /// CSR: tetrahedra incident to each node.
    node_tets: Csr,
    /// CSR: sorted neighbours of each node, itself included.
    node_adj: Csr,
    /// The element formulation.
    element: Element,
    /// The nodal volumetric operator of [`Element::Anp`] (`None` for P1).
    nodal: Option<NodalVolume>,
}

/// The element formulation: how the volumetric energy is integrated. Both keep one node per
/// mesh vertex and three displacement dofs per node, so everything downstream of `K_ff`
/// (compliance blocks, banks, firmware, display) is unchanged.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum Element {
    /// Linear tetrahedron (the paper's element): constant strain per element. Locks as
    /// nu -> 0.5 (one volumetric constraint per element, about 5 per node against 3 dofs).
    #[default]
    P1,
    /// Average nodal pressure tetrahedron (Bonet & Burton, *Commun. Numer. Meth. Engng* 14,
    /// 1998; Joldes, Wittek & Miller, *Commun. Numer. Meth. Engng* 25, 2009): the deviatoric
    /// energy is P1's, the volumetric energy uses the nodally averaged volumetric strain
    /// `theta_n = (1 / V_n) sum_{e ∋ n} (V_e / 4) tr(eps_e)`, `V_n = sum_{e ∋ n} V_e / 4`
    /// (one constraint per node), stabilised by a fraction [`ANP_STABILISATION`] of P1's
    /// element volumetric energy:
    /// `W = sum_e V_e mu |dev eps_e|^2
    ///    + (kappa / 2) [(1 - alpha) sum_n V_n theta_n^2 + alpha sum_e V_e tr(eps_e)^2]`.
    Anp,
}

/// `alpha` of [`Element::Anp`]: the fraction of the element-wise (P1) volumetric energy kept
/// to stabilise the nodal-pressure modes (volumetric strain fields that change sign from
/// element to element with a zero nodal average, which pure ANP penalises only through `mu`).
/// Both volumetric energies agree on linear fields, so any alpha passes the patch test; but
/// alpha re-introduces P1's one-constraint-per-element with penalty `alpha kappa`, so it must
/// stay small against `mu`. Measured (`tests/element.rs`, `examples/punch.rs`) at nu = 0.499:
/// pure ANP (alpha = 0) already has no near-zero eigenvalue of `K_ff` (its six lowest are
/// 64-81 % of P1's on the 3x3x3 test box; its eight lowest 45-57 % on `liver-1k4` with the bed
/// fixed, from a one-off dense eigensolve; P1's are raised by locking); alpha = 0.001 raises them by about 1 % and costs 1.3 % of tip deflection on a 40x6x6
/// cantilever and 1.1 % of punch force on `liver-1k4`, where alpha = 0.01 costs 11 % and 8 %.
/// The penalty grows like `alpha kappa / mu`, so at nu = 0.4999 alpha = 0.001 stiffens about
/// as much as 0.01 does at 0.499.
pub const ANP_STABILISATION: f64 = 0.001;

impl Element {
    /// Every formulation, in the order [`Element::name`] lists them.
    pub const ALL: [Element; 2] = [Element::P1, Element::Anp];

    /// The formulation's name: `p1` or `anp`.
    pub fn name(self) -> &'static str {
        match self {
            Element::P1 => "p1",
            Element::Anp => "anp",
        }
    }
}

impl std::fmt::Display for Element {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for Element {
    type Err = String;

    /// Parses a name of [`Element::name`].
    fn from_str(s: &str) -> Result<Element, String> {
        Element::ALL
            .into_iter()
            .find(|e| e.name() == s)
            .ok_or_else(|| format!("unknown element {s:?} (expected p1 or anp)"))
    }
}

/// The nodal volumetric operator of the ANP element: `theta_n = (1 / V_n) sum_m w_nm . u_m`
/// with `w_nm = sum_{e ∋ n, m} (V_e / 4) grad N^e_m`, so the nodal energy is
/// `(1 - alpha) kappa / 2 sum_n (w_n . u)^2 / V_n`.
#[derive(Debug, Clone)]
struct NodalVolume {
    /// `(1 - alpha) kappa / V_n` per node.
    weight: Vec<f64>,
    /// `w_nm`, aligned with the one-ring `Elasticity::ring` (row n, entry m).
    w: Vec<[f64; 3]>,
    /// One-ring neighbours (itself included); `node_adj` then holds the two-ring pattern.
    ring: Csr,
    /// `alpha`.
    alpha: f64,
}

/// A graph or incidence in compressed sparse rows.
#[derive(Debug, Clone)]
pub(crate) struct Csr {
    ptr: Vec<usize>,
    idx: Vec<usize>,
}

impl Csr {
    pub(crate) fn row(&self, i: usize) -> &[usize] {
        &self.idx[self.ptr[i]..self.ptr[i + 1]]
    }
}

impl Elasticity {
    /// Precomputes element gradients and the node graph of the P1 element.
    pub fn new(mesh: &TetMesh, material: Material) -> Result<Self, FemError> {
        Self::with_element(mesh, material, Element::P1)
    }

    /// [`Elasticity::new`] with a chosen element formulation ([`Element::Anp`] with its
    /// default stabilisation [`ANP_STABILISATION`]).
    pub fn with_element(
        mesh: &TetMesh,
        material: Material,
        element: Element,
    ) -> Result<Self, FemError> {
        let p1 = Self::p1(mesh, material)?;
        match element {
            Element::P1 => Ok(p1),
            Element::Anp => p1.anp(ANP_STABILISATION),
        }
    }

    /// The ANP element with stabilisation `alpha` in `[0, 1]` (0: pure nodal pressure, which
    /// has spurious low-energy modes; 1: P1). For studying the choice of [`ANP_STABILISATION`].
    pub fn with_anp_stabilisation(
        mesh: &TetMesh,
        material: Material,
        alpha: f64,
    ) -> Result<Self, FemError> {
        if !(0.0..=1.0).contains(&alpha) {
            return Err(FemError::Material(format!(
                "the ANP stabilisation must lie in [0, 1], got {alpha}"
            )));
        }
        Self::p1(mesh, material)?.anp(alpha)
    }

    /// Turns a P1 body into the ANP element: nodal volumes, the operator `w` and the two-ring
    /// sparsity pattern (the nodal volumetric strain of `n` involves its one-ring, so its
    /// energy couples every pair of nodes in that ring).
    fn anp(mut self, alpha: f64) -> Result<Self, FemError> {
        let n = self.nodes();
        let ring = self.node_adj.clone();
        let kappa = self.bulk_modulus();
        let rows: Vec<(f64, Vec<[f64; 3]>)> = (0..n)
            .into_par_iter()
            .map(|node| {
                let row = ring.row(node);
                let mut w = vec![[0.0; 3]; row.len()];
                let mut volume = 0.0;
                for &t in self.node_tets.row(node) {
                    let el = &self.elements[t];
                    volume += el.volume / 4.0;
                    for (a, &m) in self.tets[t].iter().enumerate() {
                        let k = row.binary_search(&m).expect("tet vertices are neighbours");
                        w[k] = add(w[k], scale(el.grad[a], el.volume / 4.0));
                    }
                }
                let weight = if volume > 0.0 {
                    (1.0 - alpha) * kappa / volume
                } else {
                    0.0
                };
                (weight, w)
            })
            .collect();
        let mut weight = Vec::with_capacity(n);
        let mut w = Vec::with_capacity(ring.idx.len());
        for (c, row) in rows {
            weight.push(c);
            w.extend(row);
        }
        self.node_adj = two_ring(&ring);
        self.element = Element::Anp;
        self.nodal = Some(NodalVolume {
            weight,
            w,
            ring,
            alpha,
        });
        Ok(self)
    }

    fn p1(mesh: &TetMesh, material: Material) -> Result<Self, FemError> {
        let elements = Tet::all(mesh)?;
        let n = mesh.nodes.len();
        let node_tets = incidence(n, &mesh.tets);
        let node_adj = adjacency(&node_tets, &mesh.tets);
        Ok(Self {
            material,
            positions: mesh.nodes.clone(),
            tets: mesh.tets.clone(),
            elements,
            node_tets,
            node_adj,
            element: Element::P1,
            nodal: None,
        })
    }

    /// The element formulation.
    pub fn element(&self) -> Element {
        self.element
    }

    /// Bulk modulus `kappa = lambda + 2 mu / 3`.
    fn bulk_modulus(&self) -> f64 {
        let (lambda, mu) = self.material.lame();
        lambda + 2.0 * mu / 3.0
    }

    /// The Lamé pair of the element-wise part of the energy: P1's, or for ANP the deviatoric
    /// part plus the stabilisation, `W_e = (alpha kappa - 2 mu / 3) / 2 tr^2 + mu eps:eps`.
    fn element_lame(&self) -> (f64, f64) {
        let (lambda, mu) = self.material.lame();
        match &self.nodal {
            None => (lambda, mu),
            Some(nodal) => (nodal.alpha * self.bulk_modulus() - 2.0 * mu / 3.0, mu),
        }
    }

    /// Number of nodes.
    pub fn nodes(&self) -> usize {
        self.node_tets.ptr.len() - 1
    }

    /// The material.
    pub fn material(&self) -> Material {
        self.material
    }

    /// Sorted nodes coupled to `node` in `K`, itself included: those sharing a tetrahedron
    /// for P1, the two-ring (neighbours of neighbours) for ANP. The sparsity pattern of `K_ff`
    /// and the graph of the METIS ordering.
    pub fn neighbours(&self, node: usize) -> &[usize] {
        self.node_adj.row(node)
    }

    /// The 3x3 blocks `K_mp` (rows: components at `m`) of column node `p` for the sorted rows
    /// `rows`, which must contain every `m <= p` coupled to `p`; entries outside `rows` are
    /// skipped. Element part tet by tet, then the ANP nodal part `c_n w_nm w_np^T` summed
    /// over the nodes `n` whose one-ring holds both.
    fn column_blocks(&self, p: usize, rows: &[usize]) -> Vec<[[f64; 3]; 3]> {
        let (lambda, mu) = self.element_lame();
        let mut blocks = vec![[[0.0; 3]; 3]; rows.len()];
        let mut add_block = |m: usize, k: [[f64; 3]; 3]| {
            if let Ok(slot) = rows.binary_search(&m) {
                for (acc, kr) in blocks[slot].iter_mut().zip(k) {
                    for (x, y) in acc.iter_mut().zip(kr) {
                        *x += y;
                    }
                }
            }
        };
        for &t in self.node_tets.row(p) {
            let tet = &self.tets[t];
            let b = tet.iter().position(|&v| v == p).expect("incident tet");
            for (a, &m) in tet.iter().enumerate() {
                add_block(m, self.elements[t].block(a, b, lambda, mu));
            }
        }
        if let Some(nodal) = &self.nodal {
            for &n in nodal.ring.row(p) {
                let range = nodal.ring.ptr[n]..nodal.ring.ptr[n + 1];
                let ring = &nodal.ring.idx[range.clone()];
                let w = &nodal.w[range];
                let Ok(at_p) = ring.binary_search(&p) else {
                    continue;
                };
                let wp = scale(w[at_p], nodal.weight[n]);
                for (&m, wm) in ring.iter().zip(w) {
                    add_block(
                        m,
                        std::array::from_fn(|i| std::array::from_fn(|j| wm[i] * wp[j])),
                    );
                }
            }
        }
        blocks
    }

    /// Assembles the upper triangle of `K_ff` in CSC form (columns in parallel: each node's
    /// three columns only read shared data, so there are no write conflicts).
    pub fn stiffness(&self, dofs: &DofMap) -> SparseColMat<usize, f64> {
        assemble_upper(
            dofs,
            |node| self.neighbours(node),
            |node, rows| self.column_blocks(node, rows),
        )
    }

    /// Applies the full (unconstrained) stiffness: returns `K u` for a node-major field `u` of
    /// length `3 N`. Element by element (and, for ANP, through the nodal volumetric strains
    /// `theta_n`), independent of [`Elasticity::stiffness`]; used for reaction forces and
    /// residual checks.
    pub fn apply(&self, u: &[f64]) -> Vec<f64> {
        let (lambda, mu) = self.element_lame();
        let n = self.nodes();
        let at = |m: usize| [u[3 * m], u[3 * m + 1], u[3 * m + 2]];
        // ANP: s_n = c_n (w_n . u), so that f_m += sum_{n in ring(m)} s_n w_nm.
        let nodal_stress: Vec<f64> = match &self.nodal {
            None => Vec::new(),
            Some(nodal) => (0..n)
                .into_par_iter()
                .map(|node| {
                    let range = nodal.ring.ptr[node]..nodal.ring.ptr[node + 1];
                    let dilatation: f64 = nodal.ring.idx[range.clone()]
                        .iter()
                        .zip(&nodal.w[range])
                        .map(|(&m, w)| dot(*w, at(m)))
                        .sum();
                    nodal.weight[node] * dilatation
                })
                .collect(),
        };
        (0..n)
            .into_par_iter()
            .flat_map_iter(|m| {
                let mut f = [0.0; 3];
                for &t in self.node_tets.row(m) {
                    let tet = &self.tets[t];
                    let a = tet.iter().position(|&v| v == m).expect("incident tet");
                    for (b, &nb) in tet.iter().enumerate() {
                        let k = self.elements[t].block(a, b, lambda, mu);
                        let ub = at(nb);
                        for (fi, ki) in f.iter_mut().zip(k) {
                            *fi += dot(ki, ub);
                        }
                    }
                }
                if let Some(nodal) = &self.nodal {
                    for &nd in nodal.ring.row(m) {
                        let range = nodal.ring.ptr[nd]..nodal.ring.ptr[nd + 1];
                        let k = nodal.ring.idx[range.clone()]
                            .binary_search(&m)
                            .expect("one-ring is symmetric");
                        f = add(f, scale(nodal.w[range][k], nodal_stress[nd]));
                    }
                }
                f
            })
            .collect()
    }

    /// Refuses a fixed set that leaves a rigid-body motion free in some connected part of the
    /// mesh: the 6 rigid modes restricted to the fixed dofs of each part must have full rank.
    pub fn check_rigid_motions(&self, fixed: &FixedSet) -> Result<(), FemError> {
        check_rigid_motions(
            &self.positions,
            |i| self.neighbours(i),
            |i| !self.node_tets.row(i).is_empty(),
            fixed,
        )
    }
}

/// What the static solves of [`crate::compliance`] need of a discretised body: its node graph
/// (the sparsity of `K` and the graph of the fill-reducing ordering), `K_ff`, `K u` and the
/// rigid-motion check of a fixed set. Implemented by [`Elasticity`] (one node per mesh vertex:
/// the bodies of banks) and [`quadratic::QuadraticBody`] (10-node tetrahedra, for references).
pub trait Stiffness: Sync {
    /// Number of nodes (three dofs each).
    fn nodes(&self) -> usize;
    /// Sorted nodes coupled to `node` in `K`, itself included.
    fn neighbours(&self, node: usize) -> &[usize];
    /// The upper triangle of `K_ff` in CSC form, free dofs numbered by `dofs`.
    fn stiffness(&self, dofs: &DofMap) -> SparseColMat<usize, f64>;
    /// `K u` for a node-major field of length `3 nodes`, element by element.
    fn apply(&self, u: &[f64]) -> Vec<f64>;
    /// Refuses a fixed set that leaves a rigid-body motion free.
    fn check_rigid_motions(&self, fixed: &FixedSet) -> Result<(), FemError>;
}

impl Stiffness for Elasticity {
    fn nodes(&self) -> usize {
        Elasticity::nodes(self)
    }
    fn neighbours(&self, node: usize) -> &[usize] {
        Elasticity::neighbours(self, node)
    }
    fn stiffness(&self, dofs: &DofMap) -> SparseColMat<usize, f64> {
        Elasticity::stiffness(self, dofs)
    }
    fn apply(&self, u: &[f64]) -> Vec<f64> {
        Elasticity::apply(self, u)
    }
    fn check_rigid_motions(&self, fixed: &FixedSet) -> Result<(), FemError> {
        Elasticity::check_rigid_motions(self, fixed)
    }
}

/// Refuses a fixed set that leaves a rigid-body motion free in some connected part of the
/// mesh (`neighbours`: the node graph; `has_elements`: whether a node belongs to an element):
/// the 6 rigid modes restricted to the fixed dofs of each part must have full rank.
pub(crate) fn check_rigid_motions<'a>(
    positions: &[[f64; 3]],
    neighbours: impl Fn(usize) -> &'a [usize],
    has_elements: impl Fn(usize) -> bool,
    fixed: &FixedSet,
) -> Result<(), FemError> {
    if fixed.nodes() != positions.len() {
        return Err(FemError::FixedSetMismatch {
            fixed: fixed.nodes(),
            nodes: positions.len(),
        });
    }
    for (part, members) in components(positions.len(), neighbours, has_elements)
        .iter()
        .enumerate()
    {
        let centre = {
            let mut c = [0.0; 3];
            for &i in members {
                c = add(c, positions[i]);
            }
            scale(c, 1.0 / members.len() as f64)
        };
        let extent = members
            .iter()
            .map(|&i| norm(sub(positions[i], centre)))
            .fold(0.0, f64::max)
            .max(f64::MIN_POSITIVE);
        // Gram matrix G = R^T R of the rigid modes sampled at the fixed dofs.
        let mut gram = [[0.0; 6]; 6];
        for &i in members {
            let r = scale(sub(positions[i], centre), 1.0 / extent);
            for axis in 0..3 {
                if !fixed.is_fixed(i, axis) {
                    continue;
                }
                let row = rigid_mode_row(r, axis);
                for a in 0..6 {
                    for b in 0..6 {
                        gram[a][b] += row[a] * row[b];
                    }
                }
            }
        }
        if let Some(mode) = free_rigid_mode(gram) {
            return Err(FemError::RigidMotion(format!(
                "part {part} of the mesh ({} nodes, first node {}) can move freely: {}",
                members.len(),
                members[0],
                describe_mode(mode)
            )));
        }
    }
    Ok(())
}

/// Connected parts of the mesh (nodes sharing tetrahedra), each a sorted node list. Nodes
/// without tetrahedra are not listed.
pub(crate) fn components<'a>(
    n: usize,
    neighbours: impl Fn(usize) -> &'a [usize],
    has_elements: impl Fn(usize) -> bool,
) -> Vec<Vec<usize>> {
    let mut seen = vec![false; n];
    let mut parts = Vec::new();
    for start in 0..n {
        if seen[start] || !has_elements(start) {
            continue;
        }
        let mut stack = vec![start];
        seen[start] = true;
        let mut members = Vec::new();
        while let Some(i) = stack.pop() {
            members.push(i);
            for &j in neighbours(i) {
                if !seen[j] {
                    seen[j] = true;
                    stack.push(j);
                }
            }
        }
        members.sort_unstable();
        parts.push(members);
    }
    parts
}

/// Row of the rigid-mode matrix for component `axis` at relative position `r`: translations
/// along x, y, z, then rotations about x, y, z (`omega x r`).
fn rigid_mode_row(r: [f64; 3], axis: usize) -> [f64; 6] {
    let mut row = [0.0; 6];
    row[axis] = 1.0;
    for w in 0..3 {
        let mut omega = [0.0; 3];
        omega[w] = 1.0;
        row[3 + w] = cross(omega, r)[axis];
    }
    row
}

/// Returns a unit rigid mode (6 coefficients) in the near-null space of the Gram matrix, if any.
fn free_rigid_mode(gram: [[f64; 6]; 6]) -> Option<[f64; 6]> {
    let g = faer::Mat::<f64>::from_fn(6, 6, |i, j| gram[i][j]);
    let eig = g.self_adjoint_eigen(faer::Side::Lower).ok()?;
    let s = eig.S();
    let largest = s[5].max(f64::MIN_POSITIVE);
    (s[0] <= 1e-10 * largest).then(|| std::array::from_fn(|i| eig.U()[(i, 0)]))
}

fn describe_mode(mode: [f64; 6]) -> String {
    let t = [mode[0], mode[1], mode[2]];
    let w = [mode[3], mode[4], mode[5]];
    let fmt = |v: [f64; 3]| format!("({:.2}, {:.2}, {:.2})", v[0], v[1], v[2]);
    if norm(w) < 1e-6 {
        format!("translation along {}", fmt(t))
    } else if norm(t) < 1e-6 {
        format!("rotation about axis {}", fmt(w))
    } else {
        format!(
            "rigid motion with translation {} and rotation {}",
            fmt(t),
            fmt(w)
        )
    }
}

/// Node -> element incidence of elements with `N` nodes each.
pub(crate) fn incidence<const N: usize>(n: usize, tets: &[[usize; N]]) -> Csr {
    let mut ptr = vec![0usize; n + 1];
    for t in tets {
        for &v in t {
            ptr[v + 1] += 1;
        }
    }
    for i in 0..n {
        ptr[i + 1] += ptr[i];
    }
    let mut fill = ptr.clone();
    let mut idx = vec![0; ptr[n]];
    for (ti, t) in tets.iter().enumerate() {
        for &v in t {
            idx[fill[v]] = ti;
            fill[v] += 1;
        }
    }
    Csr { ptr, idx }
}

/// Two-ring of a symmetric one-ring graph: row `i` is the sorted union of the rows of its
/// one-ring neighbours.
fn two_ring(ring: &Csr) -> Csr {
    union_rows(ring.ptr.len() - 1, |i| {
        ring.row(i)
            .iter()
            .flat_map(|&j| ring.row(j).iter().copied())
    })
}

/// Node adjacency: row `i` is node `i` and every node of the elements around it.
pub(crate) fn adjacency<const N: usize>(node_tets: &Csr, tets: &[[usize; N]]) -> Csr {
    union_rows(node_tets.ptr.len() - 1, |i| {
        node_tets.row(i).iter().flat_map(|&t| tets[t])
    })
}

/// The graph whose row `i` is `i` together with `around(i)`, sorted and without repeats.
fn union_rows<I: Iterator<Item = usize>>(n: usize, around: impl Fn(usize) -> I + Sync) -> Csr {
    let rows: Vec<Vec<usize>> = (0..n)
        .into_par_iter()
        .map(|i| {
            let mut row: Vec<usize> = around(i).chain(std::iter::once(i)).collect();
            row.sort_unstable();
            row.dedup();
            row
        })
        .collect();
    let mut ptr = Vec::with_capacity(n + 1);
    ptr.push(0);
    let mut idx = Vec::new();
    for row in rows {
        idx.extend(row);
        ptr.push(idx.len());
    }
    Csr { ptr, idx }
}

/// The upper triangle of `K_ff` in CSC form from each node's sorted neighbours (itself
/// included) and its column blocks `K_mp` for the rows `m <= p` (see
/// `Elasticity::column_blocks`). Columns in parallel: each node's three columns only read
/// shared data, so there are no write conflicts.
pub(crate) fn assemble_upper<'a>(
    dofs: &DofMap,
    neighbours: impl Fn(usize) -> &'a [usize] + Sync,
    column_blocks: impl Fn(usize, &[usize]) -> Vec<Block3> + Sync,
) -> SparseColMat<usize, f64> {
    let n = dofs.nodes();
    // Per node: (row indices, values) of its up-to-three columns, concatenated.
    let columns: Vec<[(Vec<usize>, Vec<f64>); 3]> = (0..n)
        .into_par_iter()
        .map(|node| {
            let all = neighbours(node);
            let lower = &all[..all.partition_point(|&m| m <= node)];
            let blocks = column_blocks(node, lower);
            std::array::from_fn(|c| {
                let mut rows = Vec::new();
                let mut vals = Vec::new();
                if let Some(col) = dofs.free_dof(node, c) {
                    for (m, block) in lower.iter().zip(&blocks) {
                        for (cr, row_of_block) in block.iter().enumerate() {
                            match dofs.free_dof(*m, cr) {
                                Some(row) if row <= col => {
                                    rows.push(row);
                                    vals.push(row_of_block[c]);
                                }
                                _ => {}
                            }
                        }
                    }
                }
                (rows, vals)
            })
        })
        .collect();
    let nf = dofs.free_count();
    let mut col_ptr = Vec::with_capacity(nf + 1);
    col_ptr.push(0usize);
    let nnz: usize = columns.iter().flatten().map(|(r, _)| r.len()).sum();
    let mut row_idx = Vec::with_capacity(nnz);
    let mut values = Vec::with_capacity(nnz);
    for (node, cols) in columns.into_iter().enumerate() {
        for (c, (rows, vals)) in cols.into_iter().enumerate() {
            if dofs.free_dof(node, c).is_some() {
                row_idx.extend(rows);
                values.extend(vals);
                col_ptr.push(row_idx.len());
            }
        }
    }
    let symbolic = SymbolicSparseColMat::new_checked(nf, nf, col_ptr, None, row_idx);
    SparseColMat::new(symbolic, values)
}
