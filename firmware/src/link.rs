//! The firmware's side of the host link (`shimmy-link`): the state the link serves, as a
//! [`Backend`] of the protocol handler. Host-compilable and host-tested; `main.rs` runs the
//! handler in the `link` task (USART1 interrupt, priority 1: below `meter` and `control`), and
//! the meter task feeds [`LinkState::on_sample`] / [`LinkState::on_update`].
//!
//! The configuration it serves is the vehicle this boot runs (the flash store's, else the
//! compiled-in defaults). A vehicle a host writes is kept here until the background loop saves
//! it with the store's standstill token ([`LinkState::take_unsaved`]); the boot after the save
//! runs it. The event log it serves is a [`RamLog`] of [`LOG_CAPACITY`] entries of this boot,
//! filled by its own [`Recorder`]; the flash log (`crate::store`) keeps the same episodes and
//! faults across resets through the store's own recorder. TODO(issue 24): serve the flash log
//! here, with one recorder for both, and hand a saved vehicle to the running tasks at
//! standstill instead of at the next boot.
//!
//! A configuration write is validated whole by the core (`Vehicle::decode_record`) before it
//! gets here; it takes effect only at standstill ([`STANDSTILL_MPS`]): while the vehicle moves it
//! is stored as pending and applied at the next standstill the meter task sees.

use shimmy_core::estimator::monitor::Monitor;
use shimmy_core::supervisor::faults::FaultSet;
use shimmy_core::vehicle::record_schema_of;
use shimmy_link::device::Backend;
use shimmy_link::log::{RamLog, Recorder};
use shimmy_link::wire::{level_code, FaultReport, Identity, LogEntry, Telemetry};
use shimmy_link::PROTOCOL_VERSION;

use crate::control::Health;
use crate::fault_memory::ResetRecord;
use crate::monitoring::{ImageVehicle, MarginUpdate};

/// Entries the RAM log keeps (the oldest go first).
pub const LOG_CAPACITY: usize = 32;
/// Below this trusted speed the vehicle is at standstill, m/s (an unknown speed is not): the
/// flash store's threshold, so the link and the store agree on what a standstill is.
pub const STANDSTILL_MPS: f32 = crate::store::STANDSTILL_SPEED_MPS;

/// What the link serves: configuration, event log, fault record, newest margin report.
pub struct LinkState {
    vehicle: ImageVehicle,
    pending: bool,
    /// A vehicle the host wrote that the flash store has not saved yet.
    unsaved: Option<ImageVehicle>,
    standstill: bool,
    log: RamLog<LOG_CAPACITY>,
    recorder: Recorder,
    faults: FaultReport,
    telemetry: Option<Telemetry>,
    open: Option<shimmy_link::wire::ShimmyEvent>,
}

impl LinkState {
    /// `vehicle`: the one this boot runs (the flash store's, or the compiled-in defaults), an
    /// empty log, no fault seen, speed unknown; `boot`: the reset record of this boot (resets,
    /// cause, faults latched before it).
    pub fn new(boot: &ResetRecord, vehicle: ImageVehicle) -> Self {
        LinkState {
            vehicle,
            pending: false,
            unsaved: None,
            standstill: false,
            log: RamLog::new(),
            recorder: Recorder::new(),
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
        }
    }

    /// The event log.
    pub fn log(&self) -> &RamLog<LOG_CAPACITY> {
        &self.log
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

    /// One 1 kHz sample's damper command, A (the controller's action during an episode).
    pub fn on_sample(&mut self, cmd_a: f32) {
        self.recorder.on_command(cmd_a);
    }

    /// After a 100 Hz margin update: the monitor's episodes and the supervisor's faults into
    /// the log, the fault record and the telemetry refreshed, and a pending configuration
    /// applied if the vehicle stands still (`speed_mps`: the newest trusted speed; `t_ms`: the
    /// control step of the update's sample, milliseconds since boot, wrapping after 49 days:
    /// the same time as the report's f64 seconds without a soft-float multiply and conversion
    /// per update).
    ///
    /// Latched faults: those restored at boot, plus the active ones of a latching kind (a
    /// latched fault stays active until the next power-on; the control task's own reset record
    /// is not shared, so that the 1 kHz step does no extra work for the link).
    pub fn on_update<const N: usize>(
        &mut self,
        u: &MarginUpdate,
        monitor: &Monitor<N>,
        speed_mps: f32,
        health: &Health,
        t_ms: u32,
    ) {
        self.recorder.on_update(monitor, &mut self.log);
        self.open = self.recorder.open_event(monitor);
        let latching = FaultSet::from_bits(health.active_faults)
            .iter()
            .filter(|k| k.latched())
            .fold(FaultSet::from_bits(self.faults.latched), |mut set, k| {
                set.insert(k);
                set
            })
            .bits();
        self.recorder
            .on_faults(t_ms, health.active_faults, latching, &mut self.log);
        self.faults = FaultReport {
            uptime_ms: t_ms,
            latched: latching,
            active: health.active_faults,
            raised: health.faults_raised,
            ..self.faults
        };
        let r = &u.report;
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
        self.standstill = speed_mps.is_finite() && speed_mps.abs() < STANDSTILL_MPS;
        if self.standstill {
            // TODO(issue 23): hand the vehicle to the control and meter tasks here (today
            // they run the compiled-in parameters; the flash store loads it at boot).
            self.pending = false;
        }
    }
}

impl Backend for LinkState {
    type Vehicle = ImageVehicle;
    fn identity(&self) -> Identity<'_> {
        Identity {
            firmware: crate::BANNER,
            core: shimmy_core::VERSION,
            protocol: PROTOCOL_VERSION,
            vehicle_schema: record_schema_of::<ImageVehicle>(),
            log_capacity: LOG_CAPACITY as u16,
        }
    }

