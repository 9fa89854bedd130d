//! The contact solve in compliance form (paper eqs. 2 and 8, compliance form in the design
//! notes): with displacements `u*_S` imposed on a contact set `S` and every other node
//! force-free, the contact forces are `f_S = C_SS^-1 u*_S`. Then the quasi non-linear law Q
//! (eqs. 3-6) on the tool force.
//!
//! Fixed sizes, f32, no heap, no panics: `C_SS` is assembled into a `9 x 9` matrix (the unused
//! part is a decoupled diagonal block that does not touch the solution), factored by Cholesky.
//!
//! Two ways to spread the tool-tip displacement `d` over a contact triangle with barycentric
//! coordinates `k = (k1, k2, k3)` of the contact point:
//!
//! - [`solve_triangle_alpha`], the paper's section 5: `u*_v = alpha_v d` with
//!   `alpha_v = k_v + 1 - (k1^2 + k2^2 + k3^2)`; then `f_S = C_SS^-1 u*_S` (a 9 x 9 solve). The
//!   contact point `sum_v k_v u_v` follows the tip exactly when `sum_v k_v = 1`.
//! - [`solve_triangle_barycentric`], energy-minimal: one 3-dof constraint `B u_S = d` on the
//!   contact point with `B = [k1 I, k2 I, k3 I]`, so `f_tool = (B C_SS B^T)^-1 d` (a 3 x 3 solve)
//!   and `f_v = k_v f_tool`. It never needs `C_SS^-1`, so nearly coincident vertices (a nearly
//!   singular `C_SS`) do not hurt it.
//!
//! The energy-minimal form works for any weights `w` (`w_a >= 0`, `sum w_a = 1`) on up to
//! [`MAX_CONTACT_NODES`] nodes ([`WeightedSolve`], [`solve_weighted`]): the force on the tissue
//! is distributed as `f_a = w_a f_tool`, and the tool displacement is imposed on the work-
//! conjugate mean `sum_a w_a u_a`. The finite tool radius ([`crate::patch`]) uses it with the
//! weights of the pressure under the tool tip.
//!
//! Sign convention: forces are those applied *to the tissue* at the contact nodes (as in the
//! host's `contact_forces`); [`ContactForces::tool_force_n`] is their sum, the force the tool
//! exerts on the tissue. The force the user feels is its opposite.

use crate::cholesky::Cholesky;
use crate::vec3::dot;
use bank_format::{Bank, TissueLaw};

/// Most nodes in one contact set (the link's contact list, [`bank_format::MAX_CONTACTS`]).
pub const MAX_CONTACT_NODES: usize = bank_format::MAX_CONTACTS;
/// Most nodes with imposed displacements in [`solve_imposed`] (one triangle, the paper's form).
pub const MAX_IMPOSED_NODES: usize = 3;
/// Degrees of freedom of the largest [`solve_imposed`] set.
pub const MAX_DOFS: usize = 3 * MAX_IMPOSED_NODES;
/// Tolerance on `|sum w_a - 1|` for contact weights (and barycentric coordinates).
pub const WEIGHT_SUM_TOL: f32 = 1.0e-3;
/// Smallest Cholesky pivot (`L_ii^2`) accepted, relative to the largest diagonal entry of the
/// matrix factored; below it the solve reports [`SolveError::IllConditioned`] instead of
/// returning forces. The bank format's margin, which its reader applies to contact samples, so
/// that a bank the reader accepts never fails here for its conditioning.
pub use bank_format::MIN_PIVOT_REL;

/// `C_SS` padded to the largest contact set.
pub type CssMatrix = [[f32; MAX_DOFS]; MAX_DOFS];

/// Why a contact solve gave no forces.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SolveError {
    /// The contact set is empty.
    NoNodes,
    /// More nodes than the solve takes ([`MAX_IMPOSED_NODES`] or [`MAX_CONTACT_NODES`]).
    TooManyNodes {
        /// Nodes given.
        count: usize,
        /// Most the solve takes.
        max: usize,
    },
    /// As many imposed displacements (or weights) as nodes are needed.
    LengthMismatch {
        /// Nodes given.
        nodes: usize,
        /// Displacements or weights given.
        imposed: usize,
    },
    /// A node index is not in the bank's region R.
    NodeOutOfRange {
        /// The node.
        node: u16,
    },
    /// A node appears twice in the contact set.
    DuplicateNode {
        /// The node.
        node: u16,
    },
    /// The bank does not couple two nodes of the contact set (they are farther apart than its
    /// truncation radius). Treating the block as zero would be wrong by up to 180%.
    MissingCoupling {
        /// First node.
        k: u16,
        /// Second node.
        l: u16,
    },
    /// A NaN or infinite input, compliance entry or result.
    NonFinite,
    /// Barycentric coordinates or contact weights that are negative or do not sum to 1 (within
    /// [`WEIGHT_SUM_TOL`]).
    BadWeights,
    /// The matrix to factor is not positive definite at f32 precision.
    NotPositiveDefinite,
    /// The smallest Cholesky pivot relative to the largest diagonal entry is below
    /// [`MIN_PIVOT_REL`] (e.g. two nearly coincident contact nodes).
    IllConditioned {
        /// That ratio.
        pivot_rel: f32,
    },
}

impl core::fmt::Display for SolveError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            SolveError::NoNodes => f.write_str("empty contact set"),
            SolveError::TooManyNodes { count, max } => {
                write!(f, "{count} contact nodes, at most {max}")
            }
            SolveError::LengthMismatch { nodes, imposed } => {
                write!(
                    f,
                    "{nodes} contact nodes but {imposed} displacements or weights"
                )
            }
            SolveError::NodeOutOfRange { node } => write!(f, "node {node} is not in the bank"),
            SolveError::DuplicateNode { node } => write!(f, "node {node} given twice"),
            SolveError::MissingCoupling { k, l } => {
                write!(f, "the bank does not couple nodes {k} and {l}")
            }
            SolveError::NonFinite => f.write_str("NaN or infinite value"),
            SolveError::BadWeights => {
                f.write_str("contact weights are negative or do not sum to 1")
            }
            SolveError::NotPositiveDefinite => f.write_str("matrix not positive definite"),
            SolveError::IllConditioned { pivot_rel } => {
                write!(
                    f,
                    "ill-conditioned solve (smallest pivot {pivot_rel:e} relative)"
                )
            }
        }
    }
}

/// Forces of one contact solve.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ContactForces {
    nodes: [u16; MAX_CONTACT_NODES],
    len: usize,
    forces: [[f32; 3]; MAX_CONTACT_NODES],
    /// Sum of the node forces: the force the tool exerts on the tissue, N.
    pub tool_force_n: [f32; 3],
    /// Condition estimate of the matrix factored (see [`Factor::condition`]).
    pub condition: f32,
}

impl ContactForces {
    /// The contact nodes, in the order given.
    pub fn nodes(&self) -> &[u16] {
        self.nodes.get(..self.len).unwrap_or(&[])
    }

    /// The force at each contact node (applied to the tissue), N, in the order of
    /// [`ContactForces::nodes`].
    pub fn forces(&self) -> &[[f32; 3]] {
        self.forces.get(..self.len).unwrap_or(&[])
    }
}

