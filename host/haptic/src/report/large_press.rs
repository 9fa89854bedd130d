//! Large presses (8, 12, 15 mm) and pulls (10, 20, 30 mm) at the study's sites: the linear
//! model's force error against the large-deformation reference, without the tissue law Q and
//! with it.
//!
//! **The reference** ([`crate::large`]): the default liver as a compressible neo-Hookean body
//! (E 3 kPa, nu 0.45 as its small-strain limit) on its 4 mm graded FEM mesh, the tool a rigid
//! disc of the 3 mm tip radius bonded to the surface at the site and moved along the site's
//! normal, the force the sum of the disc's reactions. It takes minutes per site on a 2-core
//! machine, so it is computed offline (`host/haptic/tests/large_press.rs`, ignored) and
//! committed (`host/tests/data/large-press.json`), like the converged contact study; the
//! section applies it to the default scene only. The linear model is the same mesh,
//! supports and disc in linear elasticity, so `|F_lin - F_large| / |F_large|` is the error of
//! linearity alone; the bank's own force differs from `F_lin` by its tool model and its mesh
//! (the study's converged force), which this ratio leaves out (docs/large-deformation.md
//! measures how the ratio changes with the mesh).
//!
//! **Q** is applied to the linear force's magnitude along its direction,
//! `F_Q = Q(|F_lin|) F_lin / |F_lin|`, as the firmware applies it. Two laws: the scene's own,
//! and one from a material characterisation that never sees the organ: the project's fitter
//! ([`crate::calibrate::fit::fit_law`], `host calibrate tissue`'s) fitted to the reference's
//! force against the linear force of a compression specimen of the same material
//! ([`specimen_law`]: the 20 mm cylinder between frictionless platens compressed to 40 %, as a
//! bench test would be). Q has no tension branch, so the pulls are reported without Q.
//!
//! The specimen's law is cached ([`crate::cache`], kind `large-press-q`): the key hashes the
//! scene's material, the specimen mesh's bytes, the strains and the source of this section and
//! of the solver.

use super::{HardCase, Knob, Point, Series, Verdict};
use crate::cache::{FNV_OFFSET, Store, fnv1a};
use crate::calibrate::{fit, specimen};
use crate::large::Press;
use crate::scene::Scene;
use anyhow::{Context, Result};
use fem::hyperelastic::{HyperelasticBody, NewtonOptions, Prescribed, solve_path};
use fem::mesh::TetMesh;
use serde::{Deserialize, Serialize};
use std::path::Path;
use std::time::Instant;

/// Press depths, m (along the inward normal).
pub const PRESSES_M: [f64; 3] = [0.008, 0.012, 0.015];
/// Pull heights, m (along the outward normal).
pub const PULLS_M: [f64; 3] = [0.010, 0.020, 0.030];
/// A force error above this is a weakness of the linear model (the grasping work corrects
/// pulls beyond it).
pub const WEAKNESS: f64 = 0.10;
/// The specimen's compression strains fitted by [`specimen_law`] (up to 40 %: its linear
/// forces, 0.38 N on the 20 mm cylinder of 3 kPa, cover the organ presses' 0.17-0.36 N).
pub const SPECIMEN_STRAINS: [f64; 8] = [0.05, 0.1, 0.15, 0.2, 0.25, 0.3, 0.35, 0.4];

const STORE: Store = Store {
    kind: "large-press-q",
    kept: 4,
};
/// The code the cached result depends on.
const CODE: [&str; 3] = [
    include_str!("large_press.rs"),
    include_str!("../../../fem/src/hyperelastic/newton.rs"),
    include_str!("../../../fem/src/hyperelastic/body.rs"),
];

/// A site's presses and pulls, or why the reference failed there.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SiteRun {
    /// The site's name.
    pub site: String,
    /// The presses at [`PRESSES_M`], or the solver's error.
    pub presses: Result<Vec<Press>, String>,
    /// The pulls at [`PULLS_M`], or the solver's error.
    pub pulls: Result<Vec<Press>, String>,
}

