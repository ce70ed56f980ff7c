//! `shimmy-sim faults`: the fault campaign. Every sensor/actuator fault of [`crate::model::faults`]
//! (and a few combinations) is injected into the closed loop (nominal plant, ASMC under the
//! core's `SafeController`) at speeds inside the nominal Hopf window (29.35-84.15 km/h) and
//! outside it, with road noise and a yaw kick shortly after the fault that starts shimmy
//! without a damper. For each run: the detection time, the safe state reached, the peak wheel
//! yaw after the fault and whether shimmy stayed suppressed.
//!
//! Runs are independent and go in parallel (rayon). Output: a table on stdout, `faults.csv` and
//! `faults.md` under `--out` (default `out/faults/`).

use crate::model::coil_drive::CoilDrive;
use crate::model::disturbance::{Impulse, RoadNoise, Scenario, SpeedProfile};
use crate::model::family::SimModel;
use crate::model::faults::{FaultMode, FaultSpec, Side};
use crate::model::registry::{self, ModelVisitor, Registered};
use crate::model::registry::{ReferenceModel, REFERENCE_N};
use crate::out::progress;
use crate::out::table::opt;
use crate::sim::input::arg_range::{self, Range};
use crate::sim::input::vehicle_file::{self, FileModel};
use crate::sim::run::closed_loop::{self, Arm, LoopConfig, LoopResult};
use anyhow::{bail, Context, Result};
use clap::Args;
use rayon::prelude::*;
use shimmy_core::control::ControllerKind;
use shimmy_core::model::LinearModel;
use shimmy_core::stability::{self, CrossingKind};
use shimmy_core::supervisor::checks::SupervisorEvent;
use shimmy_core::supervisor::policy::Mode;
use shimmy_core::units::{kmh_to_mps, mps_to_kmh};
use shimmy_core::vehicle::Vehicle;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Peak wheel yaw after the fault below which shimmy counts as suppressed: 0.5 deg.
pub const SUPPRESSED_BELOW_RAD: f64 = 0.5 * std::f64::consts::PI / 180.0;

/// The Hopf window of `plant` without damper, km/h (onset to offset between 1 and 70 m/s, as
/// `shimmy-sim stability` finds it); `None` if it has none.
pub fn window_kmh<M: LinearModel<N>, const N: usize>(plant: &M) -> Option<(f64, f64)> {
    let c = stability::hopf_crossings(plant, 0.0, 1.0, 70.0, 0.25, 1e-3).ok()?;
    let on = c.iter().find(|x| x.kind == CrossingKind::Onset)?;
    let off = c
        .iter()
        .find(|x| x.kind != CrossingKind::Onset && x.speed_mps > on.speed_mps)
        .map_or(f64::INFINITY, |x| x.speed_mps);
    Some((mps_to_kmh(on.speed_mps), mps_to_kmh(off)))
}

/// One campaign case: a name and its faults (empty: the healthy reference).
#[derive(Clone, Debug)]
pub struct Case {
    /// Table label.
    pub name: String,
    /// Faults, all starting at the campaign's fault time.
    pub faults: Vec<FaultMode>,
    /// Why the expected response is what it is (notes column).
    pub note: &'static str,
    /// The supervisor can keep shimmy suppressed (false: the actuator itself is lost; the
    /// firmware can only go to its safe state and report it).
    pub handleable: bool,
    /// A quiet road: no yaw kick and a fifth of the road noise (a latent fault the controller
    /// gives no current to reveal).
    pub quiet: bool,
    /// Shortest run for this case, s (an intermittent fault needs several periods).
    pub min_duration_s: f64,
    /// The faults end this long after they start, s (`None`: to the end of the run). A fault
    /// that ends must be recovered from: Normal at the end, nothing active or latched.
    pub lasts_s: Option<f64>,
    /// The vehicle pulls away from this speed, km/h (`None`: the run's speed throughout): see
    /// [`Setup::pull_away_from_kmh`].
    pub pull_away_from_kmh: Option<f64>,
}

fn case(name: &str, faults: Vec<FaultMode>, note: &'static str) -> Case {
    Case {
        name: name.to_string(),
        faults,
        note,
        handleable: true,
        quiet: false,
        min_duration_s: 0.0,
        lasts_s: None,
        pull_away_from_kmh: None,
    }
}

/// `c` on a vehicle that pulls away from `from_kmh` (below the speed gate) when the fault
/// starts (a case named `<name> pull-away`).
fn pulling_away(c: Case, from_kmh: f64) -> Case {
    Case {
        name: format!("{} pull-away", c.name),
        pull_away_from_kmh: Some(from_kmh),
        min_duration_s: PULL_AWAY_S + 3.5,
        ..c
    }
}

/// A pulling-away run accelerates from the fault time to the run's speed in this long, s (the
/// kick comes 0.1 s after it arrives).
pub const PULL_AWAY_S: f64 = 3.0;

/// `c` with its faults ending after `lasts_s` (a recovery case, named `<name> <lasts_s>s`).
fn ending(c: Case, lasts_s: f64) -> Case {
    Case {
        name: format!("{} {lasts_s}s", c.name),
        lasts_s: Some(lasts_s),
        // Fault at 1 s, 1 s of recovery, then the settled-mode window.
        min_duration_s: 2.0 + lasts_s + SETTLED_S + 0.5,
        ..c
    }
}