/// A Cholesky factorisation ([`crate::cholesky`]) of a fixed-size SPD matrix of which the
/// leading `active` rows and columns are used, with its pivot statistics.
#[derive(Clone, Copy, Debug)]
pub struct Factor<const D: usize> {
    chol: Cholesky<D>,
    min_pivot: f32,
    max_pivot: f32,
    max_diag: f32,
}

impl<const D: usize> Factor<D> {
    /// The factor of the identity matrix (every pivot 1).
    pub const IDENTITY: Factor<D> = Factor {
        chol: Cholesky::IDENTITY,
        min_pivot: 1.0,
        max_pivot: 1.0,
        max_diag: 1.0,
    };

    /// Factors `a` (only its lower triangle is read). Fails on NaN or infinite entries or when
    /// Cholesky breaks down; does *not* apply [`MIN_PIVOT_REL`] (see [`Factor::check`]).
    pub fn new(a: [[f32; D]; D], active: usize) -> Result<Factor<D>, SolveError> {
        if !a.iter().flatten().all(|x| x.is_finite()) {
            return Err(SolveError::NonFinite);
        }
        let active = active.min(D);
        // Comparisons, not `f32::max` / `min`: those are libm calls on the M4F (no VMAXNM),
        // and the entries and pivots here are finite (checked above and below).
        let mut max_diag = 0.0f32;
        for (i, r) in a.iter().enumerate().take(active) {
            if let Some(&x) = r.get(i)
                && x > max_diag
            {
                max_diag = x;
            }
        }
        let chol = Cholesky::new(&a).ok_or(SolveError::NotPositiveDefinite)?;
        let (mut min_pivot, mut max_pivot) = (f32::INFINITY, 0.0f32);
        for &l in chol.diagonal().iter().take(active) {
            let p = l * l;
            if p < min_pivot {
                min_pivot = p;
            }
            if p > max_pivot {
                max_pivot = p;
            }
        }
        if !(min_pivot > 0.0 && max_pivot.is_finite() && max_diag > 0.0) {
            return Err(SolveError::NotPositiveDefinite);
        }
        Ok(Factor {
            chol,
            min_pivot,
            max_pivot,
            max_diag,
        })
    }

    /// Condition estimate: largest over smallest squared Cholesky pivot `L_ii^2` (the LDL^T
    /// pivots). A lower bound on the 2-norm condition number, cheap and adequate to compare two
    /// formulations and to spot near-singularity.
    pub fn condition(&self) -> f32 {
        self.max_pivot / self.min_pivot
    }

    /// Smallest pivot relative to the largest diagonal entry.
    pub fn pivot_rel(&self) -> f32 {
        self.min_pivot / self.max_diag
    }

    /// `Ok` when the smallest pivot passes [`MIN_PIVOT_REL`].
    pub fn check(&self) -> Result<(), SolveError> {
        let pivot_rel = self.pivot_rel();
        if pivot_rel >= MIN_PIVOT_REL {
            Ok(())
        } else {
            Err(SolveError::IllConditioned { pivot_rel })
        }
    }

    /// `a^-1 b`.
    pub fn solve(&self, b: &[f32; D]) -> Result<[f32; D], SolveError> {
        let x = self.chol.solve(b);
        if x.iter().all(|v| v.is_finite()) {
            Ok(x)
        } else {
            Err(SolveError::NonFinite)
        }
    }
}

fn check_count(nodes: &[u16], max: usize) -> Result<(), SolveError> {
    if nodes.is_empty() {
        return Err(SolveError::NoNodes);
    }
    if nodes.len() > max {
        return Err(SolveError::TooManyNodes {
            count: nodes.len(),
            max,
        });
    }
    Ok(())
}

fn check_nodes(bank: &Bank, nodes: &[u16], max: usize) -> Result<(), SolveError> {
    check_count(nodes, max)?;
    for (a, &k) in nodes.iter().enumerate() {
        if usize::from(k) >= bank.node_count() {
            return Err(SolveError::NodeOutOfRange { node: k });
        }
        if nodes.iter().skip(a + 1).any(|&l| l == k) {
            return Err(SolveError::DuplicateNode { node: k });
        }
    }
    Ok(())
}

/// Assembles `C_SS` (m/N) for the contact set `nodes` (at most [`MAX_IMPOSED_NODES`]): block `(a, b)` is
/// `bank.coupling(nodes[a], nodes[b])`. Rows and columns past `3 * nodes.len()` hold the mean
/// active diagonal on the diagonal and zeros elsewhere, so a factorisation of the padded matrix
/// solves the active part exactly. A pair the bank does not couple is an error, never zero.
pub fn assemble_css(bank: &Bank, nodes: &[u16]) -> Result<CssMatrix, SolveError> {
    check_nodes(bank, nodes, MAX_IMPOSED_NODES)?;
    let mut c: CssMatrix = [[0.0; MAX_DOFS]; MAX_DOFS];
    for (a, &k) in nodes.iter().enumerate() {
        for (b, &l) in nodes.iter().enumerate() {
            let block = bank
                .coupling(usize::from(k), usize::from(l))
                .ok_or(SolveError::MissingCoupling { k, l })?;
            for (i, row) in block.iter().enumerate() {
                for (j, &v) in row.iter().enumerate() {
                    if !v.is_finite() {
                        return Err(SolveError::NonFinite);
                    }
                    if let Some(e) = c.get_mut(3 * a + i).and_then(|r| r.get_mut(3 * b + j)) {
                        *e = v;
                    }
                }
            }
        }
    }
    let active = 3 * nodes.len();
    let mean = c
        .iter()
        .enumerate()
        .take(active)
        .filter_map(|(i, r)| r.get(i))
        .sum::<f32>()
        / active as f32;
    let pad = if mean > 0.0 && mean.is_finite() {
        mean
    } else {
        1.0
    };
    for r in active..MAX_DOFS {
        if let Some(e) = c.get_mut(r).and_then(|row| row.get_mut(r)) {
            *e = pad;
        }
    }
    Ok(c)
}

/// Factorisation of `C_SS` for `nodes` (no pivot threshold applied).
pub fn factor_css(bank: &Bank, nodes: &[u16]) -> Result<Factor<MAX_DOFS>, SolveError> {
    let c = assemble_css(bank, nodes)?;
    Factor::new(c, 3 * nodes.len())
}

/// `f_S = C_SS^-1 u*_S`: the forces (N) at the contact nodes that impose the displacements
/// `imposed_m[a]` (m) on `nodes[a]`, all other nodes force-free.
pub fn solve_imposed(
    bank: &Bank,
    nodes: &[u16],
    imposed_m: &[[f32; 3]],
) -> Result<ContactForces, SolveError> {
    if imposed_m.len() != nodes.len() {
        return Err(SolveError::LengthMismatch {
            nodes: nodes.len(),
            imposed: imposed_m.len(),
        });
    }
    if !imposed_m.iter().flatten().all(|v| v.is_finite()) {
        return Err(SolveError::NonFinite);
    }
    let factor = factor_css(bank, nodes)?;
    factor.check()?;
    let mut u = [0.0f32; MAX_DOFS];
    for (a, d) in imposed_m.iter().enumerate() {
        for (i, &v) in d.iter().enumerate() {
            if let Some(e) = u.get_mut(3 * a + i) {
                *e = v;
            }
        }
    }
    let f = factor.solve(&u)?;
    let mut out = ContactForces {
        nodes: [0; MAX_CONTACT_NODES],
        len: nodes.len(),
        forces: [[0.0; 3]; MAX_CONTACT_NODES],
        tool_force_n: [0.0; 3],
        condition: factor.condition(),
    };
    for (a, (slot, &k)) in out.nodes.iter_mut().zip(nodes).enumerate() {
        *slot = k;
        if let Some(fa) = out.forces.get_mut(a) {
            for (i, v) in fa.iter_mut().enumerate() {
                *v = f.get(3 * a + i).copied().unwrap_or(0.0);
            }
            for (t, v) in out.tool_force_n.iter_mut().zip(fa.iter()) {
                *t += *v;
            }
        }
    }
    Ok(out)
}

