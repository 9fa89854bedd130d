//! The firmware's f32 contact solve against an f64 reference on a small analytic patch.
//!
//! The reference is the host engine's `fem::compliance::contact_forces` (`f_S = C_SS^-1 u*_S`,
//! dense Cholesky in f64) for the point and paper forms, and an f64 3 x 3 solve for the
//! energy-minimal one, on a bank built from an analytic SPD compliance `C_kl = a delta_kl I + exp(-|x_k - x_l| / L) M`
//! (`M` SPD, stiffer along the surface normal) over a 6-node patch of 4 triangles.

#![allow(clippy::needless_range_loop)]

use bank_format::{AlignedBytes, Bank, BankBuilder, TissueLaw};
use fem::compliance::{Block3, contact_forces};
use firmware::fixtures::{gauss, rel_err};
use firmware::solve::{
    alpha_weights, condition_alpha, condition_barycentric, solve_point, solve_triangle_alpha,
    solve_triangle_barycentric,
};

const A: f64 = 0.3e-3;
const L: f64 = 0.015;

fn positions() -> Vec<[f64; 3]> {
    // A gently curved 2 x 3 patch, 8 mm spacing.
    let mut p = Vec::new();
    for j in 0..2 {
        for i in 0..3 {
            let (x, y) = (0.008 * i as f64, 0.008 * j as f64);
            p.push([x, y, 0.002 * (x / 0.016 - 0.5).powi(2)]);
        }
    }
    p
}

fn block(p: &[[f64; 3]], k: usize, l: usize) -> [[f64; 3]; 3] {
    let m = [
        [0.8e-3, 0.05e-3, 0.1e-3],
        [0.05e-3, 0.9e-3, -0.05e-3],
        [0.1e-3, -0.05e-3, 1.6e-3],
    ];
    let d = (0..3)
        .map(|i| (p[k][i] - p[l][i]).powi(2))
        .sum::<f64>()
        .sqrt();
    let kern = (-d / L).exp();
    std::array::from_fn(|i| {
        std::array::from_fn(|j| kern * m[i][j] + if k == l && i == j { A } else { 0.0 })
    })
}

const TRIANGLES: [[u32; 3]; 4] = [[0, 1, 4], [0, 4, 3], [1, 2, 5], [1, 5, 4]];

fn bank_bytes() -> AlignedBytes {
    let p = positions();
    let n = p.len();
    let mut couplings = Vec::new();
    for k in 0..n {
        for l in k + 1..n {
            couplings.push((k as u32, l as u32, block(&p, k, l)));
        }
    }
    let b = BankBuilder {
        c_kk: (0..n).map(|k| block(&p, k, k)).collect(),
        couplings,
        mesh_ids: (100..100 + n as u32).collect(),
        triangles: TRIANGLES.to_vec(),
        positions_m: p,
        grid_cell_size_m: 0.008,
        truncation_radius_m: 0.03,
        scene_id: 7,
        law: TissueLaw::chebyshev(&[2.6, 2.5, 0.1], [0.0, 5.0]).unwrap(),
        gravity: None,
        relaxation: None,
        samples: None,
        device: firmware::fixtures::bench_device([0.008, 0.004, 0.1]),
    };
    AlignedBytes::new(&b.build().expect("valid analytic bank"))
}

/// `C_SS` as blocks, f64, from the analytic compliance (not the bank's f32 copy: the error
/// below includes storage rounding).
fn css_blocks(nodes: &[usize]) -> Vec<Vec<Block3>> {
    let p = positions();
    nodes
        .iter()
        .map(|&k| nodes.iter().map(|&l| block(&p, k, l)).collect())
        .collect()
}

/// The host's forces for displacements `u` imposed on `nodes`, flattened.
fn host_forces(nodes: &[usize], u: &[[f64; 3]]) -> Vec<f64> {
    contact_forces(&css_blocks(nodes), u)
        .expect("the analytic C_SS is SPD")
        .forces
        .concat()
}

/// 2-norm condition number of a symmetric positive definite matrix, from its eigenvalues.
fn condition(m: &[Vec<f64>]) -> f64 {
    let n = m.len();
    let eig = nalgebra::DMatrix::from_fn(n, n, |i, j| m[i][j]).symmetric_eigenvalues();
    eig.max() / eig.min()
}

/// Dense `C_SS`, f64, from the analytic compliance.
fn css(nodes: &[usize]) -> Vec<Vec<f64>> {
    let p = positions();
    let m = 3 * nodes.len();
    let mut c = vec![vec![0.0; m]; m];
    for (a, &k) in nodes.iter().enumerate() {
        for (b, &l) in nodes.iter().enumerate() {
            let blk = block(&p, k, l);
            for i in 0..3 {
                for j in 0..3 {
                    c[3 * a + i][3 * b + j] = blk[i][j];
                }
            }
        }
    }
    c
}