impl Case {
    /// The campaign set-up for this case: a quiet road if it asks for one, at least its
    /// duration, its fault end.
    pub fn setup<M: SimModel<N>, const N: usize>(&self, setup: &Setup<M, N>) -> Setup<M, N> {
        let quiet = if self.quiet { 0.0 } else { 1.0 };
        Setup {
            kick_nm: quiet * setup.kick_nm,
            noise_nm: (0.2 + 0.8 * quiet) * setup.noise_nm,
            duration_s: setup.duration_s.max(self.min_duration_s),
            fault_end_s: self.lasts_s.map(|d| setup.fault_s + d),
            pull_away_from_kmh: self.pull_away_from_kmh,
            kick_s: match self.pull_away_from_kmh {
                Some(_) => setup.kick_s + PULL_AWAY_S,
                None => setup.kick_s,
            },
            ..*setup
        }
    }
}

fn lost_actuator(name: &str, faults: Vec<FaultMode>, note: &'static str) -> Case {
    Case {
        handleable: false,
        ..case(name, faults, note)
    }
}

/// The standard cases: every fault kind once (left encoder where it applies, right for the
/// flag), three variants whose detection depends on size, and combinations.
pub fn standard_cases() -> Vec<Case> {
    use FaultMode as F;
    let deg = |d: f64| d.to_radians();
    vec![
        case("healthy", vec![], "reference: no fault"),
        case(
            "stuck-left",
            vec![F::Stuck(Side::Left)],
            "seen once the right encoder moves > 5 mrad in 100 ms (a frozen value on a quiet road is indistinguishable from a healthy one)",
        ),
        case(
            "noise-left 2deg",
            vec![F::Noise(Side::Left, deg(2.0))],
            "sample steps > 25 rad/s x 1 ms",
        ),
        case(
            "noise-left 0.05deg",
            vec![F::Noise(Side::Left, deg(0.05))],
            "below every plausibility bound: not a fault; conditioning filters absorb it (not expected to be detected)",
        ),
        case(
            "dropout-left 3/10",
            vec![F::Dropout {
                side: Side::Left,
                period: 10,
                length: 3,
            }],
            "failed reads",
        ),
        case(
            "spike-left 20deg",
            vec![F::Spike {
                side: Side::Left,
                period: 100,
                amplitude_rad: deg(20.0),
            }],
            "rate check",
        ),
        case("nan-left", vec![F::Nan(Side::Left)], "non-finite"),
        case("parity-left", vec![F::Parity(Side::Left)], "parity"),
        case(
            "error-flag-right",
            vec![F::ErrorFlag(Side::Right)],
            "sensor error flag",
        ),
        case(
            "speed-lost",
            vec![F::SpeedLost],
            "qualifier invalid: last trusted speed held 1 s, then speed gate off, 2 A floor",
        ),
        case(
            "speed-pulses-lost",
            vec![F::SpeedPulsesLost],
            "tone-wheel pulses stop: the decoder decays to 0 m/s (standstill after 0.5 s) faster than braking allows; last trusted speed held 1 s, then 2 A floor",
        ),
        case(
            "speed-frozen 6kmh",
            vec![F::SpeedImplausible(kmh_to_mps(6.0))],
            "frozen at a plausible low value below the 2 m/s gate: reached faster than braking allows; held speed, then 2 A floor",
        ),
        pulling_away(
            case(
                "speed-pulses-lost",
                vec![F::SpeedPulsesLost],
                "the tone wheel's pulses stop at 5 km/h, below the 2 m/s gate, as the vehicle pulls away: the decoder's fall to 0 m/s is as slow as a stop, so only the wheels' shimmy-band oscillation after the kick shows the vehicle rolls; then speed unknown, 2 A floor until the reading is back above the gate. Outside the window nothing oscillates and the gated-off damper is stable: detected once shimmy develops",
            ),
            5.0,
        ),
        pulling_away(
            case(
                "speed-frozen 0kmh",
                vec![F::SpeedImplausible(0.0)],
                "the speed reads 0 m/s (valid) as the vehicle pulls away from rest: no trusted history contradicts it; the shimmy-band oscillation does: detected once shimmy develops",
            ),
            0.0,
        ),
        pulling_away(
            case(
                "speed-frozen 6kmh",
                vec![F::SpeedImplausible(kmh_to_mps(6.0))],
                "frozen at 6 km/h (plausible, below the gate) as the vehicle pulls away from it: detected once shimmy develops",
            ),
            6.0,
        ),
        case(
            "speed-implausible 300kmh",
            vec![F::SpeedImplausible(kmh_to_mps(300.0))],
            "above 70 m/s",
        ),
        case(
            "frame-loss 10/100",
            vec![F::FrameLoss {
                period: 100,
                length: 10,
            }],
            "11 ms gaps > 5 ms: Timing",
        ),
        case(
            "frame-loss 1/10",
            vec![F::FrameLoss {
                period: 10,
                length: 1,
            }],
            "2 ms gaps: counted as missed samples, command held 1 ms (harmless, no mode change)",
        ),
        case(
            "frame-loss all",
            vec![F::FrameLoss {
                period: 1,
                length: 1,
            }],
            "no control step completes: the watchdog resets the board after at most 18.8 ms (its timeout at the slowest LSI) and it boots with the coil at 2 A, open loop",
        ),
        lost_actuator(
            "coil-open",
            vec![F::CoilOpen],
            "CANNOT be handled: no current reaches the coil, the damper is passive-off (0 A). Seen after 50 ms with > 0.2 A expected (the kick, or a test pulse at idle); latched; the firmware commands 0 A and reports damper_available = false (driver warning / service); passive-off is stable outside the window and for small disturbances inside it",
        ),
        lost_actuator(
            "coil-short x5",
            vec![F::CoilShort(5.0)],
            "CANNOT be handled: the current bypasses the coil, damper passive-off. Seen after 50 ms of more than 3x the current the drive pushes through the coil (a saturated shunt ADC where that proves it; the current loop's lowered duty is part of the drive); latched; 0 A (driving a short only heats it), damper_available = false",
        ),
        case(
            "nan-left+stuck-right",
            vec![F::Nan(Side::Left), F::Stuck(Side::Right)],
            "the right freeze cannot be seen without the left reference: degraded on the (frozen) right encoder, but the 2 A floor of degraded mode holds the damper safe",
        ),
        case(
            "stuck-both",
            vec![F::Stuck(Side::Both)],
            "common-cause freeze: only suspected after 2 s bit-identical at speed (BothStuckSuspect, 2 A floor)",
        ),
        case(
            "error-flag-both",
            vec![F::ErrorFlag(Side::Both)],
            "common cause (supply/bus): fail-safe 2 A",
        ),
        case(
            "error-flag-both+speed-pulses-lost",
            vec![F::ErrorFlag(Side::Both), F::SpeedPulsesLost],
            "no yaw and the speed reads standstill: fail-safe at 2 A (0 A only for a trusted low speed)",
        ),
        case(
            "noise-left+speed-lost",
            vec![F::Noise(Side::Left, deg(2.0)), F::SpeedLost],
            "two independent faults",
        ),
        Case {
            min_duration_s: 8.0,
            ..case(
                "dropout-left 1/1500",
                vec![F::Dropout {
                    side: Side::Left,
                    period: 1500,
                    length: 1,
                }],
                "intermittent: one failed read every 1.5 s, longer than the 1 s recovery; latched at the 3rd within 10 s (Degraded, 2 A floor) instead of toggling Normal/Degraded forever (8 s run)",
            )
        },
        lost_actuator(
            "coil-intermittent 30/50",
            vec![F::CoilIntermittent {
                period: 50,
                length: 30,
            }],
            "chattering connector, open 30 ms of every 50 ms: never 50 ms in a row, but the mismatch accumulates (drains at 1/4 while the current matches); latched, 0 A",
        ),
        Case {
            quiet: true,
            ..lost_actuator(
                "coil-open quiet",
                vec![F::CoilOpen],
                "opens on a quiet road (no kick, 1 N m road noise) while the controller demands ~0 A: found by the test pulse (0.4 A x 80 ms after 1 s without a coil check, so within ~1.1 s; here a pulse starts at the fault time); latched, 0 A",
            )
        },
        case(
            "coil-hot x1.5",
            vec![F::CoilHot(1.5)],
            "coil resistance +50 %: the closed current loop holds the command (open loop: -33 %); nothing to report (not expected to be detected)",
        ),
        case(
            "coil-sensor-offset +0.6A",
            vec![F::CoilSensorOffset(0.6)],
            "the shunt amplifier reads 0.6 A high: current with no drive, or outside what the drive can push through the coil, is the sensor's word, not a short's; coil-sensor latched, the coil driven open loop (known error: the coil's resistance), the damper kept",
        ),
        case(
            "coil-sensor-offset +0.3A",
            vec![F::CoilSensorOffset(0.3)],
            "reads 0.3 A high (the closed loop would deliver 0.3 A less): found as current with no drive; coil-sensor, open loop, the damper kept",
        ),
        case(
            "coil-sensor-gain x2",
            vec![F::CoilSensorGain(2.0)],
            "reads twice the current (the closed loop would deliver half): twice what the drive pushes through the coil, beyond any coil temperature but short of a short's 3x; coil-sensor, open loop, the damper kept",
        ),
        case(
            "coil-sensor-gain x0.4",
            vec![F::CoilSensorGain(0.4)],
            "reads 40 % (the closed loop would push 2.5x the command): below the hot coil's 67 %, above an open coil's 25 %; coil-sensor, open loop, the damper kept",
        ),
        case(
            "coil-hot x1.5+error-flag-both",
            vec![F::CoilHot(1.5), F::ErrorFlag(Side::Both)],
            "fail-safe 2 A into a hot coil: the current loop delivers it (open loop: 1.33 A)",
        ),
        ending(
            case(
                "parity-left",
                vec![F::Parity(Side::Left)],
                "recovery: the fault ends after 0.5 s; Normal 1 s later, nothing latched",
            ),
            0.5,
        ),
        ending(
            case(
                "error-flag-both",
                vec![F::ErrorFlag(Side::Both)],
                "recovery from FailSafe: Normal 1 s after the end, the controller restarted",
            ),
            0.5,
        ),
        ending(
            case(
                "speed-pulses-lost",
                vec![F::SpeedPulsesLost],
                "recovery: the pulse train comes back after 0.5 s (the reading is back above 2 m/s); Normal 1 s later",
            ),
            0.5,
        ),
        ending(
            case(
                "frame-loss all",
                vec![F::FrameLoss {
                    period: 1,
                    length: 1,
                }],
                "recovery from a watchdog reset: the board reboots when control steps complete again (latched faults kept); Normal at once",
            ),
            0.5,
        ),
        ending(
            case(
                "frame-loss 10/100",
                vec![F::FrameLoss {
                    period: 100,
                    length: 10,
                }],
                "recovery from a timing fault: Normal 1 s after the last gap",
            ),
            0.5,
        ),
    ]
}