/// Point contact: the force (N) that moves `node` by `d_m` (m).
pub fn solve_point(bank: &Bank, node: u16, d_m: [f32; 3]) -> Result<ContactForces, SolveError> {
    solve_imposed(bank, &[node], &[d_m])
}

/// A contact set for [`WeightedSolve`]: 1 ..= [`MAX_CONTACT_NODES`] nodes, as many weights
/// ([`check_weights`]); not checked for repeated nodes.
fn check_lengths(nodes: &[u16], weights: &[f32]) -> Result<(), SolveError> {
    check_count(nodes, MAX_CONTACT_NODES)?;
    if weights.len() != nodes.len() {
        return Err(SolveError::LengthMismatch {
            nodes: nodes.len(),
            imposed: weights.len(),
        });
    }
    check_weights(weights)
}

/// [`check_lengths`], and the nodes distinct.
fn check_contact(nodes: &[u16], weights: &[f32]) -> Result<(), SolveError> {
    check_lengths(nodes, weights)?;
    for (a, &k) in nodes.iter().enumerate() {
        if nodes.get(..a).is_some_and(|before| before.contains(&k)) {
            return Err(SolveError::DuplicateNode { node: k });
        }
    }
    Ok(())
}

/// Weights must be finite, non-negative and sum to 1 within [`WEIGHT_SUM_TOL`].
fn check_weights(w: &[f32]) -> Result<(), SolveError> {
    if !w.iter().all(|v| v.is_finite()) {
        return Err(SolveError::NonFinite);
    }
    let s: f32 = w.iter().sum();
    if w.iter().all(|&v| v >= 0.0) && (s - 1.0).abs() <= WEIGHT_SUM_TOL {
        Ok(())
    } else {
        Err(SolveError::BadWeights)
    }
}

/// The paper's weights `alpha_v = k_v + 1 - (k1^2 + k2^2 + k3^2)` for barycentric coordinates
/// `k` of the contact point. With `sum k_v = 1`, `sum_v k_v alpha_v = 1`: the contact point
/// moves with the tip.
pub fn alpha_weights(k: [f32; 3]) -> [f32; 3] {
    let s2 = k[0] * k[0] + k[1] * k[1] + k[2] * k[2];
    [k[0] + 1.0 - s2, k[1] + 1.0 - s2, k[2] + 1.0 - s2]
}

/// Triangle contact, the paper's form: the tip displacement `d_m` imposed on vertex `v` of
/// `triangle` scaled by [`alpha_weights`]`(bary)[v]`; `f_S = C_SS^-1 u*_S` (9 x 9).
pub fn solve_triangle_alpha(
    bank: &Bank,
    triangle: [u16; 3],
    bary: [f32; 3],
    d_m: [f32; 3],
) -> Result<ContactForces, SolveError> {
    check_weights(&bary)?;
    let alpha = alpha_weights(bary);
    let imposed = alpha.map(|a| d_m.map(|x| a * x));
    solve_imposed(bank, &triangle, &imposed)
}

/// The energy-minimal contact solve for one weighted contact set, factored once: `M = B C_SS
/// B^T = sum_ab w_a w_b C_ab` (3 x 3, m/N) and its Cholesky factor. [`WeightedSolve::forces`]
/// then costs one 3 x 3 solve, so a contact that does not slide reuses it tick after tick.
#[derive(Clone, Copy, Debug)]
pub struct WeightedSolve {
    nodes: [u16; MAX_CONTACT_NODES],
    weights: [f32; MAX_CONTACT_NODES],
    len: usize,
    factor: Factor<3>,
}

impl WeightedSolve {
    /// Assembles and factors `M` for `nodes` with `weights` (finite, `>= 0`, sum 1). Every
    /// pair must be coupled in the bank; an ill-conditioned `M` is an error.
    pub fn new(bank: &Bank, nodes: &[u16], weights: &[f32]) -> Result<WeightedSolve, SolveError> {
        let mut fill = WeightedFill::new(nodes, weights)?;
        while !fill.step(bank, usize::MAX)? {}
        fill.factor()
    }

    /// The solve of the unit compliance `M = I` over no node: storage for
    /// [`WeightedSolve::refactor`] to factor a new contact's `M` into in place (writing this
    /// costs the tick less than moving a returned solve, which it would do twice).
    pub const UNIT: WeightedSolve = WeightedSolve {
        nodes: [0; MAX_CONTACT_NODES],
        weights: [0.0; MAX_CONTACT_NODES],
        len: 0,
        factor: Factor::IDENTITY,
    };

    /// Factors a given patch compliance `M` (xx, xy, xz, yy, yz, zz, m/N; e.g. the bank's
    /// sampled `W(p)`, [`bank_format::Samples::interpolate`]) for the contact spread over
    /// `nodes` with `weights` (finite, `>= 0`, sum 1: the telemetry's node forces `w_a
    /// f_tool`), in place: the loop factors a new `M` every tick, and the solve is a few
    /// hundred bytes, which a returned value would copy twice. The same checks and factor as
    /// [`WeightedFill::factor`]; the nodes are kept in the order given (no sort: no sum over
    /// them follows). On an error `self` is unchanged.
    // Out of line: inlined into the tick (one large function) it cost the sampled contact's
    // patch phase 127 more instructions a tick (806 -> 933 under QEMU, register spills).
    #[inline(never)]
    pub fn refactor(
        &mut self,
        m: [f32; 6],
        nodes: &[u16],
        weights: &[f32],
    ) -> Result<(), SolveError> {
        check_contact(nodes, weights)?;
        self.factor = factor_compliance(m)?;
        self.set_contact(nodes, weights);
        Ok(())
    }

    /// Copies a contact set [`check_contact`] accepted.
    fn set_contact(&mut self, nodes: &[u16], weights: &[f32]) {
        self.len = nodes.len();
        for (a, (&k, &w)) in nodes.iter().zip(weights).enumerate() {
            if let (Some(n), Some(wv)) = (self.nodes.get_mut(a), self.weights.get_mut(a)) {
                (*n, *wv) = (k, w);
            }
        }
    }

    /// The contact nodes.
    pub fn nodes(&self) -> &[u16] {
        self.nodes.get(..self.len).unwrap_or(&[])
    }

