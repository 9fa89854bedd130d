//! The embassy-time driver on SysTick (QEMU models no RCC, so chip timers are out), and the
//! instruction counter the loop measures itself with.
//!
//! SysTick runs from the 168 MHz core clock and interrupts once per millisecond; the driver's
//! time base is that millisecond count (`tick-hz-1_000`). Under QEMU's `-icount shift=3` every
//! instruction advances virtual time by 2^3 ns, i.e. SysTick by 0.168 x 8 = 1.344 counts, so
//! 168 counts are exactly 125 instructions: [`InstructionCounter`] reads the SysTick position
//! as a count of virtual core cycles and [`instructions`] converts (on a board DWT's cycle
//! counter takes its place).

use core::cell::{Cell, RefCell};
use core::task::Waker;
use cortex_m::peripheral::SYST;
use cortex_m::peripheral::syst::SystClkSource;
use cortex_m_rt::exception;
use critical_section::Mutex;
use embassy_time_driver::Driver;
use embassy_time_queue_utils::Queue;
use firmware::hal::CycleCounter;

/// Core clock, Hz (the STM32F405 at full speed; QEMU's netduinoplus2 SysTick clock).
const CORE_HZ: u32 = 168_000_000;
/// SysTick counts per millisecond period (virtual core cycles: the tick's period for its
/// [`firmware::deadline::TickWatch`]).
pub const COUNTS_PER_PERIOD: u32 = CORE_HZ / 1_000;

struct SysTickDriver {
    /// Milliseconds since `start`, and the timer queue.
    state: Mutex<(Cell<u64>, RefCell<Queue>)>,
}

embassy_time_driver::time_driver_impl!(static DRIVER: SysTickDriver = SysTickDriver {
    state: Mutex::new((Cell::new(0), RefCell::new(Queue::new()))),
});

impl Driver for SysTickDriver {
    fn now(&self) -> u64 {
        critical_section::with(|cs| self.state.borrow(cs).0.get())
    }

    fn schedule_wake(&self, at: u64, waker: &Waker) {
        critical_section::with(|cs| {
            let (now, queue) = self.state.borrow(cs);
            let mut queue = queue.borrow_mut();
            if queue.schedule_wake(at, waker) {
                // Already due: wake now rather than at the next period.
                queue.next_expiration(now.get());
            }
        });
    }
}

/// Start SysTick: 1 ms period from the core clock, interrupt enabled.
pub fn start(syst: &mut SYST) {
    syst.set_clock_source(SystClkSource::Core);
    syst.set_reload(COUNTS_PER_PERIOD - 1);
    syst.clear_current();
    syst.enable_interrupt();
    syst.enable_counter();
}

/// Milliseconds since [`start`] (the current period's number).
pub fn period() -> u64 {
    DRIVER.now()
}

#[exception]
fn SysTick() {
    critical_section::with(|cs| {
        let (now, queue) = DRIVER.state.borrow(cs);
        now.set(now.get() + 1);
        queue.borrow_mut().next_expiration(now.get());
    });
}

/// The loop's cycle counter: SysTick counts since [`start`] (virtual core cycles at 168 MHz,
/// wrapping), cheap to read (no 64-bit division: the tick reads it seven times);
/// [`instructions`] turns a difference of two readings into instructions.
pub struct InstructionCounter;

impl InstructionCounter {
    /// Instructions since the SysTick interrupt that began the current period.
    pub fn since_period_start(&self) -> u32 {
        instructions(elapsed_in_period())
    }
}

impl CycleCounter for InstructionCounter {
    fn cycles(&self) -> u32 {
        critical_section::with(|cs| {
            // Wrapping: only differences of readings are used.
            let ms = DRIVER.state.borrow(cs).0.get() as u32;
            let mut within = elapsed_in_period();
            // A wrap not yet counted (interrupts are masked here): the period has ended.
            let ms = if cortex_m::peripheral::SCB::is_pendst_pending() {
                within = elapsed_in_period();
                ms.wrapping_add(1)
            } else {
                ms
            };
            ms.wrapping_mul(COUNTS_PER_PERIOD).wrapping_add(within)
        })
    }
}

/// SysTick counts since the start of the current period (it counts down from the reload).
fn elapsed_in_period() -> u32 {
    COUNTS_PER_PERIOD - 1 - SYST::get_current()
}

/// 168 SysTick counts = 125 instructions under `-icount shift=3` (rounded down; saturates
/// past 34 million counts, 200 ms, far beyond any tick).
pub fn instructions(counts: u32) -> u32 {
    counts.saturating_mul(125) / 168
}
