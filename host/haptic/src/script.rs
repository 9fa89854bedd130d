//! Aiming the tool at the organ, and the demo's scripted hand motions (`press`, `slide`,
//! `strike`, `press-hold`: [`Script`]), as joint targets `[pitch, yaw, insertion]` for
//! [`crate::display::source::Steering`].
//!
//! Depth is measured along the shaft from the organ's rest surface: `insertion = |aim -
//! fulcrum| + depth`, with `(pitch, yaw)` pointing the shaft at the aimed surface point
//! ([`Workspace::joints_for_tip`]); positive depth presses in, negative hovers above. The
//! paths are [`crate::trajectory`]'s strokes with the demo's numbers (linear ramps); a slide
//! sweeps the yaw.

use crate::kinematics::Workspace;
use crate::trajectory::{Blend, Press, Script, Stroke, Sweep};
use fem::vec3::{cross, dot, sub};

/// Joint target that points the shaft at `aim` (m) and pushes `depth` (m) beyond it.
pub fn aim_joints(ws: &Workspace, aim: [f64; 3], depth: f64) -> [f64; 3] {
    let [pitch, yaw, reach] = ws.joints_for_tip(aim);
    [pitch, yaw, reach + depth]
}

/// Where the scripts and the page's first view aim: the point of the surface (`triangles` over
/// `mesh`'s nodes) straight under the centre of the mesh's bounding box, seen from above;
/// `None` when the vertical through that centre misses the surface.
pub fn press_point(mesh: &fem::mesh::TetMesh, triangles: &[[usize; 3]]) -> Option<[f64; 3]> {
    let (lo, hi) = mesh.bounding_box();
    let from = [0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), hi[2] + 1.0];
    let d = ray_hit(&mesh.nodes, triangles, from, [0.0, 0.0, -1.0])?;
    Some([from[0], from[1], from[2] - d])
}

/// Distance along the unit ray `origin + t dir` to the nearest triangle it crosses (t > 0);
/// [`ray_triangle`] per triangle.
pub fn ray_hit(
    positions: &[[f64; 3]],
    triangles: &[[usize; 3]],
    origin: [f64; 3],
    dir: [f64; 3],
) -> Option<f64> {
    triangles
        .iter()
        .filter_map(|t| {
            let [a, b, c] = t.map(|i| positions[i]);
            ray_triangle(origin, dir, a, b, c)
        })
        .reduce(f64::min)
}

/// Distance along `dir` (unit) from `o` to triangle `abc`, if the ray hits it in front
/// (Möller-Trumbore).
pub fn ray_triangle(
    o: [f64; 3],
    dir: [f64; 3],
    a: [f64; 3],
    b: [f64; 3],
    c: [f64; 3],
) -> Option<f64> {
    let (e1, e2) = (sub(b, a), sub(c, a));
    let p = cross(dir, e2);
    let det = dot(e1, p);
    if det.abs() < 1e-18 {
        return None;
    }
    let tv = sub(o, a);
    let u = dot(tv, p) / det;
    let q = cross(tv, e1);
    let v = dot(dir, q) / det;
    let t = dot(e2, q) / det;
    (u >= 0.0 && v >= 0.0 && u + v <= 1.0 && t > 0.0).then_some(t)
}

/// The demo's path for `script`, repeated for as long as the demo runs (depth along the shaft;
/// the lateral offset is the fraction of [`SLIDE_YAW`] swept):
///
/// - `press`: every 3 s, hover 5 mm above the aim point, press 8 mm in over 1 s, hold, release;
/// - `slide`: every 4 s, press 6 mm in, slide +-0.08 rad in yaw (about +-9 mm on the organ) and
///   back, release;
/// - `strike`: every 1.5 s, from 20 mm above, strike 8 mm in at the hand's top speed, hold
///   0.25 s, withdraw;
/// - `press-hold`: every 12 s, from 5 mm above, press 5 mm in over 0.5 s, hold 10 s, release.
fn demo_stroke(script: Script) -> Stroke {
    match script {
        Script::Press => Stroke::press(
            Press::new(0.005, 0.008, [0.5, 1.5, 2.2, 2.8]),
            Blend::Linear,
            3.0,
        ),
        Script::Slide => Stroke::slide(
            Press::new(0.005, 0.006, [0.4, 1.0, 3.0, 3.5]),
            Sweep::Sine {
                start_s: 1.0,
                period_s: 2.0,
                amplitude: 1.0,
            },
            Blend::Linear,
            4.0,
        ),
        Script::Strike => Stroke::press(
            Press::new(0.020, 0.008, [0.5, 0.556, 0.806, 1.0]),
            Blend::Linear,
            1.5,
        ),
        Script::PressHold => Stroke::press(
            Press::new(0.005, 0.005, [0.3, 0.8, 10.8, 11.3]),
            Blend::Linear,
            12.0,
        ),
    }
}

