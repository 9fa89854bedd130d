//! Viscoelastic relaxation in the loop, seen in the report: the `press-hold`
//! script (5 mm in over 0.5 s, held, out) on the QLV scene (`host/scenes/liver-qlv.toml`) run
//! on the QEMU image, its rendered force against Fung's QLV response to the scene's law, and
//! the firmware's instructions per tick against the number of Prony terms.
//!
//! **Force against time.** The image's rendered tool force per tick, and the analytic
//! response: the elastic force `Q_e` of the same motion (the encoder counts the image read,
//! replayed through the firmware's loop natively on the scene's bank without its relaxation
//! section, `G = 1`) convolved with the scene's `G(t) = g_inf + sum_k g_k exp(-t / tau_k)`,
//! `F(n) = g_inf Q_e(n) + sum_k g_k sum_{j <= n} w_k exp(-(n - j) dt / tau_k) (Q_e(j) -
//! Q_e(j-1))`, `w_k = (tau_k / dt)(1 - exp(-dt / tau_k))` (the hereditary integral over a
//! piecewise-linear `Q_e`, summed directly over the whole history in f64, not by the
//! firmware's recursion), with the contact's unilateral rule of `firmware::relax` (no force
//! without an elastic one, no pull against it). The worst difference over every tick and axis
//! is reported relative to the peak elastic force (the SIL test `press_hold_relaxes_as_the_
//! scenes_qlv_law` holds it to 1e-4). The elastic force itself is plotted beside them.
//!
//! **Instructions per tick against terms.** The same script on the same bank with 0 (the
//! relaxation section left out), 1, 3 and 4 terms (the relaxation record rewritten in place
//! and the bank resealed, as the SIL test does: the first terms of `g = (0.3, 0.2, 0.15,
//! 0.1)`, `tau = (0.05, 0.5, 5, 50)` s) and 2 (the scene's own law, the run of the force
//! plot): the law phase's mean over the run's ticks and the loop body's and the whole tick's
//! worst.

use super::{HardCase, Knob, Point, Series, Verdict};
use crate::sil::harness::{self, Run, Session, Setup, TickRecord};
use crate::trajectory::Script;
use anyhow::{Result, anyhow, bail};
use bank_format::{AlignedBytes, Bank, Relaxation, SectionKind};
use firmware::hal::Interlocks;
use firmware::tick::{HapticLoop, LoopInput};
use std::path::{Path, PathBuf};

/// The loop's period, s.
const DT_S: f64 = 1.0e-3;
/// Seconds of `press-hold` run: the approach (0.5 s), the press (0.5 s), the 10 s hold, the
/// release (0.5 s), and 0.5 s after it, free.
pub const PRESS_HOLD_S: f64 = 12.0;
/// Near the end of the hold, s (as the SIL test takes it).
const HOLD_END_S: f64 = 10.9;
/// The plotted force trace: one point every this many ticks (the worst difference is over
/// every tick).
const PLOT_EVERY: usize = 20;
/// The generic law whose first terms make the 1-, 3- and 4-term banks.
const GENERIC_G: [f32; 4] = [0.3, 0.2, 0.15, 0.1];
/// Its time constants, s.
const GENERIC_TAU_S: [f32; 4] = [0.05, 0.5, 5.0, 50.0];

/// The QLV scene's bank and the same scene's bank without relaxation.
pub struct Banks {
    /// The scene's bank (its relaxation section included).
    pub qlv: Vec<u8>,
    /// The elastic scene's bank: the same scene without `[viscoelastic]`.
    pub elastic: Vec<u8>,
}

