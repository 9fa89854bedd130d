//! The board's [`Plant`] and [`CycleCounter`]: the encoder timers' 16-bit counters extended to
//! `i32` ([`Extender`]), motor currents to PWM compare values and enables through each axis's
//! [`firmware::amplifier::Amplifier`], the interlock inputs (which also gate the enables here:
//! no amplifier is driven while the e-stop or any amplifier fault input is active); DWT's cycle
//! counter. What is where comes from `board.rs`.

use core::convert::Infallible;

use firmware::amplifier::Setpoint;
use firmware::encoder::Extender;
use firmware::hal::{CycleCounter, Interlocks, Plant};

use crate::board::{BOARD, Hardware};

/// The device as the loop sees it.
pub struct BoardPlant {
    hw: Hardware,
    encoders: [Extender; 3],
}

impl BoardPlant {
    /// The plant over the configured hardware, with the motors off; the encoders count from 0
    /// at their present reading.
    pub fn new(hw: Hardware) -> BoardPlant {
        let encoders = hw.encoder_counters().map(Extender::new);
        let mut plant = BoardPlant { hw, encoders };
        plant.disable();
        plant
            .hw
            .set_compares([Setpoint::SAFE.compare(plant.hw.max_duty()); 3]);
        plant
    }
}

impl Plant for BoardPlant {
    /// Timers and pins are read and written without fail.
    type Error = Infallible;

    fn read_encoders(&mut self) -> Result<[i32; 3], Infallible> {
        let raw = self.hw.encoder_counters();
        let mut counts = [0i32; 3];
        let per_axis = counts
            .iter_mut()
            .zip(self.encoders.iter_mut())
            .zip(raw.iter().zip(BOARD.encoder_inverted));
        for ((count, extender), (&raw, inverted)) in per_axis {
            let c = extender.update(raw);
            *count = if inverted { c.wrapping_neg() } else { c };
        }
        Ok(counts)
    }

    fn drive(&mut self, currents_a: [f32; 3]) -> Result<(), Infallible> {
        // Defence in depth: whatever the application decided, no amplifier is enabled while
        // an interlock input is active (the application latches and reports the fault; this
        // holds the motors off in the same tick, whatever the application does with it).
        let interlocks = self.hw.interlocks();
        if interlocks.estop || interlocks.amplifier_fault.iter().any(|&f| f) {
            self.disable();
            return Ok(());
        }
        let max = self.hw.max_duty();
        let mut compares = [0u16; 3];
        let mut enables = [false; 3];
        let per_axis = compares
            .iter_mut()
            .zip(enables.iter_mut())
            .zip(BOARD.amplifiers.iter().zip(currents_a));
        for ((compare, enable), (amplifier, current)) in per_axis {
            let s = amplifier.setpoint(current, true);
            *compare = s.compare(max);
            *enable = s.enable;
        }
        // Set value first, so an amplifier being enabled starts at its new set value.
        self.hw.set_compares(compares);
        self.hw.set_enables(enables);
        Ok(())
    }

    fn disable(&mut self) {
        self.hw.set_enables([false; 3]);
        self.hw
            .set_compares([Setpoint::SAFE.compare(self.hw.max_duty()); 3]);
    }

    fn interlocks(&mut self) -> Interlocks {
        self.hw.interlocks()
    }
}

/// The Cortex-M4 cycle counter (DWT `CYCCNT`, enabled at boot), at the core clock.
pub struct DwtCycles;

impl CycleCounter for DwtCycles {
    fn cycles(&self) -> u32 {
        cortex_m::peripheral::DWT::cycle_count()
    }
}
