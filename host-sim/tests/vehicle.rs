//! Vehicle files on the built binary (`docs/vehicle-file.md`): bad files are rejected with a
//! message naming the field (and nothing runs), and one field changed in a vehicle file changes
//! the result of every command that takes `--vehicle` (each command's output with the reference
//! vehicle and with the changed file differ). The runs are kept tiny (one speed, a few seconds).

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::atomic::{AtomicUsize, Ordering};

/// A fresh, empty working directory under the system's temp folder.
fn temp_dir() -> PathBuf {
    static N: AtomicUsize = AtomicUsize::new(0);
    let d = std::env::temp_dir().join(format!(
        "shimmy-vehicle-{}-{}",
        std::process::id(),
        N.fetch_add(1, Ordering::Relaxed)
    ));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).expect("temp dir");
    d
}

fn run_in(dir: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_shimmy-sim"))
        .args(args)
        .current_dir(dir)
        .env("RUST_BACKTRACE", "0")
        .output()
        .expect("run shimmy-sim")
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

/// Runs `args` (plus `--vehicle`/`--model-vehicle` as `extra`) in a fresh folder and returns
/// the concatenated text of the output files `files` (relative to the folder). `faults` exits
/// non-zero when one of its campaign checks fails (a 2 s run is too short for some), but its
/// files are written either way; every other command must succeed.
fn output_of(setup: &dyn Fn(&Path), args: &[&str], extra: &[&str], files: &[&str]) -> String {
    let dir = temp_dir();
    setup(&dir);
    let all: Vec<&str> = args.iter().chain(extra).copied().collect();
    let o = run_in(&dir, &all);
    assert!(
        o.status.success() || all[0] == "faults",
        "{all:?} failed: {}",
        text(&o.stderr)
    );
    let out = files
        .iter()
        .map(|f| {
            std::fs::read_to_string(dir.join(f))
                .unwrap_or_else(|e| panic!("{all:?}: reading {f}: {e}"))
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
/// the reference vehicle.
fn changes(args: &[&str], extra: &[&str], out: &[&str]) {
    let reference = output_of(&files, args, &[], out);
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
}

/// A damper current above the vehicle's coil rating is rejected once the vehicle is known,
/// before anything runs (the parse-time range is the reference coil's 2 A).
#[test]
fn a_current_above_the_vehicles_rating_is_rejected() {
    let dir = temp_dir();
    std::fs::write(dir.join("small.toml"), "[damper]\nrated_current_a = 1.0\n").unwrap();
    for args in [
        &[
            "stability",
            "--vehicle",
            "small.toml",
            "--damper-current-a",
            "1.5",
            "--out",
            "o",
        ][..],
        &[
            "bifurcation",
            "--vehicle",
            "small.toml",
            "--damper-current-a",
            "1.5",
            "--out",
            "o",
        ],
        &[
            "sweep",
            "--vehicle",
            "small.toml",
            "--damper-current-a",
            "1.5",
            "--out",
            "o",
        ],
        &[
            "compare",
            "--vehicle",
            "small.toml",
            "--on-current-a",
            "1.5",
            "--out",
            "o",
        ],
    ] {
        let o = run_in(&dir, args);
        let err = text(&o.stderr);
        assert!(!o.status.success(), "{args:?}");
        assert!(
            err.contains("1.5") && err.contains("0 <= value <= 1 A"),
            "{args:?}: {err}"
        );
        assert!(!dir.join("o").exists(), "{args:?} wrote output");
    }
    std::fs::remove_dir_all(&dir).ok();
}