/// The specimen's curve and the law fitted to it.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SpecimenLaw {
    /// The specimen mesh.
    pub mesh: String,
    /// Linear force at each strain of [`SPECIMEN_STRAINS`], N.
    pub linear_n: Vec<f64>,
    /// The reference's force at each strain, N.
    pub large_n: Vec<f64>,
    /// The fitted Chebyshev coefficients, N.
    pub coeffs: Vec<f64>,
    /// Their domain, N.
    pub domain: [f64; 2],
    /// RMS fit error, of full scale.
    pub rms: f64,
}

/// Everything the section measured.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Measured {
    /// The FEM mesh of the reference.
    pub mesh: String,
    /// Per site.
    pub sites: Vec<SiteRun>,
    /// Q from the specimen, or why not.
    pub specimen: Result<SpecimenLaw, String>,
    /// Seconds the section's measurement took (the specimen's law, unless cached).
    pub cold_s: f64,
}

/// The committed reference runs (the module notes).
const DATA: &str = include_str!("../../../tests/data/large-press.json");
/// The mesh the committed runs were computed on.
pub const REFERENCE_MESH: &str = "host/meshes/liver-reach-4mm.msh";

/// The committed reference runs.
pub fn reference_runs() -> Result<Vec<SiteRun>> {
    serde_json::from_str(DATA).context("the committed large-press data does not parse")
}

/// The specimen law's cache key (module notes).
fn key(scene: &Scene, specimen_mesh: &Path) -> Result<u64> {
    let mut h = fnv1a(FNV_OFFSET, CODE.concat().as_bytes());
    let inputs = format!("{:?} {SPECIMEN_STRAINS:?}", scene.material);
    h = fnv1a(h, inputs.as_bytes());
    let bytes = std::fs::read(specimen_mesh)
        .with_context(|| format!("reading {}", specimen_mesh.display()))?;
    Ok(fnv1a(h, &bytes))
}

/// The committed runs and the specimen's law (computed, or from the cache).
pub fn measure(scene: &Scene, specimen_mesh: &Path, step: &dyn Fn(&str)) -> Result<Measured> {
    let sites = reference_runs()?;
    let key = key(scene, specimen_mesh)?;
    let t0 = Instant::now();
    let specimen = match STORE.load(key, |b| serde_json::from_slice::<SpecimenLaw>(&b)) {
        Some(l) => {
            step("large presses and pulls: the specimen's Q from the cache");
            Ok(l)
        }
        None => {
            step("large presses and pulls: the specimen's Q (its large-deformation compression)");
            let law = fem::mesh::load(specimen_mesh)
                .map_err(anyhow::Error::from)
                .and_then(|m| specimen_law(&m, scene))
                .map(|mut l| {
                    l.mesh = specimen_mesh.display().to_string();
                    l
                });
            if let Ok(l) = &law {
                STORE.save(key, &serde_json::to_vec(l)?);
            }
            law.map_err(|e| format!("{e:#}"))
        }
    };
    Ok(Measured {
        mesh: REFERENCE_MESH.into(),
        sites,
        specimen,
        cold_s: t0.elapsed().as_secs_f64(),
    })
}

