//! Bank size against force error (`host bank sweep`, and the report's plot): for each coupling
//! rule (a Euclidean truncation radius, or the tool's co-occurring pairs,
//! [`ToolPairs::sample`](super::ToolPairs::sample)) the bank's bytes and the firmware's force error (f32, its own
//! patch and solve on the bank's bytes) against the f64 solve on untruncated compliance, over
//! contact sites spread over the reachable surface R: a point contact (tip radius 0: the
//! barycentric weights on the contact triangle) and the scene's tool patch at each site.
//!
//! The reference weights of a tool patch are the firmware's own patch rule
//! ([`firmware::patch::tool_patch`]) on the probe bank, which couples every pair within
//! [`Prepared::probe_radius`] (every pair a patch can load: nothing is dropped for want of a
//! coupling); the reference force is the energy-minimal weighted solve
//! ([`crate::contact::weighted_tool_force`], f64) with those weights on the untruncated
//! compliance blocks `C_ab` of the patch's nodes. So the error is what the bank's truncation,
//! its f32 storage and the f32 solve cost, nothing else.

use super::{BankSpec, BlockRows, Prepared, ToolPairs, UNCOUPLED_TOL};
use crate::contact::weighted_tool_force;
use anyhow::{Context, Result, bail};
use bank_format::region::BANK_LEN;
use bank_format::{AlignedBytes, Bank, Precision};
use fem::progress::Progress;
use firmware::patch::tool_patch;
use firmware::solve::WeightedSolve;

/// One contact site on R: a triangle, the anchor's barycentric coordinates, the press.
#[derive(Debug, Clone, Copy)]
pub struct Site {
    /// Index into R's triangles.
    pub triangle: usize,
    /// Barycentric coordinates of the anchor (f32, as the firmware holds them).
    pub bary: [f32; 3],
    /// The anchor, from the bank's f32 positions, m.
    pub anchor: [f32; 3],
    /// Tool displacement, m: `depth` along the triangle's inward normal.
    pub press: [f32; 3],
}

/// The f64 references at one site.
#[derive(Debug, Clone)]
pub struct Reference {
    /// The site.
    pub site: Site,
    /// Point contact: the tool force (N, on the tissue) with the barycentric weights.
    pub point_n: [f64; 3],
    /// Tool patch: the reference weights (R indices) and the tool force, N.
    pub patch: Vec<(u16, f64)>,
    /// The patch's tool force, N.
    pub patch_n: [f64; 3],
}

/// Relative tool-force errors of the firmware on one bank over a set of sites.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct Errors {
    /// Point contact: largest and mean relative error.
    pub point_max: f64,
    /// Mean.
    pub point_mean: f64,
    /// Tool patch: largest relative error.
    pub patch_max: f64,
    /// Mean.
    pub patch_mean: f64,
    /// Largest share of a patch's load the firmware dropped on this bank.
    pub dropped_max: f64,
    /// Sites where the firmware's solve failed (counted, not in the statistics).
    pub failed: usize,
}

/// One row of the sweep.
#[derive(Debug, Clone, serde::Serialize)]
pub struct SweepRow {
    /// "radius" (pairs within `radius_m` and every triangle edge) or "tool" (the tool's
    /// co-occurring pairs, every triangle edge, and the pairs within `radius_m`).
    pub rule: &'static str,
    /// Truncation radius, m.
    pub radius_m: f64,
    /// Storage precision of the coupling blocks `C_kl`: "f32" or "bfp16" (16-bit mantissas,
    /// one exponent per block; `bank_format::Precision`).
    pub precision: &'static str,
    /// Coupled pairs stored.
    pub pairs: usize,
    /// Bank bytes.
    pub bank_bytes: usize,
    /// Whether it fits the device's bank region.
    pub fits_region: bool,
    /// Contact sites.
    pub sites: usize,
    /// The firmware's errors on this bank (flattened into the row's JSON).
    #[serde(flatten)]
    pub errors: Errors,
    /// The bank itself, as `host bank build` would write it (not in the JSON).
    #[serde(skip)]
    pub bank: Vec<u8>,
}

/// What to sweep.
#[derive(Debug, Clone)]
pub struct SweepConfig {
    /// Truncation radii of the "radius" rule, m.
    pub radii: Vec<f64>,
    /// Rows of the "tool" rule, one per radius whose pairs are added to the tool's (m; `[0.0]`
    /// for the tool's pairs alone, empty for none).
    pub tool_radii: Vec<f64>,
    /// Contact sites.
    pub sites: usize,
    /// Press depth, m.
    pub depth_m: f64,
    /// Seed of the sites' placement.
    pub seed: u64,
    /// Storage precisions of `C_kl`: every (rule, radius) is built in each.
    pub precisions: Vec<Precision>,
}

