//! The in-process simulator device: the link's own handler (`shimmy_link::device::Device`) on a
//! backend filled by the simulator's closed loop, behind the same [`Port`] as a board, so every
//! `shimmy-sim device` command works without hardware.
//!
//! The drive: the demo's road (noise, imbalance, a pothole) on a ramp through the vehicle's Hopf
//! window with the supervised ASMC, the margin pipeline (`ShimmyPipeline`, as on the board) on
//! the validated samples, a left-encoder parity fault injected for half a second, then braking to
//! a stop. The link's recorder turns the monitor's episodes and the supervisor's faults into the
//! log; the 10 Hz margin reports become the telemetry stream. After the drive the vehicle stands
//! still, so a configuration write takes effect at once.

use crate::model::board::BoardModel;
use crate::model::disturbance::{Scenario, SpeedProfile};
use crate::model::family::{FamilyVehicle, SimModel};
use crate::model::faults::{FaultMode, FaultSpec, Side};
use crate::sim::device::device_link::Port;
use crate::sim::run::closed_loop::{self, Arm, LoopConfig, LoopObserver, SampleRecord};
use crate::sim::run::demo_case::ROAD_SEED;
use crate::sim::run::standard::{fastest_growth_speed, pothole, road, POTHOLE_NM};
use anyhow::{Context, Result};
use shimmy_core::control::ControllerKind;
use shimmy_core::estimator::meter::mode_meter::WheelOrder;
use shimmy_core::estimator::pipeline::{PipelineParams, ShimmyPipeline};
use shimmy_core::model::UpdatableModel;
use shimmy_core::supervisor::faults::FaultSet;
use shimmy_core::supervisor::safe_controller::SafeController;
use shimmy_core::units::kmh_to_mps;
use shimmy_core::vehicle::{record_schema_of, RecordVehicle, Vehicle};
use shimmy_link::device::{Backend, Device, REPLY_BYTES};
use shimmy_link::log::{DiagnosisWatch, EventSink, Pager, RamLog, Recorder};
use shimmy_link::wire::{
    level_code, BootEvent, ErrorReply, FaultReport, Identity, LogEntry, ModelReport, ShimmyEvent,
    Telemetry,
};
use shimmy_link::PROTOCOL_VERSION;
use std::collections::VecDeque;
use std::time::{Duration, Instant};

/// The period of the telemetry stream, as on the board (10 Hz).
const REPORT_PERIOD: Duration = Duration::from_millis(100);

/// Capacity of the simulated device's log.
pub const SIM_LOG_CAPACITY: usize = 64;
/// The drive: ramp seconds, braking seconds, seconds standing at the end.
pub const DRIVE_S: (f64, f64, f64) = (16.0, 4.0, 1.0);
/// The injected parity fault on the left encoder: start and end, s.
pub const PARITY_FAULT_S: (f64, f64) = (6.0, 6.5);

/// What the simulated device serves: a vehicle record of a model's firmware image (the car's
/// `Vehicle` by default, [`BoardModel::Board`]) and what its drive logged.
pub struct SimBackend<V: RecordVehicle = Vehicle> {
    vehicle: V,
    pending: bool,
    standstill: bool,
    log: RamLog<SIM_LOG_CAPACITY>,
    open: Option<ShimmyEvent>,
    faults: FaultReport,
    telemetry: VecDeque<Telemetry>,
    model: ModelReport<'static>,
}