/// The disturbance and timing of a campaign run, on the vehicle model `M` (the car by default;
/// the kick and noise torques are the car's, scaled by `SimModel::yaw_torque_scale` in the
/// loop).
#[derive(Clone, Copy, Debug)]
pub struct Setup<M: SimModel<N> = ReferenceModel, const N: usize = { REFERENCE_N }> {
    /// The true vehicle (plant, damper, sensors).
    pub plant: M::Vehicle,
    /// The vehicle the firmware believes (controller model and gains); `None`: `plant`.
    pub model_vehicle: Option<M::Vehicle>,
    /// Fault injection time, s.
    pub fault_s: f64,
    /// Yaw kick (half-sine torque on both wheels) time, s.
    pub kick_s: f64,
    /// Kick peak torque, N m.
    pub kick_nm: f64,
    /// Kick duration, s.
    pub kick_duration_s: f64,
    /// Road noise standard deviation, N m.
    pub noise_nm: f64,
    /// Run length, s.
    pub duration_s: f64,
    /// Seed (road and sensor noise).
    pub seed: u64,
    /// How the command reaches the coil (the board's closed current loop by default).
    pub coil_drive: CoilDrive,
    /// The faults end at this time, s (`None`: they last to the end of the run).
    pub fault_end_s: Option<f64>,
    /// The vehicle runs at this speed, km/h, until the fault, then accelerates to the run's
    /// speed in [`PULL_AWAY_S`] (`None`: the run's speed throughout).
    pub pull_away_from_kmh: Option<f64>,
}

