//! The board image: the firmware for the real device, an STM32F405RG driving three
//! current-mode servo amplifiers (`board.rs` says what is wired where).
//!
//! - Boot: the amplifier enables become outputs at their off level before anything else
//!   ([`safe`]), then the clocks (8 MHz HSE -> 168 MHz, 48 MHz USB), the flash accelerator and
//!   the clock security system ([`board::enable_accelerator_and_css`]) and the board
//!   ([`board::take`]). The reset cause is read and reported, the amplifiers' range checked
//!   against the bank's current limits. The bank is not compiled in: the bank region of the flash (`BANK` in
//!   the top-level `memory.x`, flashed separately) is validated with [`Bank::parse`]; an
//!   invalid bank leaves the motors off and the reason on the link ([`firmware::app`]).
//! - The 1 kHz tick ([`haptic`]) runs in an embassy `InterruptExecutor` at high priority on an
//!   embassy-time `Ticker`: [`App::tick`] on the board's [`plant::BoardPlant`], measured with
//!   DWT's cycle counter against its deadline ([`firmware::deadline`]); an overrun goes to the
//!   next tick. The independent watchdog is fed after each completed tick only.
//! - The host link ([`usb`], USB CDC-ACM) and the status LED run in the thread-mode executor,
//!   below the tick, which never waits on them: the link is [`firmware::link`]'s lock-free
//!   queues.
//! - A panic, a HardFault or any unexpected interrupt drives the enables off by direct
//!   register writes and waits for the watchdog ([`safe`]).
#![no_std]
#![no_main]
// No panic paths in the image: the same lints as the firmware crate (firmware/src/lib.rs).
#![cfg_attr(
    not(test),
    deny(
        clippy::unwrap_used,
        clippy::expect_used,
        clippy::panic,
        clippy::indexing_slicing,
        clippy::unreachable,
        clippy::todo
    )
)]

mod board;
mod plant;
mod safe;
mod usb;

use core::sync::atomic::{AtomicU8, Ordering};

use bank_format::{Bank, BankError, ResetCause, State};
use embassy_executor::Executor;
use embassy_stm32::gpio::{Level, Output};
use embassy_time::{Duration, Ticker, Timer};
use firmware::app::App;
use firmware::deadline::TickWatch;
use firmware::hal::CycleCounter;
use firmware::link::Link;
use static_cell::StaticCell;

use crate::board::{BOARD, CYCLES_PER_TICK, Watchdog};
use crate::plant::{BoardPlant, DwtCycles};

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

/// The link grace of the application ([`App::new`]): none. The USB CDC link delivers a whole
/// frame within a tick, so only valid frames count as link activity, and a host that sends
/// nothing or only garbage faults `LinkSilent` after the bank's link timeout
/// (`link_timeout_ms`, one tick a ms; the device is armed for at most that long of it).
const LINK_GRACE_TICKS: u32 = 0;

/// The safety state after the last tick, for the LED (0 disarmed, 1 armed, 2 fault).
static STATE: AtomicU8 = AtomicU8::new(0);

/// The 1 kHz tick: wait for the period, run one [`App::tick`], measure it against its
/// deadline, feed the watchdog.
#[embassy_executor::task]
async fn haptic(mut app: App<'static, 'static>, mut plant: BoardPlant, mut watchdog: Watchdog) {
    let clock = DwtCycles;
    let mut watch = TickWatch::new(CYCLES_PER_TICK);
    let mut ticker = Ticker::every(Duration::from_hz(u64::from(firmware::TICK_HZ)));
    let mut overrun = false;
    watchdog.unleash();
    loop {
        ticker.next().await;
        watch.begin(clock.cycles());
        let report = match app.tick(&mut plant, &clock, overrun) {
            Ok(r) => r,
            Err(never) => match never {},
        };
        let timing = watch.end(clock.cycles());
        app.record_tick_cycles(timing.cycles);
        overrun = timing.overrun;
        if overrun {
            // Start afresh from now instead of catching up with back-to-back ticks, which
            // would starve the link task of the time to report the fault; the watch has
            // restarted its schedule from now too (`TickWatch::end`), so one late tick is one
            // overrun.
            ticker.reset();
        }
        let state = match report.state {
            State::Disarmed => 0,
            State::Armed => 1,
            State::Fault => 2,
        };
        STATE.store(state, Ordering::Relaxed);
        bringup_fault(report.tick);
        watchdog.pet();
    }
}

/// Tick at which a bring-up build (feature `bringup-*`) injects its fault: 10 s after boot.
const BRINGUP_FAULT_TICK: u32 = 10 * firmware::TICK_HZ;

