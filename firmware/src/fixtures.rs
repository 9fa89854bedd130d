//! Test fixtures shared by the firmware's unit tests and the cross-crate tests in `tests/`:
//! device calibrations and a small hand-made bank. Compiled only for tests or with the
//! `test-fixtures` feature (which needs `bank-format/alloc`); never in a firmware image.

// Test data only, never in an image: the crate's no-panic lints do not apply.
#![allow(clippy::indexing_slicing, clippy::expect_used)]

extern crate alloc;

use alloc::vec::Vec;
use bank_format::{AlignedBytes, BankBuilder, DeviceCalibration, TissueLaw};

pub use bank_format::fixtures::{FIXTURE_LINK_TIMEOUT_MS, SplitMix64, bench_device};

/// The liver scene's device (`host/scenes/liver.toml`).
pub fn liver_device() -> DeviceCalibration {
    DeviceCalibration {
        fulcrum_m: [0.0, 0.0, 0.16],
        shaft_axis: [0.0, 0.0, -1.0],
        pitch_axis: [1.0, 0.0, 0.0],
        yaw_axis: [0.0, 1.0, 0.0],
        joint_min: [-0.35, -0.35, 0.03],
        joint_max: [0.35, 0.35, 0.14],
        home_joint: [0.0, 0.0, 0.03],
        counts_per_rev: [4096, 4096, 4096],
        transmission: [12.0, 12.0, 400.0],
        torque_constant_nm_per_a: [0.025, 0.025, 0.025],
        current_limit_a: [2.0, 2.0, 2.0],
        max_force_n: 5.0,
        tip_radius_m: 0.003,
        // The scene's defaults (`haptic::scene`): 1 m/s at the tip; 10 rad/s (1 m/s at 0.1 m
        // insertion) and 1 m/s along the shaft.
        max_tip_speed_m_s: 1.0,
        max_joint_speed: [10.0, 10.0, 1.0],
        link_timeout_ms: FIXTURE_LINK_TIMEOUT_MS,
    }
}

/// A tilted gimbal: the liver-like frame turned 0.4 rad about (1, 1, 1) / sqrt(3), the
/// fulcrum away from the origin, wide joint ranges, unequal encoders and transmissions (one of
/// them reversed): the kinematics' hard case.
pub fn tilted_device() -> DeviceCalibration {
    let k = 1.0 / libm::sqrt(3.0);
    let (s, c) = (libm::sin(0.4), libm::cos(0.4));
    // Rodrigues' rotation about the unit axis (k, k, k), in f64.
    let r = |v: [f64; 3]| -> [f32; 3] {
        let a = [k, k, k];
        let dot = a[0] * v[0] + a[1] * v[1] + a[2] * v[2];
        let cross = [
            a[1] * v[2] - a[2] * v[1],
            a[2] * v[0] - a[0] * v[2],
            a[0] * v[1] - a[1] * v[0],
        ];
        core::array::from_fn(|i| (v[i] * c + cross[i] * s + a[i] * dot * (1.0 - c)) as f32)
    };
    DeviceCalibration {
        fulcrum_m: [0.12, -0.05, 0.3],
        shaft_axis: r([0.0, 0.0, -1.0]),
        pitch_axis: r([0.0, 1.0, 0.0]),
        yaw_axis: r([1.0, 0.0, 0.0]),
        joint_min: [-1.5, -3.1, 0.0],
        joint_max: [1.5, 3.1, 0.25],
        home_joint: [0.1, -0.2, 0.05],
        counts_per_rev: [2000, 1024, 500],
        transmission: [-8.0, 20.0, -250.0],
        torque_constant_nm_per_a: [0.03, 0.05, 0.02],
        current_limit_a: [1.5, 3.0, 2.5],
        max_force_n: 8.0,
        tip_radius_m: 0.002,
        max_tip_speed_m_s: 1.0,
        max_joint_speed: [10.0, 10.0, 1.0],
        link_timeout_ms: FIXTURE_LINK_TIMEOUT_MS,
    }
}

/// Spacing of [`flat_patch`], m.
pub const PATCH_SPACING_M: f64 = 0.01;
/// Nodes per side of [`flat_patch`].
pub const PATCH_SIDE: usize = 5;

/// The liver-like gimbal with its fulcrum 10 cm above the middle of [`flat_patch`], shaft
/// pointing down, home insertion 5 cm.
pub fn patch_device() -> DeviceCalibration {
    DeviceCalibration {
        fulcrum_m: [0.02, 0.02, 0.1],
        home_joint: [0.0, 0.0, 0.05],
        ..liver_device()
    }
}

