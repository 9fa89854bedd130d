//! A rigid tool pressed into (or pulling on) a body's surface, bonded: the large-deformation
//! reference of a tool press, and the same press in the linear model.
//!
//! The **bonded indenter** ([`Indenter`]) is the set of surface nodes (vertices and edge nodes
//! of the boundary triangles) within the tool's radius of the contact point. Pressing moves
//! every one of them rigidly by the same displacement vector (all three components prescribed:
//! the tissue sticks to the tool, no sliding, no lift-off), the body's supports are held, every
//! other dof is free of load, and the force on the tool is the sum of the reactions at the
//! indenter's nodes. This differs from the sampled bank's tool model
//! ([`crate::tool::ToolSurface::tool_weights`]): there the tool applies a parabolic pressure of
//! the same radius as nodal weights and its displacement is the load-weighted mean of the
//! patch's (the patch deforms under the load); here the patch is a rigid flat disc, the
//! stiffest patch of that radius (on a half-space the rigid flat punch gives
//! `2 E a / (1 - nu^2)` N/m, the mean displacement of a uniform pressure
//! `3 pi^2 / 16 E a / (1 - nu^2)`, 8 % less: Johnson, *Contact Mechanics*, 1985, section 3.2).
//! So each tool model is compared with itself only: [`indent`] returns the neo-Hookean force
//! and the linear 10-node force of the same indenter, mesh and supports, and their ratio
//! isolates the nonlinearity of the material and of the geometry.

use super::{HyperError, HyperelasticBody, NewtonOptions, Prescribed, solve_path};
use crate::compliance::{ComplianceError, solve_prescribed};
use crate::mesh::Surface;

/// Fewest nodes an indenter may hold: one or two nodes are a point or a line load, whose force
/// depends on the mesh, not on the tool.
pub const MIN_INDENTER_NODES: usize = 3;

/// The surface nodes a bonded tool holds (module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct Indenter {
    nodes: Vec<usize>,
}

/// Errors of an indentation.
#[derive(Debug, thiserror::Error)]
pub enum IndentError {
    /// The indenter is not a patch of this body (too few nodes, a node held by the supports).
    #[error("indenter: {0}")]
    Patch(String),
    /// The neo-Hookean solve failed (an inverted element, no convergence, bad supports).
    #[error(transparent)]
    Large(#[from] HyperError),
    /// The linear solve failed.
    #[error(transparent)]
    Linear(#[from] ComplianceError),
}

impl Indenter {
    /// The nodes of `surface` (the boundary of the mesh `body` is built on: vertices, and the
    /// edge nodes of its triangles' edges) within `radius` metres of `centre`. Errors: fewer
    /// than [`MIN_INDENTER_NODES`] nodes (a radius small for the mesh), a surface that is not
    /// the body's, a radius that is not a positive finite number.
    pub fn disc(
        body: &HyperelasticBody,
        surface: &Surface,
        centre: [f64; 3],
        radius: f64,
    ) -> Result<Self, IndentError> {
        if !(radius > 0.0 && radius.is_finite()) {
            return Err(IndentError::Patch(format!(
                "radius {radius} m is not a positive finite number"
            )));
        }
        let q = body.quadratic();
        let mut nodes = Vec::new();
        for &[a, b, c] in &surface.triangles {
            nodes.extend([a, b, c]);
            for (p, r) in [(a, b), (b, c), (c, a)] {
                nodes.push(q.edge_node(p, r).ok_or_else(|| {
                    IndentError::Patch(format!(
                        "the surface's edge {p}-{r} is not an edge of the body"
                    ))
                })?);
            }
        }
        nodes.sort_unstable();
        nodes.dedup();
        let positions = body.positions();
        nodes.retain(|&n| {
            let p = positions[n];
            let d2: f64 = (0..3).map(|i| (p[i] - centre[i]).powi(2)).sum();
            d2 <= radius * radius
        });
        if nodes.len() < MIN_INDENTER_NODES {
            return Err(IndentError::Patch(format!(
                "{} surface node(s) within {:.2} mm of ({:.4}, {:.4}, {:.4}) m, fewer than {}: \
                 the mesh is too coarse for this tool radius",
                nodes.len(),
                1e3 * radius,
                centre[0],
                centre[1],
                centre[2],
                MIN_INDENTER_NODES
            )));
        }
        Ok(Self { nodes })
    }

    /// The held nodes, ascending.
    pub fn nodes(&self) -> &[usize] {
        &self.nodes
    }
}

/// The force on a bonded indenter at one depth.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IndentForce {
    /// Fraction of the full displacement.
    pub load: f64,
    /// The force the indenter exerts on the body in the neo-Hookean solution, N (the sum of
    /// the reactions at its nodes).
    pub large: [f64; 3],
    /// The same in the linear 10-node model (same mesh, supports and indenter), N.
    pub linear: [f64; 3],
    /// Accepted load steps from the start of the path to this depth.
    pub steps: usize,
    /// Newton iterations over those steps.
    pub iterations: usize,
}

/// Moves `indenter` rigidly by `load * displacement` (m) for each `load` of `stops` (increasing,
/// in `(0, 1]`) along one load path, with `supports` held (their prescribed values, scaled
/// with the load like the indenter's; the indenter's nodes must not be among them), and returns the force on the indenter at each
/// stop, neo-Hookean and linear. Errors name the failure: an inverted element, Newton without
/// convergence (with the load factor reached), supports that leave a rigid motion free.
pub fn indent(
    body: &HyperelasticBody,
    supports: &Prescribed,
    indenter: &Indenter,
    displacement: [f64; 3],
    stops: &[f64],
    options: &NewtonOptions,
) -> Result<Vec<IndentForce>, IndentError> {
    let mut prescribed = supports.clone();
    for &n in &indenter.nodes {
        if (0..3).any(|a| supports.get(n, a).is_some()) {
            return Err(IndentError::Patch(format!(
                "node {n} at {:?} m is held by the supports",
                body.positions()[n]
            )));
        }
        for (axis, &v) in displacement.iter().enumerate() {
            prescribed.set(n, axis, v)?;
        }
    }
    let sum = |f: &[f64]| -> [f64; 3] {
        std::array::from_fn(|a| indenter.nodes.iter().map(|&n| f[3 * n + a]).sum())
    };
    let (_, f_linear) = solve_prescribed(
        body.quadratic(),
        &prescribed.fixed_set(),
        &prescribed.field(),
    )?;
    let linear = sum(&f_linear);
    let path = solve_path(body, &prescribed, stops, options, &mut |_| {})?;
    Ok(path
        .iter()
        .zip(stops)
        .map(|(s, &load)| IndentForce {
            load,
            large: sum(&s.forces),
            linear: linear.map(|x| load * x),
            steps: s.steps.len(),
            iterations: s.steps.iter().map(|r| r.iterations).sum(),
        })
        .collect())
}
