//! `C_RR` for a node set `R`, all pairs at once, by a partial forward substitution and a Gram
//! matrix: the paper's "elementary deformations" (section 4-1) between contact candidates.
//!
//! With `K_ff = P^T L L^T P` (`P` the fill-reducing permutation) and `E_R` the unit columns of
//! the dofs of `R`,
//!
//! ```text
//! C_RR = E_R^T K_ff^-1 E_R = Y^T Y,   Y = L^-1 P E_R,
//! ```
//!
//! so only the forward half of a solve is needed, and it is sparse: the column of `Y` for a dof
//! `r` is zero outside the path from `r`'s column to the root of the elimination tree. `Y` is
//! built supernode by supernode, children first, like a multifrontal solve restricted to the
//! active columns (those whose path passes through the supernode): the rows of supernode `s`
//! give `Y_s = L_ss^-1 B_s`, and `B_p - L_ps Y_s` is passed to the parent for the rows below.
//! The Gram matrix is accumulated on the way, `C_RR = sum_s Y_s^T Y_s`, each term a dense product
//! (faer, parallel) scattered into the 3x3 blocks; `Y_s` is dropped right after. The cost is
//! dominated by the top separators, which every column passes: about
//! `sum_s width_s * active_s^2` flops, against `4 nnz(L)` per column for full solves.
//!
//! The dense alternative, `R` ordered last so that the trailing block of `L` is the Cholesky
//! factor of the Schur complement `S = K_RR - K_RI K_II^-1 K_IR` and `C_RR = S^-1`, costs
//! `(3|R|)^3` flops for the inverse alone. On the 10k-node liver with its 2620 free surface nodes
//! that is 4.9e11 flops against 1.5e11 for this method in all; measured, it was no faster than
//! full column solves and three times slower than this method, with twice the memory.

use super::{Block3, ComplianceError};
use crate::elasticity::DofMap;
use crate::progress::Progress;
use faer::linalg::matmul::matmul;
use faer::linalg::matmul::triangular::{self, BlockStructure};
use faer::linalg::triangular_solve::solve_lower_triangular_in_place;
use faer::reborrow::{Reborrow, ReborrowMut};
use faer::sparse::linalg::cholesky::supernodal::SupernodalLltRef;
use faer::sparse::linalg::cholesky::{SymbolicCholesky, SymbolicCholeskyRaw};
use faer::{Accum, ColMut, Mat, MatMut, MatRef, Par};
use rayon::prelude::*;

/// Columns per panel of the Gram products (bounds the temporary to `active x PANEL` values).
const PANEL: usize = 384;

/// The requested nodes' free dofs (the set `R`) and where their entries go in the result.
pub(super) struct Layout {
    /// Free-dof ids of `R`, in request order (x, y, z per node; fixed components skipped).
    r_dofs: Vec<usize>,
    /// For each index of `R`: (position in the request, component).
    owner: Vec<(usize, usize)>,
    /// The indices into `R` of request position `a` are `node_r[a]..node_r[a + 1]`.
    node_r: Vec<usize>,
}

impl Layout {
    pub(super) fn new(dofs: &DofMap, nodes: &[usize]) -> Self {
        let mut r_dofs = Vec::with_capacity(3 * nodes.len());
        let mut owner = Vec::with_capacity(3 * nodes.len());
        let mut node_r = Vec::with_capacity(nodes.len() + 1);
        for (a, &k) in nodes.iter().enumerate() {
            node_r.push(r_dofs.len());
            for c in 0..3 {
                if let Some(d) = dofs.free_dof(k, c) {
                    r_dofs.push(d);
                    owner.push((a, c));
                }
            }
        }
        node_r.push(r_dofs.len());
        Self {
            r_dofs,
            owner,
            node_r,
        }
    }
}

/// The part of `Y = L^-1 P E_R` that a supernode passes to its parent: `rows x cols` values of
/// the right-hand sides still to be reduced, for the rows of the supernode's pattern.
struct Update<'a> {
    /// Indices into `R` of the columns, increasing.
    cols: Vec<usize>,
    /// Rows (permuted dof ids), the supernode's pattern.
    rows: &'a [usize],
    /// Values, `rows.len() x cols.len()`, column-major.
    val: Vec<f64>,
}

/// Where an active column of a supernode's right-hand side comes from.
#[derive(Clone, Copy)]
enum Source {
    /// A unit vector with its 1 in this row of the supernode.
    Own(usize),
    /// Column `jj` of the update of kid `k`.
    Kid(usize, usize),
}

