//! The reachable region R: the surface nodes the tool tip can touch.
//!
//! The tip moves on `p = fulcrum + insertion * d(pitch, yaw)` with
//! `d = Rot(yaw_axis, yaw) Rot(pitch_axis, pitch) shaft_axis` (the bank's forward kinematics),
//! pitch, yaw and insertion within their ranges: a spherical-shell sector around the fulcrum.
//! A surface node `x` is in R when it is within `tip_radius + margin` of that sector and none of
//! its components is fixed (a fixed component makes `C_kk` singular: no force can be rendered
//! there, and the bank requires SPD blocks).
//!
//! Approximation (a slight over-estimate, never an under-estimate of the exact distance test):
//! with `rho = |x - fulcrum|` and `(pitch, yaw)` the joint angles that point the shaft at `x`
//! (inverse kinematics, exact for `|pitch| < pi/2`), `x` is kept when
//!
//! - `rho` lies in `[ins_min - m, ins_max + m]` (radial test), and
//! - the angular excess `sqrt(dp^2 + (cos(pitch) dy)^2) <= asin(min(1, m / rho))`, where `dp`,
//!   `dy` are how far pitch and yaw fall outside their ranges (0 inside); `cos(pitch)` turns a
//!   yaw step into an arc on the unit sphere.
//!
//! Radial and angular excesses are tested separately, so a node near a corner of the sector
//! (both slightly outside) may be kept although its true distance is up to `sqrt(2) m`.
//!
//! Not modelled: whether the shaft can get to the node without passing through the organ (or
//! other tissue). Nodes on the far side of the organ, seen from the trocar, are therefore kept
//! when they lie in the sector; the scene's insertion range is what keeps R to the near surface.

use crate::vec3::{cross, dot, sub};
use bank_format::DeviceCalibration;

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

    /// Whether point `x` lies within (approximately, see the module notes) `margin` of the
    /// tip's workspace.
    pub fn reaches(&self, x: [f64; 3], margin: f64) -> bool {
        let v = sub(x, self.fulcrum);
        let rho = dot(v, v).sqrt();
        if rho < self.insertion[0] - margin || rho > self.insertion[1] + margin {
            return false;
        }
        if rho <= margin {
            return true;
        }
        let (pitch, yaw) = self.angles(v);
        let outside = |t: f64, r: [f64; 2]| (r[0] - t).max(t - r[1]).max(0.0);
        let dp = outside(pitch, self.pitch);
        let dy = outside(yaw, self.yaw) * pitch.cos();
        (dp * dp + dy * dy).sqrt() <= (margin / rho).min(1.0).asin()
    }
}

/// Rodrigues' rotation of `v` by `angle` about the unit axis `a` (right-handed).
pub fn rotate(a: [f64; 3], angle: f64, v: [f64; 3]) -> [f64; 3] {
    let (s, c) = angle.sin_cos();
    let axv = cross(a, v);
    let adv = dot(a, v);
    std::array::from_fn(|i| v[i] * c + axv[i] * s + a[i] * adv * (1.0 - c))
}

/// The reachable region: the `candidates` (surface nodes) within `tip_radius + margin` of the
/// workspace whose components are all free (`fixed(node)` is true when any component is
/// fixed). Sorted as `candidates` is.
pub fn reachable(
    workspace: &Workspace,
    positions: &[[f64; 3]],
    candidates: &[usize],
    fixed: impl Fn(usize) -> bool,
    tip_radius: f64,
    margin: f64,
) -> Vec<usize> {
    candidates
        .iter()
        .copied()
        .filter(|&k| !fixed(k) && workspace.reaches(positions[k], tip_radius + margin))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A trocar 0.1 m above the plane z = 0, shaft straight down; pitch about x tilts the shaft
    /// towards +-y, yaw about y towards +-x; both within +-atan(0.5), so at margin 0 the tip
    /// reaches the square |x|, |y| <= 0.05 on the plane (exactly on the axes).
    fn down() -> Workspace {
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

    #[test]
    fn inverse_kinematics_inverts_forward() {
        let w = down();
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
    fn flat_box_under_a_vertical_trocar() {
        // Top face of a box, z = 0, nodes every 10 mm from -80 to 80 mm.
        let mut positions = Vec::new();
        for j in -8..=8 {
            for i in -8..=8 {
                positions.push([0.01 * f64::from(i), 0.01 * f64::from(j), 0.0]);
            }
        }
        let at = |x: i32, y: i32| ((y + 8) * 17 + (x + 8)) as usize;
        let all: Vec<usize> = (0..positions.len()).collect();
        let w = down();
        // Margin 1 um (0 would put the nodes exactly on the bounds at the mercy of rounding).
        // By hand: yaw = atan2(-x, 0.1), so |x| <= 50 mm; pitch = asin(y / |p - f|) <=
        // asin(1 / sqrt 5) needs 4 y^2 <= x^2 + 0.01: every |y| <= 50 mm passes, y = 60 mm
        // needs |x| >= 66 mm (excluded by yaw). |p - f| <= 0.1225 m is inside the insertion
        // range. So the 11 x 11 nodes with |x|, |y| <= 50 mm.
        let r0 = reachable(&w, &positions, &all, |_| false, 0.0, 1e-6);
        assert_eq!(r0.len(), 121, "{r0:?}");
        assert!(r0.contains(&at(5, 5)) && r0.contains(&at(-5, 5)));
        assert!(!r0.contains(&at(6, 0)) && !r0.contains(&at(0, 6)) && !r0.contains(&at(6, 6)));
        // Tip 1 mm + margin 2 mm: the nodes at 60 mm on the axes are 0.0768 rad * 0.1166 m =
        // 9 mm outside the sector, still out.
        let r3 = reachable(&w, &positions, &all, |_| false, 0.001, 0.002);
        assert_eq!(r3, r0);
        // A node 1 mm outside the yaw bound comes in with the margin: put one at x = 51 mm.
        let mut more = positions.clone();
        more.push([0.051, 0.0, 0.0]);
        let ids: Vec<usize> = (0..more.len()).collect();
        assert!(reachable(&w, &more, &ids, |_| false, 0.001, 0.002).contains(&(more.len() - 1)));
        assert!(!reachable(&w, &more, &ids, |_| false, 0.0, 1e-6).contains(&(more.len() - 1)));
        // Fixed nodes are never reachable.
        let r = reachable(&w, &positions, &all, |k| k == at(0, 0), 0.001, 0.002);
        assert!(!r.contains(&at(0, 0)) && r.len() + 1 == r3.len());
        // Insertion too short: the plane 0.1 m below is out of reach (radial test).
        let short = Workspace {
            insertion: [0.02, 0.09],
            ..w
        };
        assert!(reachable(&short, &positions, &all, |_| false, 0.001, 0.002).is_empty());
        // Within 3 mm of a shell of radius 0.0971 m: only |p - f| <= 0.1001 m, the centre.
        let just = Workspace {
            insertion: [0.02, 0.0971],
            ..w
        };
        assert_eq!(
            reachable(&just, &positions, &all, |_| false, 0.001, 0.002),
            vec![at(0, 0)]
        );
    }
}
