//! The shipped scene's contact against the organ's own surface (`haptic::report::surface`):
//! presses 5 mm deep along the FEM surface's inward normal at random sites over its reachable
//! part, the firmware's tick on the shipped bank against the scene's extrapolated `W` computed
//! directly at each site.
//!
//! The sites and their reference are committed (`host/tests/data/surface-sites.json`), written
//! by the ignored test here (about 1 minute, 2.6 GiB: the scene's two P2 factorisations):
//!
//! ```sh
//! SURFACE_SITES_OUT=host/tests/data/surface-sites.json \
//!     cargo test --release -p host --test surface_sites -- --ignored --nocapture
//! ```

use bank_format::{AlignedBytes, Bank};
use haptic::linalg::normal_compliance;
use haptic::organ::Organ;
use haptic::reach::Region;
use haptic::report::surface::{self, SurfaceSites};
use std::path::Path;

/// Sites drawn by the ignored test, and its seed.
const SITES: usize = 200;
const SEED: u64 = 20261208;

fn manifest(p: &str) -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(p)
}

/// The firmware's force at `c`'s site against the reference's `W_ref^-1 d` for the
/// firmware's own depth: 5 mm plus the collision surface's offset along the press.
fn against_own_depth(c: &surface::SiteCheck) -> Option<f64> {
    let f = c.rendered?;
    let k = (surface::DEPTH_M + c.offset_m) / surface::DEPTH_M;
    let r = c.reference.map(|x| k * x);
    Some(
        ((0..3).map(|i| (f[i] - r[i]).powi(2)).sum::<f64>() / r.iter().map(|x| x * x).sum::<f64>())
            .sqrt(),
    )
}

/// Prints and returns the check of `sites` on the shipped bank.
fn run(sites: &SurfaceSites) -> (Vec<surface::SiteCheck>, surface::Summary) {
    let scene = manifest("scenes/liver.toml");
    let organ = Organ::load(&scene).unwrap();
    let region = Region::of(&organ).unwrap();
    let bytes = haptic::bank::scene_bank(&scene).unwrap();
    let aligned = AlignedBytes::new(&bytes);
    let bank = Bank::parse(&aligned).unwrap();
    let checks = surface::check(&organ, &region, &bank, &sites.sites, &sites.reference_w);
    let s = surface::summary(&checks);
    eprintln!(
        "{} sites: normal angle max {:.2} deg mean {:.2} deg; {} refused by R (shortfall max \
         {:.2} mm); force error mean {:.2} %, worst {:.2} % at {}",
        s.sites,
        s.angle_max_rad.to_degrees(),
        s.angle_mean_rad.to_degrees(),
        s.refused,
        1e3 * s.shortfall_max_m,
        100.0 * s.error_mean,
        100.0 * s.error_max,
        surface::name(&sites.sites[s.worst])
    );
    (checks, s)
}

/// At the committed sites on the shipped bank (from the bank cache): the reference is good to
/// 5 % against the converged study; R holds every site; and wherever the collision triangle's
/// normal lies within the stick cone (11.3 deg) of the organ's, the press sticks and the
/// firmware's force is the reference's `W^-1 d` at the firmware's own depth (5 mm plus the
/// collision surface's offset along the press) within 2.5 % (the lattice's interpolation): the
/// compliance follows the organ, the depth the collision surface. Beyond the cone the press
/// slides on the collision triangle (`docs/scenes-and-banks.md`, "The contact against the
/// organ's surface").
#[test]
fn presses_on_the_organ_render_its_compliance_at_the_collision_depth() {
    let data = surface::committed().unwrap();
    assert_eq!(data.sites.len(), SITES);
    assert_eq!(data.seed, SEED);
    assert!(data.reference_error < 0.05, "{}", data.reference_error);
    let (checks, s) = run(&data);
    assert_eq!(s.refused, 0);
    let cone = f64::from(firmware::contact::STICK_SLOPE).atan();
    let mut inside = 0;
    for (c, site) in checks.iter().zip(&data.sites) {
        if c.angle_rad > cone {
            continue;
        }
        inside += 1;
        let e = against_own_depth(c).unwrap();
        assert!(
            e <= 0.025,
            "{}: {:.2} % off the reference at the firmware's depth (offset {:.3} mm)",
            surface::name(site),
            100.0 * e,
            1e3 * c.offset_m
        );
    }
    assert!(inside >= SITES * 9 / 10, "{inside} sites within the cone");
}

