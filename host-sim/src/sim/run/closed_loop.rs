//! The closed loop in lockstep at the control rate (1 kHz): the nonlinear plant (with the MR
//! damper and its coil lag) -> [`sensors`](crate::model::sensors) (+ optional
//! [`faults`](crate::model::faults)) -> `shimmy_core::supervisor::safe_controller::SafeController`
//! (supervisor + `Controller` + final limiter, the firmware's 1 kHz call) -> coil-current command
//! -> plant; the data-driven mode meter (`shimmy_core::estimator::meter::mode_meter::MarginEstimator`)
//! runs on the validated encoder angles.
//!
//! Per control period `k` (t = k dt):
//! 1. the sensors read the true state at t (encoder angles with status bits, speed with its
//!    qualifier, coil current); a fault plan may rewrite the reading or lose the frame (then
//!    the previous command is held and nothing below runs);
//! 2. `SafeController::step` validates the raw frame and turns it into a current command
//!    (`LoopConfig::supervised == false`: the bare `Controller`, for negative tests); the
//!    margin-scheduled controller runs inside the firmware's application tasks
//!    (`shimmy_firmware::pil::HostApp`: control step, meter task after every 10th sample,
//!    model loop), so its margin report comes as on the board;
//! 3. the mode meter takes the validated sample (its 100 Hz outputs are recorded);
//! 4. observers (e.g. a margin pipeline or a monitor) see everything of the sample;
//! 5. the plant advances over [t, t + dt) with the command and the scenario's inputs held.
//!
//! [`run`] returns a decimated [`TraceRow`] trace, the meter outputs, the full-rate series
//! needed for metrics and the [`RunMetrics`].

use crate::model::coil_drive::{BoardDrive, CoilDrive};
use crate::model::disturbance::Scenario;
use crate::model::family::{FamilyVehicle, SimModel, SimPlant};
use crate::model::faults::{FaultPlan, FaultSpec};
use crate::model::integrator::IntegrateError;
use crate::model::plant::{Damper, Inputs, Method};
use crate::model::registry::{ReferenceModel, REFERENCE_N};
use crate::model::sensors::{CoilState, Measurement, Period, SensorConfig, Sensors, Truth};
use shimmy_core::control::actuator::CoilParams;
use shimmy_core::control::{
    ControlInput, ControlOutput, ControlParams, Controller, ControllerKind,
};
use shimmy_core::estimator::meter::mode_meter::{
    EstimatorConfig, MarginEstimator, MeterOutput, Sample, WheelOrder,
};
use shimmy_core::estimator::pipeline::PipelineParams;
use shimmy_core::model::UpdatableModel;
use shimmy_core::mr_damper::SpencerParams;
use shimmy_core::supervisor::checks::{Supervisor, SupervisorEvent};
use shimmy_core::supervisor::faults::{FaultKind, FaultRecord, FaultSet};
use shimmy_core::supervisor::frame::{MarginStatus, RawFrame};
use shimmy_core::supervisor::params::SupervisorParams;
use shimmy_core::supervisor::policy::{Mode, SupervisorVerdict};
use shimmy_core::supervisor::safe_controller::{SafeController, SafeOutput};
use shimmy_core::vehicle::Vehicle;
use shimmy_firmware::control::WATCHDOG_TIMEOUT_MAX_S;
use shimmy_firmware::monitoring::on_board;
use shimmy_firmware::pil::HostApp;

/// The closed loop's plant integrator: adaptive Verner 6(5) at rtol 1e-7. At that tolerance
/// its steps usually span the 1 ms period (1.1 steps, 8.8 right-hand-side calls per period on
/// the demo's ASMC arm), where Dopri5's take two (10.7 calls), and its error against a tight
/// reference is smaller (`cargo test -p shimmy-sim --test sim golden:: -- --nocapture`). The
/// fixed-step IMEX (`Method::ImexFixed`) is as accurate only at 3 steps per period and not
/// faster (speeds: `cargo bench -p shimmy-sim --bench plant -- closed_loop`).
pub const CLOSED_LOOP_METHOD: Method = Method::Vern65 { rtol: 1e-7 };

/// What sits on the track rod and drives it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Arm {
    /// No damper at all (F_d = 0): the reference plant that shimmies.
    NoDamper,
    /// The MR damper driven by a controller.
    Mr(ControllerKind),
}

impl Arm {
    /// Short name for tables, file names and legends.
    pub fn name(&self) -> &'static str {
        match self {
            Arm::NoDamper => "no-damper",
            Arm::Mr(k) => k.name(),
        }
    }

    /// Parses a name (`no-damper` or a controller name; `passive-on` takes `on_current_a`).
    pub fn from_name(name: &str, on_current_a: f32) -> Option<Self> {
        match name {
            "no-damper" | "none" => Some(Arm::NoDamper),
            n => ControllerKind::from_name(n, on_current_a).map(Arm::Mr),
        }
    }
}

