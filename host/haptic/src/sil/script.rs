//! Scripted hand trajectories for software in the loop, in joint space (pitch rad, yaw rad,
//! insertion m): the hand's grip moves along them and pulls the instrument (see
//! [`super::plant`]). Each script first brings the tip from the home pose to just above the
//! organ surface straight below the trocar, then repeats its cycle:
//!
//! - `press`: down to 6 mm below the surface in 1 s, hold 0.5 s, back up in 1 s;
//! - `slide`: down to 4 mm, sweep pitch +-0.05 rad (about +-5 mm at the tip) while pressed, up;
//! - `strike`: from 10 mm above, 18 mm down in 20 ms (peak 1.35 m/s), hold, retract;
//! - `press-hold`: down to 5 mm below the surface in 0.5 s, hold 10 s, back up in 0.5 s (a
//!   viscoelastic tissue's relaxation).
//!
//! `wander` ([`Trajectory::wander`], [`super::wander`]) is not a cycle but a seeded random path
//! near and into the surface (presses, slides, leaving and re-entering, held contacts) at tip
//! speeds up to 0.45 m/s: the tick's worst case searched on paths the cycles do not take.
//!
//! These are [`crate::trajectory`]'s strokes with the SIL hand's numbers ([`sil_stroke`]):
//! waypoints joined by smoothstep (`3 s^2 - 2 s^3`) blends, so the hand's speed is continuous;
//! the slide's lateral offset is the pitch.
//!
//! A recorded hand motion ([`Trajectory::from_csv`], `host sil --trajectory FILE`) replays a
//! CSV file instead: a header, then `t_s,x_m,y_m,z_m` (tip targets in the bank's frame, turned
//! into joints by the inverse kinematics [`Workspace::joints_for_tip`]) or
//! `t_s,pitch_rad,yaw_rad,insertion_m` (joints). The hand rests at the home pose, blends to the
//! first sample by 0.5 s (the scripts' approach), then follows the samples, linearly
//! interpolated, with the file's first time mapped to 0.5 s; it holds the last sample after
//! the file ends.

use anyhow::{Result, bail};
use bank_format::Bank;
use firmware::device::{Device, Joints};
use std::path::Path;

use crate::calibrate::csv;
use crate::kinematics::Workspace;
use crate::script::ray_triangle;
use crate::trajectory::{Blend, Press, Script, Stroke, Sweep, through};

/// Time before the first cycle: rest, then the approach to above the surface, s.
const APPROACH_END_S: f64 = 0.5;
const REST_S: f64 = 0.1;

/// The hand's joint-space path for one script, or a recorded motion, on one bank.
#[derive(Clone, Debug)]
pub struct Trajectory {
    home: [f64; 3],
    /// Insertion at which the tip meets the surface (pitch = yaw = 0).
    surface: f64,
    path: Motion,
}

/// What the hand follows after its approach.
#[derive(Clone, Debug)]
enum Motion {
    /// A script and its stroke ([`sil_stroke`]).
    Script(Script, Stroke),
    /// Recorded samples: times (s, from 0 at the first sample) and joints.
    Recorded(Vec<(f64, [f64; 3])>),
    /// The `wander` path of a seed ([`super::wander::path`]), samples as recorded ones.
    Wander(u64, Vec<(f64, [f64; 3])>),
}