/// The law Q of a compression specimen (a cylinder along z, `host calibrate tissue`'s
/// specimen) of the scene's material compressed to [`SPECIMEN_STRAINS`] between frictionless
/// platens, fitted by [`fit::fit_law`] with its automatic degree: x is the linear force
/// ([`specimen::compress`] on the mesh), y the reference's. Between frictionless platens the
/// field is homogeneous and the 10-node element represents it exactly, so the reference's
/// force over the linear force does not depend on the cross-section: it is computed on one
/// cubic cell of the specimen's height with rollers on three faces (a second; the cylinder's
/// own 10-node mesh, 3 minutes, gave the same ratios to 1e-6) and applied to the cylinder's
/// linear force. The test `the_specimen_curve_is_the_closed_form` checks it against the
/// closed form.
pub fn specimen_law(mesh: &TetMesh, scene: &Scene) -> Result<SpecimenLaw> {
    let linear = specimen::compress(mesh, scene.material)?;
    let h = linear.height_m;
    let block = fem::mesh::structured::box_mesh([h; 3], [1, 1, 1]);
    let body = HyperelasticBody::new(&block, scene.material)?;
    let tol = 1e-9 * h;
    let deepest = SPECIMEN_STRAINS[SPECIMEN_STRAINS.len() - 1] * h;
    let mut p = Prescribed::none(body.nodes());
    p.set_where(body.positions(), |x| x[0] <= tol, [Some(0.0), None, None])?;
    p.set_where(body.positions(), |x| x[1] <= tol, [None, Some(0.0), None])?;
    p.set_where(body.positions(), |x| x[2] <= tol, [None, None, Some(0.0)])?;
    p.set_where(
        body.positions(),
        |x| x[2] >= h - tol,
        [None, None, Some(-deepest)],
    )?;
    let top: Vec<usize> = (0..body.nodes())
        .filter(|&n| body.positions()[n][2] >= h - tol)
        .collect();
    let stops: Vec<f64> = SPECIMEN_STRAINS
        .iter()
        .map(|s| s / SPECIMEN_STRAINS[SPECIMEN_STRAINS.len() - 1])
        .collect();
    let path = solve_path(&body, &p, &stops, &NewtonOptions::default(), &mut |_| {})
        .context("the specimen's large-deformation compression")?;
    let linear_n: Vec<f64> = SPECIMEN_STRAINS
        .iter()
        .map(|s| s * h * linear.force_per_m)
        .collect();
    let large_n: Vec<f64> = path
        .iter()
        .zip(SPECIMEN_STRAINS.iter().zip(&linear_n))
        .map(|(sol, (e, lin))| {
            let block_linear = scene.material.young * h * h * e;
            lin * -sol.reaction(top.iter().copied(), 2) / block_linear
        })
        .collect();
    let (f, _, _) = fit::fit_law(&linear_n, &large_n, None, fit::DEFAULT_TARGET_RMS)?;
    let rms = f.errors(&linear_n, &large_n).rms_rel;
    Ok(SpecimenLaw {
        mesh: String::new(),
        linear_n,
        large_n,
        coeffs: f.coeffs.clone(),
        domain: f.domain,
        rms,
    })
}

/// `|a - b| / |b|`.
fn rel(a: [f64; 3], b: [f64; 3]) -> f64 {
    let n = |v: [f64; 3]| v.iter().map(|x| x * x).sum::<f64>().sqrt();
    n(std::array::from_fn(|i| a[i] - b[i])) / n(b)
}

/// The linear force through a law: `Q(|F|) F / |F|`.
fn through(law: &bank_format::TissueLaw, f: [f64; 3]) -> [f64; 3] {
    let n = f.iter().map(|x| x * x).sum::<f64>().sqrt();
    let q = f64::from(law.eval(n as f32));
    f.map(|x| x * q / n)
}

/// One variant's errors: per depth, `(depth in mm, signed: pulls < 0)` and per site the error.
struct Variant {
    name: String,
    points: Vec<(f64, Vec<(String, f64)>)>,
}