/// Configuration of one closed-loop run on the vehicle model `M` (the car by default; any
/// member of the family, `crate::model::family`).
#[derive(Clone, Debug)]
pub struct LoopConfig<M: SimModel<N> = ReferenceModel, const N: usize = { REFERENCE_N }> {
    /// The true plant (the controller knows only `control.nominal`).
    pub plant: M,
    /// The true damper (the controller knows only `control.mr`); `Arm::NoDamper` removes it.
    pub damper: SpencerParams,
    /// Damper and controller.
    pub arm: Arm,
    /// Controller gains and limits, and the controller's model of plant and damper: what the
    /// firmware believes ([`Self::with_model`]).
    pub control: ControlParams,
    /// Sensor models.
    pub sensors: SensorConfig,
    /// Control period, s.
    pub dt_s: f64,
    /// Length of the run, s.
    pub duration_s: f64,
    /// Record every n-th period in the trace (metrics always use every period).
    pub record_every: usize,
    /// Run the data-driven mode meter.
    pub estimator: bool,
    /// Plant integrator.
    pub method: Method,
    /// Coil resistance for the energy metric, Ohm.
    pub coil_resistance_ohm: f64,
    /// Initial plant state (the model's layout; the wheel yaw angles first).
    pub x0: M::State,
    /// Injected faults (none by default).
    pub faults: Vec<FaultSpec>,
    /// Supervisor thresholds.
    pub supervisor: SupervisorParams,
    /// Run the supervised `SafeController` (default). `false`: the bare `Controller` on the
    /// measured angles (no validation) -- only to show what the supervisor prevents.
    pub supervised: bool,
    /// How the command reaches the coil: ideal (default) or the board's drive.
    pub coil_drive: CoilDrive,
    /// The nominal coil and driver the board's drive assumes (the vehicle's).
    pub coil: CoilParams,
    /// The margin path's plant model and parameters (the vehicle the firmware believes): the
    /// firmware's meter and model tasks run them in the loop for the margin-scheduled arm,
    /// whose controller gets their report ([`Self::margin_in_loop`]).
    pub margin_model: (M, PipelineParams),
}

/// The supervisor thresholds `p` for `arm`: unchanged, except that the passive-off reference
/// arm ("damper at 0 A", the baseline of the studies) gets no coil test pulse, which would put
/// 0.4 A into it every ~1.1 s.
fn reference_supervisor(arm: Arm, mut p: SupervisorParams) -> SupervisorParams {
    if arm == Arm::Mr(ControllerKind::PassiveOff) {
        p.coil_test_current_a = 0.0;
    }
    p
}

impl LoopConfig {
    /// The loop around `vehicle` (plant, damper, sensors and coil from it; the controller's
    /// model and gains from it too, see [`Self::with_model`] for a firmware that believes
    /// another vehicle): 1 kHz, trace at 200 Hz, meter on, plant at rest, the plant on
    /// [`CLOSED_LOOP_METHOD`].
    pub fn new(vehicle: &Vehicle, arm: Arm, duration_s: f64) -> Self {
        Self::for_vehicle(&FamilyVehicle::car(*vehicle), arm, duration_s)
    }

    /// The same loop with a firmware that believes `model` (the controller's plant and damper
    /// model, gains and limits; the supervisor's fail-safe current and coil full scale); the
    /// simulated plant, damper and sensors stay.
    #[must_use]
    pub fn with_model(self, model: &Vehicle) -> Self {
        self.with_model_vehicle(&FamilyVehicle::car(*model))
    }
}

impl<M: SimModel<N>, const N: usize> LoopConfig<M, N> {
    /// [`LoopConfig::new`] for a vehicle of any model of the family.
    pub fn for_vehicle(vehicle: &FamilyVehicle<M>, arm: Arm, duration_s: f64) -> Self {
        let parts = &vehicle.parts;
        LoopConfig {
            plant: vehicle.model,
            damper: parts.damper.spencer,
            arm,
            control: vehicle.control_params(),
            sensors: SensorConfig::from_vehicle(&parts.sensors),
            dt_s: 1e-3,
            duration_s,
            record_every: 5,
            estimator: true,
            method: CLOSED_LOOP_METHOD,
            coil_resistance_ohm: f64::from(parts.damper.coil.r_coil_ohm),
            x0: M::State::default(),
            faults: Vec::new(),
            supervisor: reference_supervisor(arm, vehicle.supervisor_params()),
            supervised: true,
            coil_drive: CoilDrive::Ideal,
            coil: parts.damper.coil,
            margin_model: (vehicle.model, vehicle.pipeline_params()),
        }
    }

    /// [`LoopConfig::with_model`] for a vehicle of any model of the family.
    #[must_use]
    pub fn with_model_vehicle(mut self, model: &FamilyVehicle<M>) -> Self {
        self.control = model.control_params();
        self.supervisor = reference_supervisor(self.arm, model.supervisor_params());
        self.margin_model = (model.model, model.pipeline_params());
        self
    }

    /// The firmware's margin path runs in the loop and feeds the controller (the
    /// margin-scheduled arm only: the other laws do not read the report, and their runs stay
    /// as they were).
    pub fn margin_in_loop(&self) -> bool {
        self.arm == Arm::Mr(ControllerKind::MarginAsmc)
    }
}

/// Everything about one sample, for observers.
#[derive(Clone, Copy, Debug)]
pub struct SampleRecord<'a> {
    /// Sample index.
    pub k: u64,
    /// Time, s.
    pub t_s: f64,
    /// True plant state at t (the model's layout, [`SimPlant::state`]).
    pub state: &'a [f64],
    /// Plant inputs held over [t, t + dt).
    pub inputs: &'a Inputs,
    /// What the firmware read.
    pub meas: &'a Measurement,
    /// The controller's output (in fail-safe: the fixed command with default fields).
    pub control: &'a ControlOutput,
    /// The supervised step's output (`None` for a lost frame or an unsupervised run).
    pub safe: Option<&'a SafeOutput>,
    /// The mode meter's output, on the samples where it produced one.
    pub meter: Option<&'a MeterOutput>,
    /// Damper force at t, N.
    pub damper_force_n: f64,
}