/// Both banks (from the bank cache when their scenes are unchanged): `qlv_scene` relaxes,
/// `elastic_scene` is the same scene without `[viscoelastic]` (`liver-qlv.toml` is
/// `liver.toml` with the table, as its header says and the SIL test takes it), each from its
/// own file (the bank the SIL test and `host sil` load); the two banks must differ by the
/// relaxation section alone (its directory entry and record, within a section alignment),
/// else the pair is refused.
pub fn banks(qlv_scene: &Path, elastic_scene: &Path) -> Result<Banks> {
    let qlv = crate::bank::scene_bank(qlv_scene)?;
    let elastic = crate::bank::scene_bank(elastic_scene)?;
    let raw = AlignedBytes::new(&qlv);
    let parsed = Bank::parse(&raw).map_err(|e| anyhow!("{}: {e}", qlv_scene.display()))?;
    if parsed.relaxation().is_none() {
        bail!(
            "{}: no [viscoelastic] table: the relaxation section needs a relaxing scene",
            qlv_scene.display()
        );
    }
    let extra = bank_format::SECTION_ENTRY_LEN + std::mem::size_of::<Relaxation>();
    let more = qlv.len().checked_sub(elastic.len());
    if !more.is_some_and(|m| m >= extra && m < extra + bank_format::SECTION_ALIGN) {
        bail!(
            "{} ({} bytes) and {} ({} bytes) are not one scene with and without relaxation",
            qlv_scene.display(),
            qlv.len(),
            elastic_scene.display(),
            elastic.len()
        );
    }
    Ok(Banks { qlv, elastic })
}

/// `bytes` (a bank with a relaxation section) with its relaxation record replaced by the
/// first `terms` (1 to 4) of the generic law (`g = (0.3, 0.2, 0.15, 0.1)`, `tau = (0.05, 0.5,
/// 5, 50)` s), resealed: the same bank relaxing with another number of terms.
pub fn with_terms(bytes: &[u8], terms: usize) -> Result<Vec<u8>> {
    let mut out = bytes.to_vec();
    let count = usize::from(u16::from_le_bytes([out[14], out[15]]));
    let kind = SectionKind::Relaxation.code();
    let entry = (0..count)
        .map(|i| bank_format::HEADER_LEN + bank_format::SECTION_ENTRY_LEN * i)
        .find(|&e| out[e..e + 4] == kind.to_le_bytes())
        .ok_or_else(|| anyhow!("internal: the QLV bank has no relaxation section"))?;
    let off = u32::from_le_bytes(
        out[entry + 4..entry + 8]
            .try_into()
            .map_err(|_| anyhow!("internal: a short section entry"))?,
    ) as usize;
    // Entries past `count` zero (SPEC.md).
    let mut law = Relaxation {
        count: terms as u32,
        reserved: 0,
        g: [0.0; 4],
        tau_s: [0.0; 4],
    };
    law.g[..terms].copy_from_slice(&GENERIC_G[..terms]);
    law.tau_s[..terms].copy_from_slice(&GENERIC_TAU_S[..terms]);
    let mut record = Vec::with_capacity(40);
    record.extend(law.count.to_le_bytes());
    record.extend(law.reserved.to_le_bytes());
    for v in law.g.iter().chain(&law.tau_s) {
        record.extend(v.to_le_bytes());
    }
    out[off..off + record.len()].copy_from_slice(&record);
    if !bank_format::reseal(&mut out) {
        bail!("internal: the rewritten QLV bank could not be resealed");
    }
    let parsed = AlignedBytes::new(&out);
    let bank = Bank::parse(&parsed).map_err(|e| anyhow!("internal: a {terms}-term bank: {e}"))?;
    if bank.relaxation() != Some(&law) {
        bail!("internal: the {terms}-term bank does not carry its law");
    }
    Ok(out)
}

/// One run's cost.
#[derive(Clone, Copy, Debug)]
pub struct TermCost {
    /// Prony terms.
    pub terms: usize,
    /// The law phase's instructions, mean over the run's ticks.
    pub law_mean: f64,
    /// The loop body's worst instructions.
    pub body_worst: u32,
    /// The whole tick's worst instructions.
    pub tick_worst: u32,
}

impl TermCost {
    fn of(terms: usize, run: &Run) -> TermCost {
        let n = run.ticks.len().max(1) as f64;
        TermCost {
            terms,
            law_mean: run
                .ticks
                .iter()
                .map(|t| f64::from(t.phase_instructions.law))
                .sum::<f64>()
                / n,
            body_worst: run
                .ticks
                .iter()
                .map(|t| t.body_instructions)
                .max()
                .unwrap_or(0),
            tick_worst: run
                .ticks
                .iter()
                .map(|t| t.tick_instructions)
                .max()
                .unwrap_or(0),
        }
    }
}

