//! The convergence study of the patch compliance (`host contact study`): `W(p)` of the scene's
//! tool at named sites of the reachable surface, on a sequence of FEM meshes (finer and finer
//! where the tool reaches), with one element, and its extrapolated limit.
//!
//! A site is a point near the organ; its contact point is the collision surface's point
//! closest to it (as `host contact probe` finds it), and on each FEM mesh `W` is computed at
//! that mesh's surface point closest to the contact point, exactly as a sampled bank's samples
//! are ([`crate::bank::sampled`]). The figure of merit per site is the normal stiffness
//! `k = 1 / (n . W n)` (N/m: the normal force per metre of a frictionless normal press, the
//! linear model's), and the whole `W`.
//!
//! Extrapolation (Richardson): the levels must refine the *whole* mesh by one ratio
//! `r = h_1 / h_2 = h_2 / h_3` (fine-zone sizes), as the reference series
//! `liver-reach-scaled-*mm` does (`scripts/gen_meshes.py --reach-series scaled`: the 4 mm
//! mesh's size field scaled everywhere). One order `q` serves every site: the discretisation and
//! its order are the same over the surface, and a per-site three-level order is at the mercy of
//! the meshes' noise (unstructured meshes are not nested: at 4 of 14 sites the per-site ratio is
//! below `r`, an order under 1, while the pooled one is 2.06). So `q = ln(S_12 / S_23) / ln r`
//! with `S_ij` the sum over sites of `n . W_j n - n . W_i n` (must be above 1: the differences
//! shrink), clamped to `[1, 4]`; then per site, entry by entry,
//! `W_inf = W_3 + (W_3 - W_2) / (r^q - 1)`. For the straight-sided P2 tetrahedra of the
//! default study the expected order is 2 (the flat faces approximate the curved surface to
//! O(h^2)); the pooled estimate is printed beside it by `host contact study`.
//!
//! The reference's own error per site is Roache's grid convergence index (Roache 1998; Celik et
//! al., J. Fluids Eng. 130, 2008): `1.25 |n . W_inf n - n . W_3 n| / n . W_inf n`, the safety
//! factor 1.25 being the one for a three-grid study whose observed order is that of the method.

use crate::bank::sampled::SampledFem;
use crate::linalg::normal_compliance;
use crate::organ::Organ;
use crate::probe::closest_reachable;
use crate::reach::Region;
use crate::scene::{FemElement, SampledContact, Scene};
use anyhow::{Context, Result, bail};
use fem::compliance::Block3;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// The study's default sites on the default liver (near-surface points, m): the right lobe's
/// top and flanks, the crease between the lobes, the thinner left lobe, the edges of the reach.
pub const DEFAULT_SITES: [(&str, [f64; 3]); 14] = [
    ("right lobe top", [0.02, 0.0, 0.075]),
    ("right lobe top, front", [0.02, -0.02, 0.072]),
    ("right lobe top, back", [0.02, 0.02, 0.072]),
    ("right lobe front flank", [0.015, -0.035, 0.06]),
    ("right lobe back flank", [0.015, 0.035, 0.06]),
    ("straight below the trocar", [0.0, 0.0, 0.075]),
    ("crease", [-0.012, 0.0, 0.07]),
    ("left lobe top", [-0.03, 0.01, 0.065]),
    ("left lobe, thin end", [-0.034, 0.0, 0.062]),
    ("left lobe front", [-0.025, -0.015, 0.06]),
    ("reach edge, front", [0.0, -0.033, 0.065]),
    ("reach edge, back left", [-0.025, 0.03, 0.06]),
    ("reach edge, back right", [0.03, 0.03, 0.066]),
    ("reach edge, front right", [0.035, -0.03, 0.06]),
];

/// A site's contact point on the collision surface.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct Site {
    /// Its name.
    pub name: String,
    /// The point given, m.
    pub query: [f64; 3],
    /// The collision surface's closest point, m.
    pub point: [f64; 3],
    /// That triangle's outward unit normal.
    pub normal: [f64; 3],
}

