//! The simulated gimbal the firmware drives in software in the loop: three rigid joints (pitch,
//! yaw: rotational; insertion: prismatic) with inertia and viscous friction, the motors' effort
//! from the commanded currents, and the user's hand pulling the instrument towards a scripted
//! pose through a stiff, damped grip. Encoder counts are the joints quantised like the real
//! encoders.
//!
//! Per joint j, with motor current `i_j`:
//! `m_j q''_j = k_j (q_hand_j - q_j) + d_j (q'_hand_j - q'_j) - b_j q'_j + i_j g_j Kt_j`,
//! where `g_j` is the transmission (motor rad per joint rad or per m) and `Kt_j` the torque
//! constant, so `i g Kt` is exactly the joint effort the firmware asked for with
//! `i = tau / (g Kt)` (see `firmware::device`). With a gravity load
//! ([`PlantParams::gravity`]) the instrument's weight adds `-tau_g(q)`, the generalised force
//! of the potential `V` of `bank-format`'s `SPEC.md` ("gravity"), to the right-hand side.
//! Integrated with semi-implicit Euler in [`SUBSTEPS`] steps per 1 ms tick (f64).

use crate::kinematics::counts_for;
use bank_format::DeviceCalibration;

/// Integration steps per tick.
pub const SUBSTEPS: usize = 10;
/// The tick, s ([`firmware::TICK_HZ`]).
pub const TICK_S: f64 = 1.0 / firmware::TICK_HZ as f64;

/// Mechanical constants of the simulated device and hand.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlantParams {
    /// Inertia (kg m^2) of pitch and yaw, mass (kg) of insertion, each with the hand's share.
    pub inertia: [f64; 3],
    /// Viscous friction of the joints: N m s/rad, N m s/rad, N s/m.
    pub friction: [f64; 3],
    /// Stiffness of the hand's grip towards the scripted pose: N m/rad, N m/rad, N/m.
    pub hand_stiffness: [f64; 3],
    /// Damping of the grip: N m s/rad, N m s/rad, N s/m.
    pub hand_damping: [f64; 3],
    /// The instrument's weight as the coefficients of its potential (`SPEC.md`, "gravity";
    /// [`crate::calibrate::gravity::efforts`]); `None`: weightless, as the SIL runs by default.
    pub gravity: Option<[f64; bank_format::GRAVITY_COEFFS]>,
}

impl Default for PlantParams {
    /// A light laparoscopic gimbal held firmly: about 2 kN/m and 20 N s/m at the tip (10 cm
    /// lever for pitch and yaw), 0.1 kg moving along the shaft.
    fn default() -> PlantParams {
        PlantParams {
            inertia: [1.0e-3, 1.0e-3, 0.1],
            friction: [1.0e-3, 1.0e-3, 0.5],
            hand_stiffness: [20.0, 20.0, 2000.0],
            hand_damping: [0.2, 0.2, 20.0],
            gravity: None,
        }
    }
}

/// The gimbal's state and constants.
#[derive(Clone, Debug)]
pub struct Gimbal {
    params: PlantParams,
    /// The encoders' calibration (counts per joint unit, home pose).
    cal: DeviceCalibration,
    /// Joint effort per ampere, `g Kt`.
    effort_per_amp: [f64; 3],
    q: [f64; 3],
    qd: [f64; 3],
}

impl Gimbal {
    /// At rest in the calibration's home pose (encoders at zero).
    pub fn new(cal: &DeviceCalibration, params: PlantParams) -> Gimbal {
        Gimbal::at_rest(cal, params, cal.home_joint.map(f64::from))
    }

    /// At rest at joint values `q` (pitch rad, yaw rad, insertion m); the encoders read
    /// [`counts_for`] them.
    pub fn at_rest(cal: &DeviceCalibration, params: PlantParams, q: [f64; 3]) -> Gimbal {
        Gimbal {
            params,
            effort_per_amp: std::array::from_fn(|j| {
                f64::from(cal.transmission[j]) * f64::from(cal.torque_constant_nm_per_a[j])
            }),
            cal: *cal,
            q,
            qd: [0.0; 3],
        }
    }

    /// Joint values: pitch rad, yaw rad, insertion m.
    pub fn joints(&self) -> [f64; 3] {
        self.q
    }

    /// Joint speeds.
    pub fn speeds(&self) -> [f64; 3] {
        self.qd
    }

    /// What the encoders read ([`counts_for`] the joint values).
    pub fn encoder_counts(&self) -> [i32; 3] {
        counts_for(&self.cal, self.q)
    }

    /// Advance one tick with the motor currents `currents_a` held and the hand moving linearly
    /// from `hand_from` to `hand_to` (joint space). Non-finite currents count as zero.
    pub fn step(&mut self, currents_a: [f32; 3], hand_from: [f64; 3], hand_to: [f64; 3]) {
        let p = &self.params;
        let h = TICK_S / SUBSTEPS as f64;
        for s in 1..=SUBSTEPS {
            let a = s as f64 / SUBSTEPS as f64;
            let weight = p
                .gravity
                .map(|c| crate::calibrate::gravity::efforts(&c, self.q));
            for j in 0..3 {
                let target = hand_from[j] + a * (hand_to[j] - hand_from[j]);
                let target_speed = (hand_to[j] - hand_from[j]) / TICK_S;
                let i = f64::from(currents_a[j]);
                let motor = if i.is_finite() {
                    i * self.effort_per_amp[j]
                } else {
                    0.0
                };
                let mut force = p.hand_stiffness[j] * (target - self.q[j])
                    + p.hand_damping[j] * (target_speed - self.qd[j])
                    - p.friction[j] * self.qd[j]
                    + motor;
                if let Some(tau_g) = weight {
                    force -= tau_g[j];
                }
                self.qd[j] += h * force / p.inertia[j];
                self.q[j] += h * self.qd[j];
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cal() -> DeviceCalibration {
        firmware::fixtures::liver_device()
    }

    #[test]
    fn hand_settles_on_target_and_encoders_quantise() {
        let mut g = Gimbal::new(&cal(), PlantParams::default());
        let target = [0.1, -0.05, 0.08];
        for _ in 0..2000 {
            g.step([0.0; 3], target, target);
        }
        for (q, t) in g.joints().iter().zip(&target) {
            assert!((q - t).abs() < 1e-6, "{:?}", g.joints());
        }
        // 0.05 m of insertion at 4096 * 400 / 2 pi counts per m.
        let expect = (0.05 * 4096.0 * 400.0 / (2.0 * std::f64::consts::PI)).round() as i32;
        assert_eq!(g.encoder_counts()[2], expect);
    }

    #[test]
    fn motor_effort_balances_the_grip_statically() {
        // A constant insertion current i pushes against the grip: at rest
        // k (target - q) + i g Kt = 0, i.e. q = target + i g Kt / k.
        let mut g = Gimbal::new(&cal(), PlantParams::default());
        let target = [0.0, 0.0, 0.08];
        let i = -0.5f32;
        for _ in 0..3000 {
            g.step([0.0, 0.0, i], target, target);
        }
        let expect = 0.08 + f64::from(i) * 400.0 * 0.025 / 2000.0;
        assert!((g.joints()[2] - expect).abs() < 1e-7, "{:?}", g.joints());
    }
}
