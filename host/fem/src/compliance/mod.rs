//! Compliance: the paper's "elementary deformations" (section 4-1) in compliance form.
//!
//! `C = K_ff^-1`; the 3x3 block `C_nk` maps a force at node `k` to the displacement of node `n`.
//! The paper stores `T^u_nk = C_nk C_kk^-1` and `T^f_k = C_kk^-1`, and its mutual-influence
//! matrix `M` (eq. 8) is `C_SS` with block rows scaled by `C_kk^-1`; storing `C` (symmetric)
//! holds the same information in half the space.
//!
//! One sparse Cholesky factorisation of `K_ff` (nested-dissection ordering, supernodal) replaces
//! the paper's `3m` conjugate-gradient solves; a sparse forward substitution restricted to the
//! contact candidates then gives all their blocks at once (module `gram`). A tool load spread
//! over several nodes has the patch compliance `B K_ff^-1 B^T` ([`Compliance::patch_compliances`],
//! module `patch`).

mod gram;
mod patch;
pub use patch::largest_difference;

pub use patch::CHUNK_BYTES;

use crate::elasticity::{DofMap, Elasticity, FemError, FixedSet, Stiffness};
use crate::ordering::{DofPermutation, Ordering, permutation};
use crate::progress::Progress;
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::solvers::Solve;
use faer::perm::PermRef;
use faer::sparse::linalg::SupernodalThreshold;
use faer::sparse::linalg::cholesky::{
    CholeskySymbolicParams, LltRef, SymbolicCholesky, SymmetricOrdering,
    factorize_symbolic_cholesky,
};
use faer::sparse::{SparseColMat, Triplet};
use faer::{Conj, Mat, Par, Side};

/// A 3x3 block, row-major, in m/N for compliance and N/m for stiffness.
pub type Block3 = [[f64; 3]; 3];

/// Errors of the compliance precompute and the imposed-displacement solves.
#[derive(Debug, thiserror::Error)]
pub enum ComplianceError {
    /// Problem in the elastic model or the fixed set.
    #[error(transparent)]
    Fem(#[from] FemError),
    /// The factorisation failed (out of memory or a non positive definite `K_ff`).
    #[error("sparse Cholesky factorisation of K_ff failed: {0}")]
    Factorisation(String),
    /// A requested node does not exist.
    #[error("node {node} does not exist (the mesh has {nodes} nodes)")]
    NoSuchNode {
        /// Requested id.
        node: usize,
        /// Number of nodes.
        nodes: usize,
    },
    /// A contact node with a fixed component cannot take an imposed displacement.
    #[error("node {0} has fixed components, so no displacement can be imposed on it")]
    FixedContactNode(usize),
    /// Two contact nodes given twice, or a singular `C_SS`.
    #[error("the contact set is degenerate: {0}")]
    DegenerateContact(String),
    /// A patch load with no node, or a non-finite weight.
    #[error("patch load {load} is invalid: {reason}")]
    BadLoad {
        /// Index of the load in the request.
        load: usize,
        /// What is wrong with it.
        reason: String,
    },
}

/// Size and cost figures of a factorisation, for reports and benchmarks.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FactorStats {
    /// Order of `K_ff`.
    pub free_dofs: usize,
    /// Stored non-zeros of `K_ff` (upper triangle).
    pub nnz_k: usize,
    /// Stored entries of the Cholesky factor `L` (supernodal storage may include explicit zeros).
    pub nnz_l: usize,
}

/// `K_ff = L L^T` with a fill-reducing permutation, and the free-dof numbering.
pub struct Compliance {
    dofs: DofMap,
    symbolic: SymbolicCholesky<usize>,
    values: Vec<f64>,
    stats: FactorStats,
}

impl std::fmt::Debug for Compliance {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Compliance")
            .field("stats", &self.stats)
            .finish()
    }
}

impl Compliance {
    /// Assembles and factorises `K_ff` for `fixed`, after refusing fixed sets that leave rigid
    /// motions. Uses all rayon threads.
    pub fn factorize(body: &impl Stiffness, fixed: &FixedSet) -> Result<Self, ComplianceError> {
        Self::factorize_ordered(body, fixed, Ordering::default())
    }

