//! STM32F405RG board layer: clocks (HSE with a bounded start-up, else HSI: [`crate::clock`];
//! the watchdog runs before), pins and peripherals (stm32f4xx-hal), wrapped in the drivers of
//! [`crate::drivers`]. Wiring: docs/firmware.md, "Wiring".
//!
//! | function                     | peripheral       | pins                                  |
//! |------------------------------|------------------|---------------------------------------|
//! | left wheel-yaw AS5047P       | SPI1, mode 1     | PA5 SCK, PA6 MISO, PA7 MOSI, PA4 CS   |
//! | right wheel-yaw AS5047P      | SPI2, mode 1     | PB13 SCK, PB14 MISO, PB15 MOSI, PB12 CS |
//! | wheel-speed pulses           | TIM5 CH1 capture | PA0                                   |
//! | coil current (shunt amp out) | ADC1 IN1         | PA1                                   |
//! | coil PWM (gate driver input) | TIM4 CH1, 20 kHz | PB6                                   |
//! | control period               | TIM2 (internal)  | -                                     |

use super::parts::BoardParts;
use crate::drivers::as5047p::{AngleTracker, As5047p};
use crate::drivers::coil_current::{AdcChannel, CoilCurrentSensor};
use crate::drivers::coil_pwm::CoilDriver;
use crate::drivers::wheel_speed::{PulseCapture, PulseSample, WheelSpeed};
use crate::hal::{
    adc::{config::AdcConfig, config::SampleTime, Adc},
    gpio::{Analog, Output, Pin, PushPull},
    pac,
    prelude::*,
    rcc,
    spi::Spi,
    timer::{CaptureChannel, CaptureHzManager, CapturePolarity, Flag, PwmChannel, Timer},
};
use crate::periph::{ControlTimer, LinkPort, Watchdog};
use crate::sensors::{Sensors, YawChannel};
use core::convert::Infallible;
use embedded_hal_bus::spi::{ExclusiveDevice, NoDelay};

/// Left encoder: SPI1 with chip select PA4.
pub type EncLeft = ExclusiveDevice<Spi<pac::SPI1>, Pin<'A', 4, Output<PushPull>>, NoDelay>;
/// Right encoder: SPI2 with chip select PB12.
pub type EncRight = ExclusiveDevice<Spi<pac::SPI2>, Pin<'B', 12, Output<PushPull>>, NoDelay>;
/// The coil PWM channel.
pub type Pwm = PwmChannel<pac::TIM4, 0>;
/// The board's sensor set.
pub type BoardSensors = Sensors<EncLeft, EncRight, BoardPulses, BoardAdc>;

use crate::calibration::{COIL, SHUNT, WHEEL_SPEED as SPEED};
use crate::clock::ClockSource;

/// Raw counts of straight ahead of the two encoders.
/// TODO(calibration): store per vehicle (flash) after a straight-ahead calibration.
pub const ZERO_COUNTS: [u16; 2] = [0, 0];

/// The angle tracker only unwraps (a step of up to half a turn is taken as is): the plausibility
/// of the angle (range, rate, stuck, left/right agreement) is the core supervisor's check.
pub const MAX_STEP_COUNTS: u16 = 8191;

/// Wheel-speed pulses from TIM5 channel 1 input capture (1 MHz, 32 bit), polled once per
/// control step.
///
/// Limitation: only the newest edge per step is seen; with more than one edge per step (an
/// overcapture; above ~45 m/s with 48 teeth and 0.35 m) no period is reported and the speed
/// is bounded by the between-edges rule. TODO: capture interrupt or DMA for higher speeds.
pub struct BoardPulses {
    tim: CaptureHzManager<pac::TIM5>,
    ch1: CaptureChannel<pac::TIM5, 0>,
    last_capture: Option<u32>,
}

impl PulseCapture for BoardPulses {
    fn now_ticks(&mut self) -> u32 {
        // SAFETY: reading TIM5 CNT (read-only use of a register the manager owns).
        unsafe { (*pac::TIM5::ptr()).cnt().read().bits() }
    }

    fn take(&mut self) -> PulseSample {
        // SAFETY: reading TIM5 CNT (read-only use of a register the manager owns).
        let now = unsafe { (*pac::TIM5::ptr()).cnt().read().bits() };
        let flags = self.tim.flags();
        let mut new_period_ticks = None;
        if flags.contains(Flag::C1) {
            let cap = self.ch1.get_capture(); // reading CCR1 clears CC1IF
            if flags.contains(Flag::C1Overcapture) {
                self.tim.clear_flags(Flag::C1Overcapture);
            } else if let Some(last) = self.last_capture {
                new_period_ticks = Some(cap.wrapping_sub(last));
            }
            self.last_capture = Some(cap);
        }
        PulseSample {
            new_period_ticks,
            // Before the first edge: the time since boot (TIM5 starts at 0), so the first
            // 0.5 s after a restart read "starting" (unknown), not "standstill".
            ticks_since_edge: self.last_capture.map_or(now, |l| now.wrapping_sub(l)),
        }
    }
}

/// ADC1 channel 1 (PA1).
pub struct BoardAdc {
    adc: Adc<pac::ADC1>,
    pin: Pin<'A', 1, Analog>,
}

