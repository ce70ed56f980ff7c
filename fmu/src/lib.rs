//! The firmware's 1 kHz control step and the margin monitor as an FMI 3.0 co-simulation FMU
//! (`fmi-export`): raw sensor signals in, the coil-current command, the margin report and the
//! warning level out, every parameter from a vehicle (a named set or a vehicle file,
//! `docs/vehicle-file.md`).
//!
//! Per control period (1 ms) the FMU does exactly what the simulator's closed loop does
//! (`host-sim/src/sim/run/closed_loop.rs`, steps 2 and 3): the raw frame goes through the core's
//! `SafeController::step` (supervisor, ASMC, final limiter) with the vehicle's control and
//! supervisor parameters, and the validated sample feeds the core's `ShimmyPipeline` (mode
//! meter, model margin, fusion, monitor) with the vehicle's pipeline parameters. The outputs
//! after `fmi3DoStep(t, h)` are computed from the inputs set at `t` and are meant to be applied
//! over `[t, t + h)` (a sampled controller with direct feedthrough, as on the board); a step of
//! `h = n` ms runs `n` control periods on the held inputs.

use fmi::fmi3::Fmi3Error;
use fmi_export::fmi3::{CSDoStepResult, Context, DefaultLoggingCategory, UserModel};
use fmi_export::FmuModel;
use shimmy_core::control::ControllerKind;
use shimmy_core::estimator::meter::mode_meter::WheelOrder;
use shimmy_core::estimator::monitor::Level;
use shimmy_core::estimator::pipeline::ShimmyPipeline;
use shimmy_core::supervisor::frame::{EncoderReading, MarginStatus, RawFrame};
use shimmy_core::supervisor::policy::Mode;
use shimmy_core::supervisor::safe_controller::SafeController;
use shimmy_sim::sim::input::vehicle_file;

/// The control period, s (the firmware's 1 kHz step).
pub const CONTROL_PERIOD_S: f64 = 1e-3;

/// Entries of the monitor's event log.
const EVENT_LOG: usize = 16;

/// The supervised ASMC and the margin monitor of one vehicle (built on leaving
/// initialisation mode, when the `vehicle` parameter is final).
struct Loop {
    safe: SafeController,
    pipe: ShimmyPipeline<EVENT_LOG>,
    radius_m: f32,
    steps: u64,
}

/// shimmy: supervised adaptive sliding-mode damper controller and eigenvalue-margin monitor
#[derive(FmuModel, Default)]
#[model(model_exchange = false, co_simulation = true, user_model = false)]
pub struct ShimmyController {
    /// Vehicle: a named set (nominal, gentle, hard) or the path of a vehicle file (TOML)
    #[variable(causality = Parameter, variability = Fixed, start = String::from("nominal"))]
    pub vehicle: String,

    /// Left wheel-yaw encoder angle, rad
    #[variable(causality = Input, variability = Discrete, start = 0.0)]
    pub psi_l_rad: f64,
    /// Right wheel-yaw encoder angle, rad
    #[variable(causality = Input, variability = Discrete, start = 0.0)]
    pub psi_r_rad: f64,
    /// Left encoder transaction good: read completed, parity right, no error flag
    #[variable(causality = Input, variability = Discrete, start = true)]
    pub left_ok: bool,
    /// Right encoder transaction good: read completed, parity right, no error flag
    #[variable(causality = Input, variability = Discrete, start = true)]
    pub right_ok: bool,
    /// Vehicle speed, m/s
    #[variable(causality = Input, variability = Discrete, start = 0.0)]
    pub speed_mps: f64,
    /// The speed source marks its value valid (signal qualifier)
    #[variable(causality = Input, variability = Discrete, start = true)]
    pub speed_valid: bool,
    /// Measured coil current, A (NaN: not measured, the start value: an input left unconnected
    /// must not read as 0 A, which the supervisor takes for an open coil)
    #[variable(causality = Input, variability = Discrete, start = f64::NAN)]
    pub coil_current_a: f64,
    /// Longitudinal acceleration, m/s2 (for the margin's time to critical)
    #[variable(causality = Input, variability = Discrete, start = 0.0)]
    pub accel_mps2: f64,