const D: [f32; 3] = [0.0008, -0.0005, -0.005];

fn d64() -> Vec<f64> {
    D.iter().map(|&v| f64::from(v)).collect()
}

#[test]
fn point_contact_f32_matches_f64_reference() {
    let bytes = bank_bytes();
    let bank = Bank::parse(&bytes).unwrap();
    let mut worst = 0.0f64;
    for k in 0..bank.node_count() {
        let got = solve_point(&bank, k as u16, D).unwrap();
        let want = host_forces(&[k], &[D.map(f64::from)]);
        worst = worst.max(rel_err(got.forces(), &want));
    }
    println!("point contact, 6 nodes: worst relative error f32 vs f64 {worst:.2e}");
    // Measured 4.2e-8; 5e-6 fails on a hundredfold loss of precision.
    assert!(worst <= 5e-6, "{worst}");
}

#[test]
fn triangle_forms_f32_match_f64_reference_and_compare_conditioning() {
    let bytes = bank_bytes();
    let bank = Bank::parse(&bytes).unwrap();
    let barys = [[1.0f32 / 3.0; 3], [0.6, 0.3, 0.1], [0.05, 0.05, 0.9]];
    let (mut worst_a, mut worst_b) = (0.0f64, 0.0f64);
    for tri in TRIANGLES {
        let nodes = tri.map(|v| v as usize);
        let tri16 = tri.map(|v| v as u16);
        let c = css(&nodes);
        let ca = condition_alpha(&bank, tri16).unwrap();
        for bary in barys {
            // Paper's alpha form.
            let alpha = alpha_weights(bary);
            let u: Vec<[f64; 3]> = alpha
                .iter()
                .map(|&a| D.map(|v| f64::from(a) * f64::from(v)))
                .collect();
            let got = solve_triangle_alpha(&bank, tri16, bary, D).unwrap();
            let ea = rel_err(got.forces(), &host_forces(&nodes, &u));
            // Energy-minimal form.
            let mut m = vec![vec![0.0; 3]; 3];
            for a in 0..3 {
                for b in 0..3 {
                    let w = f64::from(bary[a]) * f64::from(bary[b]);
                    for i in 0..3 {
                        for j in 0..3 {
                            m[i][j] += w * c[3 * a + i][3 * b + j];
                        }
                    }
                }
            }
            let ft = gauss(m.clone(), d64());
            let want: Vec<f64> = (0..9).map(|r| f64::from(bary[r / 3]) * ft[r % 3]).collect();
            let gotb = solve_triangle_barycentric(&bank, tri16, bary, D).unwrap();
            let eb = rel_err(gotb.forces(), &want);
            let cb = condition_barycentric(&bank, tri16, bary).unwrap();
            // The firmware's estimates are lower bounds of the true condition numbers, and
            // the energy-minimal form is never worse conditioned than the paper's: the
            // eigenvalues of `B C_SS B^T / |k|^2` are Rayleigh quotients of `C_SS`, so they
            // lie within its spectrum.
            let (true_a, true_b) = (condition(&c), condition(&m));
            assert!(f64::from(ca) <= true_a * 1.001, "{ca} > {true_a}");
            assert!(f64::from(cb) <= true_b * 1.001, "{cb} > {true_b}");
            assert!(true_b <= true_a * (1.0 + 1e-9), "{true_b} > {true_a}");
            let fa = got.tool_force_n.map(|v| v as f64);
            let fb = gotb.tool_force_n.map(|v| v as f64);
            let norm = |f: [f64; 3]| (f[0] * f[0] + f[1] * f[1] + f[2] * f[2]).sqrt();
            println!(
                "triangle {tri:?} k {bary:.3?}: alpha form err {ea:.2e} cond {true_a:.1} \
                 (estimate {ca:.1}) |f_tool| {:.4} N; barycentric form err {eb:.2e} cond \
                 {true_b:.1} (estimate {cb:.1}) |f_tool| {:.4} N",
                norm(fa),
                norm(fb)
            );
            worst_a = worst_a.max(ea);
            worst_b = worst_b.max(eb);
        }
    }
    println!(
        "worst relative error f32 vs f64: alpha form {worst_a:.2e}, barycentric {worst_b:.2e}"
    );
    // Measured 2.6e-7 and 2.5e-7.
    assert!(worst_a <= 5e-6, "{worst_a}");
    assert!(worst_b <= 5e-6, "{worst_b}");
}
