//! [`SafeController`]: supervisor + controller + final limiter, the one call the firmware and the
//! simulator make every 1 ms.

use super::checks::{Supervisor, Validated};
use super::frame::{MarginStatus, RawFrame};
use super::params::SupervisorParams;
use super::policy::{Mode, SupervisorVerdict};
use crate::control::actuator::CurrentLimiter;
use crate::control::{ControlInput, ControlOutput, ControlParams, Controller, ControllerKind};
use crate::estimator::meter::mode_meter::{Sample, WheelOrder};

/// Output of one [`SafeController::step`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct SafeOutput {
    /// Coil-current command, A: finite, in [i_min, i_max] of the controller's limits.
    pub current_cmd_a: f32,
    /// The supervisor's verdict.
    pub verdict: SupervisorVerdict,
    /// Validated inputs.
    pub validated: Validated,
    /// The controller's output, if it ran this step.
    pub control: Option<ControlOutput>,
}

/// Supervisor + controller + final limiter: the one call the firmware and the simulator make
/// every 1 ms.
#[derive(Clone, Debug)]
pub struct SafeController {
    sup: Supervisor,
    ctl: Controller,
    out: CurrentLimiter,
    last_mode: Mode,
}

impl SafeController {
    /// A controller of `kind` with `params`, supervised with `sup`.
    pub fn new(kind: ControllerKind, params: ControlParams, sup: SupervisorParams) -> Self {
        SafeController {
            sup: Supervisor::new(sup),
            ctl: Controller::new(kind, params),
            out: CurrentLimiter::new(params.limits),
            last_mode: Mode::Normal,
        }
    }

    /// The supervisor.
    pub fn supervisor(&self) -> &Supervisor {
        &self.sup
    }

    /// The supervisor, mutable (e.g. [`Supervisor::clear_latched`]).
    pub fn supervisor_mut(&mut self) -> &mut Supervisor {
        &mut self.sup
    }

    /// The controller.
    pub fn controller(&self) -> &Controller {
        &self.ctl
    }

    /// The controller, mutable (e.g. `set_kind`).
    pub fn controller_mut(&mut self) -> &mut Controller {
        &mut self.ctl
    }

    /// The last coil command, A.
    pub fn last_command_a(&self) -> f32 {
        self.out.last()
    }

    /// One step: validate `frame`, run the controller on the validated inputs unless in
    /// FailSafe, apply the verdict, limit. `margin` is the latest margin report (its validity
    /// for the supervisor's margin check; a valid one also feeds the controller's margin
    /// schedule, an invalid one leaves the schedule on its safe side).
    pub fn step(&mut self, frame: &RawFrame, margin: MarginStatus) -> SafeOutput {
        let last_cmd = self.out.last();
        let (verdict, v) = self.sup.check(frame, last_cmd, margin);
        if self.last_mode == Mode::FailSafe && verdict.mode != Mode::FailSafe {
            // Filters hold pre-fault data: restart them.
            self.ctl.reset();
        }
        self.last_mode = verdict.mode;
        let (target, control) = match (verdict.mode, v.angles_rad) {
            (Mode::FailSafe, _) | (_, None) => (
                verdict
                    .safe_current_a
                    .unwrap_or(self.sup.params().failsafe_current_a),
                None,
            ),
            (_, Some((l, r))) => {
                self.ctl.set_margin(margin.signal());
                let c = self.ctl.step(&ControlInput {
                    t_s: v.t_s,
                    dt_s: v.dt_s,
                    psi_l_rad: l,
                    psi_r_rad: r,
                    // Unknown speed: do not gate (f32::MAX is above any gate).
                    speed_mps: v.speed_mps.unwrap_or(f32::MAX),
                    coil_current_a: v.coil_current_a,
                });
                let floor = verdict.safe_current_a.unwrap_or(0.0);
                (c.current_cmd_a.max(floor), Some(c))
            }
        };
        // The coil test pulse only raises the command (more current is only more damping).
        let target = target.max(verdict.test_current_a.unwrap_or(0.0));
        // Final clamp (NaN -> i_min) and slew limit: the output contract holds whatever
        // happened above.
        let lim = self.out.apply(target, v.dt_s);
        SafeOutput {
            current_cmd_a: lim.current_a,
            verdict,
            validated: v,
            control,
        }
    }

    /// The validated sample to feed the margin estimator, if the wheel yaw is trusted.
    pub fn estimator_sample(out: &SafeOutput, wheel: WheelOrder) -> Option<Sample> {
        out.validated.angles_rad.map(|(l, r)| Sample {
            psi_l_rad: l,
            psi_r_rad: r,
            wheel,
            damper_cmd: out.current_cmd_a,
        })
    }
}
