//! The tick tests' fixture: a loop on a bank, built in the order a host drives it (homed,
//! armed, ramped in), and the ticks' inputs and invariants.

extern crate std;

use core::ops::{Deref, DerefMut};

use bank_format::{AlignedBytes, Bank, BankBuilder, DeviceCalibration, Mode, TissueLaw};

use super::{HapticLoop, LoopInput, LoopOutput, RAMP_IN_TICKS};
use crate::device::Device;
use crate::hal::Interlocks;
use crate::safety::{SafetyConfig, State};

/// The bank in a fixture's `bytes`.
pub(super) fn parse(bytes: &AlignedBytes) -> Bank<'_> {
    Bank::parse(bytes.as_slice()).unwrap()
}

/// Encoder counts for insertion `s` (m) straight down from the rest pose.
pub(super) fn counts_for_insertion(dev: &Device, s: f32) -> [i32; 3] {
    let k = dev.joint_per_count()[2];
    [0, 0, ((s - 0.05) / k).round() as i32]
}

/// A loop under test and a copy of its gimbal model (for the counts of a pose):
/// `Rig::new(&bank).homed().armed()`, then [`Rig::ramped`]; the loop's own methods through
/// `Deref`.
pub(super) struct Rig<'b> {
    lp: HapticLoop<'b>,
    /// The loop's gimbal model.
    pub(super) dev: Device,
}

impl<'b> Rig<'b> {
    /// A loop on `bank` as at power-up: the bank's safety thresholds, not referenced,
    /// disarmed, in `Render`.
    pub(super) fn new(bank: &'b Bank<'b>) -> Rig<'b> {
        Rig::with_config(bank, SafetyConfig::new(bank.device()))
    }

    /// [`Rig::new`] with explicit safety thresholds.
    pub(super) fn with_config(bank: &'b Bank<'b>, config: SafetyConfig) -> Rig<'b> {
        let lp = HapticLoop::with_config(bank, config);
        let dev = *lp.device();
        Rig { lp, dev }
    }

    /// Referenced at encoder zero, the home pose (a host's `ZeroEncoders` before the first
    /// tick).
    pub(super) fn homed(mut self) -> Rig<'b> {
        assert!(self.lp.zero_encoders());
        self
    }

    /// In `mode` (set while disarmed).
    pub(super) fn in_mode(mut self, mode: Mode) -> Rig<'b> {
        self.lp.set_mode(mode).unwrap();
        self
    }

    /// Armed (the ramp-in starts at the next tick).
    pub(super) fn armed(mut self) -> Rig<'b> {
        self.lp.arm().unwrap();
        self
    }

    /// Encoder counts for insertion `s` (m) straight down from the rest pose.
    pub(super) fn counts(&self, s: f32) -> [i32; 3] {
        counts_for_insertion(&self.dev, s)
    }

    /// One tick at insertion `s` (m).
    pub(super) fn at(&mut self, s: f32) -> LoopOutput {
        let counts = self.counts(s);
        self.lp.tick(input(counts))
    }

    /// Ticks at insertions `from + k step` for `k` in `0..=ticks` (a press at a constant
    /// speed); the last tick's output.
    pub(super) fn pressed(&mut self, from: f32, step: f32, ticks: u32) -> LoopOutput {
        let mut out = self.at(from);
        for k in 1..=ticks {
            out = self.at(from + step * k as f32);
        }
        out
    }

    /// Ticks at `counts` until the ramp-in after the last arm is over; the last tick's output
    /// (the first with the loop's whole output).
    pub(super) fn ramped(&mut self, counts: [i32; 3]) -> LoopOutput {
        let mut out = self.lp.tick(input(counts));
        for _ in 1..RAMP_IN_TICKS {
            out = self.lp.tick(input(counts));
        }
        out
    }
}

impl<'b> Deref for Rig<'b> {
    type Target = HapticLoop<'b>;

    fn deref(&self) -> &HapticLoop<'b> {
        &self.lp
    }
}

impl DerefMut for Rig<'_> {
    fn deref_mut(&mut self) -> &mut Self::Target {
        &mut self.lp
    }
}

/// A tick's input at `counts`: no overrun, the link live, no interlock.
pub(super) fn input(counts: [i32; 3]) -> LoopInput {
    LoopInput {
        encoder_counts: counts,
        overrun: false,
        link_silence_ticks: 0,
        interlocks: Interlocks::default(),
    }
}

/// The Euclidean norm.
pub(super) fn norm(v: [f32; 3]) -> f32 {
    v.iter().map(|x| x * x).sum::<f32>().sqrt()
}

/// Invariants of every tick.
pub(super) fn check(out: &LoopOutput, cal: &DeviceCalibration) {
    for (i, &lim) in out.currents_a.iter().zip(&cal.current_limit_a) {
        assert!(i.is_finite() && i.abs() <= lim, "{out:?}");
    }
    assert!(out.tip_m.iter().all(|x| x.is_finite()), "{out:?}");
    assert!(out.tool_force_n.iter().all(|x| x.is_finite()), "{out:?}");
    assert!(norm(out.tool_force_n) <= cal.max_force_n * (1.0 + 1e-5));
    if out.state != State::Armed {
        assert_eq!(out.currents_a, [0.0; 3]);
    }
}

/// A 3-node bank far below the tool (no contact ever), with or without gravity.
pub(super) fn gravity_bank(gravity: Option<bank_format::GravityCompensation>) -> AlignedBytes {
    let c = 1.0e-3;
    let diag =
        |v: f64| core::array::from_fn(|i| core::array::from_fn(|j| if i == j { v } else { 0.0 }));
    let b = BankBuilder {
        c_kk: std::vec![diag(c); 3],
        couplings: std::vec![
            (0, 1, diag(0.1 * c)),
            (0, 2, diag(0.1 * c)),
            (1, 2, diag(0.1 * c))
        ],
        mesh_ids: std::vec![0, 1, 2],
        triangles: std::vec![[0, 1, 2]],
        positions_m: std::vec![[0.0, 0.0, 0.0], [0.01, 0.0, 0.0], [0.0, 0.01, 0.0]],
        grid_cell_size_m: 0.005,
        truncation_radius_m: 0.005,
        scene_id: 3,
        law: TissueLaw::linear(0.0, 1.0, [0.0, 5.0]).unwrap(),
        gravity,
        relaxation: None,
        samples: None,
        device: crate::fixtures::bench_device([0.0, 0.0, 0.3]),
    };
    AlignedBytes::new(&b.build().unwrap())
}