/// The knob (worst error over the sites against depth, one series per variant), the hard
/// cases (per variant and depth: the worst site, a weakness over [`WEAKNESS`]) and the
/// sentences for what was not measured.
pub fn section(m: &Measured, scene: &Scene) -> (Knob, Vec<HardCase>, Vec<String>) {
    let mut not_measured = Vec::new();
    let mut laws: Vec<(String, Option<bank_format::TissueLaw>)> = vec![("linear".into(), None)];
    match &m.specimen {
        Ok(s) => {
            let coeffs: Vec<f32> = s.coeffs.iter().map(|&c| c as f32).collect();
            match bank_format::TissueLaw::chebyshev(&coeffs, s.domain.map(|x| x as f32)) {
                Ok(l) => laws.push(("Q from the specimen".into(), Some(l))),
                Err(e) => not_measured.push(format!("the specimen's Q: {e:?}")),
            }
        }
        Err(e) => not_measured.push(format!("the specimen's Q: {e}")),
    }
    laws.push(("the scene's Q".into(), Some(scene.law)));
    let mut variants = Vec::new();
    for (name, law) in &laws {
        let mut points = Vec::new();
        for (k, &d) in PRESSES_M.iter().enumerate() {
            let per_site = m
                .sites
                .iter()
                .filter_map(|r| r.presses.as_ref().ok().map(|p| (r.site.clone(), &p[k])))
                .map(|(site, p)| {
                    let f = law.as_ref().map_or(p.linear, |l| through(l, p.linear));
                    (site, rel(f, p.large))
                })
                .collect();
            points.push((1e3 * d, per_site));
        }
        variants.push(Variant {
            name: format!("press, {name}"),
            points,
        });
    }
    let mut points = Vec::new();
    for (k, &d) in PULLS_M.iter().enumerate() {
        let per_site = m
            .sites
            .iter()
            .filter_map(|r| {
                r.pulls
                    .as_ref()
                    .ok()
                    .map(|p| (r.site.clone(), p[k].linear_error()))
            })
            .collect();
        points.push((-1e3 * d, per_site));
    }
    variants.push(Variant {
        name: "pull, linear (Q has no tension branch)".into(),
        points,
    });
    let reference = format!(
        "neo-Hookean, bonded 3 mm tool, {}, same mesh and tool",
        short(&m.mesh)
    );
    let mut cases = Vec::new();
    let mut series = Vec::new();
    for v in &variants {
        let mut pts = Vec::new();
        for (depth, per_site) in &v.points {
            let Some((worst_site, worst)) =
                per_site.iter().max_by(|a, b| a.1.total_cmp(&b.1)).cloned()
            else {
                continue;
            };
            let mean = per_site.iter().map(|x| x.1).sum::<f64>() / per_site.len() as f64;
            let what = if *depth > 0.0 { "press" } else { "pull" };
            pts.push(Point {
                x: *depth,
                y: 100.0 * worst,
                label: format!("{what} {:.0} mm", depth.abs()),
            });
            cases.push(HardCase {
                case: format!("{} {:.0} mm, {} sites", v.name, depth.abs(), per_site.len()),
                measurement: format!(
                    "force error {:.1} % at worst ({worst_site}), {:.1} % on average",
                    100.0 * worst,
                    100.0 * mean
                ),
                reference: reference.clone(),
                verdict: if worst > WEAKNESS {
                    Verdict::Weakness
                } else {
                    Verdict::Bounded
                },
                value: Some(worst),
                reference_value: None,
            });
        }
        series.push(Series {
            name: v.name.clone(),
            points: pts,
        });
    }
    for r in &m.sites {
        for (what, res) in [("presses", &r.presses), ("pulls", &r.pulls)] {
            if let Err(e) = res {
                cases.push(HardCase {
                    case: format!("{what} at {}", r.site),
                    measurement: format!("the reference failed: {e}"),
                    reference: reference.clone(),
                    verdict: Verdict::Refused,
                    value: None,
                    reference_value: None,
                });
            }
        }
    }
    let worst_of = |name: &str, sign: f64| {
        series
            .iter()
            .filter(|s| s.name == name)
            .flat_map(|s| s.points.iter().filter(|p| p.x * sign > 0.0))
            .map(|p| p.y)
            .fold(0.0f64, f64::max)
    };
    let finding = format!(
        "At {} sites (on {}, computed offline; the specimen's Q {:.1} s, cached): presses of 8-15 mm \
         are off by up to {:.0} % linear and {:.0} % with the specimen's Q; pulls of 10-30 mm \
         by up to {:.0} % (no Q in tension)",
        m.sites.len(),
        short(&m.mesh),
        m.cold_s,
        worst_of("press, linear", 1.0),
        worst_of("press, Q from the specimen", 1.0),
        worst_of("pull, linear (Q has no tension branch)", -1.0),
    );
    let knob = Knob {
        id: "large-press".into(),
        title: "Large presses and pulls: the linear model against the neo-Hookean reference".into(),
        x_label: "tool displacement along the inward normal, mm (pulls < 0)".into(),
        y_label: "force error, worst site, %".into(),
        log_x: false,
        log_y: false,
        series,
        chosen: None,
        finding,
    };
    (knob, cases, not_measured)
}

fn short(p: &str) -> String {
    Path::new(p)
        .file_stem()
        .map_or_else(|| p.to_string(), |s| s.to_string_lossy().into())
}