impl Default for Setup {
    /// Nominal plant; fault at 1.0 s, a 100 N m x 20 ms kick at 1.1 s; 5 N m road noise
    /// (20 Hz corner, half common); 5 s; the board's closed-loop coil drive.
    fn default() -> Self {
        Setup::on(Vehicle::nominal())
    }
}

impl<M: SimModel<N>, const N: usize> Setup<M, N> {
    /// [`Setup::default`]'s disturbance and timing on the vehicle `plant`.
    pub fn on(plant: M::Vehicle) -> Self {
        Setup {
            plant,
            model_vehicle: None,
            fault_s: 1.0,
            kick_s: 1.1,
            kick_nm: 100.0,
            kick_duration_s: 0.02,
            noise_nm: 5.0,
            duration_s: 5.0,
            seed: 3,
            coil_drive: CoilDrive::ClosedLoop,
            fault_end_s: None,
            pull_away_from_kmh: None,
        }
    }
}

/// Result of one (case, speed) run.
#[derive(Clone, Debug)]
pub struct CaseResult {
    /// Case label.
    pub case: String,
    /// Arm (controller) name.
    pub arm: String,
    /// Speed, km/h.
    pub speed_kmh: f64,
    /// Inside the no-damper Hopf window.
    pub in_window: bool,
    /// Faults injected.
    pub injected: bool,
    /// Detection time after the injection, ms (first detected fault or missed sample).
    pub detect_ms: Option<f64>,
    /// The detected fault kinds (names, `+`-joined).
    pub detected: String,
    /// Worst supervisor mode after the fault.
    pub worst_mode: Mode,
    /// Mode at the end of the run.
    pub final_mode: Mode,
    /// Coil command at the end, A.
    pub final_cmd_a: f64,
    /// Mean true coil current over the last 0.5 s, A.
    pub final_coil_a: f64,
    /// Peak |wheel yaw| after the fault, rad.
    pub peak_after_rad: f64,
    /// Shimmy-band amplitude over the last 0.5 s, rad.
    pub amp_end_rad: f64,
    /// Commands that broke the output contract (NaN or outside [0, i_max]).
    pub invalid_commands: u64,
    /// Supervisor mode changes after the fault.
    pub mode_changes: usize,
    /// Time of the last mode change, s (`None`: none).
    pub last_mode_change_s: Option<f64>,
    /// Run length, s.
    pub duration_s: f64,
    /// The command was constant over the last 0.5 s (so the coil current must equal it).
    pub cmd_steady_at_end: bool,
    /// Faults latched at the end because they recurred (names, `+`-joined).
    pub escalated: String,
    /// The faults ended before the end of the run (a recovery case).
    pub ended: bool,
    /// Faults still active at the end (names, `+`-joined).
    pub final_faults: String,
    /// Notes.
    pub note: &'static str,
    /// See [`Case::handleable`].
    pub handleable: bool,
}

impl CaseResult {
    /// Peak after the fault below [`SUPPRESSED_BELOW_RAD`].
    pub fn suppressed(&self) -> bool {
        self.peak_after_rad < SUPPRESSED_BELOW_RAD
    }

    /// The supervisor noticed something.
    pub fn detected(&self) -> bool {
        self.detect_ms.is_some()
    }
}

/// The closed-loop configuration and scenario of one run.
pub fn build<M: SimModel<N>, const N: usize>(
    setup: &Setup<M, N>,
    arm: Arm,
    faults: &[FaultMode],
    speed_kmh: f64,
) -> (LoopConfig<M, N>, Scenario) {
    let model = setup.model_vehicle.as_ref().unwrap_or(&setup.plant);
    let mut cfg = LoopConfig::for_vehicle(&M::family_vehicle(&setup.plant), arm, setup.duration_s)
        .with_model_vehicle(&M::family_vehicle(model));
    cfg.sensors.seed = setup.seed;
    cfg.estimator = false;
    cfg.record_every = 50;
    cfg.coil_drive = setup.coil_drive;
    cfg.faults = faults
        .iter()
        .map(|&mode| FaultSpec {
            mode,
            start_s: setup.fault_s,
            end_s: setup.fault_end_s,
        })
        .collect();
    let mut sc = Scenario::new(match setup.pull_away_from_kmh {
        Some(from) => SpeedProfile::Ramp {
            v0_mps: kmh_to_mps(from),
            v1_mps: kmh_to_mps(speed_kmh),
            t0_s: setup.fault_s,
            t1_s: setup.fault_s + PULL_AWAY_S,
        },
        None => SpeedProfile::Constant(kmh_to_mps(speed_kmh)),
    });
    sc.noise = Some(RoadNoise::new(setup.noise_nm, 20.0, 0.5, setup.seed));
    sc.impulses.push(Impulse {
        t0_s: setup.kick_s,
        duration_s: setup.kick_duration_s,
        peak_nm: [setup.kick_nm, setup.kick_nm],
    });
    (cfg, sc)
}

