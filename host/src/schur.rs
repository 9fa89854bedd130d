//! Compliance blocks of a node set by a Schur complement: the paper's "elementary deformations"
//! (section 4-1) in compliance form, for all requested nodes at once.
//!
//! The paper precomputes, for every surface node `k`, the deformation caused by a unit
//! displacement of `k` (`3m` iterative solves). In compliance form this is the column block
//! `C_{.k}` of `C = K_ff^-1`; the simulator needs `C(n, k)` for every pair of contact candidates
//! `n, k` in a set `R`, i.e. the dense `3|R| x 3|R|` block `C_RR` (see [`crate::compliance`]).
//!
//! [`crate::compliance::Compliance::blocks`] gets it by forward and backward sparse solves with
//! `3|R|` right-hand sides. Here the free dofs of `R` are ordered *last*: with `I` every other
//! free dof, `K_ff = [K_II K_IR; K_RI K_RR]` and its Cholesky factor is
//! `L = [L_II 0; L_RI L_RR]`. Then `S = K_RR - K_RI K_II^-1 K_IR = L_RR L_RR^T` is the Schur
//! complement of `K_II` (the condensed stiffness of `R`), and the block-inverse formula gives
//!
//! ```text
//! C_RR = (K_ff^-1)_RR = S^-1 = L_RR^-T L_RR^-1 = X^T X,   X = L_RR^-1.
//! ```
//!
//! Steps: a fill-reducing ordering (AMD) of `K_II` alone, the free dofs of `R` appended in the
//! order of the request (x, y, z per node); one sparse Cholesky factorisation with that
//! ordering (its trailing dense block is the Cholesky factor of `S`); `L_RR` copied out of the
//! factor (which is then freed); the dense triangular inverse `X`; and `X^T X` by column panels,
//! each a triangular-times-rectangular product, scattered into the 3x3 blocks. The dense work is
//! about `(3|R|)^3` flops in all (a third each for the factorisation of `S`, the inverse and the
//! product), done by faer's blocked, parallel kernels; the sparse solves it replaces touch the
//! whole factor `L` for every one of the `3|R|` columns.
//!
//! Memory: besides the sparse factor, two dense `3|R| x 3|R|` matrices at a time (`L_RR` and
//! `X`, then `X` and the result), each `72 |R|^2` bytes.
//!
//! A requested node's fixed components are not free dofs: their rows and columns of the blocks
//! are zero, as in [`crate::compliance::Compliance::blocks`].

use crate::compliance::{Block3, ComplianceError};
use crate::fem::{DofMap, Elasticity, FemError, FixedSet};
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::matmul::triangular::{BlockStructure, matmul};
use faer::linalg::triangular_inverse::invert_lower_triangular;
use faer::perm::PermRef;
use faer::sparse::SymbolicSparseColMatRef;
use faer::sparse::linalg::SupernodalThreshold;
use faer::sparse::linalg::amd;
use faer::sparse::linalg::cholesky::supernodal::SupernodalLltRef;
use faer::sparse::linalg::cholesky::{
    CholeskySymbolicParams, SymbolicCholeskyRaw, SymmetricOrdering, factorize_symbolic_cholesky,
};
use faer::{Accum, Mat, Par, Side};

/// Columns of `C_RR` computed per panel of the final product (a multiple of 3).
const PANEL: usize = 384;

/// The blocks `C(nodes[a], nodes[b])` of `C = K_ff^-1` for every pair, `result[a][b]`,
/// row-major in m/N: the same as
/// `Compliance::factorize(body, fixed)?.blocks(nodes, None)`, by the Schur complement of the
/// requested nodes (see the module documentation). Uses all rayon threads.
///
/// Errors: a fixed set that leaves rigid motions ([`ComplianceError::Fem`]), a node id out of
/// range ([`ComplianceError::NoSuchNode`]), a node requested twice
/// ([`ComplianceError::DegenerateContact`]), a failed factorisation
/// ([`ComplianceError::Factorisation`]).
pub fn compliance_blocks(
    body: &Elasticity,
    fixed: &FixedSet,
    nodes: &[usize],
) -> Result<Vec<Vec<Block3>>, ComplianceError> {
    compliance_blocks_with(body, fixed, nodes, SupernodalThreshold::AUTO)
}