/// Parallelism for a dense kernel of about `flops` operations.
pub(super) fn par_for(flops: f64) -> Par {
    if flops > 2e6 { Par::rayon(0) } else { Par::Seq }
}

/// Where the Gram products go: the upper triangle of the result, one row per requested node
/// (`C(nodes[a], nodes[b])` for `b >= a`; diagonal blocks need only `i <= j`).
pub(super) trait GramOut: Send {
    /// Adds `Y_s^T Y_s` for the active columns `cols` (increasing indices into `R`) of `y`.
    fn accumulate(&mut self, y: MatRef<'_, f64>, cols: &[usize], layout: &Layout);
}

/// Every pair: dense panels of the lower triangle of `Y^T Y`.
impl GramOut for Vec<Vec<Block3>> {
    fn accumulate(&mut self, y: MatRef<'_, f64>, cols: &[usize], layout: &Layout) {
        accumulate_gram(y, cols, &layout.owner, self);
    }
}

/// A row of selected pairs: `(b, block)` sorted by `b`.
type NearRow = Vec<(usize, Block3)>;

/// Selected pairs, each row `(b, block)` sorted by `b`: only those products are formed, one
/// small product `Y_a^T [Y_b ...]` per node, nodes in parallel.
impl GramOut for Vec<NearRow> {
    fn accumulate(&mut self, y: MatRef<'_, f64>, cols: &[usize], layout: &Layout) {
        let w = y.nrows();
        // Active columns of node `a`: a run of `cols` (request order follows R order).
        let runs: Vec<(usize, usize, usize)> = {
            let mut v = Vec::new();
            let mut j = 0;
            while j < cols.len() {
                let a = layout.owner[cols[j]].0;
                let mut end = j + 1;
                while end < cols.len() && layout.owner[cols[end]].0 == a {
                    end += 1;
                }
                v.push((a, j, end));
                j = end;
            }
            v
        };
        let position = |r: usize| cols.binary_search(&r).ok();
        let mut rows: Vec<(&mut NearRow, usize, usize)> = Vec::with_capacity(runs.len());
        let mut rest = self.as_mut_slice();
        let mut offset = 0;
        for &(a, j0, j1) in &runs {
            let (_, tail) = std::mem::take(&mut rest).split_at_mut(a - offset);
            let (row, after) = tail.split_at_mut(1);
            rest = after;
            offset = a + 1;
            rows.push((&mut row[0], j0, j1));
        }
        rows.into_par_iter().for_each(|(row, j0, j1)| {
            // Targets: (slot in the row, component of b, column of y).
            let mut targets = Vec::new();
            for (slot, (b, _)) in row.iter().enumerate() {
                for r in layout.node_r[*b]..layout.node_r[*b + 1] {
                    if let Some(col) = position(r) {
                        targets.push((slot, layout.owner[r].1, col));
                    }
                }
            }
            if targets.is_empty() {
                return;
            }
            let gathered = Mat::<f64>::from_fn(w, targets.len(), |i, t| y[(i, targets[t].2)]);
            let mut prod = Mat::<f64>::zeros(j1 - j0, targets.len());
            matmul(
                prod.as_mut(),
                Accum::Replace,
                y.subcols(j0, j1 - j0).transpose(),
                gathered.as_ref(),
                1.0,
                Par::Seq,
            );
            for (ia, j) in (j0..j1).enumerate() {
                let ca = layout.owner[cols[j]].1;
                for (t, &(slot, cb, _)) in targets.iter().enumerate() {
                    row[slot].1[ca][cb] += prod[(ia, t)];
                }
            }
        });
    }
}

/// `C_RR = Y^T Y` accumulated supernode by supernode (see the module documentation) into the
/// upper triangle held by `out` (one row per requested node).
pub(super) fn gram_blocks(
    symbolic: &SymbolicCholesky<usize>,
    values: &[f64],
    layout: &Layout,
    out: &mut impl GramOut,
    progress: Option<&dyn Progress>,
) -> Result<(), ComplianceError> {
    let internal = |what: &str| ComplianceError::Factorisation(format!("internal error: {what}"));
    let SymbolicCholeskyRaw::Supernodal(sym) = symbolic.raw() else {
        return Err(internal("expected a supernodal factor"));
    };
    let nf = sym.nrows();
    let n_r = layout.r_dofs.len();
    let ns = sym.n_supernodes();
    let (begin, end) = (sym.supernode_begin(), sym.supernode_end());
    // Permuted column of each R dof.
    let q_of_r: Vec<usize> = match symbolic.perm() {
        Some(perm) => {
            let inv = perm.arrays().1;
            layout.r_dofs.iter().map(|&d| inv[d]).collect()
        }
        None => layout.r_dofs.clone(),
    };
    let mut col_super = vec![0usize; nf];
    for s in 0..ns {
        col_super[begin[s]..end[s]].fill(s);
    }
    // R columns starting in each supernode (CSR), and the supernodal elimination tree.
    let mut own_ptr = vec![0usize; ns + 1];
    for &q in &q_of_r {
        own_ptr[col_super[q] + 1] += 1;
    }
    for s in 0..ns {
        own_ptr[s + 1] += own_ptr[s];
    }
    let mut own = vec![0usize; n_r];
    let mut fill = own_ptr.clone();
    for (r, &q) in q_of_r.iter().enumerate() {
        own[fill[col_super[q]]] = r;
        fill[col_super[q]] += 1;
    }
    let parent: Vec<Option<usize>> = (0..ns)
        .map(|s| {
            sym.supernode(s)
                .pattern()
                .iter()
                .min()
                .map(|&g| col_super[g])
        })
        .collect();
    drop(col_super);

    let llt = SupernodalLltRef::new(sym, values);
    let mut pending: Vec<Vec<Update<'_>>> = (0..ns).map(|_| Vec::new()).collect();
    let mut col_pos = vec![0usize; n_r];
    let mut row_pos = vec![usize::MAX; nf];
    if let Some(bar) = progress {
        bar.start(ns as u64);
    }
    for s in 0..ns {
        if let Some(bar) = progress {
            bar.advance(1);
        }
        let kids = std::mem::take(&mut pending[s]);
        let own_cols = &own[own_ptr[s]..own_ptr[s + 1]];
        if own_cols.is_empty() && kids.is_empty() {
            continue;
        }
        // Columns active here: those starting in s and those passed up by the children (a
        // column's path to the root is a chain, so these sets are disjoint).
        let mut cols: Vec<usize> = own_cols.to_vec();
        for kid in &kids {
            cols.extend_from_slice(&kid.cols);
        }
        cols.sort_unstable();
        for (j, &r) in cols.iter().enumerate() {
            col_pos[r] = j;
        }
        let sn = llt.supernode(s);
        let (start, l) = (sn.start(), sn.val());
        let pattern = sn.pattern();
        let (w, p, c) = (l.ncols(), pattern.len(), cols.len());
        for (i, &g) in pattern.iter().enumerate() {
            row_pos[g] = i;
        }
        // Where each kid's rows go: below `w` a row of `y`, from `w` on a row of `u`.
        let mut dsts = Vec::with_capacity(kids.len());
        for kid in &kids {
            let mut dst = Vec::with_capacity(kid.rows.len());
            for &g in kid.rows {
                if (start..start + w).contains(&g) {
                    dst.push(g - start);
                } else if pattern.get(row_pos[g]) == Some(&g) {
                    dst.push(w + row_pos[g]);
                } else {
                    return Err(internal("a child's pattern is not in its parent's rows"));
                }
            }
            dsts.push(dst);
        }
        // Each active column comes from exactly one place: a unit vector (own) or one column of
        // one kid's update (the kids' column sets are disjoint). Filled in parallel.
        let mut source = vec![Source::Own(0); c];
        for &r in own_cols {
            source[col_pos[r]] = Source::Own(q_of_r[r] - start);
        }
        for (k, kid) in kids.iter().enumerate() {
            for (jj, &r) in kid.cols.iter().enumerate() {
                source[col_pos[r]] = Source::Kid(k, jj);
            }
        }
        // Zeroed buffers from the allocator's zeroed pages: a column becomes resident only when
        // it is written, so filling kid by kid and dropping each kid's update right after keeps
        // the peak near one copy of the largest front, not two.
        let mut y_buf = vec![0.0f64; w * c];
        let mut u_buf = vec![0.0f64; p * c];
        let mut y = MatMut::from_column_major_slice_mut(&mut y_buf, w, c);
        let mut u = MatMut::from_column_major_slice_mut(&mut u_buf, p, c);
        for (j, src) in source.iter().enumerate() {
            if let Source::Own(row) = *src {
                y[(row, j)] = 1.0;
            }
        }
        for (k, (kid, dst)) in kids.into_iter().zip(&dsts).enumerate() {
            let kid_val = MatRef::from_column_major_slice(&kid.val, kid.rows.len(), kid.cols.len());
            let fill = |(j, (mut ycol, mut ucol)): (usize, (ColMut<'_, f64>, ColMut<'_, f64>))| {
                let Source::Kid(kk, jj) = source[j] else {
                    return;
                };
                if kk != k {
                    return;
                }
                let src = kid_val.col(jj);
                for (ii, &d) in dst.iter().enumerate() {
                    if d < w {
                        ycol[d] = src[ii];
                    } else {
                        ucol[d - w] = src[ii];
                    }
                }
            };
            if (w + p) * kid.cols.len() > 1 << 16 {
                y.rb_mut()
                    .par_col_iter_mut()
                    .zip(u.rb_mut().par_col_iter_mut())
                    .enumerate()
                    .for_each(fill);
            } else {
                y.rb_mut()
                    .col_iter_mut()
                    .zip(u.rb_mut().col_iter_mut())
                    .enumerate()
                    .for_each(fill);
            }
            drop(kid);
        }
        let (wf, pf, cf) = (w as f64, p as f64, c as f64);
        // Y_s = L_ss^-1 (rhs)_s, then the rows below: U = (rhs)_p - L_ps Y_s.
        solve_lower_triangular_in_place(l.subrows(0, w), y.rb_mut(), par_for(wf * wf * cf));
        if p > 0 {
            matmul(
                u.rb_mut(),
                Accum::Add,
                l.subrows(w, p),
                y.rb(),
                -1.0,
                par_for(2.0 * pf * wf * cf),
            );
        }
        out.accumulate(y.rb(), &cols, layout);
        drop(y_buf);
        if p > 0 {
            let up = parent[s]
                .filter(|&up| up > s)
                .ok_or_else(|| internal("a supernode with rows but no later parent"))?;
            pending[up].push(Update {
                cols,
                rows: pattern,
                val: u_buf,
            });
        }
    }
    Ok(())
}

/// `out += Y^T Y` on the upper triangle (`out[a][b]`, `a <= b`), by column panels of the lower
/// triangle of `Y^T Y`. `cols[j]` is the R index of column `j` of `y` (increasing), `owner[r]`
/// its (request position, component).
fn accumulate_gram(
    y: MatRef<'_, f64>,
    cols: &[usize],
    owner: &[(usize, usize)],
    out: &mut [Vec<Block3>],
) {
    let (w, c) = (y.nrows(), y.ncols());
    let mut panel = Mat::<f64>::zeros(c, PANEL.min(c));
    for a in (0..c).step_by(PANEL) {
        let b = (a + PANEL).min(c);
        let pw = b - a;
        let par = par_for(w as f64 * pw as f64 * (c - a) as f64 * 2.0);
        let mut p = panel.as_mut().submatrix_mut(0, 0, c - a, pw);
        let (top, bottom) = p.as_mut().split_at_row_mut(pw);
        let y_panel = y.subcols(a, pw);
        triangular::matmul(
            top,
            BlockStructure::TriangularLower,
            Accum::Replace,
            y_panel.transpose(),
            BlockStructure::Rectangular,
            y_panel,
            BlockStructure::Rectangular,
            1.0,
            par,
        );
        matmul(
            bottom,
            Accum::Replace,
            y.subcols(b, c - b).transpose(),
            y_panel,
            1.0,
            par,
        );
        // Column jj of the panel (R index rj, node aj) holds C(ri, rj) for the rows ri >= rj:
        // it goes to row aj of `out`. The panel's columns come in runs of equal aj (at most 3).
        let p = p.as_ref();
        let first = owner[cols[a]].0;
        let mut runs: Vec<(&mut Vec<Block3>, usize, usize)> = Vec::new();
        let mut rows = out[first..].iter_mut().enumerate();
        let mut jj = 0;
        while jj < pw {
            let aj = owner[cols[a + jj]].0;
            let mut end = jj + 1;
            while end < pw && owner[cols[a + end]].0 == aj {
                end += 1;
            }
            if let Some(row) = rows.find_map(|(i, row)| (first + i == aj).then_some(row)) {
                runs.push((row, jj, end));
            }
            jj = end;
        }
        let scatter = |(row, jj0, jj1): (&mut Vec<Block3>, usize, usize)| {
            for jj in jj0..jj1 {
                let cj = owner[cols[a + jj]].1;
                for (ii, &v) in p.col(jj).iter().enumerate().skip(jj) {
                    let (ai, ci) = owner[cols[a + ii]];
                    row[ai][cj][ci] += v;
                }
            }
        };
        if (c - a) * pw > 1 << 16 {
            runs.into_par_iter().for_each(scatter);
        } else {
            runs.into_iter().for_each(scatter);
        }
    }
}