/// The section on `scene` (the committed reference is the default liver's: another
/// material or tool radius is reported as not measured): its knob, hard cases and what it
/// could not measure.
pub fn run(
    scene: &Scene,
    specimen_mesh: Option<&Path>,
    step: &dyn Fn(&str),
) -> Result<(Vec<Knob>, Vec<HardCase>, Vec<String>)> {
    let default = (
        scene.material.young,
        scene.material.poisson,
        scene.tip_radius_m,
    ) == (3000.0, 0.45, 0.003);
    let why = match specimen_mesh {
        _ if !default => {
            Some("the committed reference is the default liver's (E 3 kPa, nu 0.45, 3 mm tip)")
        }
        None => Some("the specimen mesh host/meshes/cylinder-2k.msh is missing"),
        Some(_) => None,
    };
    if let Some(why) = why {
        return Ok((
            Vec::new(),
            Vec::new(),
            vec![format!("large presses and pulls: {why}")],
        ));
    }
    let m = measure(scene, specimen_mesh.expect("checked above"), step)?;
    if m.sites.is_empty() {
        return Ok((
            Vec::new(),
            Vec::new(),
            vec!["large presses and pulls: host/tests/data/large-press.json holds no runs".into()],
        ));
    }
    let (knob, cases, not) = section(&m, scene);
    Ok((vec![knob], cases, not))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn press(depth_m: f64, large: f64, linear: f64) -> Press {
        Press {
            depth_m,
            large: [0.0, 0.0, large],
            linear: [0.0, 0.0, linear],
            iterations: 1,
        }
    }

    /// Hand-made runs: the errors are `|F_lin - F_large| / |F_large|` (1/11 and 2/10 by hand),
    /// the worst site is named, a law that doubles the force doubles `F_lin` first, and the
    /// verdict is a weakness over 10 % only.
    #[test]
    fn errors_and_verdicts_by_hand() {
        let scene = Scene::load_or_default(None).unwrap();
        let presses = |large: f64| -> Vec<Press> {
            PRESSES_M
                .iter()
                .map(|&d| press(d, -large * d, -d))
                .collect()
        };
        let pulls: Vec<Press> = PULLS_M.iter().map(|&d| press(-d, d, 1.25 * d)).collect();
        let m = Measured {
            mesh: REFERENCE_MESH.into(),
            sites: vec![
                SiteRun {
                    site: "a".into(),
                    presses: Ok(presses(1.1)),
                    pulls: Ok(pulls.clone()),
                },
                SiteRun {
                    site: "b".into(),
                    presses: Ok(presses(1.0)),
                    pulls: Err("no convergence".into()),
                },
            ],
            specimen: Ok(SpecimenLaw {
                mesh: String::new(),
                linear_n: Vec::new(),
                large_n: Vec::new(),
                coeffs: vec![1.0, 1.0],
                domain: [0.0, 1.0],
                rms: 0.0,
            }),
            cold_s: 0.0,
        };
        let (knob, cases, not) = section(&m, &scene);
        assert!(not.is_empty(), "{not:?}");
        let series = |name: &str| knob.series.iter().find(|s| s.name == name).unwrap();
        for p in &series("press, linear").points {
            assert!((p.y - 100.0 / 11.0).abs() < 1e-9, "{p:?}");
        }
        // The scene's Q is the identity: the same errors (to f32, the law's arithmetic).
        for p in &series("press, the scene's Q").points {
            assert!((p.y - 100.0 / 11.0).abs() < 1e-4, "{p:?}");
        }
        // Chebyshev [1, 1] on [0, 1]: Q(f) = 1 + (2 f - 1) = 2 f, so site a is off by
        // |2 - 1.1| / 1.1 and site b by 1, the worst (to f32).
        for p in &series("press, Q from the specimen").points {
            assert!((p.y - 100.0).abs() < 1e-3, "{p:?}");
        }
        let pull = &series("pull, linear (Q has no tension branch)").points;
        assert_eq!(pull.len(), 3);
        for p in pull {
            assert!((p.y - 25.0).abs() < 1e-9 && p.x < 0.0, "{p:?}");
        }
        let row = |c: &str| cases.iter().find(|h| h.case == c).unwrap();
        let r = row("press, linear 15 mm, 2 sites");
        assert_eq!(r.verdict, Verdict::Bounded);
        assert!(r.measurement.contains("(a)"), "{}", r.measurement);
        let r = row("pull, linear (Q has no tension branch) 30 mm, 1 sites");
        assert_eq!(r.verdict, Verdict::Weakness);
        assert_eq!(row("pulls at b").verdict, Verdict::Refused);
    }
}
