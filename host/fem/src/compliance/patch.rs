//! Patch compliances: the compliance of a tool load spread over several nodes.
//!
//! A tool force `F` spread with nodal weights `w_a` (module [`crate::tool`]) is the nodal force
//! `f = B^T F`, `B = [w_1 I, ..., w_n I]` (3 rows, one 3x3 block per node; a fixed component's
//! column is simply absent from `K_ff`). The load-weighted mean displacement, work-conjugate to
//! `F`, is `B u = B K_ff^-1 B^T F`, so the patch's 3x3 compliance is
//!
//! ```text
//! W = B K_ff^-1 B^T = sum_a sum_b w_a w_b C_ab    (m/N, symmetric positive definite).
//! ```
//!
//! With `K_ff = P^T L L^T P` (`P` the fill-reducing permutation), `W = Y^T Y` with
//! `Y = L^-1 P B^T`: only the forward half of a solve is needed, as in module `gram` for unit
//! columns. And it is sparse: a column of `P B^T` has its few entries (the load's dofs for one
//! component) in a few supernodes, and its column of `Y` is zero outside the union of their
//! paths to the root of the supernodal elimination tree. The forward substitution therefore
//! runs supernode by supernode, children first, each supernode `s` on the active columns only
//! (those starting in `s` or passed up by a child): gather the rows of `s`, `Y_s = L_ss^-1 B_s`,
//! `B_p -= L_ps Y_s` for the rows below, then pass the column set to the parent. Unlike
//! `gram`'s unit columns, a column may come up from several children, so `Y` is kept dense
//! (three columns per load, free-dof rows) and updated in place; the right-hand sides are built
//! and reduced in chunks of at most [`CHUNK_BYTES`] (the temporaries of one supernode add at
//! most as much again).
//!
//! On the 10k-node liver (bed fixed, tool radius 3 mm) the active columns carry 20 % of the
//! dense forward flops. `host bench patch` times this method against full solves
//! ([`Compliance::patch_compliances_by_full_solves`]) on a scene's FEM (`docs/scenes-and-banks.md`,
//! "The converged force").

use super::gram::par_for;
use super::{Block3, Compliance, ComplianceError};
use crate::progress::Progress;
use faer::linalg::matmul::matmul;
use faer::linalg::triangular_solve::solve_lower_triangular_in_place;
use faer::sparse::linalg::cholesky::SymbolicCholeskyRaw;
use faer::sparse::linalg::cholesky::supernodal::SupernodalLltRef;
use faer::{Accum, Mat};
use rayon::prelude::*;

/// Largest block of right-hand sides held at once, bytes (256 MiB).
pub const CHUNK_BYTES: usize = 256 << 20;

/// Computes the patch compliances of a chunk of loads, appending them; the matrix is the
/// chunks' shared block of right-hand sides ([`Compliance::right_hand_sides`]).
type ChunkFn = fn(
    &Compliance,
    &[Vec<(usize, f64)>],
    &mut Mat<f64>,
    &mut Vec<Block3>,
) -> Result<(), ComplianceError>;

impl Compliance {
    /// The 3x3 patch compliance `W_s = B_s K_ff^-1 B_s^T` (m/N) of each load `loads[s]`, a list
    /// of `(node, weight)` (e.g. [`crate::tool::ToolSurface::tool_weights`]; repeated nodes add
    /// up): the displacement of the load-weighted mean point per unit tool force. A weight's
    /// fixed components contribute nothing (a load wholly on fixed nodes gives zero). Symmetric
    /// (averaged with its transpose). The progress, if any, counts chunks of right-hand sides
    /// (at most [`CHUNK_BYTES`] each).
    ///
    /// Errors: a node id out of range ([`ComplianceError::NoSuchNode`]), a load with no entry or
    /// a non-finite weight ([`ComplianceError::BadLoad`]).
    pub fn patch_compliances(
        &self,
        loads: &[Vec<(usize, f64)>],
        progress: Option<&dyn Progress>,
    ) -> Result<Vec<Block3>, ComplianceError> {
        self.patch_chunked(loads, progress, CHUNK_BYTES, Self::forward_chunk)
    }