/// Runs one case at one speed (`supervised == false`: the bare controller, no supervisor).
pub fn run_case<M: SimModel<N>, const N: usize>(
    setup: &Setup<M, N>,
    arm: Arm,
    c: &Case,
    speed_kmh: f64,
    supervised: bool,
) -> Result<(CaseResult, LoopResult)> {
    run_case_with(setup, arm, c, speed_kmh, |cfg| cfg.supervised = supervised)
}

/// [`run_case`] with the loop configuration changed by `tweak` (e.g. other supervisor
/// thresholds, to show what a check prevents).
pub fn run_case_with<M: SimModel<N>, const N: usize>(
    setup: &Setup<M, N>,
    arm: Arm,
    c: &Case,
    speed_kmh: f64,
    tweak: impl FnOnce(&mut LoopConfig<M, N>),
) -> Result<(CaseResult, LoopResult)> {
    let setup = &c.setup(setup);
    let (mut cfg, mut sc) = build(setup, arm, &c.faults, speed_kmh);
    tweak(&mut cfg);
    let r = closed_loop::run(&cfg, &mut sc, None)
        .with_context(|| format!("{} at {speed_kmh} km/h: integration failed", c.name))?;
    let k_f = ((setup.fault_s / cfg.dt_s).round() as usize).min(r.series.psi_l_rad.len());
    let peak_after_rad = r.series.psi_l_rad[k_f..]
        .iter()
        .fold(0.0f64, |a, x| a.max(x.abs()));
    let m = r.metrics(&cfg, None);
    let log = &r.faults;
    let after = |t: Option<f64>| t.filter(|&t| t >= setup.fault_s - 1e-9);
    let first = match (after(log.first_detect_s), after(log.first_missed_s)) {
        (Some(a), Some(b)) => Some(a.min(b)),
        (a, b) => a.or(b),
    };
    let tail = ((0.5 / cfg.dt_s) as usize)
        .min(r.series.coil_a.len())
        .max(1);
    let coil_tail = &r.series.coil_a[r.series.coil_a.len() - tail..];
    let cmd_tail = &r.series.cmd_a[r.series.cmd_a.len().saturating_sub(tail)..];
    let cmd_steady_at_end = cmd_tail.windows(2).all(|w| w[0] == w[1]);
    let changes: Vec<f64> = log
        .events
        .iter()
        .filter(|(t, e)| {
            *t >= setup.fault_s - 1e-9 && matches!(e, SupervisorEvent::ModeChange { .. })
        })
        .map(|(t, _)| *t)
        .collect();
    let escalated: Vec<&str> = log
        .events
        .iter()
        .filter_map(|(_, e)| match e {
            SupervisorEvent::Latched { kind, .. } => Some(kind.name()),
            _ => None,
        })
        .collect();
    let mut detected: Vec<&str> = log.detected.iter().map(|k| k.name()).collect();
    if log.missed_samples > 0 {
        detected.push("missed-samples");
    }
    if log.watchdog_resets > 0 {
        detected.push("watchdog-reset");
    }
    let res = CaseResult {
        case: c.name.clone(),
        arm: arm.name().to_string(),
        speed_kmh,
        in_window: window_kmh(&M::family_vehicle(&setup.plant).model.linear())
            .is_some_and(|(on, off)| (on..=off).contains(&speed_kmh)),
        injected: !c.faults.is_empty(),
        detect_ms: first.map(|t| (t - setup.fault_s) * 1e3),
        detected: detected.join("+"),
        worst_mode: log.worst_mode,
        final_mode: log.final_mode,
        final_cmd_a: r.series.cmd_a.last().copied().unwrap_or(0.0),
        final_coil_a: coil_tail.iter().sum::<f64>() / coil_tail.len() as f64,
        peak_after_rad,
        amp_end_rad: m.amp_end_rad,
        invalid_commands: log.invalid_commands,
        mode_changes: changes.len(),
        last_mode_change_s: changes.last().copied(),
        duration_s: setup.duration_s,
        cmd_steady_at_end,
        escalated: escalated.join("+"),
        ended: c.lasts_s.is_some(),
        final_faults: log
            .final_faults
            .iter()
            .map(|k| k.name())
            .collect::<Vec<_>>()
            .join("+"),
        note: c.note,
        handleable: c.handleable,
    };
    Ok((res, r))
}