/// A hook that sees every sample (margin pipeline, monitor, fault bookkeeping, ...).
pub trait LoopObserver {
    /// Called once per control period, after the controller and the meter ran.
    fn on_sample(&mut self, r: &SampleRecord<'_>);
}

/// One recorded row of the trace.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct TraceRow {
    /// Time, s.
    pub t_s: f64,
    /// Left wheel yaw, rad.
    pub psi_l_rad: f64,
    /// Right wheel yaw, rad.
    pub psi_r_rad: f64,
    /// Steering-wheel angle, rad.
    pub theta_sw_rad: f64,
    /// Speed, m/s.
    pub speed_mps: f64,
    /// Driver torque, N m.
    pub driver_torque_nm: f64,
    /// Coil current command to the coil driver, A (0 while the coil is open or shorted).
    pub current_cmd_a: f64,
    /// Actual coil input (the damper's filtered u, 1 V per A), A.
    pub coil_a: f64,
    /// Damper force, N.
    pub damper_force_n: f64,
    /// Sliding variable, rad/s.
    pub s_radps: f64,
    /// Switching gain in use, rad/s^2.
    pub gain_radps2: f64,
    /// Control flags as bits: clipped 1, saturated 2, slew 4, invalid 8, below speed 16,
    /// adapting 32.
    pub flags: u8,
    /// Latest mode-meter slow damping ratio (NaN before the first valid one).
    pub zeta: f64,
    /// Latest mode-meter frequency, Hz (NaN before the first valid one).
    pub freq_hz: f64,
    /// Left wheel yaw the mode meter received this period, rad (the validated measurement;
    /// NaN when it received none): with `trace_every = 1` the trace is the meter's input log
    /// (`shimmy-sim analyze`).
    pub psi_l_meas_rad: f64,
    /// Right wheel yaw the mode meter received, rad (NaN: none).
    pub psi_r_meas_rad: f64,
    /// Measured speed of the meter's wheel-order reference, m/s (NaN: no sample).
    pub speed_meas_mps: f64,
}

/// One 100 Hz output of the mode meter.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MeterRow {
    /// Time, s.
    pub t_s: f64,
    /// True speed, m/s.
    pub speed_mps: f64,
    /// Slow (margin) estimate.
    pub zeta_slow: f64,
    /// Its one-sigma uncertainty.
    pub sigma_zeta_slow: f64,
    /// Fast (warning) estimate.
    pub zeta_fast: f64,
    /// Frequency of the slow estimate, Hz.
    pub freq_hz: f64,
    /// In-band amplitude, rad.
    pub amplitude_rad: f64,
    /// Slow estimate valid.
    pub valid: bool,
}

/// Full-rate series used for metrics.
#[derive(Clone, Debug, Default)]
pub struct Series {
    /// Left wheel yaw, rad.
    pub psi_l_rad: Vec<f64>,
    /// Steering-wheel angle, rad.
    pub theta_sw_rad: Vec<f64>,
    /// Current command to the coil driver, A (0 while the coil is open or shorted).
    pub cmd_a: Vec<f64>,
    /// Actual coil current, A.
    pub coil_a: Vec<f64>,
    /// Damper force, N.
    pub force_n: Vec<f64>,
}

/// Metrics of one run.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RunMetrics {
    /// Peak |psi_L|, rad.
    pub peak_yaw_rad: f64,
    /// RMS psi_L, rad.
    pub rms_yaw_rad: f64,
    /// 2 % settling time after the disturbance, s (`None` if no disturbance time was given or
    /// it never settled).
    pub settle_s: Option<f64>,
    /// Peak |theta_sw|, rad.
    pub peak_sw_rad: f64,
    /// RMS coil current, A.
    pub rms_current_a: f64,
    /// Peak coil current, A.
    pub peak_current_a: f64,
    /// Coil energy R * integral i^2 dt, J.
    pub energy_j: f64,
    /// Total variation of the current command sum |i_k - i_{k-1}|, A.
    pub chatter_a: f64,
    /// RMS damper force, N.
    pub rms_force_n: f64,
    /// Shimmy-band (high-passed at 2 Hz) amplitude of psi_L over the last 0.5 s, rad.
    pub amp_end_rad: f64,
    /// Time, s in 0.5 s blocks whose shimmy-band amplitude exceeds [`SHIMMY_AMP_RAD`].
    pub shimmy_s: f64,
    /// Largest shimmy-band block amplitude, rad.
    pub amp_max_rad: f64,
}

/// Shimmy-band amplitude above which a block counts as shimmy: 0.5 deg.
pub const SHIMMY_AMP_RAD: f64 = 0.5 * std::f64::consts::PI / 180.0;

/// Sustained shimmy: at least this long above [`SHIMMY_AMP_RAD`], s.
pub const SHIMMY_MIN_S: f64 = 3.0;

impl RunMetrics {
    /// CSV column names of [`RunMetrics::csv_fields`] (units in the names).
    pub const CSV_HEADER: &'static str = "peak_yaw_deg,rms_yaw_deg,settle_s,peak_sw_deg,rms_current_a,peak_current_a,energy_j,chatter_a,rms_force_n,shimmy_s,amp_end_deg,amp_max_deg";