/// The columns of a recorded trajectory file.
const TIP_COLUMNS: [&str; 4] = ["t_s", "x_m", "y_m", "z_m"];
const JOINT_COLUMNS: [&str; 4] = ["t_s", "pitch_rad", "yaw_rad", "insertion_m"];

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
            path: Motion::Script(script, sil_stroke(script)),
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

    /// The `wander` path of `seed` on `bank` ([`super::wander`]), generated for `seconds` of
    /// run (the approach included; it holds its last pose after them). Fails when the bank's
    /// reachable surface is missed straight below the trocar or is too small to wander on.
    pub fn wander(bank: &Bank, seed: u64, seconds: f64) -> Result<Trajectory> {
        if !(seconds.is_finite() && seconds > 0.0 && seconds <= 3600.0) {
            bail!("a wander path lasts (0, 3600] s, not {seconds}");
        }
        let samples = super::wander::path(bank, seed, seconds - APPROACH_END_S)?;
        Ok(Trajectory {
            home: bank.device().home_joint.map(f64::from),
            surface: surface_insertion(bank, [0.0, 0.0])?,
            path: Motion::Wander(seed, samples),
        })
    }

    /// A recorded hand motion from the CSV file at `path` (see the module notes), for `bank`'s
    /// device. A file that cannot be read, lacks both column sets, has a bad value, times that
    /// do not increase, fewer than two samples, or a sample outside the device's joint range
    /// (or a tip the shaft cannot reach) is an error naming the file and the line.
    pub fn from_csv(bank: &Bank, path: &Path) -> Result<Trajectory> {
        let file = path.display().to_string();
        let text = std::fs::read_to_string(path)
            .map_err(|e| anyhow::anyhow!("{file}: cannot read: {e}"))?;
        Trajectory::from_csv_text(bank, &file, &text)
    }

    /// [`Trajectory::from_csv`] on the text of a file named `file` (in errors).
    pub fn from_csv_text(bank: &Bank, file: &str, text: &str) -> Result<Trajectory> {
        let cal = bank.device();
        let (table, tips) = match csv::parse(file, text, &TIP_COLUMNS) {
            Ok(t) => (t, true),
            Err(csv::CsvError::MissingColumn { .. }) => {
                match csv::parse(file, text, &JOINT_COLUMNS) {
                    Ok(t) => (t, false),
                    Err(csv::CsvError::MissingColumn { line, header, .. }) => bail!(
                        "{file}:{line}: expected the columns {} (tip targets) or {} (joints); the \
                     header has: {header}",
                        TIP_COLUMNS.join(","),
                        JOINT_COLUMNS.join(",")
                    ),
                    Err(e) => return Err(e.into()),
                }
            }
            Err(e) => return Err(e.into()),
        };
        table.require_rows(2, "a recorded motion needs at least two samples")?;
        let cols: Vec<Vec<f64>> = (0..4).map(|c| table.numbers(c)).collect::<Result<_, _>>()?;
        let (t, a, b, c) = (&cols[0], &cols[1], &cols[2], &cols[3]);
        table.require_increasing(0, t)?;
        let ws = Workspace::from_device(cal);
        let (lo, hi) = (cal.joint_min.map(f64::from), cal.joint_max.map(f64::from));
        let names = ["pitch", "yaw", "insertion"];
        let mut samples = Vec::with_capacity(t.len());
        for (i, &line) in table.lines.iter().enumerate() {
            let q = if tips {
                let tip = [a[i], b[i], c[i]];
                let v: [f64; 3] = std::array::from_fn(|k| tip[k] - f64::from(cal.fulcrum_m[k]));
                if v.iter().map(|x| x * x).sum::<f64>() == 0.0 {
                    return Err(table
                        .at(
                            line,
                            "the tip target is the fulcrum: no shaft direction".into(),
                        )
                        .into());
                }
                ws.joints_for_tip(tip)
            } else {
                [a[i], b[i], c[i]]
            };
            for k in 0..3 {
                if !(q[k] >= lo[k] && q[k] <= hi[k]) {
                    let what = if tips { "the tip target needs " } else { "" };
                    return Err(table
                        .at(
                            line,
                            format!(
                                "{what}{} {:.6} outside the device's range [{}, {}]",
                                names[k], q[k], lo[k], hi[k]
                            ),
                        )
                        .into());
                }
            }
            samples.push((t[i] - t[0], q));
        }
        Ok(Trajectory {
            home: cal.home_joint.map(f64::from),
            surface: 0.0,
            path: Motion::Recorded(samples),
        })
    }

    /// Seconds until the hand reaches the end of a recorded motion (the approach included);
    /// `None` for a script, which repeats.
    pub fn recorded_end_s(&self) -> Option<f64> {
        match &self.path {
            Motion::Recorded(s) => s.last().map(|l| APPROACH_END_S + l.0),
            Motion::Script(..) | Motion::Wander(..) => None,
        }
    }

    /// The script, `None` for a recorded motion or `wander`.
    pub fn script(&self) -> Option<Script> {
        match self.path {
            Motion::Script(s, _) => Some(s),
            Motion::Recorded(_) | Motion::Wander(..) => None,
        }
    }

    /// The seed of a `wander` path, `None` otherwise.
    pub fn wander_seed(&self) -> Option<u64> {
        match self.path {
            Motion::Wander(seed, _) => Some(seed),
            Motion::Script(..) | Motion::Recorded(_) => None,
        }
    }

    /// Insertion at which the tip meets the surface straight below the trocar, m (0 for a
    /// recorded motion, which does not plan against the surface).
    pub fn surface_insertion_m(&self) -> f64 {
        self.surface
    }

    /// Deepest point of the script below the surface, m (0 for a recorded motion or
    /// `wander`, whose depths follow the surface under the shaft).
    pub fn depth_m(&self) -> f64 {
        match &self.path {
            Motion::Script(_, stroke) => stroke.depth_m(),
            Motion::Recorded(_) | Motion::Wander(..) => 0.0,
        }
    }

    /// The hand's target joints at time `t` (s).
    pub fn at(&self, t: f64) -> [f64; 3] {
        let stroke = match &self.path {
            Motion::Script(_, stroke) => stroke,
            Motion::Recorded(samples) | Motion::Wander(_, samples) => {
                return self.recorded_at(samples, t);
            }
        };
        let s0 = self.surface;
        if t < APPROACH_END_S {
            let start = [0.0, 0.0, s0 + stroke.at(0.0).depth_m];
            return approach(self.home, start, t);
        }
        let p = stroke.at(t - APPROACH_END_S);
        [p.lateral, 0.0, s0 + p.depth_m]
    }

    /// A recorded motion (or `wander`) at `t`: the approach blend, then linear interpolation of
    /// the samples.
    fn recorded_at(&self, samples: &[(f64, [f64; 3])], t: f64) -> [f64; 3] {
        let Some(&(_, first)) = samples.first() else {
            return self.home;
        };
        if t < APPROACH_END_S {
            return approach(self.home, first, t);
        }
        let t = t - APPROACH_END_S;
        let i = samples.partition_point(|s| s.0 <= t);
        match (samples.get(i.wrapping_sub(1)), samples.get(i)) {
            (Some(&(t0, a)), Some(&(t1, b))) => {
                let k = (t - t0) / (t1 - t0);
                std::array::from_fn(|j| a[j] + k * (b[j] - a[j]))
            }
            (Some(&(_, a)), None) => a,
            _ => first,
        }
    }
}

