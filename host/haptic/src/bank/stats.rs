//! What a built bank gives the firmware, measured on the bank as the firmware reads it: the
//! tool patches it forms at the triangles' centroids ([`tool_patches`]) and the candidate lists
//! of the detection grid ([`grid_candidates`]). `host bank build` and `host bank inspect` print
//! them.

use bank_format::Bank;
use firmware::patch::tool_patch;

/// The firmware's tool patch (its own [`tool_patch`], at the bank's tip radius) at the
/// centroid of every triangle of a bank.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PatchStats {
    /// The most nodes in one patch.
    pub max_nodes: usize,
    /// The largest share of a patch's load dropped (nodes the bank does not couple, or beyond
    /// [`firmware::solve::MAX_CONTACT_NODES`]), 0 to 1.
    pub max_dropped: f32,
}

/// The tool patches at the triangles' centroids of `bank`.
pub fn tool_patches(bank: &Bank) -> PatchStats {
    let mut s = PatchStats::default();
    let p = bank.positions();
    for (t, tri) in bank.triangles().iter().enumerate() {
        let v = tri.map(|k| p[usize::from(k)]);
        let centroid = std::array::from_fn(|i| (v[0][i] + v[1][i] + v[2][i]) / 3.0);
        let patch = tool_patch(
            bank,
            t as u32,
            *tri,
            [1.0 / 3.0; 3],
            centroid,
            bank.device().tip_radius_m,
        );
        s.max_nodes = s.max_nodes.max(patch.nodes().len());
        s.max_dropped = s.max_dropped.max(patch.dropped);
    }
    s
}

/// Candidate triangles per cell of a bank's detection grid.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CandidateStats {
    /// The largest candidate list of the grid's cells.
    pub max: usize,
    /// The mean over the cells of clearance at most 1 (those where detection tests
    /// candidates); 0 when there is none.
    pub mean_near_surface: f64,
}

/// The candidate lists of `bank`'s grid.
pub fn grid_candidates(bank: &Bank) -> CandidateStats {
    let g = bank.grid();
    let (mut max, mut sum, mut near) = (0, 0usize, 0usize);
    for c in 0..g.cell_count() {
        let k = g.cell_triangles(c).len();
        max = max.max(k);
        if g.clearance(c) <= 1 {
            sum += k;
            near += 1;
        }
    }
    CandidateStats {
        max,
        mean_near_surface: if near > 0 {
            sum as f64 / near as f64
        } else {
            0.0
        },
    }
}
