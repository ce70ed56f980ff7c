//! Fault memory across resets: a small record in RAM that a reset leaves alone (the board puts
//! it in cortex-m-rt's `.uninit` section, NOLOAD: neither zeroed nor initialised at start-up),
//! guarded by a magic number and a CRC-32, so power-on garbage is told from a record.
//!
//! What it keeps: the resets since power-on, the last reset cause, how many abnormal resets
//! (watchdog, panic / fault handler) came in a row each after a run shorter than
//! [`RESET_LOOP_WINDOW_MS`], the uptime of the current run, and the supervisor's latched
//! faults (coil open/short, escalated intermittent faults). A power-on (or brown-out) is the
//! ignition cycle: it starts a fresh record, so latched faults clear there as documented for
//! `Supervisor::clear_latched`.
//!
//! Policy at boot ([`ResetRecord::on_boot`]):
//! - the latched faults are restored into the supervisor before the first control step, so the
//!   firmware never drives the fail-safe 2 A into a coil it had found shorted (the coil stays
//!   off from `init` on);
//! - [`RESET_LOOP_COUNT`] abnormal resets in a row, each within [`RESET_LOOP_WINDOW_MS`] of its
//!   boot, are a reset loop: the firmware stays in the safe state (fixed safe current, or coil
//!   off when a coil fault is latched; the controller does not run) and reports it, instead of
//!   looping through the fault again.
//!
//! The logic here is plain data and host-tested; only the placement of the record is
//! target code.

/// Marks a record ("SHMF").
pub const MAGIC: u32 = 0x5348_4D46;

/// Abnormal resets in a row that make a reset loop.
pub const RESET_LOOP_COUNT: u8 = 3;

/// An abnormal reset counts towards a loop when its run was shorter than this, ms.
pub const RESET_LOOP_WINDOW_MS: u32 = 60_000;

/// Why the MCU (re)started, from RCC_CSR.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum ResetCause {
    /// Power-on or brown-out: the ignition cycle (RAM content is lost anyway).
    PowerOn = 0,
    /// Independent or window watchdog: the control loop stopped completing steps.
    Watchdog = 1,
    /// Software reset: the panic or HardFault handler.
    Software = 2,
    /// Reset pin (debug probe, service).
    Pin = 3,
    /// Anything else (low-power management, no flag).
    Other = 4,
    /// The firmware restarted itself at standstill to run a new vehicle configuration
    /// (`persist::restart`, target only).
    Restart = 5,
}

impl ResetCause {
    /// The cause of a stored code (unknown codes are `Other`).
    pub const fn from_code(c: u8) -> Self {
        match c {
            0 => ResetCause::PowerOn,
            1 => ResetCause::Watchdog,
            2 => ResetCause::Software,
            3 => ResetCause::Pin,
            5 => ResetCause::Restart,
            _ => ResetCause::Other,
        }
    }

    /// A reset the firmware caused by failing (watchdog, panic, fault).
    pub const fn abnormal(self) -> bool {
        matches!(self, ResetCause::Watchdog | ResetCause::Software)
    }

    /// Short name for the log (the host link's, `shimmy_link::wire::cause_name`).
    pub const fn name(self) -> &'static str {
        shimmy_link::wire::cause_name(self as u8)
    }
}

/// The record that survives a reset.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(C)]
pub struct ResetRecord {
    magic: u32,
    /// Resets since power-on.
    pub resets: u32,
    /// Cause of the last reset ([`ResetCause`] code).
    pub last_cause: u8,
    /// Abnormal resets in a row, each after a run shorter than [`RESET_LOOP_WINDOW_MS`].
    pub quick_resets: u8,
    _pad: [u8; 2],
    /// The supervisor's latched faults (bit i = `FaultKind::ALL[i]`).
    pub latched_faults: u32,
    /// Uptime of the current run, ms (updated while running).
    pub uptime_ms: u32,
    crc: u32,
}

/// What the firmware does after a boot.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BootPolicy {
    /// Run normally (latched faults restored).
    Run,
    /// Reset loop: stay in the safe state, do not run the controller.
    HoldSafe,
}

/// CRC-32 (IEEE 802.3, reflected, bitwise: a few words, no table in flash).
pub fn crc32(words: &[u32]) -> u32 {
    let mut crc = !0u32;
    for w in words {
        for b in w.to_le_bytes() {
            crc ^= u32::from(b);
            for _ in 0..8 {
                let mask = (crc & 1).wrapping_neg();
                crc = (crc >> 1) ^ (0xEDB8_8320 & mask);
            }
        }
    }
    !crc
}