/// Runs every (case, speed) pair in parallel, plus a no-damper healthy reference per speed.
pub fn campaign<M: SimModel<N>, const N: usize>(
    setup: &Setup<M, N>,
    cases: &[Case],
    speeds_kmh: &[f64],
) -> Result<Vec<CaseResult>> {
    let mut jobs: Vec<(Arm, &Case, f64)> = Vec::new();
    let reference = case(
        "healthy (no damper)",
        vec![],
        "reference: the disturbance starts shimmy inside the window (suppressed column: does it decay?)",
    );
    for &v in speeds_kmh {
        jobs.push((Arm::NoDamper, &reference, v));
        for c in cases {
            jobs.push((Arm::Mr(ControllerKind::Asmc), c, v));
        }
    }
    let bar = progress::bar(jobs.len(), "fault runs");
    let mut out: Vec<CaseResult> = jobs
        .par_iter()
        .map(|&(arm, c, v)| {
            let r = run_case(setup, arm, c, v, true).map(|r| r.0);
            bar.inc(1);
            r
        })
        .collect::<Result<_>>()?;
    bar.finish_and_clear();
    out.sort_by(|a, b| a.speed_kmh.total_cmp(&b.speed_kmh));
    Ok(out)
}

/// Run length of a campaign run: 1 to 600 s.
pub const DURATION_S: Range = Range::closed(1.0, 600.0, "s");

/// Most speeds in one campaign.
pub const MAX_SPEEDS: usize = 32;

/// Command-line arguments of `shimmy-sim faults`.
#[derive(Args, Clone, Debug)]
pub struct FaultsArgs {
    /// Output folder (`--out`; default out/faults, [`Self::out_dir`]).
    #[command(flatten)]
    pub out: crate::cmd::OutArg,
    /// Speeds, km/h (comma separated): two inside the 29.35-84.15 km/h window, two outside.
    /// Each 1 to 250 km/h, at most 32 speeds.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "20,45,70,100",
        alias = "speeds",
        allow_negative_numbers = true, value_parser = arg_range::speed_kmh()
    )]
    pub speeds_kmh: Vec<f64>,
    /// Only cases whose name contains this (an error if none does).
    #[arg(long)]
    pub only: Option<String>,
    /// Run length, s (fault at 1.0 s, kick at 1.1 s): 1 to 600 s. At 1 s the run ends at the
    /// fault, so no injected fault can be detected and those checks fail.
    #[arg(long, default_value_t = 5.0, alias = "duration", allow_negative_numbers = true, value_parser = arg_range::f64_in(DURATION_S))]
    pub duration_s: f64,
    /// Vehicle: a named set of any model (`shimmy-sim vehicles` lists them), a vehicle file
    /// (TOML, see docs/vehicle-file.md), or `all`: every named set, each into `<out>/<set>/`.
    /// `--params` is the older name.
    #[arg(long, visible_alias = "params", default_value = "nominal")]
    pub vehicle: String,
    /// The vehicle the firmware believes (`--model-vehicle`).
    #[command(flatten)]
    pub model_vehicle: crate::cmd::ModelVehicleArg,
    /// Peak of the yaw kick after the fault (20 ms half-sine on both wheels), N m for the car
    /// (another model: times its `yaw_torque_scale`): 0 to 5000.
    #[arg(long, default_value_t = 100.0, allow_negative_numbers = true, value_parser = arg_range::f64_in(KICK_NM))]
    pub kick_nm: f64,
}

impl FaultsArgs {
    /// The output folder: `--out`, else out/faults.
    pub fn out_dir(&self) -> PathBuf {
        self.out.dir_or("out/faults")
    }
}

/// The kick's peak torque: 0 to 5000 N m (car-equivalent).
pub const KICK_NM: Range = Range::closed(0.0, 5000.0, "N m");

impl FaultsArgs {
    /// The cases `--only` selects; an error naming the existing cases when none matches.
    /// Also checks what clap cannot (the number of speeds).
    pub fn cases(&self) -> Result<Vec<Case>> {
        arg_range::ensure_count("--speeds-kmh", self.speeds_kmh.len(), MAX_SPEEDS)?;
        for &v in &self.speeds_kmh {
            arg_range::SPEED_KMH.check("--speeds-kmh", v)?;
        }
        DURATION_S.check("--duration-s", self.duration_s)?;
        KICK_NM.check("--kick-nm", self.kick_nm)?;
        let all = standard_cases();
        let names: Vec<String> = all.iter().map(|c| c.name.clone()).collect();
        let cases: Vec<Case> = all
            .into_iter()
            .filter(|c| self.only.as_deref().is_none_or(|o| c.name.contains(o)))
            .collect();
        if cases.is_empty() {
            bail!(
                "--only {:?}: no case name contains it; cases: {}",
                self.only.as_deref().unwrap_or(""),
                names.join(", ")
            );
        }
        Ok(cases)
    }
}

fn suppressed_cell(r: &CaseResult) -> &'static str {
    if r.arm == "no-damper" {
        return if r.amp_end_rad > SUPPRESSED_BELOW_RAD {
            "(shimmy)"
        } else {
            "(decays)"
        };
    }
    match (r.suppressed(), r.handleable) {
        (true, _) => "yes",
        (false, true) => "NO",
        (false, false) => "no (actuator lost)",
    }
}

/// The table as markdown.
pub fn markdown(rows: &[CaseResult]) -> String {
    let mut s = String::from(
        "| fault | arm | speed [km/h] | window | detect [ms] | detected | worst mode | final mode | mode changes | latched | cmd / coil at end [A] | peak yaw after fault [deg] | end amplitude [deg] | suppressed | note |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    let dash = |x: &str| {
        if x.is_empty() {
            "-".to_string()
        } else {
            x.to_string()
        }
    };
    for r in rows {
        let _ = writeln!(
            s,
            "| {} | {} | {:.0} | {} | {} | {} | {} | {} | {} | {} | {:.2} / {:.2} | {:.3} | {:.3} | {} | {} |",
            r.case,
            r.arm,
            r.speed_kmh,
            if r.in_window { "in" } else { "out" },
            opt(r.detect_ms, 0),
            dash(&r.detected),
            r.worst_mode.name(),
            r.final_mode.name(),
            r.mode_changes,
            dash(&r.escalated),
            r.final_cmd_a,
            r.final_coil_a,
            r.peak_after_rad.to_degrees(),
            r.amp_end_rad.to_degrees(),
            suppressed_cell(r),
            r.note
        );
    }
    s
}

