//! Register-level pieces shared by the board and the `qemu` build: the 1 kHz control-period
//! timer (TIM2), the independent watchdog and the instruction counter of the benchmark.
//! They use only registers QEMU's stm32f405 models (TIM2) or ignores harmlessly (IWDG, RCC
//! enable bits are unimplemented there and read as 0).

use crate::hal::pac;

/// Control period in timer ticks (the timer runs at 1 MHz): 1 kHz.
pub const PERIOD_TICKS: u32 = 1000;

/// TIM2 as the control-period timer: 1 MHz counter, update interrupt every [`PERIOD_TICKS`].
pub struct ControlTimer {
    tim: pac::TIM2,
}

impl ControlTimer {
    /// Starts TIM2 at 1 MHz from a timer clock of `timer_clock_hz` (84 MHz on the board,
    /// 1 GHz under QEMU) with the update interrupt enabled.
    pub fn start(tim: pac::TIM2, timer_clock_hz: u32) -> Self {
        // SAFETY: RCC APB1ENR bit 0 (TIM2EN) set with a read-modify-write before TIM2 is used;
        // nothing else touches APB1ENR concurrently during init.
        unsafe {
            let rcc = &*pac::RCC::ptr();
            rcc.apb1enr().modify(|r, w| w.bits(r.bits() | 1));
        }
        let psc = timer_clock_hz / 1_000_000 - 1;
        // SAFETY: any 32-bit value is valid for PSC/ARR/EGR/DIER/CR1 as written here.
        unsafe {
            tim.cr1().write(|w| w.bits(0));
            tim.psc().write(|w| w.bits(psc));
            tim.arr().write(|w| w.bits(PERIOD_TICKS - 1));
            tim.egr().write(|w| w.bits(1)); // UG: load PSC
            tim.sr().write(|w| w.bits(0));
            tim.dier().write(|w| w.bits(1)); // UIE
            tim.cr1().write(|w| w.bits(1)); // CEN
        }
        ControlTimer { tim }
    }

    /// Raw counter value (1 tick = 1 us).
    pub fn now_ticks(&self) -> u32 {
        self.tim.cnt().read().bits()
    }

    /// How late the control step started, ticks: the counter at entry (ticks since the
    /// update event). Board only: QEMU 7.2's STM32 timer model neither restarts CNT at the
    /// update event (it counts since the last CNT write) nor keeps the ARR period exactly
    /// (measured ~1.8 ms between update interrupts for a 1 ms period), so the `qemu` build
    /// reports 0 here and checks only overruns (UIF set again before the step ends) and step
    /// durations.
    pub fn entry_latency_ticks(&self, entry_raw: u32) -> u32 {
        if cfg!(feature = "qemu") {
            0
        } else {
            entry_raw
        }
    }

    /// True if an update event is pending (a period boundary passed since the last clear).
    pub fn update_pending(&self) -> bool {
        self.tim.sr().read().bits() & 1 != 0
    }

    /// Clears the update flag (at the start of the control step).
    pub fn clear_update(&self) {
        // SAFETY: writing 0 to UIF clears it; the other SR bits are rc_w0 and written 1 (kept).
        unsafe {
            self.tim.sr().write(|w| w.bits(!1u32 & 0xFFFF));
        }
    }
}

/// The independent watchdog: ~10 ms timeout from the 32 kHz LSI (/4, reload 80), fed only
/// when a control step completes. Once started it cannot be stopped.
pub struct Watchdog {
    iwdg: pac::IWDG,
}

/// IWDG prescaler code of the running firmware (/4).
const IWDG_PR: u16 = 0;
/// IWDG reload of the running firmware (LSI/4 ticks, ~10 ms).
const IWDG_RLR: u16 = crate::control::WATCHDOG_RELOAD_TICKS;

impl Watchdog {
    /// Starts the IWDG. LSI varies 17..47 kHz: the timeout is 6.8..18.8 ms, so the 1 ms loop
    /// can miss several steps before a reset.
    pub fn start(iwdg: pac::IWDG) -> Self {
        // SAFETY: key/prescaler/reload values from RM0090 section 19.
        unsafe {
            iwdg.kr().write(|w| w.bits(0xCCCC)); // start (LSI turns on)
            iwdg.kr().write(|w| w.bits(0x5555)); // unlock PR/RLR
            iwdg.pr().write(|w| w.bits(IWDG_PR)); // /4
            iwdg.rlr().write(|w| w.bits(IWDG_RLR));
        }
        // Wait for the prescaler/reload update (bounded: QEMU reads 0 at once).
        let mut n = 0u32;
        while iwdg.sr().read().bits() != 0 && n < 1_000_000 {
            n += 1;
        }
        let w = Watchdog { iwdg };
        w.feed();
        w
    }

    /// Reloads the counter.
    pub fn feed(&self) {
        // SAFETY: 0xAAAA is the reload key.
        unsafe {
            self.iwdg.kr().write(|w| w.bits(0xAAAA));
        }
    }
}

