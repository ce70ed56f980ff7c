//! The firmware's side of the host link (`shimmy-link`): the state the link serves and the
//! flash store behind it, as a [`Backend`] of the protocol handler ([`BoardLink`]).
//! Host-compilable and host-tested; `main.rs` runs the handler in the `link` task (USART1
//! interrupt, priority 1: below `meter` and `control`), and the meter task feeds
//! [`LinkState::on_update`].
//!
//! - Event log: the flash log (`crate::store`), so a host reads the episodes, faults and boots
//!   of earlier runs too; the episode still open is served as its last entry. One recorder
//!   makes every entry: `shimmy_link::log::Recorder` in the meter task, through a [`Batch`] and
//!   the store's queue. Clearing it erases flash, so it is refused unless the vehicle stands
//!   with the damper idle (the store's standstill token).
//! - Configuration: the vehicle this boot runs (the flash store's, else the compiled-in
//!   defaults). A vehicle a host writes has been validated whole by the core
//!   (`Vehicle::decode_record`) before it gets here; it is served as pending and kept until the
//!   background loop saves it with the standstill token ([`save_vehicle`]) and then, while
//!   the vehicle still stands ([`may_restart`]), restarts the board into it
//!   (`fault_memory::persist::restart`): the one path by which a vehicle reaches the control,
//!   meter and model tasks is the boot.

use embedded_storage_async::nor_flash::NorFlash;
use shimmy_core::eigen::SolveFloat;
use shimmy_core::estimator::model_update::ModelUpdater;
use shimmy_core::model::UpdatableModel;
use shimmy_core::supervisor::faults::FaultKind;
use shimmy_core::vehicle::record_schema_of;
use shimmy_link::device::Backend;
use shimmy_link::log::{EventSink, Pager};
use shimmy_link::wire::{
    level_code, ErrorReply, FaultReport, Identity, LogEntry, ModelReport, ParamReport, ShimmyEvent,
    Telemetry,
};
use shimmy_link::PROTOCOL_VERSION;

use crate::control::Health;
use crate::fault_memory::ResetRecord;
use crate::monitoring::{ImageVehicle, MarginUpdate};
use crate::store::{FlashError, StoreTask};

/// What the link serves besides the flash store: configuration, fault record, newest margin
/// report, the episode going on.
pub struct LinkState {
    vehicle: ImageVehicle,
    pending: bool,
    /// A vehicle the host wrote that the flash store has not saved yet.
    unsaved: Option<ImageVehicle>,
    faults: FaultReport,
    telemetry: Option<Telemetry>,
    /// The episode going on, as the log's last entry.
    open: Option<LogEntry>,
    /// Margin-path time of the newest update, s: the clock of the store's standstill watch.
    t_s: f64,
    /// The online model update after its newest measurement.
    model: ModelReport<'static>,
}

impl LinkState {
    /// `vehicle`: the one this boot runs (the flash store's, or the compiled-in defaults), no
    /// fault seen; `boot`: the reset record of this boot (resets, cause, faults latched before
    /// it).
    pub fn new(boot: &ResetRecord, vehicle: ImageVehicle) -> Self {
        LinkState {
            vehicle,
            pending: false,
            unsaved: None,
            faults: FaultReport {
                resets: boot.resets,
                last_cause: boot.last_cause,
                quick_resets: boot.quick_resets,
                uptime_ms: 0,
                latched: boot.latched_faults,
                active: 0,
                raised: 0,
            },
            telemetry: None,
            open: None,
            t_s: 0.0,
            model: ModelReport {
                enabled: false,
                updates: 0,
                gated: 0,
                failures: 0,
                params: heapless::Vec::new(),
            },
        }
    }

    /// After a measurement of the online model update (the background loop): its parameters
    /// and counters for [`Backend::model_report`].
    pub fn on_model_update<M: UpdatableModel<N>, const N: usize, T: SolveFloat>(
        &mut self,
        up: &ModelUpdater<M, N, T>,
    ) {
        self.model = model_report(up);
    }

    /// The vehicle a host wrote that is not in flash yet, for the background loop to save with
    /// the store's standstill token ([`Self::keep_unsaved`] hands it back when it cannot).
    pub fn take_unsaved(&mut self) -> Option<ImageVehicle> {
        // Checked first: `take` moves the whole vehicle-sized option even when it is `None`,
        // and the background loop asks after every meter run.
        self.unsaved.as_ref()?;
        self.unsaved.take()
    }