    /// [`Compliance::factorize`] with a chosen fill-reducing ordering.
    pub fn factorize_ordered(
        body: &impl Stiffness,
        fixed: &FixedSet,
        ordering: Ordering,
    ) -> Result<Self, ComplianceError> {
        body.check_rigid_motions(fixed)?;
        let dofs = DofMap::new(fixed);
        let perm = permutation(ordering, body, &dofs).map_err(ComplianceError::Factorisation)?;
        let k = body.stiffness(&dofs);
        Self::factorize_matrix(dofs, &k, perm.as_ref())
    }

    /// Factorises an assembled upper-triangular `K_ff` (see [`Elasticity::stiffness`]) with the
    /// given dof permutation, or faer's AMD when `None`.
    pub fn factorize_matrix(
        dofs: DofMap,
        k: &SparseColMat<usize, f64>,
        perm: Option<&DofPermutation>,
    ) -> Result<Self, ComplianceError> {
        let fail = |e: &dyn std::fmt::Display| ComplianceError::Factorisation(e.to_string());
        let ordering = match perm {
            None => SymmetricOrdering::Amd,
            Some(p) => SymmetricOrdering::Custom(PermRef::new_checked(
                &p.forward,
                &p.inverse,
                dofs.free_count(),
            )),
        };
        let symbolic = factorize_symbolic_cholesky(
            k.symbolic(),
            Side::Upper,
            ordering,
            // Always supernodal: the Gram method of [`Compliance::blocks`] walks supernodes.
            CholeskySymbolicParams {
                supernodal_flop_ratio_threshold: SupernodalThreshold::FORCE_SUPERNODAL,
                ..Default::default()
            },
        )
        .map_err(|e| fail(&format!("{e:?}")))?;
        let mut values = Vec::new();
        values
            .try_reserve_exact(symbolic.len_val())
            .map_err(|_| fail(&"out of memory for the factor"))?;
        values.resize(symbolic.len_val(), 0.0);
        let par = Par::rayon(0);
        let mut mem = MemBuffer::try_new(
            symbolic.factorize_numeric_llt_scratch::<f64>(par, Default::default()),
        )
        .map_err(|_| fail(&"out of memory for the factorisation workspace"))?;
        symbolic
            .factorize_numeric_llt(
                &mut values,
                k.as_ref(),
                Side::Upper,
                Default::default(),
                par,
                MemStack::new(&mut mem),
                Default::default(),
            )
            .map_err(|e| {
                fail(&format!(
                    "{e:?}; K_ff is not positive definite (check the fixed set and the mesh)"
                ))
            })?;
        let stats = FactorStats {
            free_dofs: dofs.free_count(),
            nnz_k: k.compute_nnz(),
            nnz_l: symbolic.len_val(),
        };
        Ok(Self {
            dofs,
            symbolic,
            values,
            stats,
        })
    }

    /// Size figures of the factorisation.
    pub fn stats(&self) -> FactorStats {
        self.stats
    }

    /// The free-dof numbering.
    pub fn dofs(&self) -> &DofMap {
        &self.dofs
    }

    /// Solves `K_ff X = B` in place for a block of right-hand sides (free-dof rows).
    pub fn solve_in_place(&self, rhs: faer::MatMut<'_, f64>, par: Par) {
        let llt = LltRef::new(&self.symbolic, &self.values);
        let mut mem = MemBuffer::new(
            self.symbolic
                .solve_in_place_scratch::<f64>(rhs.ncols(), par),
        );
        llt.solve_in_place_with_conj(Conj::No, rhs, par, MemStack::new(&mut mem));
    }

    /// Node-major displacement field (length `3 N`, zeros at fixed dofs) for node-major forces.
    pub fn displacement(&self, forces: &[f64]) -> Vec<f64> {
        let mut rhs = Mat::<f64>::zeros(self.dofs.free_count(), 1);
        for node in 0..self.dofs.nodes() {
            for c in 0..3 {
                if let Some(d) = self.dofs.free_dof(node, c) {
                    rhs[(d, 0)] = forces[3 * node + c];
                }
            }
        }
        self.solve_in_place(rhs.as_mut(), Par::rayon(0));
        self.dofs
            .expand(rhs.col(0).try_as_col_major().map_or(&[], |c| c.as_slice()))
    }

    fn check_nodes(&self, nodes: &[usize]) -> Result<(), ComplianceError> {
        let n = self.dofs.nodes();
        match nodes.iter().find(|&&k| k >= n) {
            Some(&node) => Err(ComplianceError::NoSuchNode { node, nodes: n }),
            None => Ok(()),
        }
    }

