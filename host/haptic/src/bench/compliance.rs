//! `host bench compliance`: assembly, factorisation and column-solve times and peak memory of
//! the compliance precompute on one organ mesh resting on a bed, for the contact candidates a
//! scene's reachable region would hold.

use anyhow::Result;
use fem::compliance::Compliance;
use fem::elasticity::{DofMap, Elasticity, Element, FixedSet, Material};
use fem::ordering::{Ordering, permutation};
use std::path::Path;
use std::time::Instant;

/// What [`run`] computes on a mesh.
#[derive(Clone, Copy, Debug)]
pub struct Config {
    /// The organ's material.
    pub material: Material,
    /// Nodes less than this height (m) above the organ's lowest point are fixed (the bed).
    pub bed_m: f64,
    /// At most this many contact-candidate nodes: the free surface nodes nearest the top
    /// centre, a stand-in for a scene's reachable region.
    pub max_nodes: usize,
    /// Keep only the blocks of node pairs at most this far apart (m), as a bank's truncated
    /// couplings do; `None`: every pair.
    pub radius_m: Option<f64>,
    /// Fill-reducing ordering.
    pub ordering: Ordering,
    /// Element formulation.
    pub element: Element,
}

/// The figures of one mesh.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Figures {
    /// The mesh's file name.
    pub mesh: String,
    /// The element's name.
    pub element: String,
    /// Mesh nodes.
    pub nodes: usize,
    /// Mesh tetrahedra.
    pub tets: usize,
    /// Free degrees of freedom.
    pub free_dofs: usize,
    /// Contact-candidate nodes whose columns were solved.
    pub columns: usize,
    /// Node pairs whose 3x3 blocks were kept.
    pub pairs: usize,
    /// Time to read the mesh and find its surface, s.
    pub load_s: f64,
    /// Time to assemble the stiffness matrix, s.
    pub assemble_s: f64,
    /// Time to order and factorise it, s.
    pub factor_s: f64,
    /// Time to solve the candidates' columns, s.
    pub columns_s: f64,
    /// Non-zeros of the stiffness matrix.
    pub nnz_k: usize,
    /// Non-zeros of its Cholesky factor.
    pub nnz_l: usize,
    /// Peak resident memory over the whole run, MiB.
    pub peak_rss_mib: f64,
    /// Peak resident memory up to the end of the factorisation, MiB.
    pub factor_peak_rss_mib: f64,
}

/// Measures the compliance precompute of `config` on the mesh at `path`, reporting the column
/// solves (supernodes) to `progress`.
pub fn run(
    path: &Path,
    config: &Config,
    progress: &dyn fem::progress::Progress,
) -> Result<Figures> {
    let t = Instant::now();
    let mesh = fem::mesh::load(path)?;
    let surface = fem::mesh::boundary(&mesh)?;
    let load_s = t.elapsed().as_secs_f64();

    let (lo, hi) = mesh.bounding_box();
    let mut fixed = FixedSet::none(mesh.nodes.len());
    let top = lo[2] + config.bed_m;
    fixed.fix_box(&mesh, [lo[0], lo[1], lo[2], hi[0], hi[1], top], [true; 3])?;

    let centre = [0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), hi[2]];
    let mut candidates: Vec<usize> = surface
        .nodes
        .iter()
        .copied()
        .filter(|&i| (0..3).all(|c| !fixed.is_fixed(i, c)))
        .collect();
    let dist = |i: usize| {
        (0..3)
            .map(|a| (mesh.nodes[i][a] - centre[a]).powi(2))
            .sum::<f64>()
    };
    candidates.sort_by(|&a, &b| dist(a).total_cmp(&dist(b)));
    candidates.truncate(config.max_nodes);

    crate::rss::reset_peak();
    let t = Instant::now();
    let body = Elasticity::with_element(&mesh, config.material, config.element)?;
    body.check_rigid_motions(&fixed)?;
    let dofs = DofMap::new(&fixed);
    let k = body.stiffness(&dofs);
    let assemble_s = t.elapsed().as_secs_f64();

    let t = Instant::now();
    let perm = permutation(config.ordering, &body, &dofs).map_err(anyhow::Error::msg)?;
    let c = Compliance::factorize_matrix(dofs, &k, perm.as_ref())?;
    drop((k, perm));
    let factor_s = t.elapsed().as_secs_f64();
    let factor_peak_rss_mib = crate::rss::peak_mib();

    let t = Instant::now();
    let pairs = match config.radius_m {
        None => c.blocks(&candidates, Some(progress))?.len().pow(2),
        Some(radius) => {
            let positions: Vec<[f64; 3]> = candidates.iter().map(|&k| mesh.nodes[k]).collect();
            c.blocks_within(&candidates, &positions, radius, Some(progress))?
                .iter()
                .map(Vec::len)
                .sum()
        }
    };
    let columns_s = t.elapsed().as_secs_f64();
    let stats = c.stats();
    Ok(Figures {
        mesh: path.file_name().map_or_else(
            || path.display().to_string(),
            |n| n.to_string_lossy().into(),
        ),
        element: config.element.name().into(),
        nodes: mesh.nodes.len(),
        tets: mesh.tets.len(),
        free_dofs: stats.free_dofs,
        columns: candidates.len(),
        pairs,
        load_s,
        assemble_s,
        factor_s,
        columns_s,
        nnz_k: stats.nnz_k,
        nnz_l: stats.nnz_l,
        peak_rss_mib: crate::rss::peak_mib(),
        factor_peak_rss_mib,
    })
}
