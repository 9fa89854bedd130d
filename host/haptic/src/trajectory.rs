//! The scripted tool paths (press, slide, strike, press-hold): one generator for the demo's
//! scripted hand ([`crate::script::Scripted`], steering the virtual device), the SIL plant's hand
//! ([`crate::sil::script::Trajectory`]) and the tick bench's path ([`crate::bench::tick`]).
//!
//! A path is a [`Stroke`], repeated every `period_s`: the tool's depth below the organ's rest
//! surface (m; negative above it) and its lateral offset (the caller's unit: the demo's
//! fraction of its yaw sweep, the SIL hand's pitch in rad), as functions of the time within a
//! cycle ([`Stroke::at`]). Every stroke is a [`Press`] (down from a height above the surface
//! to a depth below it, hold, back up); a strike is a press from higher up at the hand's top
//! speed, a press-hold one with a long hold, and a slide ([`Stroke::slide`]) adds a lateral
//! [`Sweep`] while the tool is down. The callers turn depth and offset into joints (the demo
//! and the bench along their shafts, the SIL hand straight below the trocar) and choose the
//! numbers; how the path moves between its waypoints is explicit ([`Blend`]: the demo and the
//! bench move at constant speed between them, the SIL hand smoothly).

/// How a path moves between two waypoints.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Blend {
    /// At constant speed.
    Linear,
    /// By smoothstep (`3 s^2 - 2 s^3` of the fraction `s` of the segment's time): zero speed
    /// at every waypoint, so the speed is continuous.
    Smoothstep,
}

/// The scripted hand motions, by name (the demo's `--script` and the SIL plant's hand; each
/// follows its own numbers for them: [`crate::script`], [`crate::sil::script`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Script {
    /// Press in, hold, release.
    Press,
    /// Press in, sweep sideways and back while pressed, release.
    Slide,
    /// From high above, strike in at the hand's top speed, hold, withdraw.
    Strike,
    /// Press in, hold for 10 s, release: what a viscoelastic tissue's relaxation shows
    /// (`[viscoelastic]`, `firmware::relax`).
    #[serde(rename = "press-hold")]
    PressHold,
}

/// A press within a cycle: the tool waits `above_m` above the surface, goes down to
/// `depth_m` below it, holds there and goes back up.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Press {
    /// Height above the surface before and after, m.
    pub above_m: f64,
    /// Depth below the surface at the bottom, m.
    pub depth_m: f64,
    /// Times within the cycle (s): leaving the height, reaching the depth, leaving the depth,
    /// back at the height.
    pub at_s: [f64; 4],
}

impl Press {
    /// `above_m` above the surface, `depth_m` below it at the bottom, at the cycle's times
    /// `at_s` (leaving the height, reaching the depth, leaving the depth, back at the height).
    pub const fn new(above_m: f64, depth_m: f64, at_s: [f64; 4]) -> Press {
        Press {
            above_m,
            depth_m,
            at_s,
        }
    }
}

/// The lateral motion of a slide, in the caller's unit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Sweep {
    /// `amplitude sin(2 pi (t - start_s) / period_s)` for one period from `start_s` (out to
    /// `+amplitude`, through 0 to `-amplitude`, back to 0), 0 outside it.
    Sine {
        /// When the sweep starts, s into the cycle.
        start_s: f64,
        /// Its duration, s.
        period_s: f64,
        /// Its largest offset.
        amplitude: f64,
    },
    /// Waypoints joined by the stroke's [`Blend`]: 0 until `at_s[0]`, `+amplitude` at
    /// `at_s[1]`, `-amplitude` at `at_s[2]`, 0 again from `at_s[3]`.
    Waypoints {
        /// The four times, s into the cycle.
        at_s: [f64; 4],
        /// Its largest offset.
        amplitude: f64,
    },
}

/// Where a stroke puts the tool at one time.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Point {
    /// Depth below the rest surface, m (negative: above it).
    pub depth_m: f64,
    /// Lateral offset, in the unit of the stroke's [`Sweep`] (0 without one).
    pub lateral: f64,
}

/// A cyclic tool path (see the module notes).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Stroke {
    press: Press,
    sweep: Option<Sweep>,
    blend: Blend,
    period_s: f64,
}

