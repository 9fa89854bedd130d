//! The tick's phases for timing ([`HapticLoop::tick_marked`](super::HapticLoop::tick_marked)):
//! kinematics, detection, patch, solve, law and supervisor.

use bank_format::PhaseCycles;

use crate::hal::CycleCounter;

/// Counter readings at the ends of a tick's first five phases
/// ([`HapticLoop::tick_marked`](super::HapticLoop::tick_marked)); the caller's readings before
/// and after the tick bound the first and the last (supervisor) phase.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PhaseMarks {
    /// After encoder counts to joints, tip and Jacobian.
    pub kinematics: u32,
    /// After the contact tracker's update.
    pub detection: u32,
    /// After the patch (and its factored solve) for this tick.
    pub patch: u32,
    /// After the 3 x 3 solve and the node forces.
    pub solve: u32,
    /// After the law, the force cap and the requested currents.
    pub law: u32,
}

impl PhaseMarks {
    /// The phases' lengths between `start` (read before the tick) and `end` (after it),
    /// wrapping: they sum to `end - start`.
    pub fn phases(&self, start: u32, end: u32) -> PhaseCycles {
        PhaseCycles {
            kinematics: self.kinematics.wrapping_sub(start),
            detection: self.detection.wrapping_sub(self.kinematics),
            patch: self.patch.wrapping_sub(self.detection),
            solve: self.solve.wrapping_sub(self.patch),
            law: self.law.wrapping_sub(self.solve),
            supervisor: end.wrapping_sub(self.law),
        }
    }
}

/// The counter of an untimed tick ([`HapticLoop::tick`](super::HapticLoop::tick)): always 0,
/// compiled away.
pub(super) struct NoCounter;

impl CycleCounter for NoCounter {
    fn cycles(&self) -> u32 {
        0
    }
}