/// The table as CSV.
pub fn csv(rows: &[CaseResult]) -> String {
    let mut s = String::from(
        "fault,arm,speed_kmh,in_window,detect_ms,detected,worst_mode,final_mode,mode_changes,latched,final_cmd_a,final_coil_a,peak_after_deg,amp_end_deg,suppressed,invalid_commands\n",
    );
    for r in rows {
        let _ = writeln!(
            s,
            "{},{},{},{},{},{},{},{},{},{},{:.4},{:.4},{:.5},{:.5},{},{}",
            r.case,
            r.arm,
            r.speed_kmh,
            r.in_window,
            r.detect_ms.map_or(String::new(), |v| format!("{v:.1}")),
            r.detected,
            r.worst_mode.name(),
            r.final_mode.name(),
            r.mode_changes,
            r.escalated,
            r.final_cmd_a,
            r.final_coil_a,
            r.peak_after_rad.to_degrees(),
            r.amp_end_rad.to_degrees(),
            r.suppressed(),
            r.invalid_commands
        );
    }
    s
}

/// Largest peak wheel yaw after a fault, relative to the fault-free ASMC run at the same
/// speed, that the target allows: 1.5.
pub const PEAK_RATIO_TARGET: f64 = 1.5;

/// The peak after each fault against the fault-free (`healthy`) ASMC run at the same speed,
/// over the ASMC runs with a working actuator: (runs within [`PEAK_RATIO_TARGET`], runs, the
/// worst run and its ratio). `None` without a fault-free run (e.g. `--only`).
pub fn peak_ratios(rows: &[CaseResult]) -> Option<(usize, usize, &CaseResult, f64)> {
    let asmc = || rows.iter().filter(|r| r.arm != "no-damper");
    let reference = |v: f64| {
        asmc()
            .find(|r| !r.injected && r.speed_kmh == v)
            .map(|r| r.peak_after_rad)
    };
    let mut within = 0;
    let mut n = 0;
    let mut worst: Option<(&CaseResult, f64)> = None;
    for r in asmc().filter(|r| r.injected && r.handleable) {
        let ratio = r.peak_after_rad / reference(r.speed_kmh)?;
        n += 1;
        within += usize::from(ratio <= PEAK_RATIO_TARGET);
        if worst.is_none_or(|(_, w)| ratio > w) {
            worst = Some((r, ratio));
        }
    }
    worst.map(|(r, x)| (within, n, r, x))
}

/// The mode must not change in the last this many seconds of a run (a fault that recurs must
/// not keep toggling the mode), s.
pub const SETTLED_S: f64 = 1.5;

/// A fault that only the wheels' shimmy-band oscillation reveals (a speed lost below the gate)
/// must be detected in a run inside the Hopf window whose wheel yaw after the fault reached
/// this: 0.25 deg, lobes well above the supervisor's 2.5 mrad (0.14 deg) motion threshold.
pub const SHIMMY_DEVELOPS_RAD: f64 = 0.25 * std::f64::consts::PI / 180.0;

/// Largest relative error of the coil current against a steady command (>= 0.5 A) at the end.
pub const COIL_CURRENT_TOL: f64 = 0.05;

/// Summary checks: every injected fault detected (except the cases whose note says it is not
/// expected), shimmy suppressed for every ASMC run where the actuator is left, fail-safe at 0 A
/// where it is lost, no invalid command anywhere, the mode settled (no change in the last
/// [`SETTLED_S`]), a steady command of at least 0.5 A carried by the coil within
/// [`COIL_CURRENT_TOL`], and after a fault that ended: Normal, nothing active or latched.
/// Returns the lines that fail.
pub fn check(rows: &[CaseResult]) -> Vec<String> {
    let mut bad = Vec::new();
    for r in rows.iter().filter(|r| r.arm != "no-damper") {
        if r.ended
            && (r.final_mode != Mode::Normal
                || !r.final_faults.is_empty()
                || !r.escalated.is_empty())
        {
            bad.push(format!(
                "{} at {} km/h: the fault ended but the run ends {} with {:?} active, {:?} latched",
                r.case,
                r.speed_kmh,
                r.final_mode.name(),
                r.final_faults,
                r.escalated
            ));
        }
        if let Some(t) = r.last_mode_change_s {
            if t > r.duration_s - SETTLED_S {
                bad.push(format!(
                    "{} at {} km/h: mode still changing at {t:.3} s ({} changes)",
                    r.case, r.speed_kmh, r.mode_changes
                ));
            }
        }
        if r.handleable
            && r.cmd_steady_at_end
            && r.final_cmd_a >= 0.5
            && (r.final_coil_a - r.final_cmd_a).abs() > COIL_CURRENT_TOL * r.final_cmd_a
        {
            bad.push(format!(
                "{} at {} km/h: coil carries {:.3} A for a {:.3} A command",
                r.case, r.speed_kmh, r.final_coil_a, r.final_cmd_a
            ));
        }
        let expect_detect = r.injected
            && !r.note.contains("not expected to be detected")
            && (!r.note.contains("detected once shimmy develops")
                || (r.in_window && r.peak_after_rad >= SHIMMY_DEVELOPS_RAD));
        if expect_detect && !r.detected() {
            bad.push(format!("{} at {} km/h: not detected", r.case, r.speed_kmh));
        }
        if !r.handleable {
            if r.final_mode != Mode::FailSafe || r.final_cmd_a != 0.0 {
                bad.push(format!(
                    "{} at {} km/h: lost actuator but {} at {} A",
                    r.case,
                    r.speed_kmh,
                    r.final_mode.name(),
                    r.final_cmd_a
                ));
            }
        } else if !r.suppressed() {
            bad.push(format!(
                "{} at {} km/h: peak {:.3} deg after the fault",
                r.case,
                r.speed_kmh,
                r.peak_after_rad.to_degrees()
            ));
        }
        if r.invalid_commands > 0 {
            bad.push(format!(
                "{} at {} km/h: {} invalid commands",
                r.case, r.speed_kmh, r.invalid_commands
            ));
        }
    }
    bad
}