impl ResetRecord {
    /// A fresh record (power-on): no reset, nothing latched.
    pub const fn fresh() -> Self {
        ResetRecord {
            magic: MAGIC,
            resets: 0,
            last_cause: ResetCause::PowerOn as u8,
            quick_resets: 0,
            _pad: [0; 2],
            latched_faults: 0,
            uptime_ms: 0,
            crc: 0,
        }
    }

    fn words(&self) -> [u32; 5] {
        [
            self.magic,
            self.resets,
            u32::from_le_bytes([self.last_cause, self.quick_resets, 0, 0]),
            self.latched_faults,
            self.uptime_ms,
        ]
    }

    /// The record with its CRC set.
    pub fn sealed(mut self) -> Self {
        self.crc = crc32(&self.words());
        self
    }

    /// Magic and CRC match (not power-on garbage, not a half-written record).
    pub fn is_valid(&self) -> bool {
        self.magic == MAGIC && self.crc == crc32(&self.words())
    }

    /// The cause of the last reset.
    pub fn cause(&self) -> ResetCause {
        ResetCause::from_code(self.last_cause)
    }

    /// The record of this boot from the one found in RAM (`stored`, possibly garbage) and the
    /// reset cause, and what to do. Power-on, or no valid record, starts fresh.
    pub fn on_boot(stored: &ResetRecord, cause: ResetCause) -> (ResetRecord, BootPolicy) {
        if cause == ResetCause::PowerOn || !stored.is_valid() {
            let mut r = ResetRecord::fresh();
            r.last_cause = cause as u8;
            return (r.sealed(), BootPolicy::Run);
        }
        let mut r = *stored;
        r.resets = r.resets.saturating_add(1);
        r.last_cause = cause as u8;
        r.quick_resets = if !cause.abnormal() {
            0
        } else if stored.uptime_ms < RESET_LOOP_WINDOW_MS {
            r.quick_resets.saturating_add(1)
        } else {
            1
        };
        r.uptime_ms = 0;
        let policy = if r.quick_resets >= RESET_LOOP_COUNT {
            BootPolicy::HoldSafe
        } else {
            BootPolicy::Run
        };
        (r.sealed(), policy)
    }

    /// Records the uptime and the latched faults of the running firmware; true when the record
    /// changed (then it is re-sealed).
    pub fn update(&mut self, uptime_ms: u32, latched_faults: u32) -> bool {
        if self.uptime_ms == uptime_ms && self.latched_faults == latched_faults {
            return false;
        }
        self.uptime_ms = uptime_ms;
        self.latched_faults = latched_faults;
        *self = self.sealed();
        true
    }
}

/// Where the record lives on the target: a static in cortex-m-rt's `.uninit` section (NOLOAD:
/// start-up neither zeroes nor initialises it, so a reset leaves its content).
#[cfg(target_os = "none")]
pub mod persist {
    use super::ResetRecord;
    use core::mem::MaybeUninit;

    #[link_section = ".uninit.shimmy_reset_record"]
    static mut RECORD: MaybeUninit<ResetRecord> = MaybeUninit::uninit();

    /// The record as found in RAM (any bit pattern after a power-on: check
    /// [`ResetRecord::is_valid`]).
    pub fn load() -> ResetRecord {
        // SAFETY: the static is only accessed through these two functions, from `init` and the
        // control task (which never preempt each other); RAM always holds some bit pattern and
        // every pattern is a `ResetRecord` (integers only).
        unsafe { core::ptr::read_volatile(core::ptr::addr_of!(RECORD).cast::<ResetRecord>()) }
    }

    /// Writes the record.
    pub fn store(r: &ResetRecord) {
        // SAFETY: as in `load`.
        unsafe {
            core::ptr::write_volatile(core::ptr::addr_of_mut!(RECORD).cast::<ResetRecord>(), *r)
        }
    }

    /// The restart request's mark (any other value: none). A power-on leaves random RAM, but
    /// the power-on flag is tested before the request.
    const RESTART_MARK: u32 = 0x5253_5452;

    #[link_section = ".uninit.shimmy_restart"]
    static mut RESTART: MaybeUninit<u32> = MaybeUninit::uninit();

    /// Restarts the MCU to run a new vehicle configuration (the boot reads it from flash): a
    /// software reset the next boot calls [`ResetCause::Restart`](super::ResetCause::Restart),
    /// not a failure. Only at standstill with the damper idle (the caller holds the store's
    /// token); the coil gets the fail-safe current out of reset as after any reset.
    pub fn restart() -> ! {
        // SAFETY: a plain word in `.uninit`, written here and read once at boot (`take_restart`).
        unsafe {
            core::ptr::write_volatile(core::ptr::addr_of_mut!(RESTART).cast::<u32>(), RESTART_MARK)
        };
        cortex_m::peripheral::SCB::sys_reset()
    }

