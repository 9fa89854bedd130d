//! The gimbal's kinematics in f64 on the host: forward ([`Workspace::tip`]) and inverse
//! ([`Workspace::joints_for_tip`]) between joint values and the tip, and between joint values
//! and encoder counts ([`counts_for`], the inverse of the firmware's
//! [`firmware::device::Device::joints`]).
//!
//! The tip moves on `p = fulcrum + insertion * d(pitch, yaw)` with
//! `d = Rot(yaw_axis, yaw) Rot(pitch_axis, pitch) shaft_axis`, the bank's forward kinematics
//! (`firmware::device` evaluates the same in f32 on the MCU). Everything on the host that
//! drives a device (the virtual device, the SIL plant, the demo's aiming, the tests) goes
//! through these functions.

use bank_format::DeviceCalibration;
use fem::vec3::{cross, dot, norm, sub};

/// The gimbal's workspace in f64, from a device calibration.
#[derive(Debug, Clone, Copy)]
pub struct Workspace {
    /// Fulcrum, m.
    pub fulcrum: [f64; 3],
    /// Shaft direction at rest (unit).
    pub shaft: [f64; 3],
    /// Pitch axis at rest (unit).
    pub pitch_axis: [f64; 3],
    /// Yaw axis (unit, ground-fixed).
    pub yaw_axis: [f64; 3],
    /// Pitch range, rad.
    pub pitch: [f64; 2],
    /// Yaw range, rad.
    pub yaw: [f64; 2],
    /// Insertion range, m.
    pub insertion: [f64; 2],
}

impl Workspace {
    /// From the bank's calibration record.
    pub fn from_device(d: &DeviceCalibration) -> Workspace {
        let f = |a: [f32; 3]| a.map(f64::from);
        Workspace {
            fulcrum: f(d.fulcrum_m),
            shaft: f(d.shaft_axis),
            pitch_axis: f(d.pitch_axis),
            yaw_axis: f(d.yaw_axis),
            pitch: [d.joint_min[0].into(), d.joint_max[0].into()],
            yaw: [d.joint_min[1].into(), d.joint_max[1].into()],
            insertion: [d.joint_min[2].into(), d.joint_max[2].into()],
        }
    }

    /// Forward kinematics: the tip for joint values (pitch, yaw, insertion).
    pub fn tip(&self, pitch: f64, yaw: f64, insertion: f64) -> [f64; 3] {
        let d = rotate(
            self.yaw_axis,
            yaw,
            rotate(self.pitch_axis, pitch, self.shaft),
        );
        std::array::from_fn(|i| self.fulcrum[i] + insertion * d[i])
    }

    /// Inverse kinematics of a direction: `(pitch, yaw)` with `|pitch| <= pi/2` that point the
    /// shaft along `v` (any length > 0).
    pub fn angles(&self, v: [f64; 3]) -> (f64, f64) {
        // Rot(p, t) s = cos t s + sin t (p x s); its component along the yaw axis is what
        // yaw preserves.
        let w = cross(self.pitch_axis, self.shaft);
        let sign = dot(w, self.yaw_axis).signum();
        let n = dot(v, v).sqrt();
        let pitch = (sign * dot(v, self.yaw_axis) / n).clamp(-1.0, 1.0).asin();
        // In the plane orthogonal to the yaw axis, Rot(y, phi) s = cos phi s + sin phi (y x s).
        let yaw = dot(v, cross(self.yaw_axis, self.shaft)).atan2(dot(v, self.shaft));
        (pitch, yaw)
    }

    /// Inverse kinematics of a tip position: the joint values `[pitch, yaw, insertion]`
    /// (`|pitch| <= pi/2`) that put the tip at `tip` (m).
    pub fn joints_for_tip(&self, tip: [f64; 3]) -> [f64; 3] {
        let v = sub(tip, self.fulcrum);
        let (pitch, yaw) = self.angles(v);
        [pitch, yaw, norm(v)]
    }
}

#[cfg(test)]
impl Workspace {
    /// Test fixture: a trocar 0.1 m above the plane z = 0, shaft straight down; pitch about x
    /// tilts the shaft towards +-y, yaw about y towards +-x; both within +-atan(0.5), so at
    /// margin 0 the tip reaches the square |x|, |y| <= 0.05 on the plane (exactly on the axes).
    pub(crate) fn straight_down() -> Workspace {
        let a = 0.5f64.atan();
        Workspace {
            fulcrum: [0.0, 0.0, 0.1],
            shaft: [0.0, 0.0, -1.0],
            pitch_axis: [1.0, 0.0, 0.0],
            yaw_axis: [0.0, 1.0, 0.0],
            pitch: [-a, a],
            yaw: [-a, a],
            insertion: [0.05, 0.2],
        }
    }
}

/// Rodrigues' rotation of `v` by `angle` about the unit axis `a` (right-handed).
pub fn rotate(a: [f64; 3], angle: f64, v: [f64; 3]) -> [f64; 3] {
    let (s, c) = angle.sin_cos();
    let axv = cross(a, v);
    let adv = dot(a, v);
    std::array::from_fn(|i| v[i] * c + axv[i] * s + a[i] * adv * (1.0 - c))
}

/// Encoder counts for joint values `q` (inverse of the firmware's counts -> joints map).
pub fn counts_for(cal: &DeviceCalibration, q: [f64; 3]) -> [i32; 3] {
    std::array::from_fn(|i| {
        let per_unit = f64::from(cal.counts_per_rev[i]) * f64::from(cal.transmission[i])
            / std::f64::consts::TAU;
        ((q[i] - f64::from(cal.home_joint[i])) * per_unit).round() as i32
    })
}

/// `q` clamped into the calibration's joint ranges.
pub fn clamp_joints(cal: &DeviceCalibration, q: [f64; 3]) -> [f64; 3] {
    std::array::from_fn(|i| q[i].clamp(cal.joint_min[i].into(), cal.joint_max[i].into()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use firmware::device::Device;
    use std::path::Path;

    #[test]
    fn inverse_kinematics_inverts_forward() {
        let w = Workspace::straight_down();
        for (p, y) in [(0.0, 0.0), (0.3, -0.2), (-0.4, 0.4), (0.1, 0.45)] {
            let t = w.tip(p, y, 0.12);
            let (p2, y2) = w.angles(sub(t, w.fulcrum));
            assert!(
                (p - p2).abs() < 1e-12 && (y - y2).abs() < 1e-12,
                "{p} {y}: {p2} {y2}"
            );
        }
    }

    #[test]
    fn tip_inverse_kinematics_inverts_forward() {
        let w = Workspace::straight_down();
        for q in [[0.0, 0.0, 0.1], [0.3, -0.2, 0.12], [-0.4, 0.4, 0.07]] {
            let back = w.joints_for_tip(w.tip(q[0], q[1], q[2]));
            for i in 0..3 {
                assert!((back[i] - q[i]).abs() < 1e-12, "{q:?}: {back:?}");
            }
        }
    }

    #[test]
    fn counts_invert_the_firmware_joint_map() {
        let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/liver.toml");
        let cal = crate::scene::Scene::load(&scene).unwrap().device;
        let dev = Device::new(&cal);
        for q in [[0.0, 0.0, 0.03], [0.2, -0.3, 0.1], [-0.34, 0.34, 0.139]] {
            let back = dev.joints(counts_for(&cal, q)).to_array();
            for i in 0..3 {
                let step = f64::from(dev.joint_per_count()[i].abs());
                assert!(
                    (f64::from(back[i]) - q[i]).abs() <= 0.5 * step + 1e-6,
                    "{q:?} {back:?}"
                );
            }
        }
    }
}
