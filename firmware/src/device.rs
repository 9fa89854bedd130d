//! The laparoscopic gimbal (paper, section 2): pitch and yaw about the fulcrum (the trocar),
//! insertion along the shaft, roll passive. Everything here is `f32`, fixed-size, heap-free and
//! panic-free; it follows the bank's [`DeviceCalibration`] record (`bank-format/SPEC.md`,
//! "device") and the host's f64 model (`host/haptic/src/reach.rs`).
//!
//! - Joints are indexed 0 = pitch (rad), 1 = yaw (rad), 2 = insertion (m, fulcrum to tip).
//! - Encoder counts `n` give `q = home + 2 pi n / (counts_per_rev * transmission)`; for
//!   insertion the transmission is in motor rad per metre, so the same formula gives metres.
//! - Forward kinematics: `tip = fulcrum + insertion * d`,
//!   `d = Rot(yaw_axis, yaw) Rot(pitch_axis, pitch) shaft_axis`, `Rot(a, t)` the right-handed
//!   Rodrigues rotation by `t` about `a` (yaw is the outer, ground-fixed axis; pitch the inner
//!   one, given at rest). The axes are used exactly as stored (not re-normalised), like the host.
//! - Jacobian `J[r][c] = d tip_r / d q_c` (row-major, columns pitch, yaw, insertion), analytic.
//!
//! **Force sign convention.** [`Device::joint_efforts`] takes `force_on_tool`: the force the
//! tissue exerts on the tool tip, N, scene frame. That is the *negative* of the sum of the contact
//! forces `f_S` the solve returns (those act on the tissue, as in telemetry's
//! `Contact::force_n`). The motors produce `tau = J^T force_on_tool`, so the device pushes the
//! tool (and the hand) exactly as the tissue would: back out of the tissue. By virtual work,
//! `tau . dq = force_on_tool . (J dq)`.
//!
//! Motor currents: `i = tau / (transmission * torque_constant)` per axis (the transmission's
//! sign is the motor's direction), then clamped to `current_limit_a`.

use bank_format::DeviceCalibration;
use core::f32::consts::PI;

use crate::vec3::{cross, dot};

/// Joint index of pitch (rad).
pub const PITCH: usize = 0;
/// Joint index of yaw (rad).
pub const YAW: usize = 1;
/// Joint index of insertion (m).
pub const INSERTION: usize = 2;

/// Joint values of the gimbal.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Joints {
    /// Pitch, rad (inner gimbal axis).
    pub pitch: f32,
    /// Yaw, rad (outer, ground-fixed gimbal axis).
    pub yaw: f32,
    /// Insertion, m: distance from the fulcrum to the tip along the shaft.
    pub insertion: f32,
}

impl Joints {
    /// From `[pitch, yaw, insertion]`.
    pub const fn from_array(q: [f32; 3]) -> Joints {
        Joints {
            pitch: q[PITCH],
            yaw: q[YAW],
            insertion: q[INSERTION],
        }
    }

    /// As `[pitch, yaw, insertion]`.
    pub const fn to_array(self) -> [f32; 3] {
        [self.pitch, self.yaw, self.insertion]
    }

    /// Whether all three values are finite.
    pub fn is_finite(&self) -> bool {
        self.pitch.is_finite() && self.yaw.is_finite() && self.insertion.is_finite()
    }
}

/// Motor currents for one tick: what the loop asked for and what may be applied.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Currents {
    /// `tau / (transmission * Kt)` before clamping, A (may be non-finite if the input was).
    pub requested_a: [f32; 3],
    /// Clamped to `[-limit, limit]` per motor, A; a non-finite request gives 0.
    pub applied_a: [f32; 3],
    /// Which motors were clamped (or zeroed because their request was not finite).
    pub clamped: [bool; 3],
}

/// The gimbal model, precomputed from a [`DeviceCalibration`].
///
/// Built from a calibration that passed [`bank_format::validate_device`] (every bank the reader
/// accepts did); with an unvalidated record nothing panics, but results may be non-finite.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Device {
    cal: DeviceCalibration,
    /// Joint units per encoder count: `2 pi / (counts_per_rev * transmission)`.
    per_count: [f32; 3],
    /// Amperes per unit joint effort: `1 / (transmission * Kt)`.
    amps_per_effort: [f32; 3],
}

