//! `host contact probe`: what a bank renders at any point of the reachable surface.
//!
//! For a query point `X`: the collision-surface point `p` closest to `X` (R's triangles; an error
//! when the organ's surface point closest to `X` is not reachable), the triangle's outward
//! normal `n`, the patch compliance `W(p)` as the firmware reads it (a sampled bank: its
//! interpolated samples, [`bank_format::Samples::interpolate`]; a nodal bank: `B C_SS B^T` of the
//! firmware's tool patch at `p`), and, for a press depth `D`, the tool force that the firmware's
//! own tick ([`firmware::tick::HapticLoop`]) renders when the device moves the tip from 5 mm
//! outside `p` to `p - D n` along `-n` (0.2 mm a tick, then held), frictionless because the path
//! is normal to the surface.

use crate::kinematics::{Workspace, counts_for};
use anyhow::{Context, Result, bail};
use bank_format::{Bank, Mode};
use fem::tool::closest_on_triangle;
use fem::vec3::{add, cross, dist2, dot, norm, scale, sub};
use firmware::hal::Interlocks;
use firmware::tick::{HapticLoop, LoopInput};

/// What a probe found.
#[derive(Debug, Clone, PartialEq)]
pub struct Probe {
    /// The collision triangle (index into the bank's triangles).
    pub triangle: u32,
    /// Barycentric coordinates of `point` in it.
    pub bary: [f64; 3],
    /// The collision-surface point closest to the query, m.
    pub point: [f64; 3],
    /// The triangle's outward unit normal.
    pub normal: [f64; 3],
    /// `W(p)`, m/N, as the firmware reads it.
    pub w: [[f64; 3]; 3],
    /// `n . W n`, m/N: the normal compliance.
    pub nwn: f64,
    /// The force the firmware renders on the tool for the press, N (with a depth).
    pub force_n: Option<[f64; 3]>,
}

/// Metres the pressing tip starts outside the surface.
const START_M: f64 = 0.005;
/// The most ticks a press may take.
const MAX_PRESS_TICKS: usize = 1_000_000;

/// How a press moves the tip ([`press`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PressPath {
    /// The tip's step per tick, m (> 0).
    pub step_m: f64,
    /// Ticks the tip is held at the press depth before the force is read.
    pub hold_ticks: usize,
}

impl PressPath {
    /// The probe's: 0.2 mm a tick (0.2 m/s, far below the overspeed threshold), held 10 ticks.
    pub const PROBE: PressPath = PressPath {
        step_m: 0.0002,
        hold_ticks: 10,
    };
}

/// The closest point to `q` over `triangles` of `positions`: (triangle, point, bary, squared
/// distance); `None` without triangles.
pub fn closest_point(
    positions: &[[f64; 3]],
    triangles: &[[usize; 3]],
    q: [f64; 3],
) -> Option<(usize, [f64; 3], [f64; 3], f64)> {
    let mut best: Option<(usize, [f64; 3], [f64; 3], f64)> = None;
    for (t, tri) in triangles.iter().enumerate() {
        let v = tri.map(|k| positions[k]);
        let (p, b) = closest_on_triangle(q, v);
        let d = dist2(p, q);
        if best.is_none_or(|x| d < x.3) {
            best = Some((t, p, b, d));
        }
    }
    best
}

/// A point of the reachable surface (R's triangles).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReachablePoint {
    /// Index of its triangle.
    pub triangle: usize,
    /// The point, m.
    pub point: [f64; 3],
    /// Its barycentric coordinates in the triangle.
    pub bary: [f64; 3],
    /// The triangle's outward unit normal.
    pub normal: [f64; 3],
}

