//! Processor in the loop: the seam between the PIL link and the application, host-compilable.
//!
//! - [`sample_set`]: the host's raw sensor frame as the sensor layer's [`SampleSet`], so the
//!   PIL board (`board/pil.rs`) feeds the control task through the same
//!   [`crate::control::raw_frame`] glue (and its driver-fault counters) as the board's drivers:
//!   a bus, parity or error-flag reading carries no angle, a missing coil-current reading is an
//!   ADC fault.
//! - [`HostApp`] (host only): the application's three tasks in the order the RTIC app runs them
//!   in one control period (control, the meter run after every 10th sample, the background
//!   loop until it has nothing due), on the host. It is the software-in-the-loop side of the
//!   PIL/SIL comparison (`shimmy-sim pil --check-sil`): the same code as the image, run
//!   natively, each task's body the RTIC task's own ([`crate::control::ControlTask::run`],
//!   [`crate::monitoring::DataMargin::run`], [`crate::background::model_pass`]); and the
//!   simulator's closed loop runs the margin-scheduled controller through it, so the
//!   simulator's margin report reaches the controller as on the board.

use crate::drivers::wheel_speed::{SpeedReading, SpeedStatus};
use crate::sensors::{SampleSet, SensorFault};
use shimmy_core::supervisor::frame::{EncoderReading, RawFrame};

fn encoder(e: &EncoderReading) -> Result<f32, SensorFault> {
    if !e.read_ok {
        Err(SensorFault::Bus)
    } else if !e.parity_ok {
        Err(SensorFault::Parity)
    } else if e.error_flag {
        // The host's encoder model has no ERRFL contents.
        Err(SensorFault::ErrorFlag(0))
    } else {
        Ok(e.angle_rad)
    }
}

/// The sensor layer's view of a raw frame from the host: what the board's drivers would have
/// returned for it.
pub fn sample_set(raw: &RawFrame) -> SampleSet {
    SampleSet {
        t_us: raw.t_us,
        psi_l_rad: encoder(&raw.left),
        psi_r_rad: encoder(&raw.right),
        speed: SpeedReading {
            speed_mps: raw.speed_mps,
            status: if raw.speed_valid {
                SpeedStatus::Valid
            } else {
                SpeedStatus::Starting
            },
        },
        coil_current_a: raw.coil_current_a.ok_or(SensorFault::Bus),
    }
}

#[cfg(not(target_os = "none"))]
pub use host::HostApp;

#[cfg(not(target_os = "none"))]
mod host {
    use super::sample_set;
    use crate::background::model_pass;
    use crate::control::{ControlTask, Health};
    use crate::monitoring::{
        board_pipeline, safe_controller_for, BoardCalibration, DataMargin, MeterEvent, MeterSample,
        ModelTask, Published,
    };
    use heapless::Deque;
    use rtic_core::Exclusive;
    use shimmy_core::estimator::meter::mode_meter::ConfigError;
    use shimmy_core::estimator::pipeline::PipelineParams;
    use shimmy_core::model::UpdatableModel;
    use shimmy_core::supervisor::checks::Supervisor;
    use shimmy_core::supervisor::frame::{MarginStatus, RawFrame};
    use shimmy_core::supervisor::safe_controller::{SafeController, SafeOutput};
    use shimmy_core::vehicle::BoardVehicle;
    use shimmy_pil::{MarginFrame, ModelFrame, StepReport, TargetFrame};

    /// The application's tasks on the host, one control period per [`HostApp::period`], with the
    /// state the RTIC app shares between them (`main.rs`: `Shared`, `Local`), for a vehicle
    /// whose linear model is `M` (`N` states): the image is built for one model (cargo feature
    /// `model-truck`), the host build runs any.
    pub struct HostApp<M: UpdatableModel<N>, const N: usize> {
        control: ControlTask,
        health: Health,
        /// The SPSC queue of the app (capacity 31).
        queue: Deque<MeterSample, 31>,
        data: DataMargin,
        model_task: ModelTask<M, N>,
        /// Every model cycle published so far, in order (cycle n at index n - 1).
        published: Vec<Published>,
        now: (f64, f32),
        margin: MarginStatus,
    }