    /// The blocks `C(nodes[a], nodes[b])` for every pair, `result[a][b]`, row-major in m/N,
    /// by a sparse forward substitution and a Gram product (module `gram`). A requested node's
    /// fixed components give zero rows and columns. The progress, if any, counts
    /// supernodes.
    pub fn blocks(
        &self,
        nodes: &[usize],
        progress: Option<&dyn Progress>,
    ) -> Result<Vec<Vec<Block3>>, ComplianceError> {
        self.check_request(nodes)?;
        let m = nodes.len();
        let mut out: Vec<Vec<Block3>> = (0..m).map(|_| vec![[[0.0; 3]; 3]; m]).collect();
        if self.dofs.free_count() > 0 {
            let layout = gram::Layout::new(&self.dofs, nodes);
            gram::gram_blocks(&self.symbolic, &self.values, &layout, &mut out, progress)?;
        }
        // Mirror the upper triangle (a <= b, and i <= j within diagonal blocks).
        for a in 0..m {
            let (head, tail) = out.split_at_mut(a);
            let row = &mut tail[0];
            for (b, other) in head.iter().enumerate() {
                row[b] = transpose(other[a]);
            }
            row[a] = symmetric_from_upper(row[a]);
        }
        Ok(out)
    }

    /// The blocks `C(nodes[a], nodes[b])` for the pairs of nodes at most `radius` metres
    /// apart (`positions[a]` is the position of `nodes[a]`), each node with itself included:
    /// `result[a]` lists `(b, C(nodes[a], nodes[b]))` sorted by `b`. Same method and cost as
    /// [`Compliance::blocks`], but memory grows with the pairs kept, not with `|nodes|^2`: this
    /// is what a bank's truncated neighbour couplings need.
    pub fn blocks_within(
        &self,
        nodes: &[usize],
        positions: &[[f64; 3]],
        radius: f64,
        progress: Option<&dyn Progress>,
    ) -> Result<Vec<Vec<(usize, Block3)>>, ComplianceError> {
        self.check_request(nodes)?;
        if positions.len() != nodes.len() || radius.is_nan() || radius < 0.0 {
            return Err(ComplianceError::DegenerateContact(format!(
                "{} positions for {} nodes, radius {radius}",
                positions.len(),
                nodes.len()
            )));
        }
        let upper = pairs_within(positions, radius);
        let mut out: Vec<Vec<(usize, Block3)>> = upper
            .iter()
            .map(|row| row.iter().map(|&b| (b, [[0.0; 3]; 3])).collect())
            .collect();
        if self.dofs.free_count() > 0 {
            let layout = gram::Layout::new(&self.dofs, nodes);
            gram::gram_blocks(&self.symbolic, &self.values, &layout, &mut out, progress)?;
        }
        // Both directions: add the transposes below the diagonal, then sort each row.
        let mut lower: Vec<Vec<(usize, Block3)>> = vec![Vec::new(); nodes.len()];
        for (a, row) in out.iter_mut().enumerate() {
            for (b, block) in row.iter_mut() {
                if *b == a {
                    *block = symmetric_from_upper(*block);
                } else {
                    lower[*b].push((a, transpose(*block)));
                }
            }
        }
        for (row, extra) in out.iter_mut().zip(lower) {
            row.extend(extra);
            row.sort_unstable_by_key(|e| e.0);
        }
        Ok(out)
    }

    /// Refuses unknown or repeated node ids.
    fn check_request(&self, nodes: &[usize]) -> Result<(), ComplianceError> {
        self.check_nodes(nodes)?;
        let mut requested = vec![false; self.dofs.nodes()];
        for &k in nodes {
            if std::mem::replace(&mut requested[k], true) {
                return Err(ComplianceError::DegenerateContact(format!(
                    "node {k} is requested twice"
                )));
            }
        }
        Ok(())
    }
}

