//! The board's margin path on a measured log: [`analyze`] resamples the log's wheel yaw and
//! speed ([`crate::sim::input::log_file`]) onto the mode meter's 1 kHz input grid and runs the core's
//! pipeline on it exactly as the firmware's meter task does (`firmware::monitoring::DataMargin`):
//! the same [`DataPipeline`] (mode meter -> fusion -> monitor, the vehicle's thresholds), the
//! same acceleration estimate ([`AccelEstimator`]), the last valid speed held, a sample with no
//! trusted angles pushed as NaN (the meter counts it as rejected), the wheel order from the
//! measured speed. With a model ([`AnalyzeOptions::model`]) the model margin comes from the
//! core's tracker stepped every tick ([`ShimmyPipeline`]) on the plant without damper (c = 0,
//! the firmware's conservative envelope).
//!
//! Resampling ([`resample`]): grid point t0 + k ms. A log sample within
//! [`SNAP_TOLERANCE_S`] of a grid point is taken as it is (a log at 1 kHz on the grid passes
//! through bit for bit); otherwise the two neighbours are interpolated linearly (the board
//! samples the encoder at one instant: no extra filter), unless they are more than
//! [`AnalyzeOptions::max_gap_s`] apart or one of them lacks the value: then the grid point has
//! no value, as a missed sample on the board.

use crate::model::family::{FamilyVehicle, SimModel};
use crate::model::registry::{self, Registered, StudyVisitor};
use crate::model::study::StudyModel;
use crate::sim::input::log_file::LogSample;
use crate::sim::input::vehicle_file::ModelVehicle;
use anyhow::{bail, Context, Result};
use shimmy_core::estimator::meter::mode_meter::{EstimateStatus, Sample, WheelOrder};
use shimmy_core::estimator::monitor::{Event, Level};
use shimmy_core::estimator::pipeline::{
    AccelEstimator, DataPipeline, PipelineOutput, ShimmyPipeline,
};
use shimmy_core::model::UpdatableModel;
use shimmy_core::vehicle::Vehicle;

/// The meter's input period, s (1 kHz, the control rate).
pub const GRID_DT_S: f64 = 1e-3;

/// A log sample this close to a grid point is that grid point's value, s.
pub const SNAP_TOLERANCE_S: f64 = 1e-9;

/// Warning episodes kept (the monitor's event log; older ones are counted as dropped).
pub const EVENT_LOG: usize = 256;

/// Longest log analysed at once, s (6 h: 21.6 M grid points; a longer span is usually a time
/// column in the wrong unit).
pub const MAX_SPAN_S: f64 = 6.0 * 3600.0;

/// Allowed range of [`AnalyzeOptions::max_gap_s`], s.
pub const MAX_GAP_RANGE_S: (f64, f64) = (1e-3, 10.0);

/// How to analyse a log.
#[derive(Clone, Debug)]
pub struct AnalyzeOptions {
    /// The vehicle: rolling radius (wheel-order reference), warning thresholds, fusion and
    /// meter parameters, and with `model` the plant the model margin linearises; the car or
    /// the mining truck (their logs carry the two wheel yaw angles the meter reads).
    pub vehicle: ModelVehicle,
    /// Run the model margin next to the data (as the board does); `false`: data only.
    pub model: bool,
    /// Log samples further apart than this are not interpolated: the grid points between them
    /// have no value, s.
    pub max_gap_s: f64,
}

impl Default for AnalyzeOptions {
    /// The nominal vehicle with its model; gaps above 20 ms (two decimated meter steps).
    fn default() -> Self {
        Self {
            vehicle: ModelVehicle::from(Vehicle::nominal()),
            model: true,
            max_gap_s: 0.02,
        }
    }
}

/// One point of the meter's 1 kHz input grid.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GridSample {
    /// Time, s.
    pub t_s: f64,
    /// Left and right wheel yaw, rad (`None`: no value here).
    pub yaw_rad: Option<(f32, f32)>,
    /// Speed, m/s (`None`: no value here).
    pub speed_mps: Option<f32>,
}

