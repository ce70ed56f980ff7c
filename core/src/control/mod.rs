//! MR steering-damper control: signal conditioning, the invertible damper model, the actuator
//! path and the controllers behind one run-time selectable interface.
//!
//! One [`Controller::step`] per sample (1 kHz): encoder angles in, coil-current command out.
//!
//! ```text
//! psi_L, psi_R --validate--> conditioning (mean, rate observer, shimmy-band HP, slow LP)
//!   --> law (PassiveOff | PassiveOn | SMC | ASMC | Skyhook) -> desired force F_des
//!   --> semi-active clip + MR inverse (measured stroke rate v_d = l_t psi')
//!   --> speed gate --> current limits + slew --> current_cmd_a  (--> actuator::CoilDriver -> PWM)
//! ```
//!
//! Everything is f32, heap-free and panic-free; time enters only as `dt_s`. Bad inputs (NaN,
//! Inf, angles beyond [`ControlParams::psi_limit_rad`], dt outside (0, 0.1] s) leave the filters
//! untouched and command [`ControlParams::fallback_current_a`] (a passive-on fail-safe).
//! The adaptive-SMC stability argument is in [`smc`].
//!
//! Use from a simulator or the firmware (one step per 1 ms sample):
//!
//! ```
//! use shimmy_core::control::{ControlInput, ControlParams, Controller, ControllerKind};
//! let mut ctl = Controller::new(ControllerKind::Asmc, ControlParams::default());
//! let out = ctl.step(&ControlInput {
//!     t_s: 0.0,
//!     dt_s: 1e-3,
//!     psi_l_rad: 0.001,
//!     psi_r_rad: 0.001,
//!     speed_mps: 20.0,
//!     coil_current_a: None,
//! });
//! assert!(out.current_cmd_a >= 0.0 && out.current_cmd_a <= 2.0);
//! // out.current_cmd_a goes to the coil (simulator: the Spencer model's u_cmd;
//! // firmware: actuator::CoilDriver::drive, with the measured coil current if there is one).
//! ```

pub mod actuator;
pub mod conditioning;
// Host-side model fitting, not on the control path.
#[cfg_attr(not(test), allow(clippy::indexing_slicing))]
pub mod mr_fit;
pub mod mr_model;
pub mod schedule;
pub mod smc;

use actuator::{CurrentLimiter, CurrentLimits};
use conditioning::{Conditioned, Conditioner, ConditioningParams};
use mr_model::MrModel;
use schedule::{MarginSignal, QuietCoil, ScheduleParams, SpeedSchedule};
use smc::{AdaptiveGain, AsmcParams, NominalPlant, SmcParams};

/// Which control law runs. Selectable at run time with [`Controller::set_kind`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ControllerKind {
    /// Coil off (0 A, or the limiter's minimum current).
    PassiveOff,
    /// Constant coil current, A.
    PassiveOn {
        /// The current, A (clamped to the limits).
        current_a: f32,
    },
    /// Sliding-mode control with a boundary layer and fixed gain.
    Smc,
    /// Adaptive sliding-mode control.
    Asmc,
    /// Clipped-optimal skyhook on the shimmy-band stroke rate: F_des = c_sky v_d,hp.
    Skyhook,
    /// The ASMC scheduled by the margin report, through the quiet coil ([`schedule`]).
    MarginAsmc,
    /// Current as a function of speed only (the production damper's baseline).
    SpeedScheduled(SpeedSchedule),
}

impl ControllerKind {
    /// Short name for logs and reports.
    pub fn name(&self) -> &'static str {
        match self {
            ControllerKind::PassiveOff => "passive-off",
            ControllerKind::PassiveOn { .. } => "passive-on",
            ControllerKind::Smc => "smc",
            ControllerKind::Asmc => "asmc",
            ControllerKind::Skyhook => "skyhook",
            ControllerKind::MarginAsmc => "margin-asmc",
            ControllerKind::SpeedScheduled(_) => "speed-sched",
        }
    }

    /// Parses a name (`passive-on` takes `on_current_a`; `speed-sched` needs its table and is
    /// not parsed).
    pub fn from_name(name: &str, on_current_a: f32) -> Option<Self> {
        Some(match name {
            "passive-off" | "off" => ControllerKind::PassiveOff,
            "passive-on" | "on" => ControllerKind::PassiveOn {
                current_a: on_current_a,
            },
            "smc" => ControllerKind::Smc,
            "asmc" => ControllerKind::Asmc,
            "skyhook" => ControllerKind::Skyhook,
            "margin-asmc" => ControllerKind::MarginAsmc,
            _ => return None,
        })
    }
}

