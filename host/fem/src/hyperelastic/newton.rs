//! Newton's method with adaptive load stepping and a backtracking line search (module docs of
//! [`super`]).

use super::body::{HyperelasticBody, State};
use super::{HyperError, Prescribed};
use crate::elasticity::{DofMap, Stiffness};
use crate::ordering::nested_dissection;
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::perm::PermRef;
use faer::sparse::SparseColMat;
use faer::sparse::linalg::cholesky::{
    CholeskySymbolicParams, LdltRef, LltRef, SymbolicCholesky, SymmetricOrdering,
    factorize_symbolic_cholesky,
};
use faer::{Conj, Mat, Par, Side};

/// Tolerances and limits of [`solve`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NewtonOptions {
    /// Load steps to try first (the step length starts at `1 / initial_steps`).
    pub initial_steps: usize,
    /// Smallest load step before giving up (fraction of the full load).
    pub min_step: f64,
    /// Newton iterations per load step before the step is halved.
    pub max_iterations: usize,
    /// Convergence: free-dof residual norm at most this fraction of the reaction norm, and
    /// the last Newton correction at most `increment_tolerance` of the displacement norm; or a
    /// correction below 1e-12 of the displacement norm (round-off); or, once the line search
    /// finds no decrease, a correction below `increment_tolerance`.
    pub residual_tolerance: f64,
    /// See `residual_tolerance`.
    pub increment_tolerance: f64,
    /// Halvings of the line search before the iteration counts as failed.
    pub line_search_halvings: usize,
}

impl Default for NewtonOptions {
    /// 4 initial steps, smallest step 1e-4, 25 iterations, tolerances 1e-10 and 1e-8, 10
    /// line-search halvings.
    fn default() -> Self {
        Self {
            initial_steps: 4,
            min_step: 1e-4,
            max_iterations: 25,
            residual_tolerance: 1e-10,
            increment_tolerance: 1e-8,
            line_search_halvings: 10,
        }
    }
}

/// A Newton correction below this fraction of the displacement norm is round-off: the
/// iteration has converged whatever the residual (which then sits at its floating-point floor,
/// above a relative tolerance at very small loads).
const ROUND_OFF: f64 = 1e-12;

/// One converged load step.
#[derive(Debug, Clone, PartialEq)]
pub struct StepReport {
    /// Step number, 1-based (accepted steps only).
    pub step: usize,
    /// Load factor reached (1 is the full prescribed displacement).
    pub load: f64,
    /// Newton iterations after the predictor.
    pub iterations: usize,
    /// Free-dof residual norm after the predictor and after each iteration, N.
    pub residuals: Vec<f64>,
    /// Failed attempts (halvings) before this step converged.
    pub halvings: usize,
    /// Whether some tangent of the step was not positive definite (factorised as `L D L^T`).
    pub indefinite: bool,
}

/// The converged state at the full load.
#[derive(Debug, Clone)]
pub struct Solution {
    /// Node-major displacements, m.
    pub u: Vec<f64>,
    /// Internal nodal forces, node-major, N: the reactions at prescribed dofs, zero to the
    /// tolerance elsewhere.
    pub forces: Vec<f64>,
    /// The accepted load steps.
    pub steps: Vec<StepReport>,
}

impl Solution {
    /// Sum of the reactions on the prescribed dofs of `nodes` along `axis`, N (the force a
    /// platen or a grasper exerts on the body is this sum).
    pub fn reaction(&self, nodes: impl IntoIterator<Item = usize>, axis: usize) -> f64 {
        nodes.into_iter().map(|n| self.forces[3 * n + axis]).sum()
    }
}

/// Why one attempt at a load step failed.
enum StepFailure {
    Inverted(usize),
    NoConvergence {
        iterations: usize,
        residual: f64,
        reason: String,
    },
    Singular(String),
}

/// The symbolic factorisation of `K_ff`, shared by every tangent of the solve.
struct Factor {
    symbolic: SymbolicCholesky<usize>,
}

/// A numeric factorisation of one tangent: `L L^T`, or `L D L^T` when the tangent is not
/// positive definite.
struct Numeric {
    values: Vec<f64>,
    indefinite: bool,
}