/// `count` sites: triangles of R chosen with probability proportional to their area, anchors
/// uniform in them, pressed `depth_m` along the inward normal (from `bank`'s f32 positions).
pub fn sites(bank: &Bank, count: usize, depth_m: f64, seed: u64) -> Vec<Site> {
    let p = bank.positions();
    let tris = bank.triangles();
    let geo: Vec<([f64; 3], f64)> = tris
        .iter()
        .map(|t| {
            let v = t.map(|k| p[usize::from(k)].map(f64::from));
            let e1 = fem::vec3::sub(v[1], v[0]);
            let e2 = fem::vec3::sub(v[2], v[0]);
            let n = fem::vec3::cross(e1, e2);
            let len = fem::vec3::norm(n);
            (n.map(|x| if len > 0.0 { x / len } else { 0.0 }), len / 2.0)
        })
        .collect();
    let total: f64 = geo.iter().map(|g| g.1).sum();
    let mut rng = crate::rng::SplitMix64::new(seed);
    let mut out = Vec::with_capacity(count);
    if total.is_nan() || total <= 0.0 {
        return out;
    }
    while out.len() < count {
        let mut x = rng.unit() * total;
        let t = geo
            .iter()
            .position(|g| {
                x -= g.1;
                x < 0.0
            })
            .unwrap_or(geo.len() - 1);
        let (mut u, mut v) = (rng.unit(), rng.unit());
        if u + v > 1.0 {
            (u, v) = (1.0 - u, 1.0 - v);
        }
        let bary = [1.0 - u - v, u, v].map(|b| b as f32);
        let vert = tris[t].map(|k| p[usize::from(k)]);
        let anchor = std::array::from_fn(|c| {
            bary[0] * vert[0][c] + bary[1] * vert[1][c] + bary[2] * vert[2][c]
        });
        let press = geo[t].0.map(|n| (-depth_m * n) as f32);
        out.push(Site {
            triangle: t,
            bary,
            anchor,
            press,
        });
    }
    out
}

/// The f64 references at `sites`: weights from the firmware's patch on `probe` (see the module
/// documentation), forces from the untruncated compliance.
pub fn references(prep: &Prepared, probe: &Bank, sites: &[Site]) -> Result<Vec<Reference>> {
    let radius = prep.organ.scene.tip_radius_m as f32;
    let mut out = Vec::with_capacity(sites.len());
    for s in sites {
        let tri = probe.triangles()[s.triangle];
        let press = s.press.map(f64::from);
        let c = blocks(prep, &tri)?;
        let w: Vec<f64> = s.bary.iter().map(|&b| f64::from(b)).collect();
        let point_n = weighted_tool_force(&c, &w, press)?;
        let patch = tool_patch(probe, s.triangle as u32, tri, s.bary, s.anchor, radius);
        if patch.dropped > UNCOUPLED_TOL && patch.nodes().len() < firmware::solve::MAX_CONTACT_NODES
        {
            bail!(
                "internal: the probe bank left a node of the patch at triangle {} uncoupled",
                s.triangle
            );
        }
        let nodes = patch.nodes();
        let weights: Vec<f64> = patch.weights().iter().map(|&w| f64::from(w)).collect();
        let c = blocks(prep, nodes)?;
        let patch_n = weighted_tool_force(&c, &weights, press)?;
        out.push(Reference {
            site: *s,
            point_n,
            patch: nodes.iter().copied().zip(weights).collect(),
            patch_n,
        });
    }
    Ok(out)
}

/// Untruncated blocks among R's nodes `nodes`.
fn blocks(prep: &Prepared, nodes: &[u16]) -> Result<Vec<Vec<fem::compliance::Block3>>> {
    let ids: Vec<usize> = nodes
        .iter()
        .map(|&k| prep.region.nodes[usize::from(k)])
        .collect();
    Ok(prep.compliance.blocks(&ids, None)?)
}