    /// The contact nodes with their weights `w_a` (the share of the tool force each carries).
    pub fn shares(&self) -> impl Iterator<Item = (u16, f32)> + '_ {
        self.nodes
            .iter()
            .copied()
            .zip(self.weights.iter().copied())
            .take(self.len)
    }

    /// Condition estimate ([`Factor::condition`]) of `M`.
    pub fn condition(&self) -> f32 {
        self.factor.condition()
    }

    /// The forces that move the weighted mean `sum_a w_a u_a` by `d_m` (m): `f_tool = M^-1 d`,
    /// `f_a = w_a f_tool` (N, on the tissue).
    pub fn forces(&self, d_m: [f32; 3]) -> Result<ContactForces, SolveError> {
        Ok(self.distribute(self.tool_force(d_m)?))
    }

    /// `f_tool = M^-1 d` (N, on the tissue) for the displacement `d_m` (m) of the weighted mean.
    pub fn tool_force(&self, d_m: [f32; 3]) -> Result<[f32; 3], SolveError> {
        if !d_m.iter().all(|v| v.is_finite()) {
            return Err(SolveError::NonFinite);
        }
        self.factor.solve(&d_m)
    }

    /// A tool force `tool` (N, on the tissue) spread over the nodes as `f_a = w_a tool`; the
    /// result's `tool_force_n` is their sum.
    pub fn distribute(&self, tool: [f32; 3]) -> ContactForces {
        let mut out = ContactForces {
            nodes: self.nodes,
            len: self.len,
            forces: [[0.0; 3]; MAX_CONTACT_NODES],
            tool_force_n: [0.0; 3],
            condition: self.factor.condition(),
        };
        for (fv, &w) in out.forces.iter_mut().zip(&self.weights).take(self.len) {
            *fv = tool.map(|t| w * t);
            for (t, v) in out.tool_force_n.iter_mut().zip(fv.iter()) {
                *t += *v;
            }
        }
        out
    }
}

/// [`WeightedSolve::new`] in steps, so that the loop can spread a large patch's assembly over
/// ticks: `M = B C_SS B^T = sum_ab w_a w_b C_ab` (3 x 3, m/N), symmetric, visited in ascending
/// node order: for each node k, `w_k^2 C_kk`, then the pairs `(k, l > k)` as
/// `w_k w_l (C_kl + C_kl^T)` from k's stored row ([`Bank::upper_couplings`]), walked once beside
/// the remaining nodes (no search per pair); then [`WeightedFill::factor`]. The same sums in the
/// same order however it is stepped, so the result is bit for bit [`WeightedSolve::new`]'s.
#[derive(Clone, Copy, Debug)]
pub struct WeightedFill {
    /// The nodes and weights, ascending by node.
    order: [(u16, f32); MAX_CONTACT_NODES],
    /// The nodes and weights as given (the solve keeps their order).
    nodes: [u16; MAX_CONTACT_NODES],
    weights: [f32; MAX_CONTACT_NODES],
    len: usize,
    /// Rows of `order` added so far.
    next: usize,
    /// Upper triangle of M: xx, xy, xz, yy, yz, zz.
    m: [f32; 6],
}

impl WeightedFill {
    /// Starts the assembly for `nodes` (1 ..= [`MAX_CONTACT_NODES`], distinct) with `weights`
    /// (finite, `>= 0`, sum 1).
    pub fn new(nodes: &[u16], weights: &[f32]) -> Result<WeightedFill, SolveError> {
        // Repeated nodes are found by the insertion below.
        check_lengths(nodes, weights)?;
        let mut out = WeightedFill {
            order: [(0, 0.0); MAX_CONTACT_NODES],
            nodes: [0; MAX_CONTACT_NODES],
            weights: [0.0; MAX_CONTACT_NODES],
            len: nodes.len(),
            next: 0,
            m: [0.0; 6],
        };
        // Ascending order by insertion; a repeated node is met on the way.
        for (i, (&k, &w)) in nodes.iter().zip(weights).enumerate() {
            if let (Some(n), Some(wv)) = (out.nodes.get_mut(i), out.weights.get_mut(i)) {
                (*n, *wv) = (k, w);
            }
            let mut j = i;
            while let Some(&prev) = j.checked_sub(1).and_then(|p| out.order.get(p))
                && prev.0 >= k
            {
                if prev.0 == k {
                    return Err(SolveError::DuplicateNode { node: k });
                }
                if let Some(slot) = out.order.get_mut(j) {
                    *slot = prev;
                }
                j -= 1;
            }
            if let Some(slot) = out.order.get_mut(j) {
                *slot = (k, w);
            }
        }
        Ok(out)
    }

    /// Adds the next rows of M, at least one and then as long as the blocks added this call
    /// stay within `budget` (a row of node a costs `len - a` blocks, its `C_kk` included);
    /// `true` once every row is in. An out-of-range node or an uncoupled pair is an error.
    pub fn step(&mut self, bank: &Bank, budget: usize) -> Result<bool, SolveError> {
        let order = self.order.get(..self.len).unwrap_or(&[]);
        let mut spent = 0usize;
        while let Some(&(k, wa)) = order.get(self.next) {
            let cost = self.len - self.next;
            if spent > 0 && spent + cost > budget {
                break;
            }
            spent += cost;
            let c = bank
                .c_kk(usize::from(k))
                .ok_or(SolveError::NodeOutOfRange { node: k })?;
            let w = wa * wa;
            for (acc, v) in self.m.iter_mut().zip(c) {
                *acc += w * v;
            }
            let row = bank.upper_couplings(usize::from(k));
            let mut at = row.nodes().iter().enumerate();
            for &(l, wb) in order.iter().skip(self.next + 1) {
                let Some((i, _)) = at.find(|&(_, &n)| n >= l).filter(|&(_, &n)| n == l) else {
                    return Err(SolveError::MissingCoupling { k, l });
                };
                row.add_symmetric_part(i, wa * wb, &mut self.m);
            }
            self.next += 1;
        }
        Ok(self.next >= self.len)
    }

    /// Factors M once every row is in ([`WeightedFill::step`] returned `true`); an
    /// ill-conditioned or non-finite M is an error.
    pub fn factor(&self) -> Result<WeightedSolve, SolveError> {
        Ok(WeightedSolve {
            nodes: self.nodes,
            weights: self.weights,
            len: self.len,
            factor: factor_compliance(self.m)?,
        })
    }
}

/// The checked factor of a 3 x 3 compliance given by its upper triangle (xx, xy, xz, yy, yz,
/// zz): a NaN or infinite entry (a zero weight turns an infinity into NaN) is
/// [`SolveError::NonFinite`] (checked by [`Factor::new`]), a pivot under [`MIN_PIVOT_REL`] an
/// error.
fn factor_compliance(m: [f32; 6]) -> Result<Factor<3>, SolveError> {
    let [xx, xy, xz, yy, yz, zz] = m;
    let factor = Factor::new([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]], 3)?;
    factor.check()?;
    Ok(factor)
}

/// Weighted contact, energy-minimal form: [`WeightedSolve::new`] then
/// [`WeightedSolve::forces`].
pub fn solve_weighted(
    bank: &Bank,
    nodes: &[u16],
    weights: &[f32],
    d_m: [f32; 3],
) -> Result<ContactForces, SolveError> {
    WeightedSolve::new(bank, nodes, weights)?.forces(d_m)
}

/// Triangle contact, energy-minimal form: the single constraint `B u_S = d_m` on the contact
/// point, `f_tool = (B C_SS B^T)^-1 d_m`, `f_v = k_v f_tool` (3 x 3 solve): [`solve_weighted`]
/// with the barycentric coordinates as weights.
pub fn solve_triangle_barycentric(
    bank: &Bank,
    triangle: [u16; 3],
    bary: [f32; 3],
    d_m: [f32; 3],
) -> Result<ContactForces, SolveError> {
    solve_weighted(bank, &triangle, &bary, d_m)
}

