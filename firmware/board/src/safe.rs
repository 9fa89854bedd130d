//! The motors' safe state without the HAL: the amplifier enables driven off with direct
//! register writes, from `board::ENABLES_OFF` (port BSRR words computed at compile time from
//! `board.rs` by [`firmware::stm32_gpio`]). Used
//!
//! - at boot, before the clocks and the HAL are set up: the enable pins become outputs at their
//!   off level ([`hold_enables_off_at_boot`]); the board's pull-downs hold them off before that;
//! - by the panic handler, the HardFault handler, the NMI handler (a failed crystal, through
//!   the clock security system) and the default handler of every other exception and
//!   interrupt, which first drive the enables off, then mask interrupts (so the
//!   tick cannot turn them on again), drive them off once more and wait for the independent
//!   watchdog to reset the chip (which it does within its timeout once the tick stops feeding
//!   it; before the watchdog is started they wait with the motors off).

use crate::board::ENABLES_OFF;
use firmware::stm32_gpio::{RCC_AHB1ENR, port_bsrr_address, port_moder_address};

/// Drive every amplifier enable off: one BSRR store per port (atomic, no read-modify-write).
#[inline(always)]
pub fn enables_off() {
    for (port, &word) in (0u32..).zip(ENABLES_OFF.bsrr.iter()) {
        if word != 0 {
            // SAFETY: a BSRR store of a GPIO port that exists on this chip; it only changes
            // the output latch of the pins whose bits are set (the enables).
            unsafe { core::ptr::write_volatile(port_bsrr_address(port) as *mut u32, word) };
        }
    }
}

/// First thing at boot: clock the enables' ports, set their output latches off, make them
/// outputs. Runs before the HAL exists, with interrupts not yet enabled.
pub fn hold_enables_off_at_boot() {
    // SAFETY: single-threaded start-up code before any other user of RCC or GPIO; the
    // read-modify-writes touch only the bits of the enable pins and their ports' clocks.
    unsafe {
        let rcc = RCC_AHB1ENR as *mut u32;
        rcc.write_volatile(rcc.read_volatile() | ENABLES_OFF.rcc_ahb1enr);
        // Read back twice: a peripheral's registers are usable two AHB cycles after its clock
        // is enabled (STM32F40x errata, "delay after an RCC peripheral clock enabling").
        let _ = rcc.read_volatile();
        let _ = rcc.read_volatile();
    }
    enables_off();
    let masks = ENABLES_OFF.moder_mask.iter().zip(ENABLES_OFF.moder_output);
    for (port, (&mask, output)) in (0u32..).zip(masks) {
        if mask != 0 {
            let moder = port_moder_address(port) as *mut u32;
            // SAFETY: as above; only the enable pins' mode bits change.
            unsafe { moder.write_volatile((moder.read_volatile() & !mask) | output) };
        }
    }
}

/// Motors off, interrupts masked, then wait for the watchdog.
#[inline(always)]
pub fn stop() -> ! {
    enables_off();
    cortex_m::interrupt::disable();
    enables_off();
    loop {
        cortex_m::asm::nop();
    }
}

#[panic_handler]
fn panic(_info: &core::panic::PanicInfo) -> ! {
    stop()
}

#[cortex_m_rt::exception(trampoline = false)]
unsafe fn HardFault() -> ! {
    stop()
}

/// The NMI: on this board, the clock security system's (the HSE crystal failed; the hardware
/// has switched the core to the HSI and stopped the PLL, so the tick's timing and USB are
/// gone). Motors off and wait for the watchdog, as on any fault. The NMI cannot be masked and
/// is not cleared here (CSSF stays set): the handler never returns, so it is not re-entered.
#[cortex_m_rt::exception]
unsafe fn NonMaskableInt() {
    stop()
}

#[cortex_m_rt::exception]
unsafe fn DefaultHandler(_irqn: i16) -> ! {
    stop()
}
