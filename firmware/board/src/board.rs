//! The board, in one file (like ODrive's `Board/v3`): which pin and timer does what, the clocks,
//! the PWM frequency, the amplifiers' ranges and polarities, the inputs' active levels, the
//! interrupt priorities. Another board is a change of this file only; the rest of the image
//! (`main.rs`, `plant.rs`, `safe.rs`, `usb.rs`) names no pin, timer or level.
//!
//! STM32F405RG (LQFP64: ports A, B, C, PD2; PH0/PH1 are the crystal), 8 MHz HSE crystal, 168 MHz
//! core, 48 MHz USB clock. Three current-mode servo amplifiers (Maxon ESCON style: PWM set value
//! 10 % = -I_max, 50 % = 0 A, 90 % = +I_max; enable, low = motor off; a "Ready" digital output),
//! three quadrature encoders, an e-stop loop, USB full-speed CDC-ACM, a status LED.
//!
//! | function | pin | peripheral | level / notes |
//! | --- | --- | --- | --- |
//! | amplifier 0 (pitch) set value | PC6 | TIM8_CH1 (AF3) | 2 kHz PWM, push-pull |
//! | amplifier 1 (yaw) set value | PC7 | TIM8_CH2 (AF3) | 2 kHz PWM, push-pull |
//! | amplifier 2 (insertion) set value | PC8 | TIM8_CH3 (AF3) | 2 kHz PWM, push-pull |
//! | amplifier 0 / 1 / 2 enable | PC10 / PC11 / PC12 | GPIO out | high = enabled; 10 k pull-down on the board, so off while the MCU is in reset or its pins float |
//! | amplifier 0 / 1 / 2 ready (fault) | PC0 / PC1 / PC2 | GPIO in, pull-down | ESCON digital output set to "Ready": high = ready, low (or unplugged) = fault |
//! | encoder 0 (pitch) A / B | PA6 / PA7 | TIM3_CH1 / CH2 (AF2) | encoder mode, 16-bit |
//! | encoder 1 (yaw) A / B | PB6 / PB7 | TIM4_CH1 / CH2 (AF2) | encoder mode, 16-bit |
//! | encoder 2 (insertion) A / B | PA0 / PA1 | TIM5_CH1 / CH2 (AF2) | encoder mode; a 32-bit timer, of which the image reads the low 16 bits like the others |
//! | e-stop | PB12 | GPIO in, pull-up | normally-closed loop to GND: low = run, high (pressed or broken) = stop |
//! | USB D- / D+ | PA11 / PA12 | OTG_FS (AF10) | full speed, CDC-ACM; no VBUS sensing (PA9 left free) |
//! | status LED | PB14 | GPIO out | high = on |
//! | crystal | PH0 / PH1 | HSE | 8 MHz |
//! | debug | PA13 / PA14, NRST | SWD | PA15, PB3, PB4 (JTAG) unused |
//!
//! Timers: TIM8 (APB2, 168 MHz) PWM; TIM3, TIM4, TIM5 encoders; TIM2 the embassy time driver
//! (`time-driver-tim2` in Cargo.toml, 1 MHz ticks); TIM1, TIM6, TIM7, TIM9-14 free. Interrupts:
//! TIM2 (time driver) priority 0, the tick executor on UART4's vector (UART4 itself unused)
//! priority 1, USB OTG_FS priority 8, thread mode below all. IWDG from the LSI.

use embassy_stm32::gpio::{Input, Level, Output, OutputType, Pin, Pull, Speed};
use embassy_stm32::interrupt::{self, InterruptExt, Priority};
use embassy_stm32::peripherals::{IWDG, TIM3, TIM4, TIM5, TIM8, USB_OTG_FS};
use embassy_stm32::time::Hertz;
use embassy_stm32::timer::low_level::CountingMode;
use embassy_stm32::timer::qei::{self, Qei};
use embassy_stm32::timer::simple_pwm::{PwmPin, SimplePwm, SimplePwmChannel};
use embassy_stm32::wdg::IndependentWatchdog;
use embassy_stm32::{Peripherals, bind_interrupts, usb};
use firmware::amplifier::Amplifier;
use firmware::hal::Interlocks;
use firmware::stm32_gpio::{GpioPin, PinLevels, Port, pin_levels};