/// [`compliance_blocks`] with a choice of simplicial or supernodal sparse factorisation.
fn compliance_blocks_with(
    body: &Elasticity,
    fixed: &FixedSet,
    nodes: &[usize],
    supernodal: SupernodalThreshold,
) -> Result<Vec<Vec<Block3>>, ComplianceError> {
    let n_nodes = body.nodes();
    if fixed.nodes() != n_nodes {
        // A fixed set built for another mesh.
        return Err(FemError::NoSuchNode {
            node: fixed.nodes().max(n_nodes) - 1,
            nodes: fixed.nodes().min(n_nodes),
        }
        .into());
    }
    body.check_rigid_motions(fixed)?;
    let mut requested = vec![false; n_nodes];
    for &k in nodes {
        let seen = requested.get_mut(k).ok_or(ComplianceError::NoSuchNode {
            node: k,
            nodes: n_nodes,
        })?;
        if *seen {
            return Err(ComplianceError::DegenerateContact(format!(
                "node {k} is requested twice"
            )));
        }
        *seen = true;
    }

    let dofs = DofMap::new(fixed);
    let layout = Layout::new(&dofs, nodes);
    let l_rr = factor_trailing_block(body, &dofs, &layout, supernodal)?;
    drop(dofs);
    Ok(inverse_blocks(l_rr, &layout, nodes.len()))
}

/// Where the requested nodes' free dofs go in the Schur ordering.
struct Layout {
    /// Free-dof ids of `R`, in request order (x, y, z per node; fixed components skipped).
    r_dofs: Vec<usize>,
    /// For each index of `R`: (position in the request, component).
    owner: Vec<(usize, usize)>,
}

impl Layout {
    fn new(dofs: &DofMap, nodes: &[usize]) -> Self {
        let mut r_dofs = Vec::with_capacity(3 * nodes.len());
        let mut owner = Vec::with_capacity(3 * nodes.len());
        for (a, &k) in nodes.iter().enumerate() {
            for c in 0..3 {
                if let Some(d) = dofs.free_dof(k, c) {
                    r_dofs.push(d);
                    owner.push((a, c));
                }
            }
        }
        Self { r_dofs, owner }
    }
}

