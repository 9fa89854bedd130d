//! Static large deformation: a compressible neo-Hookean body on 10-node tetrahedra, loaded by
//! prescribed displacements and solved by Newton's method with load stepping and a line
//! search. It is the large-strain reference the linear model of the paper (section 3, eq. 1)
//! is measured against.
//!
//! **Material** ([`NeoHookean`]): the compressible neo-Hookean strain energy of Bonet & Wood
//! (*Nonlinear Continuum Mechanics for Finite Element Analysis*, 2nd ed., 2008, eq. 6.27)
//!
//! `W(F) = mu/2 (I1 - 3) - mu ln J + lambda/2 (ln J)^2`, `I1 = tr(F^T F)`, `J = det F`,
//!
//! with first Piola-Kirchhoff stress `P = mu (F - F^-T) + lambda ln J F^-T` and tangent
//! `dP_iJ/dF_kL = mu d_ik d_JL + (mu - lambda ln J) F^-1_Li F^-1_Jk + lambda F^-1_Ji F^-1_Lk`.
//! At `F = I` this tangent is the linear elasticity tensor with the same Lamé parameters
//! `(lambda, mu)` as [`crate::elasticity::Material::lame`], so at small strain the model is the
//! linear one exactly.
//!
//! **Element**: total Lagrangian on the 10-node tetrahedra of
//! [`crate::elasticity::quadratic::QuadraticBody`] (same nodes, same numbering: mesh vertices,
//! then edge midpoints; straight-sided reference elements), integrated by the same 4-point
//! Gauss rule (degree 2). The internal force of node `a` is
//! `f_a = sum_q w_q P(F_q) G_a(q)` and the tangent block
//! `K_ab = sum_q w_q [mu (G_a . G_b) I + (mu - lambda ln J) g_b g_a^T + lambda g_a g_b^T]`,
//! with `G_a` the material gradient of the shape function and `g_a = F^-T G_a` the spatial one;
//! at `u = 0` this is the quadratic body's `K` block for block.
//!
//! **Loading** ([`Prescribed`]): a displacement per node and per component (bonded platens
//! prescribe all three, frictionless ones only the normal component), every other dof free of
//! load. The reaction forces on the prescribed dofs are the internal forces there
//! ([`Solution::forces`]).
//!
//! **Solver** ([`solve`]): the prescribed displacements are applied in load steps (adaptive:
//! a failed step is halved, an easy one lengthened); each step starts from a linearised
//! predictor (the tangent at the last converged state applied to the step's prescribed
//! increment), then Newton iterations with the consistent tangent, factorised by faer's sparse
//! Cholesky (one symbolic factorisation, nested-dissection ordering, reused by every
//! iteration) or, when the tangent is not positive definite, sparse `L D L^T` on the same
//! symbolic structure; a backtracking line search on the residual norm rejects trial states
//! with an inverted element. Failures are errors that name the reason ([`HyperError`]).
//! [`solve_path`] stops on the way at given load factors (several depths in one solve).
//!
//! **Tool presses** ([`indent`]): a rigid bonded tool patch moved into or out of the surface,
//! its force in this model and in the linear one on the same mesh.

mod body;
pub mod indent;
mod newton;

pub use body::{HyperelasticBody, Volumetric};
pub use newton::{NewtonOptions, Solution, StepReport, solve, solve_path};

/// Homogeneous uniaxial stress of the compressible neo-Hookean model (the strain energy of
/// this module, Lamé parameters `lambda`, `mu` in Pa) at axial stretch `s`: returns the lateral
/// stretch `l`, the root of `P_11 = mu (l - 1/l) + lambda ln(l^2 s) / l = 0` by a scalar Newton
/// iteration from 1, and the axial nominal (first Piola-Kirchhoff) stress
/// `P_33 = mu (s - 1/s) + lambda ln(l^2 s) / s` (Pa, negative in compression). The closed form
/// a frictionless-platen compression test is checked against.
pub fn uniaxial_stress(lambda: f64, mu: f64, s: f64) -> (f64, f64) {
    let mut l = 1.0f64;
    for _ in 0..50 {
        let g = mu * (l * l - 1.0) + lambda * (l * l * s).ln();
        l -= g / (2.0 * mu * l + 2.0 * lambda / l);
    }
    (l, mu * (s - 1.0 / s) + lambda * (l * l * s).ln() / s)
}