/// How the log became the grid.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ResampleStats {
    /// Log rows.
    pub log_rows: usize,
    /// Median spacing of the log's rows, s.
    pub log_median_dt_s: f64,
    /// Largest spacing, s.
    pub log_max_dt_s: f64,
    /// Grid points (1 kHz).
    pub grid_points: usize,
    /// Grid points taken from a log row as they are.
    pub exact: usize,
    /// Grid points interpolated between two rows.
    pub interpolated: usize,
    /// Grid points without yaw (gap longer than `max_gap_s`, or an empty cell).
    pub missing_yaw: usize,
    /// Grid points without speed.
    pub missing_speed: usize,
    /// Spacings longer than `max_gap_s`.
    pub gaps: usize,
}

/// Puts `log` (time strictly increasing) onto the 1 kHz grid (module docs).
pub fn resample(log: &[LogSample], max_gap_s: f64) -> Result<(Vec<GridSample>, ResampleStats)> {
    let (lo, hi) = MAX_GAP_RANGE_S;
    if !(lo..=hi).contains(&max_gap_s) {
        bail!("max_gap_s = {max_gap_s}: allowed {lo} ..= {hi} s");
    }
    let (Some(first), Some(last)) = (log.first(), log.last()) else {
        bail!("the log has no rows");
    };
    let mut dts: Vec<f64> = log.windows(2).map(|w| w[1].t_s - w[0].t_s).collect();
    if dts.iter().any(|&d| d.is_nan() || d <= 0.0) {
        bail!("the log's time must increase from row to row");
    }
    dts.sort_by(f64::total_cmp);
    let mut st = ResampleStats {
        log_rows: log.len(),
        log_median_dt_s: dts.get(dts.len() / 2).copied().unwrap_or(0.0),
        log_max_dt_s: dts.last().copied().unwrap_or(0.0),
        gaps: log
            .windows(2)
            .filter(|w| w[1].t_s - w[0].t_s > max_gap_s)
            .count(),
        ..ResampleStats::default()
    };
    let t0 = first.t_s;
    let span = last.t_s - t0;
    if span > MAX_SPAN_S {
        bail!(
            "the log spans {span:.0} s, more than the {MAX_SPAN_S:.0} s analysed at once (is the time unit right?)"
        );
    }
    let n = ((last.t_s - t0) / GRID_DT_S + SNAP_TOLERANCE_S / GRID_DT_S).floor() as usize + 1;
    let mut grid = Vec::with_capacity(n);
    let mut i = 0; // log[i].t_s <= t < log[i + 1].t_s (or t at log[i])
    for k in 0..n {
        let t = t0 + k as f64 * GRID_DT_S;
        while i + 1 < log.len() && log[i + 1].t_s <= t + SNAP_TOLERANCE_S {
            i += 1;
        }
        let a = &log[i];
        let g = if (t - a.t_s).abs() <= SNAP_TOLERANCE_S {
            st.exact += 1;
            GridSample {
                t_s: t,
                yaw_rad: a
                    .psi_l_rad
                    .zip(a.psi_r_rad)
                    .map(|(l, r)| (l as f32, r as f32)),
                speed_mps: a.speed_mps.map(|v| v as f32),
            }
        } else {
            match log.get(i + 1) {
                Some(b) if b.t_s - a.t_s <= max_gap_s => {
                    st.interpolated += 1;
                    let w = (t - a.t_s) / (b.t_s - a.t_s);
                    let lerp = |x: Option<f64>, y: Option<f64>| {
                        x.zip(y).map(|(x, y)| (x + w * (y - x)) as f32)
                    };
                    GridSample {
                        t_s: t,
                        yaw_rad: lerp(a.psi_l_rad, b.psi_l_rad).zip(lerp(a.psi_r_rad, b.psi_r_rad)),
                        speed_mps: lerp(a.speed_mps, b.speed_mps),
                    }
                }
                _ => GridSample {
                    t_s: t,
                    yaw_rad: None,
                    speed_mps: None,
                },
            }
        };
        st.missing_yaw += usize::from(g.yaw_rad.is_none());
        st.missing_speed += usize::from(g.speed_mps.is_none());
        grid.push(g);
    }
    st.grid_points = grid.len();
    Ok((grid, st))
}