impl Factor {
    fn scratch(&self, par: Par) -> faer::dyn_stack::StackReq {
        self.symbolic
            .factorize_numeric_llt_scratch::<f64>(par, Default::default())
            .or(self
                .symbolic
                .factorize_numeric_ldlt_scratch::<f64>(par, Default::default()))
            .or(self.symbolic.solve_in_place_scratch::<f64>(1, par))
    }

    /// Factorises `K` (upper triangle, the symbolic structure's pattern): Cholesky, or
    /// `L D L^T` if Cholesky finds it not positive definite.
    fn factorize(&self, k: &SparseColMat<usize, f64>) -> Result<Numeric, String> {
        let par = Par::rayon(0);
        let mut values = vec![0.0; self.symbolic.len_val()];
        let mut mem =
            MemBuffer::try_new(self.scratch(par)).map_err(|_| "out of memory".to_string())?;
        let llt = self.symbolic.factorize_numeric_llt(
            &mut values,
            k.as_ref(),
            Side::Upper,
            Default::default(),
            par,
            MemStack::new(&mut mem),
            Default::default(),
        );
        if llt.is_ok() {
            return Ok(Numeric {
                values,
                indefinite: false,
            });
        }
        values.fill(0.0);
        self.symbolic
            .factorize_numeric_ldlt(
                &mut values,
                k.as_ref(),
                Side::Upper,
                Default::default(),
                par,
                MemStack::new(&mut mem),
                Default::default(),
            )
            .map_err(|e| format!("L D L^T: {e:?}"))?;
        Ok(Numeric {
            values,
            indefinite: true,
        })
    }

    /// Solves `K x = b` in place with a factorisation of `K`.
    fn solve(&self, numeric: &Numeric, rhs: &mut Mat<f64>) -> Result<(), String> {
        let par = Par::rayon(0);
        let mut mem = MemBuffer::try_new(self.symbolic.solve_in_place_scratch::<f64>(1, par))
            .map_err(|_| "out of memory".to_string())?;
        let stack = MemStack::new(&mut mem);
        if numeric.indefinite {
            LdltRef::new(&self.symbolic, &numeric.values).solve_in_place_with_conj(
                Conj::No,
                rhs.as_mut(),
                par,
                stack,
            );
        } else {
            LltRef::new(&self.symbolic, &numeric.values).solve_in_place_with_conj(
                Conj::No,
                rhs.as_mut(),
                par,
                stack,
            );
        }
        Ok(())
    }
}

/// The norm of the free part of a node-major force vector.
fn free_norm(dofs: &DofMap, f: &[f64]) -> f64 {
    f.iter()
        .enumerate()
        .filter(|(d, _)| dofs.free_dof(d / 3, d % 3).is_some())
        .map(|(_, x)| x * x)
        .sum::<f64>()
        .sqrt()
}

/// The norm of the prescribed part of a node-major force vector (the reactions).
fn held_norm(dofs: &DofMap, f: &[f64]) -> f64 {
    f.iter()
        .enumerate()
        .filter(|(d, _)| dofs.free_dof(d / 3, d % 3).is_none())
        .map(|(_, x)| x * x)
        .sum::<f64>()
        .sqrt()
}

fn norm(v: &[f64]) -> f64 {
    v.iter().map(|x| x * x).sum::<f64>().sqrt()
}

/// Solves the static equilibrium of `body` under the displacements `prescribed` (every other
/// dof free of load) from the undeformed state, reporting each converged load step to
/// `on_step`. Refuses prescribed sets that leave a rigid motion free.
pub fn solve(
    body: &HyperelasticBody,
    prescribed: &Prescribed,
    options: &NewtonOptions,
    on_step: &mut dyn FnMut(&StepReport),
) -> Result<Solution, HyperError> {
    let mut path = solve_path(body, prescribed, &[1.0], options, on_step)?;
    Ok(path.pop().expect("one stop asked, one solution"))
}

