//! The virtual device: the firmware's portable loop ([`firmware::tick::HapticLoop`]) on a bank,
//! ticking at 1 kHz in its own thread on the PC, with a virtual hand on the encoders.
//!
//! The hand follows a joint target (set by the mouse or a script through [`Source::steering`]) at a
//! bounded speed, well under the supervisor's speed thresholds (the scene's defaults: 10 rad/s,
//! 10 rad/s and 1 m/s per joint, 1 m/s at the tip), and its joint values become
//! encoder counts through the bank's calibration ([`crate::kinematics::counts_for`], the inverse of
//! [`firmware::device::Device::joints`]), so the tip goes through the same device model as on the
//! hardware. Every tick publishes a [`Sample`]; readers take the newest one (a slow display
//! drops samples, the loop never waits for it). Ticks are scheduled on an absolute 1 ms grid;
//! how late each one starts is the jitter. A PC is not a real-time system: the loop does not
//! report a late tick as an overrun to the supervisor (that would latch a fault the hardware
//! would not have), it counts it in [`LoopStats`]. The loop thread asks for real-time
//! scheduling (SCHED_FIFO) and runs without it when refused. A fault raised anyway (e.g. a solve error)
//! is cleared and the loop re-armed after 0.5 s, so the demo continues.

use crate::display::source::{LoopStats, Mailbox, Sample, Source, Steering};
use crate::kinematics::{clamp_joints, counts_for};
use anyhow::{Result, anyhow};
use bank_format::{AlignedBytes, Bank, DeviceCalibration};
use firmware::hal::Interlocks;
use firmware::tick::{HapticLoop, LoopInput};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// Tick period ([`firmware::TICK_HZ`]).
const PERIOD: Duration = Duration::from_micros(1_000_000 / firmware::TICK_HZ as u64);
/// Largest hand speed per tick: pitch and yaw (rad), insertion (m); 3 rad/s and 0.5 m/s.
const MAX_STEP: [f64; 3] = [0.003, 0.003, 0.0005];
/// Lateness histogram: bins of 10 µs up to 50 ms (the last bin holds everything later).
const JITTER_BIN_US: f64 = 10.0;
const JITTER_BINS: usize = 5000;

/// Ticks after a fault before the virtual device clears it and re-arms.
const REARM_AFTER_TICKS: u32 = 500;

struct Shared {
    target: Mutex<[f64; 3]>,
    mailbox: Mailbox,
    stop: AtomicBool,
}

/// The firmware loop at 1 kHz on the PC (see the module notes).
pub struct VirtualDevice {
    shared: Arc<Shared>,
    cal: DeviceCalibration,
    thread: Option<JoinHandle<()>>,
    last_tick: Option<u32>,
}

impl VirtualDevice {
    /// Starts the loop on `bank` (validated here), armed, the hand at the home pose.
    pub fn start(bank: Vec<u8>) -> Result<VirtualDevice> {
        let aligned = AlignedBytes::new(&bank);
        let parsed = Bank::parse(&aligned).map_err(|e| anyhow!("invalid bank: {e}"))?;
        let cal = *parsed.device();
        let home = clamp_joints(&cal, cal.home_joint.map(f64::from));
        let shared = Arc::new(Shared {
            target: Mutex::new(home),
            mailbox: Mailbox::default(),
            stop: AtomicBool::new(false),
        });
        let inner = Arc::clone(&shared);
        let thread = std::thread::Builder::new()
            .name("haptic-loop".into())
            .spawn(move || run(&aligned, &inner, home))?;
        Ok(VirtualDevice {
            shared,
            cal,
            thread: Some(thread),
            last_tick: None,
        })
    }
}

