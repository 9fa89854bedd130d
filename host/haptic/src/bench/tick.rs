//! `host bench tick`: the firmware's portable loop ([`firmware::tick::HapticLoop`]) run
//! natively on a bank along a scripted press, slide and release, timed per tick. What it
//! measures is the host CPU's time, not the MCU's (that is `host bench sil`, under QEMU); what
//! it checks is that the loop runs the bank without a fault and touches the organ.

use crate::kinematics::counts_for;
use crate::trajectory::{Blend, Press, Stroke, Sweep};
use anyhow::{Result, anyhow, bail};
use bank_format::Bank;
use firmware::tick::{HapticLoop, LoopInput};
use std::time::Instant;

/// Ticks per second.
const TICK_HZ: f64 = firmware::TICK_HZ as f64;
/// The path's speed in and out, m/s (0.05 mm a tick).
const SPEED_M_S: f64 = 0.05;
/// Where the path starts and ends above the surface, m.
const ABOVE_M: f64 = 0.005;
/// Yaw amplitude of the sweep, rad (the pitch sweeps 0.3 of it).
const SWEEP_RAD: f64 = 0.05;
/// Duration of the sweep at depth, s.
const SWEEP_S: f64 = 2.0;

/// Seconds from the path's start (and from each cycle's) to the bottom of its press, `depth_m`
/// below the surface.
fn down_s(depth_m: f64) -> f64 {
    (depth_m + ABOVE_M) / SPEED_M_S
}

/// The bench's path ([`crate::trajectory`]) with its bottom `depth_m` below the surface: in
/// from [`ABOVE_M`] above at [`SPEED_M_S`], one sine sweep of [`SWEEP_S`] at depth (lateral
/// offset 1 at the sweep's largest), out at the same speed; linear between the waypoints.
fn stroke(depth_m: f64) -> Stroke {
    let down_s = down_s(depth_m);
    let press = Press {
        above_m: ABOVE_M,
        depth_m,
        at_s: [0.0, down_s, down_s + SWEEP_S, 2.0 * down_s + SWEEP_S],
    };
    let sweep = Sweep::Sine {
        start_s: down_s,
        period_s: SWEEP_S,
        amplitude: 1.0,
    };
    Stroke::slide(press, sweep, Blend::Linear, 2.0 * down_s + SWEEP_S)
}

/// What a run did and how long its ticks took.
#[derive(Clone, Debug, PartialEq)]
pub struct TickBench {
    /// Ticks run.
    pub ticks: usize,
    /// Ticks in contact with the organ.
    pub touching: usize,
    /// The largest contact set of a tick.
    pub max_contact_nodes: usize,
    /// The largest tool force rendered, N.
    pub peak_force_n: f32,
    /// The tool force, N, at the last tick of the run that ends a press (the path just at its
    /// bottom, `depth_m` past first contact straight along the shaft at the home pose, before
    /// the sweep); `None` when the run ends before the first. The first cycle's press falls
    /// inside the loop's ramp-in after arming ([`firmware::tick::RAMP_IN_TICKS`]), so only
    /// a later cycle's is the full force of that press.
    pub press_force_n: Option<f32>,
    /// Faults the loop raised.
    pub faults: usize,
    /// The insertion at which the tool first touches along its rest axis, m.
    pub contact_insertion_m: f64,
    /// Nanoseconds per tick: mean, median, 99th percentile and largest.
    pub ns_mean: f64,
    /// Median, ns.
    pub ns_median: u64,
    /// 99th percentile, ns.
    pub ns_p99: u64,
    /// Largest, ns.
    pub ns_max: u64,
}

/// Run `ticks` ticks of the loop on `bank`: from the home pose straight along the shaft until
/// the tool touches, then `depth_m` further in, a yaw and pitch sweep at that depth and back
/// out, repeated (a [`crate::trajectory`] stroke). Refuses a bank whose tool never touches along
/// its rest axis, and `ticks` of zero.
pub fn run(bank: &Bank, ticks: usize, depth_m: f64) -> Result<TickBench> {
    if ticks == 0 {
        bail!("--ticks must be at least 1");
    }
    if !(depth_m.is_finite() && depth_m >= 0.0) {
        bail!("--depth must be a finite, non-negative distance in metres, got {depth_m}");
    }
    let cal = *bank.device();
    let home = cal.home_joint.map(f64::from);
    let input = |q: [f64; 3]| LoopInput {
        encoder_counts: counts_for(&cal, q),
        overrun: false,
        link_silence_ticks: 0,
        interlocks: firmware::hal::Interlocks::default(),
    };
    // Find first contact straight along the shaft at the home pose (disarmed probe).
    let step = SPEED_M_S / TICK_HZ;
    let (lo, hi) = (f64::from(cal.joint_min[2]), f64::from(cal.joint_max[2]));
    let mut probe = HapticLoop::new(bank);
    let mut ins = lo;
    let mut contact_at = None;
    while ins <= hi {
        let out = probe.tick(input([home[0], home[1], ins]));
        if out.contact_nodes > 0 {
            contact_at = Some(ins);
            break;
        }
        ins += step;
    }
    let Some(surface) = contact_at else {
        bail!("the tool never touches the organ along its rest axis; nothing to measure");
    };
    // Press to `depth`, slide in yaw and back, release; repeat.
    let bottom = (surface + depth_m).min(hi);
    // The path's index of the tick that ends the press.
    let press_end = (down_s(bottom - surface) * TICK_HZ).round() as usize;
    let path: Vec<[f64; 3]> = {
        let stroke = stroke(bottom - surface);
        let cycle = (stroke.period_s() * TICK_HZ).round() as usize;
        (0..cycle)
            .map(|k| {
                let p = stroke.at(k as f64 / TICK_HZ);
                [
                    home[0] + 0.3 * SWEEP_RAD * p.lateral,
                    home[1] + SWEEP_RAD * p.lateral,
                    surface + p.depth_m,
                ]
            })
            .collect()
    };
    let mut haptic = HapticLoop::new(bank);
    // The path starts at the home pose (encoder zero): home there, as a host would.
    haptic.zero_encoders();
    haptic
        .arm()
        .map_err(|e| anyhow!("the loop refused to arm: {e:?}"))?;
    let mut times = Vec::with_capacity(ticks);
    let (mut touching, mut max_nodes, mut peak) = (0usize, 0usize, 0.0f32);
    let (mut faults, mut press_force) = (0, None);
    for k in 0..ticks {
        let inp = input(path[k % path.len()]);
        let t = Instant::now();
        let out = std::hint::black_box(haptic.tick(std::hint::black_box(inp)));
        times.push(t.elapsed().as_nanos() as u64);
        if out.contact_nodes > 0 {
            touching += 1;
            max_nodes = max_nodes.max(out.contact_nodes);
        }
        let f = out.tool_force_n;
        let magnitude = (f[0] * f[0] + f[1] * f[1] + f[2] * f[2]).sqrt();
        peak = peak.max(magnitude);
        if k % path.len() == press_end {
            press_force = Some(magnitude);
        }
        if out.new_fault.is_some() {
            faults += 1;
        }
    }
    times.sort_unstable();
    let pct = |p: f64| times[((times.len() - 1) as f64 * p) as usize];
    Ok(TickBench {
        ticks,
        touching,
        max_contact_nodes: max_nodes,
        peak_force_n: peak,
        press_force_n: press_force,
        faults,
        contact_insertion_m: surface,
        ns_mean: times.iter().sum::<u64>() as f64 / times.len() as f64,
        ns_median: pct(0.5),
        ns_p99: pct(0.99),
        ns_max: pct(1.0),
    })
}
