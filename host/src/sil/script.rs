//! Scripted hand trajectories for software in the loop, in joint space (pitch rad, yaw rad,
//! insertion m): the hand's grip moves along them and pulls the instrument (see
//! [`super::plant`]). Each script first brings the tip from the home pose to just above the
//! organ surface straight below the trocar, then repeats its cycle:
//!
//! - `press`: down to 6 mm below the surface in 1 s, hold 0.5 s, back up in 1 s;
//! - `slide`: down to 4 mm, sweep pitch +-0.05 rad (about +-5 mm at the tip) while pressed, up;
//! - `strike`: from 10 mm above, 18 mm down in 20 ms (peak 1.35 m/s), hold, retract.
//!
//! Waypoints are joined by smoothstep (`3 s^2 - 2 s^3`) blends, so the hand's speed is
//! continuous.

use anyhow::{Result, bail};
use bank_format::Bank;
use firmware::device::{Device, Joints};

use crate::script::ray_triangle;

/// The scripted hand motions (the demo's names; the plant's hand follows its own version of
/// each, below).
pub use crate::script::Script;

/// Time before the first cycle: rest, then the approach to above the surface, s.
const APPROACH_END_S: f64 = 0.5;
const REST_S: f64 = 0.1;

/// The hand's joint-space path for one script on one bank.
#[derive(Clone, Debug)]
pub struct Trajectory {
    home: [f64; 3],
    /// Insertion at which the tip meets the surface (pitch = yaw = 0).
    surface: f64,
    script: Script,
}

impl Trajectory {
    /// The path of `script` for `bank`'s organ and device. Fails when the straight-down ray
    /// from the trocar misses the reachable surface or the script would leave the joint range.
    pub fn new(bank: &Bank, script: Script) -> Result<Trajectory> {
        let cal = bank.device();
        let home = cal.home_joint.map(f64::from);
        let surface = surface_insertion(bank, [0.0, 0.0])?;
        let t = Trajectory {
            home,
            surface,
            script,
        };
        let (lo, hi) = (f64::from(cal.joint_min[2]), f64::from(cal.joint_max[2]));
        let (deepest, highest) = (t.surface + t.depth_m(), t.surface - 0.01);
        if deepest > hi || highest < lo {
            bail!(
                "the {script:?} script needs insertion {highest:.4}..{deepest:.4} m, outside the \
                 device's range [{lo}, {hi}] m (surface at {surface:.4} m below the trocar)"
            );
        }
        Ok(t)
    }

    /// Insertion at which the tip meets the surface straight below the trocar, m.
    pub fn surface_insertion_m(&self) -> f64 {
        self.surface
    }

    /// Deepest point of the script below the surface, m.
    pub fn depth_m(&self) -> f64 {
        match self.script {
            Script::Press => 0.006,
            Script::Slide => 0.004,
            Script::Strike => 0.008,
        }
    }

    /// The hand's target joints at time `t` (s).
    pub fn at(&self, t: f64) -> [f64; 3] {
        let s0 = self.surface;
        let pose = |pitch: f64, depth: f64| [pitch, 0.0, s0 + depth];
        let start = match self.script {
            Script::Strike => pose(0.0, -0.01),
            _ => pose(0.0, -0.005),
        };
        if t < APPROACH_END_S {
            return blend(&[(REST_S, self.home), (APPROACH_END_S, start)], t);
        }
        let d = self.depth_m();
        let (period, points): (f64, Vec<(f64, [f64; 3])>) = match self.script {
            Script::Press => (
                2.5,
                vec![
                    (0.0, start),
                    (1.0, pose(0.0, d)),
                    (1.5, pose(0.0, d)),
                    (2.5, start),
                ],
            ),
            Script::Slide => (
                3.0,
                vec![
                    (0.0, start),
                    (0.8, pose(0.0, d)),
                    (1.4, pose(0.05, d)),
                    (2.2, pose(-0.05, d)),
                    (2.6, pose(0.0, d)),
                    (3.0, start),
                ],
            ),
            Script::Strike => (
                1.5,
                vec![
                    (0.0, start),
                    (0.5, start),
                    (0.52, pose(0.0, d)),
                    (0.8, pose(0.0, d)),
                    (1.2, start),
                ],
            ),
        };
        blend(&points, (t - APPROACH_END_S).rem_euclid(period))
    }
}

/// Smoothstep between the waypoints around `t` (held before the first and after the last).
fn blend(points: &[(f64, [f64; 3])], t: f64) -> [f64; 3] {
    let Some(&(t_first, first)) = points.first() else {
        return [0.0; 3];
    };
    if t <= t_first {
        return first;
    }
    for w in points.windows(2) {
        let ((t0, a), (t1, b)) = (w[0], w[1]);
        if t <= t1 {
            let s = ((t - t0) / (t1 - t0)).clamp(0.0, 1.0);
            let k = s * s * (3.0 - 2.0 * s);
            return std::array::from_fn(|j| a[j] + k * (b[j] - a[j]));
        }
    }
    points.last().map_or(first, |p| p.1)
}

/// Insertion (m) at which the shaft at `[pitch, yaw]` meets the bank's surface: the nearest
/// hit of the ray from the trocar with the bank's triangles (Moller-Trumbore, f64).
pub fn surface_insertion(bank: &Bank, angles: [f64; 2]) -> Result<f64> {
    let cal = bank.device();
    let dev = Device::new(cal);
    let dir = dev
        .direction(&Joints::from_array([
            angles[0] as f32,
            angles[1] as f32,
            0.0,
        ]))
        .map(f64::from);
    let origin = cal.fulcrum_m.map(f64::from);
    let p = |k: u16| bank.positions()[usize::from(k)].map(f64::from);
    let mut best: Option<f64> = None;
    for tri in bank.triangles() {
        let (a, b, c) = (p(tri[0]), p(tri[1]), p(tri[2]));
        if let Some(s) = ray_triangle(origin, dir, a, b, c) {
            best = Some(best.map_or(s, |x: f64| x.min(s)));
        }
    }
    best.ok_or_else(|| {
        anyhow::anyhow!(
            "the shaft at pitch {} rad, yaw {} rad misses the bank's reachable surface",
            angles[0],
            angles[1]
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blend_is_smooth_and_holds_the_ends() {
        let pts = [(1.0, [0.0; 3]), (2.0, [1.0, 2.0, 4.0])];
        assert_eq!(blend(&pts, 0.0), [0.0; 3]);
        assert_eq!(blend(&pts, 1.5), [0.5, 1.0, 2.0]);
        assert_eq!(blend(&pts, 3.0), [1.0, 2.0, 4.0]);
        // Zero slope at the waypoints.
        let d = blend(&pts, 1.0 + 1e-4)[2] - blend(&pts, 1.0)[2];
        assert!(d < 1e-6, "{d}");
    }
}