impl Device {
    /// The model of a calibration record.
    pub fn new(cal: &DeviceCalibration) -> Device {
        let per_count = core::array::from_fn(|j| {
            let cpr = cal.counts_per_rev.get(j).copied().unwrap_or(1) as f32;
            let t = cal.transmission.get(j).copied().unwrap_or(1.0);
            2.0 * PI / (cpr * t)
        });
        let amps_per_effort = core::array::from_fn(|j| {
            let t = cal.transmission.get(j).copied().unwrap_or(1.0);
            let kt = cal.torque_constant_nm_per_a.get(j).copied().unwrap_or(1.0);
            1.0 / (t * kt)
        });
        Device {
            cal: *cal,
            per_count,
            amps_per_effort,
        }
    }

    /// The calibration record this model was built from.
    pub fn calibration(&self) -> &DeviceCalibration {
        &self.cal
    }

    /// Joint units (rad or m) per encoder count, per joint; signed like the transmission.
    pub fn joint_per_count(&self) -> [f32; 3] {
        self.per_count
    }

    /// Joint values from encoder counts: `q = home + counts * 2 pi / (counts_per_rev *
    /// transmission)`.
    pub fn joints(&self, counts: [i32; 3]) -> Joints {
        let mut q = self.cal.home_joint;
        for ((q, &n), &k) in q.iter_mut().zip(&counts).zip(&self.per_count) {
            *q += n as f32 * k;
        }
        Joints::from_array(q)
    }

    /// Unit shaft direction `d = Rot(yaw_axis, yaw) Rot(pitch_axis, pitch) shaft_axis`.
    pub fn direction(&self, q: &Joints) -> [f32; 3] {
        let (sp, cp) = sin_cos(q.pitch);
        let (sy, cy) = sin_cos(q.yaw);
        let u = rotate(self.cal.pitch_axis, sp, cp, self.cal.shaft_axis);
        rotate(self.cal.yaw_axis, sy, cy, u)
    }

    /// Forward kinematics: the tool tip, m, scene frame.
    pub fn tip(&self, q: &Joints) -> [f32; 3] {
        let d = self.direction(q);
        core::array::from_fn(|i| self.fulcrum(i) + q.insertion * d.get(i).copied().unwrap_or(0.0))
    }

    /// The Jacobian `J[r][c] = d tip_r / d q_c` (columns pitch, yaw, insertion; rows x, y, z).
    pub fn jacobian(&self, q: &Joints) -> [[f32; 3]; 3] {
        self.tip_and_jacobian(q).1
    }

    /// Tip and Jacobian together (one set of sines and cosines).
    ///
    /// With `u = Rot(p, pitch) s` and `d = Rot(y, yaw) u`: `d tip / d pitch = insertion *
    /// Rot(y, yaw) Rot'(p, pitch) s`, `d tip / d yaw = insertion * Rot'(y, yaw) u`,
    /// `d tip / d insertion = d`, where `Rot'(a, t) v = -sin t v + cos t (a x v) + sin t a (a.v)`
    /// is the exact derivative of Rodrigues' formula (equal to `a x Rot(a, t) v` for a unit `a`).
    pub fn tip_and_jacobian(&self, q: &Joints) -> ([f32; 3], [[f32; 3]; 3]) {
        let (sp, cp) = sin_cos(q.pitch);
        let (sy, cy) = sin_cos(q.yaw);
        let (p, y, s) = (self.cal.pitch_axis, self.cal.yaw_axis, self.cal.shaft_axis);
        let u = rotate(p, sp, cp, s);
        let d = rotate(y, sy, cy, u);
        let dd_pitch = rotate(y, sy, cy, rotate_derivative(p, sp, cp, s));
        let dd_yaw = rotate_derivative(y, sy, cy, u);
        let tip = core::array::from_fn(|i| self.fulcrum(i) + q.insertion * at(d, i));
        let jac = core::array::from_fn(|r| {
            [
                q.insertion * at(dd_pitch, r),
                q.insertion * at(dd_yaw, r),
                at(d, r),
            ]
        });
        (tip, jac)
    }

    /// Joint efforts `tau = J^T force_on_tool` (N m for pitch and yaw, N for insertion).
    /// `force_on_tool` is the force the tissue exerts on the tool (see the module notes for the
    /// sign): the motors then push the tool back out of the tissue.
    pub fn joint_efforts(&self, q: &Joints, force_on_tool: [f32; 3]) -> [f32; 3] {
        transpose_mul(&self.jacobian(q), force_on_tool)
    }