/// One decimated (100 Hz) output of the pipeline on the log, in plain numbers (NaN: absent).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AnalysisRow {
    /// Time, s (the log's time base).
    pub t_s: f64,
    /// Speed the pipeline used, m/s (the last valid one).
    pub speed_mps: f64,
    /// Slow (margin) damping ratio of the shimmy mode.
    pub zeta_slow: f64,
    /// Its one-sigma uncertainty.
    pub sigma_zeta_slow: f64,
    /// Damped frequency of the slow estimate, Hz.
    pub freq_slow_hz: f64,
    /// Slow estimate valid.
    pub slow_valid: bool,
    /// Fast (warning) damping ratio.
    pub zeta_fast: f64,
    /// Its one-sigma uncertainty.
    pub sigma_zeta_fast: f64,
    /// Damped frequency of the fast estimate, Hz.
    pub freq_fast_hz: f64,
    /// Fast estimate valid.
    pub fast_valid: bool,
    /// In-band yaw amplitude (envelope), rad.
    pub amplitude_rad: f64,
    /// Model damping at this speed (NaN without model).
    pub zeta_model: f64,
    /// Fused speed margin to the onset, m/s (NaN: none).
    pub speed_margin_mps: f64,
    /// Time to critical speed, s (NaN: none).
    pub time_to_critical_s: f64,
    /// Data and model agree (the fusion's consistency flag).
    pub model_consistent: bool,
    /// Warning level after this step.
    pub level: Level,
}

impl AnalysisRow {
    fn new(t_s: f64, o: &PipelineOutput) -> Self {
        let r = &o.report;
        let m = &o.meter;
        let opt = |x: Option<f32>| x.map_or(f64::NAN, f64::from);
        Self {
            t_s,
            speed_mps: f64::from(r.speed_mps),
            zeta_slow: f64::from(m.slow.zeta),
            sigma_zeta_slow: f64::from(m.slow.sigma_zeta),
            freq_slow_hz: f64::from(m.slow.freq_hz),
            slow_valid: m.slow.valid,
            zeta_fast: f64::from(m.fast.zeta),
            sigma_zeta_fast: f64::from(m.fast.sigma_zeta),
            freq_fast_hz: f64::from(m.fast.freq_hz),
            fast_valid: m.fast.valid,
            amplitude_rad: f64::from(m.amplitude_rad),
            zeta_model: opt(r.zeta_model),
            speed_margin_mps: opt(r.speed_margin_mps),
            time_to_critical_s: opt(r.time_to_critical_s),
            model_consistent: r.model_consistent,
            level: o.level,
        }
    }
}

/// The result of [`analyze`].
#[derive(Clone, Debug)]
pub struct Analysis {
    /// Every decimated output (100 Hz).
    pub rows: Vec<AnalysisRow>,
    /// Warning episodes (the monitor's event log, oldest first; the last may be open).
    pub events: Vec<Event>,
    /// Episodes dropped because the event log was full.
    pub dropped_events: u32,
    /// How the log became the grid.
    pub resampling: ResampleStats,
    /// Input samples the mode meter rejected (no trusted angles).
    pub rejected_samples: u32,
    /// The model margin ran.
    pub model: bool,
    /// The meter's 100 Hz steps by the status of the slow estimate (frozen when the meter froze
    /// its updates on the step), in the order of [`SLOW_STATUSES`].
    pub slow_status_steps: [usize; SLOW_STATUSES.len()],
}

/// Every status of the meter's slow estimate with what it means for a log, in the order
/// [`Analysis::slow_status_steps`] counts them.
pub const SLOW_STATUSES: [(EstimateStatus, &str); 6] = [
    (EstimateStatus::NotStarted, "no estimate yet"),
    (EstimateStatus::WarmingUp, "warming up"),
    (EstimateStatus::Frozen, "frozen (too little excitation)"),
    (EstimateStatus::NoModeInBand, "no mode in the shimmy band"),
    (EstimateStatus::RootFailure, "root finder failed"),
    (EstimateStatus::Ok, "an estimate without a finite sigma"),
];