/// [`solve`] along one load path that stops at each load factor of `stops` (increasing, in
/// `(0, 1]`): the load steps are shortened to land on every stop, and the converged state at
/// each stop is returned, in order (its `steps` are those of the path up to it). One path to
/// several depths costs about one solve to the deepest, not one solve per depth.
pub fn solve_path(
    body: &HyperelasticBody,
    prescribed: &Prescribed,
    stops: &[f64],
    options: &NewtonOptions,
    on_step: &mut dyn FnMut(&StepReport),
) -> Result<Vec<Solution>, HyperError> {
    if stops.is_empty()
        || stops.iter().any(|&s| !(s > 0.0 && s <= 1.0))
        || stops.windows(2).any(|w| w[1] <= w[0])
    {
        return Err(HyperError::Prescribed(format!(
            "the load stops must increase within (0, 1], got {stops:?}"
        )));
    }
    if prescribed.nodes() != body.nodes() {
        return Err(HyperError::Prescribed(format!(
            "the prescribed set covers {} nodes but the body has {}",
            prescribed.nodes(),
            body.nodes()
        )));
    }
    if options.initial_steps == 0 || !(options.min_step > 0.0 && options.min_step <= 1.0) {
        return Err(HyperError::Prescribed(format!(
            "options: initial_steps must be at least 1 and min_step in (0, 1], got {} and {}",
            options.initial_steps, options.min_step
        )));
    }
    let fixed = prescribed.fixed_set();
    body.quadratic().check_rigid_motions(&fixed)?;
    let dofs = DofMap::new(&fixed);
    let target = prescribed.field();
    let mut u = vec![0.0; 3 * body.nodes()];
    let rest = body.evaluate(&u).map_err(|element| HyperError::Inverted {
        element,
        step: 1,
        from: 0.0,
        to: 0.0,
    })?;
    let factor = if dofs.free_count() == 0 {
        None
    } else {
        let perm =
            nested_dissection(body.quadratic(), &dofs).map_err(|e| HyperError::Singular {
                step: 1,
                load: 0.0,
                reason: e,
            })?;
        let pattern = body.tangent(&rest, &dofs);
        let symbolic = factorize_symbolic_cholesky(
            pattern.symbolic(),
            Side::Upper,
            SymmetricOrdering::Custom(PermRef::new_checked(
                &perm.forward,
                &perm.inverse,
                dofs.free_count(),
            )),
            CholeskySymbolicParams::default(),
        )
        .map_err(|e| HyperError::Singular {
            step: 1,
            load: 0.0,
            reason: format!("{e:?}"),
        })?;
        Some(Factor { symbolic })
    };
    let mut load = 0.0;
    let mut dl = 1.0 / options.initial_steps as f64;
    let mut steps = Vec::new();
    let mut halvings = 0;
    let mut last_tangent = None;
    let mut solutions = Vec::with_capacity(stops.len());
    for &stop in stops {
        while load < stop {
            let to = if load + dl > stop - 1e-12 * stop {
                stop
            } else {
                load + dl
            };
            let increment: Vec<f64> = target.iter().map(|x| (to - load) * x).collect();
            match step(
                body,
                &dofs,
                factor.as_ref(),
                &u,
                &increment,
                options,
                &mut last_tangent,
            ) {
                Ok((next, residuals, indefinite)) => {
                    u = next;
                    load = to;
                    let report = StepReport {
                        step: steps.len() + 1,
                        load,
                        iterations: residuals.len() - 1,
                        residuals,
                        halvings,
                        indefinite,
                    };
                    on_step(&report);
                    if report.iterations <= 4 {
                        dl = (dl * 1.5).min(1.0);
                    }
                    steps.push(report);
                    halvings = 0;
                }
                Err(failure) => {
                    // The failed attempt's tangents belong to states that were not kept.
                    last_tangent = None;
                    if dl * 0.5 >= options.min_step * (1.0 - 1e-12) {
                        dl *= 0.5;
                        halvings += 1;
                        continue;
                    }
                    let (step, from) = (steps.len() + 1, load);
                    return Err(match failure {
                        StepFailure::Inverted(element) => HyperError::Inverted {
                            element,
                            step,
                            from,
                            to,
                        },
                        StepFailure::NoConvergence {
                            iterations,
                            residual,
                            reason,
                        } => HyperError::NoConvergence {
                            step,
                            from,
                            to,
                            iterations,
                            residual,
                            reason,
                        },
                        StepFailure::Singular(reason) => HyperError::Singular {
                            step,
                            load: from,
                            reason,
                        },
                    });
                }
            }
        }
        let state = body
            .evaluate(&u)
            .expect("the converged state was evaluated");
        let forces = body.forces(&state);
        solutions.push(Solution {
            u: u.clone(),
            forces,
            steps: steps.clone(),
        });
    }
    Ok(solutions)
}

