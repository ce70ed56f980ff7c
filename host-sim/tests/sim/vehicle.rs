//! Vehicle files on the built binary (`docs/vehicle-file.md`): bad files are rejected with a
//! message naming the field (and nothing runs), and one field changed in a vehicle file changes
//! the result of every command that takes `--vehicle` (each command's output with the reference
//! vehicle and with the changed file differ). The runs are kept tiny (one speed, a few seconds).

use std::path::{Path, PathBuf};

use crate::common;

use common::run_in;

/// A fresh, empty working directory for one test.
fn temp_dir() -> PathBuf {
    common::temp_dir("vehicle")
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

/// `params FILE` with `content` in FILE fails and names every one of `expect`.
fn bad_file(content: &str, expect: &[&str]) {
    let dir = temp_dir();
    std::fs::write(dir.join("v.toml"), content).expect("write");
    let o = run_in(&dir, &["params", "v.toml"]);
    let err = text(&o.stderr);
    assert!(
        !o.status.success(),
        "{content:?} accepted: {}",
        text(&o.stdout)
    );
    for e in expect {
        assert!(err.contains(e), "{content:?}: `{e}` not in: {err}");
    }
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn bad_vehicle_files_are_rejected_naming_the_field() {
    bad_file("", &["empty vehicle file", "`base`"]);
    bad_file("# only a comment\n", &["empty vehicle file"]);
    bad_file(
        "[plant]\nmu = 1000.0\n",
        &["`plant.mu` = 1000", "0.05 <= value <= 1.5"],
    );
    bad_file(
        "[plant]\nf_z = 1e12\n",
        &["`plant.f_z` = 1000000000000", "100000 N"],
    );
    bad_file(
        "[plant]\nmud = 0.8\n",
        &["`plant.mud`", "no such field", "mu"],
    );
    bad_file(
        "[plant]\nk_d = \"stiff\"\n",
        &["`plant.k_d`", "expected a number"],
    );
    bad_file(
        "[plant]\nk_d = nan\n",
        &["`plant.k_d` = NaN", "out of range"],
    );
    bad_file("[overrides]\ni_k = -4.54\n", &["`overrides.i_k` = -4.54"]);
    bad_file("[tyres]\nc_a = 1.0\n", &["`tyres`", "no such section"]);
    bad_file("plant = 3\n", &["`plant`", "expected a section"]);
    bad_file("base = \"truck\"\n", &["`base`", "unknown set `truck`"]);
    bad_file("base = 3\n", &["`base`", "expected a set name"]);
    bad_file(
        "[sensors]\nencoder_bits = 12.5\n",
        &["`sensors.encoder_bits` = 12.5", "whole number"],
    );
    bad_file(
        "[damper]\nrated_current_a = 0.0\n",
        &["`damper.rated_current_a` = 0"],
    );
    bad_file(
        "[thresholds]\ndv_low_off_mps = 1.0\n",
        &["`thresholds.dv_low_off_mps` = 1", "dv_low_on_mps"],
    );
    bad_file(
        "[controller]\nk_init_radps2 = 40.0\n",
        &["`controller.k_init_radps2` = 40", "k_max_radps2"],
    );
    bad_file(
        "[plant]\nk_d = 5000.0\n[overrides]\nk_d = 6000.0\n",
        &["`overrides`", "only one"],
    );
    bad_file("[plant\nk_d = 1.0\n", &["v.toml"]);
}

#[test]
fn a_missing_file_says_no_such_file_before_anything_runs() {
    let dir = temp_dir();
    for args in [
        &["params", "missing.toml"][..],
        &["stability", "--vehicle", "missing.toml", "--out", "o"],
        &["margin", "--model-vehicle", "missing.toml", "--out", "o"],
        &[
            "compare",
            "--quick",
            "--vehicle",
            "missing.toml",
            "--out",
            "o",
        ],
        &["faults", "--vehicle", "missing.toml", "--out", "o"],
    ] {
        let o = run_in(&dir, args);
        let err = text(&o.stderr);
        assert!(!o.status.success(), "{args:?}");
        assert!(
            err.contains("missing.toml") && err.contains("no such file"),
            "{args:?}: {err}"
        );
        assert!(!err.contains("unknown parameter set"), "{err}");
    }
    let left: Vec<_> = std::fs::read_dir(&dir).unwrap().collect();
    assert!(left.is_empty(), "something was written before the error");
    std::fs::remove_dir_all(&dir).ok();
}

/// `csv` without its wall-clock columns (`wall_s`, `sim_per_wall`), which differ from run to run.
fn without_timing(csv: &str) -> String {
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap_or("").split(',').collect();
    let keep: Vec<bool> = header
        .iter()
        .map(|h| *h != "wall_s" && *h != "sim_per_wall")
        .collect();
    std::iter::once(header.join(","))
        .chain(lines.map(|l| {
            l.split(',')
                .zip(&keep)
                .filter(|(_, &k)| k)
                .map(|(x, _)| x)
                .collect::<Vec<_>>()
                .join(",")
        }))
        .collect::<Vec<_>>()
        .join("\n")
}

/// Runs `args` (plus `--vehicle`/`--model-vehicle` as `extra`) in a fresh folder and returns
/// the concatenated text of the output files `files` (relative to the folder; CSV files
/// [`without_timing`]). `faults` exits
/// non-zero when one of its campaign checks fails (a 2 s run is too short for some), but its
/// files are written either way; every other command must succeed.
fn output_of(setup: &dyn Fn(&Path), args: &[&str], extra: &[&str], files: &[&str]) -> String {
    let dir = temp_dir();
    setup(&dir);
    let all: Vec<&str> = args.iter().chain(extra).copied().collect();
    let o = run_in(&dir, &all);
    assert!(
        o.status.success() || all.first() == Some(&"faults"),
        "{all:?} failed: {}",
        text(&o.stderr)
    );
    let out = files
        .iter()
        .map(|f| {
            let t = std::fs::read_to_string(dir.join(f))
                .unwrap_or_else(|e| panic!("{all:?}: reading {f}: {e}"));
            if f.ends_with(".csv") {
                without_timing(&t)
            } else {
                t
            }
        })
        .collect::<Vec<_>>()
        .join("\n");
    std::fs::remove_dir_all(&dir).ok();
    out
}

/// A plant field (drag-link stiffness), a damper field and controller gains, each in its own
/// file, plus two scenarios inside the Hopf window, one naming `../gains.toml` relative to itself.
fn files(dir: &Path) {
    std::fs::write(dir.join("plant.toml"), "[plant]\nk_d = 8000.0\n").unwrap();
    std::fs::write(dir.join("damper.toml"), "[damper]\nc1a = 5000.0\n").unwrap();
    std::fs::write(
        dir.join("gains.toml"),
        "[controller]\nlambda_per_s = 3.0\ngamma = 100.0\n",
    )
    .unwrap();
    std::fs::create_dir_all(dir.join("sc")).unwrap();
    std::fs::write(
        dir.join("sc/kick.toml"),
        "duration_s = 2.0\n[plant]\nvehicle = \"../gains.toml\"\n[controller]\nkind = \"asmc\"\n\
         [speed]\nconstant_kmh = 45.0\n[initial]\nyaw_deg = 3.0\n",
    )
    .unwrap();
    std::fs::write(
        dir.join("sc/kick-nominal.toml"),
        "duration_s = 2.0\n[controller]\nkind = \"asmc\"\n[speed]\nconstant_kmh = 45.0\n\
         [initial]\nyaw_deg = 3.0\n",
    )
    .unwrap();
}

/// `args` with `--vehicle FILE` (or the given extra options) gives another result than with
/// the reference vehicle. The reference is run twice and must be the same both times, so a
/// difference is the vehicle's doing, not the clock's.
fn changes(args: &[&str], extra: &[&str], out: &[&str]) {
    let reference = output_of(&files, args, &[], out);
    let again = output_of(&files, args, &[], out);
    assert!(reference == again, "{args:?}: not reproducible");
    let changed = output_of(&files, args, extra, out);
    assert!(reference != changed, "{args:?} {extra:?}: same result");
}

#[test]
fn a_field_in_the_vehicle_file_changes_every_commands_result() {
    changes(
        &[
            "stability",
            "--v-min-kmh",
            "20",
            "--v-max-kmh",
            "40",
            "--out",
            "o",
        ],
        &["--vehicle", "plant.toml"],
        &["o/stability.csv", "o/crossings.csv"],
    );
    // The damper's Spencer model enters through its equivalent viscous coefficient.
    changes(
        &[
            "stability",
            "--v-min-kmh",
            "20",
            "--v-max-kmh",
            "40",
            "--damper-current-a",
            "0",
            "--out",
            "o",
        ],
        &["--vehicle", "damper.toml"],
        &["o/stability.csv"],
    );
    changes(
        &[
            "bifurcation",
            "--v-min-kmh",
            "45",
            "--v-max-kmh",
            "45",
            "--duration-s",
            "1",
            "--window-s",
            "0.25",
            "--damper-current-a",
            "0",
            "--out",
            "o",
        ],
        &["--vehicle", "damper.toml"],
        &["o/bifurcation.csv"],
    );
    changes(
        &[
            "sweep",
            "--v-steps",
            "3",
            "--factor-steps",
            "2",
            "--v-min-kmh",
            "20",
            "--v-max-kmh",
            "40",
            "--quiet",
            "--out",
            "o",
        ],
        &["--vehicle", "plant.toml"],
        &["o/sweep-k_d-no-damper.csv"],
    );
    changes(
        &[
            "compare",
            "--quick",
            "--only",
            "kick-0.5deg",
            "--controllers",
            "asmc",
            "--on-current-a",
            "1",
            "--out",
            "o",
        ],
        &["--vehicle", "gains.toml"],
        &["o/compare.csv"],
    );
    changes(
        &[
            "compare",
            "--quick",
            "--only",
            "kick-0.5deg",
            "--controllers",
            "asmc",
            "--on-current-a",
            "1",
            "--out",
            "o",
        ],
        &["--model-vehicle", "gains.toml"],
        &["o/compare.csv"],
    );
    // The scenario names `../gains.toml` relative to itself; `--vehicle` overrides it.
    changes(
        &["run", "sc/kick.toml", "--out", "o"],
        &["--vehicle", "nominal"],
        &["o/trace.csv"],
    );
    changes(
        &["run", "sc/kick-nominal.toml", "--out", "o"],
        &["--model-vehicle", "gains.toml"],
        &["o/trace.csv"],
    );
    changes(
        &[
            "margin",
            "--constant-kmh",
            "26",
            "--duration-s",
            "3",
            "--out",
            "o",
        ],
        &["--vehicle", "plant.toml"],
        &["o/margin.csv"],
    );
    // The pipeline's model is the model vehicle's plant (the simulated plant stays).
    changes(
        &[
            "margin",
            "--constant-kmh",
            "26",
            "--duration-s",
            "3",
            "--out",
            "o",
        ],
        &["--model-vehicle", "plant.toml"],
        &["o/margin.csv"],
    );
    changes(
        &[
            "faults",
            "--only",
            "noise-left 0.05",
            "--speeds-kmh",
            "45",
            "--duration-s",
            "2",
            "--out",
            "o",
        ],
        &["--vehicle", "gains.toml"],
        &["o/faults.csv"],
    );
    changes(
        &["report", "sc/kick-nominal.toml", "--out", "o"],
        &["--vehicle", "damper.toml"],
        &["o/metrics.csv"],
    );
    // The demo (no command) on another plant, and with a firmware believing other gains.
    let demo_trace = "out/demo/ramp_20-120_km_h_ASMC.csv";
    changes(
        &["--ramp-s", "3"],
        &["--vehicle", "plant.toml"],
        &[demo_trace],
    );
    changes(
        &["--ramp-s", "3"],
        &["--model-vehicle", "gains.toml"],
        &[demo_trace],
    );
}

/// Every coil current a command or a scenario file asks for is checked against the coil rating
/// of the vehicle in question (`damper.rated_current_a`), not the reference coil's 2 A: with a
/// 1.5 A coil, 1.8 A is rejected by each command before anything runs (nothing written); with
/// a 3 A coil, 2.5 A is accepted and reaches the damper.
#[test]
fn currents_are_checked_against_the_vehicles_own_coil_rating() {
    let setup = |dir: &Path| {
        std::fs::write(dir.join("small.toml"), "[damper]\nrated_current_a = 1.5\n").unwrap();
        std::fs::write(dir.join("big.toml"), "[damper]\nrated_current_a = 3.0\n").unwrap();
        for (name, vehicle, current) in [
            ("small", "small.toml", 1.8),
            ("big", "big.toml", 2.5),
            ("nominal", "nominal", 1.8),
        ] {
            std::fs::write(
                dir.join(format!("on-{name}.toml")),
                format!(
                    "duration_s = 1.0\n[plant]\nvehicle = \"{vehicle}\"\n[controller]\n\
                     kind = \"passive-on\"\non_current_a = {current}\n[speed]\nconstant_kmh = 45.0\n"
                ),
            )
            .unwrap();
        }
        std::fs::write(
            dir.join("asmc.toml"),
            "duration_s = 1.0\n[speed]\nconstant_kmh = 45.0\n",
        )
        .unwrap();
    };
    let sweep_td = [
        "sweep",
        "--controllers",
        "passive-on",
        "--v-steps",
        "2",
        "--factor-steps",
        "1",
        "--duration-s",
        "1",
        "--quiet",
    ];
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (
            vec![
                "stability",
                "--v-min-kmh",
                "40",
                "--v-max-kmh",
                "50",
                "--damper-current-a",
            ],
            "--vehicle",
        ),
        (
            vec![
                "bifurcation",
                "--v-min-kmh",
                "45",
                "--v-max-kmh",
                "45",
                "--duration-s",
                "1",
                "--window-s",
                "0.25",
                "--damper-current-a",
            ],
            "--vehicle",
        ),
        (
            vec![
                "sweep",
                "--v-steps",
                "2",
                "--factor-steps",
                "1",
                "--quiet",
                "--damper-current-a",
            ],
            "--vehicle",
        ),
        (
            sweep_td.iter().copied().chain(["--on-current-a"]).collect(),
            "--vehicle",
        ),
        (
            vec![
                "compare",
                "--quick",
                "--only",
                "kick-0.5deg",
                "--controllers",
                "passive-on",
                "--on-current-a",
            ],
            "--model-vehicle",
        ),
        (
            vec![
                "run",
                "asmc.toml",
                "--controller",
                "passive-on",
                "--on-current-a",
            ],
            "--model-vehicle",
        ),
        (
            vec![
                "report",
                "asmc.toml",
                "--controllers",
                "passive-on",
                "--on-current-a",
            ],
            "--model-vehicle",
        ),
        (vec!["reference-bench", "--damper-current-a"], "--vehicle"),
    ];
    let dir = temp_dir();
    setup(&dir);
    let reject = |args: &[&str]| {
        let all: Vec<&str> = args.iter().copied().chain(["--out", "o"]).collect();
        let o = run_in(&dir, &all);
        let err = text(&o.stderr);
        assert!(!o.status.success(), "{all:?} accepted");
        assert!(
            err.contains("1.8") && err.contains("0 <= value <= 1.5 A"),
            "{all:?}: {err}"
        );
        assert!(!dir.join("o").exists(), "{all:?} wrote output");
    };
    for (args, vehicle_option) in &cases {
        let mut a = args.clone();
        a.extend(["1.8", vehicle_option, "small.toml"]);
        reject(&a);
    }
    // Scenario files: the file's own vehicle, and `--model-vehicle` overriding it.
    reject(&["run", "on-small.toml"]);
    reject(&["report", "on-small.toml"]);
    reject(&["run", "on-nominal.toml", "--model-vehicle", "small.toml"]);
    reject(&["report", "on-nominal.toml", "--model-vehicle", "small.toml"]);

    // The 3 A coil takes 2.5 A (reference-bench needs SciPy: its rejection above suffices).
    let accept = |args: &[&str]| -> String {
        let all: Vec<&str> = args.iter().copied().chain(["--out", "o"]).collect();
        let o = run_in(&dir, &all);
        assert!(o.status.success(), "{all:?} failed: {}", text(&o.stderr));
        std::fs::remove_dir_all(dir.join("o")).ok();
        text(&o.stdout)
    };
    for (args, vehicle_option) in cases.iter().filter(|(a, _)| a[0] != "reference-bench") {
        let mut a = args.clone();
        a.extend(["2.5", vehicle_option, "big.toml"]);
        accept(&a);
    }
    accept(&["report", "on-big.toml"]);
    // The run's coil reaches the commanded 2.5 A (the 2 A coil would stop at 2 A).
    let out = accept(&["run", "on-big.toml"]);
    let peak: f64 = out
        .lines()
        .find(|l| l.contains("RMS / peak current"))
        .and_then(|l| l.split('/').nth(2))
        .and_then(|x| x.trim().trim_end_matches('A').trim().parse().ok())
        .unwrap_or_else(|| panic!("no peak current in: {out}"));
    assert!((peak - 2.5).abs() < 0.05, "peak current {peak} A");
    std::fs::remove_dir_all(&dir).ok();
}