impl<V: RecordVehicle> Backend for SimBackend<V> {
    type Vehicle = V;
    fn identity(&self) -> Identity<'_> {
        Identity {
            firmware: concat!("shimmy-sim in-process device ", env!("CARGO_PKG_VERSION")),
            core: shimmy_core::VERSION,
            protocol: PROTOCOL_VERSION,
            vehicle_schema: record_schema_of::<V>(),
            log_capacity: SIM_LOG_CAPACITY as u16,
        }
    }
    fn vehicle(&self) -> (&V, bool) {
        (&self.vehicle, self.pending)
    }
    fn store_vehicle(&mut self, v: V) -> bool {
        self.vehicle = v;
        self.pending = !self.standstill;
        self.standstill
    }
    fn read_log(&mut self, pager: &mut Pager<'_>) -> Result<(u16, u32), ErrorReply<'static>> {
        Ok(self.log.page(self.open, pager))
    }
    /// As on the board: only standing (the board's clear erases flash).
    fn clear_log(&mut self) -> Result<u16, ErrorReply<'static>> {
        if !self.standstill {
            return Err(ErrorReply::NotAtStandstill);
        }
        Ok(self.log.clear())
    }
    fn faults(&self) -> FaultReport {
        self.faults
    }
    fn take_telemetry(&mut self) -> Option<Telemetry> {
        self.telemetry.pop_front()
    }
    fn model_report(&self) -> ModelReport<'_> {
        self.model.clone()
    }
}

/// The loop observer of the drive: pipeline (on the model `L` with `S` states), recorder, fault
/// bits, telemetry.
struct DriveObserver<V: RecordVehicle, L: UpdatableModel<S>, const S: usize> {
    pipe: Box<ShimmyPipeline<16, L, S>>,
    recorder: Recorder,
    diagnosis: DiagnosisWatch,
    backend: SimBackend<V>,
    radius_m: f32,
    last_v: Option<(f64, f32)>,
    updates: u32,
}

impl<V: RecordVehicle, L: UpdatableModel<S>, const S: usize> LoopObserver
    for DriveObserver<V, L, S>
{
    fn on_sample(&mut self, r: &SampleRecord<'_>) {
        let Some(o) = r.safe else {
            return;
        };
        self.recorder.on_command(o.current_cmd_a);
        let v = o.validated.speed_mps.unwrap_or(f32::NAN);
        let accel = match self.last_v {
            Some((t0, v0)) if v.is_finite() && r.t_s > t0 => (v - v0) / (r.t_s - t0) as f32,
            _ => 0.0,
        };
        if v.is_finite() {
            self.last_v = Some((r.t_s, v));
        }
        let wheel = WheelOrder::Speed {
            speed_mps: v,
            radius_m: self.radius_m,
        };
        let b = &mut self.backend;
        let active = o.verdict.faults.bits();
        let latched = FaultSet::from_bits(active)
            .iter()
            .filter(|k| k.latched())
            .fold(FaultSet::from_bits(0), |mut s, k| {
                s.insert(k);
                s
            })
            .bits();
        let t_ms = (r.t_s * 1e3).round() as u32;
        self.recorder.on_faults(t_ms, active, latched, &mut b.log);
        let new = active & !b.faults.active;
        b.faults.raised = b.faults.raised.saturating_add(new.count_ones());
        b.faults.uptime_ms = t_ms;
        b.faults.active = active;
        b.faults.latched |= latched;
        b.standstill = v.is_finite() && v.abs() < STANDSTILL_MPS;
        let Some(sample) = SafeController::estimator_sample(o, wheel) else {
            return;
        };
        let Some(u) = self.pipe.push(&sample, v, accel, r.t_s) else {
            return;
        };
        self.recorder.on_update(self.pipe.monitor(), &mut b.log);
        b.open = self.recorder.open_event(self.pipe.monitor());
        // the online model update's diagnosis, as the board's background loop logs it
        if let Some(e) = self
            .diagnosis
            .on_update(t_ms, self.pipe.updater().diagnosis_indexed())
        {
            b.log.append(LogEntry::Diagnosis(e));
        }
        self.updates += 1;
        if self.updates.is_multiple_of(10) {
            let m = &u.report;
            b.telemetry.push_back(Telemetry {
                t_s: m.t_s,
                speed_mps: m.speed_mps,
                zeta_data: m.zeta_data,
                sigma_zeta_data: m.sigma_zeta_data,
                zeta_fast: m.zeta_fast,
                freq_hz: m.freq_hz,
                zeta_model: m.zeta_model.unwrap_or(f32::NAN),
                speed_margin_mps: m.speed_margin_mps.unwrap_or(f32::NAN),
                level: level_code(u.level),
                valid: m.valid,
            });
        }
    }
}