/// The factorised tangent `K_ff` of `state`.
fn factorize(
    body: &HyperelasticBody,
    dofs: &DofMap,
    factor: &Factor,
    state: &State,
) -> Result<Numeric, StepFailure> {
    factor
        .factorize(&body.tangent(state, dofs))
        .map_err(StepFailure::Singular)
}

/// Solves `K_ff x = -r_f` with a factorised tangent; returns the node-major correction (zero
/// at prescribed dofs).
fn correction(
    dofs: &DofMap,
    factor: &Factor,
    numeric: &Numeric,
    r: &[f64],
) -> Result<Vec<f64>, StepFailure> {
    let mut rhs = Mat::<f64>::zeros(dofs.free_count(), 1);
    for (d, x) in r.iter().enumerate() {
        if let Some(f) = dofs.free_dof(d / 3, d % 3) {
            rhs[(f, 0)] = -x;
        }
    }
    factor
        .solve(numeric, &mut rhs)
        .map_err(StepFailure::Singular)?;
    let free: Vec<f64> = (0..dofs.free_count()).map(|f| rhs[(f, 0)]).collect();
    if free.iter().any(|x| !x.is_finite()) {
        return Err(StepFailure::Singular(
            "the tangent solve gave a non-finite correction".into(),
        ));
    }
    Ok(dofs.expand(&free))
}