    /// Hands back a vehicle [`Self::take_unsaved`] gave out and the store could not save yet
    /// (no standstill), unless the host has written a newer one since.
    pub fn keep_unsaved(&mut self, v: ImageVehicle) {
        self.unsaved.get_or_insert(v);
    }

    /// After a 100 Hz margin update: the episode going on (`open`, from the recorder), the
    /// fault record and the telemetry refreshed (`latched`: the supervisor's latched faults;
    /// `t_ms`: the control step of the update's sample, milliseconds since boot, wrapping
    /// after 49 days: the same time as the report's f64 seconds without a soft-float multiply
    /// and conversion per update).
    pub fn on_update(
        &mut self,
        u: &MarginUpdate,
        open: Option<ShimmyEvent>,
        health: &Health,
        latched: u32,
        t_ms: u32,
    ) {
        self.open = open.map(LogEntry::Shimmy);
        self.faults = FaultReport {
            uptime_ms: t_ms,
            latched: latched | self.faults.latched,
            active: health.active_faults,
            raised: health.faults_raised,
            ..self.faults
        };
        let r = &u.report;
        self.t_s = r.t_s;
        self.telemetry = Some(Telemetry {
            t_s: r.t_s,
            speed_mps: r.speed_mps,
            zeta_data: r.zeta_data,
            sigma_zeta_data: r.sigma_zeta_data,
            zeta_fast: r.zeta_fast,
            freq_hz: r.freq_hz,
            zeta_model: r.zeta_model.unwrap_or(f32::NAN),
            speed_margin_mps: r.speed_margin_mps.unwrap_or(f32::NAN),
            level: level_code(u.level),
            valid: r.valid,
        });
    }
}

/// Entries one margin update can record: every fault kind raised at once, and two episodes (the
/// monitor can close one and the recorder find another closed since the last update).
pub const BATCH_ENTRIES: usize = FaultKind::ALL.len() + 2;

/// The entries one margin update records (the recorder's sink in the meter task; the store
/// gets them through its queue).
#[derive(Clone, Debug, Default)]
pub struct Batch {
    entries: heapless::Vec<LogEntry, BATCH_ENTRIES>,
    /// Entries that did not fit.
    pub lost: u32,
}

impl Batch {
    /// Empty.
    pub const fn new() -> Self {
        Batch {
            entries: heapless::Vec::new(),
            lost: 0,
        }
    }
}

impl EventSink for Batch {
    fn append(&mut self, e: LogEntry) {
        if self.entries.push(e).is_err() {
            self.lost = self.lost.saturating_add(1);
        }
    }
}

impl IntoIterator for Batch {
    type Item = LogEntry;
    type IntoIter = <heapless::Vec<LogEntry, BATCH_ENTRIES> as IntoIterator>::IntoIter;
    fn into_iter(self) -> Self::IntoIter {
        self.entries.into_iter()
    }
}

/// The link's backend on the board: its state and the flash store.
pub struct BoardLink<'a, F> {
    /// Configuration, faults, telemetry, the open episode.
    pub state: &'a mut LinkState,
    /// The store: the event log.
    pub store: &'a mut StoreTask<F>,
}