use crate::elasticity::{FemError, FixedSet, Material};

/// The compressible neo-Hookean material (module docs: Bonet & Wood eq. 6.27), in pascals.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NeoHookean {
    /// First Lamé parameter lambda, Pa.
    pub lambda: f64,
    /// Shear modulus mu, Pa.
    pub mu: f64,
}

impl NeoHookean {
    /// The neo-Hookean material whose small-strain limit is `material` (same Lamé parameters).
    pub fn new(material: Material) -> Self {
        let (lambda, mu) = material.lame();
        Self { lambda, mu }
    }
}

/// `ln det F` from `H = F - I` without cancellation at small strain
/// (`det(I + H) - 1 = tr H + ((tr H)^2 - tr H^2) / 2 + det H`), or `None` if `det F <= 0`.
pub(crate) fn log_det(h: [[f64; 3]; 3]) -> Option<f64> {
    let tr = h[0][0] + h[1][1] + h[2][2];
    let tr2: f64 = (0..3)
        .flat_map(|i| (0..3).map(move |j| (i, j)))
        .map(|(i, j)| h[i][j] * h[j][i])
        .sum();
    let j_minus_1 = tr + 0.5 * (tr * tr - tr2) + det(h);
    (j_minus_1 > -1.0 && j_minus_1.is_finite()).then(|| j_minus_1.ln_1p())
}

fn det(a: [[f64; 3]; 3]) -> f64 {
    a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1])
        - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
        + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0])
}

/// `F^-1` by cofactors, or `None` if `det F <= 0` or not finite.
pub(crate) fn inverse(f: [[f64; 3]; 3]) -> Option<[[f64; 3]; 3]> {
    let d = det(f);
    if !(d > 0.0 && d.is_finite()) {
        return None;
    }
    let c = |i: usize, j: usize| {
        let (r0, r1) = ((i + 1) % 3, (i + 2) % 3);
        let (c0, c1) = ((j + 1) % 3, (j + 2) % 3);
        f[r0][c0] * f[r1][c1] - f[r0][c1] * f[r1][c0]
    };
    // inv[i][j] = cofactor(j, i) / det (cyclic indices carry the cofactor's sign).
    Some(std::array::from_fn(|i| {
        std::array::from_fn(|j| c(j, i) / d)
    }))
}

/// Prescribed displacements, per node and per component (m); components left unset are free
/// and carry no load.
#[derive(Debug, Clone, PartialEq)]
pub struct Prescribed {
    values: Vec<[Option<f64>; 3]>,
}

impl Prescribed {
    /// Nothing prescribed, for a body of `nodes` nodes.
    pub fn none(nodes: usize) -> Self {
        Self {
            values: vec![[None; 3]; nodes],
        }
    }

    /// Prescribes component `axis` (0 = x, 1 = y, 2 = z) of `node` to `value` metres.
    pub fn set(&mut self, node: usize, axis: usize, value: f64) -> Result<(), HyperError> {
        let nodes = self.values.len();
        if !value.is_finite() {
            return Err(HyperError::Prescribed(format!(
                "node {node} axis {axis}: displacement {value} is not a finite number of metres"
            )));
        }
        if axis > 2 {
            return Err(HyperError::Prescribed(format!(
                "node {node}: axis {axis} is not 0, 1 or 2"
            )));
        }
        let slot = self
            .values
            .get_mut(node)
            .ok_or(FemError::NoSuchNode { node, nodes })?;
        slot[axis] = Some(value);
        Ok(())
    }

