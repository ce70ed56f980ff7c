//! `shimmy-sim analyze` on logs written by the simulator: the board's margin path on a log
//! gives the in-loop meter's estimates, bit for bit when the log is the meter's own 1 kHz
//! input, and close to them (and to the plant's true damping) when the log comes at another
//! rate with jitter and gaps; fed at the wrong rate, the estimate is wrong (the negative).

use crate::common;

use common::{run_in, temp_dir};
use shimmy_sim::sim::analyze::{analyze, Analysis, AnalyzeOptions};
use shimmy_sim::sim::input::log_file::{self, LogMapping, MappingChanges};
use shimmy_sim::sim::run::closed_loop::{LoopConfig, LoopResult};
use shimmy_sim::sim::run::reference::reference_line;
use shimmy_sim::sim::run::{scenario, scenario_file};
use std::fmt::Write as _;
use std::path::Path;

/// No damper at 25 km/h (4 km/h below the onset, the shimmy mode lightly damped), road noise
/// and imbalance, the trace at 1 kHz.
const SCENARIO: &str = r#"
name = "analyze-log"
duration_s = 24.0
seed = 3
[controller]
kind = "no-damper"
[speed]
constant_kmh = 25.0
[road_noise]
std_nm = 10.0
corner_hz = 20.0
common = 0.5
[imbalance]
amplitude_nm = 2.0
phase_deg = [0.0, 60.0]
[output]
trace_every = 1
"#;