/// What the section measured.
pub struct Measured {
    /// Seconds of `press-hold` run.
    pub seconds: f64,
    /// Per tick: time (s), rendered |F|, analytic |F| and the elastic |Q_e| (N).
    pub trace: Vec<(f64, f64, f64, f64)>,
    /// The elastic force's largest magnitude, N.
    pub peak: f64,
    /// The worst |rendered - analytic| over every tick and axis, relative to `peak`.
    pub worst: f64,
    /// The scene's `g_inf`.
    pub g_inf: f64,
    /// Cost per number of terms, 0..=4.
    pub costs: Vec<TermCost>,
    /// Faults the image reported over the runs.
    pub faults: usize,
}

/// Writes a bank for the image and gives its set-up (and the directory that keeps it).
pub type SetupFor<'a> = dyn Fn(&[u8]) -> Result<(Setup, tempfile::TempDir)> + 'a;

/// Runs `press-hold` for `seconds` on the image (`setup_for` writes a bank and gives its
/// set-up) for the scene's law and for 0, 1, 3 and 4 terms, and computes the analytic response.
pub fn measure(
    banks: &Banks,
    setup_for: &SetupFor,
    seconds: f64,
    step: &dyn Fn(&str),
) -> Result<Measured> {
    let qlv_raw = AlignedBytes::new(&banks.qlv);
    let qlv = Bank::parse(&qlv_raw).map_err(|e| anyhow!("the QLV scene's bank: {e}"))?;
    let elastic_raw = AlignedBytes::new(&banks.elastic);
    let elastic = Bank::parse(&elastic_raw).map_err(|e| anyhow!("the elastic bank: {e}"))?;
    let law = *qlv
        .relaxation()
        .ok_or_else(|| anyhow!("internal: the QLV bank does not relax"))?;
    // The scene's law, then elastic and 1, 3 and 4 terms: five runs, side by side
    // (`harness::run_all`: the same script and costs as one at a time).
    let mut variants = vec![
        (
            format!("the scene's law ({} terms)", law.count),
            law.count as usize,
            banks.qlv.clone(),
        ),
        ("elastic".to_string(), 0, banks.elastic.clone()),
    ];
    for terms in [1, 3, 4] {
        let bytes = with_terms(&banks.qlv, terms)?;
        variants.push((format!("{terms} term(s)"), terms, bytes));
    }
    let raws: Vec<AlignedBytes> = variants.iter().map(|v| AlignedBytes::new(&v.2)).collect();
    let parsed = raws
        .iter()
        .map(|r| Bank::parse(r).map_err(|e| anyhow!("internal: {e}")))
        .collect::<Result<Vec<_>>>()?;
    let setups = variants
        .iter()
        .map(|v| setup_for(&v.2))
        .collect::<Result<Vec<_>>>()?;
    let jobs = setups
        .iter()
        .zip(&parsed)
        .map(|((setup, _dir), bank)| Ok((setup, Session::new(bank, Script::PressHold, seconds)?)))
        .collect::<Result<Vec<_>>>()?;
    step(&format!(
        "relaxation: press-hold for {seconds} s on the QEMU image: {}",
        variants
            .iter()
            .map(|v| v.0.as_str())
            .collect::<Vec<_>>()
            .join(", ")
    ));
    let mut runs = Vec::new();
    for (r, (what, terms, _)) in harness::run_all(&jobs).into_iter().zip(&variants) {
        let r = r?;
        if let Some(why) = &r.stopped {
            bail!(
                "press-hold ({what}): the image stopped early: {why}\n{}",
                r.stderr
            );
        }
        runs.push((*terms, r));
    }
    // Faults of the relaxing runs (the elastic one is the reference).
    let faults: usize = runs
        .iter()
        .filter(|(terms, _)| *terms > 0)
        .map(|(_, r)| r.faults().len())
        .sum();
    let mut costs: Vec<TermCost> = runs.iter().map(|(t, r)| TermCost::of(*t, r)).collect();
    let run = runs.swap_remove(0).1;
    costs.sort_by_key(|c| c.terms);

    let q = elastic_replay(&elastic, &run.ticks);
    let analytic = qlv_response(&q, &law);
    let peak = q.iter().map(|v| norm(*v)).fold(0.0, f64::max);
    if peak <= 0.0 {
        bail!("press-hold on the QLV scene: the tool never touched the organ");
    }
    let mut worst = 0.0f64;
    let mut trace = Vec::with_capacity(run.ticks.len());
    for (k, (rec, want)) in run.ticks.iter().zip(&analytic).enumerate() {
        let got = rec.force_n.map(f64::from);
        for i in 0..3 {
            worst = worst.max((got[i] - want[i]).abs() / peak);
        }
        trace.push((k as f64 * DT_S, norm(got), norm(*want), norm(q[k])));
    }
    let g_inf = 1.0 - law.terms().map(|(g, _)| f64::from(g)).sum::<f64>();
    Ok(Measured {
        seconds,
        trace,
        peak,
        worst,
        g_inf,
        costs,
        faults,
    })
}