    /// Prescribes the given components (`Some(value)`, metres) of every node at `positions`
    /// for which `select` holds (a platen, a contact patch, a grasp point); returns how many
    /// nodes it selected, an error if none.
    pub fn set_where(
        &mut self,
        positions: &[[f64; 3]],
        select: impl Fn([f64; 3]) -> bool,
        components: [Option<f64>; 3],
    ) -> Result<usize, HyperError> {
        if positions.len() != self.values.len() {
            return Err(HyperError::Prescribed(format!(
                "{} positions given for a set of {} nodes",
                positions.len(),
                self.values.len()
            )));
        }
        let mut count = 0;
        for (node, &p) in positions.iter().enumerate() {
            if select(p) {
                for (axis, v) in components.iter().enumerate() {
                    if let Some(v) = *v {
                        self.set(node, axis, v)?;
                    }
                }
                count += 1;
            }
        }
        if count == 0 {
            return Err(HyperError::Prescribed(
                "the selection contains no node".into(),
            ));
        }
        Ok(count)
    }

    /// The prescribed value of component `axis` of `node`, if any.
    pub fn get(&self, node: usize, axis: usize) -> Option<f64> {
        self.values[node][axis]
    }

    /// Number of nodes the set covers.
    pub fn nodes(&self) -> usize {
        self.values.len()
    }

    /// The prescribed dofs as a fixed set.
    pub fn fixed_set(&self) -> FixedSet {
        let mut fixed = FixedSet::none(self.values.len());
        for (node, v) in self.values.iter().enumerate() {
            for (axis, x) in v.iter().enumerate() {
                if x.is_some() {
                    fixed
                        .fix_component(node, axis)
                        .expect("node ids come from the same set");
                }
            }
        }
        fixed
    }

    /// The full node-major field: prescribed values, zeros elsewhere.
    pub fn field(&self) -> Vec<f64> {
        self.values
            .iter()
            .flat_map(|v| v.map(|x| x.unwrap_or(0.0)))
            .collect()
    }
}

/// Errors of the large-deformation solve.
#[derive(Debug, thiserror::Error)]
pub enum HyperError {
    /// Problem in the mesh, the material or the supports.
    #[error(transparent)]
    Fem(#[from] FemError),
    /// Invalid prescribed displacements.
    #[error("invalid prescribed displacements: {0}")]
    Prescribed(String),
    /// An element inverted (`J <= 0` at a quadrature point) and halving the load step down to
    /// the smallest allowed did not avoid it.
    #[error(
        "element {element} inverts (J <= 0 at a quadrature point) in load step {step}, going \
         from load factor {from:.6} to {to:.6}; the smallest load step did not avoid it"
    )]
    Inverted {
        /// The first inverted element (id in the mesh).
        element: usize,
        /// The load step (1-based) that failed.
        step: usize,
        /// Load factor of the last converged state.
        from: f64,
        /// Load factor the step aimed at.
        to: f64,
    },
    /// Newton's method did not converge in a step even at the smallest load step.
    #[error(
        "no convergence in load step {step} (load factor {from:.6} to {to:.6}): {reason}; \
         residual {residual:.3e} N after {iterations} iterations"
    )]
    NoConvergence {
        /// The load step (1-based) that failed.
        step: usize,
        /// Load factor of the last converged state.
        from: f64,
        /// Load factor the step aimed at.
        to: f64,
        /// Newton iterations done in the last attempt.
        iterations: usize,
        /// Norm of the free-dof residual at the end, N.
        residual: f64,
        /// What stopped it (iteration limit, line search).
        reason: String,
    },
    /// The tangent could not be factorised even as `L D L^T`.
    #[error(
        "the tangent stiffness is singular in load step {step} (load factor {load:.6}): {reason}"
    )]
    Singular {
        /// The load step (1-based).
        step: usize,
        /// Load factor of the state where it was assembled.
        load: f64,
        /// faer's report.
        reason: String,
    },
}