/// The firmware's errors on `bank` against `refs`.
pub fn errors(prep: &Prepared, bank: &Bank, refs: &[Reference]) -> Errors {
    let radius = prep.organ.scene.tip_radius_m as f32;
    let rel = |got: [f32; 3], want: [f64; 3]| {
        let d: [f64; 3] = std::array::from_fn(|c| f64::from(got[c]) - want[c]);
        fem::vec3::norm(d) / fem::vec3::norm(want)
    };
    let mut e = Errors::default();
    let (mut points, mut patches) = (0usize, 0usize);
    for r in refs {
        let s = r.site;
        let tri = bank.triangles()[s.triangle];
        let point = tool_patch(bank, s.triangle as u32, tri, s.bary, s.anchor, 0.0);
        match WeightedSolve::new(bank, point.nodes(), point.weights())
            .and_then(|w| w.forces(s.press))
        {
            Ok(f) => {
                let x = rel(f.tool_force_n, r.point_n);
                e.point_max = e.point_max.max(x);
                e.point_mean += x;
                points += 1;
            }
            Err(_) => e.failed += 1,
        }
        let patch = tool_patch(bank, s.triangle as u32, tri, s.bary, s.anchor, radius);
        e.dropped_max = e.dropped_max.max(f64::from(patch.dropped));
        match WeightedSolve::new(bank, patch.nodes(), patch.weights())
            .and_then(|w| w.forces(s.press))
        {
            Ok(f) => {
                let x = rel(f.tool_force_n, r.patch_n);
                e.patch_max = e.patch_max.max(x);
                e.patch_mean += x;
                patches += 1;
            }
            Err(_) => e.failed += 1,
        }
    }
    e.point_mean /= points.max(1) as f64;
    e.patch_mean /= patches.max(1) as f64;
    e
}

/// The probe bank's bytes (every pair within [`Prepared::probe_radius`]) from `rows`.
pub fn probe_bytes(prep: &Prepared, rows: &BlockRows) -> Result<AlignedBytes> {
    prep.probe_bank(rows)
}

/// The sweep: one row per radius (rule "radius") and one per `config.tool_radii` for the
/// tool's pairs plus those within that radius (rule "tool"). `progress` counts the compliance's supernodes, then the rows.
pub fn run(
    prep: &Prepared,
    config: &SweepConfig,
    progress: Option<&dyn Progress>,
) -> Result<Vec<SweepRow>> {
    if config.sites == 0 {
        bail!("at least one contact site is needed");
    }
    if let Some(r) = config
        .radii
        .iter()
        .chain(&config.tool_radii)
        .find(|r| !(r.is_finite() && **r >= 0.0))
    {
        bail!("every radius must be a number >= 0 m, got {r}");
    }
    if !(config.depth_m.is_finite() && config.depth_m > 0.0) {
        bail!("the press depth must be > 0 m, got {}", config.depth_m);
    }
    let rmax = config
        .radii
        .iter()
        .chain(&config.tool_radii)
        .copied()
        .fold(0.0, f64::max);
    let rows = prep.blocks(rmax.max(prep.probe_radius()), progress)?;
    let probe_bytes = probe_bytes(prep, &rows)?;
    let probe = Bank::parse_unbounded(&probe_bytes)
        .map_err(|e| anyhow::anyhow!("internal: the probe bank is invalid: {e}"))?;
    let sites = sites(&probe, config.sites, config.depth_m, config.seed);
    let refs = references(prep, &probe, &sites)?;
    if config.precisions.is_empty() {
        bail!("at least one storage precision is needed");
    }
    let mut rules: Vec<(&'static str, f64)> = config.radii.iter().map(|&r| ("radius", r)).collect();
    rules.extend(config.tool_radii.iter().map(|&r| ("tool", r)));
    let plan: Vec<(&'static str, f64, Precision)> = rules
        .iter()
        .flat_map(|&(rule, r)| config.precisions.iter().map(move |&p| (rule, r, p)))
        .collect();
    if let Some(p) = progress {
        p.start(plan.len() as u64);
    }
    let mut out = Vec::with_capacity(plan.len());
    let mut tool_pairs = None;
    for (rule, radius, precision) in plan {
        let built = if rule == "tool" {
            let pairs = match &tool_pairs {
                Some(p) => p,
                None => tool_pairs.insert(
                    ToolPairs::sample(
                        &probe,
                        prep.organ.scene.tip_radius_m,
                        super::TOOL_DIVISIONS,
                    )?
                    .pairs,
                ),
            };
            prep.bank(&BankSpec::Nodal {
                rows: &rows,
                radius,
                extra: Some(pairs),
                precision,
            })?
        } else {
            prep.bank(&BankSpec::Nodal {
                rows: &rows,
                radius,
                extra: None,
                precision,
            })?
        };
        let aligned = AlignedBytes::new(&built.bytes);
        let bank = Bank::parse(&aligned)
            .map_err(|e| anyhow::anyhow!("the swept bank ({rule}, {radius} m): {e}"))
            .context("internal")?;
        let errors = errors(prep, &bank, &refs);
        out.push(SweepRow {
            rule,
            radius_m: radius,
            precision: precision.name(),
            pairs: built.pairs,
            bank_bytes: built.bytes.len(),
            fits_region: built.bytes.len() <= BANK_LEN,
            sites: refs.len(),
            errors,
            bank: built.bytes,
        });
        if let Some(p) = progress {
            p.advance(1);
        }
    }
    Ok(out)
}