    /// `force` scaled down (direction kept) to at most `max_force_n` in magnitude; a non-finite
    /// force is returned as is (the safety supervisor faults on it). A finite force whose
    /// squared norm overflows f32 (above about 1.8e19 N) is scaled through its largest
    /// component, so it is capped like any other.
    pub fn limit_force(&self, force: [f32; 3]) -> [f32; 3] {
        let max = self.cal.max_force_n;
        let n2 = dot(force, force);
        if n2.is_finite() {
            let n = crate::vec3::sqrt(n2);
            return if n > max {
                let k = max / n;
                force.map(|f| f * k)
            } else {
                force
            };
        }
        // Overflowed, or not finite: `max / |f|` as `(max / m) / |f / m|`, m the largest
        // component's magnitude (comparisons, not `f32::max`: a libm call on the M4F).
        let mut m = 0.0f32;
        for f in force {
            let a = if f < 0.0 { -f } else { f };
            if a > m || a.is_nan() {
                m = a;
            }
        }
        if !m.is_finite() {
            return force;
        }
        let s = force.map(|f| f / m);
        let k = (max / m) / crate::vec3::sqrt(dot(s, s));
        force.map(|f| f * k)
    }

    /// Unclamped motor currents for joint efforts: `i = tau / (transmission * Kt)`, A.
    pub fn requested_currents(&self, tau: [f32; 3]) -> [f32; 3] {
        core::array::from_fn(|j| at(tau, j) * at(self.amps_per_effort, j))
    }

    /// Clamp currents to `[-current_limit_a, current_limit_a]` per motor and report which were
    /// clamped. A non-finite request gives 0 A and counts as clamped.
    pub fn clamp_currents(&self, requested_a: [f32; 3]) -> Currents {
        let mut applied_a = [0.0; 3];
        let mut clamped = [false; 3];
        for (((a, c), &r), &lim) in applied_a
            .iter_mut()
            .zip(clamped.iter_mut())
            .zip(&requested_a)
            .zip(&self.cal.current_limit_a)
        {
            (*a, *c) = clamp_symmetric(r, lim);
        }
        Currents {
            requested_a,
            applied_a,
            clamped,
        }
    }

    /// The whole output stage for a tick: `tau = J^T force_on_tool`, currents, clamp.
    /// `force_on_tool` is used as given (call [`Device::limit_force`] first to cap it).
    pub fn currents_for_force(&self, q: &Joints, force_on_tool: [f32; 3]) -> Currents {
        self.clamp_currents(self.requested_currents(self.joint_efforts(q, force_on_tool)))
    }

    fn fulcrum(&self, i: usize) -> f32 {
        at(self.cal.fulcrum_m, i)
    }
}

/// `x` clamped to `[-lim, lim]` and whether it was changed; NaN gives `(0, true)`. Never panics
/// (unlike `f32::clamp` with a NaN or negative bound).
pub fn clamp_symmetric(x: f32, lim: f32) -> (f32, bool) {
    let lim = if lim >= 0.0 { lim } else { 0.0 };
    if x.is_nan() {
        (0.0, true)
    } else if x > lim {
        (lim, true)
    } else if x < -lim {
        (-lim, true)
    } else {
        (x, false)
    }
}

/// `J^T v` for a row-major 3x3 `J`.
pub fn transpose_mul(j: &[[f32; 3]; 3], v: [f32; 3]) -> [f32; 3] {
    let mut out = [0.0; 3];
    for (row, &vr) in j.iter().zip(&v) {
        for (o, &jrc) in out.iter_mut().zip(row) {
            *o += jrc * vr;
        }
    }
    out
}

