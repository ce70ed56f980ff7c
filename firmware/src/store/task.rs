//! The store as the firmware's background loop runs it: log entries from the meter task's
//! recorder, and the standstill work (the only holder of a [`Standstill`] token at run time).

use super::flash::FlashError;
use super::log::LogEntry;
use super::standstill::{Standstill, StandstillWatch};
use super::storage::{Maintenance, Store, StoreError};
use embedded_storage_async::nor_flash::NorFlash;

/// A failed standstill maintenance is retried after this long, s.
pub const RETRY_S: f64 = 10.0;

/// What the meter task publishes for the store after each run: time, trusted speed and the
/// largest coil command of the run.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Motion {
    /// Margin-path time, s.
    pub t_s: f64,
    /// Trusted speed, m/s (NaN when not trusted).
    pub speed_mps: f32,
    /// Largest coil command of the run, A.
    pub cmd_peak_a: f32,
}

impl Motion {
    /// Before the first meter run: not a standstill.
    pub const UNKNOWN: Motion = Motion {
        t_s: 0.0,
        speed_mps: f32::NAN,
        cmd_peak_a: f32::NAN,
    };
}

/// What one pass did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Pass {
    /// Entries appended (in flash or pending).
    pub appended: u32,
    /// The standstill maintenance of this pass, if one ran.
    pub maintained: Option<Result<Maintenance, StoreError>>,
}

/// The background loop's store work (see the module documentation).
pub struct StoreTask<F> {
    store: Store<F>,
    watch: StandstillWatch,
    retry_at_s: f64,
}

impl<F: NorFlash<Error = FlashError>> StoreTask<F> {
    /// The task over the booted `store`.
    pub fn new(store: Store<F>) -> Self {
        StoreTask {
            store,
            watch: StandstillWatch::new(),
            retry_at_s: f64::NEG_INFINITY,
        }
    }

    /// The store, for reads (the host link: load the configuration, read the log or the
    /// faults). Its erasing operations need a token, which only [`Self::at_standstill`] gives.
    pub fn store(&mut self) -> &mut Store<F> {
        &mut self.store
    }

    /// Entries the log holds at least ([`Store::log_capacity`]).
    pub fn log_capacity(&self) -> u16 {
        self.store.log_capacity()
    }

    /// One pass: appends `entries` and at standstill writes what waits for an erase.
    pub fn step(&mut self, motion: Motion, entries: impl Iterator<Item = LogEntry>) -> Pass {
        let mut pass = Pass::default();
        for e in entries {
            self.store.append(&e);
            pass.appended += 1;
        }
        self.watch
            .observe(motion.t_s, motion.speed_mps, motion.cmd_peak_a);
        if self.store.needs_maintenance() && motion.t_s >= self.retry_at_s {
            if let Some(token) = self.watch.check(motion.t_s) {
                let done = self.store.maintain(&token);
                if done.is_err() {
                    self.retry_at_s = motion.t_s + RETRY_S;
                }
                pass.maintained = Some(done);
            }
        }
        pass
    }

    /// Runs `work` with the standstill token if the vehicle has stood with the damper idle long
    /// enough at `t_s` (the host link's configuration write or log clear); `None` otherwise.
    pub fn at_standstill<R>(
        &mut self,
        t_s: f64,
        work: impl FnOnce(&mut Store<F>, &Standstill<'_>) -> R,
    ) -> Option<R> {
        let token = self.watch.check(t_s)?;
        Some(work(&mut self.store, &token))
    }
}