/// Assembles `K_ff`, orders `R` last and factorises; returns the dense lower-triangular `L_RR`.
fn factor_trailing_block(
    body: &Elasticity,
    dofs: &DofMap,
    layout: &Layout,
    supernodal: SupernodalThreshold,
) -> Result<Mat<f64>, ComplianceError> {
    let fail = |e: &dyn std::fmt::Display| ComplianceError::Factorisation(e.to_string());
    let t0 = std::time::Instant::now();
    let k = body.stiffness(dofs);
    let nf = dofs.free_count();
    let n_r = layout.r_dofs.len();
    let n_i = nf - n_r;

    // Fill-reducing ordering of K_II: AMD on the pattern of K_ff with R's rows and columns
    // removed (I keeps the free-dof order, so the upper triangle stays upper).
    let mut in_r = vec![false; nf];
    for &d in &layout.r_dofs {
        in_r[d] = true;
    }
    let i_dofs: Vec<usize> = (0..nf).filter(|&d| !in_r[d]).collect();
    let mut compact = vec![usize::MAX; nf];
    for (ci, &d) in i_dofs.iter().enumerate() {
        compact[d] = ci;
    }
    let mut col_ptr = Vec::with_capacity(n_i + 1);
    col_ptr.push(0usize);
    let mut row_idx = Vec::new();
    for &j in &i_dofs {
        row_idx.extend(
            k.row_idx_of_col(j)
                .filter(|&i| !in_r[i])
                .map(|i| compact[i]),
        );
        col_ptr.push(row_idx.len());
    }
    drop(compact);
    let k_ii = SymbolicSparseColMatRef::new_checked(n_i, n_i, &col_ptr, None, &row_idx);
    let mut amd_fwd = vec![0usize; n_i];
    let mut amd_inv = vec![0usize; n_i];
    {
        let mut mem = MemBuffer::try_new(amd::order_maybe_unsorted_scratch::<usize>(
            n_i,
            row_idx.len(),
        ))
        .map_err(|_| fail(&"out of memory for the ordering"))?;
        amd::order_maybe_unsorted(
            &mut amd_fwd,
            &mut amd_inv,
            k_ii,
            amd::Control::default(),
            MemStack::new(&mut mem),
        )
        .map_err(|e| fail(&format!("AMD ordering of K_II: {e:?}")))?;
    }
    drop((col_ptr, row_idx, amd_inv));

    // Full ordering (new position -> free dof): I by AMD, then R in request order.
    let fwd: Vec<usize> = amd_fwd
        .iter()
        .map(|&p| i_dofs[p])
        .chain(layout.r_dofs.iter().copied())
        .collect();
    drop((amd_fwd, i_dofs, in_r));
    let mut inv = vec![0usize; nf];
    for (new, &old) in fwd.iter().enumerate() {
        inv[old] = new;
    }
    let perm = PermRef::new_checked(&fwd, &inv, nf);
    let symbolic = factorize_symbolic_cholesky(
        k.symbolic(),
        Side::Upper,
        SymmetricOrdering::Custom(perm),
        CholeskySymbolicParams {
            supernodal_flop_ratio_threshold: supernodal,
            ..Default::default()
        },
    )
    .map_err(|e| fail(&format!("{e:?}")))?;
    drop((fwd, inv));
    eprintln!(
        "TIMING assemble+amd+symbolic {:.3}",
        t0.elapsed().as_secs_f64()
    );
    let t0 = std::time::Instant::now();

    let mut values = Vec::new();
    values
        .try_reserve_exact(symbolic.len_val())
        .map_err(|_| fail(&"out of memory for the factor"))?;
    values.resize(symbolic.len_val(), 0.0);
    let par = Par::rayon(0);
    {
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
    }
    drop(k);
    eprintln!(
        "TIMING numeric {:.3} len_val {}",
        t0.elapsed().as_secs_f64(),
        values.len()
    );
    if let SymbolicCholeskyRaw::Supernodal(sym) = symbolic.raw() {
        let ns = sym.n_supernodes();
        let b = sym.supernode_begin();
        eprintln!(
            "TIMING last supernodes {:?} n_i {}",
            &b[ns.saturating_sub(4)..],
            n_i
        );
    }
    let t0 = std::time::Instant::now();

    // L_RR: the trailing n_r x n_r block of L (lower triangle).
    let mut l_rr = Mat::<f64>::zeros(n_r, n_r);
    match symbolic.raw() {
        SymbolicCholeskyRaw::Supernodal(sym) => {
            let llt = SupernodalLltRef::new(sym, &values);
            for s in (0..sym.n_supernodes()).rev() {
                let sn = llt.supernode(s);
                let (start, val, pattern) = (sn.start(), sn.val(), sn.pattern());
                let width = val.ncols();
                if start + width <= n_i {
                    // Supernodes are contiguous column ranges in increasing order.
                    break;
                }
                for jj in n_i.saturating_sub(start)..width {
                    let j = start + jj - n_i;
                    for ii in jj..val.nrows() {
                        let row = if ii < width {
                            start + ii
                        } else {
                            pattern[ii - width]
                        };
                        l_rr[(row - n_i, j)] = val[(ii, jj)];
                    }
                }
            }
        }
        SymbolicCholeskyRaw::Simplicial(sym) => {
            let factor = sym.factor();
            for j in n_i..nf {
                for (i, &v) in factor.row_idx_of_col(j).zip(&values[factor.col_range(j)]) {
                    if i >= j {
                        l_rr[(i - n_i, j - n_i)] = v;
                    }
                }
            }
        }
    }
    eprintln!("TIMING extract {:.3}", t0.elapsed().as_secs_f64());
    Ok(l_rr)
}