fn norm(v: [f64; 3]) -> f64 {
    v.iter().map(|x| x * x).sum::<f64>().sqrt()
}

/// The elastic tool force of a run's motion, per tick: the encoder counts the image read,
/// replayed through the firmware's loop natively on `elastic` (the scene's bank without its
/// relaxation section), homed at the first tick as the run was.
pub fn elastic_replay(elastic: &Bank, ticks: &[TickRecord]) -> Vec<[f64; 3]> {
    let mut lp = HapticLoop::new(elastic);
    lp.zero_encoders();
    ticks
        .iter()
        .map(|rec| {
            lp.tick(LoopInput {
                encoder_counts: rec.encoder_counts,
                overrun: false,
                link_silence_ticks: 0,
                interlocks: Interlocks::default(),
            })
            .tool_force_n
            .map(f64::from)
        })
        .collect()
}

/// Fung's QLV response to the per-tick elastic force `q` under the reduced relaxation function
/// of `law` (module notes: the hereditary integral summed directly in f64, then the
/// unilateral rule): the reference the firmware's recursion is held to.
pub fn qlv_response(q: &[[f64; 3]], law: &Relaxation) -> Vec<[f64; 3]> {
    let terms: Vec<(f64, f64)> = law
        .terms()
        .map(|(g, tau)| (f64::from(g), f64::from(tau)))
        .collect();
    let g_inf = 1.0 - terms.iter().map(|t| t.0).sum::<f64>();
    let n = q.len();
    let dq: Vec<[f64; 3]> = (0..n)
        .map(|j| {
            let prev = if j == 0 { [0.0; 3] } else { q[j - 1] };
            std::array::from_fn(|i| q[j][i] - prev[i])
        })
        .collect();
    // Per term: g w exp(-m dt / tau) for every age m.
    let kernels: Vec<Vec<f64>> = terms
        .iter()
        .map(|&(g, tau)| {
            let w = tau / DT_S * (1.0 - (-DT_S / tau).exp());
            (0..n)
                .map(|m| g * w * (-(m as f64) * DT_S / tau).exp())
                .collect()
        })
        .collect();
    (0..n)
        .map(|k| {
            let mut f = q[k].map(|v| g_inf * v);
            for kernel in &kernels {
                for j in 0..=k {
                    let w = kernel[k - j];
                    for (fi, d) in f.iter_mut().zip(dq[j]) {
                        *fi += w * d;
                    }
                }
            }
            let qq: f64 = q[k].iter().map(|v| v * v).sum();
            let along: f64 = (0..3).map(|i| f[i] * q[k][i]).sum();
            if qq == 0.0 {
                [0.0; 3]
            } else if along < 0.0 {
                std::array::from_fn(|i| f[i] - along / qq * q[k][i])
            } else {
                f
            }
        })
        .collect()
}

