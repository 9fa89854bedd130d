//! Fill-reducing orderings for the Cholesky factorisation of `K_ff`.
//!
//! Both orderings work on the *node* graph and keep each node's free dofs together, so the
//! factor's supernodes align with the 3x3 blocks. Nested dissection (METIS) is what makes
//! large organs tractable: its fill grows like `n^(4/3)` on 3D meshes, against far more for
//! minimum degree.

use crate::elasticity::{DofMap, Stiffness};

/// Which fill-reducing ordering to use.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Ordering {
    /// Approximate minimum degree (faer's AMD) on the dof graph.
    Amd,
    /// Nested dissection (METIS `NodeND`) on the node graph.
    #[default]
    NestedDissection,
}

impl Ordering {
    /// Every ordering, in the order [`Ordering::name`] lists them.
    pub const ALL: [Ordering; 2] = [Ordering::Amd, Ordering::NestedDissection];

    /// The ordering's name: `amd` or `nested-dissection`.
    pub fn name(self) -> &'static str {
        match self {
            Ordering::Amd => "amd",
            Ordering::NestedDissection => "nested-dissection",
        }
    }
}

impl std::fmt::Display for Ordering {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for Ordering {
    type Err = String;

    /// Parses a name of [`Ordering::name`].
    fn from_str(s: &str) -> Result<Ordering, String> {
        Ordering::ALL
            .into_iter()
            .find(|o| o.name() == s)
            .ok_or_else(|| format!("unknown ordering {s:?} (expected amd or nested-dissection)"))
    }
}

/// A dof permutation: `forward[k]` is the free dof eliminated `k`-th; `inverse` its inverse.
#[derive(Debug, Clone)]
pub struct DofPermutation {
    /// New position to free-dof index.
    pub forward: Vec<usize>,
    /// Free-dof index to new position.
    pub inverse: Vec<usize>,
}

/// The dof permutation of `ordering`, or `None` for faer's built-in AMD.
pub fn permutation(
    ordering: Ordering,
    body: &impl Stiffness,
    dofs: &DofMap,
) -> Result<Option<DofPermutation>, String> {
    match ordering {
        Ordering::Amd => Ok(None),
        Ordering::NestedDissection => nested_dissection(body, dofs).map(Some),
    }
}

/// Nested dissection of the node graph of the nodes that have a free dof, expanded to dofs.
pub fn nested_dissection(body: &impl Stiffness, dofs: &DofMap) -> Result<DofPermutation, String> {
    let n = body.nodes();
    let has_free = |i: usize| (0..3).any(|c| dofs.free_dof(i, c).is_some());
    // Compact numbering of the nodes that take part.
    let mut compact = vec![usize::MAX; n];
    let mut members = Vec::new();
    for i in (0..n).filter(|&i| has_free(i)) {
        compact[i] = members.len();
        members.push(i);
    }
    let to_idx = |v: usize| i32::try_from(v).map_err(|_| "graph too large for METIS".to_string());
    let mut xadj = Vec::with_capacity(members.len() + 1);
    let mut adjncy = Vec::new();
    xadj.push(0);
    for &i in &members {
        for &j in body.neighbours(i) {
            if j != i && compact[j] != usize::MAX {
                adjncy.push(to_idx(compact[j])?);
            }
        }
        xadj.push(to_idx(adjncy.len())?);
    }
    let mut nvtxs = to_idx(members.len())?;
    let mut perm = vec![0i32; members.len()];
    let mut iperm = vec![0i32; members.len()];
    if !members.is_empty() {
        let mut options = [-1i32; metis_sys::METIS_NOPTIONS as usize];
        // SAFETY: METIS_SetDefaultOptions fills the METIS_NOPTIONS-long array; METIS_NodeND
        // reads a valid CSR graph of `nvtxs` vertices (xadj has nvtxs + 1 entries, adjncy
        // xadj[nvtxs], symmetric, no self loops) and writes `nvtxs` entries to perm and iperm.
        let status = unsafe {
            metis_sys::METIS_SetDefaultOptions(options.as_mut_ptr());
            metis_sys::METIS_NodeND(
                &mut nvtxs,
                xadj.as_mut_ptr(),
                adjncy.as_mut_ptr(),
                std::ptr::null_mut(),
                options.as_mut_ptr(),
                perm.as_mut_ptr(),
                iperm.as_mut_ptr(),
            )
        };
        if status != metis_sys::rstatus_et_METIS_OK {
            return Err(format!("METIS_NodeND failed with status {status}"));
        }
    }
    // METIS: row k of the permuted matrix is row perm[k] of the original.
    let mut forward = Vec::with_capacity(dofs.free_count());
    for &p in &perm {
        let node = members[usize::try_from(p).map_err(|_| "METIS returned a negative index")?];
        forward.extend((0..3).filter_map(|c| dofs.free_dof(node, c)));
    }
    let mut inverse = vec![0; forward.len()];
    for (k, &d) in forward.iter().enumerate() {
        inverse[d] = k;
    }
    Ok(DofPermutation { forward, inverse })
}