/// `(sin t, cos t)` in f32, written out: the same bits natively and on the MCU (plain f32
/// operations, no platform `sinf`). `libm::sincosf` is as portable but evaluates its kernels
/// in f64, which the Cortex-M4's single-precision FPU does in software: 2,118 instructions a
/// call against 48 here; micromath's `sin_cos` costs 47 but is off by up to 1.1e-3, 0.1 mm at
/// the tip at 10 cm insertion (`docs/firmware-loop.md`, "The card's crates",
/// `firmware/qemu/src/bin/mathbench.rs`).
///
/// `t = k pi/2 + r`, `|r| <= pi/4` (`k` rounded, `pi/2` split in three parts, Cody-Waite, so the
/// reduction is exact to f32 rounding for the joint angles, `|t| <= pi`); Taylor series of
/// `sin r` to `r^9` and `cos r` to `r^10` (truncation below 2e-9), then the quadrant of `k`.
/// NaN or infinite `t` gives NaN (the supervisor faults on it).
pub fn sin_cos(t: f32) -> (f32, f32) {
    // pi/2 = P1 + P2 + P3; P1 has 8 significant bits, so k P1 is exact for |k| < 2^16.
    const P1: f32 = 1.570_312_5;
    const P2: f32 = 4.837_513e-4;
    const P3: f32 = 7.549_79e-8;
    if !t.is_finite() {
        return (f32::NAN, f32::NAN);
    }
    let q = t * core::f32::consts::FRAC_2_PI;
    // Round half away from zero; `as` saturates (|t| > 3e9 rad is no joint angle).
    let k = (q + if q >= 0.0 { 0.5 } else { -0.5 }) as i32;
    let kf = k as f32;
    let r = ((t - kf * P1) - kf * P2) - kf * P3;
    let r2 = r * r;
    let s = r + r * r2 * (-1.0 / 6.0 + r2 * (1.0 / 120.0 + r2 * (-1.0 / 5040.0 + r2 / 362_880.0)));
    let c = 1.0
        + r2 * (-0.5
            + r2 * (1.0 / 24.0 + r2 * (-1.0 / 720.0 + r2 * (1.0 / 40_320.0 - r2 / 3_628_800.0))));
    match k & 3 {
        0 => (s, c),
        1 => (c, -s),
        2 => (-s, -c),
        _ => (-c, s),
    }
}

fn at(v: [f32; 3], i: usize) -> f32 {
    v.get(i).copied().unwrap_or(0.0)
}

/// Rodrigues: `v cos t + (a x v) sin t + a (a.v)(1 - cos t)`, given `sin t`, `cos t`.
fn rotate(a: [f32; 3], s: f32, c: f32, v: [f32; 3]) -> [f32; 3] {
    let axv = cross(a, v);
    let adv = dot(a, v) * (1.0 - c);
    [
        v[0] * c + axv[0] * s + a[0] * adv,
        v[1] * c + axv[1] * s + a[1] * adv,
        v[2] * c + axv[2] * s + a[2] * adv,
    ]
}

