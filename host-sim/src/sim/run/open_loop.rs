//! Open-loop runs of the plant (no controller in the loop): a scenario's inputs applied period
//! by period ([`simulate`], recording a [`Trace`]), and constant-speed runs with a fixed damper
//! setting summarised by their end amplitude ([`run_speed`]), with the peak-tracking analysis
//! ([`peaks`], [`fit_growth`]) used to compare time-domain growth rates with eigenvalues.

use crate::model::disturbance::Scenario;
use crate::model::family::{SimModel, SimPlant};
use crate::model::integrator::IntegrateError;
use crate::model::plant::{Damper, Forces, Inputs, Method, Simulator, State, STATE_NAMES};
use shimmy_core::mr_damper::SpencerParams;

/// Control period of the runs, s (inputs held per period, as in closed loop).
pub const DT_S: f64 = 1e-3;

/// What a run's oscillation does at its end.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Trend {
    /// Amplitude in the last window > 1.02 x the window before.
    Growing,
    /// Amplitude in the last window < 0.98 x the window before.
    Decaying,
    /// Within +-2 %: a settled limit cycle (or rest).
    Steady,
}

impl Trend {
    /// Label for tables and CSV.
    pub fn name(self) -> &'static str {
        match self {
            Trend::Growing => "growing",
            Trend::Decaying => "decaying",
            Trend::Steady => "steady",
        }
    }
}

/// Result of one run.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RunSummary {
    /// Speed, m/s.
    pub v_mps: f64,
    /// Initial in-phase wheel yaw, rad.
    pub psi0_rad: f64,
    /// Peak |psi_L| over the last window, rad.
    pub amp_end_rad: f64,
    /// Peak |psi_L| over the window before it, rad.
    pub amp_prev_rad: f64,
    /// Classification of the end.
    pub trend: Trend,
}

impl RunSummary {
    /// Shimmy at the end of the run: an oscillation that is not dying out and is larger than
    /// 1e-4 rad (0.006 deg; below the default small start of 0.05 deg = 8.7e-4 rad).
    pub fn shimmies(&self) -> bool {
        self.trend != Trend::Decaying && self.amp_end_rad > 1e-4
    }
}

/// The damper configuration of a study.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum DamperSetting {
    /// No damper (F_d = 0).
    Off,
    /// The MR damper `damper` with a constant coil current `current_a`, A.
    Mr {
        /// The damper (a vehicle's `damper.spencer`).
        damper: SpencerParams,
        /// Coil current, A.
        current_a: f64,
    },
}

impl DamperSetting {
    /// The reference vehicle's MR damper at `current_a`.
    pub fn reference_mr(current_a: f64) -> Self {
        DamperSetting::Mr {
            damper: SpencerParams::steering(),
            current_a,
        }
    }

    /// The plant's damper and its constant coil current, A.
    pub fn damper(self) -> (Damper, f64) {
        match self {
            DamperSetting::Off => (Damper::None, 0.0),
            DamperSetting::Mr { damper, current_a } => (Damper::Mr(damper), current_a),
        }
    }
}

/// Runs the plant of the vehicle model `params` (any member of the family) at constant speed
/// `v_mps` from an in-phase wheel-yaw start `psi0_rad` for `duration_s` and summarises the last
/// two windows of `window_s` (peak |psi_L|).
pub fn run_speed<M: SimModel<N>, const N: usize>(
    params: &M,
    damper: DamperSetting,
    v_mps: f64,
    psi0_rad: f64,
    duration_s: f64,
    window_s: f64,
) -> anyhow::Result<RunSummary> {
    let (damper, current) = damper.damper();
    let mut sim = params.plant(damper, Method::default());
    sim.set_wheel_yaw(psi0_rad, psi0_rad);
    let u = Inputs {
        current_cmd_a: current,
        speed_mps: v_mps,
        ..Inputs::default()
    };
    let n = (duration_s / DT_S).round() as usize;
    let w = (window_s / DT_S).round() as usize;
    let (mut amp_end, mut amp_prev) = (0.0f64, 0.0f64);
    for k in 0..n {
        sim.advance(DT_S, &u)?;
        let a = sim.wheel_yaw_rad()[0].abs();
        if k + w >= n {
            amp_end = amp_end.max(a);
        } else if k + 2 * w >= n {
            amp_prev = amp_prev.max(a);
        }
    }
    let trend = if amp_end > 1.02 * amp_prev {
        Trend::Growing
    } else if amp_end < 0.98 * amp_prev {
        Trend::Decaying
    } else {
        Trend::Steady
    };
    Ok(RunSummary {
        v_mps,
        psi0_rad,
        amp_end_rad: amp_end,
        amp_prev_rad: amp_prev,
        trend,
    })
}

/// Local maxima of a uniformly sampled signal, refined by a parabola through the three samples
/// around each: `(time in s, value)`.
pub fn peaks(t0_s: f64, dt_s: f64, s: &[f64]) -> Vec<(f64, f64)> {
    let mut out = Vec::new();
    for k in 1..s.len().saturating_sub(1) {
        let (a, b, c) = (s[k - 1], s[k], s[k + 1]);
        if b > a && b >= c {
            let den = a - 2.0 * b + c;
            let off = if den != 0.0 { 0.5 * (a - c) / den } else { 0.0 };
            let val = b - 0.25 * (a - c) * off;
            out.push((t0_s + (k as f64 + off) * dt_s, val));
        }
    }
    out
}