impl Drop for VirtualDevice {
    fn drop(&mut self) {
        self.shared.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

impl Source for VirtualDevice {
    fn latest(&mut self, timeout: Duration) -> Result<Option<Sample>> {
        self.shared.mailbox.newer(&mut self.last_tick, timeout)
    }

    fn stats(&self) -> LoopStats {
        self.shared.mailbox.stats()
    }

    fn steering(&self) -> Option<Steering> {
        let shared = Arc::clone(&self.shared);
        let cal = self.cal;
        Some(Arc::new(move |q: [f64; 3]| {
            if let Ok(mut t) = shared.target.lock() {
                *t = clamp_joints(&cal, q);
            }
        }))
    }
}

/// The loop thread.
fn run(bytes: &AlignedBytes, shared: &Shared, home: [f64; 3]) {
    let Ok(bank) = Bank::parse(bytes) else {
        return;
    };
    let cal = *bank.device();
    let realtime = crate::realtime::request();
    let mut haptic = HapticLoop::new(&bank);
    // The hand starts at the home pose (encoder zero): the homing the loop needs to arm.
    haptic.zero_encoders();
    let _ = haptic.arm();
    let mut q = home;
    let start = Instant::now();
    let mut next = start;
    let mut stats = LoopStats {
        max_jitter_us: Some(0.0),
        realtime,
        ..LoopStats::default()
    };
    let mut ticks: u64 = 0;
    let mut histogram = vec![0u64; JITTER_BINS];
    let mut fault_ticks = 0u32;
    while !shared.stop.load(Ordering::Relaxed) {
        let now = Instant::now();
        if now < next {
            std::thread::sleep(next - now);
        }
        let began = Instant::now();
        let late = began.saturating_duration_since(next);
        if late > 50 * PERIOD {
            // Suspended (debugger, machine overload): restart the schedule rather than burst.
            next = began;
        } else {
            let us = late.as_secs_f64() * 1e6;
            stats.max_jitter_us = stats.max_jitter_us.map(|m| m.max(us));
            let bin = ((us / JITTER_BIN_US) as usize).min(JITTER_BINS - 1);
            if let Some(h) = histogram.get_mut(bin) {
                *h += 1;
            }
        }
        let target = shared.target.lock().map(|t| *t).unwrap_or(q);
        for i in 0..3 {
            q[i] += (target[i] - q[i]).clamp(-MAX_STEP[i], MAX_STEP[i]);
        }
        let out = haptic.tick(LoopInput {
            encoder_counts: counts_for(&cal, q),
            overrun: false,
            link_silence_ticks: 0,
            // A PC has no e-stop or amplifier fault lines.
            interlocks: Interlocks::default(),
        });
        ticks += 1;
        if out.new_fault.is_some() {
            stats.faults += 1;
        }
        if matches!(out.state, firmware::safety::State::Fault(_)) {
            fault_ticks += 1;
            if fault_ticks >= REARM_AFTER_TICKS {
                haptic.clear_fault();
                let _ = haptic.arm();
                fault_ticks = 0;
            }
        }
        let f = out.tool_force_n;
        let force = f64::from((f[0] * f[0] + f[1] * f[1] + f[2] * f[2]).sqrt());
        stats.peak_force_n = stats.peak_force_n.max(force);
        let elapsed = began.duration_since(start).as_secs_f64();
        if elapsed > 0.0 {
            stats.tick_rate_hz = ticks as f64 / elapsed;
        }
        // Every 256 ticks.
        if ticks & 0xff == 0 {
            stats.p99_jitter_us = Some(percentile(&histogram, 0.99));
        }
        let sample = Sample {
            tick: out.tick,
            state: out.state.wire(),
            fault: out.fault.map(|f| f.reason),
            tip_m: out.tip_m,
            contacts: haptic.contacts().clone(),
            contact_point: haptic.contact_point(),
            tool_force_n: out.tool_force_n,
            mode: haptic.mode(),
            currents_a: out.currents_a,
        };
        shared.mailbox.publish(sample, stats);
        next += PERIOD;
    }
}

/// Upper edge (µs) of the histogram bin holding quantile `q`.
fn percentile(histogram: &[u64], q: f64) -> f64 {
    let total: u64 = histogram.iter().sum();
    let want = (q * total as f64).ceil() as u64;
    let mut seen = 0;
    for (i, &n) in histogram.iter().enumerate() {
        seen += n;
        if seen >= want {
            return (i + 1) as f64 * JITTER_BIN_US;
        }
    }
    histogram.len() as f64 * JITTER_BIN_US
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The hand at its top speed on all three joints at once, reversing at the ends of the
    /// shipped scene's ranges, never trips the supervisor's speed checks (the scene's default
    /// thresholds; the encoders quantise as the real ones do).
    #[test]
    fn the_hand_at_top_speed_never_trips_the_speed_checks() {
        use firmware::device::Device;
        use firmware::safety::{SafetyConfig, Supervisor, TickInput};
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/liver.toml");
        let cal = crate::scene::Scene::load(&path).unwrap().device;
        let dev = Device::new(&cal);
        let mut sup = Supervisor::new(SafetyConfig::new(&cal));
        let (lo, hi) = (cal.joint_min.map(f64::from), cal.joint_max.map(f64::from));
        let mut q = clamp_joints(&cal, cal.home_joint.map(f64::from));
        let mut target = hi;
        let mut prev_tip: Option<[f32; 3]> = None;
        let mut peak = 0.0f32;
        sup.arm(true, true).unwrap();
        for tick in 0..5000 {
            for i in 0..3 {
                if (target[i] - q[i]).abs() < 1e-12 {
                    target[i] = if target[i] == hi[i] { lo[i] } else { hi[i] };
                }
                q[i] += (target[i] - q[i]).clamp(-MAX_STEP[i], MAX_STEP[i]);
            }
            let counts = counts_for(&cal, q);
            let joints = dev.joints(counts);
            let tip = dev.tip(&joints);
            let out = sup.tick(&TickInput {
                counts,
                joints: joints.to_array(),
                tip_m: tip,
                ..TickInput::quiet()
            });
            assert_eq!(out.new_fault, None, "tick {tick}: {q:?}");
            if let Some(p) = prev_tip {
                let d: f32 = (0..3).map(|i| (tip[i] - p[i]).powi(2)).sum();
                peak = peak.max(d.sqrt() * firmware::TICK_HZ as f32);
            }
            prev_tip = Some(tip);
        }
        // It really moved fast: well over half the 1 m/s tip threshold.
        assert!(peak > 0.6 && peak < cal.max_tip_speed_m_s, "{peak}");
    }

    #[test]
    fn percentile_reads_the_histogram() {
        let mut h = vec![0u64; 10];
        h[0] = 98;
        h[3] = 1;
        h[7] = 1;
        assert_eq!(percentile(&h, 0.5), 10.0);
        assert_eq!(percentile(&h, 0.99), 40.0);
        assert_eq!(percentile(&h, 1.0), 80.0);
    }
}