impl Stroke {
    /// A press (or a strike, or a press-hold: the numbers differ) repeated every `period_s`,
    /// without lateral motion.
    pub fn press(press: Press, blend: Blend, period_s: f64) -> Stroke {
        Stroke {
            press,
            sweep: None,
            blend,
            period_s,
        }
    }

    /// A press with a lateral `sweep` (meant for while the tool is down), repeated every
    /// `period_s`.
    pub fn slide(press: Press, sweep: Sweep, blend: Blend, period_s: f64) -> Stroke {
        Stroke {
            press,
            sweep: Some(sweep),
            blend,
            period_s,
        }
    }

    /// The deepest point below the surface, m.
    pub fn depth_m(&self) -> f64 {
        self.press.depth_m
    }

    /// One cycle's duration, s.
    pub fn period_s(&self) -> f64 {
        self.period_s
    }

    /// The tool at time `t` (s) from the start of the first cycle (times before it count from
    /// the cycle before).
    pub fn at(&self, t: f64) -> Point {
        let t = t.rem_euclid(self.period_s);
        let Press {
            above_m,
            depth_m,
            at_s,
        } = self.press;
        let depth = [-above_m, depth_m, depth_m, -above_m];
        let depth_m = through(&waypoints(at_s, depth), self.blend, t)[0];
        let lateral = match self.sweep {
            Some(Sweep::Sine {
                start_s,
                period_s,
                amplitude,
            }) if (start_s..start_s + period_s).contains(&t) => {
                amplitude * (std::f64::consts::TAU * (t - start_s) / period_s).sin()
            }
            Some(Sweep::Waypoints { at_s, amplitude }) => {
                let offsets = [0.0, amplitude, -amplitude, 0.0];
                through(&waypoints(at_s, offsets), self.blend, t)[0]
            }
            // No sweep, or outside the sine's period.
            None | Some(Sweep::Sine { .. }) => 0.0,
        };
        Point { depth_m, lateral }
    }
}

/// Four scalar waypoints.
fn waypoints(at_s: [f64; 4], values: [f64; 4]) -> [(f64, [f64; 1]); 4] {
    std::array::from_fn(|i| (at_s[i], [values[i]]))
}

