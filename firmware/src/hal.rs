//! The boundary between the portable firmware and the hardware: encoders in, motor currents
//! out, interlock inputs, and a cycle counter. An image implements these traits for its
//! platform (the QEMU software-in-the-loop image: a lockstep plant channel and SysTick; the
//! board: timer encoders, PWM set values and enable lines of current-mode amplifiers, GPIO
//! interlocks and DWT) and hands them to [`crate::app::App::tick`], which holds everything
//! else. The host link is not a trait: it is the pair of queues of [`crate::link`], drained by
//! the image's link task.

/// The gimbal's encoders and motor drivers.
pub trait Plant {
    /// Why the plant could not be read or written (the image stops the loop on it).
    type Error;

    /// Latch the encoder counts (pitch, yaw, insertion), extended to `i32`
    /// ([`crate::encoder::Extender`] for 16-bit timers).
    fn read_encoders(&mut self) -> Result<[i32; 3], Self::Error>;

    /// Drive the motors with `currents_a` (A, zero unless armed; the supervisor has clamped
    /// them to their limits).
    fn drive(&mut self, currents_a: [f32; 3]) -> Result<(), Self::Error>;

    /// Put every motor in its safe state at once (amplifiers disabled, zero set value). Called
    /// when the application stops driving; cannot fail.
    fn disable(&mut self);

    /// The interlock inputs this tick (e-stop, amplifier fault outputs). A plant without any
    /// reports none.
    fn interlocks(&mut self) -> Interlocks {
        Interlocks::default()
    }
}

/// Hardware interlock inputs, read every tick; any one latches a fault with zero current.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Interlocks {
    /// The emergency stop is pressed (or its loop is open).
    pub estop: bool,
    /// Amplifier `j` reports a fault on its fault output.
    pub amplifier_fault: [bool; 3],
}

/// A free-running cycle counter (wrapping): CPU cycles on a board, instructions under QEMU.
pub trait CycleCounter {
    /// The counter now.
    fn cycles(&self) -> u32;
}