/// d/dt of [`rotate`]: `-v sin t + (a x v) cos t + a (a.v) sin t`.
fn rotate_derivative(a: [f32; 3], s: f32, c: f32, v: [f32; 3]) -> [f32; 3] {
    let axv = cross(a, v);
    let adv = dot(a, v) * s;
    [
        -v[0] * s + axv[0] * c + a[0] * adv,
        -v[1] * s + axv[1] * c + a[1] * adv,
        -v[2] * s + axv[2] * c + a[2] * adv,
    ]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fixtures::{liver_device, tilted_device};

    fn close(a: [f32; 3], b: [f32; 3], tol: f32) -> bool {
        a.iter().zip(&b).all(|(x, y)| (x - y).abs() <= tol)
    }

    /// The f32 `sin_cos` against libm's f64 `sin` and `cos` over two turns, densely: within
    /// 1.2e-7 (measured: 8.3e-8, about 1.4 ulp of 1), and exact at 0.
    #[test]
    fn sin_cos_matches_f64_over_the_joint_range() {
        let mut worst = 0.0f64;
        for i in -200_000..=200_000 {
            let t = i as f32 * (2.0 * PI / 200_000.0);
            let (s, c) = sin_cos(t);
            let (ws, wc) = (libm::sin(f64::from(t)), libm::cos(f64::from(t)));
            worst = worst
                .max((f64::from(s) - ws).abs())
                .max((f64::from(c) - wc).abs());
        }
        assert!(worst < 1.2e-7, "{worst}");
        assert_eq!(sin_cos(0.0), (0.0, 1.0));
        let (s, c) = sin_cos(f32::NAN);
        assert!(s.is_nan() && c.is_nan());
        assert!(sin_cos(f32::INFINITY).0.is_nan());
    }

    #[test]
    fn calibrations_are_valid() {
        assert_eq!(bank_format::validate_device(&liver_device()), Ok(()));
        assert_eq!(bank_format::validate_device(&tilted_device()), Ok(()));
    }

    #[test]
    fn rest_pose_is_along_the_shaft() {
        for cal in [liver_device(), tilted_device()] {
            let dev = Device::new(&cal);
            let q = Joints::from_array([0.0, 0.0, 0.1]);
            let want = core::array::from_fn(|i| cal.fulcrum_m[i] + 0.1 * cal.shaft_axis[i]);
            assert!(close(dev.tip(&q), want, 1e-7), "{:?}", dev.tip(&q));
        }
    }

    #[test]
    fn hand_computed_poses() {
        let dev = Device::new(&liver_device());
        // Pitch about +x by +pi/2 turns -z into +y: Rot(x, t)(0, 0, -1) = (0, sin t, -cos t).
        let q = Joints::from_array([PI / 2.0, 0.0, 0.1]);
        assert!(
            close(dev.tip(&q), [0.0, 0.1, 0.16], 1e-7),
            "{:?}",
            dev.tip(&q)
        );
        // Yaw about +y by +pi/2 turns -z into -x: Rot(y, t)(0, 0, -1) = (-sin t, 0, -cos t).
        let q = Joints::from_array([0.0, PI / 2.0, 0.1]);
        assert!(close(dev.tip(&q), [-0.1, 0.0, 0.16], 1e-7));
        // Both: pitch first (inner), then yaw: (0, sin p, -cos p) -> yaw mixes x and z.
        let (p, y, r) = (0.3f32, -0.2f32, 0.12f32);
        let want = [
            -r * p.cos() * y.sin(),
            r * p.sin(),
            0.16 - r * p.cos() * y.cos(),
        ];
        let got = dev.tip(&Joints::from_array([p, y, r]));
        assert!(close(got, want, 2e-7), "{got:?} vs {want:?}");
    }

    #[test]
    fn joints_from_counts() {
        let cal = liver_device();
        let dev = Device::new(&cal);
        assert_eq!(dev.joints([0, 0, 0]), Joints::from_array(cal.home_joint));
        // One motor revolution is 1/12 rad of pitch and yaw, 1/400 rad -> 2 pi / 400 m insertion.
        let q = dev.joints([4096, -4096, 4096]);
        assert!((q.pitch - 2.0 * PI / 12.0).abs() < 1e-6);
        assert!((q.yaw + 2.0 * PI / 12.0).abs() < 1e-6);
        assert!((q.insertion - (0.03 + 2.0 * PI / 400.0)).abs() < 1e-7);
        // A negative transmission reverses the direction.
        let cal = tilted_device();
        let dev = Device::new(&cal);
        let q = dev.joints([2000, 0, -500]);
        assert!((q.pitch - (0.1 - 2.0 * PI / 8.0)).abs() < 1e-6);
        assert!((q.insertion - (0.05 + 2.0 * PI / 250.0)).abs() < 1e-6);
    }

    fn poses() -> [[f32; 3]; 6] {
        [
            [0.0, 0.0, 0.1],
            [0.3, -0.2, 0.12],
            [-0.35, 0.35, 0.03],
            [1.0, 2.0, 0.15],
            [-1.1, -2.4, 0.07],
            [0.7, 0.05, 0.19],
        ]
    }

    #[test]
    fn jacobian_matches_central_differences() {
        for cal in [liver_device(), tilted_device()] {
            let dev = Device::new(&cal);
            for q0 in poses() {
                let jac = dev.jacobian(&Joints::from_array(q0));
                let scale = jac.iter().flatten().fold(0.0f32, |m, v| m.max(v.abs()));
                for c in 0..3 {
                    // f32 central differences: the step balances truncation and rounding.
                    let h = 1e-2;
                    let mut qp = q0;
                    let mut qm = q0;
                    qp[c] += h;
                    qm[c] -= h;
                    let tp = dev.tip(&Joints::from_array(qp));
                    let tm = dev.tip(&Joints::from_array(qm));
                    for r in 0..3 {
                        let fd = (tp[r] - tm[r]) / (2.0 * h);
                        let err = (fd - jac[r][c]).abs();
                        assert!(
                            err <= 1e-3 * scale,
                            "pose {q0:?} J[{r}][{c}] = {} vs fd {fd}",
                            jac[r][c]
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn efforts_do_the_same_virtual_work() {
        let forces = [[1.0, -2.0, 0.5], [0.0, 0.0, 3.0], [-0.7, 0.2, -1.5]];
        for cal in [liver_device(), tilted_device()] {
            let dev = Device::new(&cal);
            for q0 in poses() {
                let q = Joints::from_array(q0);
                let jac = dev.jacobian(&q);
                for f in forces {
                    let tau = dev.joint_efforts(&q, f);
                    for dq in [
                        [1e-3, 0.0, 0.0],
                        [0.0, 1e-3, 0.0],
                        [0.0, 0.0, 1e-3],
                        [2e-3, -1e-3, 5e-4],
                    ] {
                        let dtip: [f32; 3] = core::array::from_fn(|r| {
                            jac[r][0] * dq[0] + jac[r][1] * dq[1] + jac[r][2] * dq[2]
                        });
                        let w_joint = dot(tau, dq);
                        let w_tip = dot(f, dtip);
                        assert!((w_joint - w_tip).abs() <= 1e-6 * (1.0 + w_tip.abs()));
                    }
                }
            }
        }
    }

    #[test]
    fn a_push_out_of_the_tissue_drives_insertion_back() {
        // Tissue below the liver trocar pushes the tool up (+z): insertion effort is negative
        // (pull the tool out), and so is the insertion current for a positive transmission.
        let dev = Device::new(&liver_device());
        let q = Joints::from_array([0.0, 0.0, 0.1]);
        let tau = dev.joint_efforts(&q, [0.0, 0.0, 1.0]);
        assert!(close(tau, [0.0, 0.0, -1.0], 1e-7), "{tau:?}");
        let i = dev.currents_for_force(&q, [0.0, 0.0, 1.0]);
        assert!((i.applied_a[2] + 1.0 / (400.0 * 0.025)).abs() < 1e-7);
        // A sideways push (+y) at the tip: pitch about +x; d tip / d pitch = 0.1 * (0, 1, 0).
        let tau = dev.joint_efforts(&q, [0.0, 2.0, 0.0]);
        assert!(close(tau, [0.2, 0.0, 0.0], 1e-7), "{tau:?}");
    }

    #[test]
    fn currents_and_clamps() {
        let cal = tilted_device();
        let dev = Device::new(&cal);
        let tau = [0.01, -0.05, 0.3];
        let i = dev.requested_currents(tau);
        for j in 0..3 {
            let want = tau[j] / (cal.transmission[j] * cal.torque_constant_nm_per_a[j]);
            assert!((i[j] - want).abs() <= 1e-6 * want.abs());
        }
        let c = dev.clamp_currents([1.0, -3.5, 2.6]);
        assert_eq!(c.applied_a, [1.0, -3.0, 2.5]);
        assert_eq!(c.clamped, [false, true, true]);
        assert_eq!(c.requested_a, [1.0, -3.5, 2.6]);
        let c = dev.clamp_currents([f32::NAN, f32::INFINITY, f32::NEG_INFINITY]);
        assert_eq!(c.applied_a, [0.0, 3.0, -2.5]);
        assert_eq!(c.clamped, [true; 3]);
        assert_eq!(clamp_symmetric(1.0, f32::NAN), (0.0, true));
        assert_eq!(clamp_symmetric(-1.0, -2.0), (0.0, true));
    }

    #[test]
    fn force_limit_keeps_direction() {
        let dev = Device::new(&liver_device());
        assert_eq!(dev.limit_force([0.0, 3.0, 4.0]), [0.0, 3.0, 4.0]);
        let f = dev.limit_force([0.0, 6.0, 8.0]);
        assert!(close(f, [0.0, 3.0, 4.0], 1e-6));
        assert!(dev.limit_force([f32::NAN, 0.0, 0.0])[0].is_nan());
        // Finite forces whose squared norm overflows f32 are capped too, direction kept.
        let max = dev.cal.max_force_n;
        let f = dev.limit_force([0.0, 3.0e19, -4.0e19]);
        let want = [0.0, 0.6 * max, -0.8 * max];
        assert!(
            f.iter()
                .zip(&want)
                .all(|(a, b)| (a - b).abs() <= 1e-6 * max),
            "{f:?}"
        );
        let f = dev.limit_force([f32::MAX, -f32::MAX, f32::MAX]);
        let third = max / 3.0f32.sqrt();
        let want = [third, -third, third];
        assert!(
            f.iter()
                .zip(&want)
                .all(|(a, b)| (a - b).abs() <= 1e-6 * max),
            "{f:?}"
        );
        assert!(dev.limit_force([f32::INFINITY, 1.0, 0.0])[0].is_infinite());
        assert!(dev.limit_force([1.0e30, f32::NAN, 0.0])[1].is_nan());
    }
}
