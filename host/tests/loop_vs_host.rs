//! The firmware's f32 contact solve on a real bank (the shipped liver scene) against the host's
//! f64 solve on the untruncated compliance of the same contact set: point contacts and the
//! paper's alpha-weighted triangle contacts.

use bank_format::{AlignedBytes, Bank};
use host::compliance::{Compliance, contact_forces};
use host::fem::Elasticity;
use host::scene::Scene;
use std::path::Path;
use std::process::Command;

#[test]
fn firmware_forces_match_the_host_f64_reference_on_the_liver_bank() {
    let scene_path = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/liver.toml");
    let dir = tempfile::tempdir().unwrap();
    let bank_path = dir.path().join("liver.bank");
    let built = Command::new(env!("CARGO_BIN_EXE_host"))
        .args(["bank", "build"])
        .arg(&scene_path)
        .arg("-o")
        .arg(&bank_path)
        .output()
        .unwrap();
    assert!(
        built.status.success(),
        "{}",
        String::from_utf8_lossy(&built.stderr)
    );
    let bytes = std::fs::read(&bank_path).unwrap();
    let aligned = AlignedBytes::new(&bytes);
    let bank = Bank::parse(&aligned).unwrap();

    // The host's reference: the full (untruncated) compliance of the same scene.
    let scene = Scene::load(&scene_path).unwrap();
    let (mesh, _, _) = scene.load_mesh().unwrap();
    let fixed = scene.fixed_set(&mesh).unwrap();
    let body = Elasticity::new(&mesh, scene.material).unwrap();
    let compliance = Compliance::factorize(&body, &fixed).unwrap();
    let ids: Vec<usize> = bank.mesh_ids().iter().map(|&i| i as usize).collect();

    let d = [0.0f32, 0.0, -0.005];
    let bary = [0.2f32, 0.3, 0.5];
    let alpha = firmware::solve::alpha_weights(bary);
    let mut worst: f64 = 0.0;
    let triangles = bank.triangles();
    for tri in triangles.iter().step_by((triangles.len() / 25).max(1)) {
        let nodes: Vec<usize> = tri.iter().map(|&k| ids[k as usize]).collect();
        let c_ss = compliance.blocks(&nodes, None).unwrap();
        // Triangle, alpha weights.
        let imposed: Vec<[f64; 3]> = alpha
            .iter()
            .map(|&a| d.map(|x| f64::from(a) * f64::from(x)))
            .collect();
        let reference = contact_forces(&c_ss, &imposed).unwrap();
        let got = firmware::solve::solve_triangle_alpha(&bank, *tri, bary, d).unwrap();
        worst = worst.max(relative(got.forces(), &reference.forces));
        // Point contact at the first vertex.
        let single = contact_forces(&[vec![c_ss[0][0]]], &[d.map(f64::from)]).unwrap();
        let got = firmware::solve::solve_point(&bank, tri[0], d).unwrap();
        worst = worst.max(relative(got.forces(), &single.forces));
    }
    eprintln!(
        "firmware f32 vs host f64, untruncated compliance: worst relative force error {worst:.2e}"
    );
    assert!(worst <= 1e-4, "{worst:e}");
}

fn relative(got: &[[f32; 3]], want: &[[f64; 3]]) -> f64 {
    let mut num = 0.0;
    let mut den = 0.0;
    for (g, w) in got.iter().zip(want) {
        for c in 0..3 {
            num += (f64::from(g[c]) - w[c]).powi(2);
            den += w[c] * w[c];
        }
    }
    assert_eq!(got.len(), want.len());
    (num / den).sqrt()
}