/// Runs `erase` with the watchdog's timeout stretched from ~10 ms to at least 11 s (LSI /128,
/// reload 4095) and restores it after. Erasing a 128 KiB flash sector at x8 parallelism takes up
/// to 4 s (STM32F405 datasheet, t_ERASE128KB) and stalls every read of the flash, so the
/// control task and its watchdog feed stop meanwhile; only the store's standstill work (vehicle
/// stopped, damper idle: the coil keeps its 0 A duty) and its boot repair reach this.
pub fn with_watchdog_stretched<R>(erase: impl FnOnce() -> R) -> R {
    let set = |pr: u16, rlr: u16| {
        // SAFETY: the IWDG is only written by `Watchdog` (the key register) and here; the
        // unlock-write-reload sequence runs with interrupts off so no feed of the control task
        // (another key) relocks PR/RLR halfway. Values from RM0090 section 19.
        cortex_m::interrupt::free(|_| unsafe {
            let iwdg = pac::IWDG::steal();
            iwdg.kr().write(|w| w.bits(0xAAAA));
            iwdg.kr().write(|w| w.bits(0x5555));
            iwdg.pr().write(|w| w.bits(pr));
            iwdg.rlr().write(|w| w.bits(rlr));
            iwdg.kr().write(|w| w.bits(0xAAAA));
        });
        // SAFETY: a read of the status register.
        let sr = || unsafe { pac::IWDG::steal() }.sr().read().bits();
        let mut n = 0u32;
        while sr() != 0 && n < 1_000_000 {
            n += 1;
        }
    };
    set(5, 4095);
    let result = erase();
    set(IWDG_PR, IWDG_RLR);
    result
}

/// The host link's serial port: USART1, 8N1, receive interrupt on, polled transmit. On the board
/// PA9 (TX) and PA10 (RX) at [`LINK_BAUD`] to a USB-serial adapter; under QEMU the first
/// `-serial` chardev (netduinoplus2 wires `serial_hd(0)` to USART1, IRQ 37).
///
/// Why a USART and not USB CDC: a few hundred bytes of flash instead of a USB stack (~10 KiB,
/// its own interrupt load and the 48 MHz clock), and the same code runs under QEMU, which models
/// the USARTs and no USB device.
pub struct LinkPort {
    usart: pac::USART1,
}

/// Link speed, baud: a 0.8 KiB reply (a vehicle record) takes 9 ms, so the polled transmit in
/// the priority-1 link task holds the background model loop for at most that (its period is
/// 100 ms).
pub use shimmy_link::LINK_BAUD;

impl LinkPort {
    /// Clocks and enables USART1 (transmitter, receiver, RXNE interrupt) for [`LINK_BAUD`] from
    /// its bus clock `pclk2_hz` (84 MHz on the board; QEMU ignores the divider). Bytes a host
    /// sent before this are lost: the link task announces itself after it (the ready frame).
    pub fn start(usart: pac::USART1, pclk2_hz: u32) -> Self {
        // SAFETY: RCC APB2ENR bit 4 (USART1EN) set with a read-modify-write during init, when
        // nothing else touches APB2ENR.
        unsafe {
            let rcc = &*pac::RCC::ptr();
            rcc.apb2enr().modify(|r, w| w.bits(r.bits() | (1 << 4)));
        }
        // Oversampling by 16: BRR = f_ck / baud holds mantissa and fraction (RM0090 30.3.4).
        let brr = (pclk2_hz + LINK_BAUD / 2) / LINK_BAUD;
        // SAFETY: BRR takes any 16-bit divider; CR1 = UE | RXNEIE | TE | RE.
        unsafe {
            usart.brr().write(|w| w.bits(brr.min(0xFFFF) as u16));
            usart
                .cr1()
                .write(|w| w.bits((1 << 13) | (1 << 5) | (1 << 3) | (1 << 2)));
        }
        LinkPort { usart }
    }

    /// The received byte, if one is waiting (an overrun is cleared by the same SR/DR read:
    /// the lost bytes make the frame fail its CRC, and the host gets an error reply).
    pub fn read(&mut self) -> Option<u8> {
        let sr = self.usart.sr().read().bits();
        // RXNE (bit 5) or ORE (bit 3): reading DR after SR clears both.
        if sr & ((1 << 5) | (1 << 3)) == 0 {
            return None;
        }
        let dr = self.usart.dr().read().bits();
        (sr & (1 << 5) != 0).then_some(dr as u8)
    }

    /// Sends `bytes`, waiting for TXE before each.
    pub fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            while self.usart.sr().read().bits() & (1 << 7) == 0 {}
            // SAFETY: DR takes any 8-bit value.
            unsafe {
                self.usart.dr().write(|w| w.bits(u16::from(b)));
            }
        }
    }
}
