//! The sampled contact's knobs: the FEM the patch compliance `W` is computed on
//! (mesh and element, with or without Richardson extrapolation) and the sample spacing (lattice
//! level) against the force the firmware renders, bank bytes, MCU instructions per tick and
//! precompute time; with the scene's nodal bank beside them, all on one error axis.
//!
//! **Error.** Against the converged reference committed with the tests
//! (`host/tests/data/patch-study-p2.json`: `W` at 14 sites of the default liver on P2 meshes
//! refined as a whole to 2 mm, extrapolated; its own error per site, a grid convergence index,
//! is stated there): at each site the
//! firmware tick's force for a normal press (`host contact probe`'s press, linear model) against
//! the reference's `W^-1 d`, mean and worst of the vector's relative error over sites and
//! depths. So the nodal bank and every sampled variant are measured against the same
//! continuum answer, not against their own mesh.
//!
//! **Cost.** One factor per FEM body serves every level (its `W` at the union of the levels'
//! lattice points); a variant's precompute time is its bodies' factor time plus their `W` time
//! for its points. Instructions are the worst loop body under QEMU over the press, slide and
//! strike scripts, measured on the chosen FEM's bank at each level (the tick's code path does
//! not depend on which FEM made `W`, only on the bank's sections).
//!
//! **Precision.** The samples are f32 only (bank format 6 has no bfp16 samples): not a knob.

use super::{HardCase, Knob, Point, Series, Verdict};
use crate::bank::sampled::{SampledFem, extrapolated, lattice_points, samples_from, spd};
use crate::bank::{BankSpec, Prepared, SampledParts};
use crate::organ::Organ;
use crate::scene::{ContactModel, FemElement, Scene};
use crate::study::Study;
use anyhow::{Context, Result, bail};
use bank_format::{AlignedBytes, Bank};
use fem::compliance::Block3;
use std::time::Instant;

/// The converged reference (module notes).
const REFERENCE: &str = include_str!("../../../tests/data/patch-study-p2.json");

/// One sampled bank.
#[derive(Debug, Clone)]
pub struct Variant {
    /// The FEM, e.g. `P2 liver-reach-2.8mm + Richardson (liver-reach-4mm)`.
    pub fem: String,
    /// Lattice level.
    pub level: u32,
    /// The bank.
    pub bank: Vec<u8>,
    /// Precompute seconds (module notes).
    pub precompute_s: f64,
    /// Mean and worst relative force error against the reference.
    pub error: (f64, f64),
    /// The scene's own choice.
    pub chosen: bool,
    /// Worst loop-body instructions under QEMU, when measured.
    pub instructions: Option<f64>,
}

/// The scene's nodal bank on the same axes.
#[derive(Debug, Clone)]
pub struct NodalPoint {
    /// What it is.
    pub name: String,
    /// Bank bytes.
    pub bytes: usize,
    /// Mean and worst relative force error against the reference.
    pub error: (f64, f64),
    /// Worst loop-body instructions under QEMU, when measured.
    pub instructions: Option<f64>,
}

/// The reference study.
pub fn reference() -> Result<Study> {
    serde_json::from_str(REFERENCE).context("the committed reference study does not parse")
}

fn short(p: &std::path::Path) -> String {
    p.file_stem()
        .map_or_else(|| p.display().to_string(), |s| s.to_string_lossy().into())
}

