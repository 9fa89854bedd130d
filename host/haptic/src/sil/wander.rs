//! `wander`: a seeded random hand path near and into the organ's surface, for searching the
//! tick's worst case on paths the fixed scripts do not take (`host sil --script wander --seed
//! N`, `host bench sil`).
//!
//! The path is a chain of moves in joint space drawn from [`SplitMix64`] seeded with `seed`,
//! so a seed gives the same path on every machine. It starts where the scripts' approach ends
//! (5 mm above the surface straight below the trocar) and draws, one after the other:
//!
//! - a **press** in place, to 0.5..6 mm below the surface;
//! - a **slide** to a point up to 0.08 rad away (about 8 mm at the tip), 0.5..6 mm deep;
//! - a **leave**, up to 0.5..5 mm above the surface, with a small lateral drift;
//! - a **re-entry** elsewhere: to a point up to 0.1 rad away, from 4 mm above to 6 mm below;
//!
//! each followed, two times in five, by a **hold** of 0.05..0.5 s (a held contact when the
//! move ended below the surface). Pitch and yaw stay within [`ANGLE_RAD`] of the trocar's axis
//! and the insertion within the device's range; the depth is measured along the shaft from the
//! bank's surface under the current angles ([`surface_insertion`]), so the path follows the
//! organ's shape. A move whose path leaves the angles, the insertion range or the bank's
//! reachable surface is drawn again.
//!
//! Each move is blended by smoothstep over a time chosen from its own speed, drawn in
//! 0.1..1 of the limit: the hand's tip speed stays below [`TIP_SPEED_M_S`] (0.45 m/s, under
//! the shipped scene's 1 m/s overspeed threshold; on a bank with a lower threshold, 45% of
//! it) and each joint's below 45% of the bank's joint-speed threshold, checked on the samples
//! the hand follows (every [`SAMPLE_S`], linearly interpolated in between), so the device,
//! which follows the hand through a stiff grip, stays clear of `Overspeed` and `JointLimit`.

use anyhow::Result;
use bank_format::Bank;

use super::script::surface_insertion;
use crate::kinematics::Workspace;
use crate::rng::SplitMix64;

/// The hand's top tip speed, m/s (on a bank whose overspeed threshold is at least 1 m/s).
pub const TIP_SPEED_M_S: f64 = 0.45;
/// The hand's speeds as a share of the bank's overspeed thresholds, at most.
const SPEED_SHARE: f64 = 0.45;
/// Largest pitch and yaw, rad.
pub const ANGLE_RAD: f64 = 0.15;
/// Time between the samples of the path, s.
pub const SAMPLE_S: f64 = 0.005;
/// Height above the surface where the path starts (the scripts' approach ends there), m.
const START_ABOVE_M: f64 = 0.005;
/// Draws of a move before giving up on a seed (a bank whose reachable surface is too small).
const MAX_DRAWS: usize = 1_000;

/// A point of the path: pitch and yaw (rad) and the depth below the surface along the shaft
/// (m; negative above it).
#[derive(Clone, Copy, Debug, PartialEq)]
struct Pose {
    angles: [f64; 2],
    depth_m: f64,
}

/// The hand's path for `seed` on `bank`, `seconds` long: samples `(t_s, [pitch, yaw,
/// insertion])` from `t_s` = 0, every [`SAMPLE_S`] while moving (a hold is its two ends).
/// Fails when the bank's reachable surface is missed straight below the trocar or no move can
/// be drawn within the limits.
pub fn path(bank: &Bank, seed: u64, seconds: f64) -> Result<Vec<(f64, [f64; 3])>> {
    let cal = bank.device();
    let ws = Workspace::from_device(cal);
    let tip_speed = TIP_SPEED_M_S.min(SPEED_SHARE * f64::from(cal.max_tip_speed_m_s));
    let joint_speed = cal.max_joint_speed.map(|v| SPEED_SHARE * f64::from(v));
    let limits = Limits {
        ws,
        tip_speed,
        joint_speed,
        angle: ANGLE_RAD
            .min(ws.pitch[1])
            .min(-ws.pitch[0])
            .min(ws.yaw[1])
            .min(-ws.yaw[0]),
    };
    let mut rng = SplitMix64::new(seed);
    let mut at = Pose {
        angles: [0.0, 0.0],
        depth_m: -START_ABOVE_M,
    };
    let first = joints(bank, &limits, at).ok_or_else(|| {
        anyhow::anyhow!(
            "a wander path starts {} mm above the surface straight below the trocar: the \
             shaft there misses the bank's reachable surface, or that point is outside the \
             device's insertion range",
            START_ABOVE_M * 1e3
        )
    })?;
    let mut samples = vec![(0.0, first)];
    let mut t = 0.0;
    while t < seconds {
        let (to, moved) = (0..MAX_DRAWS)
            .find_map(|_| {
                let to = draw(&mut rng, &limits, at);
                let speed = (0.1 + 0.9 * rng.unit()) * limits.tip_speed;
                segment(bank, &limits, at, to, speed).map(|moved| (to, moved))
            })
            .ok_or_else(|| {
                anyhow::anyhow!(
                    "seed {seed}: no wander move within the limits after {MAX_DRAWS} draws from \
                     pitch {:.3} rad, yaw {:.3} rad (the bank's reachable surface around the \
                     trocar's axis is too small)",
                    at.angles[0],
                    at.angles[1]
                )
            })?;
        samples.extend(moved.into_iter().map(|(dt, q)| (t + dt, q)));
        t = samples.last().map_or(t, |s| s.0);
        at = to;
        if rng.unit() < 0.4 {
            t += 0.05 + 0.45 * rng.unit();
            let last = samples.last().map_or(first, |s| s.1);
            samples.push((t, last));
        }
    }
    Ok(samples)
}

