//! The tool's pairs: which nodes of R one contact of the scene's tool can load together, found
//! by running the firmware's own patch rule over the reachable surface. A bank with
//! `bank.couplings = "tool"` couples exactly these (and the pairs within its radius), so the
//! firmware's mutual-influence solve (the paper's eq. 8) never lacks a block it needs.

use anyhow::{Result, bail};
use bank_format::Bank;
use std::collections::BTreeSet;

/// Anchors per triangle side of the lattice [`ToolPairs::sample`] samples: the anchors are
/// the points of barycentric coordinates `(i, j, k) / TOOL_DIVISIONS`, `i + j + k =
/// TOOL_DIVISIONS`, of every triangle of R (91 per triangle).
pub const TOOL_DIVISIONS: usize = 12;

/// A patch with fewer than [`firmware::solve::MAX_CONTACT_NODES`] nodes that dropped more than
/// this share of its load left a node out for want of a coupling (below it: f32 rounding of
/// `1 - kept / total`).
pub const UNCOUPLED_TOL: f32 = 1e-5;

/// The pairs of R the scene's tool can put into one contact set, and what the sampling saw.
#[derive(Debug, Clone)]
pub struct ToolPairs {
    /// Pairs `(a, b)`, `a < b`, indices into R: nodes of one tool patch, and the node the
    /// firmware's nodal quadrature starts from with every node within the tip radius.
    pub pairs: BTreeSet<(usize, usize)>,
    /// Anchors sampled.
    pub anchors: usize,
    /// Most nodes in one patch.
    pub max_nodes: usize,
    /// Largest share of a patch's load the firmware dropped (more than
    /// [`firmware::solve::MAX_CONTACT_NODES`] nodes).
    pub max_dropped: f32,
}

impl ToolPairs {
    /// The pairs a tool of radius `tip_radius_m` can put into one contact set: the firmware's
    /// own patch rule ([`firmware::patch::tool_patch`], f32, on `probe`, a bank of the scene
    /// that couples every pair within [`crate::bank::Prepared::probe_radius`]) at the anchors of a lattice with
    /// `divisions` steps per side on every triangle of R (the reachable surface). Besides
    /// the patch's nodes, the nodal quadrature's start (the contact triangle's vertex of
    /// largest barycentric coordinate) is paired with every node within the tip radius, so
    /// that the firmware finds the same nodal pressures on the smaller bank. Fails if the
    /// probe left a patch node uncoupled.
    pub fn sample(probe: &Bank, tip_radius_m: f64, divisions: usize) -> Result<ToolPairs> {
        let radius = tip_radius_m as f32;
        let r2 = radius * radius;
        let n = divisions.max(1);
        let positions = probe.positions();
        let mut out = ToolPairs {
            pairs: BTreeSet::new(),
            anchors: 0,
            max_nodes: 0,
            max_dropped: 0.0,
        };
        for (t, tri) in probe.triangles().iter().enumerate() {
            let v = tri.map(|k| positions[usize::from(k)]);
            for i in 0..=n {
                for j in 0..=n - i {
                    let bary = [i, j, n - i - j].map(|m| m as f32 / n as f32);
                    let anchor: [f32; 3] = std::array::from_fn(|c| {
                        bary[0] * v[0][c] + bary[1] * v[1][c] + bary[2] * v[2][c]
                    });
                    let patch =
                        firmware::patch::tool_patch(probe, t as u32, *tri, bary, anchor, radius);
                    let nodes = patch.nodes();
                    if patch.dropped > UNCOUPLED_TOL
                        && nodes.len() < firmware::solve::MAX_CONTACT_NODES
                    {
                        bail!(
                            "internal: the probe bank left a node of the tool patch at triangle \
                             {t} uncoupled (its radius is too small)"
                        );
                    }
                    out.anchors += 1;
                    out.max_nodes = out.max_nodes.max(nodes.len());
                    out.max_dropped = out.max_dropped.max(patch.dropped);
                    for (x, &a) in nodes.iter().enumerate() {
                        for &b in &nodes[x + 1..] {
                            let (a, b) = (usize::from(a), usize::from(b));
                            out.pairs.insert((a.min(b), a.max(b)));
                        }
                    }
                    // The firmware's nodal pressures: the nearest vertex (first largest
                    // coordinate) and its neighbours within the tip radius.
                    let nearest =
                        (0..3).fold(0, |best, c| if bary[c] > bary[best] { c } else { best });
                    let a = tri[nearest];
                    for &b in probe.neighbours(usize::from(a)) {
                        let p = positions[usize::from(b)];
                        let d2: f32 = (0..3).map(|c| (p[c] - anchor[c]).powi(2)).sum();
                        if d2 < r2 {
                            let (a, b) = (usize::from(a), usize::from(b));
                            out.pairs.insert((a.min(b), a.max(b)));
                        }
                    }
                }
            }
        }
        Ok(out)
    }
}