    /// [`Compliance::patch_compliances`] the straightforward way: full solves
    /// `X = K_ff^-1 B^T`, then `W = B X`. The reference the sparse forward substitution is
    /// checked and timed against (`host bench patch`); several times slower.
    pub fn patch_compliances_by_full_solves(
        &self,
        loads: &[Vec<(usize, f64)>],
        progress: Option<&dyn Progress>,
    ) -> Result<Vec<Block3>, ComplianceError> {
        self.patch_chunked(loads, progress, CHUNK_BYTES, Self::full_solve_chunk)
    }

    /// Validation, chunking, progress and symmetrisation around `reduce`.
    fn patch_chunked(
        &self,
        loads: &[Vec<(usize, f64)>],
        progress: Option<&dyn Progress>,
        chunk_bytes: usize,
        reduce: ChunkFn,
    ) -> Result<Vec<Block3>, ComplianceError> {
        self.check_loads(loads)?;
        let nf = self.dofs.free_count();
        let per_chunk = (chunk_bytes / (3 * 8 * nf.max(1))).max(1);
        let chunks = loads.len().div_ceil(per_chunk);
        if let Some(bar) = progress {
            bar.start(chunks as u64);
        }
        let mut out = Vec::with_capacity(loads.len());
        // One block of right-hand sides for all the chunks: a fresh one per chunk is fresh
        // memory, a page fault per 4 KiB each time (about half the system time of the sampled
        // report's 70-chunk call).
        let mut rhs = Mat::new();
        for chunk in loads.chunks(per_chunk) {
            if nf == 0 {
                out.extend(chunk.iter().map(|_| [[0.0; 3]; 3]));
            } else {
                reduce(self, chunk, &mut rhs, &mut out)?;
            }
            if let Some(bar) = progress {
                bar.advance(1);
            }
        }
        for w in &mut out {
            *w = std::array::from_fn(|i| std::array::from_fn(|j| 0.5 * (w[i][j] + w[j][i])));
        }
        Ok(out)
    }

    /// Every load has a node, every node exists, every weight is finite.
    fn check_loads(&self, loads: &[Vec<(usize, f64)>]) -> Result<(), ComplianceError> {
        let n = self.dofs.nodes();
        for (s, load) in loads.iter().enumerate() {
            if load.is_empty() {
                return Err(ComplianceError::BadLoad {
                    load: s,
                    reason: "it has no node".into(),
                });
            }
            for &(node, w) in load {
                if node >= n {
                    return Err(ComplianceError::NoSuchNode { node, nodes: n });
                }
                if !w.is_finite() {
                    return Err(ComplianceError::BadLoad {
                        load: s,
                        reason: format!("node {node} has the weight {w}"),
                    });
                }
            }
        }
        Ok(())
    }

    /// `X = K_ff^-1 B^T` for the tool `loads` (as [`Compliance::patch_compliances`] takes
    /// them): three columns per load, rows in free-dof order. The sparse forward substitution
    /// `Y = L^-1 P B^T` of the module notes, then the dense backward solve `X = P^T L^-T Y`:
    /// the forward half of a full solve costs only the loads' active columns.
    ///
    /// Errors: as [`Compliance::patch_compliances`].
    pub fn solve_loads(&self, loads: &[Vec<(usize, f64)>]) -> Result<Mat<f64>, ComplianceError> {
        self.check_loads(loads)?;
        let nf = self.dofs.free_count();
        if nf == 0 {
            return Ok(Mat::zeros(0, 3 * loads.len()));
        }
        let mut y = Mat::new();
        let row_of = self.sparse_forward(loads, &mut y)?;
        let SymbolicCholeskyRaw::Supernodal(sym) = self.symbolic.raw() else {
            return Err(ComplianceError::Factorisation(
                "internal error: expected a supernodal factor".into(),
            ));
        };
        let par = faer::Par::rayon(0);
        let mut mem = faer::dyn_stack::MemBuffer::new(
            self.symbolic.solve_in_place_scratch::<f64>(y.ncols(), par),
        );
        SupernodalLltRef::new(sym, &self.values).l_transpose_solve_with_conj(
            faer::Conj::No,
            y.as_mut(),
            par,
            faer::dyn_stack::MemStack::new(&mut mem),
        );
        Ok(Mat::from_fn(nf, y.ncols(), |d, j| y[(row_of[d], j)]))
    }