/// Samples of the rest surface's distance from the fulcrum along the shaft across the slide's
/// yaw sweep.
const SWEEP_SAMPLES: usize = 65;
/// Yaw amplitude of `slide`, rad.
const SLIDE_YAW: f64 = 0.08;

/// A script bound to a scene: the aim direction and the surface distances along the sweep.
#[derive(Debug, Clone)]
pub struct Scripted {
    stroke: Stroke,
    pitch: f64,
    yaw: f64,
    /// Surface distance for yaw `yaw + SLIDE_YAW * (2 i / (n - 1) - 1)`.
    sweep: Vec<f64>,
}

impl Scripted {
    /// Binds `script` to the surface (rest `positions`, outward `triangles`) aimed at `aim`.
    /// Returns `None` when the shaft pointed at `aim` misses the surface.
    pub fn new(
        script: Script,
        ws: &Workspace,
        positions: &[[f64; 3]],
        triangles: &[[usize; 3]],
        aim: [f64; 3],
    ) -> Option<Scripted> {
        let [pitch, yaw, _] = aim_joints(ws, aim, 0.0);
        let sweep = (0..SWEEP_SAMPLES)
            .map(|i| {
                let y = yaw + SLIDE_YAW * (2.0 * i as f64 / (SWEEP_SAMPLES - 1) as f64 - 1.0);
                let tip = ws.tip(pitch, y, 1.0);
                let dir = std::array::from_fn(|k| tip[k] - ws.fulcrum[k]);
                ray_hit(positions, triangles, ws.fulcrum, dir)
            })
            .collect::<Option<Vec<f64>>>()?;
        Some(Scripted {
            stroke: demo_stroke(script),
            pitch,
            yaw,
            sweep,
        })
    }

    /// Surface distance at yaw offset `s * SLIDE_YAW`, `s` in [-1, 1] (linear interpolation).
    fn surface(&self, s: f64) -> f64 {
        let x = (s.clamp(-1.0, 1.0) + 1.0) * 0.5 * (SWEEP_SAMPLES - 1) as f64;
        let i = (x.floor() as usize).min(SWEEP_SAMPLES - 2);
        let w = x - i as f64;
        self.sweep[i] * (1.0 - w) + self.sweep[i + 1] * w
    }