/// The fault a bring-up build injects in the tick, if any (none in a normal build).
#[inline(always)]
fn bringup_fault(tick: u32) {
    if tick != BRINGUP_FAULT_TICK {
        return;
    }
    if cfg!(feature = "bringup-hang") {
        // The tick never completes: the watchdog is not fed and resets the chip.
        loop {
            cortex_m::asm::nop();
        }
    } else if cfg!(feature = "bringup-hardfault") {
        cortex_m::asm::udf();
    } else if cfg!(feature = "bringup-panic") {
        bringup_panic();
    } else if cfg!(feature = "bringup-overflow") {
        bringup_overflow(0);
    }
}

/// Recurses with 256-byte frames until the stack runs off the bottom of CCM (stack.x): the
/// guard's test, a bus fault rather than a write into SRAM's static data.
#[inline(never)]
fn bringup_overflow(depth: u32) -> u32 {
    let frame = core::hint::black_box([depth; 64]);
    if core::hint::black_box(true) {
        frame[63].wrapping_add(bringup_overflow(depth.wrapping_add(1)))
    } else {
        frame[0]
    }
}

#[allow(clippy::panic)]
#[inline(never)]
fn bringup_panic() {
    panic!("bring-up: injected panic");
}

/// Why this boot happened, from RCC_CSR's reset flags ([`firmware::reset::cause_from_rcc_csr`]:
/// power-on, pin, brown-out, software, either watchdog, low-power); clears the flags (RMVF) so
/// the next boot reads its own cause.
fn take_reset_cause() -> ResetCause {
    let rcc = embassy_stm32::pac::RCC;
    let csr = rcc.csr().read().0;
    rcc.csr().modify(|w| w.set_rmvf(true));
    firmware::reset::cause_from_rcc_csr(csr)
}

/// `FLASH_OPTCR`, the option bytes loaded at reset: its `BOR_LEV` bits tell the brown-out
/// reset level ([`firmware::brownout`], checked by [`App::check_brown_out`]).
fn read_optcr() -> u32 {
    embassy_stm32::pac::FLASH.optcr().read().0
}

/// Status LED: slow blink disarmed, on armed, fast blink on a fault.
#[embassy_executor::task]
async fn led(mut led: Output<'static>) {
    let off = match BOARD.led_on {
        Level::High => Level::Low,
        Level::Low => Level::High,
    };
    let mut phase = 0u32;
    loop {
        let on = match STATE.load(Ordering::Relaxed) {
            0 => phase.is_multiple_of(10),
            1 => true,
            _ => phase.is_multiple_of(2),
        };
        led.set_level(if on { BOARD.led_on } else { off });
        phase = phase.wrapping_add(1);
        Timer::after_millis(100).await;
    }
}

#[cortex_m_rt::entry]
fn main() -> ! {
    safe::hold_enables_off_at_boot();
    let p = embassy_stm32::init(board::clocks());
    board::enable_accelerator_and_css();
    let Ok(parts) = board::take(p) else {
        safe::stop()
    };
    let Some(mut core) = cortex_m::Peripherals::take() else {
        safe::stop()
    };
    core.DCB.enable_trace();
    core.DWT.enable_cycle_counter();

    static BANK: StaticCell<Result<Bank<'static>, BankError>> = StaticCell::new();
    static LINK: StaticCell<Link> = StaticCell::new();
    static EXECUTOR: StaticCell<Executor> = StaticCell::new();

    let bank: &'static Result<Bank<'static>, BankError> = BANK.init(Bank::parse(bank_region()));
    let (tick_end, driver_end) = LINK.init(Link::new()).split();
    let mut app = App::new(bank.as_ref().map_err(|e| *e), tick_end, LINK_GRACE_TICKS);
    app.reset(take_reset_cause());
    app.check_amplifiers(&BOARD.amplifiers);
    app.check_brown_out(read_optcr());
    let plant = BoardPlant::new(parts.hardware);

    let tick_spawner = board::start_tick_executor();
    match haptic(app, plant, parts.watchdog) {
        Ok(token) => tick_spawner.spawn(token),
        Err(_) => safe::stop(),
    }

    let executor = EXECUTOR.init(Executor::new());
    executor.run(move |spawner| {
        match usb::run(parts.usb, driver_end) {
            Ok(token) => spawner.spawn(token),
            Err(_) => safe::stop(),
        }
        match led(parts.led) {
            Ok(token) => spawner.spawn(token),
            Err(_) => safe::stop(),
        }
    })
}