/// The point of the reachable triangles (`triangles` of `positions`) closest to `q`; an error
/// when the organ's surface point closest to `q` (`organ`: the whole boundary's positions and
/// triangles) is not reachable, with 1 um of slack (a bank's positions are f32).
pub fn closest_reachable(
    positions: &[[f64; 3]],
    triangles: &[[usize; 3]],
    organ: (&[[f64; 3]], &[[usize; 3]]),
    q: [f64; 3],
) -> Result<ReachablePoint> {
    let Some((t, point, bary, d2)) = closest_point(positions, triangles, q) else {
        bail!("the reachable region has no triangles");
    };
    if let Some((_, o, _, o2)) = closest_point(organ.0, organ.1, q)
        && o2.sqrt() + 1e-6 < d2.sqrt()
    {
        bail!(
            "the organ's surface point closest to it, [{:.4}, {:.4}, {:.4}] m, is outside the \
             tool's reachable region (or on the fixed supports); the nearest reachable point is \
             {:.1} mm away",
            o[0],
            o[1],
            o[2],
            1e3 * d2.sqrt()
        );
    }
    let v = triangles[t].map(|k| positions[k]);
    let n = cross(sub(v[1], v[0]), sub(v[2], v[0]));
    Ok(ReachablePoint {
        triangle: t,
        point,
        bary,
        normal: scale(n, 1.0 / norm(n)),
    })
}

/// Probes `bank` at `at` (m). `organ` is the collision mesh's whole boundary (positions and
/// triangles), to tell a query whose closest surface point is not reachable. `depth` (m, > 0)
/// asks for the rendered force of a press; `law` renders it through the bank's Q (else the
/// linear model's force, the firmware's `LinearLaw` mode).
pub fn probe(
    bank: &Bank<'_>,
    organ: (&[[f64; 3]], &[[usize; 3]]),
    at: [f64; 3],
    depth: Option<f64>,
    law: bool,
) -> Result<Probe> {
    let name = format!("[{:.4}, {:.4}, {:.4}] m", at[0], at[1], at[2]);
    if !at.iter().all(|x| x.is_finite()) {
        bail!("--at {name}: not a finite point");
    }
    let positions: Vec<[f64; 3]> = bank.positions().iter().map(|p| p.map(f64::from)).collect();
    let triangles: Vec<[usize; 3]> = bank
        .triangles()
        .iter()
        .map(|t| t.map(usize::from))
        .collect();
    let ReachablePoint {
        triangle: t,
        point,
        bary,
        normal,
    } = closest_reachable(&positions, &triangles, organ, at)
        .with_context(|| format!("--at {name}"))?;
    let tri = bank.triangles()[t];
    let b32 = bary.map(|x| x as f32);
    let w6 = match bank.samples() {
        Some(s) => s.interpolate(t, b32),
        None => nodal_w(bank, t as u32, tri, b32, point.map(|x| x as f32)),
    };
    let Some(w6) = w6 else {
        bail!("--at {name}: the bank gives no patch compliance there");
    };
    let w6 = w6.map(f64::from);
    let w = [
        [w6[0], w6[1], w6[2]],
        [w6[1], w6[3], w6[4]],
        [w6[2], w6[4], w6[5]],
    ];
    let wn: [f64; 3] = std::array::from_fn(|i| dot(w[i], normal));
    let nwn = dot(normal, wn);
    let force_n = match depth {
        Some(d) if !valid_depth(d) => bail!("--depth {d}: must lie in (0, 0.05] m"),
        Some(d) => Some(
            press(bank, point, scale(normal, -1.0), d, PressPath::PROBE, law)
                .with_context(|| format!("--at {name}"))?,
        ),
        None => None,
    };
    Ok(Probe {
        triangle: t as u32,
        bary,
        point,
        normal,
        w,
        nwn,
        force_n,
    })
}

/// `B C_SS B^T` of the firmware's tool patch at `point` on a nodal bank (upper triangle: xx,
/// xy, xz, yy, yz, zz).
fn nodal_w(
    bank: &Bank<'_>,
    t: u32,
    tri: [u16; 3],
    bary: [f32; 3],
    p: [f32; 3],
) -> Option<[f32; 6]> {
    let r = bank.device().tip_radius_m;
    let patch = firmware::patch::tool_patch(bank, t, tri, bary, p, r);
    let mut m = [0.0f32; 6];
    for (&a, &wa) in patch.nodes().iter().zip(patch.weights()) {
        for (&b, &wb) in patch.nodes().iter().zip(patch.weights()) {
            let c = bank.coupling(usize::from(a), usize::from(b))?;
            let idx = [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)];
            for (o, (i, j)) in m.iter_mut().zip(idx) {
                *o += wa * wb * c[i][j];
            }
        }
    }
    Some(m)
}