/// What the path must keep to.
struct Limits {
    ws: Workspace,
    tip_speed: f64,
    joint_speed: [f64; 3],
    angle: f64,
}

/// The next move's end from `at` (see the module notes).
fn draw(rng: &mut SplitMix64, limits: &Limits, at: Pose) -> Pose {
    // Uniform over the disc of radius `reach` around the current angles.
    let near = |rng: &mut SplitMix64, reach: f64| {
        let (r, phi) = (
            reach * rng.unit().sqrt(),
            std::f64::consts::TAU * rng.unit(),
        );
        [at.angles[0] + r * phi.cos(), at.angles[1] + r * phi.sin()]
            .map(|a| a.clamp(-limits.angle, limits.angle))
    };
    let (angles, depth_m) = match rng.below(10) {
        // Press in place.
        0..=2 => (at.angles, 0.0005 + 0.0055 * rng.unit()),
        // Slide.
        3..=5 => (near(rng, 0.08), 0.0005 + 0.0055 * rng.unit()),
        // Leave.
        6..=7 => (near(rng, 0.01), -(0.0005 + 0.0045 * rng.unit())),
        // Re-enter elsewhere.
        _ => (near(rng, 0.1), -0.004 + 0.01 * rng.unit()),
    };
    Pose { angles, depth_m }
}

/// The hand's joints at `pose`, `None` when the shaft misses the bank's surface or the
/// insertion leaves the device's range.
fn joints(bank: &Bank, limits: &Limits, pose: Pose) -> Option<[f64; 3]> {
    let s = surface_insertion(bank, pose.angles).ok()? + pose.depth_m;
    let [lo, hi] = limits.ws.insertion;
    (s >= lo && s <= hi).then_some([pose.angles[0], pose.angles[1], s])
}

/// The samples of the move from `from` to `to` at a peak tip speed of about `speed` (times
/// from the move's start, the first sample after it), `None` when a sample leaves the limits.
/// The angles and the depth follow smoothstep; the move's time is stretched until every
/// sample-to-sample speed is within the limits.
fn segment(
    bank: &Bank,
    limits: &Limits,
    from: Pose,
    to: Pose,
    speed: f64,
) -> Option<Vec<(f64, [f64; 3])>> {
    let pose = |u: f64| Pose {
        angles: [0, 1].map(|k| from.angles[k] + u * (to.angles[k] - from.angles[k])),
        depth_m: from.depth_m + u * (to.depth_m - from.depth_m),
    };
    // The path's geometry at 32 steps of its parameter: its longest step sets the time (a
    // smoothstep's peak rate is 1.5 / duration).
    let steps = 32;
    let mut prev = joints(bank, limits, from)?;
    let mut steepest = 0.0f64;
    for i in 1..=steps {
        let q = joints(bank, limits, pose(f64::from(i) / f64::from(steps)))?;
        steepest = steepest.max(rate(limits, prev, q, 1.0 / f64::from(steps), speed));
        prev = q;
    }
    let mut duration = (1.5 * steepest).max(2.0 * SAMPLE_S);
    // Stretched by 10% until the samples keep the limits (the 32 steps only estimate them).
    for _ in 0..20 {
        let n = (duration / SAMPLE_S).ceil() as u32;
        let dt = duration / f64::from(n);
        let mut out = Vec::with_capacity(n as usize);
        let mut prev = joints(bank, limits, from)?;
        let mut worst = 0.0f64;
        for i in 1..=n {
            let s = f64::from(i) / f64::from(n);
            let q = joints(bank, limits, pose(s * s * (3.0 - 2.0 * s)))?;
            worst = worst.max(rate(limits, prev, q, dt, 1.0));
            out.push((f64::from(i) * dt, q));
            prev = q;
        }
        if worst <= 1.0 {
            return Some(out);
        }
        duration *= 1.1;
    }
    None
}

