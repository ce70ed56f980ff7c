//! The clock source at start-up. The HAL's clock set-up waits for the 8 MHz crystal (HSE)
//! without a bound: a dead crystal would hang the boot before the watchdog runs. So the board
//! starts the watchdog first, switches the HSE on and polls its ready flag a bounded number of
//! times ([`HSE_STARTUP_POLLS`]); if it never comes, the PLL runs from the internal 16 MHz RC
//! oscillator (HSI, +-1 % over temperature: the 1 kHz loop and the 1 MHz timers keep their rate
//! within that) and the boot log says so.
//!
//! The decision is host-tested here; QEMU has no RCC model (the `qemu` build does no clock
//! set-up), so the board path itself only runs on hardware.

/// Where the system clock comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ClockSource {
    /// The external crystal started.
    Hse,
    /// The crystal did not start in time: the internal RC oscillator.
    Hsi,
}

impl ClockSource {
    /// Short name for the log.
    pub const fn name(self) -> &'static str {
        match self {
            ClockSource::Hse => "HSE 8 MHz crystal",
            ClockSource::Hsi => "HSI 16 MHz internal RC (crystal did not start)",
        }
    }
}

/// Polls of the HSE ready flag before falling back: a poll is a volatile register read and a
/// branch, at least 4 cycles at the 16 MHz HSI that runs out of reset, so 50,000 polls take at
/// least 12.5 ms, six times the crystal's typical 2 ms start-up (RM0090). The watchdog (6.8 ms
/// at its shortest) is fed every 4096 polls (1-3 ms).
pub const HSE_STARTUP_POLLS: u32 = 50_000;

/// Polls `hse_ready` at most `max_polls` times: [`ClockSource::Hse`] as soon as it reports
/// ready, [`ClockSource::Hsi`] if it never does. `feed` runs every 4096 polls (the watchdog).
pub fn choose(
    mut hse_ready: impl FnMut() -> bool,
    max_polls: u32,
    mut feed: impl FnMut(),
) -> ClockSource {
    for n in 0..max_polls {
        if hse_ready() {
            return ClockSource::Hse;
        }
        if n % 4096 == 4095 {
            feed();
        }
    }
    ClockSource::Hsi
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_crystal_that_starts_is_used() {
        let mut polls = 0;
        let src = choose(
            || {
                polls += 1;
                polls > 300
            },
            HSE_STARTUP_POLLS,
            || {},
        );
        assert_eq!((src, polls), (ClockSource::Hse, 301));
    }

    /// A dead crystal: the decision comes after the bounded wait, with the watchdog fed on the
    /// way (no hang, no watchdog reset during the wait).
    #[test]
    fn a_dead_crystal_falls_back_to_the_internal_oscillator() {
        let (mut polls, mut feeds) = (0u32, 0u32);
        let src = choose(
            || {
                polls += 1;
                false
            },
            HSE_STARTUP_POLLS,
            || feeds += 1,
        );
        assert_eq!(src, ClockSource::Hsi);
        assert_eq!(polls, HSE_STARTUP_POLLS);
        assert_eq!(feeds, HSE_STARTUP_POLLS / 4096);
    }
}