/// All gains and limits of the control path, in one place.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ControlParams {
    /// Conditioning chain.
    pub conditioning: ConditioningParams,
    /// Nominal plant data (I_k, c_k, l_t).
    pub nominal: NominalPlant,
    /// Invertible damper model.
    pub mr: MrModel,
    /// Sliding surface and fixed-gain SMC.
    pub smc: SmcParams,
    /// Adaptation law.
    pub asmc: AsmcParams,
    /// Margin schedule and quiet coil of [`ControllerKind::MarginAsmc`].
    pub schedule: ScheduleParams,
    /// Skyhook coefficient on the shimmy-band stroke rate, N s/m.
    pub skyhook_ns_per_m: f32,
    /// Coil-current limits and slew rate.
    pub limits: CurrentLimits,
    /// Current commanded while inputs are invalid, A.
    pub fallback_current_a: f32,
    /// Below this speed the damper is left at the minimum current (no shimmy at walking pace,
    /// and parking is not made heavier), m/s. A non-finite speed does not gate.
    pub min_speed_mps: f32,
    /// Encoder angles beyond +-this are invalid, rad.
    pub psi_limit_rad: f32,
}

impl ControlParams {
    /// Defaults for the reference plant's nominal parameter set and the fitted damper.
    /// fallback: the fail-safe current [`actuator::FAILSAFE_CURRENT_A`] (a passive-on current
    /// that keeps the analysed plants stable); min speed 2 m/s; psi limit 0.8 rad (beyond full
    /// lock).
    pub const DEFAULT: Self = ControlParams {
        conditioning: ConditioningParams::DEFAULT,
        nominal: NominalPlant::DEFAULT,
        mr: MrModel::FITTED,
        smc: SmcParams::DEFAULT,
        asmc: AsmcParams::DEFAULT,
        schedule: ScheduleParams::DEFAULT,
        skyhook_ns_per_m: 1000.0,
        limits: CurrentLimits::DEFAULT,
        // the fail-safe current (one place, next to the coil limits; chosen from the stability
        // analysis)
        fallback_current_a: actuator::FAILSAFE_CURRENT_A,
        min_speed_mps: 2.0,
        psi_limit_rad: 0.8,
    };
}

impl Default for ControlParams {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// Inputs of one control step.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ControlInput {
    /// Time of the sample, s (logged; the laws use `dt_s`).
    pub t_s: f32,
    /// Time since the previous step, s (nominally 1e-3).
    pub dt_s: f32,
    /// Left wheel yaw, rad.
    pub psi_l_rad: f32,
    /// Right wheel yaw, rad.
    pub psi_r_rad: f32,
    /// Vehicle speed, m/s.
    pub speed_mps: f32,
    /// Measured coil current in A, if available (passed through to the actuator path).
    pub coil_current_a: Option<f32>,
}

/// Status flags of one control step.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct ControlFlags {
    /// The semi-active constraint removed the request (F_des v_d <= 0).
    pub clipped: bool,
    /// The request needed more than I_max (inverse or limiter clamp at the top).
    pub saturated: bool,
    /// The slew limit shortened the current step.
    pub slew_limited: bool,
    /// Inputs invalid: fallback current, filters held.
    pub input_invalid: bool,
    /// Below the speed gate.
    pub below_speed: bool,
    /// The ASMC growth term was active this step.
    pub adapting: bool,
    /// The quiet coil is engaged ([`ControllerKind::MarginAsmc`]).
    pub engaged: bool,
}