/// The committed sites are the ones [`surface::draw`] draws today from the committed seed (the
/// same FEM mesh, the same reach), and `host report`'s rows state the check's figures: the
/// worst press error and its site, the largest normal angle, R's shortfall.
#[test]
fn the_committed_sites_and_the_report_rows_are_todays() {
    let scene_path = manifest("scenes/liver.toml");
    let scene = haptic::scene::Scene::load(&scene_path).unwrap();
    let data = surface::committed().unwrap();
    let drawn = surface::draw(&scene, SITES, data.seed, surface::Reach::Press).unwrap();
    // To the JSON's round trip (serde_json parses a decimal to within an ulp or so).
    assert_eq!(drawn.len(), data.sites.len());
    for (a, b) in drawn.iter().zip(&data.sites) {
        for c in 0..3 {
            assert!((a.point[c] - b.point[c]).abs() < 1e-15, "{a:?} vs {b:?}");
            assert!((a.normal[c] - b.normal[c]).abs() < 1e-14, "{a:?} vs {b:?}");
        }
    }
    let bytes = haptic::bank::scene_bank(&scene_path).unwrap();
    let rows = surface::section(&scene, &bytes).unwrap();
    let (_, s) = run(&data);
    assert_eq!(rows.len(), 3);
    assert_eq!(rows[0].value, Some(s.error_max));
    assert!(
        rows[0]
            .measurement
            .contains(&surface::name(&data.sites[s.worst])),
        "{}",
        rows[0].measurement
    );
    assert_eq!(rows[1].value, Some(s.angle_max_rad));
    let short = rows[2].value.unwrap();
    assert!(short.is_finite() && short >= 0.0, "{short}");
}

