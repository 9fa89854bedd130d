//! `host bench tick`: the firmware's portable loop ([`firmware::tick::HapticLoop`]) run
//! natively on a bank along a scripted press, slide and release, timed per tick. What it
//! measures is the host CPU's time, not the MCU's (that is `host bench sil`, under QEMU); what
//! it checks is that the loop runs the bank without a fault and touches the organ.

use crate::kinematics::counts_for;
use anyhow::{Result, anyhow, bail};
use bank_format::Bank;
use firmware::tick::{HapticLoop, LoopInput};
use std::time::Instant;

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
/// out, repeated. Refuses a bank whose tool never touches along its rest axis, and `ticks` of
/// zero.
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
    let step = 5e-5;
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
    let mut path = Vec::new();
    let mut q = [home[0], home[1], surface - 0.005];
    while q[2] < bottom {
        q[2] += step;
        path.push(q);
    }
    let sweep = 0.05;
    for i in 0..2000 {
        let phase = i as f64 / 2000.0 * std::f64::consts::TAU;
        path.push([
            home[0] + 0.3 * sweep * phase.sin(),
            home[1] + sweep * phase.sin(),
            q[2],
        ]);
    }
    while q[2] > surface - 0.005 {
        q[2] -= step;
        path.push(q);
    }
    let mut haptic = HapticLoop::new(bank);
    // The path starts at the home pose (encoder zero): home there, as a host would.
    haptic.zero_encoders();
    haptic
        .arm()
        .map_err(|e| anyhow!("the loop refused to arm: {e:?}"))?;
    let mut times = Vec::with_capacity(ticks);
    let (mut touching, mut max_nodes, mut peak) = (0usize, 0usize, 0.0f32);
    let mut faults = 0;
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
        peak = peak.max((f[0] * f[0] + f[1] * f[1] + f[2] * f[2]).sqrt());
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
        faults,
        contact_insertion_m: surface,
        ns_mean: times.iter().sum::<u64>() as f64 / times.len() as f64,
        ns_median: pct(0.5),
        ns_p99: pct(0.99),
        ns_max: pct(1.0),
    })
}