/// Outputs of one control step.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct ControlOutput {
    /// Coil-current command in A, always in [i_min, i_max] and finite.
    pub current_cmd_a: f32,
    /// Desired damper force of the law, N (before the semi-active clip; for passive modes the
    /// model force at the commanded current).
    pub desired_force_n: f32,
    /// Sliding variable s, rad/s.
    pub s_radps: f32,
    /// Switching gain in use (adaptive for ASMC, fixed for SMC, 0 otherwise), rad/s^2.
    pub gain_radps2: f32,
    /// Stroke rate estimate v_d = l_t psi', m/s.
    pub stroke_rate_mps: f32,
    /// Conditioned signals.
    pub conditioned: Conditioned,
    /// Status flags.
    pub flags: ControlFlags,
}

/// The damper controller: conditioning + law + inverse + limits, one `step` per sample.
#[derive(Clone, Copy, Debug)]
pub struct Controller {
    kind: ControllerKind,
    params: ControlParams,
    cond: Conditioner,
    gain: AdaptiveGain,
    limiter: CurrentLimiter,
    coil: QuietCoil,
    margin: Option<MarginSignal>,
}

impl Controller {
    /// A controller of `kind` with `params`.
    pub fn new(kind: ControllerKind, params: ControlParams) -> Self {
        Controller {
            kind,
            params,
            cond: Conditioner::new(&params.conditioning),
            gain: AdaptiveGain::new(&params.asmc),
            limiter: CurrentLimiter::new(params.limits),
            coil: QuietCoil::new(),
            margin: None,
        }
    }

    /// The newest margin report for the schedule (`None`: no valid report, the schedule's safe
    /// side). Kept until the next call.
    pub fn set_margin(&mut self, margin: Option<MarginSignal>) {
        self.margin = margin;
    }

    /// The margin the schedule uses.
    pub fn margin(&self) -> Option<&MarginSignal> {
        self.margin.as_ref()
    }

    /// The quiet coil's state (noise floor).
    pub fn quiet_coil(&self) -> &QuietCoil {
        &self.coil
    }

    /// The law in use.
    pub fn kind(&self) -> ControllerKind {
        self.kind
    }

    /// The parameters.
    pub fn params(&self) -> &ControlParams {
        &self.params
    }

    /// Switches the law at run time (conditioning, limiter and adaptive gain keep their state,
    /// so the switch is bumpless up to the slew limit).
    pub fn set_kind(&mut self, kind: ControllerKind) {
        self.kind = kind;
    }

    /// Current adaptive gain, rad/s^2.
    pub fn adaptive_gain(&self) -> f32 {
        self.gain.get()
    }

    /// Back to the initial state (filters re-initialise on the next sample, gain to K_init,
    /// command to the minimum current).
    pub fn reset(&mut self) {
        self.cond.reset();
        self.gain.reset(&self.params.asmc);
        self.limiter.reset_to(0.0);
        self.coil = QuietCoil::new();
    }

    fn inputs_valid(&self, i: &ControlInput) -> bool {
        let lim = self.params.psi_limit_rad;
        libm::fabsf(i.psi_l_rad) <= lim
            && libm::fabsf(i.psi_r_rad) <= lim
            && i.dt_s > 0.0
            && i.dt_s <= 0.1
    }