impl<F: NorFlash<Error = FlashError>> Backend for BoardLink<'_, F> {
    type Vehicle = ImageVehicle;
    fn identity(&self) -> Identity<'_> {
        Identity {
            firmware: crate::BANNER,
            core: shimmy_core::VERSION,
            protocol: PROTOCOL_VERSION,
            vehicle_schema: record_schema_of::<ImageVehicle>(),
            log_capacity: self.store.log_capacity(),
        }
    }

    fn vehicle(&self) -> (&ImageVehicle, bool) {
        (&self.state.vehicle, self.state.pending)
    }

    /// Never in effect at once: saved at the next standstill, then run after a restart.
    fn store_vehicle(&mut self, v: ImageVehicle) -> bool {
        self.state.vehicle = v;
        self.state.unsaved = Some(v);
        self.state.pending = true;
        false
    }

    /// The flash log, then the episode still open (if any). Entries that do not read back
    /// (written by another firmware, or damaged) are skipped and counted as dropped.
    fn read_log(&mut self, pager: &mut Pager<'_>) -> Result<(u16, u32), ErrorReply<'static>> {
        let mut unreadable = 0u32;
        let store = self.store.store();
        store
            .read_log(&mut |e| match e {
                Ok(e) => pager.offer(e),
                Err(_) => unreadable += 1,
            })
            .map_err(|_| ErrorReply::Storage)?;
        if let Some(e) = &self.state.open {
            pager.offer(e);
        }
        Ok((
            pager.seen(),
            store.lost_entries().saturating_add(unreadable),
        ))
    }

    /// Counts the entries only once the token is granted: a refused clear walks no flash.
    fn clear_log(&mut self) -> Result<u16, ErrorReply<'static>> {
        let cleared = self.store.at_standstill(self.state.t_s, |s, token| {
            let kept = s.read_log(&mut |_| ())?;
            s.clear_log(token).map(|()| kept)
        });
        match cleared {
            None => Err(ErrorReply::NotAtStandstill),
            Some(Err(_)) => Err(ErrorReply::Storage),
            Some(Ok(kept)) => Ok(u16::try_from(kept).unwrap_or(u16::MAX)),
        }
    }

    fn faults(&self) -> FaultReport {
        self.state.faults
    }

    fn take_telemetry(&mut self) -> Option<Telemetry> {
        self.state.telemetry.take()
    }

    fn model_report(&self) -> ModelReport<'_> {
        self.state.model.clone()
    }
}

/// The online model update as the link reports it.
pub fn model_report<M: UpdatableModel<N>, const N: usize, T: SolveFloat>(
    up: &ModelUpdater<M, N, T>,
) -> ModelReport<'static> {
    let (updates, gated, failures) = up.counts();
    ModelReport {
        enabled: up.config().enabled,
        updates,
        gated,
        failures,
        params: up
            .estimates()
            .iter()
            .map(|e| ParamReport {
                field: e.field,
                what: e.what,
                factor: e.factor as f32,
                sigma_ln: e.sigma_ln as f32,
                band_low: e.band.0 as f32,
                band_high: e.band.1 as f32,
                out_of_band: e.out_of_band,
            })
            .collect(),
    }
}

/// What [`save_vehicle`] did.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Saved {
    /// Not at standstill: the vehicle waits.
    Waiting,
    /// Saved: restart to run it.
    Saved,
    /// The write failed; retried at the next pass.
    Failed,
}

/// The background loop's part: a vehicle the host wrote ([`LinkState::take_unsaved`]) goes to
/// flash with the store's standstill token (the erase a write may need stalls flash reads);
/// unless [`Saved::Saved`], the caller hands it back ([`LinkState::keep_unsaved`]).
pub fn save_vehicle<F: NorFlash<Error = FlashError>>(
    task: &mut StoreTask<F>,
    v: &ImageVehicle,
    t_s: f64,
) -> Saved {
    match task.at_standstill(t_s, |store, token| store.save_config(v, token)) {
        Some(Ok(())) => Saved::Saved,
        Some(Err(_)) => Saved::Failed,
        None => Saved::Waiting,
    }
}