/// One FEM mesh's results.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct Level {
    /// The mesh file.
    pub mesh: String,
    /// Its fine-zone mesh size, m (as given).
    pub h_m: f64,
    /// Element name.
    pub element: String,
    /// Vertices and body nodes.
    pub vertices: usize,
    /// Body nodes (P2: vertices and edge nodes).
    pub nodes: usize,
    /// Free dofs and entries of the factor.
    pub free_dofs: usize,
    /// Entries of the Cholesky factor.
    pub nnz_l: usize,
    /// Seconds to assemble and factorise, and for the sites' `W`.
    pub seconds: f64,
    /// `W` per site, m/N.
    pub w: Vec<Block3>,
}

/// The study's result: sites, levels, and the extrapolated reference.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct Study {
    /// The scene file the study ran on.
    pub scene: String,
    /// The tool radius, m.
    pub tip_radius_m: f64,
    /// The sites.
    pub sites: Vec<Site>,
    /// The levels, coarse to fine.
    pub levels: Vec<Level>,
    /// Extrapolated `W` per site (from the last three levels), m/N.
    pub reference_w: Vec<Block3>,
    /// The extrapolation's order per site (one pooled order: the module notes).
    pub order: Vec<f64>,
    /// Estimated relative error of the reference's `n . W n` per site (the grid convergence
    /// index).
    pub reference_error: Vec<f64>,
}

/// The sites' contact points on the scene's collision surface (R's triangles).
pub fn sites(organ: &Organ, region: &Region, given: &[(String, [f64; 3])]) -> Result<Vec<Site>> {
    let triangles: Vec<[usize; 3]> = region
        .triangles
        .iter()
        .map(|t| t.map(|k| k as usize))
        .collect();
    given
        .iter()
        .map(|(name, q)| {
            let surface = (&organ.mesh.nodes[..], &organ.surface.triangles[..]);
            let p = closest_reachable(&region.positions, &triangles, surface, *q).with_context(
                || format!("site {name:?} at [{:.4}, {:.4}, {:.4}] m", q[0], q[1], q[2]),
            )?;
            Ok(Site {
                name: name.clone(),
                query: *q,
                point: p.point,
                normal: p.normal,
            })
        })
        .collect()
}

/// `W` at the sites on one FEM mesh of size `h_m` with `element`.
pub fn level(
    scene: &Scene,
    sites: &[Site],
    mesh: &Path,
    h_m: f64,
    element: FemElement,
) -> Result<Level> {
    let t0 = std::time::Instant::now();
    let spec = SampledContact {
        fem_mesh: mesh.to_path_buf(),
        element,
        level: 1,
        richardson: None,
    };
    let fem = SampledFem::new(scene, &spec)?;
    let points: Vec<[f64; 3]> = sites.iter().map(|s| s.point).collect();
    let (w, _, _) = fem.patch_compliance(&points, scene.tip_radius_m, None)?;
    let stats = fem.compliance.stats();
    Ok(Level {
        mesh: mesh.display().to_string(),
        h_m,
        element: element.name().to_string(),
        vertices: fem.vertices,
        nodes: fem.nodes,
        free_dofs: stats.free_dofs,
        nnz_l: stats.nnz_l,
        seconds: t0.elapsed().as_secs_f64(),
        w,
    })
}

/// Roache's safety factor of the grid convergence index for a three-grid study (module notes).
pub const GCI_SAFETY: f64 = 1.25;