    /// The metrics as comma-separated CSV fields (angles in degrees, an empty field for a
    /// missing settling time), in the order of [`RunMetrics::CSV_HEADER`].
    pub fn csv_fields(&self) -> String {
        format!(
            "{},{},{},{},{},{},{},{},{},{},{},{}",
            self.peak_yaw_rad.to_degrees(),
            self.rms_yaw_rad.to_degrees(),
            self.settle_s.map_or(String::new(), |x| x.to_string()),
            self.peak_sw_rad.to_degrees(),
            self.rms_current_a,
            self.peak_current_a,
            self.energy_j,
            self.chatter_a,
            self.rms_force_n,
            self.shimmy_s,
            self.amp_end_rad.to_degrees(),
            self.amp_max_rad.to_degrees(),
        )
    }

    /// A limit cycle / sustained shimmy was seen: the shimmy-band amplitude is above
    /// [`SHIMMY_AMP_RAD`] in the last 0.5 s, or it was above it for [`SHIMMY_MIN_S`] or longer
    /// (a shimmy that a speed ramp leaves behind at its end). A decaying transient of a
    /// disturbance does neither.
    pub fn shimmies(&self) -> bool {
        self.amp_end_rad > SHIMMY_AMP_RAD || self.shimmy_s >= SHIMMY_MIN_S
    }
}

/// Computes the metrics from full-rate series (period `dt_s`; disturbance at `t_dist_s`).
pub fn metrics(s: &Series, dt_s: f64, coil_r_ohm: f64, t_dist_s: Option<f64>) -> RunMetrics {
    let n = s.psi_l_rad.len().max(1) as f64;
    let peak = |v: &[f64]| v.iter().fold(0.0f64, |a, x| a.max(x.abs()));
    let rms = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / n).sqrt();
    let mut m = RunMetrics {
        peak_yaw_rad: peak(&s.psi_l_rad),
        rms_yaw_rad: rms(&s.psi_l_rad),
        peak_sw_rad: peak(&s.theta_sw_rad),
        rms_current_a: rms(&s.coil_a),
        peak_current_a: peak(&s.coil_a),
        energy_j: coil_r_ohm * s.coil_a.iter().map(|i| i * i).sum::<f64>() * dt_s,
        chatter_a: s.cmd_a.windows(2).map(|w| (w[1] - w[0]).abs()).sum(),
        rms_force_n: rms(&s.force_n),
        ..RunMetrics::default()
    };
    // Shimmy-band amplitude: 2nd-order Butterworth high pass at 2 Hz (bilinear), 0.5 s blocks.
    let hp = high_pass(&s.psi_l_rad, 2.0, dt_s);
    let block = ((0.5 / dt_s).round() as usize).max(1);
    let mut last = 0.0;
    for b in hp.chunks(block) {
        let a = peak(b);
        if a > SHIMMY_AMP_RAD {
            m.shimmy_s += b.len() as f64 * dt_s;
        }
        m.amp_max_rad = m.amp_max_rad.max(a);
        last = a;
    }
    m.amp_end_rad = last;
    // 2 % settling about the final value (mean of the last 0.5 s: a friction damper can stop
    // off centre), relative to the peak excursion after the disturbance.
    if let Some(td) = t_dist_s {
        let k0 = ((td / dt_s).round() as usize).min(s.psi_l_rad.len());
        let tail = &s.psi_l_rad[s.psi_l_rad.len().saturating_sub(block)..];
        let fin = tail.iter().sum::<f64>() / tail.len().max(1) as f64;
        let after = &s.psi_l_rad[k0..];
        let pk = after.iter().fold(0.0f64, |a, x| a.max((x - fin).abs()));
        let band = 0.02 * pk;
        if pk > 0.0 {
            let last_out = after.iter().rposition(|x| (x - fin).abs() > band);
            m.settle_s = match last_out {
                None => Some(0.0),
                Some(i) if i + block >= after.len() => None,
                Some(i) => Some((i + 1) as f64 * dt_s),
            };
        }
    }
    m
}

/// Second-order Butterworth high pass (bilinear transform, prewarped) of `x`.
pub fn high_pass(x: &[f64], fc_hz: f64, dt_s: f64) -> Vec<f64> {
    let k = (std::f64::consts::PI * fc_hz * dt_s).tan();
    let q = std::f64::consts::FRAC_1_SQRT_2;
    let norm = 1.0 / (1.0 + k / q + k * k);
    let (b0, b1, b2) = (norm, -2.0 * norm, norm);
    let a1 = 2.0 * (k * k - 1.0) * norm;
    let a2 = (1.0 - k / q + k * k) * norm;
    let (mut y1, mut y2) = (0.0, 0.0);
    let x0 = x.first().copied().unwrap_or(0.0);
    // Start from the first value as steady state (no step transient).
    let (mut xi1, mut xi2) = (x0, x0);
    x.iter()
        .map(|&xi| {
            let y = b0 * xi + b1 * xi1 + b2 * xi2 - a1 * y1 - a2 * y2;
            xi2 = xi1;
            xi1 = xi;
            y2 = y1;
            y1 = y;
            y
        })
        .collect()
}