/// Condition estimate ([`Factor::condition`]) of the paper's form: `C_SS` of the triangle.
pub fn condition_alpha(bank: &Bank, triangle: [u16; 3]) -> Result<f32, SolveError> {
    Ok(factor_css(bank, &triangle)?.condition())
}

/// Condition estimate ([`Factor::condition`]) of the energy-minimal form: `B C_SS B^T`.
pub fn condition_barycentric(
    bank: &Bank,
    triangle: [u16; 3],
    bary: [f32; 3],
) -> Result<f32, SolveError> {
    Ok(WeightedSolve::new(bank, &triangle, &bary)?.condition())
}

/// Slope (dimensionless, N of rendered force per N of the linear model's force) at which a
/// positive Q(0) is blended out near zero ([`apply_tissue_law`]): `Q_b(s) = Q(s) - max(0,
/// Q(0) - LAW_ZERO_BLEND_SLOPE s)`. So `Q_b(0) = 0`, `Q_b = Q` from `s = Q(0) /
/// LAW_ZERO_BLEND_SLOPE` on, and in between the law's slope plus this one: the blend at most
/// adds the linear model's own stiffness (1), never a step. Without it a law with an offset
/// (`Q(0) > 0`) renders `Q(0)` at the slightest penetration, in the direction of micrometre
/// encoder noise: the surface buzzes. A law with `Q(0) <= 0` is unchanged, bit for bit.
pub const LAW_ZERO_BLEND_SLOPE: f32 = 1.0;

/// The quasi non-linear law (paper eqs. 5-6) on a force `f` (N) produced by imposing the
/// displacement `d` (m): `f = f_t + f_r` with `f_t = (f . d^) d^` along the imposed direction;
/// `|f_t|` is replaced by `max(law.eval(|f_t|), 0)` (linear continuation outside the fitted
/// domain, clamped at 0 so a fit never pulls the tool in), less a positive `Q(0)` blended out
/// near zero ([`LAW_ZERO_BLEND_SLOPE`]), so zero penetration renders zero force; `f_r` is
/// kept. `d = 0` has no direction: `f` is returned unchanged; `f_t = 0` has none either: only
/// `f_r` is returned. NaN or infinite input or result is an error.
pub fn apply_tissue_law(law: &TissueLaw, f: [f32; 3], d: [f32; 3]) -> Result<[f32; 3], SolveError> {
    if !f.iter().chain(d.iter()).all(|v| v.is_finite()) {
        return Err(SolveError::NonFinite);
    }
    let dd = dot(d, d);
    if !dd.is_finite() {
        return Err(SolveError::NonFinite);
    }
    if dd <= 0.0 {
        return Ok(f);
    }
    let norm = crate::vec3::sqrt(dd);
    let dh = d.map(|x| x / norm);
    let s = dot(f, dh);
    let ft = dh.map(|x| s * x);
    let fr = [f[0] - ft[0], f[1] - ft[1], f[2] - ft[2]];
    if s == 0.0 {
        return Ok(fr);
    }
    // Clamped at 0 (`SPEC.md`, tissue law): a fit continued below its domain can go negative,
    // which would pull the tool into the tissue.
    // (Written so that a NaN stays one and is reported below.)
    let q = law.eval(s.abs());
    let q = if q < 0.0 { 0.0 } else { q };
    // Q(s) >= Q(0) (Q increases), so this stays >= 0.
    let excess = law.at_zero() - LAW_ZERO_BLEND_SLOPE * s.abs();
    let q = if excess > 0.0 { q - excess } else { q };
    let qs = if s > 0.0 { q } else { -q };
    let out = [fr[0] + qs * dh[0], fr[1] + qs * dh[1], fr[2] + qs * dh[2]];
    if out.iter().all(|v| v.is_finite()) {
        Ok(out)
    } else {
        Err(SolveError::NonFinite)
    }
}

#[cfg(test)]
#[allow(clippy::needless_range_loop)]
mod tests {
    extern crate std;
    use super::*;
    use crate::fixtures::{gauss, rel_err};
    use bank_format::{AlignedBytes, BankBuilder, TissueLaw};
    use std::vec;
    use std::vec::Vec;

    /// `C_kl = exp(-|x_k - x_l| / L) M` (an SPD kernel times an SPD 3x3), m/N.
    fn block(p: &[[f64; 3]], k: usize, l: usize) -> [[f64; 3]; 3] {
        let m = [
            [1.0e-3, 0.1e-3, 0.0],
            [0.1e-3, 1.2e-3, 0.05e-3],
            [0.0, 0.05e-3, 2.0e-3],
        ];
        let d = (0..3)
            .map(|i| (p[k][i] - p[l][i]).powi(2))
            .sum::<f64>()
            .sqrt();
        let kern = (-d / 0.02).exp();
        m.map(|r| r.map(|v| kern * v))
    }

    /// A bank over `positions` with triangle [0, 1, 2], coupling the pairs `pairs`.
    fn bank_bytes(positions: Vec<[f64; 3]>, pairs: &[(u32, u32)], radius: f64) -> AlignedBytes {
        let n = positions.len();
        let b = BankBuilder {
            c_kk: (0..n).map(|k| block(&positions, k, k)).collect(),
            couplings: pairs
                .iter()
                .map(|&(k, l)| (k, l, block(&positions, k as usize, l as usize)))
                .collect(),
            mesh_ids: (0..n as u32).collect(),
            triangles: vec![[0, 1, 2]],
            positions_m: positions,
            grid_cell_size_m: 0.008,
            truncation_radius_m: radius,
            scene_id: 1,
            law: TissueLaw::chebyshev(&[2.6, 2.5, 0.1], [0.0, 5.0]).unwrap(),
            gravity: None,
            relaxation: None,
            samples: None,
            device: crate::fixtures::bench_device([0.005, 0.005, 0.1]),
        };
        AlignedBytes::new(&b.build().unwrap())
    }

    fn triangle_bank() -> AlignedBytes {
        let p = vec![[0.0, 0.0, 0.0], [0.01, 0.0, 0.0], [0.0, 0.01, 0.0]];
        bank_bytes(p, &[(0, 1), (0, 2), (1, 2)], 0.02)
    }

    /// Dense `C_SS` in f64 from the bank's (f32) blocks.
    fn css64(bank: &Bank, nodes: &[u16]) -> Vec<Vec<f64>> {
        let m = 3 * nodes.len();
        let mut c = vec![vec![0.0; m]; m];
        for (a, &k) in nodes.iter().enumerate() {
            for (b, &l) in nodes.iter().enumerate() {
                let blk = bank.coupling(k as usize, l as usize).unwrap();
                for i in 0..3 {
                    for j in 0..3 {
                        c[3 * a + i][3 * b + j] = f64::from(blk[i][j]);
                    }
                }
            }
        }
        c
    }