    /// Whether the last reset was a [`restart`] (and forgets it, so a later panic's software
    /// reset is not taken for one).
    pub fn take_restart() -> bool {
        // SAFETY: as in `restart`; read and cleared by `init` only.
        unsafe {
            let p = core::ptr::addr_of_mut!(RESTART).cast::<u32>();
            let marked = core::ptr::read_volatile(p) == RESTART_MARK;
            core::ptr::write_volatile(p, 0);
            marked
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_cause_has_a_code_and_a_name() {
        use ResetCause::*;
        for c in [PowerOn, Watchdog, Software, Pin, Other, Restart] {
            assert_eq!(ResetCause::from_code(c as u8), c);
            assert_ne!(c.name(), "?");
        }
        // A restart for a new configuration is not a failure: it does not count toward a loop.
        assert!(!Restart.abnormal());
    }

    #[test]
    fn crc32_matches_the_standard_check_value() {
        // CRC-32 of the ASCII bytes "12345678" (two little-endian words), as zlib computes it.
        let w = [u32::from_le_bytes(*b"1234"), u32::from_le_bytes(*b"5678")];
        assert_eq!(crc32(&w), 0x9AE0_DAAF);
    }

    #[test]
    fn garbage_and_power_on_start_fresh() {
        let garbage = ResetRecord {
            magic: 0xDEAD_BEEF,
            resets: 7,
            ..ResetRecord::fresh()
        };
        let (r, p) = ResetRecord::on_boot(&garbage, ResetCause::Watchdog);
        assert_eq!((r.resets, r.latched_faults, p), (0, 0, BootPolicy::Run));
        assert!(r.is_valid());
        // A valid record with a flipped bit is garbage too.
        let mut good = ResetRecord::fresh().sealed();
        good.update(10, 1 << 17);
        let mut flipped = good;
        flipped.latched_faults ^= 1;
        assert!(good.is_valid() && !flipped.is_valid());
        // Power-on: the ignition cycle clears the latched faults.
        let (r, _) = ResetRecord::on_boot(&good, ResetCause::PowerOn);
        assert_eq!(r.latched_faults, 0);
    }

    #[test]
    fn latched_faults_and_the_count_survive_a_reset() {
        let (mut r, _) = ResetRecord::on_boot(&ResetRecord::fresh(), ResetCause::PowerOn);
        assert!(r.update(120_000, 1 << 18));
        assert!(!r.update(120_000, 1 << 18), "unchanged: no rewrite");
        let (r, p) = ResetRecord::on_boot(&r, ResetCause::Software);
        assert_eq!(p, BootPolicy::Run);
        assert_eq!(r.latched_faults, 1 << 18);
        assert_eq!(
            (r.resets, r.cause(), r.quick_resets),
            (1, ResetCause::Software, 1)
        );
    }

    /// Three watchdog resets, each a few seconds after boot: a reset loop, hold the safe state.
    /// Runs longer than a minute in between, or a reset by the pin, are not a loop.
    #[test]
    fn repeated_quick_resets_hold_the_safe_state() {
        let boot = |r: &ResetRecord, up: u32, c: ResetCause| {
            let mut r = *r;
            r.update(up, r.latched_faults);
            ResetRecord::on_boot(&r, c)
        };
        let (r0, _) = ResetRecord::on_boot(&ResetRecord::fresh(), ResetCause::PowerOn);
        let (r1, p1) = boot(&r0, 5_000, ResetCause::Watchdog);
        let (r2, p2) = boot(&r1, 5_000, ResetCause::Watchdog);
        let (r3, p3) = boot(&r2, 5_000, ResetCause::Watchdog);
        assert_eq!(
            (p1, p2, p3),
            (BootPolicy::Run, BootPolicy::Run, BootPolicy::HoldSafe)
        );
        assert_eq!(r3.resets, 3);
        // A long run in between restarts the count.
        let (s2, _) = boot(&r1, 5 * 60_000, ResetCause::Watchdog);
        let (_, q3) = boot(&s2, 5_000, ResetCause::Watchdog);
        assert_eq!((s2.quick_resets, q3), (1, BootPolicy::Run));
        // The reset pin (service) is not a failure.
        let (t2, _) = boot(&r1, 5_000, ResetCause::Pin);
        assert_eq!(t2.quick_resets, 0);
    }
}
