//! The software-in-the-loop image: the firmware exactly as it would be flashed, run by QEMU's
//! `netduinoplus2` (an STM32F405) against the host's plant simulator.
//!
//! - The bank is not compiled in. QEMU loads the bank file into the flash's bank region
//!   (`-device loader,file=x.bank,addr=0x08040000`), as flashing would, and the image validates
//!   it at boot with [`Bank::parse`] on `__bank_start..__bank_end` (linker symbols of the
//!   top-level `memory.x`). An invalid bank leaves the motors at zero current and the reason on
//!   the link ([`firmware::app`]).
//! - embassy-executor runs the 1 kHz tick as a task on an embassy-time `Ticker`; the time
//!   driver is SysTick ([`systick`]). The executor idles on WFI, which under QEMU's
//!   `-icount shift=3,sleep=off` makes runs deterministic.
//! - The host link is USART1 ([`usart`]), the plant (encoders in, currents out) a lockstep
//!   semihosting channel ([`plant`]) that holds virtual time while the host answers.
//!
//! The image exits (semihosting) when the plant channel closes: code 0 for a clean close, 1
//! for a plant error, 101 for a panic.
#![no_std]
#![no_main]

mod plant;
mod systick;
mod usart;

use bank_format::{Bank, BankError};
use core::sync::atomic::{AtomicBool, Ordering};
use embassy_executor::raw::Executor;
use embassy_time::{Duration, Ticker};
use firmware::app::App;

use crate::plant::{PlantChannel, PlantError};
use crate::systick::InstructionCounter;
use crate::usart::Usart1;

unsafe extern "C" {
    static __bank_start: u8;
    static __bank_end: u8;
}

/// The flash's bank region, as the linker script places it.
fn bank_region() -> &'static [u8] {
    // SAFETY: `memory.x` defines `__bank_start..__bank_end` as the BANK flash region, which is
    // mapped, read-only and never written while the firmware runs.
    unsafe {
        let start = &raw const __bank_start;
        let end = &raw const __bank_end;
        core::slice::from_raw_parts(start, end as usize - start as usize)
    }
}

/// Set by the executor's pender when a task was woken; cleared before each poll.
static WORK: AtomicBool = AtomicBool::new(true);

/// Wake the thread-mode executor loop (called by embassy when a task is woken).
#[unsafe(export_name = "__pender")]
fn pender(_context: *mut ()) {
    WORK.store(true, Ordering::Release);
}

/// The 1 kHz tick: wait for the period, run one [`App::tick`], measure it.
#[embassy_executor::task]
async fn haptic(mut app: App<'static>, mut plant: PlantChannel, mut link: Usart1) {
    let counter = InstructionCounter;
    let mut ticker = Ticker::every(Duration::from_hz(firmware::TICK_HZ as u64));
    let mut overrun = false;
    loop {
        ticker.next().await;
        let period = systick::period();
        match app.tick(&mut plant, &mut link, &counter, overrun) {
            Ok(_) => {}
            Err(PlantError::Closed) => semihosting::process::exit(0),
            Err(e) => {
                semihosting::eprintln!("sil image: plant channel: {e}");
                semihosting::process::exit(1)
            }
        }
        // Whole tick, from the SysTick interrupt that started it (executor wake included).
        app.record_tick_cycles(counter.since_period_start());
        overrun = systick::period() != period;
    }
}

#[cortex_m_rt::entry]
fn main() -> ! {
    static mut BANK: Option<Result<Bank<'static>, BankError>> = None;
    static mut EXECUTOR: Option<Executor> = None;

    let bank: &'static Result<Bank<'static>, BankError> = BANK.insert(Bank::parse(bank_region()));
    if let Err(e) = bank {
        semihosting::eprintln!("sil image: bank region invalid: {e}");
    }
    let app = App::new(bank.as_ref().map_err(|e| *e));
    let link = Usart1::init();
    let plant = match PlantChannel::open() {
        Ok(p) => p,
        Err(e) => {
            semihosting::eprintln!("sil image: plant channel: {e}");
            semihosting::process::exit(1)
        }
    };
    let mut core = cortex_m::Peripherals::take().unwrap_or_else(|| semihosting::process::exit(1));
    systick::start(&mut core.SYST);

    let executor: &'static Executor = EXECUTOR.insert(Executor::new(core::ptr::null_mut()));
    executor
        .spawner()
        .spawn(haptic(app, plant, link).unwrap_or_else(|_| semihosting::process::exit(1)));
    loop {
        if WORK.swap(false, Ordering::AcqRel) {
            // SAFETY: polled only from this thread-mode loop, never re-entrantly.
            unsafe { executor.poll() };
        }
        // Sleep until the next interrupt unless a wake arrived meanwhile. WFI (not the stock
        // executor's WFE, on which QEMU spins) lets `-icount ... sleep=off` skip idle time.
        cortex_m::interrupt::free(|_| {
            if !WORK.load(Ordering::Acquire) {
                cortex_m::asm::wfi();
            }
        });
    }
}

/// A panic stops the image; the plant then sees its channel close and holds zero current.
#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    semihosting::eprintln!("sil image: panic: {info}");
    semihosting::process::exit(101)
}