    /// An 8-node weighted solve, every pair coupled: `WeightedFill` stepped with any block
    /// budget gives `WeightedSolve::new`'s factor bit for bit (the same sums in the same
    /// order), and both match the f64 `B C_SS B^T` solve; a missing pair or a repeated node is
    /// an error naming it.
    /// A given compliance: the solve renders `W^-1 d`; a refactor that fails (repeated node,
    /// weights not summing to 1, a singular `W`) leaves the held solve as it was.
    #[test]
    fn refactor_in_place_keeps_the_solve_on_error() {
        let w = [2.0e-3, 1.0e-4, 0.0, 1.5e-3, 2.0e-4, 1.0e-3];
        let d = [1.0e-3, -2.0e-3, 5.0e-3];
        let mut s = WeightedSolve::UNIT;
        assert_eq!(s.tool_force(d).unwrap(), d, "M = I");
        s.refactor(w, &[4, 7], &[0.25, 0.75]).unwrap();
        let before = s.tool_force(d).unwrap();
        // W f = d.
        let m = [[w[0], w[1], w[2]], [w[1], w[3], w[4]], [w[2], w[4], w[5]]];
        for (r, row) in m.iter().enumerate() {
            let got: f32 = row.iter().zip(before).map(|(a, f)| a * f).sum();
            assert!((got - d[r]).abs() < 1e-6, "{before:?}");
        }
        assert_eq!(
            s.refactor(w, &[4, 4], &[0.5, 0.5]),
            Err(SolveError::DuplicateNode { node: 4 })
        );
        assert_eq!(s.refactor(w, &[4], &[0.5]), Err(SolveError::BadWeights));
        let singular = [1.0e-3, 1.0e-3, 0.0, 1.0e-3, 0.0, 1.0e-3];
        assert!(s.refactor(singular, &[4], &[1.0]).is_err());
        assert_eq!(s.tool_force(d).unwrap(), before);
        assert_eq!(s.shares().collect::<Vec<_>>(), [(4, 0.25), (7, 0.75)]);
        // A good one replaces it.
        s.refactor([1.0e-3, 0.0, 0.0, 1.0e-3, 0.0, 1.0e-3], &[9], &[1.0])
            .unwrap();
        assert_eq!(s.shares().collect::<Vec<_>>(), [(9, 1.0)]);
        let f = s.tool_force(d).unwrap();
        assert!((0..3).all(|i| (f[i] - 1.0e3 * d[i]).abs() < 1e-3), "{f:?}");
    }

    #[test]
    fn weighted_fill_in_steps_equals_the_one_go_solve_and_f64() {
        let p: Vec<[f64; 3]> = (0..8)
            .map(|i| {
                let a = i as f64 * 0.7;
                [0.004 * a.cos(), 0.004 * a.sin(), 0.0003 * i as f64]
            })
            .collect();
        let pairs: Vec<(u32, u32)> = (0..8u32)
            .flat_map(|k| (k + 1..8).map(move |l| (k, l)))
            .collect();
        let bytes = bank_bytes(p, &pairs, 0.02);
        let bank = Bank::parse(bytes.as_slice()).unwrap();
        let nodes = [5u16, 0, 7, 2, 3, 6, 1, 4];
        let raw = [0.3f32, 0.2, 0.1, 0.1, 0.1, 0.08, 0.07, 0.05];
        let sum: f32 = raw.iter().sum();
        let weights = raw.map(|w| w / sum);
        let d = [0.2e-3, -0.1e-3, -1.0e-3];
        let whole = WeightedSolve::new(&bank, &nodes, &weights).unwrap();
        let want = whole.forces(d).unwrap();
        for budget in [1, 5, 18, 36, usize::MAX] {
            let mut fill = WeightedFill::new(&nodes, &weights).unwrap();
            let mut steps = 1;
            while !fill.step(&bank, budget).unwrap() {
                steps += 1;
            }
            if budget == 18 {
                assert_eq!(steps, 3, "8 nodes, 36 blocks, at most 18 a step");
            }
            let got = fill.factor().unwrap().forces(d).unwrap();
            assert_eq!(got.nodes(), &nodes[..]);
            for (a, b) in got.forces().iter().zip(want.forces()) {
                assert_eq!(a.map(f32::to_bits), b.map(f32::to_bits), "budget {budget}");
            }
        }
        // f64: M = sum_ab w_a w_b C_ab, f_tool = M^-1 d.
        let c = css64(&bank, &nodes);
        let mut m = vec![vec![0.0; 3]; 3];
        for a in 0..8 {
            for b in 0..8 {
                let w = f64::from(weights[a]) * f64::from(weights[b]);
                for i in 0..3 {
                    for j in 0..3 {
                        m[i][j] += w * c[3 * a + i][3 * b + j];
                    }
                }
            }
        }
        let ft = gauss(m, d.map(f64::from).to_vec());
        let tool: Vec<f64> = want.tool_force_n.iter().map(|&v| f64::from(v)).collect();
        assert!(
            rel_err(&[want.tool_force_n], &ft) < 1e-5,
            "{tool:?} vs {ft:?}"
        );

        let kept: Vec<(u32, u32)> = pairs.iter().copied().filter(|&p| p != (3, 4)).collect();
        let missing = bank_bytes(
            (0..8)
                .map(|i| [0.003 * i as f64, 0.001 * (i % 2) as f64, 0.0])
                .collect(),
            &kept,
            0.0,
        );
        let missing = Bank::parse(missing.as_slice()).unwrap();
        assert_eq!(
            WeightedSolve::new(&missing, &nodes, &weights).unwrap_err(),
            SolveError::MissingCoupling { k: 3, l: 4 }
        );
        let twice = [5u16, 0, 7, 2, 3, 6, 1, 5];
        assert_eq!(
            WeightedFill::new(&twice, &weights).unwrap_err(),
            SolveError::DuplicateNode { node: 5 }
        );
    }

    #[test]
    fn point_contact_matches_f64() {
        let bytes = triangle_bank();
        let bank = Bank::parse(&bytes).unwrap();
        let d = [0.001f32, -0.002, -0.005];
        let got = solve_point(&bank, 1, d).unwrap();
        let want = gauss(
            css64(&bank, &[1]),
            d.iter().map(|&v| f64::from(v)).collect(),
        );
        let e = rel_err(got.forces(), &want);
        std::println!("point: rel err {e:.2e}, condition {:.3}", got.condition);
        assert!(e <= 1e-4, "{e}");
        assert_eq!(got.nodes(), &[1]);
        assert_eq!(got.tool_force_n, got.forces()[0]);
    }

    #[test]
    fn triangle_alpha_matches_f64_and_follows_the_tip() {
        let bytes = triangle_bank();
        let bank = Bank::parse(&bytes).unwrap();
        let tri = [0u16, 1, 2];
        let d = [0.0005f32, 0.001, -0.004];
        for bary in [
            [0.2f32, 0.3, 0.5],
            [1.0 / 3.0; 3],
            [0.9, 0.05, 0.05],
            [1.0, 0.0, 0.0],
        ] {
            let alpha = alpha_weights(bary);
            // The paper's claim: the contact point sum k_v u_v moves by d.
            let s: f32 = alpha.iter().zip(bary).map(|(a, k)| a * k).sum();
            assert!((s - 1.0).abs() < 1e-6, "{s}");
            let got = solve_triangle_alpha(&bank, tri, bary, d).unwrap();
            let mut u = Vec::new();
            for a in alpha {
                u.extend(d.iter().map(|&v| f64::from(a) * f64::from(v)));
            }
            let c = css64(&bank, &tri);
            let want = gauss(c.clone(), u.clone());
            let e = rel_err(got.forces(), &want);
            // The solved forces reproduce u*_S, hence B u_S = d.
            let f: Vec<f64> = got
                .forces()
                .iter()
                .flatten()
                .map(|&v| f64::from(v))
                .collect();
            let mut point = [0.0f64; 3];
            for r in 0..9 {
                let ur: f64 = (0..9).map(|j| c[r][j] * f[j]).sum();
                point[r % 3] += f64::from(bary[r / 3]) * ur;
            }
            for i in 0..3 {
                assert!(
                    (point[i] - f64::from(d[i])).abs() <= 1e-4 * 0.005,
                    "{point:?}"
                );
            }
            std::println!(
                "alpha {bary:?}: rel err {e:.2e}, condition {:.1}",
                got.condition
            );
            assert!(e <= 1e-4, "{e}");
        }
    }