/// Name of a warning level for tables and CSV.
pub fn level_name(l: Level) -> &'static str {
    match l {
        Level::Normal => "normal",
        Level::MarginLow => "margin-low",
        Level::ApproachingCritical => "approaching-critical",
        Level::ShimmyPresent => "shimmy-present",
    }
}

/// The pipeline of an analysis: with the model tracker on the vehicle's model `M`, or data
/// only.
enum Pipe<M: UpdatableModel<S>, const S: usize> {
    Full(Box<ShimmyPipeline<EVENT_LOG, M, S>>),
    DataOnly(Box<DataPipeline<EVENT_LOG>>),
}

impl<M: UpdatableModel<S>, const S: usize> Pipe<M, S> {
    fn push(&mut self, s: &Sample, v: f32, a: f32, t: f64) -> Option<PipelineOutput> {
        match self {
            Pipe::Full(p) => p.push(s, v, a, t),
            Pipe::DataOnly(p) => p.push(s, v, a, t, None),
        }
    }

    fn data(&self) -> &DataPipeline<EVENT_LOG> {
        match self {
            Pipe::Full(p) => p.data(),
            Pipe::DataOnly(p) => p,
        }
    }
}

/// Runs the board's margin path on `log` (module docs).
pub fn analyze(log: &[LogSample], o: &AnalyzeOptions) -> Result<Analysis> {
    analyze_with_progress(log, o, &mut |_, _| {})
}

/// [`analyze`], telling `progress(done, total)` grid points every 10,000 (a long log takes
/// seconds).
pub fn analyze_with_progress(
    log: &[LogSample],
    o: &AnalyzeOptions,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<Analysis> {
    struct On<'a>(
        &'a [LogSample],
        &'a AnalyzeOptions,
        &'a mut dyn FnMut(usize, usize),
    );
    impl StudyVisitor for On<'_> {
        type Output = Result<Analysis>;
        fn visit<M: Registered<N> + StudyModel<N>, const N: usize>(
            self,
            v: M::File,
        ) -> Result<Analysis> {
            analyze_on(self.0, self.1, &registry::family::<M, N>(v)?, self.2)
        }
    }
    match registry::with_image_model(o.vehicle.clone(), On(log, o, progress)) {
        Ok(r) => r,
        Err(other) => bail!(
            "analyze runs logs of the {} models, not of the {} (its meter reads other signals \
             than a log's two wheel yaw angles)",
            registry::image_models(),
            other.model_name()
        ),
    }
}

