//! The open-loop margin run behind `shimmy-sim margin` and `shimmy-sim mismatch`: the plant
//! (damper off: `Damper::None`, no damper force at all) on a speed profile with road noise and
//! wheel imbalance; the measured wheel yaw angles, speed and acceleration feed the firmware's
//! pipeline every 1 ms exactly as on the target (`ShimmyPipeline`, or the data-only
//! `DataPipeline` without a model margin). Next to the report the *true* eigenvalues of the
//! simulated plant are computed: the shimmy mode of A(V) at the true speed
//! ([`ModeSelect::Shimmy`]) and the Hopf onset by an independent scan
//! ([`stability::hopf_crossings`]).

use crate::model::registry::{ReferenceModel, REFERENCE_N};
use anyhow::{Context, Result};
use shimmy_core::estimator::meter::mode_meter::{Sample, WheelOrder};
use shimmy_core::estimator::model_update::ParamEstimate;
use shimmy_core::estimator::monitor::Level;
use shimmy_core::estimator::pipeline::{
    DataPipeline, PipelineOutput, PipelineParams, ShimmyPipeline,
};
use shimmy_core::model::UpdatableModel;
use shimmy_core::stability::{self, ModeSelect};
use shimmy_core::units::{kmh_to_mps, mps_to_kmh};

use crate::model::disturbance::{Imbalance, RoadNoise, Scenario, SpeedProfile};
use crate::model::family::{SimModel, SimPlant};
use crate::model::plant::{Damper, Method};

/// Control period, s.
pub const DT_S: f64 = 1e-3;

/// An open-loop margin scenario on the vehicle model `M` (the car by default).
#[derive(Clone, Debug)]
pub struct MarginScenario<M: SimModel<N> = ReferenceModel, const N: usize = { REFERENCE_N }> {
    /// Parameters of the simulated plant.
    pub params: M,
    /// Parameters of the pipeline's model (the same as `params` unless a mismatch is studied);
    /// `None`: the data-only arm (mode meter, fusion and monitor without a model margin).
    pub model: Option<M>,
    /// Speed profile.
    pub speed: SpeedProfile,
    /// Simulated duration, s.
    pub duration_s: f64,
    /// Road-noise std per wheel, N m (corner 30 Hz, half common to both wheels), for the car:
    /// times [`SimModel::yaw_torque_scale`] on the model.
    pub noise_nm: f64,
    /// Imbalance amplitude per wheel, N m (phases 0 and 1 rad), for the car: times
    /// [`SimModel::yaw_torque_scale`] on the model.
    pub imbalance_nm: f64,
    /// Noise seed.
    pub seed: u64,
}

impl<M: SimModel<N>, const N: usize> MarginScenario<M, N> {
    /// Constant speed `v_kmh` for `settle_s`, then a ramp to `to_kmh` at `rate` km/h/s.
    pub fn ramp(params: M, from_kmh: f64, to_kmh: f64, rate: f64, settle_s: f64) -> Self {
        let t1 = settle_s + (to_kmh - from_kmh).abs() / rate.max(1e-6);
        Self {
            params,
            model: Some(params),
            speed: SpeedProfile::Ramp {
                v0_mps: kmh_to_mps(from_kmh),
                v1_mps: kmh_to_mps(to_kmh),
                t0_s: settle_s,
                t1_s: t1,
            },
            duration_s: t1,
            noise_nm: 5.0,
            imbalance_nm: 2.0,
            seed: 1,
        }
    }

    /// Constant speed for `duration_s`.
    pub fn constant(params: M, v_kmh: f64, duration_s: f64) -> Self {
        Self {
            params,
            model: Some(params),
            speed: SpeedProfile::Constant(kmh_to_mps(v_kmh)),
            duration_s,
            noise_nm: 5.0,
            imbalance_nm: 2.0,
            seed: 1,
        }
    }

    /// The disturbances of the run (road noise, imbalance; damper current 0).
    pub fn scenario(&self) -> Scenario {
        let mut s = Scenario::new(self.speed.clone());
        s.current_a = 0.0;
        let scale = self.params.yaw_torque_scale();
        if self.noise_nm > 0.0 {
            s.noise = Some(RoadNoise::new(self.noise_nm * scale, 30.0, 0.5, self.seed));
        }
        if self.imbalance_nm > 0.0 {
            s.imbalance = Some(Imbalance {
                amplitude_nm: [self.imbalance_nm * scale; 2],
                phase_rad: [0.0, 1.0],
                radius_m: self.params.rolling_radius_m(),
            });
        }
        s
    }
}