/// Everything about the board that is a number or a level.
pub struct Board {
    /// Core clock, Hz (DWT counts at this rate).
    pub core_hz: u32,
    /// The crystal, Hz.
    pub hse_hz: u32,
    /// PWM frequency of the amplifiers' set values, Hz.
    pub pwm_hz: u32,
    /// Amplifier of each axis (pitch, yaw, insertion): the current at 10 % / 90 % as set in the
    /// amplifier itself (ESCON Studio "set value" scaling), and whether a positive set value
    /// turns the motor the other way (wiring). The one place the amplifiers' range is written:
    /// the PWM mapping uses it, and the boot checks the bank's `current_limit_a` against it
    /// (`App::check_amplifiers`: a limit above it faults `AmplifierRange`, every arm refused).
    pub amplifiers: [Amplifier; 3],
    /// Encoder `j` counts down when its motor turns forward (A and B swapped in the wiring).
    pub encoder_inverted: [bool; 3],
    /// Pull on the encoder inputs (none for line-receiver outputs, up for open collector).
    pub encoder_pull: Pull,
    /// The amplifier enables, as plain port/pin numbers for the panic path; [`take`] checks
    /// that the typed pins it configures are these.
    pub enable_pins: [GpioPin; 3],
    /// Level of an enable that is on (the other one is off).
    pub enable_on: Level,
    /// Level of an amplifier's fault input that means "fault", and the pull that makes an
    /// unplugged input read as a fault.
    pub fault_active: Level,
    /// Pull on the fault inputs.
    pub fault_pull: Pull,
    /// Level of the e-stop input that means "stop", and its pull (an open loop reads "stop").
    pub estop_active: Level,
    /// Pull on the e-stop input.
    pub estop_pull: Pull,
    /// Level that lights the status LED.
    pub led_on: Level,
    /// Independent watchdog timeout, microseconds (fed after every completed 1 ms tick).
    pub watchdog_timeout_us: u32,
    /// NVIC priority of the tick executor (0 is the highest; the time driver's TIM2 is 0).
    pub tick_priority: Priority,
    /// NVIC priority of the USB interrupt (below the tick).
    pub usb_priority: Priority,
    /// USB vendor and product id (pid.codes test id: for bench use only, not for a product).
    pub usb_vid_pid: (u16, u16),
    /// USB strings: manufacturer, product, serial number.
    pub usb_strings: (&'static str, &'static str, &'static str),
}

/// This board.
pub const BOARD: Board = Board {
    core_hz: 168_000_000,
    hse_hz: 8_000_000,
    // An ESCON's PWM set-value input takes 10 Hz to 5 kHz (typical accuracy 0.5 % at 1 kHz,
    // 2.5 % at 5 kHz); 2 kHz trades accuracy against the half-millisecond a period adds to the
    // 1 kHz loop's latency. TIM8 at 168 MHz: prescaler 2, 42,000 counts a period.
    pwm_hz: 2_000,
    // Must equal the ESCON's own scaling (bring-up step 3).
    amplifiers: [
        Amplifier::escon(3.0, false),
        Amplifier::escon(3.0, false),
        Amplifier::escon(2.0, false),
    ],
    encoder_inverted: [false, false, false],
    encoder_pull: Pull::None,
    enable_pins: [
        GpioPin::new(Port::C, 10),
        GpioPin::new(Port::C, 11),
        GpioPin::new(Port::C, 12),
    ],
    enable_on: Level::High,
    fault_active: Level::Low,
    fault_pull: Pull::Down,
    estop_active: Level::High,
    estop_pull: Pull::Up,
    led_on: Level::High,
    watchdog_timeout_us: 5_000,
    tick_priority: Priority::P1,
    usb_priority: Priority::P8,
    usb_vid_pid: (0x1209, 0x0001),
    usb_strings: ("haptic-sim", "haptic device (STM32F405)", "board-0"),
};

// The enables' table is checked at compile time (pin numbers, distinct pins).
const _: () = {
    let [a, b, c] = BOARD.enable_pins;
    assert!(a.is_valid() && b.is_valid() && c.is_valid());
    assert!(!same_pin(a, b) && !same_pin(a, c) && !same_pin(b, c));
};

const fn same_pin(p: GpioPin, q: GpioPin) -> bool {
    p.port as u8 == q.port as u8 && p.pin == q.pin
}

/// The BSRR words (per port) that switch every amplifier enable off, for the panic and fault
/// handlers and the first instructions of boot (`safe.rs`).
pub const ENABLES_OFF: PinLevels =
    pin_levels(&BOARD.enable_pins, matches!(BOARD.enable_on, Level::Low));

/// Cycles of the core clock per tick of the force loop.
pub const CYCLES_PER_TICK: u32 = BOARD.core_hz / firmware::TICK_HZ;

/// Turn on what embassy-stm32's clock set-up leaves off, right after `embassy_stm32::init`:
///
/// - the flash accelerator (RM0090, FLASH_ACR): instruction cache (ICEN), data cache (DCEN) and
///   prefetch (PRFTEN). embassy writes FLASH_ACR with the wait states alone (5 at 168 MHz),
///   which leaves all three off, so every fetch of code and every read of the bank (read in
///   place from flash) pays the wait states. The latency embassy set is kept (a
///   read-modify-write of the three bits). Both caches are empty at reset, so no cache reset
///   is needed first.
/// - the clock security system (RCC_CR.CSSON): if the 8 MHz crystal (HSE) stops, the hardware
///   switches the system clock to the 16 MHz HSI, stops the PLL and raises the NMI, whose
///   handler (`safe.rs`) drives every enable off and waits for the watchdog (its LSI clock is
///   independent of the HSE). Without it a failed crystal would leave the core stalled on a
///   dead PLL with the enables at their last level until the watchdog fired.
pub fn enable_accelerator_and_css() {
    embassy_stm32::pac::FLASH.acr().modify(|w| {
        w.set_icen(true);
        w.set_dcen(true);
        w.set_prften(true);
    });
    embassy_stm32::pac::RCC.cr().modify(|w| w.set_csson(true));
}

/// The clock tree: 8 MHz HSE / 4 x 168 = 336 MHz VCO; / 2 = 168 MHz system clock, / 7 = 48 MHz
/// USB clock; AHB 168 MHz, APB1 42 MHz (timers 84 MHz), APB2 84 MHz (timers 168 MHz).
pub fn clocks() -> embassy_stm32::Config {
    use embassy_stm32::rcc::{
        AHBPrescaler, APBPrescaler, Hse, HseMode, Pll, PllMul, PllPDiv, PllPreDiv, PllQDiv,
        PllSource, Sysclk, mux,
    };
    let mut config = embassy_stm32::Config::default();
    config.rcc.hse = Some(Hse {
        freq: Hertz(BOARD.hse_hz),
        mode: HseMode::Oscillator,
    });
    config.rcc.pll_src = PllSource::HSE;
    config.rcc.pll = Some(Pll {
        prediv: PllPreDiv::DIV4,
        mul: PllMul::MUL168,
        divp: Some(PllPDiv::DIV2),
        divq: Some(PllQDiv::DIV7),
        divr: None,
    });
    config.rcc.ahb_pre = AHBPrescaler::DIV1;
    config.rcc.apb1_pre = APBPrescaler::DIV4;
    config.rcc.apb2_pre = APBPrescaler::DIV2;
    config.rcc.sys = Sysclk::PLL1_P;
    config.rcc.mux.clk48sel = mux::Clk48sel::PLL1_Q;
    config
}

bind_interrupts!(struct Irqs {
    OTG_FS => usb::InterruptHandler<USB_OTG_FS>;
});

/// The USB driver of this board.
pub type UsbDriver = usb::Driver<'static, USB_OTG_FS>;
/// The watchdog of this board.
pub type Watchdog = IndependentWatchdog<'static, IWDG>;

/// The tick's executor: runs in the handler of a spare interrupt at [`Board::tick_priority`].
pub static TICK_EXECUTOR: embassy_executor::InterruptExecutor =
    embassy_executor::InterruptExecutor::new();

#[embassy_stm32::interrupt]
#[allow(non_snake_case)]
unsafe fn UART4() {
    // SAFETY: the vector of the interrupt `TICK_EXECUTOR` was started on.
    unsafe { TICK_EXECUTOR.on_interrupt() }
}

/// Start the tick's executor at its priority; returns its spawner.
pub fn start_tick_executor() -> embassy_executor::SendSpawner {
    interrupt::UART4.set_priority(BOARD.tick_priority);
    TICK_EXECUTOR.start(interrupt::UART4)
}

/// The amplifiers, encoders and interlock inputs, as the plant uses them.
pub struct Hardware {
    encoders: (Qei<'static, TIM3>, Qei<'static, TIM4>, Qei<'static, TIM5>),
    pwm: [SimplePwmChannel<'static, TIM8>; 3],
    max_duty: u16,
    enables: [Output<'static>; 3],
    faults: [Input<'static>; 3],
    estop: Input<'static>,
}

/// What [`take`] hands the image.
pub struct Parts {
    /// Amplifiers, encoders, interlocks.
    pub hardware: Hardware,
    /// USB full-speed driver (OTG_FS on PA11/PA12).
    pub usb: UsbDriver,
    /// The independent watchdog, configured, not started.
    pub watchdog: Watchdog,
    /// The status LED, off.
    pub led: Output<'static>,
}

/// Why [`take`] refused the board.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BoardError {
    /// The typed enable pins are not [`Board::enable_pins`] (this file contradicts itself).
    EnablePinsMismatch,
    /// The PWM timer's period does not fit 16 bits.
    PwmPeriod,
    /// The clocks came out other than [`clocks`] asks (the core clock is not
    /// [`Board::core_hz`], or there is no 48 MHz USB clock).
    Clocks,
}

/// Configure the board: enables first (off), then PWM at 50 %, encoders, inputs, USB, watchdog.
pub fn take(p: Peripherals) -> Result<Parts, BoardError> {
    // The tick's cycle budget (`CYCLES_PER_TICK`) and USB rest on these.
    let clocks = embassy_stm32::rcc::clocks(&p.RCC);
    if clocks.sys.to_hertz() != Some(Hertz(BOARD.core_hz))
        || clocks.pll1_q.to_hertz() != Some(Hertz(48_000_000))
    {
        return Err(BoardError::Clocks);
    }
    let typed = [
        (p.PC10.port(), p.PC10.pin()),
        (p.PC11.port(), p.PC11.pin()),
        (p.PC12.port(), p.PC12.pin()),
    ];
    let matches = typed
        .iter()
        .zip(BOARD.enable_pins.iter())
        .all(|(&(port, pin), e)| port == e.port as u8 && pin == e.pin);
    if !matches {
        return Err(BoardError::EnablePinsMismatch);
    }
    let off = off_level();
    let enables = [
        Output::new(p.PC10, off, Speed::Low),
        Output::new(p.PC11, off, Speed::Low),
        Output::new(p.PC12, off, Speed::Low),
    ];

    let pwm = SimplePwm::new(
        p.TIM8,
        Some(PwmPin::new(p.PC6, OutputType::PushPull)),
        Some(PwmPin::new(p.PC7, OutputType::PushPull)),
        Some(PwmPin::new(p.PC8, OutputType::PushPull)),
        None,
        Hertz(BOARD.pwm_hz),
        CountingMode::EdgeAlignedUp,
    );
    let channels = pwm.split();
    let mut pwm = [channels.ch1, channels.ch2, channels.ch3];
    let max_duty = pwm
        .first()
        .map(|c| c.max_duty_cycle())
        .and_then(|m| u16::try_from(m).ok())
        .ok_or(BoardError::PwmPeriod)?;
    let half = firmware::amplifier::Setpoint::SAFE.compare(max_duty);
    for ch in &mut pwm {
        ch.set_duty_cycle(u32::from(half));
        ch.enable();
    }

    let qei_config = qei::Config {
        ch1_pull: BOARD.encoder_pull,
        ch2_pull: BOARD.encoder_pull,
        auto_reload: u16::MAX,
        ..qei::Config::default()
    };
    let encoders = (
        Qei::new(p.TIM3, p.PA6, p.PA7, qei_config),
        Qei::new(p.TIM4, p.PB6, p.PB7, qei_config),
        Qei::new(p.TIM5, p.PA0, p.PA1, qei_config),
    );

    let faults = [
        Input::new(p.PC0, BOARD.fault_pull),
        Input::new(p.PC1, BOARD.fault_pull),
        Input::new(p.PC2, BOARD.fault_pull),
    ];
    let estop = Input::new(p.PB12, BOARD.estop_pull);
    let led = Output::new(p.PB14, invert(BOARD.led_on), Speed::Low);

    // The USB interrupt is enabled when the bus starts: give it its priority first.
    interrupt::OTG_FS.set_priority(BOARD.usb_priority);
    let usb_config = {
        let mut c = usb::Config::default();
        c.vbus_detection = false;
        c
    };
    static EP_OUT_BUFFER: static_cell::StaticCell<[u8; 256]> = static_cell::StaticCell::new();
    let usb = usb::Driver::new_fs(
        p.USB_OTG_FS,
        Irqs,
        p.PA12,
        p.PA11,
        EP_OUT_BUFFER.init([0; 256]),
        usb_config,
    );
    let watchdog = IndependentWatchdog::new(p.IWDG, BOARD.watchdog_timeout_us);

    Ok(Parts {
        hardware: Hardware {
            encoders,
            pwm,
            max_duty,
            enables,
            faults,
            estop,
        },
        usb,
        watchdog,
        led,
    })
}

fn invert(level: Level) -> Level {
    match level {
        Level::High => Level::Low,
        Level::Low => Level::High,
    }
}

fn off_level() -> Level {
    invert(BOARD.enable_on)
}

impl Hardware {
    /// The encoder timers' 16-bit counters (pitch, yaw, insertion).
    pub fn encoder_counters(&self) -> [u16; 3] {
        [
            self.encoders.0.count(),
            self.encoders.1.count(),
            self.encoders.2.count(),
        ]
    }

    /// Timer counts of a full PWM period (compare values run 0..=this).
    pub fn max_duty(&self) -> u16 {
        self.max_duty
    }

    /// Write the amplifiers' PWM compare values (clamped to the period).
    pub fn set_compares(&mut self, compares: [u16; 3]) {
        for (ch, c) in self.pwm.iter_mut().zip(compares) {
            ch.set_duty_cycle(u32::from(c.min(self.max_duty)));
        }
    }

    /// Switch the amplifiers' enables on or off.
    pub fn set_enables(&mut self, on: [bool; 3]) {
        for (pin, on) in self.enables.iter_mut().zip(on) {
            pin.set_level(if on { BOARD.enable_on } else { off_level() });
        }
    }

    /// The interlock inputs, at their active levels.
    pub fn interlocks(&self) -> Interlocks {
        let mut amplifier_fault = [false; 3];
        for (f, pin) in amplifier_fault.iter_mut().zip(&self.faults) {
            *f = pin.get_level() == BOARD.fault_active;
        }
        Interlocks {
            estop: self.estop.get_level() == BOARD.estop_active,
            amplifier_fault,
        }
    }
}
