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

use crate::kinematics::Workspace;
use fem::vec3::{dot, sub};

impl Workspace {
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
        let w = Workspace::straight_down();
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