/// One recorded row (every decimated pipeline output, 100 Hz).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MarginRow {
    /// Time, s.
    pub t_s: f64,
    /// True speed, km/h.
    pub speed_kmh: f64,
    /// True shimmy-mode damping of A(V) at the true speed (filled every `true_every` rows).
    pub zeta_true: f64,
    /// True shimmy-mode frequency, Hz.
    pub freq_true_hz: f64,
    /// True speed margin to the onset, km/h (onset - V; negative inside the window).
    pub margin_true_kmh: f64,
    /// Slow data damping.
    pub zeta_data: f64,
    /// Its sigma.
    pub sigma_data: f64,
    /// Fast data damping.
    pub zeta_fast: f64,
    /// Data valid (slow).
    pub data_valid: bool,
    /// Fast valid.
    pub fast_valid: bool,
    /// Model damping (pipeline's model margin).
    pub zeta_model: f64,
    /// Data frequency, Hz.
    pub freq_data_hz: f64,
    /// Reported speed margin, km/h (NaN when none).
    pub margin_kmh: f64,
    /// Time to critical, s (NaN when none).
    pub ttc_s: f64,
    /// Monitor level.
    pub level: Level,
    /// Data and model agree (the fusion's consistency flag).
    pub model_consistent: bool,
    /// The fusion's measured damping offset (data minus window-averaged model).
    pub zeta_offset: f64,
    /// The part of it applied to the model margin.
    pub zeta_correction: f64,
    /// Yaw envelope amplitude, deg.
    pub amplitude_deg: f64,
    /// Mean of the yaw pair the meter is fed (`SimPlant::meter_yaw_rad`: the car's wheel
    /// yaw), deg.
    pub yaw_deg: f64,
}

/// Result of a run.
#[derive(Clone, Debug)]
pub struct MarginRun {
    /// Rows at 100 Hz.
    pub rows: Vec<MarginRow>,
    /// Linear onset speed of the simulated plant, from an independent scan, km/h.
    pub onset_kmh: Option<f64>,
    /// First time the level left Normal: (t, speed km/h, level).
    pub first_warning: Option<(f64, f64, Level)>,
    /// Number of warning onsets (transitions from Normal to a higher level).
    pub warnings: u32,
    /// Highest level reached.
    pub max_level: Level,
    /// First time the consistency flag dropped: (t, speed km/h).
    pub first_inconsistent: Option<(f64, f64)>,
    /// Time at which the true speed crosses the onset, s.
    pub onset_time_s: Option<f64>,
    /// Largest eigen-solves done in one pipeline call.
    pub max_solves_per_call: u8,
    /// Model cycles completed.
    pub model_cycles: u32,
    /// The online model update's parameters at the end (empty when it is off).
    pub updated: Vec<ParamEstimate>,
    /// The update's diagnosis at the end: the parameter furthest outside its plausible band.
    pub diagnosis: Option<ParamEstimate>,
    /// Wall-clock time of the run, s.
    pub wall_s: f64,
}

impl MarginRun {
    /// Lead of the first warning before the onset: (km/h, s). Positive = before.
    pub fn lead(&self) -> Option<(f64, f64)> {
        let (t, v, _) = self.first_warning?;
        Some((self.onset_kmh? - v, self.onset_time_s? - t))
    }
}

pub use crate::model::family::onset_kmh;

/// The pipeline of a run: the full one (model tracker stepped every call) or the data-only arm.
enum Pipe<M: UpdatableModel<N>, const N: usize> {
    Full(Box<ShimmyPipeline<16, M, N>>),
    DataOnly(Box<DataPipeline<16>>),
}

impl<M: UpdatableModel<N>, const N: usize> Pipe<M, N> {
    fn new(model: Option<M>, pp: PipelineParams) -> Result<Self> {
        Ok(match model {
            Some(m) => Pipe::Full(Box::new(
                ShimmyPipeline::for_model(m, pp).context("pipeline config")?,
            )),
            None => Pipe::DataOnly(Box::new(DataPipeline::new(&pp).context("pipeline config")?)),
        })
    }

    fn push(&mut self, s: &Sample, v: f32, a: f32, t: f64) -> Option<PipelineOutput> {
        match self {
            Pipe::Full(p) => p.push(s, v, a, t),
            Pipe::DataOnly(p) => p.push(s, v, a, t, None),
        }
    }

    fn solves_last_call(&self) -> u8 {
        match self {
            Pipe::Full(p) => p.model().solves_last_call(),
            Pipe::DataOnly(_) => 0,
        }
    }

    fn cycles(&self) -> u32 {
        match self {
            Pipe::Full(p) => p.model().cycles(),
            Pipe::DataOnly(_) => 0,
        }
    }

    fn diagnosis(&self) -> Option<ParamEstimate> {
        match self {
            Pipe::Full(p) if p.params().update.enabled => p.updater().diagnosis(),
            _ => None,
        }
    }

    fn estimates(&self) -> Vec<ParamEstimate> {
        match self {
            Pipe::Full(p) if p.params().update.enabled => p.updater().estimates().to_vec(),
            _ => Vec::new(),
        }
    }
}