/// The two knobs (force against time; instructions against terms) and the hard-case row.
pub fn section(m: &Measured) -> (Vec<Knob>, HardCase) {
    let sampled = |pick: fn(&(f64, f64, f64, f64)) -> f64| -> Vec<Point> {
        m.trace
            .iter()
            .step_by(PLOT_EVERY)
            .map(|p| Point {
                x: p.0,
                y: pick(p),
                label: format!("{:.3} s", p.0),
            })
            .collect()
    };
    // Near the end of the hold: how far the force relaxed.
    let held = m
        .trace
        .get((HOLD_END_S / DT_S) as usize)
        .map_or(f64::NAN, |p| p.1);
    let peak_rendered = m.trace.iter().map(|p| p.1).fold(0.0, f64::max);
    let force = Knob {
        id: "relaxation-press-hold".into(),
        title: "Relaxation: press-hold on liver-qlv, rendered force against time (QEMU image)"
            .into(),
        x_label: "time, s".into(),
        y_label: "|tool force|, N".into(),
        log_x: false,
        log_y: false,
        series: vec![
            Series {
                name: "firmware on the QEMU image".into(),
                points: sampled(|p| p.1),
            },
            Series {
                name: "analytic QLV (scene's G(t) on the elastic force, f64)".into(),
                points: sampled(|p| p.2),
            },
            Series {
                name: "elastic force of the same motion (G = 1, liver.toml's bank)".into(),
                points: sampled(|p| p.3),
            },
        ],
        chosen: None,
        finding: format!(
            "{:.1} s of press-hold ({} ticks, plotted every {PLOT_EVERY}): the rendered force \
             peaks at {peak_rendered:.4} N and relaxes to {held:.4} N at {HOLD_END_S} s, the \
             end of the hold (g_inf {:.3}); the worst difference from the analytic QLV response over every tick and axis is \
             {:.2e} of the {:.4} N peak elastic force; {} faults",
            m.seconds,
            m.trace.len(),
            m.g_inf,
            m.worst,
            m.peak,
            m.faults
        ),
    };
    let cost_series = |name: &str, f: fn(&TermCost) -> f64| Series {
        name: name.into(),
        points: m
            .costs
            .iter()
            .map(|c| Point {
                x: c.terms as f64,
                y: f(c),
                label: if c.terms == 2 {
                    "2 terms (the scene's law)".into()
                } else {
                    format!("{} term(s)", c.terms)
                },
            })
            .collect(),
    };
    let law_of = |terms: usize| {
        m.costs
            .iter()
            .find(|c| c.terms == terms)
            .map(|c| c.law_mean)
    };
    let per_term = match (law_of(4), law_of(1)) {
        (Some(four), Some(one)) => (four - one) / 3.0,
        _ => f64::NAN,
    };
    let listed: Vec<String> = m
        .costs
        .iter()
        .map(|c| {
            format!(
                "{}: law mean {:.1}, body worst {}, tick worst {}",
                c.terms, c.law_mean, c.body_worst, c.tick_worst
            )
        })
        .collect();
    let cost = Knob {
        id: "relaxation-terms".into(),
        title: "Relaxation: instructions per tick against Prony terms (QEMU image, press-hold)"
            .into(),
        x_label: "Prony terms".into(),
        y_label: "instructions per tick".into(),
        log_x: false,
        log_y: false,
        series: vec![
            cost_series("law phase, mean over the run's ticks", |c| c.law_mean),
            cost_series("loop body, worst tick", |c| f64::from(c.body_worst)),
            cost_series("whole tick, worst", |c| f64::from(c.tick_worst)),
        ],
        chosen: None,
        finding: format!(
            "{:.1} s of press-hold per count; the law phase's mean grows {per_term:.1} \
             instructions a term (1 to 4 terms); {}",
            m.seconds,
            listed.join("; ")
        ),
    };
    let row = HardCase {
        case: "press-hold on the QLV scene (QEMU image)".into(),
        measurement: format!(
            "worst |rendered - analytic QLV| over {} ticks and 3 axes, relative to the {:.4} N \
             peak elastic force",
            m.trace.len(),
            m.peak
        ),
        reference: "Fung's QLV response to the elastic force, 1e-4 relative".into(),
        verdict: if m.worst < 1e-4 {
            Verdict::MatchesReference
        } else {
            Verdict::Weakness
        },
        value: Some(m.worst),
        reference_value: Some(1e-4),
    };
    (vec![force, cost], row)
}

/// The shipped QLV scene and its elastic twin (the checkout's; named when missing).
pub fn shipped_scenes() -> Result<(PathBuf, PathBuf)> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes");
    let (qlv, elastic) = (dir.join("liver-qlv.toml"), dir.join("liver.toml"));
    for p in [&qlv, &elastic] {
        if !p.exists() {
            bail!("{}: not in this checkout", p.display());
        }
    }
    Ok((qlv, elastic))
}
