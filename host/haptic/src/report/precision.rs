//! f32 on the MCU against f64 on the host: the firmware's own contact solves
//! (`firmware::solve`, the code the tick runs) on a bank built by the host, against the host's
//! f64 solves of the same contact on the same compliance (the paper's `f_S = C_SS^-1 u*_S`,
//! eq. 7, by `fem::compliance::contact_forces`; the energy-minimal 3 x 3 solve by
//! `haptic::contact::weighted_tool_force`). A point or triangle contact only uses blocks the bank
//! always keeps (own blocks and triangle edges), so the truncation does not enter: the
//! reference is the untruncated compliance, as in `host/tests/loop_vs_host.rs`.
//!
//! Also the near-incompressible rows: per Poisson's ratio, the f32 error and the condition
//! numbers of `K_ff` (estimated, see [`k_ff_condition`]) and of `C_SS` (exact, dense
//! eigenvalues).

use super::{HardCase, Knob, Point, Series, Verdict};
use crate::bank::{BankSpec, Prepared};
use crate::contact::weighted_tool_force;
use anyhow::{Result, anyhow};
use bank_format::Bank;
use fem::compliance::{Block3, Compliance, contact_forces};
use fem::elasticity::{DofMap, Elasticity, Material};
use firmware::solve::{
    alpha_weights, solve_point, solve_triangle_alpha, solve_triangle_barycentric,
};

/// The press of every solve: 5 mm mostly down with a tangential part, m.
const PRESS: [f32; 3] = [0.0008, -0.0005, -0.005];
/// Barycentric coordinates tried on every triangle (centroid, interior, near a vertex).
const BARYS: [[f32; 3]; 3] = [[1.0 / 3.0; 3], [0.6, 0.3, 0.1], [0.05, 0.05, 0.9]];
/// The bound the tests hold the f32 solve to (`tests/tests/solve_vs_host.rs`).
pub const F32_BOUND: f64 = 1e-4;
/// Distance bins of the reachable-region plot.
const BINS: usize = 6;

/// Relative 2-norm error of f32 node forces against f64 ones.
pub fn relative(got: &[[f32; 3]], want: &[[f64; 3]]) -> f64 {
    let (mut num, mut den) = (0.0, 0.0);
    for (g, w) in got.iter().zip(want) {
        for c in 0..3 {
            num += (f64::from(g[c]) - w[c]).powi(2);
            den += w[c] * w[c];
        }
    }
    if got.len() != want.len() || den == 0.0 {
        return f64::INFINITY;
    }
    (num / den).sqrt()
}

/// The worst f32 errors of one triangle of `bank`: (point at each vertex, alpha form,
/// energy-minimal form), against f64 on `compliance` (`ids`: bank index -> mesh node).
pub fn triangle_errors(
    bank: &Bank,
    compliance: &Compliance,
    ids: &[usize],
    tri: [u16; 3],
) -> Result<[f64; 3]> {
    let nodes: Vec<usize> = tri.iter().map(|&k| ids[usize::from(k)]).collect();
    let c = compliance.blocks(&nodes, None)?;
    let d = PRESS.map(f64::from);
    let fw = |e: firmware::solve::SolveError| anyhow!("firmware solve on {tri:?}: {e:?}");
    let mut worst = [0.0f64; 3];
    for (a, &k) in tri.iter().enumerate() {
        let want = contact_forces(&[vec![c[a][a]]], &[d])?.forces;
        let got = solve_point(bank, k, PRESS).map_err(fw)?;
        worst[0] = worst[0].max(relative(got.forces(), &want));
    }
    for bary in BARYS {
        let alpha = alpha_weights(bary);
        let imposed: Vec<[f64; 3]> = alpha.iter().map(|&w| d.map(|x| f64::from(w) * x)).collect();
        let want = contact_forces(&c, &imposed)?.forces;
        let got = solve_triangle_alpha(bank, tri, bary, PRESS).map_err(fw)?;
        worst[1] = worst[1].max(relative(got.forces(), &want));
        let w: Vec<f64> = bary.iter().map(|&b| f64::from(b)).collect();
        let ft = weighted_tool_force(&c, &w, d)?;
        let want: Vec<[f64; 3]> = w.iter().map(|&b| ft.map(|f| b * f)).collect();
        let got = solve_triangle_barycentric(bank, tri, bary, PRESS).map_err(fw)?;
        worst[2] = worst[2].max(relative(got.forces(), &want));
    }
    Ok(worst)
}