/// Below this trusted speed the simulated vehicle stands still, m/s (the firmware's store's
/// value, so the simulated device and a board agree on what a standstill is).
pub use shimmy_firmware::store::STANDSTILL_SPEED_MPS as STANDSTILL_MPS;

/// Runs the drive with `vehicle` as plant and firmware model; returns the filled backend,
/// which stores the vehicle as its model's firmware image does.
pub fn drive<M: BoardModel<N>, const N: usize>(
    vehicle: &FamilyVehicle<M>,
) -> Result<SimBackend<M::Board>> {
    let (noise, imbalance) = road(ROAD_SEED, vehicle.model.rolling_radius_m());
    let mut scenario = Scenario::new(SpeedProfile::Piecewise(vec![]));
    scenario.noise = Some(noise);
    scenario.imbalance = Some(imbalance);
    if M::DEVICE_POTHOLE {
        // the demo's pothole, where the model's shimmy grows fastest on the ramp
        let (v0, v1) = (kmh_to_mps(20.0), kmh_to_mps(M::DEVICE_TOP_KMH));
        let v_fg = fastest_growth_speed(&vehicle.model.linear());
        scenario
            .impulses
            .push(pothole(DRIVE_S.0 * (v_fg - v0) / (v1 - v0), POTHOLE_NM));
    }
    drive_model(
        vehicle,
        M::board_vehicle(vehicle),
        vehicle.pipeline_params(),
        scenario,
        M::DEVICE_TOP_KMH,
    )
}

/// The drive of any model: `scenario`'s disturbances on the ramp 20 km/h -> `top_kmh`, braking
/// to a stop; `stored` is what the device then serves, `params` the margin pipeline's.
fn drive_model<M: SimModel<N>, const N: usize, V: RecordVehicle>(
    vehicle: &FamilyVehicle<M>,
    stored: V,
    params: PipelineParams,
    mut scenario: Scenario,
    top_kmh: f64,
) -> Result<SimBackend<V>> {
    let (ramp_s, brake_s, stand_s) = DRIVE_S;
    let top = kmh_to_mps(top_kmh);
    scenario.speed = SpeedProfile::Piecewise(vec![
        (0.0, kmh_to_mps(20.0)),
        (ramp_s, top),
        (ramp_s + brake_s, 0.0),
    ]);
    let duration = ramp_s + brake_s + stand_s;
    let mut cfg = LoopConfig::for_vehicle(vehicle, Arm::Mr(ControllerKind::Asmc), duration);
    cfg.estimator = false;
    cfg.record_every = 1000;
    cfg.faults = vec![FaultSpec {
        mode: FaultMode::Parity(Side::Left),
        start_s: PARITY_FAULT_S.0,
        end_s: Some(PARITY_FAULT_S.1),
    }];
    // the board's pipeline: the online model update on
    let params = shimmy_firmware::monitoring::on_board(params);
    let pipe = ShimmyPipeline::<16, M::Linear, N>::for_model(vehicle.model.linear(), params)
        .context("pipeline configuration")?;
    // The log starts as a board's does: with its first boot after a power-on.
    let mut log = RamLog::new();
    log.append(LogEntry::Boot(BootEvent {
        cause: 0,
        resets_since_power_on: 0,
        boot_count: 1,
    }));
    let model = shimmy_firmware::link::model_report(pipe.updater());
    let mut obs = DriveObserver {
        pipe: Box::new(pipe),
        recorder: Recorder::new(),
        diagnosis: DiagnosisWatch::new(),
        backend: SimBackend {
            vehicle: stored,
            pending: false,
            standstill: false,
            log,
            open: None,
            faults: FaultReport {
                resets: 0,
                last_cause: 0,
                quick_resets: 0,
                uptime_ms: 0,
                latched: 0,
                active: 0,
                raised: 0,
            },
            telemetry: VecDeque::new(),
            model,
        },
        radius_m: vehicle.model.rolling_radius_m() as f32,
        last_v: None,
        updates: 0,
    };
    closed_loop::run(&cfg, &mut scenario, Some(&mut obs)).context("the simulated drive")?;
    // the device serves what the drive left: the update as it ended
    obs.backend.model = shimmy_firmware::link::model_report(obs.pipe.updater());
    Ok(obs.backend)
}