/// What the supervisor saw and did during a run.
#[derive(Clone, Debug, Default)]
pub struct FaultLog {
    /// First time a fault was detected in a frame, s.
    pub first_detect_s: Option<f64>,
    /// First time the supervisor counted a missed sample, s.
    pub first_missed_s: Option<f64>,
    /// First time in Degraded, s.
    pub first_degraded_s: Option<f64>,
    /// First time in FailSafe, s.
    pub first_failsafe_s: Option<f64>,
    /// Worst mode seen.
    pub worst_mode: Mode,
    /// Mode of the last frame.
    pub final_mode: Mode,
    /// Every fault detected at least once.
    pub detected: FaultSet,
    /// Active faults at the end.
    pub final_faults: FaultSet,
    /// Counters of every fault kind that was detected.
    pub records: Vec<(FaultKind, FaultRecord)>,
    /// Supervisor events with their simulation time, s.
    pub events: Vec<(f64, SupervisorEvent)>,
    /// Frames lost by the fault plan (command held).
    pub lost_frames: u64,
    /// Watchdog resets: runs of lost frames longer than the watchdog's timeout
    /// (`shimmy_firmware::control::WATCHDOG_TIMEOUT_MAX_S`).
    pub watchdog_resets: u32,
    /// Samples the supervisor counted as missing.
    pub missed_samples: u32,
    /// Samples whose command was NaN or outside [0, i_max] (the output contract broken).
    pub invalid_commands: u64,
}

/// Result of one run.
#[derive(Clone, Debug, Default)]
pub struct LoopResult {
    /// Decimated trace.
    pub trace: Vec<TraceRow>,
    /// Mode-meter outputs (100 Hz).
    pub meter: Vec<MeterRow>,
    /// Full-rate series.
    pub series: Series,
    /// Simulated time, s.
    pub sim_s: f64,
    /// Wall-clock time of the run, s.
    pub wall_s: f64,
    /// Supervisor record (empty for unsupervised runs, except `invalid_commands`).
    pub faults: FaultLog,
}

impl LoopResult {
    /// Metrics with the disturbance at `t_dist_s`.
    pub fn metrics<M: SimModel<N>, const N: usize>(
        &self,
        cfg: &LoopConfig<M, N>,
        t_dist_s: Option<f64>,
    ) -> RunMetrics {
        metrics(&self.series, cfg.dt_s, cfg.coil_resistance_ohm, t_dist_s)
    }

    /// Writes the trace as CSV.
    pub fn write_trace_csv(&self, path: &std::path::Path) -> anyhow::Result<()> {
        use std::io::Write;
        let mut w = Vec::new();
        writeln!(
            w,
            "t_s,psi_l_rad,psi_r_rad,theta_sw_rad,speed_mps,driver_torque_nm,current_cmd_a,coil_a,damper_force_n,s_radps,gain_radps2,flags,zeta,freq_hz,psi_l_meas_rad,psi_r_meas_rad,speed_meas_mps"
        )?;
        // The meter's inputs are f32 widened to f64: printed in shortest round-trip form,
        // parsing them back gives the very same f32.
        for r in &self.trace {
            writeln!(
                w,
                "{},{:e},{:e},{:e},{},{},{},{},{},{},{},{},{},{},{},{},{}",
                r.t_s,
                r.psi_l_rad,
                r.psi_r_rad,
                r.theta_sw_rad,
                r.speed_mps,
                r.driver_torque_nm,
                r.current_cmd_a,
                r.coil_a,
                r.damper_force_n,
                r.s_radps,
                r.gain_radps2,
                r.flags,
                r.zeta,
                r.freq_hz,
                r.psi_l_meas_rad,
                r.psi_r_meas_rad,
                r.speed_meas_mps
            )?;
        }
        crate::sim::input::files::write_file(path, &w)
    }
}

fn flag_bits(o: &ControlOutput) -> u8 {
    let f = o.flags;
    u8::from(f.clipped)
        | (u8::from(f.saturated) << 1)
        | (u8::from(f.slew_limited) << 2)
        | (u8::from(f.input_invalid) << 3)
        | (u8::from(f.below_speed) << 4)
        | (u8::from(f.adapting) << 5)
}

/// Where the supervised 1 kHz step runs. [`run`] calls the core's `SafeController` in this
/// process; [`run_on`] hands each raw frame to another implementation: the firmware's tasks on
/// the host or the firmware image under QEMU (processor in the loop, `sim::pil`).
pub trait FirmwareStep {
    /// Why a step failed (e.g. the image under QEMU hung or crashed).
    type Error;
    /// One control period on `frame`: the supervised step's output (the margin report, if the
    /// controller reads one, is the firmware's own).
    fn step(&mut self, frame: &RawFrame) -> Result<SafeOutput, Self::Error>;
    /// The supervisor, when it runs in this process (the fault log's counters and events).
    fn supervisor(&mut self) -> Option<&mut Supervisor>;
    /// The board came back from a watchdog reset: the state a boot gives (the latched faults
    /// kept, as the fault memory does). Where the step cannot be rebooted (an image under QEMU,
    /// the application's tasks) it keeps its state.
    fn reboot(&mut self) {}
}

/// The core's `SafeController` in this process, with a fixed margin status; the controller as
/// it booted, for [`FirmwareStep::reboot`].
struct InProcess {
    safe: SafeController,
    booted: SafeController,
    margin: MarginStatus,
}

impl InProcess {
    fn new(safe: SafeController, margin: MarginStatus) -> Self {
        InProcess {
            booted: safe.clone(),
            safe,
            margin,
        }
    }
}

