//! The firmware's f32 gimbal kinematics against an independent f64 reference (Rodrigues'
//! formula written out here, the convention of `host/haptic/src/reach.rs` and the bank's SPEC:
//! `tip = fulcrum + insertion * Rot(yaw_axis, yaw) Rot(pitch_axis, pitch) shaft_axis`), over a
//! grid of joint values covering the calibrated ranges.

use bank_format::DeviceCalibration;
use firmware::device::{Device, Joints};
use firmware::fixtures::{liver_device, tilted_device};

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Right-handed rotation of `v` by `t` about the unit axis `a`, f64.
fn rotate(a: [f64; 3], t: f64, v: [f64; 3]) -> [f64; 3] {
    let (s, c) = t.sin_cos();
    let axv = cross(a, v);
    let adv = dot(a, v);
    std::array::from_fn(|i| v[i] * c + axv[i] * s + a[i] * adv * (1.0 - c))
}

fn tip_f64(cal: &DeviceCalibration, q: [f64; 3]) -> [f64; 3] {
    let f = |a: [f32; 3]| a.map(f64::from);
    let d = rotate(
        f(cal.yaw_axis),
        q[1],
        rotate(f(cal.pitch_axis), q[0], f(cal.shaft_axis)),
    );
    std::array::from_fn(|i| f64::from(cal.fulcrum_m[i]) + q[2] * d[i])
}

#[test]
fn f32_forward_kinematics_matches_f64_over_the_ranges() {
    const N: usize = 21;
    for (name, cal) in [("liver", liver_device()), ("tilted", tilted_device())] {
        assert_eq!(bank_format::validate_device(&cal), Ok(()));
        let dev = Device::new(&cal);
        let lerp = |j: usize, k: usize| {
            let (lo, hi) = (f64::from(cal.joint_min[j]), f64::from(cal.joint_max[j]));
            lo + (hi - lo) * k as f64 / (N - 1) as f64
        };
        let mut max_err = 0.0f64;
        let mut worst = [0.0; 3];
        for a in 0..N {
            for b in 0..N {
                for c in 0..N {
                    // The f32 joints, and the reference at exactly those values.
                    let q32 = [lerp(0, a) as f32, lerp(1, b) as f32, lerp(2, c) as f32];
                    let q64 = q32.map(f64::from);
                    let got = dev.tip(&Joints::from_array(q32));
                    let want = tip_f64(&cal, q64);
                    let err = (0..3)
                        .map(|i| (f64::from(got[i]) - want[i]).powi(2))
                        .sum::<f64>()
                        .sqrt();
                    if err > max_err {
                        max_err = err;
                        worst = q64;
                    }
                }
            }
        }
        eprintln!(
            "{name}: f32 FK vs f64 over {} poses: max error {max_err:.3e} m at {worst:?}",
            N * N * N
        );
        assert!(max_err < 1e-5, "{name}: {max_err} m");
    }
}

#[test]
fn joints_from_counts_match_f64() {
    // Counts over the liver device's whole ranges: q = home + 2 pi n / (cpr * transmission).
    let cal = liver_device();
    let dev = Device::new(&cal);
    let mut max_err = [0.0f64; 3];
    for n in (-30_000..=30_000).step_by(37) {
        let q = dev.joints([n, -n, n.abs()]).to_array();
        for (j, c) in [n, -n, n.abs()].into_iter().enumerate() {
            let want = f64::from(cal.home_joint[j])
                + 2.0 * std::f64::consts::PI * f64::from(c)
                    / (f64::from(cal.counts_per_rev[j]) * f64::from(cal.transmission[j]));
            max_err[j] = max_err[j].max((f64::from(q[j]) - want).abs());
        }
    }
    eprintln!(
        "joints from counts: max error {:.3e} rad, {:.3e} rad, {:.3e} m",
        max_err[0], max_err[1], max_err[2]
    );
    assert!(max_err[0] < 1e-6 && max_err[1] < 1e-6 && max_err[2] < 1e-7);
}
