//! The large-deformation reference on the default liver (`haptic::large`): presses of 8, 12
//! and 15 mm and pulls of 10, 20 and 30 mm at study sites, neo-Hookean and linear on the same
//! mesh, the data of `host report`'s large-press section. Ignored by default (minutes per site
//! and mesh): `cargo test --profile checked -p haptic --test large_press -- --ignored
//! --nocapture`. `LARGE_MESH` = the mesh file (default the committed liver-reach-4mm),
//! `LARGE_SITES` = site names separated by `;` (default right lobe top), `LARGE_OUT` = a JSON
//! file to write the runs to (`host/tests/data/large-press.json` is this output).

use fem::hyperelastic::uniaxial_stress;
use haptic::large::LargeFem;
use haptic::report::large_press::{
    Measured, PRESSES_M, PULLS_M, REFERENCE_MESH, SPECIMEN_STRAINS, SiteRun, reference_runs,
    section, specimen_law,
};
use haptic::scene::Scene;
use haptic::study::Site;
use std::path::{Path, PathBuf};
use std::time::Instant;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

#[test]
#[ignore = "minutes: large presses and pulls on the liver"]
fn liver_presses_and_pulls() {
    let scene = Scene::load(&root().join("scenes/liver.toml")).unwrap();
    let mesh = std::env::var("LARGE_MESH")
        .map_or_else(|_| root().join("meshes/liver-reach-4mm.msh"), PathBuf::from);
    let text = std::fs::read_to_string(root().join("tests/data/patch-study-p2.json")).unwrap();
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    let all: Vec<Site> = serde_json::from_value(v["sites"].clone()).unwrap();
    let wanted = std::env::var("LARGE_SITES").unwrap_or_else(|_| "right lobe top".into());
    let t0 = Instant::now();
    let fem = LargeFem::load(&scene, &mesh).unwrap();
    println!(
        "{}: {} vertices, {} nodes, built in {:.1} s",
        mesh.display(),
        fem.vertices,
        fem.nodes(),
        t0.elapsed().as_secs_f64()
    );
    let pulls: Vec<f64> = PULLS_M.iter().map(|d| -d).collect();
    let mut runs = Vec::new();
    for site in all
        .iter()
        .filter(|s| wanted.split(';').any(|w| w == s.name))
    {
        let run = |what: &str, depths: &[f64]| {
            let t = Instant::now();
            let r = fem.press(site, depths).map_err(|e| format!("{e:#}"));
            match &r {
                Ok(p) => {
                    for x in p {
                        let n = |v: [f64; 3]| v.iter().map(|c| c * c).sum::<f64>().sqrt();
                        println!(
                            "{:<22} {what} {:4.1} mm: |F_large| {:.5} N, |F_lin| {:.5} N, ratio \
                             {:.4}, linear error {:5.1} %, {} iterations",
                            site.name,
                            x.depth_m.abs() * 1e3,
                            n(x.large),
                            n(x.linear),
                            x.ratio(),
                            100.0 * x.linear_error(),
                            x.iterations
                        );
                    }
                }
                Err(e) => println!("{:<22} {what}: FAILED: {e}", site.name),
            }
            println!("    {what}: {:.1} s", t.elapsed().as_secs_f64());
            r
        };
        let presses = run("press", &PRESSES_M);
        let pulls = run("pull", &pulls);
        runs.push(SiteRun {
            site: site.name.clone(),
            presses,
            pulls,
        });
    }
    if let Ok(out) = std::env::var("LARGE_OUT") {
        std::fs::write(&out, serde_json::to_string_pretty(&runs).unwrap()).unwrap();
    }
}

/// The specimen's large-deformation curve (`host report`'s Q is fitted to it) against the
/// closed form of homogeneous uniaxial compression of the same strain energy: between
/// frictionless platens the field is homogeneous, so force / linear force is
/// `-P_33 / (E strain)` whatever the cross-section, with the lateral stretch `l` the root of
/// `mu (l^2 - 1) + lambda ln(l^2 s) = 0` and `P_33 = mu (s - 1/s) + lambda ln(l^2 s) / s`.
#[test]
fn the_specimen_curve_is_the_closed_form() {
    let scene = Scene::load(&root().join("scenes/liver.toml")).unwrap();
    let mesh = fem::mesh::load(&root().join("meshes/cylinder-2k.msh")).unwrap();
    let t = Instant::now();
    let law = specimen_law(&mesh, &scene).unwrap();
    println!(
        "specimen law in {:.1} s, RMS {:.2e}",
        t.elapsed().as_secs_f64(),
        law.rms
    );
    let (lambda, mu) = scene.material.lame();
    for (k, &e) in SPECIMEN_STRAINS.iter().enumerate() {
        let (_, p33) = uniaxial_stress(lambda, mu, 1.0 - e);
        let want = -p33 / (scene.material.young * e);
        let got = law.large_n[k] / law.linear_n[k];
        println!("strain {e}: force / linear {got:.6}, closed form {want:.6}");
        assert!(
            (got - want).abs() < 1e-5 * want,
            "strain {e}: {got} against {want}"
        );
    }
}

/// The report's section on the committed runs: the worst linear error per press depth is the
/// largest `|F_lin - F_large| / |F_large|` over the sites, recomputed here from the vectors.
#[test]
fn the_report_section_on_the_committed_runs() {
    let scene = Scene::load(&root().join("scenes/liver.toml")).unwrap();
    let mesh = fem::mesh::load(&root().join("meshes/cylinder-2k.msh")).unwrap();
    let runs = reference_runs().unwrap();
    let m = Measured {
        mesh: REFERENCE_MESH.into(),
        sites: runs.clone(),
        specimen: Ok(specimen_law(&mesh, &scene).unwrap()),
        cold_s: 0.0,
    };
    let (knob, cases, not) = section(&m, &scene);
    assert!(not.is_empty(), "{not:?}");
    println!("{}", knob.finding);
    for c in &cases {
        println!("{}: {} [{}]", c.case, c.measurement, c.verdict.text());
    }
    let linear = knob
        .series
        .iter()
        .find(|s| s.name == "press, linear")
        .unwrap();
    for (k, p) in linear.points.iter().enumerate() {
        let worst = runs
            .iter()
            .map(|r| {
                let x = &r.presses.as_ref().unwrap()[k];
                let d: f64 = (0..3).map(|a| (x.linear[a] - x.large[a]).powi(2)).sum();
                let l: f64 = (0..3).map(|a| x.large[a].powi(2)).sum();
                (d / l).sqrt()
            })
            .fold(0.0f64, f64::max);
        assert!((p.y - 100.0 * worst).abs() < 1e-9, "{p:?} against {worst}");
    }
}