impl FirmwareStep for InProcess {
    type Error = std::convert::Infallible;
    fn step(&mut self, frame: &RawFrame) -> Result<SafeOutput, Self::Error> {
        Ok(self.safe.step(frame, self.margin))
    }
    fn supervisor(&mut self) -> Option<&mut Supervisor> {
        Some(self.safe.supervisor_mut())
    }
    fn reboot(&mut self) {
        let latched = self.safe.supervisor().latched();
        self.safe = self.booted.clone();
        self.safe.supervisor_mut().restore_latched(latched);
    }
}

/// The firmware's application tasks in this process (`HostApp`: the control step, the meter
/// task after every 10th sample, the model loop with each cycle done at once): the
/// margin-scheduled controller reads the meter task's report as on the board.
struct InApp<L: UpdatableModel<N>, const N: usize>(Box<HostApp<L, N>>);

impl<L: UpdatableModel<N>, const N: usize> FirmwareStep for InApp<L, N> {
    type Error = std::convert::Infallible;
    fn step(&mut self, frame: &RawFrame) -> Result<SafeOutput, Self::Error> {
        Ok(self.0.period(frame, None, &mut |_| {}))
    }
    fn supervisor(&mut self) -> Option<&mut Supervisor> {
        Some(self.0.supervisor_mut())
    }
}

/// Why [`run_on`] stopped.
#[derive(Debug)]
pub enum LoopError<E> {
    /// The plant's integrator failed.
    Integrate(IntegrateError),
    /// The firmware step failed.
    Firmware(E),
}

impl<E: std::fmt::Display> std::fmt::Display for LoopError<E> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            LoopError::Integrate(e) => write!(f, "plant integration: {e}"),
            LoopError::Firmware(e) => write!(f, "firmware: {e}"),
        }
    }
}

impl<E: std::fmt::Display + std::fmt::Debug> std::error::Error for LoopError<E> {}

/// Runs the closed loop over `scenario` (its `current_a` is ignored: the controller sets the
/// current). `observer` sees every sample.
pub fn run<M: SimModel<N>, const N: usize>(
    cfg: &LoopConfig<M, N>,
    scenario: &mut Scenario,
    observer: Option<&mut dyn LoopObserver>,
) -> Result<LoopResult, IntegrateError> {
    let kind = match cfg.arm {
        Arm::NoDamper => ControllerKind::PassiveOff,
        Arm::Mr(k) => k,
    };
    let safe = SafeController::new(kind, cfg.control, cfg.supervisor);
    let (model, pipeline) = cfg.margin_model;
    // The host build of the firmware's application runs the model task of a model the
    // firmware is built for; another model has no margin report in the loop (its commands
    // reject the margin-scheduled arm).
    let app = model
        .host_app_model()
        .filter(|_| cfg.margin_in_loop())
        .map(|(model, radius_m)| {
            HostApp::with_parts(safe.clone(), &on_board(pipeline), radius_m, model)
        });
    let r = match app {
        Some(app) => match app {
            Ok(app) => run_loop(cfg, scenario, observer, &mut InApp(Box::new(app))),
            // The parameters come from a validated vehicle; a configuration the meter rejects
            // leaves the report invalid, the schedule's safe side.
            Err(_) => run_loop(
                cfg,
                scenario,
                observer,
                &mut InProcess::new(safe, MarginStatus::Invalid),
            ),
        },
        None => run_loop(
            cfg,
            scenario,
            observer,
            &mut InProcess::new(
                safe,
                if cfg.margin_in_loop() {
                    MarginStatus::Invalid
                } else {
                    MarginStatus::NotUsed
                },
            ),
        ),
    };
    r.map_err(|e| match e {
        LoopError::Integrate(e) => e,
        LoopError::Firmware(never) => match never {},
    })
}

/// [`run`] with the supervised step in `fw` (the controller, gains and supervisor thresholds
/// are then `fw`'s own, and `cfg.supervised` is taken as true).
pub fn run_on<M: SimModel<N>, const N: usize, F: FirmwareStep>(
    cfg: &LoopConfig<M, N>,
    scenario: &mut Scenario,
    observer: Option<&mut dyn LoopObserver>,
    fw: &mut F,
) -> Result<LoopResult, LoopError<F::Error>> {
    let cfg = LoopConfig {
        supervised: true,
        ..cfg.clone()
    };
    run_loop(&cfg, scenario, observer, fw)
}