/// The path through `points` (times increasing) at time `t`, joined by `blend`: held at the
/// first point before it and at the last after it.
pub fn through<const N: usize>(points: &[(f64, [f64; N])], blend: Blend, t: f64) -> [f64; N] {
    let Some(&(t_first, first)) = points.first() else {
        return [0.0; N];
    };
    if t <= t_first {
        return first;
    }
    for w in points.windows(2) {
        let ((t0, a), (t1, b)) = (w[0], w[1]);
        if t <= t1 {
            let s = ((t - t0) / (t1 - t0)).clamp(0.0, 1.0);
            let k = match blend {
                Blend::Linear => s,
                Blend::Smoothstep => s * s * (3.0 - 2.0 * s),
            };
            return std::array::from_fn(|j| a[j] + k * (b[j] - a[j]));
        }
    }
    points.last().map_or(first, |p| p.1)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() < 1e-12
    }

    /// A 6 mm press from 5 mm above, down from 1 s to 2 s, held to 3 s, up by 4 s, every 5 s.
    fn press(blend: Blend) -> Stroke {
        let press = Press {
            above_m: 0.005,
            depth_m: 0.006,
            at_s: [1.0, 2.0, 3.0, 4.0],
        };
        Stroke::press(press, blend, 5.0)
    }

    #[test]
    fn a_press_starts_above_reaches_its_depth_and_comes_back() {
        let s = press(Blend::Linear);
        let depth = |t| s.at(t).depth_m;
        // Start and end of the cycle: 5 mm above.
        assert_eq!(depth(0.0), -0.005);
        assert_eq!(depth(4.5), -0.005);
        // Peak depth, held.
        assert!(close(depth(2.0), 0.006));
        assert_eq!(depth(2.7), 0.006);
        // Constant speed on the way down: 11 mm in 1 s, so 5.5 mm at half way.
        assert!(close(depth(1.5), 0.0005), "{}", depth(1.5));
        assert!(close(depth(1.25), -0.00225), "{}", depth(1.25));
        assert!(close((depth(1.6) - depth(1.4)) / 0.2, 0.011));
        // The next cycle repeats it; no lateral motion.
        assert!(close(depth(7.5), depth(2.5)));
        assert!(close(depth(6.5), depth(1.5)));
        assert_eq!(s.at(1.5).lateral, 0.0);
        assert_eq!(s.period_s(), 5.0);
    }

    #[test]
    fn a_smooth_press_has_zero_speed_at_its_waypoints() {
        let s = press(Blend::Smoothstep);
        let depth = |t| s.at(t).depth_m;
        assert_eq!(depth(1.0), -0.005);
        assert!(close(depth(2.0), 0.006));
        // Half way in time is half way in depth; 1.5 times the mean speed there.
        assert!(close(depth(1.5), 0.0005));
        let h = 1e-6;
        let mid = (depth(1.5 + h) - depth(1.5 - h)) / (2.0 * h);
        assert!((mid - 1.5 * 0.011).abs() < 1e-8, "{mid}");
        let start = (depth(1.0 + h) - depth(1.0)) / h;
        assert!(start.abs() < 1e-7, "{start}");
        // s = 0.25: 3/16 - 2/64 = 5/32 of the way.
        assert!(close(depth(1.25), -0.005 + 0.011 * 5.0 / 32.0));
    }

    #[test]
    fn a_sine_sweep_goes_out_and_back_once() {
        let press = Press {
            above_m: 0.005,
            depth_m: 0.004,
            at_s: [0.0, 0.5, 3.0, 3.5],
        };
        let sweep = Sweep::Sine {
            start_s: 1.0,
            period_s: 2.0,
            amplitude: 0.1,
        };
        let s = Stroke::slide(press, sweep, Blend::Linear, 4.0);
        let lateral = |t| s.at(t).lateral;
        assert_eq!(lateral(0.9), 0.0);
        assert_eq!(lateral(1.0), 0.0);
        assert!(close(lateral(1.5), 0.1));
        assert!(close(lateral(2.0), 0.0));
        assert!(close(lateral(2.5), -0.1));
        assert_eq!(lateral(3.0), 0.0);
        // Pressed 4 mm throughout the sweep.
        assert_eq!(s.at(1.5).depth_m, 0.004);
        assert_eq!(s.at(2.5).depth_m, 0.004);
    }

    #[test]
    fn a_waypoint_sweep_passes_its_extremes() {
        let press = Press {
            above_m: 0.005,
            depth_m: 0.004,
            at_s: [0.0, 0.8, 2.6, 3.0],
        };
        let sweep = Sweep::Waypoints {
            at_s: [0.8, 1.4, 2.2, 2.6],
            amplitude: 0.05,
        };
        let s = Stroke::slide(press, sweep, Blend::Smoothstep, 3.0);
        let lateral = |t| s.at(t).lateral;
        assert_eq!(lateral(0.5), 0.0);
        assert_eq!(lateral(1.4), 0.05);
        assert_eq!(lateral(2.2), -0.05);
        assert_eq!(lateral(2.8), 0.0);
        assert!(close(lateral(1.8), 0.0));
        assert!(close(lateral(1.1), 0.025));
    }

    #[test]
    fn through_is_smooth_and_holds_the_ends() {
        let pts = [(1.0, [0.0; 3]), (2.0, [1.0, 2.0, 4.0])];
        let at = |t| through(&pts, Blend::Smoothstep, t);
        assert_eq!(at(0.0), [0.0; 3]);
        assert_eq!(at(1.5), [0.5, 1.0, 2.0]);
        assert_eq!(at(3.0), [1.0, 2.0, 4.0]);
        // Zero slope at the waypoints.
        let d = at(1.0 + 1e-4)[2] - at(1.0)[2];
        assert!(d < 1e-6, "{d}");
        assert_eq!(through(&pts, Blend::Linear, 1.25), [0.25, 0.5, 1.0]);
        assert_eq!(through::<2>(&[], Blend::Linear, 1.0), [0.0; 2]);
    }
}