/// `C_kl = exp(-|x_k - x_l| / 15 mm) M + 0.3e-3 exp(-|x_k - x_l| / 1 mm) I`: SPD (a sum of
/// exponential kernels times SPD matrices), m/N, and continuous in the positions, so nodes a
/// few micrometres apart have nearly equal blocks, as an elastic body's would.
pub fn kernel_block(p: &[[f64; 3]], k: usize, l: usize) -> [[f64; 3]; 3] {
    let m = [
        [1.0e-3, 0.1e-3, 0.0],
        [0.1e-3, 1.2e-3, 0.05e-3],
        [0.0, 0.05e-3, 2.0e-3],
    ];
    // libm: this module is `no_std` too.
    let d = libm::sqrt(
        (0..3)
            .map(|i| (p[k][i] - p[l][i]) * (p[k][i] - p[l][i]))
            .sum::<f64>(),
    );
    let kern = libm::exp(-d / 0.015);
    let local = 0.3e-3 * libm::exp(-d / 0.001);
    core::array::from_fn(|i| {
        core::array::from_fn(|j| kern * m[i][j] + if i == j { local } else { 0.0 })
    })
}

/// A flat 5 x 5-node patch at z = 0 (outward normal +z), 1 cm spacing, every pair coupled with
/// [`kernel_block`], the [`patch_device`] and a Chebyshev tissue law.
pub fn flat_patch() -> AlignedBytes {
    grid_patch(PATCH_SIDE, PATCH_SPACING_M, 0.06)
}

/// A flat `n_side x n_side`-node grid at z = 0 (outward normal +z) with spacing `h` (m), two
/// triangles per square (every interior node has six, lumped area `h^2`), the pairs closer than
/// `truncation_m` coupled with [`kernel_block`], the [`patch_device`] and a Chebyshev law.
pub fn grid_patch(n_side: usize, h: f64, truncation_m: f64) -> AlignedBytes {
    grid_patch_with(n_side, h, truncation_m, patch_device())
}

/// [`grid_patch`] with the device calibration `device`.
pub fn grid_patch_with(
    n_side: usize,
    h: f64,
    truncation_m: f64,
    device: DeviceCalibration,
) -> AlignedBytes {
    let ticks: Vec<f64> = (0..n_side).map(|i| h * i as f64).collect();
    grid_bank(&ticks, &ticks, truncation_m, device)
}

/// [`grid_patch`] with node columns at `xs` and rows at `ys` (increasing, m): uneven grids,
/// e.g. two rows a few micrometres apart (sliver triangles, nearly coincident contact nodes).
///
/// # Panics
/// Only if the builder rejects it, which would be a bug in this fixture.
pub fn grid_patch_at(xs: &[f64], ys: &[f64], truncation_m: f64) -> AlignedBytes {
    grid_bank(xs, ys, truncation_m, patch_device())
}

/// The patch compliance of [`sampled_patch`]'s samples at point `x` (m): a linear field, so
/// that the firmware's interpolation reproduces it exactly, SPD on the patch (m/N).
pub fn sampled_w(x: [f64; 3]) -> [[f64; 3]; 3] {
    let a = 0.05 + 0.4 * x[0] + 0.2 * x[1];
    [
        [a, 0.002, 0.001],
        [0.002, 1.1 * a, 0.003 + 0.05 * x[0]],
        [0.001, 0.003 + 0.05 * x[0], 0.6 * a],
    ]
}

/// [`flat_patch`] with contact samples (bank format 6) at lattice level 2: each sample's `W` is
/// [`sampled_w`] at its point.
pub fn sampled_patch() -> AlignedBytes {
    sampled_patch_with(sampled_w)
}

/// [`sampled_patch`] with each sample's `W` given by `w` at its point (m -> m/N).
pub fn sampled_patch_with(w: impl Fn([f64; 3]) -> [[f64; 3]; 3]) -> AlignedBytes {
    sampled_patch_at_level(2, w)
}

/// [`sampled_patch_with`] at lattice `level` (1..=8).
pub fn sampled_patch_at_level(level: u32, w: impl Fn([f64; 3]) -> [[f64; 3]; 3]) -> AlignedBytes {
    let b = sampled_patch_builder(level, w);
    AlignedBytes::new(&b.build().expect("valid fixture bank"))
}

/// The builder of [`sampled_patch_at_level`], for a test to build (or see refused) itself.
pub fn sampled_patch_builder(level: u32, w: impl Fn([f64; 3]) -> [[f64; 3]; 3]) -> BankBuilder {
    let xs: Vec<f64> = (0..PATCH_SIDE)
        .map(|i| PATCH_SPACING_M * i as f64)
        .collect();
    let mut b = grid_builder(&xs, &xs, 0.06, patch_device());
    let lattice = bank_format::SharedLattice::new(&b.triangles, level);
    let w = lattice
        .points
        .iter()
        .map(|&(t, bary)| {
            let tri = b.triangles[t].map(|k| b.positions_m[k as usize]);
            w(core::array::from_fn(|c| {
                bary[0] * tri[0][c] + bary[1] * tri[1][c] + bary[2] * tri[2][c]
            }))
        })
        .collect();
    b.samples = Some(bank_format::ContactSamples {
        level,
        tip_radius_m: 0.003,
        triangle_samples: lattice.triangle_points,
        w,
    });
    b
}