/// Runs the open-loop scenario through the pipeline. `true_every`: compute the true
/// eigenvalues every n-th row (0 = never).
pub fn run<M: SimModel<N>, const N: usize>(
    sc: &MarginScenario<M, N>,
    pp: PipelineParams,
    true_every: usize,
) -> Result<MarginRun> {
    run_with_progress(sc, pp, true_every, &mut |_, _| {})
}

/// [`run`], telling `progress(done, total)` 1 ms steps every simulated second and at the end.
pub fn run_with_progress<M: SimModel<N>, const N: usize>(
    sc: &MarginScenario<M, N>,
    pp: PipelineParams,
    true_every: usize,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<MarginRun> {
    let wall = std::time::Instant::now();
    let p = sc.params.linear();
    let mut sim = sc.params.plant(Damper::None, Method::default());
    let mut scen = sc.scenario();
    let mut pipe = Pipe::new(sc.model.map(|m| m.linear()), pp)?;
    let mut first_inconsistent = None;
    let onset = onset_kmh(&p);
    let radius_m = sc.params.rolling_radius_m() as f32;
    let n = (sc.duration_s / DT_S).round() as usize;
    let mut rows = Vec::with_capacity(n / 10 + 1);
    let mut first_warning = None;
    let mut warnings = 0u32;
    let mut last_level = Level::Normal;
    let mut max_level = Level::Normal;
    let mut onset_time = None;
    let mut max_solves = 0u8;
    let (mut zt, mut ft) = (f64::NAN, f64::NAN);
    for k in 0..n {
        if k % 1000 == 0 {
            progress(k, n);
        }
        let t = k as f64 * DT_S;
        let u = scen.inputs(t, DT_S);
        sim.advance(DT_S, &u)
            .with_context(|| format!("integration failed at t = {t}"))?;
        let t1 = t + DT_S;
        let [psi_l, psi_r] = sim.meter_yaw_rad();
        let v = sc.speed.at(t1);
        let accel = (sc.speed.at(t1 + 0.5 * DT_S) - sc.speed.at(t1 - 0.5 * DT_S)) / DT_S;
        if let (Some(on), None) = (onset, onset_time) {
            if mps_to_kmh(v) >= on {
                onset_time = Some(t1);
            }
        }
        let sample = Sample {
            psi_l_rad: psi_l as f32,
            psi_r_rad: psi_r as f32,
            wheel: WheelOrder::Speed {
                speed_mps: v as f32,
                radius_m,
            },
            damper_cmd: 0.0,
        };
        let out = pipe.push(&sample, v as f32, accel as f32, t1);
        max_solves = max_solves.max(pipe.solves_last_call());
        let Some(o) = out else { continue };
        if o.level > Level::Normal && first_warning.is_none() {
            first_warning = Some((t1, mps_to_kmh(v), o.level));
        }
        if o.level > Level::Normal && last_level == Level::Normal {
            warnings += 1;
        }
        last_level = o.level;
        max_level = max_level.max(o.level);
        if !o.report.model_consistent && first_inconsistent.is_none() {
            first_inconsistent = Some((t1, mps_to_kmh(v)));
        }
        if true_every > 0 && rows.len() % true_every == 0 {
            if let Ok(m) = stability::mode_at(&p, v, 0.0, ModeSelect::Shimmy) {
                zt = m.zeta;
                ft = m.freq_hz;
            }
        }
        let r = &o.report;
        rows.push(MarginRow {
            t_s: t1,
            speed_kmh: mps_to_kmh(v),
            zeta_true: zt,
            freq_true_hz: ft,
            margin_true_kmh: onset.map_or(f64::NAN, |on| on - mps_to_kmh(v)),
            zeta_data: r.zeta_data as f64,
            sigma_data: r.sigma_zeta_data as f64,
            zeta_fast: r.zeta_fast as f64,
            data_valid: r.data_valid,
            fast_valid: r.fast_valid,
            zeta_model: r.zeta_model.map_or(f64::NAN, f64::from),
            freq_data_hz: r.freq_hz as f64,
            margin_kmh: r
                .speed_margin_mps
                .map_or(f64::NAN, |m| mps_to_kmh(m as f64)),
            ttc_s: r.time_to_critical_s.map_or(f64::NAN, f64::from),
            level: o.level,
            model_consistent: r.model_consistent,
            zeta_offset: r.zeta_offset as f64,
            zeta_correction: r.zeta_correction as f64,
            amplitude_deg: (o.meter.amplitude_rad as f64).to_degrees(),
            yaw_deg: (0.5 * (psi_l + psi_r)).to_degrees(),
        });
    }
    progress(n, n);
    Ok(MarginRun {
        rows,
        onset_kmh: onset,
        first_warning,
        warnings,
        max_level,
        first_inconsistent,
        onset_time_s: onset_time,
        max_solves_per_call: max_solves,
        model_cycles: pipe.cycles(),
        updated: pipe.estimates(),
        diagnosis: pipe.diagnosis(),
        wall_s: wall.elapsed().as_secs_f64(),
    })
}