    #[test]
    fn triangle_barycentric_matches_f64_and_meets_the_constraint() {
        let bytes = triangle_bank();
        let bank = Bank::parse(&bytes).unwrap();
        let tri = [0u16, 1, 2];
        let d = [0.0005f32, 0.001, -0.004];
        for bary in [[0.2f32, 0.3, 0.5], [1.0 / 3.0; 3], [0.9, 0.05, 0.05]] {
            let got = solve_triangle_barycentric(&bank, tri, bary, d).unwrap();
            let c = css64(&bank, &tri);
            let mut m = vec![vec![0.0; 3]; 3];
            for a in 0..3 {
                for b in 0..3 {
                    let w = f64::from(bary[a]) * f64::from(bary[b]);
                    for i in 0..3 {
                        for j in 0..3 {
                            m[i][j] += w * c[3 * a + i][3 * b + j];
                        }
                    }
                }
            }
            let ft = gauss(m, d.iter().map(|&v| f64::from(v)).collect());
            let want: Vec<f64> = (0..9).map(|r| f64::from(bary[r / 3]) * ft[r % 3]).collect();
            let e = rel_err(got.forces(), &want);
            // B u_S = d with u_S = C_SS f_S.
            let f: Vec<f64> = got
                .forces()
                .iter()
                .flatten()
                .map(|&v| f64::from(v))
                .collect();
            let mut point = [0.0f64; 3];
            for r in 0..9 {
                let ur: f64 = (0..9).map(|j| c[r][j] * f[j]).sum();
                point[r % 3] += f64::from(bary[r / 3]) * ur;
            }
            for i in 0..3 {
                assert!(
                    (point[i] - f64::from(d[i])).abs() <= 1e-4 * 0.005,
                    "{point:?}"
                );
            }
            let ca = condition_alpha(&bank, tri).unwrap();
            let cb = condition_barycentric(&bank, tri, bary).unwrap();
            std::println!(
                "barycentric {bary:?}: rel err {e:.2e}; condition alpha form {ca:.1}, \
                 barycentric form {cb:.1}"
            );
            assert_eq!(cb, got.condition);
            assert!(e <= 1e-4, "{e}");
        }
    }

    #[test]
    fn nearly_coincident_nodes_error_or_stay_finite() {
        for gap in [1.0e-3, 1.0e-5, 1.0e-7] {
            let p = vec![[0.0, 0.0, 0.0], [gap, 0.0, 0.0], [0.0, 0.01, 0.0]];
            let bytes = bank_bytes(p, &[(0, 1), (0, 2), (1, 2)], 0.02);
            let bank = Bank::parse(&bytes).unwrap();
            let tri = [0u16, 1, 2];
            let bary = [0.4f32, 0.4, 0.2];
            let d = [0.0f32, 0.0, -0.005];
            let ca = condition_alpha(&bank, tri);
            let cb = condition_barycentric(&bank, tri, bary).unwrap();
            let alpha = solve_triangle_alpha(&bank, tri, bary, d);
            std::println!(
                "gap {gap:e} m: condition alpha {ca:?}, barycentric {cb:.1}; alpha solve {:?}",
                alpha.map(|f| f.tool_force_n)
            );
            match alpha {
                Ok(f) => {
                    assert!(f.forces().iter().flatten().all(|v| v.is_finite()));
                    assert!(f.tool_force_n.iter().all(|v| v.abs() < 1e3));
                }
                Err(e) => assert!(
                    matches!(
                        e,
                        SolveError::IllConditioned { .. } | SolveError::NotPositiveDefinite
                    ),
                    "{e:?}"
                ),
            }
            // The energy-minimal form does not invert C_SS: always fine here.
            let b = solve_triangle_barycentric(&bank, tri, bary, d).unwrap();
            assert!(b.forces().iter().flatten().all(|v| v.is_finite()));
        }
        // The tightest gap must be refused by the alpha form.
        let p = vec![[0.0, 0.0, 0.0], [1.0e-7, 0.0, 0.0], [0.0, 0.01, 0.0]];
        let bytes = bank_bytes(p, &[(0, 1), (0, 2), (1, 2)], 0.02);
        let bank = Bank::parse(&bytes).unwrap();
        assert!(
            solve_triangle_alpha(&bank, [0, 1, 2], [0.4, 0.4, 0.2], [0.0, 0.0, -0.005]).is_err()
        );
    }

    #[test]
    fn bad_inputs_are_errors() {
        let p = vec![
            [0.0, 0.0, 0.0],
            [0.01, 0.0, 0.0],
            [0.0, 0.01, 0.0],
            [0.05, 0.05, 0.0],
        ];
        // Node 3 is 50+ mm from the others, beyond the 15 mm radius: not coupled.
        let bytes = bank_bytes(p, &[(0, 1), (0, 2), (1, 2)], 0.015);
        let bank = Bank::parse(&bytes).unwrap();
        let d = [0.0f32, 0.0, -0.001];
        assert_eq!(
            solve_imposed(&bank, &[0, 3], &[d, d]).unwrap_err(),
            SolveError::MissingCoupling { k: 0, l: 3 }
        );
        assert_eq!(
            solve_imposed(&bank, &[], &[]).unwrap_err(),
            SolveError::NoNodes
        );
        assert_eq!(
            solve_imposed(&bank, &[0, 1, 2, 3], &[d; 4]).unwrap_err(),
            SolveError::TooManyNodes { count: 4, max: 3 }
        );
        assert_eq!(
            solve_imposed(&bank, &[0, 0], &[d, d]).unwrap_err(),
            SolveError::DuplicateNode { node: 0 }
        );
        assert_eq!(
            solve_point(&bank, 9, d).unwrap_err(),
            SolveError::NodeOutOfRange { node: 9 }
        );
        assert_eq!(
            solve_imposed(&bank, &[0, 1], &[d]).unwrap_err(),
            SolveError::LengthMismatch {
                nodes: 2,
                imposed: 1
            }
        );
        assert_eq!(
            solve_point(&bank, 0, [f32::NAN, 0.0, 0.0]).unwrap_err(),
            SolveError::NonFinite
        );
        assert_eq!(
            solve_triangle_alpha(&bank, [0, 1, 2], [0.5, 0.5, 0.5], d).unwrap_err(),
            SolveError::BadWeights
        );
        assert_eq!(
            solve_triangle_barycentric(&bank, [0, 1, 2], [f32::NAN, 0.5, 0.5], d).unwrap_err(),
            SolveError::NonFinite
        );
        // Zero displacement: zero force.
        let z = solve_point(&bank, 0, [0.0; 3]).unwrap();
        assert_eq!(z.tool_force_n, [0.0; 3]);
    }