/// For each point `a`, the sorted indices `b >= a` of the points within `radius` (a uniform
/// grid of cell `radius`, so each query looks at 27 cells).
fn pairs_within(positions: &[[f64; 3]], radius: f64) -> Vec<Vec<usize>> {
    use std::collections::HashMap;
    let cell = |p: &[f64; 3]| -> [i64; 3] {
        std::array::from_fn(|i| {
            if radius > 0.0 {
                (p[i] / radius).floor() as i64
            } else {
                0
            }
        })
    };
    let mut grid: HashMap<[i64; 3], Vec<usize>> = HashMap::new();
    for (a, p) in positions.iter().enumerate() {
        grid.entry(cell(p)).or_default().push(a);
    }
    let r2 = radius * radius;
    positions
        .iter()
        .enumerate()
        .map(|(a, p)| {
            let c = cell(p);
            let mut near = Vec::new();
            for dx in -1..=1 {
                for dy in -1..=1 {
                    for dz in -1..=1 {
                        if let Some(list) = grid.get(&[c[0] + dx, c[1] + dy, c[2] + dz]) {
                            near.extend(list.iter().copied().filter(|&b| {
                                b >= a
                                    && (0..3)
                                        .map(|i| (positions[b][i] - p[i]).powi(2))
                                        .sum::<f64>()
                                        <= r2
                            }));
                        }
                    }
                }
            }
            near.sort_unstable();
            near.dedup();
            near
        })
        .collect()
}

/// The symmetric block whose upper triangle (`i <= j`) is that of `b`.
fn symmetric_from_upper(b: Block3) -> Block3 {
    std::array::from_fn(|i| std::array::from_fn(|j| b[i.min(j)][i.max(j)]))
}

/// Transpose of a 3x3 block.
pub fn transpose(b: Block3) -> Block3 {
    std::array::from_fn(|i| std::array::from_fn(|j| b[j][i]))
}

/// Forces and displacements of an imposed-displacement solve.
#[derive(Debug, Clone, PartialEq)]
pub struct ImposedSolution {
    /// Force at each contact node (N), in the order of the contact set.
    pub forces: Vec<[f64; 3]>,
}

/// Compliance form of the paper's eq. 2 / eq. 8: with displacements `u*_S` imposed on the
/// contact set `S` and every other free node force-free, the contact forces are
/// `f_S = C_SS^-1 u*_S`. `c_ss[a][b]` is `C(S_a, S_b)`. Dense Cholesky on `3|S| x 3|S|`.
pub fn contact_forces(
    c_ss: &[Vec<Block3>],
    imposed: &[[f64; 3]],
) -> Result<ImposedSolution, ComplianceError> {
    let m = imposed.len();
    if c_ss.len() != m || c_ss.iter().any(|row| row.len() != m) {
        return Err(ComplianceError::DegenerateContact(format!(
            "C_SS is {}x? blocks but {m} displacements were imposed",
            c_ss.len()
        )));
    }
    let c = Mat::<f64>::from_fn(3 * m, 3 * m, |i, j| c_ss[i / 3][j / 3][i % 3][j % 3]);
    let llt = c.llt(Side::Lower).map_err(|e| {
        ComplianceError::DegenerateContact(format!("C_SS is not positive definite ({e:?})"))
    })?;
    let u = Mat::<f64>::from_fn(3 * m, 1, |i, _| imposed[i / 3][i % 3]);
    let f = llt.solve(&u);
    Ok(ImposedSolution {
        forces: (0..m)
            .map(|a| [f[(3 * a, 0)], f[(3 * a + 1, 0)], f[(3 * a + 2, 0)]])
            .collect(),
    })
}

/// Superposition (the paper's eq. 9 in compliance form): `u_n = sum_k C_nk f_k`.
pub fn superpose(c_ns: &[Block3], forces: &[[f64; 3]]) -> [f64; 3] {
    let mut u = [0.0; 3];
    for (c, f) in c_ns.iter().zip(forces) {
        for (r, ur) in u.iter_mut().enumerate() {
            *ur += c[r][0] * f[0] + c[r][1] * f[1] + c[r][2] * f[2];
        }
    }
    u
}