fn run_loop<M: SimModel<N>, const N: usize, F: FirmwareStep>(
    cfg: &LoopConfig<M, N>,
    scenario: &mut Scenario,
    mut observer: Option<&mut dyn LoopObserver>,
    safe: &mut F,
) -> Result<LoopResult, LoopError<F::Error>> {
    let wall = std::time::Instant::now();
    let (damper, kind) = match cfg.arm {
        Arm::NoDamper => (Damper::None, ControllerKind::PassiveOff),
        Arm::Mr(k) => (Damper::Mr(cfg.damper), k),
    };
    let mut sim = cfg.plant.plant(damper, cfg.method);
    sim.set_state(cfg.x0.as_ref());
    // the scenario's kingpin yaw torques are the car's (`SimModel::yaw_torque_scale`)
    let torque_scale = cfg.plant.yaw_torque_scale();
    let mut ctl = Controller::new(kind, cfg.control);
    let mut last_verdict = None;
    let mut sensors = Sensors::new(cfg.sensors);
    if !cfg.faults.is_empty() {
        sensors.fault = Some(Box::new(FaultPlan::new(
            cfg.faults.clone(),
            cfg.sensors.seed,
        )));
    }
    let no_damper = matches!(cfg.arm, Arm::NoDamper);
    let i_max = cfg.control.limits.i_max_a;
    // Command applied over the previous period (held across lost frames).
    let mut held = ControlOutput::default();
    // Time since the last completed control step, s, and whether the watchdog reset the board.
    let mut lost_run_s = 0.0;
    let mut in_reset = false;
    let mut drive = BoardDrive::new(cfg.coil_drive, cfg.coil);
    // The board drive's plant input of the previous period (held across lost frames).
    let mut driven_a = 0.0;
    let mut meter = if cfg.estimator {
        MarginEstimator::<f32>::new(EstimatorConfig::default()).ok()
    } else {
        None
    };
    let n = (cfg.duration_s / cfg.dt_s).round() as usize;
    let every = cfg.record_every.max(1);
    let mut res = LoopResult::default();
    let s = &mut res.series;
    s.psi_l_rad.reserve(n);
    s.theta_sw_rad.reserve(n);
    s.cmd_a.reserve(n);
    s.coil_a.reserve(n);
    s.force_n.reserve(n);
    let (mut zeta, mut freq) = (f64::NAN, f64::NAN);
    let radius = cfg.plant.rolling_radius_m() as f32;
    for k in 0..n {
        let t = k as f64 * cfg.dt_s;
        let [psi_l, psi_r] = sim.wheel_yaw_rad();
        let steering = sim.steering_angle_rad();
        let coil = if no_damper { 0.0 } else { sim.coil_input_a() };
        // The board's drive over the last period (`None`: an ideal current source, whose drive
        // is the command held over it).
        let coil_drive_a = drive.as_ref().map(BoardDrive::drive_a);
        let mut inputs = scenario.inputs(t, cfg.dt_s);
        for tq in &mut inputs.yaw_torque_nm {
            *tq *= torque_scale;
        }
        let Period {
            meas,
            coil: coil_state,
            drive: drive_condition,
        } = sensors.period(
            t,
            &Truth {
                psi_l_rad: psi_l,
                psi_r_rad: psi_r,
                speed_mps: inputs.speed_mps,
                coil_current_a: coil,
            },
            f64::from(coil_drive_a.unwrap_or(held.current_cmd_a)),
            no_damper,
        );
        let mut safe_out = None;
        if meas.lost {
            lost_run_s += cfg.dt_s;
        } else {
            lost_run_s = 0.0;
            if in_reset {
                safe.reboot();
                in_reset = false;
            }
        }
        let out = if meas.lost {
            res.faults.lost_frames += 1;
            if cfg.supervised && !in_reset && lost_run_s > f64::from(WATCHDOG_TIMEOUT_MAX_S) {
                // No control step completed for the watchdog's timeout: the board resets and
                // boots with the coil at the fail-safe current (off if a coil fault is latched),
                // open loop, until control steps complete again.
                in_reset = true;
                res.faults.watchdog_resets += 1;
                res.faults.first_detect_s.get_or_insert(t);
                res.faults.first_failsafe_s.get_or_insert(t);
                res.faults.worst_mode = Mode::FailSafe;
                let dead = last_verdict.is_some_and(|v: SupervisorVerdict| !v.damper_available);
                held = ControlOutput {
                    current_cmd_a: if dead {
                        0.0
                    } else {
                        cfg.supervisor.failsafe_current_a
                    },
                    ..ControlOutput::default()
                };
            }
            held
        } else if cfg.supervised {
            let t_us = ((t * 1e6).round() as u64) as u32;
            let o = safe
                .step(&meas.raw_frame(t_us, coil_drive_a))
                .map_err(LoopError::Firmware)?;
            log_verdict(&mut res.faults, safe.supervisor(), &o, t);
            last_verdict = Some(o.verdict);
            safe_out = Some(o);
            let mut c = o.control.unwrap_or_default();
            c.current_cmd_a = o.current_cmd_a;
            c
        } else {
            ctl.step(&ControlInput {
                t_s: t as f32,
                dt_s: cfg.dt_s as f32,
                psi_l_rad: meas.psi_l_rad,
                psi_r_rad: meas.psi_r_rad,
                speed_mps: meas.speed_mps,
                coil_current_a: meas.coil_current_a,
            })
        };
        held = out;
        if !(out.current_cmd_a.is_finite() && (0.0..=i_max).contains(&out.current_cmd_a)) {
            res.faults.invalid_commands += 1;
        }
        // The command to the coil driver: a NaN (only possible unsupervised) drives nothing.
        let cmd = if out.current_cmd_a.is_finite() {
            f64::from(out.current_cmd_a)
        } else {
            0.0
        };
        if let (Some(d), true) = (drive.as_mut(), in_reset) {
            // The boot's fixed duty: no current loop runs.
            driven_a = d.plant_input_a(out.current_cmd_a, None, cfg.dt_s as f32, drive_condition);
        } else if let (Some(d), false) = (drive.as_mut(), meas.lost) {
            // The firmware's `drive_coil`: off for a coil found open/shorted, else closed loop
            // on the trusted measured current.
            let (available, measured) = match &safe_out {
                Some(o) => (o.verdict.damper_available, o.validated.coil_current_a),
                None => (true, meas.coil_current_a),
            };
            driven_a = if available {
                d.plant_input_a(
                    out.current_cmd_a,
                    measured,
                    cfg.dt_s as f32,
                    drive_condition,
                )
            } else {
                d.off();
                0.0
            };
        }
        // Open or shorted coil: no current through the coil, whatever is commanded.
        let (coil_cmd, plant_in) = match coil_state {
            _ if no_damper => (0.0, 0.0),
            CoilState::Open | CoilState::Short { .. } => (0.0, 0.0),
            CoilState::Healthy => (cmd, if drive.is_some() { driven_a } else { cmd }),
        };
        inputs.current_cmd_a = plant_in;
        let wheel = WheelOrder::Speed {
            speed_mps: meas.speed_mps,
            radius_m: radius,
        };
        let sample = match (&safe_out, meas.lost) {
            (_, true) => None,
            (Some(o), _) => SafeController::estimator_sample(o, wheel),
            (None, _) => Some(Sample {
                psi_l_rad: meas.psi_l_rad,
                psi_r_rad: meas.psi_r_rad,
                wheel,
                damper_cmd: out.current_cmd_a,
            }),
        };
        let meter_in = sample.map_or((f64::NAN, f64::NAN, f64::NAN), |smp| {
            (
                f64::from(smp.psi_l_rad),
                f64::from(smp.psi_r_rad),
                f64::from(meas.speed_mps),
            )
        });
        let mo = match (meter.as_mut(), sample) {
            (Some(m), Some(smp)) => m.push(&smp),
            _ => None,
        };
        if let Some(o) = &mo {
            if o.slow.valid {
                zeta = f64::from(o.slow.zeta);
                freq = f64::from(o.slow.freq_hz);
            }
            res.meter.push(MeterRow {
                t_s: t,
                speed_mps: inputs.speed_mps,
                zeta_slow: f64::from(o.slow.zeta),
                sigma_zeta_slow: f64::from(o.slow.sigma_zeta),
                zeta_fast: f64::from(o.fast.zeta),
                freq_hz: f64::from(o.slow.freq_hz),
                amplitude_rad: f64::from(o.amplitude_rad),
                valid: o.slow.valid,
            });
        }
        let f_d = sim.damper_force_n(&inputs);
        s.psi_l_rad.push(psi_l);
        s.theta_sw_rad.push(steering);
        s.cmd_a.push(coil_cmd);
        s.coil_a.push(coil);
        s.force_n.push(f_d);
        if let Some(obs) = observer.as_deref_mut() {
            obs.on_sample(&SampleRecord {
                k: k as u64,
                t_s: t,
                state: sim.state(),
                inputs: &inputs,
                meas: &meas,
                control: &out,
                safe: safe_out.as_ref(),
                meter: mo.as_ref(),
                damper_force_n: f_d,
            });
        }
        if k % every == 0 {
            res.trace.push(TraceRow {
                t_s: t,
                psi_l_rad: psi_l,
                psi_r_rad: psi_r,
                theta_sw_rad: steering,
                speed_mps: inputs.speed_mps,
                driver_torque_nm: inputs.driver_torque_nm,
                current_cmd_a: coil_cmd,
                coil_a: coil,
                damper_force_n: f_d,
                s_radps: f64::from(out.s_radps),
                gain_radps2: f64::from(out.gain_radps2),
                flags: flag_bits(&out),
                zeta,
                freq_hz: freq,
                psi_l_meas_rad: meter_in.0,
                psi_r_meas_rad: meter_in.1,
                speed_meas_mps: meter_in.2,
            });
        }
        SimPlant::advance(&mut sim, cfg.dt_s, &inputs).map_err(LoopError::Integrate)?;
    }
    res.sim_s = n as f64 * cfg.dt_s;
    res.wall_s = wall.elapsed().as_secs_f64();
    if let Some(v) = last_verdict {
        res.faults.final_mode = v.mode;
        res.faults.final_faults = v.faults;
    }
    if let Some(sup) = safe.supervisor().filter(|_| cfg.supervised) {
        res.faults.final_mode = sup.mode();
        res.faults.final_faults = sup.faults();
        res.faults.missed_samples = sup.missed_samples();
        res.faults.records = FaultKind::ALL
            .into_iter()
            .map(|k| (k, sup.record(k)))
            .filter(|(_, r)| r.frames > 0)
            .collect();
    }
    if in_reset {
        // The run ends with the board in its boot's safe state.
        res.faults.final_mode = Mode::FailSafe;
    }
    Ok(res)
}

fn mode_rank(m: Mode) -> u8 {
    match m {
        Mode::Normal => 0,
        Mode::Degraded => 1,
        Mode::FailSafe => 2,
    }
}

/// Books one supervised step into the fault log (missed samples and events only when the
/// supervisor runs in this process).
fn log_verdict(log: &mut FaultLog, sup: Option<&mut Supervisor>, o: &SafeOutput, t_s: f64) {
    let v = &o.verdict;
    if !v.detected.is_empty() {
        log.first_detect_s.get_or_insert(t_s);
        for k in v.detected.iter() {
            log.detected.insert(k);
        }
    }
    let missed = sup.as_ref().is_some_and(|s| s.missed_samples() > 0);
    if missed {
        log.first_missed_s.get_or_insert(t_s);
    }
    match v.mode {
        Mode::Degraded => {
            log.first_degraded_s.get_or_insert(t_s);
        }
        Mode::FailSafe => {
            log.first_failsafe_s.get_or_insert(t_s);
        }
        Mode::Normal => {}
    }
    if mode_rank(v.mode) > mode_rank(log.worst_mode) {
        log.worst_mode = v.mode;
    }
    if let Some(sup) = sup {
        log.events.extend(sup.drain_events().map(|e| (t_s, e)));
    }
}