/// `C_RR = X^T X` with `X = L_RR^-1`, scattered into `m x m` blocks (zeros at fixed components).
fn inverse_blocks(l_rr: Mat<f64>, layout: &Layout, m: usize) -> Vec<Vec<Block3>> {
    let n = l_rr.nrows();
    let par = Par::rayon(0);
    let mut x = Mat::<f64>::zeros(n, n);
    let t0 = std::time::Instant::now();
    invert_lower_triangular(x.as_mut(), l_rr.as_ref(), par);
    eprintln!("TIMING inverse {:.3}", t0.elapsed().as_secs_f64());
    let t0 = std::time::Instant::now();
    let mut tm = 0.0;
    drop(l_rr);

    let mut out = vec![vec![[[0.0; 3]; 3]; m]; m];
    let mut panel = Mat::<f64>::zeros(n, PANEL.min(n));
    for a in (0..n).step_by(PANEL) {
        let b = (a + PANEL).min(n);
        let w = b - a;
        // Columns a..b of C, rows a..n: C[i, j] = sum_{k >= max(i, j)} X[k, i] X[k, j].
        let mut p = panel.as_mut().submatrix_mut(0, 0, n - a, w);
        let (mut top, mut bottom) = p.as_mut().split_at_row_mut(w);
        let x_diag = x.as_ref().submatrix(a, a, w, w);
        let x_below = x.as_ref().submatrix(b, a, n - b, w);
        matmul(
            top.as_mut(),
            BlockStructure::TriangularLower,
            Accum::Replace,
            x_diag.transpose(),
            BlockStructure::TriangularUpper,
            x_diag,
            BlockStructure::TriangularLower,
            1.0,
            par,
        );
        if b < n {
            matmul(
                top.as_mut(),
                BlockStructure::TriangularLower,
                Accum::Add,
                x_below.transpose(),
                BlockStructure::Rectangular,
                x_below,
                BlockStructure::Rectangular,
                1.0,
                par,
            );
            let x_trail = x.as_ref().submatrix(b, b, n - b, n - b);
            matmul(
                bottom.as_mut(),
                BlockStructure::Rectangular,
                Accum::Replace,
                x_trail.transpose(),
                BlockStructure::TriangularUpper,
                x_below,
                BlockStructure::Rectangular,
                1.0,
                par,
            );
        }
        tm += t0.elapsed().as_secs_f64();
        let p = p.as_ref();
        for jj in 0..w {
            let (pj, cj) = layout.owner[a + jj];
            for ii in jj..n - a {
                let (pi, ci) = layout.owner[a + ii];
                let v = p[(ii, jj)];
                out[pi][pj][ci][cj] = v;
                out[pj][pi][cj][ci] = v;
            }
        }
    }
    eprintln!("TIMING product+scatter {:.3}", t0.elapsed().as_secs_f64());
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::compliance::Compliance;
    use crate::fem::Material;
    use crate::mesh::structured::box_mesh;

    /// Simplicial and supernodal factors give the same blocks as the column solves.
    #[test]
    fn both_factor_kinds_match_column_solves() {
        let mesh = box_mesh([0.04, 0.03, 0.02], [5, 4, 3]);
        let body = Elasticity::new(&mesh, Material::new(3.0e3, 0.45).unwrap()).unwrap();
        let mut fixed = FixedSet::none(mesh.nodes.len());
        fixed
            .fix_box(&mesh, [-1.0, -1.0, -1.0, 1.0, 1.0, 1e-9], [true; 3])
            .unwrap();
        fixed
            .fix_box(
                &mesh,
                [-1.0, -1.0, -1.0, 1e-9, 1.0, 1.0],
                [true, false, false],
            )
            .unwrap();
        // Every other node, in reverse: interior, top, partly and fully fixed ones.
        let nodes: Vec<usize> = (0..mesh.nodes.len()).rev().step_by(2).collect();
        let reference = Compliance::factorize(&body, &fixed)
            .unwrap()
            .blocks(&nodes, None)
            .unwrap();
        let scale = reference
            .iter()
            .flatten()
            .flatten()
            .flatten()
            .fold(0.0f64, |s, v| s.max(v.abs()));
        for kind in [
            SupernodalThreshold::FORCE_SIMPLICIAL,
            SupernodalThreshold::FORCE_SUPERNODAL,
        ] {
            let got = compliance_blocks_with(&body, &fixed, &nodes, kind).unwrap();
            let diff = got
                .iter()
                .flatten()
                .flatten()
                .flatten()
                .zip(reference.iter().flatten().flatten().flatten())
                .fold(0.0f64, |s, (a, b)| s.max((a - b).abs()));
            assert!(diff <= 1e-10 * scale, "{kind:?}: {diff:e} vs {scale:e}");
        }
    }
}