    /// Coil-current command to the coil driver, A
    #[variable(causality = Output, variability = Discrete, initial = Exact, start = 0.0)]
    pub current_cmd_a: f64,
    /// Supervisor mode: 0 normal, 1 degraded, 2 fail-safe
    #[variable(causality = Output, variability = Discrete, initial = Exact, start = 0)]
    pub supervisor_mode: i32,
    /// The damper can be used (coil not found open or shorted)
    #[variable(causality = Output, variability = Discrete, initial = Exact, start = true)]
    pub damper_available: bool,
    /// Warning level: 0 normal, 1 margin low, 2 approaching critical, 3 shimmy present
    #[variable(causality = Output, variability = Discrete, initial = Exact, start = 0)]
    pub warning_level: i32,
    /// The margin report is valid
    #[variable(causality = Output, variability = Discrete, initial = Exact, start = false)]
    pub margin_valid: bool,
    /// Data (mode meter) damping ratio of the shimmy mode, slow estimate
    #[variable(causality = Output, variability = Discrete, initial = Exact, start = 0.0)]
    pub zeta_data: f64,
    /// One-sigma uncertainty of zeta_data
    #[variable(causality = Output, variability = Discrete, initial = Exact, start = 0.0)]
    pub sigma_zeta_data: f64,
    /// Fast (warning) damping estimate
    #[variable(causality = Output, variability = Discrete, initial = Exact, start = 0.0)]
    pub zeta_fast: f64,
    /// Frequency of the shimmy mode, Hz
    #[variable(causality = Output, variability = Discrete, initial = Exact, start = 0.0)]
    pub freq_hz: f64,
    /// Model damping ratio at the current speed (NaN: none yet)
    #[variable(causality = Output, variability = Discrete, initial = Exact, start = 0.0)]
    pub zeta_model: f64,
    /// Speed margin to the nearest Hopf crossing, m/s (NaN: none)
    #[variable(causality = Output, variability = Discrete, initial = Exact, start = 0.0)]
    pub speed_margin_mps: f64,
    /// Time to the critical speed at the current acceleration, s (NaN: not approaching)
    #[variable(causality = Output, variability = Discrete, initial = Exact, start = 0.0)]
    pub time_to_critical_s: f64,

    #[variable(skip = true)]
    state: Option<Box<Loop>>,
}

impl ShimmyController {
    /// Builds the controller and the monitor of the `vehicle` parameter.
    fn build(&self) -> Result<Loop, String> {
        let v = vehicle_file::load(&self.vehicle)
            .map_err(|e| format!("parameter `vehicle` = {:?}: {e:#}", self.vehicle))?;
        let pipe = ShimmyPipeline::new(v.plant, v.pipeline_params())
            .map_err(|e| format!("vehicle {:?}: margin pipeline: {e}", self.vehicle))?;
        Ok(Loop {
            safe: SafeController::new(
                ControllerKind::Asmc,
                v.control_params(),
                v.supervisor_params(),
            ),
            pipe,
            radius_m: v.plant.r as f32,
            steps: 0,
        })
    }