/// The largest of the tip's and the joints' speeds from `a` to `b` in `dt` against their
/// limits (the tip's at `tip_speed`, the joints' at theirs): at most 1 within all of them.
fn rate(limits: &Limits, a: [f64; 3], b: [f64; 3], dt: f64, tip_speed: f64) -> f64 {
    let (pa, pb) = (
        limits.ws.tip(a[0], a[1], a[2]),
        limits.ws.tip(b[0], b[1], b[2]),
    );
    let tip = (0..3).map(|k| (pb[k] - pa[k]).powi(2)).sum::<f64>().sqrt() / dt;
    (0..3)
        .map(|k| (b[k] - a[k]).abs() / dt / limits.joint_speed[k])
        .fold(tip / tip_speed.min(limits.tip_speed), f64::max)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn patch() -> bank_format::AlignedBytes {
        firmware::fixtures::flat_patch()
    }

    /// On the flat patch (the plane z = 0, the trocar 0.1 m above it): every seed's path keeps
    /// the hand's tip under 0.45 m/s and each joint under 45% of its threshold between samples,
    /// the angles within 0.15 rad, the tip within 6 mm below and 5 mm above the plane (the
    /// plane's height is the independent reference for the depth); it presses, leaves and
    /// re-enters several times, and holds still in contact; the same seed gives the same path.
    #[test]
    fn wander_paths_keep_the_limits_and_touch_leave_and_hold() {
        let bytes = patch();
        let bank = Bank::parse(&bytes).unwrap();
        let cal = bank.device();
        let ws = Workspace::from_device(cal);
        for seed in 0..20 {
            let p = path(&bank, seed, 10.0).unwrap();
            assert_eq!(p, path(&bank, seed, 10.0).unwrap(), "seed {seed}");
            assert!(p.last().unwrap().0 >= 10.0);
            let (mut entries, mut held) = (0, 0.0);
            for w in p.windows(2) {
                let ((t0, a), (t1, b)) = (w[0], w[1]);
                let dt = t1 - t0;
                assert!(dt > 0.0, "seed {seed}: {t0} -> {t1}");
                let (pa, pb) = (ws.tip(a[0], a[1], a[2]), ws.tip(b[0], b[1], b[2]));
                let v = (0..3).map(|k| (pb[k] - pa[k]).powi(2)).sum::<f64>().sqrt() / dt;
                assert!(v <= 0.45 + 1e-9, "seed {seed} at {t0} s: {v} m/s");
                for k in 0..3 {
                    let limit = 0.45 * f64::from(cal.max_joint_speed[k]);
                    assert!((b[k] - a[k]).abs() / dt <= limit + 1e-9, "seed {seed}");
                }
                assert!(b[2] >= ws.insertion[0] && b[2] <= ws.insertion[1], "{b:?}");
                assert!(
                    b[0].abs() <= 0.15 && b[1].abs() <= 0.15,
                    "seed {seed}: {b:?}"
                );
                // The plane's height: -6 mm along a shaft at most 0.15 rad off the vertical
                // is at least -6 mm in z.
                assert!(pb[2] >= -0.006 - 1e-9 && pb[2] <= 0.005 + 1e-9, "{pb:?}");
                if pa[2] > 0.0 && pb[2] <= 0.0 {
                    entries += 1;
                }
                if a == b && pb[2] < 0.0 {
                    held += dt;
                }
            }
            assert!(entries >= 3, "seed {seed}: {entries} entries");
            assert!(held > 0.0, "seed {seed}: no held contact");
        }
        assert_ne!(path(&bank, 0, 3.0).unwrap(), path(&bank, 1, 3.0).unwrap());
    }

    /// A bank whose device's overspeed threshold is 0.5 m/s: the hand keeps to 45% of it.
    #[test]
    fn a_lower_overspeed_threshold_lowers_the_speed() {
        let mut cal = firmware::fixtures::patch_device();
        cal.max_tip_speed_m_s = 0.5;
        let bytes = firmware::fixtures::grid_patch_with(5, 0.01, 0.06, cal);
        let bank = Bank::parse(&bytes).unwrap();
        let ws = Workspace::from_device(&cal);
        let p = path(&bank, 7, 5.0).unwrap();
        let fastest = p
            .windows(2)
            .map(|w| {
                let ((t0, a), (t1, b)) = (w[0], w[1]);
                let (pa, pb) = (ws.tip(a[0], a[1], a[2]), ws.tip(b[0], b[1], b[2]));
                (0..3).map(|k| (pb[k] - pa[k]).powi(2)).sum::<f64>().sqrt() / (t1 - t0)
            })
            .fold(0.0, f64::max);
        assert!(fastest <= 0.225 + 1e-9 && fastest > 0.1, "{fastest}");
    }
}