/// Richardson extrapolation of the last three levels with one pooled order (module notes):
/// `(W_inf, order, relative error of n . W n)` per site.
pub fn extrapolate(sites: &[Site], levels: &[Level]) -> Result<(Vec<Block3>, Vec<f64>, Vec<f64>)> {
    let [.., a, b, c] = levels else {
        bail!("the extrapolation needs at least three levels");
    };
    let r = b.h_m / c.h_m;
    if r <= 1.0 || r.is_nan() || ((a.h_m / b.h_m) / r - 1.0).abs() > 0.05 {
        bail!(
            "the last three mesh sizes must shrink by one constant ratio (got {} / {} / {} m)",
            a.h_m,
            b.h_m,
            c.h_m
        );
    }
    let nwn = |l: &Level, s: usize| normal_compliance(&l.w[s], sites[s].normal);
    let (coarse, fine) = (0..sites.len()).fold((0.0, 0.0), |(x, y), s| {
        (x + nwn(b, s) - nwn(a, s), y + nwn(c, s) - nwn(b, s))
    });
    let ratio = coarse / fine;
    if !(ratio > 1.0 && ratio.is_finite()) {
        bail!(
            "the differences between the levels do not shrink (pooled ratio {ratio:.3} over {} \
             sites): the meshes are not in the asymptotic range",
            sites.len()
        );
    }
    let q = (ratio.ln() / r.ln()).clamp(1.0, 4.0);
    let f = 1.0 / (r.powf(q) - 1.0);
    let mut out = (Vec::new(), Vec::new(), Vec::new());
    for (s, site) in sites.iter().enumerate() {
        let w: Block3 = std::array::from_fn(|i| {
            std::array::from_fn(|j| c.w[s][i][j] + (c.w[s][i][j] - b.w[s][i][j]) * f)
        });
        let kinf = normal_compliance(&w, site.normal);
        out.0.push(w);
        out.1.push(q);
        out.2.push(GCI_SAFETY * ((kinf - nwn(c, s)) / kinf).abs());
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn level(h: f64, w: Vec<Block3>) -> Level {
        Level {
            mesh: format!("{h}"),
            h_m: h,
            element: "p2".into(),
            vertices: 0,
            nodes: 0,
            free_dofs: 0,
            nnz_l: 0,
            seconds: 0.0,
            w,
        }
    }

    /// Sites whose `n . W n` converge as `c_s + C_s h^2` with their own constants: one pooled
    /// order 2, the exact limits, and the grid convergence index by hand.
    #[test]
    fn extrapolation_pools_one_order_and_recovers_an_h2_limit() {
        let consts = [(0.05, 3.0), (0.06, -1.0), (0.04, 7.0)];
        let sites: Vec<Site> = consts
            .iter()
            .map(|&(c, _)| Site {
                name: format!("{c}"),
                query: [0.0; 3],
                point: [0.0; 3],
                normal: [0.0, 0.0, 1.0],
            })
            .collect();
        let at = |h: f64| {
            consts
                .iter()
                .map(|&(c, k)| {
                    let mut w = [[0.0; 3]; 3];
                    w[0][0] = 0.09;
                    w[1][1] = 0.09 + k * h * h;
                    w[2][2] = c + k * h * h;
                    w
                })
                .collect::<Vec<Block3>>()
        };
        let levels: Vec<Level> = [0.004, 0.0028, 0.00196]
            .iter()
            .map(|&h| level(h, at(h)))
            .collect();
        let (w, order, err) = extrapolate(&sites, &levels).unwrap();
        for (s, &(c, k)) in consts.iter().enumerate() {
            assert!((order[s] - 2.0).abs() < 1e-9, "{order:?}");
            assert!((w[s][2][2] - c).abs() < 1e-12, "{:?}", w[s]);
            assert!((w[s][1][1] - 0.09).abs() < 1e-12);
            let k3 = c + k * 0.00196 * 0.00196;
            assert!((err[s] - 1.25 * ((c - k3) / c).abs()).abs() < 1e-12);
        }
        // Levels that grow apart are refused, not extrapolated.
        let wrong: Vec<Level> = [(0.004, 0.001), (0.0028, 0.002), (0.00196, 0.004)]
            .iter()
            .map(|&(h, like)| level(h, at(like)))
            .collect();
        assert!(extrapolate(&sites, &wrong).is_err());
    }
}