/// The paper's eq. 2 solved as written: the saddle-point system
/// `[K_ff Kbar; Kbar^T 0] [u; lambda] = [0; u*]` (appendix A, Lagrange multipliers), by a
/// sparse LU factorisation. Returns the contact forces `f = -lambda` (the paper: "lambda_i are
/// equal to the opposite of the force ... to impose u_i = u*_i").
///
/// This is the reference the compliance form is checked against; it is much slower than
/// [`contact_forces`] and only meant for tests and audits.
pub fn lagrange_forces(
    body: &Elasticity,
    fixed: &FixedSet,
    contact: &[usize],
    imposed: &[[f64; 3]],
) -> Result<ImposedSolution, ComplianceError> {
    let dofs = DofMap::new(fixed);
    let k = body.stiffness(&dofs);
    let nf = dofs.free_count();
    let mut constrained = Vec::with_capacity(3 * contact.len());
    for &node in contact {
        if node >= dofs.nodes() {
            return Err(ComplianceError::NoSuchNode {
                node,
                nodes: dofs.nodes(),
            });
        }
        for c in 0..3 {
            constrained.push(
                dofs.free_dof(node, c)
                    .ok_or(ComplianceError::FixedContactNode(node))?,
            );
        }
    }
    let n = nf + constrained.len();
    let mut triplets = Vec::with_capacity(2 * k.compute_nnz() + 2 * constrained.len());
    for j in 0..nf {
        for (i, &v) in k.row_idx_of_col(j).zip(k.val_of_col(j)) {
            triplets.push(Triplet::new(i, j, v));
            if i != j {
                triplets.push(Triplet::new(j, i, v));
            }
        }
    }
    for (l, &d) in constrained.iter().enumerate() {
        triplets.push(Triplet::new(d, nf + l, 1.0));
        triplets.push(Triplet::new(nf + l, d, 1.0));
    }
    let a = SparseColMat::<usize, f64>::try_new_from_triplets(n, n, &triplets)
        .map_err(|e| ComplianceError::Factorisation(format!("{e:?}")))?;
    let lu = a
        .sp_lu()
        .map_err(|e| ComplianceError::Factorisation(format!("{e:?}")))?;
    let mut rhs = Mat::<f64>::zeros(n, 1);
    for (a, u) in imposed.iter().enumerate() {
        for c in 0..3 {
            rhs[(nf + 3 * a + c, 0)] = u[c];
        }
    }
    lu.solve_in_place(rhs.as_mut());
    Ok(ImposedSolution {
        forces: (0..contact.len())
            .map(|a| std::array::from_fn(|c| -rhs[(nf + 3 * a + c, 0)]))
            .collect(),
    })
}

/// Static solve with prescribed values on the held dofs: `u = u_held` where `held` is fixed,
/// `K u = 0` at every other dof. Returns `(u, K u)`: the field and the nodal forces, which are
/// the reactions at the held dofs. `K u` is computed element by element, independently of the
/// assembled matrix.
pub fn solve_prescribed(
    body: &impl Stiffness,
    held: &FixedSet,
    u_held: &[f64],
) -> Result<(Vec<f64>, Vec<f64>), ComplianceError> {
    let n = body.nodes();
    let mut u: Vec<f64> = (0..3 * n)
        .map(|d| {
            if held.is_fixed(d / 3, d % 3) {
                u_held[d]
            } else {
                0.0
            }
        })
        .collect();
    let k_u = body.apply(&u);
    let inner = Compliance::factorize(body, held)?;
    let dofs = inner.dofs();
    let mut rhs = Mat::<f64>::zeros(dofs.free_count(), 1);
    for (d, ku) in k_u.iter().enumerate() {
        if let Some(f) = dofs.free_dof(d / 3, d % 3) {
            rhs[(f, 0)] = -ku;
        }
    }
    inner.solve_in_place(rhs.as_mut(), Par::rayon(0));
    for (d, ud) in u.iter_mut().enumerate() {
        if let Some(f) = dofs.free_dof(d / 3, d % 3) {
            *ud = rhs[(f, 0)];
        }
    }
    let forces = body.apply(&u);
    Ok((u, forces))
}

/// Independent reference for [`contact_forces`]: the imposed displacements as Dirichlet
/// conditions. The contact nodes join the fixed set, the other free dofs are solved force-free
/// and the contact forces are the reactions `(K u)_S`.
pub fn dirichlet_forces(
    body: &Elasticity,
    fixed: &FixedSet,
    contact: &[usize],
    imposed: &[[f64; 3]],
) -> Result<ImposedSolution, ComplianceError> {
    let mut held = fixed.clone();
    let mut u_held = vec![0.0; 3 * body.nodes()];
    for (&node, u) in contact.iter().zip(imposed) {
        if (0..3).any(|c| fixed.is_fixed(node, c)) {
            return Err(ComplianceError::FixedContactNode(node));
        }
        held.fix_node(node)?;
        u_held[3 * node..3 * node + 3].copy_from_slice(u);
    }
    let (_, reactions) = solve_prescribed(body, &held, &u_held)?;
    Ok(ImposedSolution {
        forces: contact
            .iter()
            .map(|&k| [reactions[3 * k], reactions[3 * k + 1], reactions[3 * k + 2]])
            .collect(),
    })
}