    /// One control step. Call once per sample (the filters are designed for
    /// `params.conditioning.sample_rate_hz`).
    pub fn step(&mut self, input: &ControlInput) -> ControlOutput {
        // By reference: a copy of the whole parameter set costs the 1 kHz step ~250 instructions.
        let p = &self.params;
        let mut flags = ControlFlags::default();
        if !self.inputs_valid(input) {
            flags.input_invalid = true;
            let dt = if input.dt_s > 0.0 && input.dt_s <= 0.1 {
                input.dt_s
            } else {
                1.0 / p.conditioning.sample_rate_hz
            };
            let lim = self.limiter.apply(p.fallback_current_a, dt);
            flags.slew_limited = lim.slew_limited;
            // The adaptive gain only leaks while blind.
            self.gain.update(&p.asmc, 0.0, dt, true);
            return ControlOutput {
                current_cmd_a: lim.current_a,
                desired_force_n: 0.0,
                s_radps: 0.0,
                gain_radps2: self.gain.get(),
                stroke_rate_mps: 0.0,
                conditioned: self.cond.last(),
                flags,
            };
        }
        let dt = input.dt_s;
        let c = self.cond.update(input.psi_l_rad, input.psi_r_rad);
        let nom = &p.nominal;
        let v_d = nom.l_t_m * c.rate_radps;
        let s = smc::sliding_surface(c.psi_hp_rad, c.rate_hp_radps, p.smc.lambda_per_s);
        // Law -> (target current, desired force, gain shown).
        let (target, force, gain) = match self.kind {
            ControllerKind::PassiveOff => (0.0, None, 0.0),
            ControllerKind::PassiveOn { current_a } => (current_a, None, 0.0),
            ControllerKind::SpeedScheduled(table) => (table.current_at(input.speed_mps), None, 0.0),
            ControllerKind::MarginAsmc => {
                let sch = p.schedule.schedule(self.margin.as_ref(), p.smc.phi_radps);
                let smc = SmcParams {
                    phi_radps: sch.phi_radps,
                    ..p.smc
                };
                let k = self.gain.get();
                let f = smc::smc_force_n(nom, &smc, s, c.rate_hp_radps, k);
                let inv = p.mr.inverse(f, v_d);
                flags.clipped = inv.clipped;
                flags.saturated = inv.saturated;
                let amp = self
                    .coil
                    .band_amplitude(&p.schedule, c.psi_hp_rad, c.rate_hp_radps, dt);
                let q = self
                    .coil
                    .step(&p.schedule, &sch, amp, inv.current_a, p.limits.i_max_a, dt);
                flags.engaged = q.engaged;
                (q.current_a, Some(f), k)
            }
            ControllerKind::Smc | ControllerKind::Asmc | ControllerKind::Skyhook => {
                let (f, k) = match self.kind {
                    ControllerKind::Smc => (
                        smc::smc_force_n(nom, &p.smc, s, c.rate_hp_radps, p.smc.k_radps2),
                        p.smc.k_radps2,
                    ),
                    ControllerKind::Asmc => (
                        smc::smc_force_n(nom, &p.smc, s, c.rate_hp_radps, self.gain.get())
                            * smc::quiet_weight(s, p.asmc.dead_zone_radps),
                        self.gain.get(),
                    ),
                    _ => (p.skyhook_ns_per_m * nom.l_t_m * c.rate_hp_radps, 0.0),
                };
                let inv = p.mr.inverse(f, v_d);
                flags.clipped = inv.clipped;
                flags.saturated = inv.saturated;
                (inv.current_a, Some(f), k)
            }
        };
        let gated = input.speed_mps < p.min_speed_mps;
        flags.below_speed = gated;
        let target = if gated { 0.0 } else { target };
        let lim = self.limiter.apply(target, dt);
        flags.slew_limited = lim.slew_limited;
        flags.saturated |= lim.clamped && target > p.limits.i_max_a;
        let force = force.unwrap_or_else(|| p.mr.force_n(lim.current_a, v_d));
        let adaptive = matches!(self.kind, ControllerKind::Asmc | ControllerKind::MarginAsmc);
        if adaptive {
            let limited = flags.clipped || flags.saturated || flags.slew_limited;
            // The margin-scheduled law learns only while its coil is engaged (road noise below
            // the engage amplitude does not pump K).
            let idle = self.kind == ControllerKind::MarginAsmc && !flags.engaged;
            let freeze = gated || idle || (p.asmc.anti_windup && limited);
            flags.adapting = self.gain.update(&p.asmc, s, dt, freeze);
        }
        ControlOutput {
            current_cmd_a: lim.current_a,
            desired_force_n: force,
            s_radps: s,
            gain_radps2: gain,
            stroke_rate_mps: v_d,
            conditioned: c,
            flags,
        }
    }
}

#[cfg(test)]
mod tests;