/// Whether joint values `q` (pitch, yaw in rad, insertion in m) lie within the device's ranges
/// (1e-9 of slack for the round trip through the kinematics).
fn joints_inside(cal: &bank_format::DeviceCalibration, q: [f64; 3]) -> bool {
    (0..3).all(|j| {
        (f64::from(cal.joint_min[j]) - 1e-9..=f64::from(cal.joint_max[j]) + 1e-9).contains(&q[j])
    })
}

/// Whether the device of `cal` can make [`press`]'s whole path through `point` along `inward`
/// to `depth` (m): every tip from 5 mm short of `point` to `depth` past it, at 0.1 mm spacing,
/// within its joint ranges.
pub fn press_fits(
    cal: &bank_format::DeviceCalibration,
    point: [f64; 3],
    inward: [f64; 3],
    depth: f64,
) -> bool {
    let ws = Workspace::from_device(cal);
    let steps = ((START_M + depth) / 1e-4).ceil().max(1.0) as usize;
    (0..=steps).all(|i| {
        let s = (i as f64 / steps as f64) * (START_M + depth) - START_M;
        joints_inside(cal, ws.joints_for_tip(add(point, scale(inward, s))))
    })
}

/// A press depth the probe accepts, m.
fn valid_depth(depth: f64) -> bool {
    depth > 0.0 && depth.is_finite() && depth <= 0.05
}

/// The tool force, N, that the firmware's own tick (a fresh [`HapticLoop`], disarmed) renders
/// when the device moves its tip along the straight line through `point` (m) in the unit
/// direction `inward` (into the organ): from 5 mm short of `point` to `depth` (m, in
/// (0, 0.05]) past it in equal steps of at most `path.step_m`, then held `path.hold_ticks`
/// ticks; through the bank's Q with `law`, else the linear model's force. The probe's press is
/// this with `inward` the inward normal and [`PressPath::PROBE`]: frictionless, the anchor
/// never moves. Along any other line the contact's stick cone lets the anchor slide, which
/// rebuilds the patch over several ticks, so the force then depends on the speed and needs a
/// hold to settle. Refuses a tip the device cannot reach and a failed solve.
pub fn press(
    bank: &Bank<'_>,
    point: [f64; 3],
    inward: [f64; 3],
    depth: f64,
    path: PressPath,
    law: bool,
) -> Result<[f64; 3]> {
    if !valid_depth(depth) {
        bail!("press depth {depth} m: must lie in (0, 0.05] m");
    }
    let unit = (norm(inward) - 1.0).abs() < 1e-6;
    if !unit {
        bail!("the press direction {inward:?} is not a unit vector");
    }
    let steps = ((START_M + depth) / path.step_m).ceil();
    if !(steps.is_finite() && steps >= 1.0) || steps as usize + path.hold_ticks > MAX_PRESS_TICKS {
        bail!(
            "a press of {} mm in steps of {} m held {} ticks: not a positive step, or over \
             {MAX_PRESS_TICKS} ticks",
            1e3 * (START_M + depth),
            path.step_m,
            path.hold_ticks
        );
    }
    let steps = steps as usize;
    let cal = *bank.device();
    let ws = Workspace::from_device(&cal);
    let mut lp = HapticLoop::new(bank);
    if lp
        .set_mode(if law { Mode::Render } else { Mode::LinearLaw })
        .is_err()
    {
        bail!("internal: the loop refused the mode");
    }
    let mut force = [0.0f32; 3];
    for i in 0..=steps + path.hold_ticks {
        let s = (i.min(steps) as f64 / steps as f64) * (START_M + depth) - START_M;
        let tip = add(point, scale(inward, s));
        let q = ws.joints_for_tip(tip);
        if !joints_inside(&cal, q) {
            bail!(
                "the device cannot put its tip at [{:.4}, {:.4}, {:.4}] m on the \
                 press (pitch {:.3} rad, yaw {:.3} rad, insertion {:.4} m): outside its ranges",
                tip[0],
                tip[1],
                tip[2],
                q[0],
                q[1],
                q[2]
            );
        }
        let out = lp.tick(LoopInput {
            encoder_counts: counts_for(&cal, q),
            overrun: false,
            link_silence_ticks: 0,
            interlocks: Interlocks::default(),
        });
        if let Some(e) = out.solve_error {
            bail!("the firmware's solve failed on the press: {e}");
        }
        force = out.tool_force_n;
    }
    Ok(force.map(f64::from))
}