    impl<M: UpdatableModel<N>, const N: usize> HostApp<M, N> {
        /// The application as `init` leaves it after a power-on (no latched fault) with
        /// `vehicle` loaded (the image under PIL boots with an empty RAM flash: its compiled-in
        /// vehicle, [`BoardVehicle::compiled_in`]).
        pub fn new<V: BoardVehicle<N, Model = M> + BoardCalibration>(
            vehicle: &V,
        ) -> Result<Self, ConfigError> {
            Self::with_parts(
                safe_controller_for(vehicle),
                &board_pipeline(vehicle),
                vehicle.wheel_order_radius_m(),
                vehicle.model(),
            )
        }

        /// The application around `ctrl` (its controller, gains and supervisor), the data path
        /// with `pipeline` and the wheel order's rolling radius `radius_m`, and the model task
        /// on `model`: [`Self::new`] takes them all from one vehicle; the simulator's studies
        /// also run other controllers or gains.
        pub fn with_parts(
            ctrl: SafeController,
            pipeline: &PipelineParams,
            radius_m: f32,
            model: M,
        ) -> Result<Self, ConfigError> {
            Ok(HostApp {
                control: ControlTask::new(ctrl),
                health: Health::default(),
                queue: Deque::new(),
                data: DataMargin::with_params(pipeline, radius_m)?,
                model_task: ModelTask::new(model, pipeline.matched_update()),
                published: Vec::new(),
                now: (0.0, f32::NAN),
                margin: MarginStatus::Invalid,
            })
        }

        /// The background model task (tracker, online model update).
        pub fn model_task(&self) -> &ModelTask<M, N> {
            &self.model_task
        }

        /// The health counters.
        pub fn health(&self) -> &Health {
            &self.health
        }

        /// The control task's supervisor (fault records and events).
        pub fn supervisor_mut(&mut self) -> &mut Supervisor {
            self.control.controller_mut().supervisor_mut()
        }