/// After [`Saved::Saved`]: whether the board may restart into the saved vehicle now. Only
/// with nothing waiting to be written (`entries_waiting`: entries still in the meter's queue;
/// the store's pending entries and boot count) and while the vehicle still stands with the
/// damper idle: it may have driven off while a maintenance waited for its retry.
pub fn may_restart<F: NorFlash<Error = FlashError>>(
    task: &mut StoreTask<F>,
    t_s: f64,
    entries_waiting: bool,
) -> bool {
    !entries_waiting
        && !task.store().needs_maintenance()
        && task.at_standstill(t_s, |_, _| ()).is_some()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fault_memory::ResetCause;
    use crate::monitoring::{DataMargin, MeterSample};
    use crate::sim::{self, SimWorld};
    use crate::store::{Layout, RamFlash, Store};
    use shimmy_core::vehicle::Vehicle;
    use shimmy_link::log::Recorder;
    use shimmy_link::wire::{fault_code, level_code, EVENTS_PER_PAGE};

    const PAGE: usize = 16 * 1024;
    type Flash = RamFlash<{ 4 * PAGE }, PAGE>;
    const LAYOUT: Layout = Layout::split(PAGE as u32, 2, 2);

    fn boot(flash: Flash) -> (StoreTask<Flash>, ImageVehicle) {
        let b = Store::boot(flash, LAYOUT, ResetCause::PowerOn, 0).unwrap();
        (StoreTask::new(b.store), b.report.config.vehicle)
    }

    /// The whole log as a host reads it, page by page.
    fn read_all(link: &mut BoardLink<'_, Flash>) -> (Vec<LogEntry>, u32) {
        let mut all = Vec::new();
        loop {
            let mut page = heapless::Vec::new();
            let (kept, dropped) = link
                .read_log(&mut Pager::new(all.len() as u16, &mut page))
                .unwrap();
            all.extend(page.iter().copied());
            if all.len() >= usize::from(kept) || page.is_empty() {
                assert!(page.len() <= EVENTS_PER_PAGE);
                return (all, dropped);
            }
        }
    }

    /// The speed the meter trusts (`DataMargin::speed_mps`) stands below this.
    fn stand(task: &mut StoreTask<Flash>, link: &mut LinkState, from_s: f64) {
        for k in 0..300 {
            let t = from_s + f64::from(k) * 0.01;
            task.step(
                crate::store::Motion {
                    t_s: t,
                    speed_mps: 0.0,
                    cmd_peak_a: 0.0,
                },
                core::iter::empty(),
            );
            link.t_s = t;
        }
    }

    /// The firmware's own chain on the simulated sensors (the QEMU app's scenario: shimmy at
    /// 8 Hz from boot, encoder faults at 1.3, 1.5 and 2.6 s) into the flash store, as the meter
    /// task and the background loop run it: the link serves each fault the supervisor raised,
    /// once, the boot, and the shimmy episode going on; after a reset, the same entries again
    /// (now from an earlier run) behind the new boot.
    #[test]
    fn the_scenario_fills_the_flash_log_and_a_reset_keeps_it() {
        use crate::control::{supervised_step, Health};
        use shimmy_core::supervisor::frame::MarginStatus;
        let world: &'static SimWorld = Box::leak(Box::new(SimWorld::new()));
        let mut sensors = sim::sensors(world);
        let mut ctrl = crate::monitoring::safe_controller();
        let mut data = DataMargin::new().unwrap();
        let (mut task, vehicle) = boot(Flash::new());
        let mut state = LinkState::new(&ResetRecord::fresh().sealed(), vehicle);
        let mut recorder = Recorder::new();
        let mut h = Health::default();
        let pwm = sim::SimPwm::new(world);
        let mut coil = crate::drivers::coil_pwm::CoilDriver::new(pwm, sim::COIL).unwrap();
        for step in 0..sim::SCENARIO_STEPS {
            world.set_step(step);
            let set = sensors.sample(sim::TICKS_PER_STEP);
            let out = supervised_step(
                &mut ctrl,
                &set,
                Some(coil.drive_a()),
                MarginStatus::NotUsed,
                &mut h,
            );
            crate::control::drive_coil(&mut coil, &out).unwrap();
            let s = MeterSample::of(step, &out);
            recorder.on_command(s.cmd_a);
            if let Some((u, _)) = data.push(&s, None) {
                let monitor = data.pipeline().monitor();
                let latched = ctrl.supervisor().latched().bits();
                let mut batch = Batch::new();
                recorder.on_update(monitor, &mut batch);
                recorder.on_faults(step, h.active_faults, latched, &mut batch);
                assert_eq!(batch.lost, 0);
                state.on_update(&u, recorder.open_event(monitor), &h, latched, step);
                let motion = crate::store::Motion {
                    t_s: u.report.t_s,
                    speed_mps: data.speed_mps(),
                    cmd_peak_a: s.cmd_a,
                };
                task.step(motion, batch.into_iter());
            }
        }
        let (entries, dropped) = read_all(&mut BoardLink {
            state: &mut state,
            store: &mut task,
        });
        assert_eq!(dropped, 0);
        assert!(
            matches!(entries.first(), Some(LogEntry::Boot(_))),
            "{entries:?}"
        );
        let faults: Vec<u8> = entries
            .iter()
            .filter_map(|e| match e {
                LogEntry::Fault(f) => Some(f.kind),
                _ => None,
            })
            .collect();
        assert_eq!(
            faults.len() as u32,
            h.faults_raised,
            "each raised fault once"
        );
        for k in [
            FaultKind::LeftFlag,
            FaultKind::RightFlag,
            FaultKind::RightStuck,
        ] {
            assert!(faults.contains(&fault_code(k)), "{} logged", k.name());
        }
        let Some(LogEntry::Shimmy(e)) = entries.last() else {
            panic!("the shimmy episode is the last entry: {entries:?}");
        };
        assert!(e.open);
        assert!(e.level >= level_code(shimmy_core::estimator::monitor::Level::MarginLow));
        assert!((e.freq_hz - sim::SHIMMY_HZ).abs() < 0.5, "{}", e.freq_hz);
        assert!(e.peak_current_a.is_finite());

        // A reset: the episode that was open is gone with the RAM, the rest is served again.
        let flash = task.store().flash().clone();
        let (mut task, vehicle) = boot(flash);
        let mut state = LinkState::new(&ResetRecord::fresh().sealed(), vehicle);
        let (after, _) = read_all(&mut BoardLink {
            state: &mut state,
            store: &mut task,
        });
        let closed = entries.len() - 1;
        assert_eq!(after[..closed], entries[..closed]);
        assert!(matches!(after[closed..], [LogEntry::Boot(_)]), "{after:?}");
    }

    /// A written vehicle is served as pending, waits while the vehicle moves, and is saved at
    /// the first standstill, so that the next boot runs it; a newer write wins over one that
    /// waits. A clear of the log is refused while moving, carried out at standstill.
    #[test]
    fn a_written_vehicle_is_saved_at_standstill_for_the_next_boot() {
        let (mut task, booted) = boot(Flash::new());
        let mut state = LinkState::new(&ResetRecord::fresh().sealed(), booted);
        assert_eq!(
            state.take_unsaved(),
            None,
            "the booted vehicle is in flash already"
        );
        let mut first = Vehicle::nominal();
        first.set("controller", "slew_a_per_s", 100.0).unwrap();
        let mut second = first;
        second.set("controller", "slew_a_per_s", 200.0).unwrap();
        let mut link = BoardLink {
            state: &mut state,
            store: &mut task,
        };
        assert!(!link.store_vehicle(first), "never in effect at once");
        assert_eq!(link.vehicle(), (&first, true), "served as pending");
        assert_eq!(link.clear_log(), Err(ErrorReply::NotAtStandstill));
        // Moving: the background loop hands it back...
        let taken = state.take_unsaved().unwrap();
        assert_eq!(save_vehicle(&mut task, &taken, 1.0), Saved::Waiting);
        state.keep_unsaved(taken);
        // ...unless the host wrote a newer one meanwhile.
        BoardLink {
            state: &mut state,
            store: &mut task,
        }
        .store_vehicle(second);
        state.keep_unsaved(first);
        let taken = state.take_unsaved().unwrap();
        assert_eq!(taken, second);
        stand(&mut task, &mut state, 1.0);
        assert_eq!(save_vehicle(&mut task, &taken, state.t_s), Saved::Saved);
        let mut link = BoardLink {
            state: &mut state,
            store: &mut task,
        };
        let (before, _) = read_all(&mut link);
        assert_eq!(link.clear_log(), Ok(before.len() as u16));
        assert!(read_all(&mut link).0.is_empty());
        // The restart: at standstill with nothing waiting, never while moving; the boot
        // loads the vehicle.
        assert!(!may_restart(&mut task, state.t_s, true), "an entry waits");
        assert!(may_restart(&mut task, state.t_s, false));
        task.step(
            crate::store::Motion {
                t_s: state.t_s + 0.01,
                speed_mps: 3.0,
                cmd_peak_a: 0.2,
            },
            core::iter::empty(),
        );
        assert!(
            !may_restart(&mut task, state.t_s + 0.01, false),
            "driven off"
        );
        let (_, next) = boot(task.store().flash().clone());
        assert_eq!(next, second);
    }
}