/// Worst errors over (a sample of) the bank's triangles: `(distance of the triangle's first
/// vertex from the region's centroid, errors)`.
pub fn region_errors(p: &Prepared, bank: &Bank, quick: bool) -> Result<Vec<(f64, [f64; 3])>> {
    let ids: Vec<usize> = bank.mesh_ids().iter().map(|&i| i as usize).collect();
    let positions = bank.positions();
    let n = positions.len().max(1) as f64;
    let centre: [f64; 3] =
        std::array::from_fn(|c| positions.iter().map(|q| f64::from(q[c])).sum::<f64>() / n);
    let tris = bank.triangles();
    let step = if quick { (tris.len() / 60).max(1) } else { 1 };
    let mut out = Vec::new();
    for &tri in tris.iter().step_by(step) {
        let q = positions[usize::from(tri[0])];
        let r = (0..3)
            .map(|c| (f64::from(q[c]) - centre[c]).powi(2))
            .sum::<f64>()
            .sqrt();
        out.push((r, triangle_errors(bank, &p.compliance, &ids, tri)?));
    }
    Ok(out)
}

/// The knob: worst f32 error per distance bin from the reachable region's centre, per form.
pub fn section(errors: &[(f64, [f64; 3])], truncation_m: f64) -> Knob {
    let r_max = errors.iter().map(|e| e.0).fold(0.0, f64::max).max(1e-9);
    let names = [
        "point contact",
        "triangle, alpha weights (paper)",
        "triangle, energy-minimal",
    ];
    let series = names
        .iter()
        .enumerate()
        .map(|(form, name)| Series {
            name: (*name).into(),
            points: (0..BINS)
                .filter_map(|b| {
                    let (lo, hi) = (
                        r_max * b as f64 / BINS as f64,
                        r_max * (b + 1) as f64 / BINS as f64,
                    );
                    let worst = errors
                        .iter()
                        .filter(|e| e.0 >= lo && (e.0 < hi || b + 1 == BINS))
                        .map(|e| e.1[form])
                        .fold(None, |m: Option<f64>, v| Some(m.map_or(v, |m| m.max(v))))?;
                    Some(Point {
                        x: 0.5 * (lo + hi) * 1e3,
                        y: worst.max(1e-12),
                        label: format!("{:.0}-{:.0} mm", lo * 1e3, hi * 1e3),
                    })
                })
                .collect(),
        })
        .collect();
    let worst = errors.iter().flat_map(|e| e.1).fold(0.0, f64::max);
    Knob {
        id: "f32-vs-f64".into(),
        title: "f32 on the MCU against f64 on the host, across the reachable region".into(),
        x_label: "distance of the contact from the reachable region's centre, mm".into(),
        y_label: "worst relative force error".into(),
        log_x: false,
        log_y: true,
        series,
        chosen: None,
        finding: format!(
            "the firmware's solves on the scene's bank (f32 storage and arithmetic) against \
             f64 on the untruncated compliance, {} triangles: worst {worst:.1e} ({} the \
             tests' {F32_BOUND:.0e}); point and triangle contacts use only blocks the bank \
             always keeps, so the truncation radius ({:.0} mm) does not enter",
            errors.len(),
            if worst <= F32_BOUND {
                "within"
            } else {
                "WORSE than"
            },
            truncation_m * 1e3
        ),
    }
}

/// Estimated 2-norm condition number of `K_ff`: `lambda_max` by power iteration on
/// `Elasticity::apply` restricted to the free dofs, `lambda_min` by inverse iteration with the
/// factorisation (`Compliance::displacement`), each the Rayleigh quotient after `iterations`
/// steps from a fixed start. Both quotients lie inside the spectrum, so the estimate is a
/// lower bound of the true condition number.
pub fn k_ff_condition(body: &Elasticity, compliance: &Compliance, iterations: usize) -> f64 {
    let dofs: &DofMap = compliance.dofs();
    let n = dofs.nodes();
    let free = |u: &mut Vec<f64>| {
        for node in 0..n {
            for c in 0..3 {
                if dofs.free_dof(node, c).is_none() {
                    u[3 * node + c] = 0.0;
                }
            }
        }
    };
    let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
    let start = || {
        let mut u: Vec<f64> = (0..3 * n)
            .map(|i| 1.0 + 0.37 * ((i as f64) * 0.731).sin())
            .collect();
        free(&mut u);
        u
    };
    let iterate = |op: &dyn Fn(&[f64]) -> Vec<f64>| {
        let mut u = start();
        let mut quotient = 0.0;
        for _ in 0..iterations {
            let norm = dot(&u, &u).sqrt();
            u.iter_mut().for_each(|x| *x /= norm);
            let mut v = op(&u);
            free(&mut v);
            quotient = dot(&u, &v);
            u = v;
        }
        quotient
    };
    let lambda_max = iterate(&|u| body.apply(u));
    let compliance_max = iterate(&|u| compliance.displacement(u));
    lambda_max * compliance_max
}

/// Exact 2-norm condition number of the SPD matrix of 3 x 3 blocks `c` (dense eigenvalues).
pub fn blocks_condition(c: &[Vec<Block3>]) -> Result<f64> {
    let m = 3 * c.len();
    let a = faer::Mat::<f64>::from_fn(m, m, |i, j| c[i / 3][j / 3][i % 3][j % 3]);
    let eig = a
        .self_adjoint_eigenvalues(faer::Side::Lower)
        .map_err(|e| anyhow!("eigenvalues of C_SS: {e:?}"))?;
    let (lo, hi) = eig.iter().fold((f64::INFINITY, 0.0f64), |(a, b), &v| {
        (a.min(v), b.max(v.abs()))
    });
    Ok(if lo > 0.0 { hi / lo } else { f64::INFINITY })
}