/// Builds the variants of the sampled `scene` (levels 1, 2 and 3; its FEM,
/// its Richardson partner alone, the extrapolation, and P1 on its FEM unless `quick`) and
/// measures their force error. Instructions are left for the caller ([`Variant::instructions`]).
pub fn measure(scene: &Scene, quick: bool, step: &dyn Fn(&str)) -> Result<Vec<Variant>> {
    let ContactModel::Sampled(spec) = &scene.contact else {
        bail!("the sampled knobs need a scene with [contact] model = \"sampled\"");
    };
    let study = reference()?;
    let prep = Prepared::from_scene(scene.clone())?;
    let r = prep.organ.scene.tip_radius_m;
    let levels: Vec<u32> = vec![1, 2, 3];
    let lattices: Vec<_> = levels
        .iter()
        .map(|&l| lattice_points(&prep.region.positions, &prep.region.triangles, l))
        .collect();
    let all: Vec<[f64; 3]> = lattices.iter().flat_map(|(_, p)| p.clone()).collect();
    let ranges: Vec<std::ops::Range<usize>> = lattices
        .iter()
        .scan(0, |at, (_, p)| {
            let r = *at..*at + p.len();
            *at += p.len();
            Some(r)
        })
        .collect();
    let mut bodies: Vec<(String, FemElement, std::path::PathBuf)> =
        vec![(short(&spec.fem_mesh), spec.element, spec.fem_mesh.clone())];
    if let Some(rich) = &spec.richardson {
        bodies.push((short(&rich.mesh), spec.element, rich.mesh.clone()));
    }
    if !quick && spec.element != FemElement::Linear(fem::elasticity::Element::P1) {
        bodies.push((
            short(&spec.fem_mesh),
            FemElement::Linear(fem::elasticity::Element::P1),
            spec.fem_mesh.clone(),
        ));
    }
    // Per body: its name, seconds (factor, W), and per level the samples and statistics.
    let mut computed = Vec::new();
    for (name, element, path) in &bodies {
        step(&format!(
            "sampled contact: W on {name} ({}) at {} lattice points",
            element.name(),
            all.len()
        ));
        let fem = SampledFem::load(&prep.organ.scene, path, *element)?;
        let t = Instant::now();
        let (w, at, widest) = fem.patch_compliance(&all, r, None)?;
        let w_s = t.elapsed().as_secs_f64();
        let mut per_level = Vec::new();
        for (((lattice, points), range), &level) in lattices.iter().zip(&ranges).zip(&levels) {
            per_level.push(samples_from(
                lattice.clone(),
                points,
                w[range.clone()].to_vec(),
                &at[range.clone()],
                widest,
                &fem,
                level,
                r,
                w_s * range.len() as f64 / all.len() as f64,
            )?);
        }
        computed.push((
            format!("{} {name}", element.name().to_uppercase()),
            fem.factor_s,
            fem.mesh_hash,
            per_level,
        ));
    }
    let mut variants = Vec::new();
    let mut push =
        |fem: String, level_index: usize, samples, stats, mesh_hashes, seconds: f64, chosen| {
            let built = prep.bank(&BankSpec::Sampled(SampledParts {
                samples,
                stats,
                mesh_hashes,
            }))?;
            variants.push(Variant {
                fem,
                level: levels[level_index],
                bank: built.bytes,
                precompute_s: seconds,
                error: (0.0, 0.0),
                chosen,
                instructions: None,
            });
            anyhow::Ok(())
        };
    for (b, (name, factor_s, hash, per_level)) in computed.iter().enumerate() {
        for (i, (samples, stats)) in per_level.iter().enumerate() {
            let chosen = b == 0 && spec.richardson.is_none() && levels[i] == spec.level;
            let seconds = factor_s + stats.w_s;
            push(
                name.clone(),
                i,
                samples.clone(),
                *stats,
                vec![*hash],
                seconds,
                chosen,
            )?;
        }
    }
    if let (Some(rich), [fine, coarse, ..]) = (&spec.richardson, computed.as_slice()) {
        for (i, &level) in levels.iter().enumerate() {
            let (mut samples, stats) = fine.3[i].clone();
            let coarse_w: &[Block3] = &coarse.3[i].0.w;
            samples.w = extrapolated(&samples.w, coarse_w, rich.factor());
            if samples.w.iter().any(|w| !spd(w)) {
                continue;
            }
            let seconds = fine.1 + stats.w_s + coarse.1 + coarse.3[i].1.w_s;
            push(
                format!("{} + Richardson ({})", fine.0, short(&rich.mesh)),
                i,
                samples,
                stats,
                vec![fine.2, coarse.2],
                seconds,
                level == spec.level,
            )?;
        }
    }
    step("sampled contact: the firmware's force against the converged reference");
    let depths: &[f64] = if quick {
        &[0.005]
    } else {
        &[0.002, 0.005, 0.008]
    };
    for v in &mut variants {
        let aligned = AlignedBytes::new(&v.bank);
        let bank = Bank::parse(&aligned)
            .map_err(|e| anyhow::anyhow!("internal: a sampled bank does not parse: {e}"))?;
        v.error = force_error(&prep.organ, &bank, &study, depths)?;
    }
    Ok(variants)
}

/// One press of [`press_errors`].
#[derive(Debug, Clone, PartialEq)]
pub struct Press {
    /// The study's site index.
    pub site: usize,
    /// Press depth, m.
    pub depth: f64,
    /// The force the firmware's tick renders, N.
    pub rendered: [f64; 3],
    /// The reference's force for the same press, `W_ref^-1 d`, N.
    pub reference: [f64; 3],
    /// `|rendered - reference| / |reference|`.
    pub error: f64,
}