/// The hand's path from `home` to `start` before the first cycle: at rest until [`REST_S`],
/// then a smoothstep blend to `start` by [`APPROACH_END_S`].
fn approach(home: [f64; 3], start: [f64; 3], t: f64) -> [f64; 3] {
    through(
        &[(REST_S, home), (APPROACH_END_S, start)],
        Blend::Smoothstep,
        t,
    )
}

/// The SIL hand's stroke for `script` (see the module notes; the lateral offset is the pitch,
/// rad), each cycle starting above the surface where the approach ends.
pub fn sil_stroke(script: Script) -> Stroke {
    match script {
        Script::Press => Stroke::press(
            Press::new(0.005, 0.006, [0.0, 1.0, 1.5, 2.5]),
            Blend::Smoothstep,
            2.5,
        ),
        Script::Slide => Stroke::slide(
            Press::new(0.005, 0.004, [0.0, 0.8, 2.6, 3.0]),
            Sweep::Waypoints {
                at_s: [0.8, 1.4, 2.2, 2.6],
                amplitude: 0.05,
            },
            Blend::Smoothstep,
            3.0,
        ),
        Script::Strike => Stroke::press(
            Press::new(0.01, 0.008, [0.5, 0.52, 0.8, 1.2]),
            Blend::Smoothstep,
            1.5,
        ),
        Script::PressHold => Stroke::press(
            Press::new(0.005, 0.005, [0.0, 0.5, 10.5, 11.0]),
            Blend::Smoothstep,
            11.5,
        ),
    }
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

    /// The SIL strike (module notes): from 10 mm above the surface to 8 mm below it between
    /// 0.5 s and 0.52 s into its cycle by smoothstep, so its peak speed, half way down, is 1.5
    /// times the mean: 1.5 x 18 mm / 20 ms = 1.35 m/s; held to 0.8 s, back above by 1.2 s.
    #[test]
    fn the_strike_descends_18_mm_in_20_ms_at_a_peak_of_1_35_m_s() {
        let s = sil_stroke(Script::Strike);
        let depth = |t| s.at(t).depth_m;
        assert_eq!(depth(0.0), -0.01);
        assert_eq!(depth(0.5), -0.01);
        assert!((depth(0.52) - 0.008).abs() < 1e-12);
        assert!((depth(0.7) - 0.008).abs() < 1e-12);
        assert!((depth(1.2) + 0.01).abs() < 1e-12);
        assert!((depth(0.51) + 0.001).abs() < 1e-12);
        let h = 1e-7;
        let v = (depth(0.51 + h) - depth(0.51 - h)) / (2.0 * h);
        assert!((v - 1.35).abs() < 1e-6, "{v}");
        assert_eq!(s.period_s(), 1.5);
    }

    /// The SIL press through [`Trajectory::at`] on the flat patch: the approach ends 5 mm above
    /// the surface straight below the trocar, the bottom is 6 mm below it 1 s later.
    #[test]
    fn the_press_starts_above_the_surface_and_reaches_6_mm() {
        let bytes = patch_bank();
        let bank = Bank::parse(bytes.as_slice()).unwrap();
        let t = Trajectory::new(&bank, Script::Press).unwrap();
        let s0 = t.surface_insertion_m();
        let home = bank.device().home_joint.map(f64::from);
        assert_eq!(t.at(0.0), home);
        assert_eq!(t.at(0.5), [0.0, 0.0, s0 - 0.005]);
        let bottom = t.at(1.5);
        assert!((bottom[2] - (s0 + 0.006)).abs() < 1e-12, "{bottom:?}");
        assert_eq!(t.depth_m(), 0.006);
        // A cycle later (2.5 s), the same.
        assert!((t.at(4.0)[2] - bottom[2]).abs() < 1e-12);
    }

    fn patch_bank() -> bank_format::AlignedBytes {
        firmware::fixtures::flat_patch()
    }

    /// A joints file replays through the approach, then its samples linearly interpolated with
    /// its first time at 0.5 s, then holds its last sample.
    #[test]
    fn a_joint_file_is_replayed_after_the_approach() {
        let bytes = patch_bank();
        let bank = Bank::parse(bytes.as_slice()).unwrap();
        let text = "# recorded by hand\nt_s,pitch_rad,yaw_rad,insertion_m\n\
                    2.0,0.0,0.0,0.09\n2.5,0.1,-0.05,0.1\n3.0,0.1,-0.05,0.095\n";
        let t = Trajectory::from_csv_text(&bank, "rec.csv", text).unwrap();
        assert_eq!(t.script(), None);
        assert_eq!(t.recorded_end_s(), Some(0.5 + 1.0));
        let home = bank.device().home_joint.map(f64::from);
        assert_eq!(t.at(0.0), home);
        assert_eq!(t.at(0.5), [0.0, 0.0, 0.09]);
        let mid = t.at(0.75);
        for (got, want) in mid.iter().zip([0.05, -0.025, 0.095]) {
            assert!((got - want).abs() < 1e-12, "{mid:?}");
        }
        assert_eq!(t.at(1.0), [0.1, -0.05, 0.1]);
        assert_eq!(t.at(9.0), [0.1, -0.05, 0.095]);
        // The approach is the scripts' smoothstep from home to the first sample.
        let q = t.at(0.3);
        assert!(q[2] > home[2] && q[2] < 0.09, "{q:?}");
    }

    /// Tip targets go through the inverse kinematics: the forward kinematics of the joints
    /// replayed puts the tip back on the targets.
    #[test]
    fn a_tip_file_goes_through_the_inverse_kinematics() {
        let bytes = patch_bank();
        let bank = Bank::parse(bytes.as_slice()).unwrap();
        let targets = [
            [0.02, 0.02, 0.004],
            [0.025, 0.018, 0.001],
            [0.015, 0.022, -0.002],
        ];
        let mut text = String::from("t_s, x_m, y_m, z_m\n");
        for (i, p) in targets.iter().enumerate() {
            text.push_str(&format!("{},{},{},{}\n", 0.1 * i as f64, p[0], p[1], p[2]));
        }
        let t = Trajectory::from_csv_text(&bank, "tips.csv", &text).unwrap();
        let ws = Workspace::from_device(bank.device());
        for (i, p) in targets.iter().enumerate() {
            let q = t.at(0.5 + 0.1 * i as f64);
            let tip = ws.tip(q[0], q[1], q[2]);
            for k in 0..3 {
                assert!((tip[k] - p[k]).abs() < 1e-12, "{tip:?} vs {p:?}");
            }
        }
    }

    /// Every bad file names its line (comment lines counted) and what is wrong.
    #[test]
    fn a_bad_trajectory_file_names_its_line() {
        let bytes = patch_bank();
        let bank = Bank::parse(bytes.as_slice()).unwrap();
        let err = |text: &str| {
            Trajectory::from_csv_text(&bank, "bad.csv", text)
                .unwrap_err()
                .to_string()
        };
        let head = "# comment\nt_s,pitch_rad,yaw_rad,insertion_m\n";
        let e = err("# comment\ntime,x,y\n0,0,0\n");
        assert!(
            e.starts_with("bad.csv:2: expected the columns t_s,x_m,y_m,z_m"),
            "{e}"
        );
        assert!(e.contains("time,x,y"), "{e}");
        let e = err(&format!("{head}0,0,0,0.09\n0.1,0,zero,0.09\n"));
        assert!(e.starts_with("bad.csv:4: column \"yaw_rad\""), "{e}");
        let e = err(&format!("{head}0,0,0,0.09\n0.1,0,0,0.09\n0.1,0,0,0.09\n"));
        assert!(
            e.starts_with("bad.csv:5: column \"t_s\" must increase"),
            "{e}"
        );
        let e = err(&format!("{head}0,0,0,0.09\n0.1,0,0,0.9\n"));
        assert!(
            e.starts_with("bad.csv:4: insertion 0.900000 outside"),
            "{e}"
        );
        let e = err("t_s,x_m,y_m,z_m\n0,0.02,0.02,-0.5\n1,0.02,0.02,0\n");
        assert!(
            e.starts_with("bad.csv:2: the tip target needs insertion"),
            "{e}"
        );
        let e = err(&format!("{head}0,0,0,0.09\n"));
        assert!(e.contains("1 data rows, need at least 2"), "{e}");
        let e = err(&format!("{head}0,0,0,0.09\n1,0,0\n"));
        assert!(e.starts_with("bad.csv:4: bad record"), "{e}");
    }
}
