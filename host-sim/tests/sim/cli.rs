//! The command line's contract, on the built binary: a bad numeric option is rejected before
//! any work starts (non-zero exit, a message naming the option and its allowed range, nothing
//! written), and `faults` exits non-zero when `--only` matches no case or a campaign check
//! fails. Every run here is either rejected at once or a one-case, one-speed campaign (or a
//! 1 s margin run), so the file takes well under a second.

use std::path::PathBuf;
use std::process::Output;

use crate::common;

use common::run_in;

/// A fresh, empty working directory for one test.
fn temp_dir() -> PathBuf {
    common::temp_dir("cli")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// `args` fails, its message contains every one of `expect`, and nothing was written.
fn rejected(args: &[&str], expect: &[&str]) {
    let dir = temp_dir();
    let o = run_in(&dir, args);
    let err = stderr(&o);
    assert!(!o.status.success(), "{args:?} exited 0; stderr: {err}");
    for e in expect {
        assert!(err.contains(e), "{args:?}: `{e}` not in the message: {err}");
    }
    let left: Vec<_> = std::fs::read_dir(&dir)
        .expect("read temp dir")
        .map(|e| e.expect("entry").path())
        .collect();
    assert!(left.is_empty(), "{args:?} wrote {left:?} before failing");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn faults_rejects_bad_numbers_before_running() {
    let dur = "1 <= value <= 600 s";
    let speed = "1 <= value <= 250 km/h";
    rejected(
        &["faults", "--duration-s", "0"],
        &["--duration-s", "'0'", dur],
    );
    rejected(
        &["faults", "--duration-s", "1e9"],
        &["--duration-s", "'1e9'", dur],
    );
    rejected(&["faults", "--duration-s", "NaN"], &["--duration-s", dur]);
    rejected(
        &["faults", "--duration-s", "-5"],
        &["--duration-s", "'-5'", dur],
    );
    rejected(
        &["faults", "--speeds-kmh", "45,1e9"],
        &["--speeds-kmh", "'1e9'", speed],
    );
    rejected(&["faults", "--speeds-kmh", "0"], &["--speeds-kmh", speed]);
    rejected(&["faults", "--speeds-kmh", "inf"], &["--speeds-kmh", speed]);
    let many = vec!["45"; 33].join(",");
    rejected(
        &["faults", "--speeds-kmh", &many],
        &["--speeds-kmh", "33", "1 to 32"],
    );
}

#[test]
fn faults_only_without_a_match_fails_and_lists_the_cases() {
    rejected(
        &["faults", "--only", "nonexistent", "--speeds-kmh", "45"],
        &["--only", "nonexistent", "healthy", "nan-left"],
    );
}

/// A failing check, provoked legitimately: `--duration-s 1` ends every run at the fault time
/// (1.0 s), so the injected NaN can never be detected and the campaign's "every injected fault
/// detected" check fails. The table and files are still written (the results are kept); the
/// exit status and the message report the failed checks.
#[test]
fn faults_exits_non_zero_when_a_check_fails() {
    let dir = temp_dir();
    let o = run_in(
        &dir,
        &[
            "faults",
            "--only",
            "nan-left",
            "--speeds-kmh",
            "45",
            "--duration-s",
            "1",
        ],
    );
    let err = stderr(&o);
    assert!(!o.status.success(), "exited 0; stderr: {err}");
    assert!(err.contains("check(s) failed"), "{err}");
    assert!(err.contains("nan-left at 45 km/h: not detected"), "{err}");
    assert!(dir.join("out/faults/faults.csv").is_file(), "results kept");
    std::fs::remove_dir_all(&dir).ok();
}

/// The mapping from check results to the exit status, independent of the campaign.
#[test]
fn verdict_fails_exactly_when_a_check_failed() {
    use shimmy_sim::cmd::faults::verdict;
    assert!(verdict(&[]).is_ok());
    let e = verdict(&[
        "a at 45 km/h: not detected".into(),
        "b: 3 invalid commands".into(),
    ])
    .expect_err("two failed checks");
    let msg = e.to_string();
    assert!(msg.contains("2 fault-campaign check(s) failed"), "{msg}");
    assert!(msg.contains("a at 45 km/h: not detected") && msg.contains("b: 3 invalid"));
}

#[test]
fn faults_tiny_valid_run_exits_zero() {
    let dir = temp_dir();
    let o = run_in(
        &dir,
        &[
            "faults",
            "--only",
            "healthy",
            "--speeds-kmh",
            "45",
            "--duration-s",
            "1",
        ],
    );
    assert!(o.status.success(), "stderr: {}", stderr(&o));
    assert!(dir.join("out/faults/faults.csv").is_file());
    assert!(dir.join("out/faults/faults.md").is_file());
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn other_commands_reject_bad_numbers_before_running() {
    // Parsing allows up to the largest coil rating a vehicle file may give; the vehicle's own
    // rating (the nominal 2 A here) is checked once it is loaded (vehicle.rs here has more).
    let amps = "0 <= value <= 10 A";
    let rated = "0 <= value <= 2 A";
    let speed = "1 <= value <= 250 km/h";
    let cases: &[(&[&str], &[&str])] = &[
        (
            &["stability", "--damper-current-a", "-1"],
            &["--damper-current-a", "'-1'", amps],
        ),
        (
            &["stability", "--step-kmh", "0"],
            &["--step-kmh", "0.01 <= value <= 50 km/h"],
        ),
        (
            &["stability", "--v-max-kmh", "1e9"],
            &["--v-max-kmh", speed],
        ),
        (
            &["stability", "--ref-amplitude-deg", "0"],
            &["--ref-amplitude-deg", "0 < value <= 20 deg"],
        ),
        (
            &["stability", "--v-min-kmh", "50", "--v-max-kmh", "10"],
            &["--v-min-kmh 50", "--v-max-kmh 10"],
        ),
        (
            &["sensitivity", "--percent", "-20"],
            &["--percent", "0 < value <= 90 %"],
        ),
        (
            &["gas-charge", "--v0-max-l", "500"],
            &["--v0-max-l", "0.1 <= value <= 200 l"],
        ),
        (
            &["gas-charge", "--v0-min-l", "30", "--v0-max-l", "10"],
            &["--v0-min-l 30", "--v0-max-l 10"],
        ),
        (
            &["gas-charge", "--vehicle", "nominal"],
            &["--vehicle `nominal`", "mining-truck-5dof"],
        ),
        (
            &["sway-damping", "--zeta", "0.9"],
            &["--zeta", "0.001 <= value <= 0.5"],
        ),
        (
            &["sway-damping", "--v-min-kmh", "150", "--v-max-kmh", "100"],
            &["--v-min-kmh 150", "--v-max-kmh 100"],
        ),
        (
            &["sway-damping", "--vehicle", "nominal"],
            &["--vehicle `nominal`", "trailer-2dof"],
        ),
        (
            &[
                "margin",
                "--vehicle",
                "trailer",
                "--model-vehicle",
                "nominal",
            ],
            &["`nominal`", "trailer-2dof", "car-4dof"],
        ),
        (
            // the truck's damper has the car's coil: rated 2 A
            &[
                "stability",
                "--vehicle",
                "truck-full",
                "--damper-current-a",
                "2.5",
            ],
            &["--damper-current-a", rated],
        ),
        (
            &[
                "bifurcation",
                "--vehicle",
                "truck-full",
                "--damper-current-a",
                "2.5",
            ],
            &["--damper-current-a", rated],
        ),
        (
            &["bifurcation", "--damper-current-a", "NaN"],
            &["--damper-current-a", amps],
        ),
        (
            &[
                "bifurcation",
                "--vehicle",
                "dual-axle",
                "--friction-eps-radps",
                "0",
            ],
            &["--friction-eps-radps", "0 < value <= 1 rad/s"],
        ),
        (
            &["bifurcation", "--step-kmh", "0"],
            &["--step-kmh", "0.1 <= value <= 100 km/h"],
        ),
        (
            &["bifurcation", "--duration-s", "1e9"],
            &["--duration-s", "0 < value <= 600 s"],
        ),
        (
            &["bifurcation", "--duration-s", "4"],
            &["--duration-s 4", "--window-s 3"],
        ),
        (&["sweep", "--v-steps", "0"], &["--v-steps", "2..=1001"]),
        (
            &["sweep", "--factor-steps", "1000000"],
            &["--factor-steps", "1..=401"],
        ),
        (
            &["sweep", "--factor-min", "-1"],
            &["--factor-min", "0 < value <= 10"],
        ),
        (
            &["sweep", "--damper-current-a", "0.5,11"],
            &["--damper-current-a", "'11'", amps],
        ),
        (
            &["sweep", "--damper-current-a", "0.5,3"],
            &["--damper-current-a 3", rated],
        ),
        (
            &["sweep", "--on-current-a", "11"],
            &["--on-current-a", amps],
        ),
        (
            &[
                "sweep",
                "--controllers",
                "passive-on",
                "--on-current-a",
                "9",
            ],
            &["--on-current-a 9", rated],
        ),
        (
            &["sweep", "--kick-deg", "90"],
            &["--kick-deg", "-20 <= value <= 20 deg"],
        ),
        (
            &[
                "sweep",
                "--controllers",
                "asmc",
                "--v-steps",
                "1001",
                "--factor-steps",
                "401",
            ],
            &["closed-loop runs", "at most 20000"],
        ),
        (
            &["compare", "--on-current-a", "-0.1"],
            &["--on-current-a", amps],
        ),
        (
            &["compare", "--phi", "0"],
            &["--phi", "0 < value <= 100 rad/s"],
        ),
        (
            &["compare", "--gamma", "NaN"],
            &["--gamma", "0 <= value <= 100000"],
        ),
        (
            &["run", "x.toml", "--on-current-a", "11"],
            &["--on-current-a", amps],
        ),
        (
            &["report", "--on-current-a", "inf"],
            &["--on-current-a", amps],
        ),
        (
            &["margin", "--rate-kmh-per-s", "0"],
            &["--rate-kmh-per-s", "0.01 <= value <= 50 km/h/s"],
        ),
        (
            &["margin", "--constant-kmh", "1e9"],
            &["--constant-kmh", speed],
        ),
        (
            &["margin", "--noise-nm", "-1"],
            &["--noise-nm", "0 <= value <= 200 N m"],
        ),
        (
            &["margin", "--duration-s", "0"],
            &["--duration-s", "0 < value <= 3600 s"],
        ),
        (
            &[
                "margin",
                "--settle-s",
                "600",
                "--ramp-to-kmh",
                "250",
                "--rate-kmh-per-s",
                "0.01",
            ],
            &["--settle-s", "0 < value <= 3600 s"],
        ),
        (
            &["reference-bench", "--damper-current-a", "-1"],
            &["--damper-current-a", amps],
        ),
        (
            &["reference-bench", "--sweep-points", "0"],
            &["--sweep-points", "2..=100000"],
        ),
        (
            &["reference-bench", "--speed-kmh", "1e9"],
            &["--speed-kmh", speed],
        ),
        (
            &["reference-bench", "--cl-ramp-s", "0"],
            &["--cl-ramp-s", "1 <= value <= 600 s"],
        ),
    ];
    for (args, expect) in cases {
        rejected(args, expect);
    }
}

/// `margin`'s `summary.json` says where it comes from: the command line, the vehicle file's
/// and the resolved vehicle's hashes, and the road-noise seed.
#[test]
fn margin_summary_carries_the_provenance() {
    let dir = temp_dir();
    std::fs::write(
        dir.join("v.toml"),
        "base = \"nominal\"\n[plant]\nk_d = 9000.0\n",
    )
    .expect("write vehicle");
    let args = [
        "margin",
        "--vehicle",
        "v.toml",
        "--constant-kmh",
        "20",
        "--duration-s",
        "1",
        "--seed",
        "5",
        "--out",
        "m",
    ];
    let o = run_in(&dir, &args);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = std::fs::read_to_string(dir.join("m/summary.json")).expect("summary.json");
    let json: serde_json::Value = serde_json::from_str(&text).expect("JSON");
    let prov = &json["provenance"];
    assert_eq!(prov["git"], shimmy_sim::out::provenance::GIT);
    assert!(
        prov["command_line"]
            .as_str()
            .is_some_and(|c| c.ends_with(&args.join(" "))),
        "{prov}"
    );
    let file_hash = shimmy_sim::out::provenance::sha256_hex(
        &std::fs::read(dir.join("v.toml")).expect("read vehicle"),
    );
    assert_eq!(prov["inputs"][0]["role"], "vehicle file");
    assert_eq!(prov["inputs"][0]["sha256"], file_hash.as_str());
    assert_eq!(prov["inputs"][1]["role"], "vehicle record");
    assert_eq!(prov["seeds"][0]["seed"], 5);
    // The metrics stay where scripts read them.
    assert_eq!(json["duration_s"], 1.0);
    std::fs::remove_dir_all(&dir).ok();
}

/// `gas-charge` exits non-zero when no charge in the range keeps the truck free of shimmy (the
/// full truck at 30 km/h needs more than 5 l), with its table and files still written, and zero
/// with the least charge when one does.
#[test]
fn gas_charge_fails_without_a_stable_charge_and_answers_with_one() {
    let dir = temp_dir();
    let o = run_in(
        &dir,
        &[
            "gas-charge",
            "--v0-min-l",
            "1",
            "--v0-max-l",
            "5",
            "--map-v-max-kmh",
            "3",
            "--out",
            "o",
        ],
    );
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("no initial gas volume in 1 .. 5 l"),
        "{}",
        stderr(&o)
    );
    assert!(dir.join("o/gas-charge.csv").is_file() && dir.join("o/hopf-map.png").is_file());
    let o = run_in(
        &dir,
        &[
            "gas-charge",
            "--v0-min-l",
            "30",
            "--v0-max-l",
            "45",
            "--step-l",
            "5",
            "--map-v-max-kmh",
            "3",
            "--out",
            "o",
        ],
    );
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(out.contains("least gas charge: 37.2"), "{out}");
    std::fs::remove_dir_all(&dir).ok();
}

/// A truck vehicle on a command that runs the car only is rejected before anything runs,
/// naming both models and the commands that take the truck; the same vehicle runs through a
/// command of the family (`params`).
#[test]
fn a_truck_on_a_car_only_command_is_rejected_naming_the_models() {
    rejected(
        &["reference-bench", "--vehicle", "truck-full"],
        &[
            "mining-truck-5dof",
            "car-4dof",
            "compare, analyze, device, pil and the demo",
        ],
    );
    let dir = temp_dir();
    let o = run_in(&dir, &["params", "truck-full"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        out.contains("[truck]") && out.contains("[damper]") && !out.contains("[plant]"),
        "{out}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// `identifiability` rejects bad values and a model without updatable parameters before it
/// writes anything; on the car it writes its tables, and the data separate the steering
/// linkage stiffness (k_d) at once while the onset's sigma shrinks as the evidence nears the
/// onset (the study's finding, not its construction: a wrong Jacobian or noise model moves
/// both).
#[test]
fn identifiability_rejects_bad_input_and_separates_the_linkage_stiffness() {
    rejected(
        &["identifiability", "--sigma-zeta", "0"],
        &["--sigma-zeta", "0.001 <= value <= 0.1"],
    );
    rejected(
        &["identifiability", "--speeds", "1"],
        &["--speeds", "2..=50"],
    );
    rejected(
        &["identifiability", "--vehicle", "trailer"],
        &["trailer-2dof", "car, truck"],
    );
    let dir = temp_dir();
    let o = run_in(
        &dir,
        &["identifiability", "--sigma-zeta", "0.01", "--out", "o"],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let csv = std::fs::read_to_string(dir.join("o/identifiability.csv")).expect("csv");
    assert!(dir.join("o/identifiability.md").is_file());
    let rows: Vec<(f64, String, f64, f64)> = csv
        .lines()
        .skip(1)
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            (
                f[1].parse().expect("speed"),
                f[2].to_string(),
                f[3].parse().expect("sigma"),
                f[4].parse().expect("onset sigma"),
            )
        })
        .collect();
    let kd: Vec<f64> = rows.iter().filter(|r| r.1 == "k_d").map(|r| r.2).collect();
    let onset: Vec<f64> = rows.iter().filter(|r| r.1 == "k_d").map(|r| r.3).collect();
    assert!(
        kd.len() == 6 && kd.iter().all(|&s| s < 0.5 * 0.15),
        "{kd:?}"
    );
    assert!(
        onset.windows(2).all(|w| w[1] < w[0]) && onset[5] < 0.7 * onset[0],
        "{onset:?}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// `margin --model-update` on the `hard` plant (K_d x0.5) with the nominal model: the warning
/// comes before the onset and the diagnosis names the steering linkage stiffness, about half
/// the file's, in the terminal and in `summary.json`; without the flag neither key is written
/// (the negative arm: the nominal model alone warns after this plant's onset).
#[test]
fn margin_with_model_update_diagnoses_the_soft_linkage() {
    let dir = temp_dir();
    let args = |update: bool| {
        let mut v = vec![
            "margin",
            "--vehicle",
            "hard",
            "--model-vehicle",
            "nominal",
            "--ramp-from-kmh",
            "4.6",
            "--ramp-to-kmh",
            "10",
            "--out",
        ];
        v.push(if update { "u" } else { "o" });
        if update {
            v.push("--model-update");
        }
        v
    };
    let o = run_in(&dir, &args(true));
    assert!(o.status.success(), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        out.contains("diagnosis: steering linkage stiffness (k_d) 5"),
        "{out}"
    );
    let json: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.join("u/summary.json")).expect("summary"),
    )
    .expect("json");
    assert!(json["lead_kmh"].as_f64().is_some_and(|l| l > 0.0), "{json}");
    let kd = json["updated"]
        .as_array()
        .and_then(|a| a.iter().find(|u| u["field"] == "k_d"))
        .and_then(|u| u["factor"].as_f64())
        .expect("k_d");
    assert!((kd - 0.5).abs() < 0.05, "{kd}");
    let o = run_in(&dir, &args(false));
    assert!(o.status.success(), "{}", stderr(&o));
    let json: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.join("o/summary.json")).expect("summary"),
    )
    .expect("json");
    assert!(json.get("updated").is_none() && json.get("diagnosis").is_none());
    assert!(json["lead_kmh"].as_f64().is_none_or(|l| l < 0.0), "{json}");
    std::fs::remove_dir_all(&dir).ok();
}