    /// `B^T` of a chunk into `rhs`, free dof `d` in row `row(d)` (three columns per load);
    /// `rhs` is reshaped and zeroed, keeping its allocation.
    fn right_hand_sides(
        &self,
        chunk: &[Vec<(usize, f64)>],
        row: impl Fn(usize) -> usize,
        rhs: &mut Mat<f64>,
    ) {
        rhs.truncate(0, 0);
        rhs.resize_with(self.dofs.free_count(), 3 * chunk.len(), |_, _| 0.0);
        for (s, load) in chunk.iter().enumerate() {
            for &(node, w) in load {
                for i in 0..3 {
                    if let Some(d) = self.dofs.free_dof(node, i) {
                        rhs[(row(d), 3 * s + i)] += w;
                    }
                }
            }
        }
    }

    /// `W = Y^T Y`, `Y = L^-1 P B^T` by the sparse forward substitution of the module
    /// documentation.
    fn forward_chunk(
        &self,
        chunk: &[Vec<(usize, f64)>],
        y: &mut Mat<f64>,
        out: &mut Vec<Block3>,
    ) -> Result<(), ComplianceError> {
        self.sparse_forward(chunk, y)?;
        let y = &*y;
        out.par_extend((0..chunk.len()).into_par_iter().map(|s| {
            let cols = [0, 1, 2].map(|i| y.col_as_slice(3 * s + i));
            let mut w = [[0.0; 3]; 3];
            for i in 0..3 {
                for j in i..3 {
                    let v: f64 = cols[i].iter().zip(cols[j]).map(|(a, b)| a * b).sum();
                    w[i][j] = v;
                    w[j][i] = v;
                }
            }
            w
        }));
        Ok(())
    }