/// Per Poisson's ratio on the scene's mesh and supports: the f32 error over a sample of the
/// bank's triangles, `cond(K_ff)` and the worst `cond(C_SS)` of those triangles.
pub struct NuRow {
    /// Poisson's ratio.
    pub nu: f64,
    /// Worst f32 relative error (point, alpha, energy-minimal).
    pub f32_error: f64,
    /// Estimated condition number of `K_ff`.
    pub cond_k: f64,
    /// Worst exact condition number of a triangle's `C_SS`.
    pub cond_css: f64,
}

/// [`NuRow`]s for `nus`, rebuilding the scene's bank with each ratio.
pub fn nu_rows(p: &Prepared, nus: &[f64], step: &dyn Fn(&str)) -> Result<Vec<NuRow>> {
    let mut rows = Vec::new();
    for &nu in nus {
        step(&format!("f32 error and condition numbers at nu = {nu}"));
        let mut scene = p.organ.scene.clone();
        scene.material = Material::new(scene.material.young, nu)?;
        let q = Prepared::from_scene(scene)?;
        let radius = q.organ.scene.bank.truncation_radius_m;
        let built = q.bank(&BankSpec::Nodal {
            rows: &q.blocks(radius, None)?,
            radius,
            extra: None,
            precision: q.organ.scene.bank.precision,
        })?;
        let bytes = bank_format::AlignedBytes::new(&built.bytes);
        let bank = Bank::parse(&bytes).map_err(|e| anyhow!("bank at nu = {nu}: {e}"))?;
        let ids: Vec<usize> = bank.mesh_ids().iter().map(|&i| i as usize).collect();
        let tris = bank.triangles();
        let (mut f32_error, mut cond_css) = (0.0f64, 0.0f64);
        for &tri in tris.iter().step_by((tris.len() / 12).max(1)) {
            f32_error = f32_error.max(
                triangle_errors(&bank, &q.compliance, &ids, tri)?
                    .into_iter()
                    .fold(0.0, f64::max),
            );
            let nodes: Vec<usize> = tri.iter().map(|&k| ids[usize::from(k)]).collect();
            cond_css = cond_css.max(blocks_condition(&q.compliance.blocks(&nodes, None)?)?);
        }
        let cond_k = k_ff_condition(&q.organ.body, &q.compliance, 60);
        rows.push(NuRow {
            nu,
            f32_error,
            cond_k,
            cond_css,
        });
    }
    Ok(rows)
}

/// The hard-case rows of [`nu_rows`].
pub fn nu_cases(rows: &[NuRow]) -> Vec<HardCase> {
    let mut out = Vec::new();
    for r in rows {
        out.push(HardCase {
            case: format!("nu = {}: f32 force error", r.nu),
            measurement: format!(
                "worst relative error of the firmware's point, alpha and energy-minimal solves \
                 on the scene's bank rebuilt at this nu: {:.1e}",
                r.f32_error
            ),
            reference: format!("f64 solve on the same compliance; bound {F32_BOUND:.0e}"),
            verdict: if r.f32_error <= F32_BOUND {
                Verdict::MatchesReference
            } else {
                Verdict::Weakness
            },
            value: Some(r.f32_error),
            reference_value: Some(F32_BOUND),
        });
        out.push(HardCase {
            case: format!("nu = {}: condition number of K_ff", r.nu),
            measurement: format!(
                "cond(K_ff) >= {:.2e}: power iteration on K u for lambda_max, inverse \
                 iteration with the Cholesky factor for lambda_min, 60 steps each (both \
                 Rayleigh quotients lie in the spectrum: a lower bound)",
                r.cond_k
            ),
            reference: "finite; the f64 factorisation loses about log10(cond) of its 16 digits"
                .into(),
            verdict: if r.cond_k.is_finite() && r.cond_k < 1e12 {
                Verdict::Bounded
            } else {
                Verdict::Weakness
            },
            value: Some(r.cond_k),
            reference_value: None,
        });
        out.push(HardCase {
            case: format!("nu = {}: condition number of C_SS", r.nu),
            measurement: format!(
                "worst cond(C_SS) of a sampled contact triangle (9 x 9, dense eigenvalues, \
                 exact): {:.1}",
                r.cond_css
            ),
            reference: "f32 has 24 bits: cond(C_SS) x 6e-8 bounds the solve's relative error; \
                        bounded if below 1e3"
                .into(),
            verdict: if r.cond_css.is_finite() && r.cond_css < 1e3 {
                Verdict::Bounded
            } else {
                Verdict::Weakness
            },
            value: Some(r.cond_css),
            reference_value: None,
        });
    }
    out
}
