//! Test fixtures shared by this crate's tests and the firmware's (`firmware::fixtures`
//! re-exports them): the bench gimbal hand-made test banks use, and the seeded generator the
//! tests draw reproducible "random" values from. Compiled only for tests or with the
//! `test-fixtures` feature; never in a firmware image.

use crate::DeviceCalibration;

/// The fixture devices' link timeout, ms: 10 ticks at 1 kHz, which the tests' silence counts
/// are written against (a scene's default is [`crate::DEFAULT_LINK_TIMEOUT_MS`]).
pub const FIXTURE_LINK_TIMEOUT_MS: u32 = 10;

/// A bench gimbal for hand-made test banks: shaft down from `fulcrum_m` (m), pitch and yaw
/// +-0.8 rad, insertion 2-20 cm (home 5 cm), a 2 mm tool tip.
pub fn bench_device(fulcrum_m: [f32; 3]) -> DeviceCalibration {
    DeviceCalibration {
        fulcrum_m,
        shaft_axis: [0.0, 0.0, -1.0],
        pitch_axis: [1.0, 0.0, 0.0],
        yaw_axis: [0.0, 1.0, 0.0],
        joint_min: [-0.8, -0.8, 0.02],
        joint_max: [0.8, 0.8, 0.2],
        home_joint: [0.0, 0.0, 0.05],
        counts_per_rev: [4096, 4096, 2048],
        transmission: [10.0, -10.0, 100.0],
        torque_constant_nm_per_a: [0.03, 0.03, 0.025],
        current_limit_a: [2.0, 2.0, 1.5],
        max_force_n: 5.0,
        tip_radius_m: 0.002,
        max_tip_speed_m_s: 1.0,
        max_joint_speed: [10.0, 10.0, 1.0],
        link_timeout_ms: FIXTURE_LINK_TIMEOUT_MS,
    }
}

/// The tests' seeded stream (the workspace's one generator).
pub use splitmix::SplitMix64;