    /// `Y = L^-1 P B^T` for a chunk of loads into `y` by the sparse forward substitution of the
    /// module documentation (rows in the factor's order; `y` reshaped as by
    /// [`Compliance::right_hand_sides`]), and each free dof's row in it.
    fn sparse_forward(
        &self,
        chunk: &[Vec<(usize, f64)>],
        y: &mut Mat<f64>,
    ) -> Result<Vec<usize>, ComplianceError> {
        let internal =
            |what: &str| ComplianceError::Factorisation(format!("internal error: {what}"));
        let SymbolicCholeskyRaw::Supernodal(sym) = self.symbolic.raw() else {
            return Err(internal("expected a supernodal factor"));
        };
        let inverse = self.symbolic.perm().map(|p| p.arrays().1);
        let rows: Vec<usize> = (0..self.dofs.free_count())
            .map(|d| inverse.map_or(d, |inv| inv[d]))
            .collect();
        let row_of = |d: usize| rows[d];
        self.right_hand_sides(chunk, row_of, y);
        let ns = sym.n_supernodes();
        let (begin, end) = (sym.supernode_begin(), sym.supernode_end());
        let mut col_super = vec![0usize; sym.nrows()];
        for s in 0..ns {
            col_super[begin[s]..end[s]].fill(s);
        }
        // The columns entering each supernode: first those with an entry in its rows.
        let mut pending: Vec<Vec<usize>> = vec![Vec::new(); ns];
        for (s, load) in chunk.iter().enumerate() {
            for &(node, _) in load {
                for i in 0..3 {
                    if let Some(d) = self.dofs.free_dof(node, i) {
                        pending[col_super[row_of(d)]].push(3 * s + i);
                    }
                }
            }
        }
        let llt = SupernodalLltRef::new(sym, &self.values);
        for s in 0..ns {
            let mut cols = std::mem::take(&mut pending[s]);
            if cols.is_empty() {
                continue;
            }
            cols.sort_unstable();
            cols.dedup();
            let sn = llt.supernode(s);
            let (start, l) = (sn.start(), sn.val());
            let pattern = sn.pattern();
            let (w, p, c) = (l.ncols(), pattern.len(), cols.len());
            let mut top = Mat::<f64>::zeros(w, c);
            for (jj, &j) in cols.iter().enumerate() {
                top.col_as_slice_mut(jj)
                    .copy_from_slice(&y.col_as_slice(j)[start..start + w]);
            }
            let (wf, pf, cf) = (w as f64, p as f64, c as f64);
            solve_lower_triangular_in_place(l.subrows(0, w), top.as_mut(), par_for(wf * wf * cf));
            let mut below = Mat::<f64>::zeros(p, c);
            if p > 0 {
                matmul(
                    below.as_mut(),
                    Accum::Replace,
                    l.subrows(w, p),
                    top.as_ref(),
                    1.0,
                    par_for(2.0 * pf * wf * cf),
                );
            }
            for (jj, &j) in cols.iter().enumerate() {
                let col = y.col_as_slice_mut(j);
                col[start..start + w].copy_from_slice(top.col_as_slice(jj));
                for (&g, &v) in pattern.iter().zip(below.col_as_slice(jj)) {
                    col[g] -= v;
                }
            }
            if let Some(&first) = pattern.iter().min() {
                let up = col_super[first];
                if up <= s {
                    return Err(internal("a supernode's parent comes before it"));
                }
                pending[up].extend_from_slice(&cols);
            }
        }
        Ok(rows)
    }

    /// The straightforward reference: `X = K_ff^-1 B^T` by full solves, then `W = B X`.
    fn full_solve_chunk(
        &self,
        chunk: &[Vec<(usize, f64)>],
        x: &mut Mat<f64>,
        out: &mut Vec<Block3>,
    ) -> Result<(), ComplianceError> {
        self.right_hand_sides(chunk, |d| d, x);
        self.solve_in_place(x.as_mut(), faer::Par::rayon(0));
        out.extend(chunk.iter().enumerate().map(|(s, load)| {
            let mut w = [[0.0; 3]; 3];
            for &(node, weight) in load {
                for (i, row) in w.iter_mut().enumerate() {
                    if let Some(d) = self.dofs.free_dof(node, i) {
                        for (j, v) in row.iter_mut().enumerate() {
                            *v += weight * x[(d, 3 * s + j)];
                        }
                    }
                }
            }
            w
        }));
        Ok(())
    }
}