/// The campaign's verdict from [`check`]'s failing lines: `Ok` when there are none, else an
/// error naming every failed check (the command's exit status is non-zero).
pub fn verdict(bad: &[String]) -> Result<()> {
    if bad.is_empty() {
        return Ok(());
    }
    bail!(
        "{} fault-campaign check(s) failed:\n  {}",
        bad.len(),
        bad.join("\n  ")
    )
}

/// `--vehicle` value that runs the campaign on every shipped vehicle.
pub const ALL_VEHICLES: &str = "all";

/// The command. Every option is checked before anything runs; the table and files are
/// written either way, then the command fails if any check failed. `--vehicle all`: the
/// campaign on every named set of every model, each into `<out>/<set>/`; it fails naming the
/// vehicles whose checks failed.
pub fn command(a: &FaultsArgs) -> Result<()> {
    if a.vehicle != ALL_VEHICLES {
        return command_one(a);
    }
    if a.model_vehicle.given().is_some() {
        bail!("--model-vehicle needs one --vehicle, not `{ALL_VEHICLES}`");
    }
    a.cases()?;
    let mut failed = Vec::new();
    for set in registry::all_sets() {
        println!("\n== vehicle `{set}`");
        let one = FaultsArgs {
            vehicle: set.to_string(),
            out: crate::cmd::OutArg::new(a.out_dir().join(set)),
            ..a.clone()
        };
        if let Err(e) = command_one(&one) {
            println!("{e:#}");
            failed.push(set);
        }
    }
    if !failed.is_empty() {
        bail!(
            "the fault campaign failed on {} of the shipped vehicles: {}",
            failed.len(),
            failed.join(", ")
        );
    }
    println!(
        "\nthe fault campaign passed on every shipped vehicle ({})",
        registry::all_sets().join(", ")
    );
    Ok(())
}

/// The command on one vehicle (a named set or a file).
fn command_one(a: &FaultsArgs) -> Result<()> {
    struct On<'a>(&'a FaultsArgs);
    impl ModelVisitor for On<'_> {
        type Output = Result<()>;
        fn visit<M: Registered<N>, const N: usize>(self, f: M::File) -> Result<()> {
            command_on::<M, N>(self.0, M::vehicle(f)?)
        }
    }
    registry::with_model(vehicle_file::load_model(&a.vehicle)?, On(a))
}

/// The command on the vehicle `plant` of the model `M`.
fn command_on<M: FileModel<N>, const N: usize>(a: &FaultsArgs, plant: M::Vehicle) -> Result<()> {
    let cases = a.cases()?;
    let setup = Setup {
        model_vehicle: match a.model_vehicle.given() {
            Some(m) => Some(M::load_vehicle(m, Path::new("")).context("--model-vehicle")?),
            None => None,
        },
        duration_s: a.duration_s,
        kick_nm: a.kick_nm,
        ..Setup::<M, N>::on(plant)
    };
    let _out_dir = crate::sim::input::files::OutDir::claim(&a.out_dir())?;
    let wall = std::time::Instant::now();
    let rows = campaign(&setup, &cases, &a.speeds_kmh)?;
    let md = markdown(&rows);
    println!(
        "fault campaign: ASMC under SafeController, vehicle `{}`, fault at {} s, kick {} N m x {} ms at {} s, road noise {} N m; {} runs in {:.1} s wall",
        a.vehicle,
        setup.fault_s,
        setup.kick_nm,
        setup.kick_duration_s * 1e3,
        setup.kick_s,
        setup.noise_nm,
        rows.len(),
        wall.elapsed().as_secs_f64()
    );
    println!("{md}");
    crate::sim::input::files::write_file(&a.out_dir().join("faults.csv"), csv(&rows))?;
    crate::sim::input::files::write_file(&a.out_dir().join("faults.md"), &md)?;
    if let Some((within, n, worst, ratio)) = peak_ratios(&rows) {
        println!(
            "peak yaw after the fault against the fault-free run at the same speed: within {PEAK_RATIO_TARGET}x in {within} of {n} ASMC runs with a working actuator; worst {ratio:.2}x ({} at {} km/h: {:.3} deg)",
            worst.case,
            worst.speed_kmh,
            worst.peak_after_rad.to_degrees()
        );
    }
    let bad = check(&rows);
    if bad.is_empty() {
        println!("every injected fault detected (where expected); shimmy suppressed in every ASMC run with a working actuator; coil faults at 0 A fail-safe; every mode settled; every steady command carried by the coil");
    } else {
        println!("CHECKS FAILED:");
        for b in &bad {
            println!("  {b}");
        }
    }
    println!("wrote {}", a.out_dir().display());
    verdict(&bad)
}