    /// One control period on the current inputs.
    fn control_period(&mut self, t_s: f64) -> Result<(), Fmi3Error> {
        let enc = |angle: f64, ok: bool| EncoderReading {
            angle_rad: angle as f32,
            read_ok: ok,
            parity_ok: ok,
            error_flag: false,
        };
        let frame = RawFrame {
            t_us: ((t_s * 1e6).round() as u64) as u32,
            left: enc(self.psi_l_rad, self.left_ok),
            right: enc(self.psi_r_rad, self.right_ok),
            speed_mps: self.speed_mps as f32,
            speed_valid: self.speed_valid,
            coil_current_a: self
                .coil_current_a
                .is_finite()
                .then_some(self.coil_current_a as f32),
            // The importer's coil drive is not modelled here: an ideal current source.
            coil_drive_a: None,
        };
        let lp = self.state.as_mut().ok_or(Fmi3Error::Error)?;
        lp.steps += 1;
        let out = lp.safe.step(&frame, MarginStatus::NotUsed);
        let wheel = WheelOrder::Speed {
            speed_mps: frame.speed_mps,
            radius_m: lp.radius_m,
        };
        let report = SafeController::estimator_sample(&out, wheel).and_then(|sample| {
            let speed = out.validated.speed_mps.unwrap_or(frame.speed_mps);
            lp.pipe.push(&sample, speed, self.accel_mps2 as f32, t_s)
        });
        self.current_cmd_a = f64::from(out.current_cmd_a);
        self.supervisor_mode = match out.verdict.mode {
            Mode::Normal => 0,
            Mode::Degraded => 1,
            Mode::FailSafe => 2,
        };
        self.damper_available = out.verdict.damper_available;
        if let Some(p) = report {
            let r = p.report;
            let nan = |x: Option<f32>| x.map_or(f64::NAN, f64::from);
            self.warning_level = match p.level {
                Level::Normal => 0,
                Level::MarginLow => 1,
                Level::ApproachingCritical => 2,
                Level::ShimmyPresent => 3,
            };
            self.margin_valid = r.valid;
            self.zeta_data = f64::from(r.zeta_data);
            self.sigma_zeta_data = f64::from(r.sigma_zeta_data);
            self.zeta_fast = f64::from(r.zeta_fast);
            self.freq_hz = f64::from(r.freq_hz);
            self.zeta_model = nan(r.zeta_model);
            self.speed_margin_mps = nan(r.speed_margin_mps);
            self.time_to_critical_s = nan(r.time_to_critical_s);
        }
        Ok(())
    }
}

impl UserModel for ShimmyController {
    type LoggingCategory = DefaultLoggingCategory;

    fn configurate(&mut self, context: &dyn Context<Self>) -> Result<(), Fmi3Error> {
        match self.build() {
            Ok(lp) => {
                self.state = Some(Box::new(lp));
                Ok(())
            }
            Err(e) => {
                context.log(
                    fmi::fmi3::Fmi3Status::from(Fmi3Error::Error),
                    DefaultLoggingCategory::LogAll,
                    format_args!("{e}"),
                );
                Err(Fmi3Error::Error)
            }
        }
    }

    fn do_step(
        &mut self,
        context: &mut dyn Context<Self>,
        current_communication_point: f64,
        communication_step_size: f64,
        _no_set_fmu_state_prior_to_current_point: bool,
    ) -> Result<CSDoStepResult, Fmi3Error> {
        let periods = communication_step_size / CONTROL_PERIOD_S;
        let n = periods.round();
        if !(n >= 1.0 && (periods - n).abs() < 1e-6) {
            context.log(
                fmi::fmi3::Fmi3Status::from(Fmi3Error::Error),
                DefaultLoggingCategory::LogAll,
                format_args!(
                    "communication step {communication_step_size} s: must be a whole number \
                     (at least 1) of the 1 ms control period"
                ),
            );
            return Err(Fmi3Error::Error);
        }
        for i in 0..n as u64 {
            self.control_period(current_communication_point + i as f64 * CONTROL_PERIOD_S)?;
        }
        let end = current_communication_point + communication_step_size;
        context.set_time(end);
        Ok(CSDoStepResult::completed(end))
    }
}

/// The FMI 3.0 C API of [`ShimmyController`] (generated; `coverage_nightly` is fmi-export's own
/// cfg, and the generated items carry no docs).
#[allow(unexpected_cfgs, missing_docs)]
mod export {
    use super::ShimmyController;
    fmi_export::export_fmu!(ShimmyController);
}