/// The largest difference of an entry between the patch compliances `a` and `b`, relative to
/// that `b`'s largest diagonal entry (how two methods' `W` agree).
pub fn largest_difference(a: &[Block3], b: &[Block3]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| {
            let scale = (0..3).map(|i| y[i][i].abs()).fold(0.0, f64::max);
            x.iter()
                .flatten()
                .zip(y.iter().flatten())
                .map(|(p, q)| (p - q).abs() / scale)
                .fold(0.0, f64::max)
        })
        .fold(0.0, f64::max)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::elasticity::{Elasticity, FixedSet, Material};
    use crate::mesh::TetMesh;
    use crate::tool::ToolSurface;
    use std::cell::Cell;

    fn liver(name: &str) -> TetMesh {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../meshes");
        crate::mesh::load(&dir.join(name)).unwrap()
    }

    fn bed(positions: &[[f64; 3]]) -> FixedSet {
        let mut fixed = FixedSet::none(positions.len());
        for (i, p) in positions.iter().enumerate() {
            if p[2] <= 0.01 {
                fixed.fix_node(i).unwrap();
            }
        }
        fixed
    }

    /// Tool loads of radius `radius` at every `step`-th surface vertex.
    fn loads(
        tool: &ToolSurface,
        mesh: &TetMesh,
        step: usize,
        radius: f64,
    ) -> Vec<Vec<(usize, f64)>> {
        let surface = crate::mesh::boundary(mesh).unwrap();
        surface
            .nodes
            .iter()
            .step_by(step)
            .map(|&v| tool.tool_weights(mesh.nodes[v], radius).unwrap())
            .collect()
    }

    struct Count(Cell<u64>, Cell<u64>);
    impl Progress for Count {
        fn start(&self, total: u64) {
            self.0.set(total);
        }
        fn advance(&self, steps: u64) {
            self.1.set(self.1.get() + steps);
        }
    }

    /// The methods to compare: the full-solve reference and the sparse forward substitution.
    const METHODS: [(&str, ChunkFn); 2] = [
        ("full solves", Compliance::full_solve_chunk),
        ("sparse forward", Compliance::forward_chunk),
    ];

    /// `solve_loads` (sparse forward, dense backward) against full solves of the same
    /// right-hand sides, fixed dofs and all.
    #[test]
    fn solve_loads_matches_full_solves() {
        let mesh = liver("liver-1k4.msh");
        let body = Elasticity::new(&mesh, Material::new(3.0e3, 0.45).unwrap()).unwrap();
        let c = Compliance::factorize(&body, &bed(&mesh.nodes)).unwrap();
        let tool = ToolSurface::linear(&mesh, &crate::mesh::boundary(&mesh).unwrap()).unwrap();
        let l = loads(&tool, &mesh, 11, 0.004);
        let x = c.solve_loads(&l).unwrap();
        let mut full = Mat::new();
        c.right_hand_sides(&l, |d| d, &mut full);
        c.solve_in_place(full.as_mut(), faer::Par::Seq);
        assert_eq!((x.nrows(), x.ncols()), (full.nrows(), full.ncols()));
        let scale = (0..full.ncols())
            .flat_map(|j| full.col_as_slice(j).iter().copied())
            .fold(0.0f64, |m, v| m.max(v.abs()));
        let diff = (0..full.ncols())
            .flat_map(|j| {
                let (a, b) = (x.col_as_slice(j), full.col_as_slice(j));
                a.iter()
                    .zip(b)
                    .map(|(p, q)| (p - q).abs())
                    .collect::<Vec<_>>()
            })
            .fold(0.0f64, f64::max);
        assert!(
            scale > 0.0 && diff <= 1e-12 * scale,
            "{diff:e} of {scale:e}"
        );
        let bad = vec![vec![(0usize, f64::NAN)]];
        assert!(c.solve_loads(&bad).is_err());
    }

    #[test]
    fn sparse_forward_matches_full_solves_for_any_chunk_size() {
        let mesh = liver("liver-1k4.msh");
        let body = Elasticity::new(&mesh, Material::new(3.0e3, 0.45).unwrap()).unwrap();
        let c = Compliance::factorize(&body, &bed(&mesh.nodes)).unwrap();
        let tool = ToolSurface::linear(&mesh, &crate::mesh::boundary(&mesh).unwrap()).unwrap();
        let l = loads(&tool, &mesh, 7, 0.004);
        let reference = c
            .patch_chunked(&l, None, CHUNK_BYTES, Compliance::full_solve_chunk)
            .unwrap();
        let nf = c.dofs().free_count();
        for (name, method) in METHODS {
            // Chunks of 1, 5 and all loads.
            for bytes in [1, 5 * 24 * nf + 7, CHUNK_BYTES] {
                let count = Count(Cell::new(0), Cell::new(0));
                let w = c.patch_chunked(&l, Some(&count), bytes, method).unwrap();
                let chunks = l.len().div_ceil((bytes / (24 * nf)).max(1)) as u64;
                assert_eq!((count.0.get(), count.1.get()), (chunks, chunks));
                let err = largest_difference(&w, &reference);
                assert!(err < 1e-12, "{name} {bytes}: {err:e}");
            }
        }
    }
}