/// Draws the sites, computes their reference (and the reference's own error at the study's
/// sites), writes them where `SURFACE_SITES_OUT` says, and prints the check.
#[test]
#[ignore = "about a minute and 2.6 GiB: regenerates host/tests/data/surface-sites.json"]
fn measure_the_contact_against_the_organ_surface() {
    let scene_path = manifest("scenes/liver.toml");
    let organ = Organ::load(&scene_path).unwrap();
    let scene = &organ.scene;
    let haptic::scene::ContactModel::Sampled(spec) = &scene.contact else {
        panic!("the shipped scene is sampled");
    };
    let sites = surface::draw(scene, SITES, SEED, surface::Reach::Press).unwrap();
    let study = haptic::report::sampled::reference().unwrap();
    let mut points: Vec<[f64; 3]> = sites.iter().map(|s| s.point).collect();
    points.extend(study.sites.iter().map(|s| s.point));
    let mut w = surface::reference_w(scene, &points).unwrap();
    let at_study = w.split_off(sites.len());
    let reference_error = study
        .sites
        .iter()
        .enumerate()
        .map(|(s, site)| {
            let k = 1.0 / normal_compliance(&at_study[s], site.normal);
            let k_inf = 1.0 / normal_compliance(&study.reference_w[s], site.normal);
            (k / k_inf - 1.0).abs()
        })
        .fold(0.0, f64::max);
    let name = |p: &Path| p.file_name().unwrap().to_string_lossy().into_owned();
    let data = SurfaceSites {
        fem_mesh: name(&spec.fem_mesh),
        fem_mesh_hash: haptic::bank::cache::file_hash(scene, &spec.fem_mesh).unwrap(),
        richardson_mesh: spec.richardson.as_ref().map(|r| name(&r.mesh)),
        seed: SEED,
        sites,
        reference_w: w,
        reference_error,
    };
    eprintln!(
        "reference: the scene's extrapolation against the converged continuum at the study's \
         sites, largest difference {:.2} %",
        100.0 * reference_error
    );
    if let Ok(out) = std::env::var("SURFACE_SITES_OUT") {
        std::fs::write(out, serde_json::to_string_pretty(&data).unwrap()).unwrap();
    }
    let (checks, _) = run(&data);
    let region = Region::of(&organ).unwrap();
    let wide = surface::draw(scene, 2000, SEED, surface::Reach::Region).unwrap();
    let short = surface::shortfalls(&organ, &region, &wide);
    let refused: Vec<usize> = (0..wide.len()).filter(|&i| short[i] > 0.0).collect();
    let worst = refused
        .iter()
        .copied()
        .max_by(|&a, &b| short[a].total_cmp(&short[b]));
    eprintln!(
        "reach: {} of {} FEM surface sites within R's reach test are refused by R{}",
        refused.len(),
        wide.len(),
        worst.map_or(String::new(), |i| format!(
            ", worst {:.2} mm short at {}",
            1e3 * short[i],
            surface::name(&wide[i])
        ))
    );
    let mut order: Vec<usize> = (0..checks.len()).collect();
    order.sort_by(|&a, &b| checks[b].error.total_cmp(&checks[a].error));
    // The diagnosis: within the stick cone, the force against the reference scaled by the
    // firmware's depth (5 mm plus the collision surface's offset).
    let cone = f64::from(firmware::contact::STICK_SLOPE).atan();
    let mut rows = Vec::new();
    for c in &checks {
        let Some(e) = against_own_depth(c) else {
            continue;
        };
        rows.push((c.angle_rad <= cone, c.error, e, c.offset_m));
    }
    for inside in [true, false] {
        let sel: Vec<_> = rows.iter().filter(|r| r.0 == inside).collect();
        let n = sel.len().max(1) as f64;
        eprintln!(
            "within the cone {inside}: {} sites, error mean {:.2} % max {:.2} %; against the \
             depth-scaled reference mean {:.2} % max {:.2} %; |offset| mean {:.3} max {:.3} mm",
            sel.len(),
            100.0 * sel.iter().map(|r| r.1).sum::<f64>() / n,
            100.0 * sel.iter().map(|r| r.1).fold(0.0, f64::max),
            100.0 * sel.iter().map(|r| r.2).sum::<f64>() / n,
            100.0 * sel.iter().map(|r| r.2).fold(0.0, f64::max),
            1e3 * sel.iter().map(|r| r.3.abs()).sum::<f64>() / n,
            1e3 * sel.iter().map(|r| r.3.abs()).fold(0.0, f64::max),
        );
    }
    for &i in order.iter().take(10) {
        let c = &checks[i];
        eprintln!(
            "  {}: error {:.2} %, offset {:.3} mm, angle {:.1} deg, shortfall {:.2} mm, rendered {:?}, \
             reference {:?}",
            surface::name(&data.sites[i]),
            100.0 * c.error,
            1e3 * c.offset_m,
            c.angle_rad.to_degrees(),
            1e3 * c.shortfall_m,
            c.rendered,
            c.reference
        );
    }
}

/// R's shortfall on the organ's surface against the reach margin R is cut with: the 2000
/// FEM-surface points the report draws (within the scene's tip radius and margin of the
/// workspace), R's nodes and triangles, and the points R refuses, for margins of 2 to 10 mm.
#[test]
#[ignore = "a few seconds per margin: a measurement for docs/scenes-and-banks.md"]
fn reach_margin_against_the_shortfall() {
    let scene_path = manifest("scenes/liver.toml");
    let organ = Organ::load(&scene_path).unwrap();
    let seed = surface::committed().unwrap().seed;
    let sites = surface::draw(
        &organ.scene,
        surface::REACH_SITES,
        seed,
        surface::Reach::Region,
    )
    .unwrap();
    for margin_mm in [2.0, 4.0, 6.0, 8.0, 10.0] {
        let mut scene = organ.scene.clone();
        scene.bank.reach_margin_m = 1e-3 * margin_mm;
        let wider = Organ::from_scene(scene).unwrap();
        let region = Region::of(&wider).unwrap();
        let short = surface::shortfalls(&wider, &region, &sites);
        let refused = short.iter().filter(|&&x| x > 0.0).count();
        let worst = short.iter().copied().fold(0.0, f64::max);
        eprintln!(
            "margin {margin_mm} mm: R {} nodes, {} triangles; {refused} of {} refused, up to \
             {:.2} mm",
            region.len(),
            region.triangles.len(),
            sites.len(),
            1e3 * worst
        );
    }
}
