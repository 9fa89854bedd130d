//! The shipped scene's rendered force against the converged reference.
//!
//! Reference: `host/tests/data/patch-study-p2.json`, written by
//!
//! ```sh
//! python3 scripts/gen_meshes.py --reach-series scaled  # liver-reach-scaled-*mm -> generated/
//! cargo run --release -p host -- contact study --element p2 \
//!     --mesh host/meshes/liver-reach-4mm.msh:0.004 \
//!     --mesh host/meshes/generated/liver-reach-scaled-2.8mm.msh:0.0028 \
//!     --mesh host/meshes/generated/liver-reach-scaled-2mm.msh:0.002 \
//!     --out host/tests/data/patch-study-p2.json
//! ```
//!
//! (about 5 minutes and 10 GiB; `patch-study-p1.json` the same with `--element p1` on the
//! scaled 2.8, 2, 1.4 and 1 mm meshes): the patch compliance `W` of the scene's 3 mm tool at 14
//! sites of the reachable surface on meshes that refine as a whole by the ratio 1.4,
//! Richardson-extrapolated with one pooled order, each site with its own grid convergence
//! index (`haptic::study`). The two series use different elements on different meshes; their
//! limits must agree within their error estimates.

use bank_format::{AlignedBytes, Bank};
use haptic::linalg::normal_compliance;
use haptic::organ::Organ;
use haptic::reach::Region;
use haptic::report::sampled;
use haptic::study::Study;
use std::path::Path;

fn manifest(p: &str) -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(p)
}

fn study(name: &str) -> Study {
    let text = std::fs::read_to_string(manifest(&format!("tests/data/{name}"))).unwrap();
    serde_json::from_str(&text).unwrap()
}

/// `W^-1 v` for a symmetric positive definite 3 x 3 `W` (Cramer's rule, f64).
#[test]
fn the_p1_and_p2_limits_agree_within_their_error_estimates() {
    let (p2, p1) = (study("patch-study-p2.json"), study("patch-study-p1.json"));
    assert_eq!(p2.sites, p1.sites);
    assert!(p2.sites.len() >= 12);
    for (s, site) in p2.sites.iter().enumerate() {
        let k2 = 1.0 / normal_compliance(&p2.reference_w[s], site.normal);
        let k1 = 1.0 / normal_compliance(&p1.reference_w[s], site.normal);
        let bound = p1.reference_error[s] + p2.reference_error[s];
        assert!(
            (k1 / k2 - 1.0).abs() <= bound,
            "{}: P1 limit {k1:.3} N/m, P2 limit {k2:.3} N/m, beyond their errors ({bound:.3})",
            site.name
        );
    }
}

/// The study's sites are the default scene's: the same collision-surface points.
#[test]
fn the_study_sites_are_the_default_scenes() {
    let st = study("patch-study-p2.json");
    let liver = Organ::load(&manifest("scenes/liver.toml")).unwrap();
    let given: Vec<(String, [f64; 3])> = haptic::study::DEFAULT_SITES
        .iter()
        .map(|(n, p)| (n.to_string(), *p))
        .collect();
    let sites = haptic::study::sites(&liver, &Region::of(&liver).unwrap(), &given).unwrap();
    assert_eq!(sites.len(), st.sites.len());
    for (a, b) in sites.iter().zip(&st.sites) {
        assert_eq!(a.name, b.name);
        for c in 0..3 {
            assert!((a.point[c] - b.point[c]).abs() < 1e-12, "{}", a.name);
        }
    }
}

/// At every site and press depth (2, 5, 8 mm along the inward normal), the force the
/// firmware's tick renders on the shipped bank (`host contact probe`'s press, linear model)
/// against the reference's `W^-1 d`: the whole force vector within 5 %, the reference itself
/// good to better than 5 % at every site. The mean error of the force vector is under 3 %. The
/// bank fits the demo's 128 KiB.
#[test]
fn the_shipped_bank_renders_the_converged_force() {
    let st = study("patch-study-p2.json");
    let scene = manifest("scenes/liver.toml");
    let liver = Organ::load(&scene).unwrap();
    let bytes = haptic::bank::scene_bank(&scene).unwrap();
    assert!(bytes.len() <= 128 * 1024, "{} bytes", bytes.len());
    let aligned = AlignedBytes::new(&bytes);
    let bank = Bank::parse(&aligned).unwrap();
    assert!(bank.samples().is_some(), "the shipped bank is sampled");
    let presses = sampled::press_errors(&liver, &bank, &st, &[0.002, 0.005, 0.008]).unwrap();
    assert_eq!(presses.len(), 3 * st.sites.len());
    for p in &presses {
        let site = &st.sites[p.site];
        let ref_err = st.reference_error[p.site];
        assert!(
            ref_err < 0.05,
            "{}: the reference is uncertain by {:.1} %",
            site.name,
            100.0 * ref_err
        );
        assert!(
            p.error <= 0.05,
            "{} at {} m: rendered {:?} N, reference {:?} N: {:.1} % off",
            site.name,
            p.depth,
            p.rendered,
            p.reference,
            100.0 * p.error
        );
    }
    let worst = presses
        .iter()
        .max_by(|a, b| a.error.total_cmp(&b.error))
        .unwrap();
    let mean = presses.iter().map(|p| p.error).sum::<f64>() / presses.len() as f64;
    eprintln!(
        "rendered force against the converged reference: mean {:.2} %, worst {:.2} % ({} at {} \
         m), {} presses",
        100.0 * mean,
        100.0 * worst.error,
        st.sites[worst.site].name,
        worst.depth,
        presses.len()
    );
    assert!(mean < 0.03, "mean error {mean}");
}