impl AdcChannel for BoardAdc {
    type Error = Infallible;
    fn read_counts(&mut self) -> Result<u16, Infallible> {
        Ok(self.adc.convert(&self.pin, SampleTime::Cycles_84))
    }
}

/// The parts of this variant the application gets.
pub type Board = BoardParts<BoardSensors, Pwm>;

/// Brings up the board: 168 MHz from the 8 MHz HSE, peripherals, coil at the fail-safe
/// current (or off: `coil_off`, a coil fault latched before the reset), watchdog running,
/// control timer started (its interrupt fires once `init` returns); and the host link's port
/// (USART1, enabled).
pub fn init(dp: pac::Peripherals, coil_off: bool) -> (Board, LinkPort) {
    // Watchdog first: a clock that does not start must not hang the boot unsupervised.
    let watchdog = Watchdog::start(dp.IWDG);
    // The HAL waits for the HSE without a bound: start it here and give it a bounded time.
    // SAFETY: RCC CR is only touched here, before the HAL takes the RCC; HSEON is set with a
    // read-modify-write and cleared again if the crystal does not start.
    let rcc_regs = unsafe { &*pac::RCC::ptr() };
    rcc_regs.cr().modify(|_, w| w.hseon().set_bit());
    let source = crate::clock::choose(
        || rcc_regs.cr().read().hserdy().bit_is_set(),
        crate::clock::HSE_STARTUP_POLLS,
        || watchdog.feed(),
    );
    let base = match source {
        ClockSource::Hse => rcc::Config::hse(8.MHz()),
        ClockSource::Hsi => {
            rcc_regs.cr().modify(|_, w| w.hseon().clear_bit());
            rcc::Config::hsi()
        }
    };
    defmt::warn!("clock source: {=str}", source.name());
    let mut rcc = dp
        .RCC
        .freeze(base.sysclk(168.MHz()).pclk1(42.MHz()).pclk2(84.MHz()));
    watchdog.feed();
    let timer_clock_hz = rcc.clocks.timclk1().raw();
    let gpioa = dp.GPIOA.split(&mut rcc);
    let gpiob = dp.GPIOB.split(&mut rcc);

    // Coil first, so the fail-safe current is on before anything else can fail.
    let (_, (pwm_ch1, ..)) = dp.TIM4.pwm_hz(20.kHz(), &mut rcc);
    let mut pwm = pwm_ch1.with(gpiob.pb6);
    pwm.enable();
    let coil = match if coil_off {
        CoilDriver::new_off(pwm, COIL)
    } else {
        CoilDriver::new(pwm, COIL)
    } {
        Ok(c) => c,
        Err(e) => match e {},
    };

    let spi1 = dp.SPI1.spi(
        (Some(gpioa.pa5), Some(gpioa.pa6), Some(gpioa.pa7)),
        embedded_hal::spi::MODE_1,
        1.MHz(),
        &mut rcc,
    );
    let spi2 = dp.SPI2.spi(
        (Some(gpiob.pb13), Some(gpiob.pb14), Some(gpiob.pb15)),
        embedded_hal::spi::MODE_1,
        1.MHz(),
        &mut rcc,
    );
    let cs1 = gpioa
        .pa4
        .into_push_pull_output_in_state(crate::hal::gpio::PinState::High);
    let cs2 = gpiob
        .pb12
        .into_push_pull_output_in_state(crate::hal::gpio::PinState::High);
    let enc_l = match ExclusiveDevice::new_no_delay(spi1, cs1) {
        Ok(d) => d,
        Err(e) => match e {},
    };
    let enc_r = match ExclusiveDevice::new_no_delay(spi2, cs2) {
        Ok(d) => d,
        Err(e) => match e {},
    };

    let (tim5, (cap1, ..)) = Timer::new(dp.TIM5, &mut rcc).capture_hz(1.MHz());
    let mut cap1 = cap1.with(gpioa.pa0);
    cap1.set_polarity(CapturePolarity::ActiveHigh);
    cap1.enable();

    let adc = Adc::new(dp.ADC1, true, AdcConfig::default(), &mut rcc);
    let current = CoilCurrentSensor::new(
        BoardAdc {
            adc,
            pin: gpioa.pa1.into_analog(),
        },
        SHUNT,
    );

    let sensors = Sensors {
        left: YawChannel {
            encoder: As5047p::new(enc_l),
            tracker: AngleTracker::new(ZERO_COUNTS[0], MAX_STEP_COUNTS),
        },
        right: YawChannel {
            encoder: As5047p::new(enc_r),
            tracker: AngleTracker::new(ZERO_COUNTS[1], MAX_STEP_COUNTS),
        },
        pulses: BoardPulses {
            tim: tim5,
            ch1: cap1,
            last_capture: None,
        },
        speed: WheelSpeed::new(SPEED),
        current,
    };

    // Host link: USART1 on PA9 (TX) / PA10 (RX), alternate function 7.
    let _link_tx = gpioa.pa9.into_alternate::<7>();
    let _link_rx = gpioa.pa10.into_alternate::<7>();
    let link = LinkPort::start(dp.USART1, rcc.clocks.pclk2().raw());

    watchdog.feed();
    let board = Board {
        sensors,
        coil,
        timer: ControlTimer::start(dp.TIM2, timer_clock_hz),
        watchdog,
    };
    (board, link)
}