    #[test]
    fn tissue_law_splits_along_the_imposed_direction() {
        let law = TissueLaw::chebyshev(&[2.6, 2.5, 0.1], [0.0, 5.0]).unwrap();
        let d = [0.0f32, 0.0, -0.002];
        let f = [0.3f32, -0.1, -1.5];
        let out = apply_tissue_law(&law, f, d).unwrap();
        // f_r = (0.3, -0.1, 0) kept; |f_t| = 1.5 along -z replaced by Q(1.5).
        let q = law.eval(1.5);
        assert_eq!(&out[..2], &f[..2]);
        assert!((out[2] + q).abs() <= 1e-6 * q.abs(), "{out:?} {q}");
        // A pulling force (against d) keeps its sign.
        let pull = apply_tissue_law(&law, [0.0, 0.0, 0.7], d).unwrap();
        assert!((pull[2] - law.eval(0.7)).abs() <= 1e-6);
        // Outside the domain: the law's linear continuation, still finite.
        let big = apply_tissue_law(&law, [0.0, 0.0, -50.0], d).unwrap();
        assert!((big[2] + law.eval(50.0)).abs() <= 1e-4 * law.eval(50.0).abs());
        // Oblique d.
        let d2 = [1.0f32, 1.0, 0.0];
        let o = apply_tissue_law(&law, [2.0, 0.0, 1.0], d2).unwrap();
        let s = 2.0f32 / 2.0f32.sqrt();
        let q2 = law.eval(s);
        let h = 1.0 / 2.0f32.sqrt();
        let want = [1.0 + q2 * h, -1.0 + q2 * h, 1.0];
        for i in 0..3 {
            assert!((o[i] - want[i]).abs() <= 1e-5, "{o:?} {want:?}");
        }
        // d = 0: unchanged; NaN: error; f_t = 0: only f_r.
        assert_eq!(apply_tissue_law(&law, f, [0.0; 3]).unwrap(), f);
        assert_eq!(
            apply_tissue_law(&law, [f32::NAN, 0.0, 0.0], d).unwrap_err(),
            SolveError::NonFinite
        );
        assert_eq!(
            apply_tissue_law(&law, f, [0.0, f32::INFINITY, 0.0]).unwrap_err(),
            SolveError::NonFinite
        );
        assert_eq!(
            apply_tissue_law(&law, [1.0, 0.0, 0.0], d).unwrap(),
            [1.0, 0.0, 0.0]
        );
    }

    /// Q(0) = 0 at the surface: a linear law with a 0.5 N offset, and a fit whose
    /// continuation below its domain is positive at 0 (Q(0) = 0.2 N), render no force at zero
    /// penetration and a force that grows continuously from it: at most the blend's slope plus
    /// the law's, monotone, and the law itself once `s >= Q(0) / LAW_ZERO_BLEND_SLOPE`. (The
    /// law alone rendered Q(0) at the slightest press.) A law through 0 is untouched, bit for
    /// bit.
    #[test]
    fn zero_penetration_renders_zero_force_whatever_the_law_at_zero() {
        let offset = TissueLaw::linear(0.5, 1.0, [0.0, 5.0]).unwrap();
        let fit = TissueLaw::chebyshev(&[2.6, 2.5, 0.1], [0.0, 5.0]).unwrap();
        let continued = TissueLaw::chebyshev(&[1.0, 0.2], [0.5, 2.5]).unwrap();
        let d = [0.0, 0.0, 1e-6];
        for law in [offset, fit, continued] {
            let q0 = law.at_zero();
            assert!(q0 > 0.1, "{q0}");
            let along = |s: f32| apply_tissue_law(&law, [0.0, 0.0, s], d).unwrap()[2];
            assert_eq!(
                along(1e-9),
                law.eval(1e-9) - (q0 - 1e-9 * LAW_ZERO_BLEND_SLOPE)
            );
            assert!(along(1e-6) <= 1e-5, "{}", along(1e-6));
            let mut last = 0.0f32;
            for k in 1..=1000 {
                let s = 2.0e-3 * k as f32;
                let q = along(s);
                assert!(q >= last, "{s}: {q} < {last}");
                let slope = law.slope(s) + LAW_ZERO_BLEND_SLOPE;
                assert!(q - last <= slope * 2.0e-3 * (1.0 + 1e-3) + 1e-6, "{s}");
                if s >= q0 / LAW_ZERO_BLEND_SLOPE {
                    assert_eq!(q, law.eval(s), "{s}");
                }
                last = q;
            }
        }
        // Through zero: the law's own values.
        let through = TissueLaw::linear(0.0, 1.3, [0.0, 5.0]).unwrap();
        assert_eq!(through.at_zero(), 0.0);
        for s in [1e-9f32, 1e-4, 0.3, 4.0] {
            let q = apply_tissue_law(&through, [0.0, 0.0, s], d).unwrap()[2];
            assert_eq!(q, through.eval(s));
        }
    }

    /// A stiffening fit (convex, `Q(f_min) = 0.25 N` with slope 1.2 at `f_min = 0.5 N`) whose
    /// linear continuation below its domain crosses zero at 0.29 N: at contact onset, when the
    /// linear force along the press is 0.1 N, the continuation gives -0.23 N, which would pull
    /// the tool into the tissue. Q is clamped at 0 (`SPEC.md`, tissue law): the component along
    /// the press is zero, the transverse one kept.
    #[test]
    fn tissue_law_is_clamped_at_zero_below_a_stiffening_fit() {
        // Q(x) = 1 + 0.9 T1 + 0.15 T2 on [0.5, 1.0] N: Q(-1) = 0.25, dQ/dx(-1) = 0.9 - 0.6 = 0.3,
        // dQ/df = 0.3 * 2 / 0.5 = 1.2; Q'' > 0 (stiffening).
        let law = TissueLaw::chebyshev(&[1.0, 0.9, 0.15], [0.5, 1.0]).unwrap();
        let continued = law.eval(0.1);
        assert!(
            (continued - (0.25 + 1.2 * (0.1 - 0.5))).abs() < 1e-5,
            "{continued}"
        );
        let d = [0.0, 0.0, 1e-4];
        // Along the press only: nothing left.
        assert_eq!(
            apply_tissue_law(&law, [0.0, 0.0, 0.1], d).unwrap(),
            [0.0; 3]
        );
        // With a transverse part: that part kept as is, none along the press.
        let out = apply_tissue_law(&law, [0.05, 0.0, 0.1], d).unwrap();
        assert_eq!(out, [0.05, 0.0, 0.0]);
        // Pulled out (negative along d): -Q(|s|) clamped the same way.
        assert_eq!(
            apply_tissue_law(&law, [0.0, 0.0, -0.1], d).unwrap(),
            [0.0; 3]
        );
        // Inside the domain it is the law itself.
        let out = apply_tissue_law(&law, [0.0, 0.0, 0.75], d).unwrap();
        assert!((out[2] - law.eval(0.75)).abs() < 1e-6 && out[2] > 0.0);
    }
}