/// One load step from the converged `u` by the prescribed `increment` (zero at free dofs):
/// the linearised predictor, then Newton iterations with a backtracking line search on the
/// free-dof residual norm. Returns the new state, the residual history and whether a tangent
/// was indefinite. `last_tangent` holds the last tangent factorised by the previous step (assembled
/// one correction before its converged state): the predictor solves with it instead of
/// factorising the converged state's tangent, which is one factorisation fewer per step and
/// only an initial guess; this step's last factorisation replaces it.
fn step(
    body: &HyperelasticBody,
    dofs: &DofMap,
    factor: Option<&Factor>,
    u: &[f64],
    increment: &[f64],
    options: &NewtonOptions,
    last_tangent: &mut Option<Numeric>,
) -> Result<(Vec<f64>, Vec<f64>, bool), StepFailure> {
    let mut x: Vec<f64> = u.iter().zip(increment).map(|(a, b)| a + b).collect();
    let Some(factor) = factor else {
        body.evaluate(&x).map_err(StepFailure::Inverted)?;
        return Ok((x, vec![0.0], false));
    };
    // Predictor: K_ff dx_f = -(r_f(u) + K_fp du_p) at the converged state.
    let old = body.evaluate(u).map_err(StepFailure::Inverted)?;
    let r_old = body.forces(&old);
    let k_inc = body.tangent_apply(&old, increment);
    let rhs: Vec<f64> = r_old.iter().zip(&k_inc).map(|(a, b)| a + b).collect();
    let numeric = match last_tangent.take() {
        Some(n) => n,
        None => factorize(body, dofs, factor, &old)?,
    };
    let mut indefinite = numeric.indefinite;
    let dx = correction(dofs, factor, &numeric, &rhs)?;
    for (xi, d) in x.iter_mut().zip(&dx) {
        *xi += d;
    }
    let mut state = body.evaluate(&x).map_err(StepFailure::Inverted)?;
    let mut forces = body.forces(&state);
    let mut residual = free_norm(dofs, &forces);
    let mut residuals = vec![residual];
    let mut last = norm(&dx);
    for _ in 0..=options.max_iterations {
        let scale = held_norm(dofs, &forces);
        let size = norm(&x);
        if (residual <= options.residual_tolerance * scale
            && last <= options.increment_tolerance * size)
            || last <= ROUND_OFF * size
        {
            return Ok((x, residuals, indefinite));
        }
        if residuals.len() > options.max_iterations {
            break;
        }
        let numeric = factorize(body, dofs, factor, &state)?;
        indefinite |= numeric.indefinite;
        let dx = correction(dofs, factor, &numeric, &forces)?;
        *last_tangent = Some(numeric);
        let mut alpha = 1.0;
        let mut accepted = None;
        let mut inverted = None;
        for _ in 0..=options.line_search_halvings {
            let trial: Vec<f64> = x.iter().zip(&dx).map(|(a, d)| a + alpha * d).collect();
            match body.evaluate(&trial) {
                Err(t) => inverted = Some(t),
                Ok(s) => {
                    let f = body.forces(&s);
                    let r = free_norm(dofs, &f);
                    // Sufficient decrease, or already at round-off (a full step near the
                    // solution whose residual cannot drop further).
                    if r <= (1.0 - 1e-4 * alpha) * residual
                        || (alpha == 1.0 && r <= 1e3 * options.residual_tolerance * scale)
                    {
                        accepted = Some((trial, s, f, r));
                        break;
                    }
                }
            }
            alpha *= 0.5;
        }
        let Some((trial, s, f, r)) = accepted else {
            // At round-off the residual cannot drop further; a correction below the increment
            // tolerance says the state is the solution to that precision.
            if inverted.is_none() && norm(&dx) <= options.increment_tolerance * norm(&x) {
                return Ok((x, residuals, indefinite));
            }
            return Err(match inverted {
                Some(t) => StepFailure::Inverted(t),
                None => StepFailure::NoConvergence {
                    iterations: residuals.len(),
                    residual,
                    reason: "the line search found no decrease of the residual".into(),
                },
            });
        };
        last = alpha * norm(&dx);
        x = trial;
        state = s;
        forces = f;
        residual = r;
        residuals.push(residual);
    }
    Err(StepFailure::NoConvergence {
        iterations: residuals.len() - 1,
        residual,
        reason: format!("{} iterations were not enough", options.max_iterations),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use faer::sparse::{SymbolicSparseColMat, Triplet};

    /// The upper triangle of a symmetric matrix given densely, in CSC.
    fn upper(a: &[[f64; 4]; 4]) -> SparseColMat<usize, f64> {
        let mut t = Vec::new();
        for (i, row) in a.iter().enumerate() {
            for (j, &x) in row.iter().enumerate() {
                if i <= j && x != 0.0 {
                    t.push(Triplet::new(i, j, x));
                }
            }
        }
        SparseColMat::try_new_from_triplets(4, 4, &t).unwrap()
    }

    fn factor(k: &SparseColMat<usize, f64>) -> Factor {
        let symbolic: SymbolicSparseColMat<usize> = k.symbolic().to_owned().unwrap();
        Factor {
            symbolic: factorize_symbolic_cholesky(
                symbolic.as_ref(),
                Side::Upper,
                SymmetricOrdering::Identity,
                CholeskySymbolicParams::default(),
            )
            .unwrap(),
        }
    }

    /// Solves with the matrix and checks `A x = b` by a dense product.
    fn solves(a: [[f64; 4]; 4], definite: bool) {
        let k = upper(&a);
        let b = [1.0, -2.0, 0.5, 3.0];
        let mut x = Mat::<f64>::from_fn(4, 1, |i, _| b[i]);
        let f = factor(&k);
        let numeric = f.factorize(&k).unwrap();
        assert_eq!(numeric.indefinite, !definite);
        f.solve(&numeric, &mut x).unwrap();
        for (row, bi) in a.iter().zip(b) {
            let ax: f64 = (0..4).map(|j| row[j] * x[(j, 0)]).sum();
            assert!((ax - bi).abs() < 1e-12, "{ax} vs {bi}");
        }
    }

    #[test]
    fn positive_definite_tangents_take_cholesky() {
        solves(
            [
                [4.0, 1.0, 0.0, 0.5],
                [1.0, 3.0, 1.0, 0.0],
                [0.0, 1.0, 2.0, 0.3],
                [0.5, 0.0, 0.3, 5.0],
            ],
            true,
        );
    }

    #[test]
    fn indefinite_tangents_fall_back_to_ldlt() {
        // Eigenvalues of the leading 2x2 block: 3 and -1.
        solves(
            [
                [1.0, 2.0, 0.0, 0.0],
                [2.0, 1.0, 0.5, 0.0],
                [0.0, 0.5, 3.0, 1.0],
                [0.0, 0.0, 1.0, -2.0],
            ],
            false,
        );
    }
}