/// [`analyze_with_progress`] on the vehicle `v` of the model `M`.
fn analyze_on<M: SimModel<S>, const S: usize>(
    log: &[LogSample],
    o: &AnalyzeOptions,
    v: &FamilyVehicle<M>,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<Analysis> {
    let (grid, resampling) = resample(log, o.max_gap_s)?;
    let params = v.pipeline_params();
    let mut pipe: Pipe<M::Linear, S> = if o.model {
        Pipe::Full(Box::new(
            ShimmyPipeline::for_model(v.model.linear(), params)
                .context("pipeline configuration")?,
        ))
    } else {
        Pipe::DataOnly(Box::new(
            DataPipeline::new(&params).context("pipeline configuration")?,
        ))
    };
    let radius_m = v.model.rolling_radius_m() as f32;
    let mut accel = AccelEstimator::new();
    let mut speed_mps = f32::NAN;
    let mut rows = Vec::with_capacity(grid.len() / 10 + 1);
    let mut slow_status_steps = [0; SLOW_STATUSES.len()];
    for (k, g) in grid.iter().enumerate() {
        if k % 10_000 == 0 {
            progress(k, grid.len());
        }
        if let Some(v) = g.speed_mps {
            speed_mps = v;
        }
        let (psi_l_rad, psi_r_rad) = g.yaw_rad.unwrap_or((f32::NAN, f32::NAN));
        let sample = Sample {
            psi_l_rad,
            psi_r_rad,
            wheel: match g.speed_mps {
                Some(v) => WheelOrder::Speed {
                    speed_mps: v,
                    radius_m,
                },
                None => WheelOrder::None,
            },
            damper_cmd: 0.0,
        };
        let a = accel.update(g.t_s, speed_mps);
        if let Some(out) = pipe.push(&sample, speed_mps, a, g.t_s) {
            // A step with the updates frozen is counted as frozen whatever the estimate says:
            // without excitation the fit has nothing to solve, and its root solve fails first.
            let status = if out.meter.frozen {
                EstimateStatus::Frozen
            } else {
                out.meter.slow.status
            };
            if let Some(i) = SLOW_STATUSES.iter().position(|(s, _)| *s == status) {
                slow_status_steps[i] += 1;
            }
            rows.push(AnalysisRow::new(g.t_s, &out));
        }
    }
    progress(grid.len(), grid.len());
    let data = pipe.data();
    Ok(Analysis {
        rows,
        events: data.monitor().events().copied().collect(),
        dropped_events: data.monitor().dropped_events(),
        resampling,
        rejected_samples: data.meter().counters().rejected_samples,
        model: o.model,
        slow_status_steps,
    })
}

/// The headline numbers of an analysis.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AnalysisSummary {
    /// Length of the analysed grid, s.
    pub duration_s: f64,
    /// Share of decimated steps with a valid slow estimate.
    pub valid_fraction: f64,
    /// Lowest valid slow damping ratio (NaN: none valid).
    pub zeta_slow_min: f64,
    /// Median of the valid slow damping ratios (NaN: none valid).
    pub zeta_slow_median: f64,
    /// Median sigma of the valid slow estimates.
    pub sigma_slow_median: f64,
    /// Median frequency of the valid slow estimates, Hz.
    pub freq_slow_median_hz: f64,
    /// Highest warning level reached.
    pub max_level: Level,
    /// First time the level left Normal: (t s, speed m/s, level).
    pub first_warning: Option<(f64, f64, Level)>,
    /// Warning episodes (including dropped ones).
    pub episodes: usize,
}