fn grid_bank(xs: &[f64], ys: &[f64], truncation_m: f64, device: DeviceCalibration) -> AlignedBytes {
    let b = grid_builder(xs, ys, truncation_m, device);
    AlignedBytes::new(&b.build().expect("valid fixture bank"))
}

/// The builder of a flat grid bank (z = 0, nodes at `xs` x `ys`, two triangles a square,
/// every pair within `truncation_m` coupled by a smooth SPD kernel), for a test to alter
/// before building.
pub fn grid_builder(
    xs: &[f64],
    ys: &[f64],
    truncation_m: f64,
    device: DeviceCalibration,
) -> BankBuilder {
    let (nx, ny) = (xs.len(), ys.len());
    let mut p = Vec::new();
    for &y in ys {
        for &x in xs {
            p.push([x, y, 0.0]);
        }
    }
    let h = xs
        .windows(2)
        .chain(ys.windows(2))
        .map(|w| w[1] - w[0])
        .fold(0.0, f64::max);
    let id = |i: usize, j: usize| (i + nx * j) as u32;
    let mut triangles = Vec::new();
    for j in 0..ny - 1 {
        for i in 0..nx - 1 {
            let (a, b, c, d) = (id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
            triangles.push([a, b, c]);
            triangles.push([a, c, d]);
        }
    }
    surface_builder(p, triangles, truncation_m, h, device)
}

/// The builder of a bank on any triangulated surface (nodes `p`, m; `triangles` outward
/// counter-clockwise): every triangle edge and every pair of nodes closer than `truncation_m`
/// coupled by [`kernel_block`], grid cells of `cell_m`, a Chebyshev law, for a test to alter before
/// building.
pub fn surface_builder(
    p: Vec<[f64; 3]>,
    triangles: Vec<[u32; 3]>,
    truncation_m: f64,
    cell_m: f64,
    device: DeviceCalibration,
) -> BankBuilder {
    let n = p.len();
    let mut pairs = alloc::collections::BTreeSet::new();
    for t in &triangles {
        for (a, b) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
            pairs.insert((a.min(b) as usize, a.max(b) as usize));
        }
    }
    for k in 0..n {
        for l in k + 1..n {
            let d2: f64 = (0..3)
                .map(|i| (p[k][i] - p[l][i]) * (p[k][i] - p[l][i]))
                .sum();
            if d2 < truncation_m * truncation_m {
                pairs.insert((k, l));
            }
        }
    }
    let couplings = pairs
        .into_iter()
        .map(|(k, l)| (k as u32, l as u32, kernel_block(&p, k, l)))
        .collect();
    BankBuilder {
        c_kk: (0..n).map(|k| kernel_block(&p, k, k)).collect(),
        couplings,
        mesh_ids: (0..n as u32).collect(),
        triangles,
        positions_m: p,
        grid_cell_size_m: cell_m,
        truncation_radius_m: truncation_m,
        scene_id: 7,
        law: TissueLaw::chebyshev(&[2.6, 2.5, -0.1], [0.0, 5.0]).expect("valid law"),
        gravity: None,
        relaxation: None,
        samples: None,
        device,
    }
}

/// Gaussian elimination with partial pivoting in f64: the independent reference the f32 solves
/// are checked against.
///
/// # Panics
/// On an empty or singular system, which would be a bug in the calling test.
#[allow(clippy::needless_range_loop)]
pub fn gauss(mut a: Vec<Vec<f64>>, mut b: Vec<f64>) -> Vec<f64> {
    let n = b.len();
    for c in 0..n {
        let p = (c..n)
            .max_by(|&i, &j| a[i][c].abs().total_cmp(&a[j][c].abs()))
            .expect("a non-empty column");
        a.swap(c, p);
        b.swap(c, p);
        for r in c + 1..n {
            let f = a[r][c] / a[c][c];
            for k in c..n {
                a[r][k] -= f * a[c][k];
            }
            b[r] -= f * b[c];
        }
    }
    let mut x = alloc::vec![0.0; n];
    for r in (0..n).rev() {
        let s: f64 = (r + 1..n).map(|k| a[r][k] * x[k]).sum();
        x[r] = (b[r] - s) / a[r][r];
    }
    x
}

/// `|got - want| / |want|` over all components (f32 results against an f64 reference).
pub fn rel_err(got: &[[f32; 3]], want: &[f64]) -> f64 {
    let num: f64 = got
        .iter()
        .flatten()
        .zip(want)
        .map(|(&a, b)| (f64::from(a) - b) * (f64::from(a) - b))
        .sum();
    let den: f64 = want.iter().map(|b| b * b).sum();
    libm::sqrt(num / den)
}