    /// Joint target at time `t` (s) since the start.
    pub fn joints(&self, t: f64) -> [f64; 3] {
        let p = self.stroke.at(t);
        [
            self.pitch,
            self.yaw + SLIDE_YAW * p.lateral,
            self.surface(p.lateral) + p.depth_m,
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ray_hits_a_triangle_at_the_right_distance() {
        let t = ray_triangle(
            [0.2, 0.2, 1.0],
            [0.0, 0.0, -1.0],
            [0.0, 0.0, 0.25],
            [1.0, 0.0, 0.25],
            [0.0, 1.0, 0.25],
        );
        assert_eq!(t, Some(0.75));
        // Outside the triangle, and behind the origin.
        let miss = |o| {
            ray_triangle(
                o,
                [0.0, 0.0, -1.0],
                [0.0; 3],
                [1.0, 0.0, 0.0],
                [0.0, 1.0, 0.0],
            )
        };
        assert_eq!(miss([0.8, 0.8, 1.0]), None);
        assert_eq!(miss([0.2, 0.2, -1.0]), None);
    }

    /// The flat-box workspace of `reach`'s tests (trocar 0.1 m above z = 0, shaft down) with
    /// wider ranges.
    fn down() -> Workspace {
        Workspace {
            pitch: [-0.4, 0.4],
            yaw: [-0.4, 0.4],
            insertion: [0.02, 0.2],
            ..Workspace::straight_down()
        }
    }

    /// Two triangles covering [-0.1, 0.1]^2 at z = 0, normal up.
    fn plane() -> (Vec<[f64; 3]>, Vec<[usize; 3]>) {
        let p = vec![
            [-0.1, -0.1, 0.0],
            [0.1, -0.1, 0.0],
            [0.1, 0.1, 0.0],
            [-0.1, 0.1, 0.0],
        ];
        (p, vec![[0, 1, 2], [0, 2, 3]])
    }

    /// The press point of a tetrahedron under a plane's two triangles: the top centre of the
    /// bounding box dropped onto the plane.
    #[test]
    fn the_press_point_is_under_the_top_centre() {
        let (mut p, t) = plane();
        p.push([0.04, 0.02, -0.05]);
        let mesh = fem::mesh::TetMesh {
            nodes: p,
            tets: vec![[0, 1, 2, 4]],
        };
        assert_eq!(press_point(&mesh, &t), Some([0.0, 0.0, 0.0]));
        assert_eq!(press_point(&mesh, &[]), None);
    }

    #[test]
    fn aiming_reaches_the_aim_point_plus_depth_along_the_shaft() {
        let ws = down();
        let aim = [0.02, -0.03, 0.0];
        let q = aim_joints(&ws, aim, 0.004);
        let tip = ws.tip(q[0], q[1], q[2]);
        let v: [f64; 3] = std::array::from_fn(|i| aim[i] - ws.fulcrum[i]);
        let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        for i in 0..3 {
            let want = aim[i] + 0.004 * v[i] / n;
            assert!((tip[i] - want).abs() < 1e-12, "{tip:?}");
        }
    }

    #[test]
    fn ray_hits_the_plane_at_the_hand_computed_distance() {
        let (p, t) = plane();
        // From (0, 0, 0.1) towards (0.03, 0.04, 0): distance sqrt(0.03^2 + 0.04^2 + 0.1^2).
        let d = [0.03, 0.04, -0.1];
        let n = (0.03f64 * 0.03 + 0.04 * 0.04 + 0.01).sqrt();
        let hit = ray_hit(&p, &t, [0.0, 0.0, 0.1], d.map(|x| x / n)).unwrap();
        assert!((hit - n).abs() < 1e-12);
        assert_eq!(ray_hit(&p, &t, [0.0, 0.0, 0.1], [0.0, 0.0, 1.0]), None);
    }

    #[test]
    fn scripts_press_to_their_depth_below_the_rest_surface() {
        let (p, t) = plane();
        let ws = down();
        let s = Scripted::new(Script::Press, &ws, &p, &t, [0.0, 0.0, 0.0]).unwrap();
        // Held at 8 mm from 1.5 s to 2.2 s, straight down: tip at z = -0.008.
        let q = s.joints(1.8);
        assert!((ws.tip(q[0], q[1], q[2])[2] + 0.008).abs() < 1e-12);
        assert!(
            (s.joints(0.2)[2] - 0.095).abs() < 1e-12,
            "hovering 5 mm above"
        );
        // Slide: mid-sweep (t = 1.5 s) at +SLIDE_YAW, 6 mm below the plane along the shaft.
        let s = Scripted::new(Script::Slide, &ws, &p, &t, [0.0, 0.0, 0.0]).unwrap();
        let q = s.joints(1.5);
        assert!((q[1] - SLIDE_YAW).abs() < 1e-12);
        let tip = ws.tip(q[0], q[1], q[2]);
        assert!((tip[2] + 0.006 * SLIDE_YAW.cos()).abs() < 1e-6, "{tip:?}");
        // Strike: 8 mm in shortly after 0.556 s.
        let s = Scripted::new(Script::Strike, &ws, &p, &t, [0.0, 0.0, 0.0]).unwrap();
        assert!((s.joints(0.7)[2] - 0.108).abs() < 1e-12);
        assert!((s.joints(0.1)[2] - 0.08).abs() < 1e-12);
    }
}