/// Growth rate, 1/s and angular frequency (rad/s) from successive positive peaks: least-squares
/// line through ln(peak) over time, and the mean peak spacing. `None` with fewer than 3 peaks.
pub fn fit_growth(pk: &[(f64, f64)]) -> Option<(f64, f64)> {
    if pk.len() < 3 || pk.iter().any(|p| p.1 <= 0.0) {
        return None;
    }
    let n = pk.len() as f64;
    let mt = pk.iter().map(|p| p.0).sum::<f64>() / n;
    let ml = pk.iter().map(|p| p.1.ln()).sum::<f64>() / n;
    let (mut sxy, mut sxx) = (0.0, 0.0);
    for p in pk {
        sxy += (p.0 - mt) * (p.1.ln() - ml);
        sxx += (p.0 - mt) * (p.0 - mt);
    }
    let rate = sxy / sxx;
    let period = (pk[pk.len() - 1].0 - pk[0].0) / (n - 1.0);
    Some((rate, 2.0 * std::f64::consts::PI / period))
}

/// A recorded run.
#[derive(Clone, Debug, Default)]
pub struct Trace {
    /// Time, s.
    pub t_s: Vec<f64>,
    /// States.
    pub x: Vec<State>,
    /// Damper force, N.
    pub damper_force_n: Vec<f64>,
    /// Coil current command, A.
    pub current_cmd_a: Vec<f64>,
    /// Forward speed, m/s.
    pub speed_mps: Vec<f64>,
    /// Driver torque, N m.
    pub driver_torque_nm: Vec<f64>,
}

impl Trace {
    fn push(&mut self, t: f64, x: &State, f: &Forces, u: &Inputs) {
        self.t_s.push(t);
        self.x.push(*x);
        self.damper_force_n.push(f.damper_n);
        self.current_cmd_a.push(u.current_cmd_a);
        self.speed_mps.push(u.speed_mps);
        self.driver_torque_nm.push(u.driver_torque_nm);
    }

    /// One state over time.
    pub fn series(&self, i: usize) -> Vec<f64> {
        self.x.iter().map(|x| x[i]).collect()
    }

    /// Writes the trace as CSV (units in the header).
    pub fn write_csv(&self, path: &std::path::Path) -> anyhow::Result<()> {
        use std::io::Write;
        let mut w = Vec::new();
        write!(w, "t_s")?;
        for n in STATE_NAMES {
            write!(w, ",{n}")?;
        }
        writeln!(
            w,
            ",damper_force_n,current_cmd_a,speed_mps,driver_torque_nm"
        )?;
        for k in 0..self.t_s.len() {
            write!(w, "{}", self.t_s[k])?;
            for v in &self.x[k] {
                write!(w, ",{v:e}")?;
            }
            writeln!(
                w,
                ",{},{},{},{}",
                self.damper_force_n[k],
                self.current_cmd_a[k],
                self.speed_mps[k],
                self.driver_torque_nm[k]
            )?;
        }
        crate::sim::input::files::write_file(path, &w)
    }
}

/// Runs `scenario` open loop for `duration_s` with control period `dt_s`, recording every
/// `record_every`-th period (and the start). The scenario supplies speed, current, driver torque
/// and yaw torques per period.
pub fn simulate(
    sim: &mut Simulator,
    scenario: &mut Scenario,
    duration_s: f64,
    dt_s: f64,
    record_every: usize,
) -> Result<Trace, IntegrateError> {
    let n = (duration_s / dt_s).round() as usize;
    let every = record_every.max(1);
    let mut trace = Trace::default();
    for k in 0..n {
        let t = sim.time_s();
        let u = scenario.inputs(t, dt_s);
        if k % every == 0 {
            let f = sim.forces(&u);
            trace.push(t, sim.state(), &f, &u);
        }
        sim.advance(dt_s, &u)?;
    }
    let u = scenario.inputs(sim.time_s(), dt_s);
    let f = sim.forces(&u);
    trace.push(sim.time_s(), sim.state(), &f, &u);
    Ok(trace)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn peak_fit_recovers_a_damped_sine() {
        let (sigma, w) = (-0.7, 2.0 * std::f64::consts::PI * 6.3);
        let dt = 1e-3;
        let s: Vec<f64> = (0..3000)
            .map(|k| {
                let t = k as f64 * dt;
                (sigma * t).exp() * (w * t + 0.3).sin()
            })
            .collect();
        let (r, om) = fit_growth(&peaks(0.0, dt, &s)).expect("fit");
        // Peaks of e^{st} sin(wt) are spaced exactly 2 pi / w and decay by e^{s T}: the fit is
        // exact up to the parabolic refinement (~1e-5 here).
        assert!((r - sigma).abs() < 1e-3 * sigma.abs(), "{r}");
        assert!((om - w).abs() < 1e-4 * w, "{om}");
    }
}