    fn vehicle(&self) -> (&ImageVehicle, bool) {
        (&self.vehicle, self.pending)
    }

    fn store_vehicle(&mut self, v: ImageVehicle) -> bool {
        self.vehicle = v;
        self.unsaved = Some(v);
        self.pending = !self.standstill;
        self.standstill
    }

    fn log_len(&self) -> (u16, u32) {
        self.log.len_with_open(self.open)
    }

    /// The kept entries, then the episode still open (if any) as the last one.
    fn log_entry(&self, i: u16) -> Option<LogEntry> {
        self.log.get_with_open(i, self.open)
    }

    fn clear_log(&mut self) -> u16 {
        self.log.clear()
    }

    fn faults(&self) -> FaultReport {
        self.faults
    }

    fn take_telemetry(&mut self) -> Option<Telemetry> {
        self.telemetry.take()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::monitoring::{DataMargin, MeterSample};
    use crate::sim::{self, SimWorld};
    use shimmy_core::vehicle::Vehicle;
    use shimmy_link::wire::{fault_code, level_code};

    /// The firmware's own chain on the simulated sensors (the QEMU app's scenario: shimmy at
    /// 8 Hz from boot, encoder faults at 1.3, 1.5 and 2.6 s): the link state logs each fault
    /// the supervisor raised, once, and shows the shimmy episode going on.
    #[test]
    fn the_scenario_fills_the_log_with_its_faults_and_the_open_shimmy_episode() {
        use crate::control::{supervised_step, Health};
        use shimmy_core::supervisor::frame::MarginStatus;
        let world: &'static SimWorld = Box::leak(Box::new(SimWorld::new()));
        let mut sensors = sim::sensors(world);
        let mut ctrl = crate::monitoring::safe_controller();
        let mut data = DataMargin::new().unwrap();
        let mut link = LinkState::new(&ResetRecord::fresh().sealed(), Vehicle::nominal());
        let mut h = Health::default();
        let pwm = sim::SimPwm::new(world);
        let mut coil = crate::drivers::coil_pwm::CoilDriver::new(pwm, sim::COIL).unwrap();
        for step in 0..sim::SCENARIO_STEPS {
            world.set_step(step);
            let set = sensors.sample(sim::TICKS_PER_STEP);
            let out = supervised_step(&mut ctrl, &set, MarginStatus::NotUsed, &mut h);
            crate::control::drive_coil(&mut coil, &out).unwrap();
            let s = MeterSample::of(step, &out);
            link.on_sample(s.cmd_a);
            if let Some((u, _)) = data.push(&s, None) {
                let monitor = data.pipeline().monitor();
                link.on_update(&u, monitor, data.speed_mps(), &h, step);
            }
        }
        let (kept, _) = link.log_len();
        let entries: Vec<LogEntry> = (0..kept).filter_map(|i| link.log_entry(i)).collect();
        let faults: Vec<u8> = entries
            .iter()
            .filter_map(|e| match e {
                LogEntry::Fault(f) => Some(f.kind),
                LogEntry::Shimmy(_) => None,
            })
            .collect();
        assert_eq!(
            faults.len() as u32,
            h.faults_raised,
            "each raised fault once"
        );
        use shimmy_core::supervisor::faults::FaultKind;
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
        // Moving: a configuration waits for standstill.
        let mut v = Vehicle::nominal();
        v.set("plant", "k_d", 4000.0).unwrap();
        assert!(!link.store_vehicle(v));
        assert!(link.vehicle().1, "pending");
    }

    #[test]
    fn a_written_vehicle_waits_for_the_store_and_a_newer_one_wins() {
        let mut link = LinkState::new(&ResetRecord::fresh().sealed(), Vehicle::nominal());
        assert_eq!(
            link.take_unsaved(),
            None,
            "the booted vehicle is in flash already"
        );
        let mut first = Vehicle::nominal();
        first.set("controller", "slew_a_per_s", 100.0).unwrap();
        let mut second = first;
        second.set("controller", "slew_a_per_s", 200.0).unwrap();
        link.store_vehicle(first);
        let taken = link.take_unsaved().unwrap();
        assert_eq!(taken, first);
        assert_eq!(link.take_unsaved(), None, "handed out once");
        // No standstill yet: the background loop hands it back...
        link.keep_unsaved(taken);
        assert_eq!(link.take_unsaved(), Some(first));
        // ...unless the host wrote a newer one meanwhile.
        link.store_vehicle(second);
        link.keep_unsaved(first);
        assert_eq!(link.take_unsaved(), Some(second));
    }
}