fn median(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

impl Analysis {
    /// Why the log cannot be judged (not one valid slow estimate and no warning: "no
    /// warning" would say nothing about the vehicle), or `None` when it can (a warning raised
    /// from the amplitude alone, shimmy present, is a judgement).
    pub fn not_judged(&self) -> Option<String> {
        if self
            .rows
            .iter()
            .any(|r| r.slow_valid || r.level != Level::Normal)
        {
            return None;
        }
        let st = &self.resampling;
        if st.missing_yaw >= st.grid_points {
            return Some(format!(
                "no usable yaw sample: all {} samples at 1 kHz lack the wheel yaw (empty or \
                 non-numeric cells, or gaps longer than the limit)",
                st.grid_points
            ));
        }
        let steps = self.rows.len();
        if steps == 0 {
            return Some(format!(
                "too short: {:.3} s of log gives no meter step (one every 10 ms)",
                st.grid_points as f64 * GRID_DT_S
            ));
        }
        let mut by_count: Vec<(EstimateStatus, &str, usize)> = SLOW_STATUSES
            .iter()
            .zip(self.slow_status_steps)
            .filter(|(_, n)| *n > 0)
            .map(|(&(s, words), n)| (s, words, n))
            .collect();
        by_count.sort_by_key(|&(.., n)| std::cmp::Reverse(n));
        let lead = match by_count.first().map(|&(s, ..)| s) {
            Some(EstimateStatus::NotStarted | EstimateStatus::WarmingUp) => {
                "too short: the mode meter was still warming up when the log ended"
            }
            Some(EstimateStatus::Frozen) => {
                "no usable samples: too little wheel yaw in the shimmy band"
            }
            Some(EstimateStatus::NoModeInBand) => {
                "no usable samples: the mode meter found no mode in the shimmy band"
            }
            _ => "no usable samples: the mode meter's estimate failed",
        };
        let shares: Vec<String> = by_count
            .iter()
            .map(|&(_, words, n)| format!("{words} {:.0} %", 100.0 * n as f64 / steps as f64))
            .collect();
        Some(format!(
            "{lead} (its {steps} steps at 100 Hz over {:.1} s: {})",
            st.grid_points as f64 * GRID_DT_S,
            shares.join(", ")
        ))
    }

    /// The headline numbers.
    pub fn summary(&self) -> AnalysisSummary {
        let valid: Vec<&AnalysisRow> = self.rows.iter().filter(|r| r.slow_valid).collect();
        let first_warning = self
            .rows
            .iter()
            .find(|r| r.level > Level::Normal)
            .map(|r| (r.t_s, r.speed_mps, r.level));
        AnalysisSummary {
            duration_s: self.resampling.grid_points as f64 * GRID_DT_S,
            valid_fraction: valid.len() as f64 / self.rows.len().max(1) as f64,
            zeta_slow_min: valid.iter().map(|r| r.zeta_slow).fold(f64::NAN, f64::min),
            zeta_slow_median: median(valid.iter().map(|r| r.zeta_slow).collect()),
            sigma_slow_median: median(valid.iter().map(|r| r.sigma_zeta_slow).collect()),
            freq_slow_median_hz: median(valid.iter().map(|r| r.freq_slow_hz).collect()),
            max_level: self.rows.iter().map(|r| r.level).max().unwrap_or_default(),
            first_warning,
            episodes: self.events.len() + self.dropped_events as usize,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(t_s: f64, y: f64, v: f64) -> LogSample {
        LogSample {
            t_s,
            psi_l_rad: Some(y),
            psi_r_rad: Some(-y),
            speed_mps: Some(v),
        }
    }

    #[test]
    fn a_log_on_the_grid_passes_through_unchanged() {
        let log: Vec<LogSample> = (0..50)
            .map(|k| row(k as f64 * 1e-3, 1e-3 * (k as f64).sin(), 5.0 + k as f64))
            .collect();
        let (g, st) = resample(&log, 0.02).unwrap();
        assert_eq!((st.grid_points, st.exact, st.interpolated), (50, 50, 0));
        for (g, l) in g.iter().zip(&log) {
            assert_eq!(g.t_s, l.t_s);
            assert_eq!(
                g.yaw_rad,
                Some((l.psi_l_rad.unwrap() as f32, l.psi_r_rad.unwrap() as f32))
            );
            assert_eq!(g.speed_mps, Some(l.speed_mps.unwrap() as f32));
        }
    }

    #[test]
    fn another_rate_is_interpolated_and_gaps_stay_empty() {
        // 400 Hz, a line y = t; a 0.1 s hole between 0.1 and 0.2 s; a missing speed cell.
        let mut log: Vec<LogSample> = (0..=40)
            .map(|j| row(j as f64 / 400.0, j as f64 / 400.0, 3.0))
            .collect();
        log.extend((80..=100).map(|j| row(j as f64 / 400.0, j as f64 / 400.0, 3.0)));
        log[3].speed_mps = None;
        let (g, st) = resample(&log, 0.02).unwrap();
        assert_eq!(st.grid_points, 251);
        assert_eq!(st.gaps, 1);
        assert!((st.log_median_dt_s - 2.5e-3).abs() < 1e-12);
        // Exact at multiples of 5 ms (every second 400 Hz row), interpolated between.
        assert_eq!(st.exact, 21 + 11);
        for p in &g {
            match p.yaw_rad {
                Some((l, r)) => {
                    assert!((f64::from(l) - p.t_s).abs() < 1e-6, "{p:?}");
                    assert_eq!(l, -r);
                }
                None => assert!(p.t_s > 0.1 && p.t_s < 0.2, "{p:?}"),
            }
        }
        assert_eq!(st.missing_yaw, 99);
        // Rows 3 (7.5 ms) lacks the speed: grid points 6..=9 ms (neighbours of row 3) lack it.
        assert_eq!(st.missing_speed, 99 + 4);
        assert!(resample(&log, 0.0)
            .unwrap_err()
            .to_string()
            .contains("max_gap_s = 0"));
        // Milliseconds read as seconds: an hour becomes 41 days, refused before any memory
        // is taken.
        let long = [row(0.0, 0.0, 3.0), row(3.6e6, 0.0, 3.0)];
        let e = resample(&long, 0.02).unwrap_err().to_string();
        assert!(
            e.contains("spans 3600000 s") && e.contains("time unit"),
            "{e}"
        );
    }
}
