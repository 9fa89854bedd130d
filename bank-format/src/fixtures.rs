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

/// SplitMix64 (Steele, Lea & Flood, OOPSLA 2014), the tests' seeded stream: the same seed
/// gives the same values on every platform. Not for anything secret.
#[derive(Clone, Debug)]
pub struct SplitMix64(u64);

impl SplitMix64 {
    /// A stream from `seed`.
    pub fn new(seed: u64) -> SplitMix64 {
        SplitMix64(seed)
    }

    /// The next 64 bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1) (24 bits, every value exact in f32).
    pub fn unit_f32(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 / (1u32 << 24) as f32
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The reference stream of SplitMix64 from seed 0 (the first outputs given with the
    /// algorithm's public-domain C code by Vigna).
    #[test]
    fn matches_the_reference_stream() {
        let mut r = SplitMix64::new(0);
        assert_eq!(r.next_u64(), 0xe220_a839_7b1d_cdaf);
        assert_eq!(r.next_u64(), 0x6e78_9e6a_a1b9_65f4);
        assert_eq!(r.next_u64(), 0x06c4_5d18_8009_454f);
    }
}