/// The firmware's rendered force on `bank` against the reference at the study's sites, for
/// frictionless presses of `depths` (m) along the inward normal of the collision triangle
/// `host contact probe` finds there (`d = -depth n`, the same `d` for both: a site on a
/// triangle edge has two normals, and the bank's press takes the probe's).
pub fn press_errors(
    organ: &Organ,
    bank: &Bank<'_>,
    study: &Study,
    depths: &[f64],
) -> Result<Vec<Press>> {
    let mut out = Vec::new();
    for (s, site) in study.sites.iter().enumerate() {
        for &depth in depths {
            let p = crate::probe::probe(
                bank,
                (&organ.mesh.nodes, &organ.surface.triangles),
                site.query,
                Some(depth),
                false,
            )
            .with_context(|| format!("site {}", site.name))?;
            let rendered = p.force_n.context("the probe rendered no force")?;
            let reference =
                crate::linalg::solve3(&study.reference_w[s], p.normal.map(|x| depth * x));
            let diff = (0..3)
                .map(|c| (rendered[c] - reference[c]).powi(2))
                .sum::<f64>()
                .sqrt();
            let size = reference.iter().map(|x| x * x).sum::<f64>().sqrt();
            out.push(Press {
                site: s,
                depth,
                rendered,
                reference,
                error: diff / size,
            });
        }
    }
    Ok(out)
}

/// Mean and worst relative error of the firmware's rendered force on `bank` against the
/// reference at its sites, for normal presses of `depths` (m) ([`press_errors`]).
pub fn force_error(
    organ: &Organ,
    bank: &Bank<'_>,
    study: &Study,
    depths: &[f64],
) -> Result<(f64, f64)> {
    let presses = press_errors(organ, bank, study, depths)?;
    let worst = presses.iter().fold(0.0f64, |m, p| m.max(p.error));
    let mean = presses.iter().map(|p| p.error).sum::<f64>() / presses.len().max(1) as f64;
    Ok((mean, worst))
}

/// A point of the Pareto front: its costs (mean error, worst error, bytes, instructions) and
/// its label.
struct Candidate {
    costs: [f64; 4],
    label: String,
}