/// The simulated device as a [`Port`]: bytes written go to the handler, its replies (and the
/// stream, while on) come back on reads.
pub struct SimDevice<V: RecordVehicle = Vehicle> {
    device: Device,
    backend: SimBackend<V>,
    out: VecDeque<u8>,
    reply: Box<[u8; REPLY_BYTES]>,
    /// When the stream last sent a report (the drive's reports go out at their 10 Hz).
    last_report: Option<Instant>,
}

impl<V: RecordVehicle> SimDevice<V> {
    /// Runs the drive with `vehicle` and announces the device (the ready frame): a device that
    /// stores vehicles of the model `M`.
    pub fn new<M: BoardModel<N, Board = V>, const N: usize>(
        vehicle: &FamilyVehicle<M>,
    ) -> Result<Self> {
        SimDevice::with_backend(drive(vehicle)?)
    }
}

impl<V: RecordVehicle> SimDevice<V> {
    /// The device serving `backend`, announced (the ready frame).
    fn with_backend(backend: SimBackend<V>) -> Result<Self> {
        let mut d = SimDevice {
            device: Device::new(),
            backend,
            out: VecDeque::new(),
            reply: Box::new([0; REPLY_BYTES]),
            last_report: None,
        };
        let n = Device::ready(&d.backend, &mut d.reply);
        d.out.extend(&d.reply[..n]);
        Ok(d)
    }

    /// The state behind the link (tests check that bad input leaves it alone).
    pub fn backend(&self) -> &SimBackend<V> {
        &self.backend
    }
}

impl<V: RecordVehicle> SimBackend<V> {
    /// The stored vehicle.
    pub fn stored_vehicle(&self) -> &V {
        &self.vehicle
    }
    /// Entries in the log (kept, dropped), without the open episode.
    pub fn logged(&self) -> (u16, u32) {
        self.log.len()
    }
}

impl<V: RecordVehicle> Port for SimDevice<V> {
    fn send(&mut self, bytes: &[u8]) -> Result<()> {
        for &b in bytes {
            if let Some(n) = self.device.on_byte(b, &mut self.backend, &mut self.reply) {
                self.out.extend(&self.reply[..n]);
            }
        }
        Ok(())
    }

    fn receive(&mut self, buf: &mut [u8], timeout: Duration) -> Result<usize> {
        if self.out.is_empty() {
            let due = self
                .last_report
                .is_none_or(|t| t.elapsed() >= REPORT_PERIOD);
            let report = if due {
                self.device.poll_stream(&mut self.backend, &mut self.reply)
            } else {
                None
            };
            if let Some(n) = report {
                self.last_report = Some(Instant::now());
                self.out.extend(&self.reply[..n]);
            } else {
                // Nothing will come: what a quiet serial line does until the timeout.
                std::thread::sleep(timeout.min(Duration::from_millis(5)));
                return Ok(0);
            }
        }
        let n = buf.len().min(self.out.len());
        for (slot, b) in buf.iter_mut().zip(self.out.drain(..n)) {
            *slot = b;
        }
        Ok(n)
    }
}