fn simulate(dir: &Path) -> (LoopConfig, LoopResult, std::path::PathBuf) {
    let spec = scenario_file::parse(SCENARIO, "analyze-log").unwrap();
    let (cfg, r) = scenario::run(&spec).unwrap();
    let trace = dir.join("trace.csv");
    r.write_trace_csv(&trace).unwrap();
    (cfg, r, trace)
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Median slow damping and frequency of the valid estimates after `t0`.
fn settled(a: &Analysis, t0: f64) -> (f64, f64) {
    let v: Vec<_> = a
        .rows
        .iter()
        .filter(|r| r.slow_valid && r.t_s >= t0)
        .collect();
    assert!(v.len() > 100, "{} valid rows after {t0} s", v.len());
    (
        median(v.iter().map(|r| r.zeta_slow).collect()),
        median(v.iter().map(|r| r.freq_slow_hz).collect()),
    )
}

#[test]
fn a_simulator_log_gives_the_in_loop_estimates_bit_for_bit() {
    let dir = temp_dir("analyze-bits");
    let (_, r, trace) = simulate(&dir);
    // `run` writes the columns the default mapping reads.
    let head = std::fs::read_to_string(&trace).unwrap();
    let header = head.lines().next().unwrap();
    for c in ["t_s", "psi_l_meas_rad", "psi_r_meas_rad", "speed_meas_mps"] {
        assert!(
            header.split(',').any(|h| h == c),
            "trace lacks {c}: {header}"
        );
    }
    let log = log_file::load(&trace, &LogMapping::default()).unwrap();
    assert_eq!(log.samples.len(), 24_000);
    for model in [false, true] {
        let a = analyze(
            &log.samples,
            &AnalyzeOptions {
                model,
                ..AnalyzeOptions::default()
            },
        )
        .unwrap();
        assert_eq!(a.resampling.exact, 24_000, "the identity resampling");
        assert_eq!(a.rows.len(), r.meter.len());
        for (x, m) in a.rows.iter().zip(&r.meter) {
            let ours = (
                x.t_s,
                x.zeta_slow,
                x.sigma_zeta_slow,
                x.zeta_fast,
                x.freq_slow_hz,
            );
            let theirs = (
                m.t_s,
                m.zeta_slow,
                m.sigma_zeta_slow,
                m.zeta_fast,
                m.freq_hz,
            );
            // Debug text: every bit of each f64 (and NaN equal to NaN).
            assert_eq!(format!("{ours:?}"), format!("{theirs:?}"), "at {} s", m.t_s);
            assert_eq!(x.amplitude_rad.to_bits(), m.amplitude_rad.to_bits());
            assert_eq!(x.slow_valid, m.valid);
        }
        assert!(a.rows.iter().filter(|x| x.slow_valid).count() > 1000);
        // The model arm reports the model damping; the data-only arm none.
        assert_eq!(a.rows.iter().any(|x| x.zeta_model.is_finite()), model);
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// Deterministic uniform numbers in [-1, 1).
struct Lcg(u64);
impl Lcg {
    fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (self.0 >> 11) as f64 / (1u64 << 52) as f64 - 1.0
    }
}

/// The 1 kHz meter input of `r` as another logger would have written it: 400 Hz with
/// +-0.4 ms of time-stamp jitter (values at the jittered instants, linear between the 1 kHz
/// samples), two holes (0.3 s and 60 ms), the yaw of one wheel in degrees, the speed in km/h,
/// time in ms, `;`-separated.
fn foreign_log(r: &LoopResult) -> String {
    let mut rng = Lcg(11);
    let at = |t: f64, get: &dyn Fn(usize) -> f64| {
        let k = (t / 1e-3).floor() as usize;
        let w = t / 1e-3 - k as f64;
        get(k) + w * (get(k + 1) - get(k))
    };
    let tr = &r.trace;
    let mut s = String::from("# other logger, 400 Hz\ntime_ms;steer_deg;v_kmh;note\n");
    for j in 1..(23.9 * 400.0) as usize {
        let t = j as f64 / 400.0 + 0.4e-3 * rng.next();
        if (6.0..6.3).contains(&t) || (15.0..15.06).contains(&t) {
            continue;
        }
        let yaw = at(t, &|k| tr[k].psi_l_meas_rad);
        let v = at(t, &|k| tr[k].speed_meas_mps);
        let _ = writeln!(s, "{};{};{};x", t * 1e3, yaw.to_degrees(), v * 3.6);
    }
    s
}

const FOREIGN_MAPPING: &str = r#"
delimiter = ";"
[time]
column = "time_ms"
unit = "ms"
[yaw]
column = "steer_deg"
unit = "deg"
gain = 1.0
[speed]
column = "v_kmh"
unit = "km/h"
"#;

#[test]
fn a_log_at_another_rate_with_jitter_and_gaps_gives_the_same_damping() {
    let dir = temp_dir("analyze-foreign");
    let (cfg, r, _) = simulate(&dir);
    let map = MappingChanges::parse_toml(FOREIGN_MAPPING)
        .unwrap()
        .mapping()
        .unwrap();
    let log = log_file::parse(&foreign_log(&r), &map).unwrap();
    let a = analyze(&log.samples, &AnalyzeOptions::default()).unwrap();
    let st = a.resampling;
    assert_eq!(st.gaps, 2, "{st:?}");
    assert!((st.log_median_dt_s - 2.5e-3).abs() < 0.3e-3, "{st:?}");
    // The holes (minus the usual spacing at their edges) have no samples; the meter rejected
    // them as the board rejects a missed sample.
    assert!((340..=370).contains(&st.missing_yaw), "{st:?}");
    assert_eq!(a.rejected_samples as usize, st.missing_yaw);

    let in_loop = Analysis {
        rows: r
            .meter
            .iter()
            .map(|m| shimmy_sim::sim::analyze::AnalysisRow {
                t_s: m.t_s,
                speed_mps: m.speed_mps,
                zeta_slow: m.zeta_slow,
                sigma_zeta_slow: m.sigma_zeta_slow,
                freq_slow_hz: m.freq_hz,
                slow_valid: m.valid,
                zeta_fast: m.zeta_fast,
                sigma_zeta_fast: f64::NAN,
                freq_fast_hz: f64::NAN,
                fast_valid: false,
                amplitude_rad: m.amplitude_rad,
                zeta_model: f64::NAN,
                speed_margin_mps: f64::NAN,
                time_to_critical_s: f64::NAN,
                model_consistent: true,
                level: Default::default(),
            })
            .collect(),
        ..a.clone()
    };
    let (z_log, f_log) = settled(&a, 12.0);
    let (z_loop, f_loop) = settled(&in_loop, 12.0);
    // Independent truth: the shimmy mode of the simulated plant at its speed.
    let truth = median(
        reference_line(&cfg, &r, 0.5)
            .iter()
            .filter(|p| p.t_s >= 12.0)
            .map(|p| p.mode.zeta)
            .collect(),
    );
    println!("zeta: log {z_log:.4}, in-loop {z_loop:.4}, true {truth:.4}; freq {f_log:.3} / {f_loop:.3} Hz");
    assert!((z_log - z_loop).abs() < 0.005, "{z_log} vs {z_loop}");
    assert!((f_log - f_loop).abs() < 0.05, "{f_log} vs {f_loop}");
    assert!((z_log - truth).abs() < 0.02, "{z_log} vs true {truth}");

    // Negative: the same rows taken as 1 kHz samples (the rate not told) put the mode at 2.5
    // times its frequency.
    let wrong = MappingChanges::parse_toml(
        FOREIGN_MAPPING
            .replace("column = \"time_ms\"\nunit = \"ms\"", "rate_hz = 1000.0")
            .as_str(),
    )
    .unwrap()
    .mapping()
    .unwrap();
    let bad = analyze(
        &log_file::parse(&foreign_log(&r), &wrong).unwrap().samples,
        &AnalyzeOptions::default(),
    )
    .unwrap();
    let valid: Vec<f64> = bad
        .rows
        .iter()
        .filter(|x| x.slow_valid)
        .map(|x| x.freq_slow_hz)
        .collect();
    if !valid.is_empty() {
        let f_bad = median(valid);
        println!("at the wrong rate: {f_bad:.3} Hz");
        assert!((f_bad - f_loop).abs() > 3.0, "{f_bad} vs {f_loop}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// The command from the outside: `run` writes the log, `analyze` reads it and writes the CSV,
/// plot, Markdown, self-contained HTML and JSON with provenance; a bad log or option exits
/// non-zero with the line and column (or the option) named, and writes nothing.
#[test]
fn the_command_writes_its_report_and_rejects_bad_logs() {
    let dir = temp_dir("analyze-cli");
    std::fs::write(
        dir.join("s.toml"),
        SCENARIO.replace("duration_s = 24.0", "duration_s = 8.0"),
    )
    .unwrap();
    let ok = |args: &[&str]| {
        let o = run_in(&dir, args);
        let text = String::from_utf8_lossy(&o.stdout).to_string();
        assert!(
            o.status.success(),
            "{args:?}: {text}{}",
            String::from_utf8_lossy(&o.stderr)
        );
        text
    };
    ok(&["run", "s.toml", "--out", "sim"]);
    let stdout = ok(&["analyze", "sim/trace.csv", "--out", "a", "--data-only"]);
    assert!(
        stdout.contains("8000 samples at 1 kHz (8000 as logged"),
        "{stdout}"
    );
    let a = dir.join("a");
    let csv = std::fs::read_to_string(a.join("analysis.csv")).unwrap();
    assert_eq!(csv.lines().count(), 1 + 800);
    let md = std::fs::read_to_string(a.join("report.md")).unwrap();
    shimmy_sim::out::html::check_tables(&md).unwrap();
    let html = std::fs::read_to_string(a.join("report.html")).unwrap();
    assert!(
        html.contains("<img src=\"data:image/png;base64,"),
        "plot not embedded"
    );
    assert!(!html.contains("src=\"analysis.png\""));
    shimmy_sim::out::plot_util::assert_real_plot(&a.join("analysis.png"), 8).unwrap();
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(a.join("summary.json")).unwrap()).unwrap();
    let prov = &json["provenance"];
    assert_eq!(prov["git"], shimmy_sim::out::provenance::GIT);
    assert!(prov["command_line"]
        .as_str()
        .unwrap()
        .ends_with("analyze sim/trace.csv --out a --data-only"));
    let log_hash =
        shimmy_sim::out::provenance::sha256_hex(&std::fs::read(dir.join("sim/trace.csv")).unwrap());
    assert_eq!(prov["inputs"][0]["sha256"], log_hash.as_str());
    assert_eq!(json["metrics"]["resampling"]["exact"], 8000);
    assert_eq!(json["metrics"]["model"], false);
    assert_eq!(json["metrics"]["not_judged"], serde_json::Value::Null);
    assert!(md.contains("| verdict | judged |"), "{md}");

    // A mapping file (one yaw signal for both wheels; the true speed column, said to be in
    // km/h) is read, hashed into the provenance, and overridden by an option (m/s).
    std::fs::write(
        dir.join("m.toml"),
        "[yaw]\ncolumn = \"psi_l_meas_rad\"\ngain = 1.0\n[speed]\ncolumn = \"speed_mps\"\nunit = \"km/h\"\n",
    )
    .unwrap();
    ok(&[
        "analyze",
        "sim/trace.csv",
        "--mapping",
        "m.toml",
        "--speed-unit",
        "m/s",
        "--out",
        "m",
    ]);
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("m/summary.json")).unwrap())
            .unwrap();
    let roles: Vec<&str> = json["provenance"]["inputs"]
        .as_array()
        .unwrap()
        .iter()
        .map(|i| i["role"].as_str().unwrap())
        .collect();
    assert_eq!(roles, ["log", "vehicle record", "mapping file"]);
    assert_eq!(json["metrics"]["model"], true);
    let rows = std::fs::read_to_string(dir.join("m/analysis.csv")).unwrap();
    let kmh: f64 = rows
        .lines()
        .nth(1)
        .unwrap()
        .split(',')
        .nth(1)
        .unwrap()
        .parse()
        .unwrap();
    assert!(
        (kmh - 25.0).abs() < 1e-6,
        "{kmh} km/h: the option's m/s must win"
    );
    std::fs::write(dir.join("bad.toml"), "[yaw]\ncolum = \"a\"\n").unwrap();

    // A corrupted cell, a missing column, a bad option: non-zero exit, named, nothing written.
    let trace = std::fs::read_to_string(dir.join("sim/trace.csv")).unwrap();
    let mut lines: Vec<String> = trace.lines().map(String::from).collect();
    let cells: Vec<&str> = lines[41].split(',').collect();
    let mut bad: Vec<String> = cells.iter().map(|c| c.to_string()).collect();
    bad[15] = "0.0o1".into();
    lines[41] = bad.join(",");
    std::fs::write(dir.join("bad.csv"), lines.join("\n")).unwrap();
    for (args, want) in [
        (
            vec!["analyze", "bad.csv", "--out", "x"],
            "line 42, column 16 `psi_r_meas_rad`: `0.0o1` is not a number",
        ),
        (
            vec![
                "analyze",
                "sim/trace.csv",
                "--speed-column",
                "v",
                "--out",
                "x",
            ],
            "speed column `v` is not in the header",
        ),
        (
            vec![
                "analyze",
                "sim/trace.csv",
                "--yaw-unit",
                "grad",
                "--out",
                "x",
            ],
            "yaw.unit `grad`: allowed: rad, mrad, deg",
        ),
        (
            vec![
                "analyze",
                "sim/trace.csv",
                "--max-gap-ms",
                "0",
                "--out",
                "x",
            ],
            "--max-gap-ms",
        ),
        (
            vec![
                "analyze",
                "sim/trace.csv",
                "--mapping",
                "bad.toml",
                "--out",
                "x",
            ],
            "unknown field `colum`",
        ),
    ] {
        let o = run_in(&dir, &args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{args:?} succeeded");
        assert!(err.contains(want), "{args:?}: {err}");
    }
    assert!(
        !dir.join("x").exists(),
        "nothing may be written for a bad log"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// The loaded mining truck without damper at 20 km/h (its onset: 23.51 km/h), the trace at
/// 1 kHz.
const TRUCK_SCENARIO: &str = r#"
name = "analyze-truck-log"
duration_s = 60.0
seed = 5
[plant]
vehicle = "truck-full"
[controller]
kind = "no-damper"
[speed]
constant_kmh = 20.0
[road_noise]
std_nm = 40.0
corner_hz = 20.0
common = 0.5
[imbalance]
amplitude_nm = 8.0
phase_deg = [0.0, 60.0]
[output]
trace_every = 1
"#;

/// A truck's log read as the truck (`--vehicle truck-full`: the meter slowed to its ~3 Hz
/// shimmy) gives the truck's shimmy damping; read as the car (the car's meter, band and wheel)
/// it gives a worse one: the vehicle of `analyze` is not decoration.
#[test]
fn a_truck_log_is_read_with_the_trucks_meter() {
    use shimmy_core::stability::{mode_at, ModeSelect};
    use shimmy_core::units::kmh_to_mps;
    use shimmy_core::vehicle::Vehicle;
    use shimmy_core::vehicles::truck::TruckSet;
    use shimmy_sim::model::family::SimModel;
    use shimmy_sim::sim::input::vehicle_file::{self, ModelVehicle};

    let dir = temp_dir("analyze-truck");
    let Ok(spec) = scenario_file::parse_any_in(TRUCK_SCENARIO, "analyze-truck-log", &dir)
        .unwrap()
        .into_spec::<shimmy_core::vehicles::truck::TruckParams, { shimmy_core::vehicles::truck::N_STATES }>()
    else {
        panic!("not a truck scenario");
    };
    let (_, r) = scenario::run(&spec).unwrap();
    let trace = dir.join("trace.csv");
    r.write_trace_csv(&trace).unwrap();
    let log = log_file::load(&trace, &LogMapping::default()).unwrap();
    let truth = mode_at(
        &TruckSet::Full.params().linear(),
        kmh_to_mps(20.0),
        0.0,
        ModeSelect::Shimmy,
    )
    .unwrap();
    let read_as = |vehicle: ModelVehicle| {
        analyze(
            &log.samples,
            &AnalyzeOptions {
                vehicle,
                model: false,
                ..AnalyzeOptions::default()
            },
        )
        .unwrap()
    };
    let truck = read_as(vehicle_file::load_model("truck-full").unwrap());
    let (zeta, f_hz) = settled(&truck, 30.0);
    println!(
        "truth zeta {:.4} at {:.2} Hz; as the truck {zeta:.4} at {f_hz:.2} Hz",
        truth.zeta, truth.freq_hz
    );
    assert!((f_hz - truth.freq_hz).abs() < 0.2, "{f_hz} Hz");
    assert!((zeta - truth.zeta).abs() < 0.02, "zeta {zeta}");

    let car = read_as(ModelVehicle::Car(Vehicle::nominal()));
    let valid: Vec<_> = car
        .rows
        .iter()
        .filter(|x| x.slow_valid && x.t_s >= 30.0)
        .collect();
    let car_f = median(valid.iter().map(|x| x.freq_slow_hz).collect());
    let car_zeta = median(valid.iter().map(|x| x.zeta_slow).collect());
    println!(
        "as the car {car_zeta:.4} at {car_f:.2} Hz ({} valid rows)",
        valid.len()
    );
    // Read as the car, the same log gives another (here: a worse) estimate: analyze uses
    // the vehicle it is given (the mode, sharp at 20 km/h, lies at the car meter's band edge).
    assert!(valid.len() > 100);
    assert!(
        (car_zeta - truth.zeta).abs() > (zeta - truth.zeta).abs(),
        "the car's meter read the truck's mode as well as the truck's: {car_zeta} vs {zeta}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// A model whose meter reads other signals than two wheel yaw angles is refused by name.
#[test]
fn analyze_refuses_a_model_its_log_cannot_feed() {
    use shimmy_sim::sim::input::vehicle_file;
    let log = [];
    let e = analyze(
        &log,
        &AnalyzeOptions {
            vehicle: vehicle_file::load_model("dual-axle").unwrap(),
            ..AnalyzeOptions::default()
        },
    )
    .unwrap_err();
    assert!(format!("{e:#}").contains("dual-axle-truck-8dof"), "{e:#}");
}

/// Logs the meter can estimate nothing in: the command says why (the meter's own status on its
/// steps, or the missing yaw), in its error, the report and `summary.json`, and fails, instead
/// of reporting "no warning" as if the log were normal.
#[test]
fn a_log_with_no_estimable_stretch_fails_naming_the_reason() {
    let dir = temp_dir("analyze-nothing");
    let mut rng = Lcg(5);
    // A car standing still (speed 0, a little yaw noise), 10 s at 400 Hz.
    let mut still = String::from("time_ms;steer_deg;v_kmh;note\n");
    for j in 0..(10.0 * 400.0) as usize {
        let _ = writeln!(still, "{};{};0;x", j as f64 * 2.5, 0.01 * rng.next());
    }
    // Shimmy at 6 Hz and 40 km/h, but 0.3 s of it.
    let mut short = String::from("time_ms;steer_deg;v_kmh;note\n");
    for j in 0..(0.3 * 400.0) as usize {
        let t = j as f64 * 2.5e-3;
        let y = 0.5 * (std::f64::consts::TAU * 6.0 * t).sin() + 0.01 * rng.next();
        let _ = writeln!(short, "{};{y};40;x", j as f64 * 2.5);
    }
    // 3 s at 40 km/h with every yaw cell empty.
    let mut no_yaw = String::from("time_ms;steer_deg;v_kmh;note\n");
    for j in 0..(3.0 * 400.0) as usize {
        let _ = writeln!(no_yaw, "{};;40;x", j as f64 * 2.5);
    }
    std::fs::write(dir.join("m.toml"), FOREIGN_MAPPING).unwrap();
    for (name, log, reason, evidence) in [
        (
            "still",
            still,
            "no usable samples: too little wheel yaw in the shimmy band",
            "frozen (too little excitation) ",
        ),
        (
            "short",
            short,
            "too short: the mode meter was still warming up",
            "over 0.3 s: warming up",
        ),
        (
            "no-yaw",
            no_yaw,
            "no usable yaw sample",
            "samples at 1 kHz lack the wheel yaw",
        ),
    ] {
        std::fs::write(dir.join(format!("{name}.csv")), log).unwrap();
        let file = format!("{name}.csv");
        let o = run_in(
            &dir,
            &[
                "analyze",
                &file,
                "--mapping",
                "m.toml",
                "--data-only",
                "--out",
                name,
            ],
        );
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(
            !o.status.success(),
            "{name}: exit 0 on a log with nothing estimable: {}{err}",
            String::from_utf8_lossy(&o.stdout)
        );
        assert!(
            err.contains(&file)
                && err.contains("could not be judged")
                && err.contains(reason)
                && err.contains(evidence),
            "{name}: {err}"
        );
        let md = std::fs::read_to_string(dir.join(name).join("report.md")).unwrap();
        assert!(
            md.contains("| verdict | **not judged**: ") && md.contains(reason),
            "{name}: {md}"
        );
        let json: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(dir.join(name).join("summary.json")).unwrap(),
        )
        .unwrap();
        let why = json["metrics"]["not_judged"].as_str().unwrap_or_default();
        assert!(why.contains(reason), "{name}: {json}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}