/// The knob and its rows: error against bank bytes per FEM (points per level), the nodal
/// bank beside, the Pareto front of (mean error, worst error, bytes, instructions) over every
/// point whose instructions were measured.
pub fn section(variants: &[Variant], nodal: &[NodalPoint]) -> (Knob, Vec<HardCase>) {
    let label = |v: &Variant| {
        format!(
            "{} level {}: mean {:.1} %, worst {:.1} %, {} B, {:.0} s{}",
            v.fem,
            v.level,
            100.0 * v.error.0,
            100.0 * v.error.1,
            v.bank.len(),
            v.precompute_s,
            v.instructions
                .map_or(String::new(), |i| format!(", {i:.0} instructions"))
        )
    };
    let mut fems: Vec<&str> = Vec::new();
    for v in variants {
        if !fems.contains(&v.fem.as_str()) {
            fems.push(&v.fem);
        }
    }
    let point = |v: &Variant| Point {
        x: v.bank.len() as f64,
        y: v.error.0,
        label: label(v),
    };
    let mut series: Vec<Series> = fems
        .iter()
        .map(|f| Series {
            name: format!("sampled W on {f} (levels)"),
            points: variants.iter().filter(|v| v.fem == *f).map(point).collect(),
        })
        .collect();
    let nodal_point = |n: &NodalPoint| Point {
        x: n.bytes as f64,
        y: n.error.0,
        label: format!(
            "{}: mean {:.1} %, worst {:.1} %, {} B{}",
            n.name,
            100.0 * n.error.0,
            100.0 * n.error.1,
            n.bytes,
            n.instructions
                .map_or(String::new(), |i| format!(", {i:.0} instructions"))
        ),
    };
    if !nodal.is_empty() {
        series.push(Series {
            name: "nodal tool patch on the collision mesh".into(),
            points: nodal.iter().map(nodal_point).collect(),
        });
    }
    // The objectives: mean and worst error (the goal is per site: every press within 5 %),
    // bytes, instructions.
    let mut all: Vec<Candidate> = variants
        .iter()
        .filter_map(|v| {
            Some(Candidate {
                costs: [v.error.0, v.error.1, v.bank.len() as f64, v.instructions?],
                label: label(v),
            })
        })
        .collect();
    all.extend(nodal.iter().filter_map(|n| {
        Some(Candidate {
            costs: [n.error.0, n.error.1, n.bytes as f64, n.instructions?],
            label: nodal_point(n).label,
        })
    }));
    let beats = |a: &Candidate, b: &Candidate| {
        a.costs.iter().zip(&b.costs).all(|(x, y)| x <= y)
            && a.costs.iter().zip(&b.costs).any(|(x, y)| x < y)
    };
    let front: Vec<&Candidate> = all
        .iter()
        .filter(|c| !all.iter().any(|o| beats(o, c)))
        .collect();
    // Drawn as a series when it has a shape (three points or more); named in the finding
    // either way.
    if front.len() >= 3 {
        series.push(Series {
            name: "Pareto front (mean error, worst error, bytes, instructions)".into(),
            points: front
                .iter()
                .map(|c| Point {
                    x: c.costs[2],
                    y: c.costs[0],
                    label: c.label.clone(),
                })
                .collect(),
        });
    }
    let chosen = variants.iter().find(|v| v.chosen);
    let on_front = chosen.is_some_and(|c| front.iter().any(|f| f.label == label(c)));
    let fits = |v: &&Variant| v.bank.len() <= 128 * 1024;
    let best_fit = variants
        .iter()
        .filter(fits)
        .min_by(|a, b| a.error.0.total_cmp(&b.error.0));
    let finding = format!(
        "{} sampled banks against the converged reference ({} nodal). The front: {}. The \
         scene's choice: {}; it is {}on the front (mean error, worst error, bytes, \
         instructions{}). The most \
         accurate bank within the demo's 128 KiB: {}. Nodal: {}",
        variants.len(),
        nodal.len(),
        front
            .iter()
            .map(|c| c.label.as_str())
            .collect::<Vec<_>>()
            .join("; "),
        chosen.map_or("not among the variants".into(), label),
        if on_front { "" } else { "NOT " },
        if variants.iter().all(|v| v.instructions.is_none()) {
            "; no instructions were measured, the front is empty"
        } else {
            ""
        },
        best_fit.map_or("none".into(), label),
        nodal
            .iter()
            .map(|n| nodal_point(n).label)
            .collect::<Vec<_>>()
            .join("; ")
    );
    let knob = Knob {
        id: "sampled".into(),
        title: "Sampled patch compliance: FEM and sample spacing against the converged force"
            .into(),
        x_label: "bank bytes".into(),
        y_label: "mean force error against the converged reference".into(),
        log_x: true,
        log_y: true,
        series,
        chosen: chosen.map(point),
        finding,
    };
    let mut rows = Vec::new();
    if let Some(c) = chosen {
        rows.push(HardCase {
            case: format!(
                "converged force: the scene's bank ({} level {})",
                c.fem, c.level
            ),
            measurement: format!(
                "firmware force against the converged reference at 14 sites: mean {:.1} %, \
                 worst {:.1} %",
                100.0 * c.error.0,
                100.0 * c.error.1
            ),
            reference: format!(
                "within 5 % at every site and depth (the reference's own error: {})",
                reference().map_or_else(
                    |e| format!("unknown, {e}"),
                    |st| {
                        let (lo, hi) = st
                            .reference_error
                            .iter()
                            .fold((f64::INFINITY, 0.0f64), |(l, h), &e| (l.min(e), h.max(e)));
                        format!("{:.1}-{:.1} %", 100.0 * lo, 100.0 * hi)
                    }
                )
            ),
            verdict: if c.error.1 <= 0.05 {
                Verdict::MatchesReference
            } else if c.error.0 <= 0.05 {
                Verdict::Bounded
            } else {
                Verdict::Weakness
            },
            value: Some(c.error.1),
            reference_value: Some(0.05),
        });
    }
    (knob, rows)
}

/// The refinement row of the sampled model: the reference study's `n . W n` change between
/// its two finest meshes (mean over sites), and the extrapolated reference's own error.
pub fn refinement_case(study: &Study) -> Option<HardCase> {
    let [.., a, b] = study.levels.as_slice() else {
        return None;
    };
    let change: Vec<f64> = study
        .sites
        .iter()
        .enumerate()
        .map(|(s, site)| {
            let (ka, kb) = (
                crate::linalg::normal_compliance(&a.w[s], site.normal),
                crate::linalg::normal_compliance(&b.w[s], site.normal),
            );
            ((kb - ka) / kb).abs()
        })
        .collect();
    let mean = change.iter().sum::<f64>() / change.len().max(1) as f64;
    let ref_mean =
        study.reference_error.iter().sum::<f64>() / study.reference_error.len().max(1) as f64;
    Some(HardCase {
        case: format!(
            "refinement x{}: sampled patch compliance ({})",
            study.levels.len(),
            b.element
        ),
        measurement: format!(
            "n.W.n changes by {:.1} % (mean over {} sites) from {} to {}; the extrapolated \
             reference's estimated error {:.1} % (mean)",
            100.0 * mean,
            study.sites.len(),
            a.mesh,
            b.mesh,
            100.0 * ref_mean
        ),
        reference: "a converging model changes by less than 10 % between refinements".into(),
        verdict: if mean <= 0.1 {
            Verdict::Bounded
        } else {
            Verdict::Weakness
        },
        value: Some(mean),
        reference_value: Some(0.1),
    })
}