        /// One control period on `raw`; `emit` gets the frames the image would send, in the
        /// same order. `model_cycles`: for a meter run, how many model cycles it sees
        /// published (on the target this depends on how far the background loop got in
        /// instructions, which only the target knows; `None`: every cycle completed so far).
        /// Returns the control step's output.
        pub fn period(
            &mut self,
            raw: &RawFrame,
            model_cycles: Option<u32>,
            emit: &mut dyn FnMut(TargetFrame),
        ) -> SafeOutput {
            // control task (the board's coil and timing are the host's)
            let s = self.control.run(
                &sample_set(raw),
                raw.coil_drive_a,
                self.margin,
                &mut Exclusive(&mut self.health),
                |_| {},
                |sample| self.queue.push_back(sample).is_ok(),
            );
            self.health.record_step(s.dropped);
            let (step, out) = (s.step, s.out);
            emit(TargetFrame::Step(StepReport {
                step,
                out,
                instructions: 0,
            }));
            // meter task, spawned after every 10th sample
            if s.meter_due {
                let seen = model_cycles.map_or(self.published.len(), |n| n as usize);
                let model = seen
                    .checked_sub(1)
                    .and_then(|i| self.published.get(i))
                    .copied();
                let (queue, now, margin) = (&mut self.queue, &mut self.now, &mut self.margin);
                self.data.run(
                    model.as_ref(),
                    || queue.pop_front(),
                    |data, event| {
                        if let MeterEvent::Update(s, u, _) = event {
                            *now = (u.report.t_s, data.speed_mps());
                            *margin = data.margin_status();
                            emit(TargetFrame::Margin(MarginFrame {
                                step: s.step,
                                report: u.report,
                                level: u.level,
                                model_cycles: seen as u32,
                            }));
                        }
                    },
                );
                emit(TargetFrame::MeterRun {
                    step,
                    instructions: 0,
                });
            }
            // background loop: runs until nothing is due
            let mut measurement = self.data.take_measurement();
            loop {
                let published = &mut self.published;
                let done = model_pass::<(), _, _>(
                    &mut self.model_task,
                    self.now,
                    measurement.take(),
                    &mut Exclusive(&mut self.health),
                    |_| {},
                    |p| published.push(p),
                );
                if let Some((pt, cycles)) = done {
                    emit(TargetFrame::Model(ModelFrame {
                        cycle: cycles,
                        margin: pt.margin(),
                        instructions: 0,
                    }));
                }
                if !self.model_task.tracker().busy() {
                    break;
                }
            }
            out
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::control::raw_frame;
    use crate::control::Health;

    /// A healthy frame goes through the sensor layer and the firmware's frame glue unchanged,
    /// bit for bit; a parity error loses the angle (as the board's driver does) and is counted.
    #[test]
    fn host_frames_reach_the_supervisor_as_the_drivers_would_deliver_them() {
        let mut f = RawFrame::ok(7000, 0.0123, -0.0, 13.5);
        f.coil_current_a = Some(0.75);
        let mut h = Health::default();
        let back = raw_frame(&sample_set(&f), f.coil_drive_a, &mut h);
        assert_eq!(back.left.angle_rad.to_bits(), f.left.angle_rad.to_bits());
        assert_eq!(back.right.angle_rad.to_bits(), f.right.angle_rad.to_bits());
        assert_eq!(
            (back.t_us, back.speed_mps, back.coil_current_a),
            (7000, 13.5, Some(0.75))
        );
        assert_eq!(h, Health::default());
        f.left.parity_ok = false;
        f.speed_valid = false;
        f.coil_current_a = None;
        let back = raw_frame(&sample_set(&f), f.coil_drive_a, &mut h);
        assert!(!back.left.parity_ok && back.left.angle_rad.is_nan());
        assert!(!back.speed_valid);
        assert!(back.coil_current_a.is_some_and(f32::is_nan));
        // The ADC error is counted as a bus error, as `coil_current::Error::Adc` is on the board.
        assert_eq!((h.enc_parity, h.enc_bus), (1, 1));
    }

    /// The board's application updates its model from the wheel yaw it measures. The yaw is
    /// an AR(2) process with the shimmy pole of the `hard` car (half the drag-link stiffness,
    /// onset 7.6 km/h) at each speed of a 4 -> 6.5 km/h drive; the app's vehicle file is the
    /// nominal car (onset 29.35 km/h). After 90 s the update has found the drag link (factor
    /// within 2 sigma of 0.5, the diagnosis names it) and the tracker's onset is within
    /// 1 km/h of the plant's. The negative arm, the same drive with the update off: the
    /// onset stays the file's.
    #[test]
    fn the_board_app_updates_its_model_from_the_measured_yaw() {
        use shimmy_core::eigen;
        use shimmy_core::estimator::model_update::ModelUpdateConfig;
        use shimmy_core::model::LinearModel;
        use shimmy_core::stability::{self, ModeSelect};
        use shimmy_core::units::kmh_to_mps;
        use shimmy_core::vehicle::{BoardVehicle, Vehicle};
        use shimmy_core::vehicles::car::{ParamSet, PlantParams, N_STATES};
        let plant = ParamSet::Hard.params();
        let pole = |v: f64| {
            let a = plant.linearise(v, 0.0);
            let vals = eigen::eigenvalues_of::<f64, N_STATES>(&a).expect("eigenvalues");
            stability::select_mode_of::<f64, PlantParams, N_STATES>(
                &plant,
                &a,
                &vals,
                ModeSelect::Shimmy,
            )
            .expect("shimmy mode")
            .eigenvalue()
        };
        let drive = |update: ModelUpdateConfig| {
            let vehicle = Vehicle::nominal();
            let pipeline = shimmy_core::estimator::pipeline::PipelineParams {
                update,
                ..vehicle.margin_pipeline()
            };
            let mut app = HostApp::with_parts(
                crate::monitoring::safe_controller_for(&vehicle),
                &pipeline,
                crate::monitoring::ROLLING_RADIUS_M,
                vehicle.model(),
            )
            .expect("configuration");
            let (mut x1, mut x2, mut seed, mut cmd) = (0.0f64, 0.0f64, 7u32, 0.0f32);
            let steps = 90_000u32;
            for k in 0..steps {
                let v = kmh_to_mps(4.0 + 2.5 * f64::from(k) / f64::from(steps));
                let (l, dt) = (pole(v), 1e-3);
                let (r, w) = (libm::exp(l.re * dt), l.im * dt);
                // a sum of 4 uniforms: about Gaussian road excitation
                let mut e = 0.0;
                for _ in 0..4 {
                    seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                    e += f64::from(seed >> 8) / 16_777_216.0 - 0.5;
                }
                let x = 2.0 * r * libm::cos(w) * x1 - r * r * x2 + 2e-5 * e;
                (x2, x1) = (x1, x);
                let mut f = RawFrame::ok(k * 1000, x as f32, x as f32, v as f32);
                f.coil_current_a = Some(cmd);
                cmd = app.period(&f, None, &mut |_| {}).current_cmd_a;
            }
            let onset = app
                .model_task()
                .tracker()
                .latest()
                .and_then(|p| p.margin().v_crit_onset_mps)
                .expect("an onset");
            (app.model_task().updater().clone(), onset)
        };
        let truth = 7.633; // km/h, `shimmy-sim stability --vehicle hard`
        let (up, onset) = drive(ModelUpdateConfig::ON);
        let onset_kmh = shimmy_core::units::mps_to_kmh(onset);
        assert!(up.counts().0 > 40, "{:?}", up.counts());
        let d = up.diagnosis().expect("a diagnosis");
        assert_eq!(d.field, "k_d", "{d:?}");
        assert!(
            (libm::log(d.factor) - libm::log(0.5)).abs() <= 2.0 * d.sigma_ln,
            "{d:?}"
        );
        assert!((onset_kmh - truth).abs() < 1.0, "onset {onset_kmh} km/h");
        let (off, onset) = drive(ModelUpdateConfig::OFF);
        assert_eq!(off.counts(), (0, 0, 0));
        let onset_kmh = shimmy_core::units::mps_to_kmh(onset);
        assert!((onset_kmh - 29.35).abs() < 0.1, "onset {onset_kmh} km/h");
    }

    /// The host app answers like the image: one step report per period, a meter run after
    /// every 10th step with one margin update each, model cycles once the meter has published
    /// a speed.
    #[test]
    fn host_app_emits_the_frames_of_each_period_in_order() {
        use shimmy_pil::TargetFrame;
        let mut app =
            HostApp::new(&shimmy_core::vehicle::Vehicle::nominal()).expect("default configuration");
        let mut frames = Vec::new();
        for k in 0..300u32 {
            let mut f = RawFrame::ok(k * 1000, 0.0, 0.0, 12.0);
            f.coil_current_a = Some(0.0);
            app.period(&f, None, &mut |t| frames.push(t));
        }
        let count = |p: fn(&TargetFrame) -> bool| frames.iter().filter(|f| p(f)).count();
        assert_eq!(count(|f| matches!(f, TargetFrame::Step(_))), 300);
        assert_eq!(count(|f| matches!(f, TargetFrame::MeterRun { .. })), 30);
        assert_eq!(count(|f| matches!(f, TargetFrame::Margin(_))), 30);
        assert!(count(|f| matches!(f, TargetFrame::Model(_))) >= 2);
        assert!(matches!(frames[0], TargetFrame::Step(s) if s.step == 0));
        // the first meter run follows step 9 and reports sample 9
        let first_run = frames
            .iter()
            .position(|f| matches!(f, TargetFrame::MeterRun { .. }))
            .expect("a meter run");
        assert!(matches!(
            frames[first_run],
            TargetFrame::MeterRun { step: 9, .. }
        ));
        assert!(matches!(frames[first_run - 1], TargetFrame::Margin(m) if m.step == 9));
        assert_eq!(app.health().steps, 300);
    }
}
