//! Project automation. `cargo xtask test` is the one test command (CI runs exactly it).
//!
//! ```text
//! cargo xtask test               host tests, fmt, clippy (host build + target), the Python module's
//!                                and the FMU's tests, firmware build + size, on-target tests
//!                                under QEMU (and proof that a failing one fails), the fault
//!                                campaign on every shipped vehicle; in two lanes
//!                                side by side (host, firmware), see `test`
//! cargo xtask qemu [BIN]         build BIN (default: shimmy-firmware) for QEMU and run it,
//!                                printing its decoded defmt log
//! cargo xtask size               release firmware build and its flash/RAM table, checked
//!                                against the budgets (flash <= FLASH_BUDGET, static RAM <= 24 KiB;
//!                                the `model-truck` image against its own, `elf::TRUCK_BUDGET`),
//!                                flash by crate, largest symbols, and where the bytes go
//!                                that no sized symbol covers
//! cargo xtask link               the host link end to end: the QEMU app with its USART on a
//!                                TCP socket and `shimmy-sim device` against it (identity,
//!                                config written and read back, events of the scenario as CSV)
//! cargo xtask conformance        replay the committed sensor trace on the host and under QEMU
//!                                and require bit-identical controller/estimator outputs
//! cargo xtask fuzz [--seconds N]  build the fuzz targets in fuzz/ with libFuzzer + coverage
//!                                instrumentation on the pinned stable toolchain and run them for
//!                                N s (default 60); a crash fails and prints the reproducer
//! cargo xtask python [--wheel]   the `shimmy` Python module from the host build, run by the
//!                                pytest suite (python/tests) in a venv in target/py-venv;
//!                                `--wheel`: the wheel `pip install ./python` builds (maturin,
//!                                dev profile, its own dependency build) installed there instead
//! cargo xtask fmu                build the FMI 3.0 co-simulation FMU (fmu/) into
//!                                target/fmu/shimmy_fmu.fmu, validate it with fmpy and
//!                                co-simulate it with the SciPy reference plant (fmu/tests/)
//! cargo xtask bench              on-target benchmark under QEMU -icount shift=0: instructions
//!                                per call of each entry, checked against its budget, and the
//!                                stack high-water mark; then the host simulator next to the
//!                                NumPy/SciPy reference (`shimmy-sim reference-bench`, release:
//!                                time domain, closed loop, eigenvalue sweep), skipped with a
//!                                message when python3 with numpy and scipy is missing;
//!                                `--target-only` stops after the on-target part
//! cargo xtask docs               measure the images' size and the on-target benchmark and write
//!                                docs/measurements.md (`cargo xtask test` fails when it is stale)
//! ```
//!
//! Missing system tools are installed when this runs as root with apt (qemu-system-arm, g++) or
//! rustup (the thumbv7em target); otherwise it stops and says what to install.

mod conformance;
mod elf;
mod fmu;
mod fuzz;
mod link_e2e;
mod measurements;
mod python;
mod qemu;

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, ExitCode, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Mutex;
use std::thread::JoinHandle;
use std::time::Instant;

/// The firmware's target triple (Cortex-M4F with hardware floating point).
pub const TARGET: &str = "thumbv7em-none-eabihf";
/// The application binary.
pub const FIRMWARE: &str = "shimmy-firmware";

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let result = match args.first().map(String::as_str) {
        Some("test") => test(),
        Some("qemu") => run_in_qemu(args.get(1).map(String::as_str).unwrap_or(FIRMWARE)),
        Some("size") => size(),
        Some("docs") => docs(),
        Some("bench") => bench().and_then(|s| {
            println!("on-target benchmark: {s}");
            println!("{TRUCK_MODEL} image (the model task on the truck's 12-state model):");
            let truck = run_truck_bench()?;
            println!("on-target benchmark, {TRUCK_MODEL} image: {truck}");
            if args.get(1).is_some_and(|a| a == "--target-only") {
                return Ok(());
            }
            host_reference_bench()
        }),
        Some("conformance") => conformance::step().map(|s| println!("{s}")),
        Some("link") => link_e2e::step().map(|s| println!("{s}")),
        Some("pil") => pil().map(|s| println!("xtask: {s}")),
        Some("python") if args.get(1).is_some_and(|a| a == "--wheel") => {
            python::wheel_tests().map(|s| println!("{s}"))
        }
        Some("python") => python::module_tests().map(|s| println!("{s}")),
        Some("fmu") => fmu::tests().map(|s| println!("{s}")),
        Some("fuzz") => fuzz::command(&args[1..]),
        Some("help" | "--help" | "-h") => {
            print!("{USAGE}");
            return ExitCode::SUCCESS;
        }
        other => {
            if let Some(o) = other {
                eprintln!("xtask: unknown command `{o}`");
            }
            eprint!("{USAGE}");
            return ExitCode::from(2);
        }
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("xtask: {e}");
            ExitCode::FAILURE
        }
    }
}

/// `cargo xtask help`: every command in one line each.
const USAGE: &str = "usage: cargo xtask <command>
  test                 every check CI runs (host and firmware lanes, QEMU, PIL)
  qemu [BIN]           build BIN (default shimmy-firmware) for QEMU, run it, print its log
  size                 flash/RAM of the release images against their budgets
  bench [--target-only] on-target instruction counts under QEMU -icount (then the host bench)
  docs                 measure size and bench, write docs/measurements.md
  conformance          host vs target replay of the committed trace, bit-identical
  link                 the host link end to end (QEMU app over TCP, shimmy-sim device)
  pil                  processor in the loop: PIL = SIL bit for bit
  python [--wheel]     the Python module's tests
  fmu                  build, validate and co-simulate the FMU
  fuzz [--seconds N] [--target NAME]  the fuzz targets
  help                 this text
";

type Step = Result<String, String>;
type StepFn = fn() -> Step;

/// The fuzz run that the fuzz step leaves in the background; `test` joins it at the end.
static FUZZ_RUN: Mutex<Option<JoinHandle<Step>>> = Mutex::new(None);

/// Every firmware image the steps build, by feature set (`[]` is the board build).
const FIRMWARE_IMAGES: &[(&[&str], &[&str])] = &[
    (&[], &[FIRMWARE, "panic-free-check"]),
    (&["panic-check"], &["panic-free-glue"]),
    (
        &["qemu"],
        &[
            FIRMWARE,
            "target-tests",
            "target-bench",
            "conformance",
            "reset-memory",
            "store-check",
        ],
    ),
    (
        &["qemu", "deliberate-failure"],
        &["target-tests", "target-bench"],
    ),
    (&["qemu", "stack-guard-test"], &["stack-guard"]),
    (&["qemu", "link-e2e"], &[FIRMWARE]),
    (&["pil"], &[FIRMWARE]),
    (&["pil", TRUCK_MODEL], &[FIRMWARE]),
    (&[TRUCK_MODEL], &[FIRMWARE]),
];

/// The feature that builds the image for the mining truck's model (`docs/mining-truck.md`).
const TRUCK_MODEL: &str = "model-truck";

/// The one host build: every host artifact the steps use (the test binaries, `shimmy-sim` for
/// the link and PIL steps, the Python module's and the FMU's libraries, the FMU packer) from a
/// cargo call that resolves features as `cargo test --workspace` does (`--workspace`, and
/// `--tests` turns the dev-dependencies on) and builds every target kind that it builds, so the
/// host tests and every later step reuse it.
/// Building one package (`-p shimmy-sim`, maturin's `cargo rustc` of `python/`) resolves its
/// dependencies' features without the rest of the workspace and compiles most of them again.
/// A new host artifact belongs here; a step uses it from [`host_build`]'s directory.
/// It is also the host's lint: clippy checks every workspace crate as it compiles
/// ([`with_host_lints`]), so the lint and the build are one compilation, not two.
const HOST_BUILD: &[&str] = &["build", "--workspace", "--all-targets"];

/// `cmd` (a host cargo call) with clippy as the compiler of the workspace's own crates, its
/// warnings denied: what `cargo clippy --workspace --all-targets -- -D warnings` does, but the
/// artifacts are real, so [`HOST_BUILD`] is the lint. Every host cargo call of a step goes
/// through here ([`host_cargo`], [`cargo_rebuilt`]): the wrapper is part of cargo's
/// fingerprint, and a call without it would compile the workspace again. Never for the
/// firmware: clippy-driver compiles at MIR opt-level 0, which would change the images.
fn with_host_lints(cmd: &mut Command) -> &mut Command {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let driver = Path::new(&cargo).with_file_name("clippy-driver");
    cmd.env("RUSTC_WORKSPACE_WRAPPER", driver).env(
        "CLIPPY_ARGS",
        "-D__CLIPPY_HACKERY__warnings__CLIPPY_HACKERY__",
    )
}

/// `cargo args` for the host with the lint of [`with_host_lints`], so it reuses [`host_build`].
pub fn host_cargo(args: &[&str]) -> Result<(), String> {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    run(with_host_lints(&mut Command::new(cargo))
        .args(args)
        .current_dir(root()))
}

/// Set once [`HOST_BUILD`] has run in this process.
static HOST_BUILT: AtomicBool = AtomicBool::new(false);

/// Runs [`HOST_BUILD`] (a few seconds when nothing changed) and returns the directory of its
/// artifacts (`target/debug`). Every call after the first in a process must find everything
/// fresh, and fails naming what was compiled again (a build script that reruns on every build,
/// or an input that a step changed).
pub fn host_build() -> Result<PathBuf, String> {
    let rebuilt = cargo_rebuilt(HOST_BUILD)?;
    if HOST_BUILT.swap(true, Ordering::Relaxed) && !rebuilt.is_empty() {
        return Err(format!(
            "the host build was not reused: cargo compiled {} again",
            rebuilt.join(", ")
        ));
    }
    Ok(root().join("target").join("debug"))
}

/// The host tests on [`host_build`]'s artifacts: `cargo test --workspace` must find every test
/// binary built (nothing compiled, else the step fails naming it), then runs them.
fn host_tests() -> Step {
    host_build()?;
    let rebuilt = cargo_rebuilt(&["test", "--workspace", "--no-run"])?;
    if !rebuilt.is_empty() {
        return Err(format!(
            "cargo test --workspace compiled {} that the host build had not (a target kind or \
             feature resolution missing from HOST_BUILD)",
            rebuilt.join(", ")
        ));
    }
    host_cargo(&["test", "--workspace"])?;
    Ok(String::new())
}

/// Runs cargo with `args` and JSON messages (diagnostics still rendered on stderr) and returns
/// the packages it compiled ([`rebuilt_packages`]).
fn cargo_rebuilt(args: &[&str]) -> Result<Vec<String>, String> {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let out = with_host_lints(&mut Command::new(cargo))
        .args(args)
        .arg("--message-format=json-render-diagnostics")
        .stderr(lane_output())
        .current_dir(root())
        .output()
        .map_err(|e| format!("cannot run cargo: {e}"))?;
    if !out.status.success() {
        return Err(format!(
            "cargo {} exited with {}",
            args.join(" "),
            out.status
        ));
    }
    Ok(rebuilt_packages(&String::from_utf8_lossy(&out.stdout)))
}

/// The packages (`name@version`) of the artifacts that cargo's JSON messages report as
/// compiled rather than fresh.
fn rebuilt_packages(json_lines: &str) -> Vec<String> {
    let mut names: Vec<String> = json_lines
        .lines()
        .filter(|l| l.contains(r#""reason":"compiler-artifact""#) && l.contains(r#""fresh":false"#))
        .filter_map(|l| {
            let id = l.split(r#""package_id":""#).nth(1)?.split('"').next()?;
            Some(id.rsplit('#').next().unwrap_or(id).to_string())
        })
        .collect();
    names.sort();
    names.dedup();
    names
}

/// Runs every check, keeps going after a failure so the summary shows all of them, and fails
/// if any failed.
///
/// Two lanes run side by side, because each leaves a core idle much of the time (the host
/// build's last crates and a fat-LTO link compile on one core): the host lane (the host build,
/// its tests, the Python module, the FMU, rustdoc) on a second thread, its output in
/// [`HOST_LANE_LOG`] and printed when it ends, and the firmware lane (clippy for the target,
/// the images, the QEMU steps) on this one. The two never wait for each other's cargo lock: the
/// host lane builds in `target/debug`, the firmware lane only in the release profile
/// (`target/release` for its build scripts). The steps that need both (conformance, the host
/// link, PIL) run after both lanes.
fn test() -> Result<(), String> {
    ensure_thumb_target()?;
    qemu::ensure_installed()?;
    ensure_scipy()?;
    fmu::ensure_libclang()?;
    let host_steps: Vec<(&str, StepFn)> = vec![
        (
            "host build with clippy -D warnings (all targets, Python module, FMU)",
            || host_build().map(|_| "one feature resolution for every host step".into()),
        ),
        ("host tests (cargo test --workspace)", host_tests),
        (
            "fault campaign on every shipped vehicle (shimmy-sim faults --vehicle all)",
            fault_campaign,
        ),
        ("Python module (pytest python/tests)", python::module_tests),
        (
            "FMU (fmi-export, fmpy validation, co-simulation)",
            fmu::tests,
        ),
        ("rustdoc (workspace, -D warnings)", rustdoc),
    ];
    let firmware_steps: Vec<(&str, StepFn)> = vec![
        ("cargo fmt --check", || {
            cargo(&["fmt", "--all", "--check"]).map(|_| String::new())
        }),
        ("clippy (firmware, thumbv7em)", clippy_firmware),
        (
            "firmware release builds (one cargo call per feature set)",
            || {
                // Later steps find their image built: the library compiles once per feature set
                // and the images of a set link in parallel.
                for (features, bins) in FIRMWARE_IMAGES {
                    build_firmware_images(bins, features)?;
                }
                let n: usize = FIRMWARE_IMAGES.iter().map(|(_, b)| b.len()).sum();
                Ok(format!(
                    "{n} images in {} feature sets",
                    FIRMWARE_IMAGES.len()
                ))
            },
        ),
        ("fuzz targets: build, then 30 s in the background", || {
            let run = fuzz::start_in_background()?;
            *FUZZ_RUN.lock().map_err(|_| "fuzz handle lock poisoned")? = Some(run);
            Ok(format!(
                "fuzzing {} s alongside the next steps",
                fuzz::CI_SECONDS
            ))
        }),
        (
            "firmware size (and its section of docs/measurements.md)",
            || {
                let section = measure_size(false)?;
                measurements::check("size", &section)?;
                Ok("both images within budget; docs/measurements.md current".into())
            },
        ),
        ("panic-free control path (link check)", || {
            // Links only if no panic is reachable (firmware/src/bin/panic-free-check.rs).
            build_firmware("panic-free-check", &[]).map(|_| "no reachable panic".into())
        }),
        ("panic-free firmware glue (link check)", || {
            // The control task's glue around the core step (firmware/src/bin/panic-free-glue.rs).
            build_firmware("panic-free-glue", &["panic-check"]).map(|_| "no reachable panic".into())
        }),
        ("on-target tests (QEMU netduinoplus2)", on_target_tests),
        ("stack overflow caught by the guard (QEMU)", stack_guard),
        ("fault memory across resets (QEMU)", reset_memory),
        ("flash store across resets (QEMU)", store_check),
        ("on-target benchmark budgets (QEMU -icount)", || {
            let run = run_bench_measured(&["qemu"])?;
            measurements::check("bench", &run.section())?;
            Ok(format!(
                "{} entries within budget; docs/measurements.md current",
                run.rows.len()
            ))
        }),
        (
            "an over-budget benchmark entry fails the run",
            || match run_bench(&["qemu", "deliberate-failure"]) {
                Ok(_) => Err("the deliberately over-budget entry did not fail the bench".into()),
                Err(e) if e.contains("over budget") => {
                    Ok("exit non-zero, row marked OVER BUDGET".into())
                }
                Err(e) => Err(format!("the bench failed, but not for the budget: {e}")),
            },
        ),
        (
            "a failing on-target test fails the run",
            on_target_failure_is_caught,
        ),
        ("firmware app under QEMU (RTIC, simulated sensors)", || {
            let elf = build_firmware(FIRMWARE, &["qemu"])?;
            let run = qemu::run_with(&elf, qemu::APP_ICOUNT)?;
            run.print();
            run.expect_success()?;
            let story = qemu::check_supervisor(&run.log)?;
            Ok(format!("{} log lines; {story}", run.log.len()))
        }),
    ];
    let joint_steps: Vec<(&str, StepFn)> = vec![
        (
            "host/target conformance (trace replay, bit-identical)",
            conformance::step,
        ),
        (
            "host link under QEMU (shimmy-sim device over TCP)",
            link_e2e::step,
        ),
        ("processor in the loop, PIL = SIL bit for bit (QEMU)", pil),
    ];

    let log = root().join(HOST_LANE_LOG);
    let lane_log = log.clone();
    let host_count = host_steps.len();
    let host_lane = std::thread::spawn(move || -> Result<Vec<Outcome>, String> {
        if let Some(dir) = lane_log.parent() {
            std::fs::create_dir_all(dir).map_err(|e| format!("create {}: {e}", dir.display()))?;
        }
        let file = std::fs::File::create(&lane_log)
            .map_err(|e| format!("create {}: {e}", lane_log.display()))?;
        LANE_LOG.set(Some(file));
        Ok(run_steps(host_steps))
    });
    println!(
        "\n==> host lane: {host_count} steps beside the firmware steps (log: {HOST_LANE_LOG})"
    );
    let mut results = run_steps(firmware_steps);
    let host = host_lane
        .join()
        .unwrap_or_else(|_| Err("the host lane's thread panicked".into()));
    println!("\n==> host lane, its log ({HOST_LANE_LOG}):");
    match std::fs::read_to_string(&log) {
        Ok(text) => print!("{text}"),
        Err(e) => println!("(cannot read it: {e})"),
    }
    match host {
        Ok(host) => results.extend(host),
        Err(e) => results.push(("host lane", Err(e), 0.0)),
    }
    results.extend(run_steps(joint_steps));
    let fuzz_run = FUZZ_RUN.lock().ok().and_then(|mut h| h.take());
    if let Some(run) = fuzz_run {
        let name = "fuzz run (time waited for it here)";
        println!("\n==> {name}");
        let start = Instant::now();
        let outcome = run
            .join()
            .unwrap_or_else(|_| Err("the fuzz thread panicked".into()));
        results.push((name, outcome, start.elapsed().as_secs_f64()));
    }

    println!("\n==> summary");
    for (name, outcome, secs) in &results {
        match outcome {
            Ok(detail) => println!("  ok    {name:<42} {secs:>6.1} s  {detail}"),
            Err(e) => println!("  FAIL  {name:<42} {secs:>6.1} s  {e}"),
        }
    }
    let failed = results.iter().filter(|r| r.1.is_err()).count();
    println!("xtask: {} passed, {failed} failed", results.len() - failed);
    if failed == 0 {
        Ok(())
    } else {
        Err(format!("{failed} step(s) failed"))
    }
}

/// The host lane's output in a `cargo xtask test` (relative to the workspace root).
const HOST_LANE_LOG: &str = "target/xtask/host-lane.log";

/// A step's name, what it ended with, and its wall time in s.
type Outcome = (&'static str, Step, f64);

/// Runs `steps` in order on this thread, each after a header ([`say`]), and keeps going after
/// a failure.
fn run_steps(steps: Vec<(&'static str, StepFn)>) -> Vec<Outcome> {
    steps
        .into_iter()
        .map(|(name, step)| {
            say(&format!("\n==> {name}"));
            let start = Instant::now();
            let outcome = step();
            if let Err(e) = &outcome {
                say(&format!("FAILED: {name}: {e}"));
            }
            (name, outcome, start.elapsed().as_secs_f64())
        })
        .collect()
}

thread_local! {
    /// The log of the lane this thread runs (`cargo xtask test`'s host lane); `None`: the
    /// terminal.
    static LANE_LOG: std::cell::RefCell<Option<std::fs::File>> = const { std::cell::RefCell::new(None) };
}

/// Where the commands of this thread write: its lane's log, or the terminal.
fn lane_output() -> Stdio {
    LANE_LOG.with_borrow(|log| {
        log.as_ref()
            .and_then(|f| f.try_clone().ok())
            .map_or_else(Stdio::inherit, Stdio::from)
    })
}

/// One line of this thread's progress, into its lane's log or onto the terminal (the steps'
/// own modules report through it too, so a line of the host lane lands in its log).
pub fn say(line: &str) {
    LANE_LOG.with_borrow_mut(|log| match log {
        Some(f) => {
            // A lost progress line is not worth failing a step for.
            let _ = writeln!(f, "{line}");
        }
        None => println!("{line}"),
    });
}

/// The API docs build without a warning: every public item documented, every intra-doc link
/// resolves (a unit written as `[rad]` would read as a broken link).
fn rustdoc() -> Step {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    run(Command::new(cargo)
        .args(["doc", "--workspace", "--no-deps"])
        .env("RUSTDOCFLAGS", "-D warnings")
        .current_dir(root()))?;
    Ok(String::new())
}

/// Clippy on the firmware for the target, per feature set. In the release profile: its build
/// scripts and proc macros are the release images' (`target/release`), and it never waits for
/// the host lane's lock on `target/debug` ([`test()`]).
fn clippy_firmware() -> Step {
    for features in [
        "",
        "qemu,deliberate-failure",
        "pil",
        TRUCK_MODEL,
        // the debug build's features, together
        "panic-location,probe-telemetry",
    ] {
        let mut args = vec![
            "clippy",
            "--release",
            "-p",
            FIRMWARE,
            "--target",
            TARGET,
            "--bins",
        ];
        if !features.is_empty() {
            args.extend(["--features", features]);
        }
        args.extend(["--", "-D", "warnings"]);
        cargo(&args)?;
    }
    Ok(String::new())
}

fn on_target_tests() -> Step {
    let elf = build_firmware("target-tests", &["qemu"])?;
    let run = qemu::run(&elf)?;
    run.print();
    run.expect_success()?;
    let summary = run
        .log
        .iter()
        .rev()
        .find(|l| l.contains(" passed, "))
        .ok_or("the harness printed no summary line")?;
    if !summary.contains(" passed, 0 failed") {
        return Err(format!("unexpected summary: {summary}"));
    }
    Ok(summary.trim_start_matches("INFO ").to_string())
}

/// The reset record must survive three resets under QEMU, restore the latched coil short and
/// hold the safe state at the third quick reset (firmware/src/bin/reset-memory.rs).
fn reset_memory() -> Step {
    let elf = build_firmware("reset-memory", &["qemu"])?;
    let run = qemu::run(&elf)?;
    run.print();
    run.expect_success()?;
    run.log
        .iter()
        .find(|l| l.contains("reset memory ok"))
        .map(|_| "record survived 3 resets, latch restored (0 A), reset loop held".to_string())
        .ok_or_else(|| "the run ended without the final report".to_string())
}

/// The flash store on QEMU's RAM flash across two resets (firmware/src/bin/store-check.rs):
/// a configuration saved at standstill and loaded at the next boot, a shimmy episode and a
/// latched coil short logged while driving, the log read back after the reset.
fn store_check() -> Step {
    let elf = build_firmware("store-check", &["qemu"])?;
    let run = qemu::run(&elf)?;
    run.print();
    run.expect_success()?;
    run.log
        .iter()
        .find(|l| l.contains("store ok"))
        .map(|_| {
            "configuration kept, episode and fault logged, log read back after 2 resets".to_string()
        })
        .ok_or_else(|| "the run ended without the final report".to_string())
}

/// A stack overflow must end in the guard's fault handler (firmware/src/bin/stack-guard.rs):
/// a clean exit and the handler's report, not a HardFault after corrupting the statics.
fn stack_guard() -> Step {
    let elf = build_firmware("stack-guard", &["qemu", "stack-guard-test"])?;
    let run = qemu::run(&elf)?;
    run.print();
    run.expect_success()?;
    run.log
        .iter()
        .find(|l| l.contains("stack overflow: the stack guard caught it"))
        .map(|_| "overflow ended in the guard's handler (coil off, reported)".to_string())
        .ok_or_else(|| "the run ended without the guard's report".to_string())
}

/// The harness must turn a failing assertion into a failed run: build it with one test that
/// fails on purpose and demand a non-zero exit that names the failure.
fn on_target_failure_is_caught() -> Step {
    let elf = build_firmware("target-tests", &["qemu", "deliberate-failure"])?;
    let run = qemu::run(&elf)?;
    if run.success() {
        run.print();
        return Err("the deliberately failing on-target test did not fail the run".into());
    }
    if !run
        .log
        .iter()
        .any(|l| l.contains("panic") && l.contains("deliberate"))
    {
        run.print();
        return Err("the run failed, but not with the deliberate assertion".into());
    }
    Ok(format!(
        "exit status {:?}, panic message decoded",
        run.status
    ))
}

/// Builds and runs the benchmark binary with instruction counting, prints its table and
/// fails if the counter calibration failed or an entry is over its budget.
fn bench() -> Step {
    run_bench(&["qemu"])
}

/// The simulator's speed next to the NumPy/SciPy reference implementation of the plant
/// (`shimmy-sim reference-bench` in release), or a clear skip when python3 with numpy and
/// scipy is not available.
fn host_reference_bench() -> Result<(), String> {
    let probe = Command::new("python3")
        .args(["-c", "import numpy, scipy"])
        .output();
    match probe {
        Ok(o) if o.status.success() => {}
        Ok(o) => {
            println!(
                "host reference bench SKIPPED: python3 has no numpy/scipy ({}); install them with `pip install numpy scipy`",
                String::from_utf8_lossy(&o.stderr).lines().last().unwrap_or("").trim()
            );
            return Ok(());
        }
        Err(e) => {
            println!("host reference bench SKIPPED: cannot run python3 ({e})");
            return Ok(());
        }
    }
    println!("host simulator vs the NumPy/SciPy reference (release build):");
    cargo(&[
        "run",
        "--release",
        "--quiet",
        "-p",
        "shimmy-sim",
        "--",
        "reference-bench",
    ])
}

/// The fault campaign (`shimmy-sim faults`) at its defaults on every named set of every model,
/// on [`host_build`]'s simulator (its dev build takes ~30 s for all of them): any failed check
/// (a fault not detected, shimmy not suppressed, a mode still changing, ...) fails the step.
fn fault_campaign() -> Step {
    let sim = host_build()?.join("shimmy-sim");
    run(Command::new(&sim)
        .args(["faults", "--vehicle", "all", "--out", "target/xtask/faults"])
        .current_dir(root()))?;
    Ok("every check passed on every shipped vehicle".into())
}

/// The scenarios of the PIL check, each with the features of its image: 12 s through the Hopf
/// window onset with a pothole and an injected encoder fault, on the car and on the mining
/// truck.
const PIL_SCENARIOS: [(&str, &[&str]); 2] = [
    ("host-sim/scenarios/pil/demo.toml", &["pil"]),
    ("host-sim/scenarios/pil/truck.toml", &["pil", TRUCK_MODEL]),
];

/// Processor in the loop: the application image built with the `pil` feature closes the loop
/// with the simulator's plant under QEMU (`shimmy-sim pil`), and the run must agree bit for bit
/// with the firmware's application run natively (`--check-sil`); `shimmy-sim` exits non-zero
/// otherwise. The dev build of [`host_build`] is enough (11x real time here, 2.2 s with the
/// SIL run): a release build would add a fat-LTO link of the simulator to a cold CI run.
fn pil() -> Step {
    ensure_thumb_target()?;
    qemu::ensure_installed()?;
    let sim = host_build()?.join("shimmy-sim");
    let mut done = Vec::new();
    let mut images = Vec::new();
    for (scenario, features) in PIL_SCENARIOS {
        let elf = build_firmware(FIRMWARE, features)?;
        images.push(elf.clone());
        let name = Path::new(scenario)
            .file_stem()
            .map_or_else(String::new, |s| s.to_string_lossy().into_owned());
        run(Command::new(&sim)
            .args(["pil", scenario, "--elf"])
            .arg(&elf)
            .args(["--check-sil", "--out"])
            .arg(format!("target/xtask/pil/{name}"))
            .current_dir(root()))?;
        done.push(scenario);
    }
    // The negative check: the truck's scenario on the car's image is refused at the image's
    // hello, naming the model the image is built for.
    let (truck, _) = PIL_SCENARIOS[1];
    let out = Command::new(&sim)
        .args(["pil", truck, "--elf"])
        .arg(&images[0])
        .args(["--out", "target/xtask/pil/refused"])
        .current_dir(root())
        .output()
        .map_err(|e| format!("running shimmy-sim: {e}"))?;
    let err = String::from_utf8_lossy(&out.stderr);
    if out.status.success() || !err.contains("is built for the car-4dof model") {
        return Err(format!(
            "the truck's scenario on the car's image was not refused at its hello: {err}"
        ));
    }
    Ok(format!(
        "{}: PIL = SIL bit for bit; the truck's scenario on the car's image refused",
        done.join(", ")
    ))
}

/// The truck-model image's benchmark, every row against the truck image's budgets (the bench's
/// `model-truck` CPU-load budget, `firmware/src/bin/target-bench.rs`): over one fails the run.
fn run_truck_bench() -> Step {
    run_bench(&["qemu", TRUCK_MODEL])
}

fn run_bench(features: &[&str]) -> Step {
    run_bench_measured(features).map(|b| format!("{} entries within budget", b.rows.len()))
}

/// What one on-target benchmark run measured.
struct BenchRun {
    /// name, instructions, budget, result
    rows: Vec<Vec<String>>,
    /// The run's stack high-water mark and CPU load lines.
    notes: Vec<String>,
}

impl BenchRun {
    /// The `bench` section of `docs/measurements.md`.
    fn section(&self) -> String {
        let rows: Vec<Vec<String>> = self.rows.iter().filter(|r| r.len() == 4).cloned().collect();
        let mut out = measurements::table(
            &["entry", "instructions", "budget", "result"],
            &[false, true, true, false],
            &rows,
        );
        for note in &self.notes {
            out.push_str(&format!("\n{note}\n"));
        }
        out
    }
}

fn run_bench_measured(features: &[&str]) -> Result<BenchRun, String> {
    ensure_thumb_target()?;
    qemu::ensure_installed()?;
    let elf = build_firmware("target-bench", features)?;
    let run = qemu::run_with(&elf, qemu::BENCH_ICOUNT)?;
    let mut rows = Vec::new();
    let mut notes = Vec::new();
    for line in &run.log {
        match line.split_once("bench | ") {
            Some((_, rest)) => rows.push(rest.split(" | ").map(str::to_string).collect::<Vec<_>>()),
            None => {
                println!("  | {line}");
                for key in ["stack high-water mark", "cpu load:"] {
                    if let Some(i) = line.find(key) {
                        notes.push(line[i..].to_string());
                    }
                }
            }
        }
    }
    println!(
        "  {:<50} {:>12} {:>8}  result",
        "name", "instructions", "budget"
    );
    for r in &rows {
        if let [name, n, budget, result] = r.as_slice() {
            println!("  {name:<50} {n:>12} {budget:>8}  {result}");
        }
    }
    if !run.stderr.trim().is_empty() {
        eprintln!("  qemu stderr: {}", run.stderr.trim());
    }
    let over = rows
        .iter()
        .filter(|r| r.get(3).is_some_and(|x| x.contains("OVER BUDGET")))
        .count();
    run.expect_success().map_err(|e| {
        format!("{e}: {over} entries over budget (or the counter calibration failed)")
    })?;
    if rows.is_empty() {
        return Err("the benchmark printed no rows".into());
    }
    Ok(BenchRun { rows, notes })
}

/// The `size` section of `docs/measurements.md`: both images against their budgets and slot.
fn size_section(images: &[(&elf::Budget, &elf::MemoryReport)]) -> String {
    let rows: Vec<Vec<String>> = images
        .iter()
        .map(|(budget, report)| {
            let flash = report.flash_bytes();
            let headroom = 100.0 * (1.0 - flash as f64 / elf::APP_SLOT_BYTES as f64);
            vec![
                budget.image.to_string(),
                flash.to_string(),
                budget.flash.to_string(),
                format!("{headroom:.1} %"),
                report.ram_bytes().to_string(),
                budget.ram.to_string(),
            ]
        })
        .collect();
    format!(
        "{}\nThe application slot is {} B; the budget keeps {} % of it free (`xtask/src/elf.rs`).",
        measurements::table(
            &[
                "image",
                "flash B",
                "flash budget B",
                "slot free",
                "static RAM B",
                "RAM budget B"
            ],
            &[false, true, true, true, true, true],
            &rows,
        ),
        elf::APP_SLOT_BYTES,
        elf::FLASH_HEADROOM_PERCENT
    )
}

/// Builds both board images, prints their tables, checks fit and budget, and returns the
/// `size` section of `docs/measurements.md`.
fn measure_size(detail: bool) -> Result<String, String> {
    ensure_thumb_target()?;
    let car_elf = build_firmware(FIRMWARE, &[])?;
    let car = elf::MemoryReport::read(&car_elf)?;
    println!("{car}");
    if detail {
        println!("{}", elf::top_symbols(&car_elf, 25)?);
        println!("{}", elf::attribution(&car_elf, 12)?);
        println!("{}", elf::source_table(&car_elf, 30)?);
        println!("{}", elf::soft_f64_table(&car_elf, 12)?);
    } else {
        println!("{}", elf::top_symbols(&car_elf, 15)?);
    }
    car.check_fits()?;
    car.check_budget(&elf::CAR_BUDGET)?;
    elf::check_unwanted(&car_elf)?;
    let truck_elf = build_firmware(FIRMWARE, &[TRUCK_MODEL])?;
    let truck = elf::MemoryReport::read(&truck_elf)?;
    println!("{TRUCK_MODEL} image:\n{truck}");
    truck.check_fits()?;
    truck.check_budget(&elf::TRUCK_BUDGET)?;
    elf::check_unwanted(&truck_elf)?;
    Ok(size_section(&[
        (&elf::CAR_BUDGET, &car),
        (&elf::TRUCK_BUDGET, &truck),
    ]))
}

/// `cargo xtask docs`: measures and writes `docs/measurements.md`.
fn docs() -> Result<(), String> {
    let size = measure_size(false)?;
    let bench = run_bench_measured(&["qemu"])?.section();
    measurements::write(&[("size", size), ("bench", bench)])?;
    println!("xtask: wrote {}", measurements::PATH);
    Ok(())
}

fn size() -> Result<(), String> {
    let section = measure_size(true)?;
    measurements::check("size", &section)
}

fn run_in_qemu(bin: &str) -> Result<(), String> {
    ensure_thumb_target()?;
    qemu::ensure_installed()?;
    if bin == "stack-guard" {
        return stack_guard().map(|s| println!("xtask: {s}"));
    }
    if bin == "reset-memory" {
        return reset_memory().map(|s| println!("xtask: {s}"));
    }
    if bin == "store-check" {
        return store_check().map(|s| println!("xtask: {s}"));
    }
    let elf = build_firmware(bin, &["qemu"])?;
    let run = qemu::run_with(&elf, qemu::APP_ICOUNT)?;
    run.print();
    run.expect_success()?;
    if bin == FIRMWARE {
        println!("xtask: {}", qemu::check_supervisor(&run.log)?);
    }
    Ok(())
}

/// Builds a firmware binary in release mode for the target and copies the ELF to a name that
/// records its features, so builds with different features never overwrite each other.
pub fn build_firmware(bin: &str, features: &[&str]) -> Result<PathBuf, String> {
    let mut copies = build_firmware_images(&[bin], features)?;
    copies.pop().ok_or_else(|| format!("{bin}: nothing built"))
}

/// [`build_firmware`] for several binaries with the same features in one cargo call.
fn build_firmware_images(bins: &[&str], features: &[&str]) -> Result<Vec<PathBuf>, String> {
    let features = features.join(",");
    let mut args = vec!["build", "--release", "-p", FIRMWARE, "--target", TARGET];
    for bin in bins {
        args.extend(["--bin", bin]);
    }
    if !features.is_empty() {
        args.extend(["--features", &features]);
    }
    cargo(&args)?;
    let dir = root().join("target").join("xtask");
    std::fs::create_dir_all(&dir).map_err(|e| format!("create {}: {e}", dir.display()))?;
    let tag = if features.is_empty() {
        "board".to_string()
    } else {
        features.replace(',', "+")
    };
    bins.iter()
        .map(|bin| {
            let built = root().join("target").join(TARGET).join("release").join(bin);
            let copy = dir.join(format!("{bin}.{tag}.elf"));
            std::fs::copy(&built, &copy).map_err(|e| format!("copy {}: {e}", built.display()))?;
            Ok(copy)
        })
        .collect()
}

/// Runs the cargo that runs xtask (same toolchain) with `args` in the workspace root.
pub fn cargo(args: &[&str]) -> Result<(), String> {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    run(Command::new(cargo).args(args).current_dir(root()))
}

/// Installs the Debian package `package` with apt-get when we are root; otherwise, or when
/// apt-get fails, an error that names `missing` and ends with `hint` (how to install by hand).
fn apt_install(package: &str, missing: &str, hint: &str) -> Result<(), String> {
    let is_root = Command::new("id")
        .arg("-u")
        .output()
        .is_ok_and(|o| String::from_utf8_lossy(&o.stdout).trim() == "0");
    if !is_root {
        return Err(format!("{missing} and this is not root; {hint}"));
    }
    println!("xtask: installing {package} with apt-get");
    let apt = |args: &[&str]| {
        Command::new("apt-get")
            .args(args)
            .env("DEBIAN_FRONTEND", "noninteractive")
            .status()
            .is_ok_and(|s| s.success())
    };
    if apt(&["update", "-qq"]) && apt(&["install", "-y", "-qq", "--no-install-recommends", package])
    {
        Ok(())
    } else {
        Err(format!("apt-get could not install {package}; {hint}"))
    }
}

fn run(cmd: &mut Command) -> Result<(), String> {
    let shown = format!("{cmd:?}");
    let status = cmd
        .stdout(lane_output())
        .stderr(lane_output())
        .status()
        .map_err(|e| format!("cannot start {shown}: {e}"))?;
    if status.success() {
        Ok(())
    } else {
        Err(format!("{shown} exited with {status}"))
    }
}

/// The workspace root (xtask lives one level below it).
pub fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .map(Path::to_path_buf)
        .unwrap_or_default()
}

/// The thumbv7em standard library must be installed; rust-toolchain.toml names it, and
/// `rustup target add` fetches it where rustup did not.
fn ensure_thumb_target() -> Result<(), String> {
    let out = Command::new("rustc")
        .args(["--print", "target-libdir", "--target", TARGET])
        .current_dir(root())
        .output()
        .map_err(|e| format!("cannot run rustc: {e}"))?;
    let libdir = String::from_utf8_lossy(&out.stdout).trim().to_string();
    if out.status.success() && Path::new(&libdir).is_dir() {
        return Ok(());
    }
    println!("xtask: installing the {TARGET} standard library with rustup");
    run(Command::new("rustup")
        .args(["target", "add", TARGET])
        .current_dir(root()))
    .map_err(|e| {
        format!("{e}\nInstall it by hand: rustup target add {TARGET} (in the repository root)")
    })
}

/// The host tests compare the plant with an independent NumPy/SciPy implementation
/// (`host-sim/reference/plant_scipy.py`): install numpy and scipy with pip when they are missing.
fn ensure_scipy() -> Result<(), String> {
    let have = |py: &str| {
        Command::new(py)
            .args(["-c", "import numpy, scipy"])
            .output()
            .is_ok_and(|o| o.status.success())
    };
    if have("python3") {
        return Ok(());
    }
    println!("xtask: installing numpy and scipy with pip");
    run(Command::new("python3").args(["-m", "pip", "install", "--quiet", "numpy", "scipy"]))
        .map_err(|e| format!("{e}\nInstall them by hand: python3 -m pip install numpy scipy"))?;
    if have("python3") {
        Ok(())
    } else {
        Err("numpy/scipy still not importable after pip install".into())
    }
}

#[cfg(test)]
mod tests {
    use super::rebuilt_packages;

    #[test]
    fn rebuilt_packages_names_only_compiled_artifacts() {
        let lines = concat!(
            r#"{"reason":"compiler-artifact","package_id":"registry+https://github.com/rust-lang/crates.io-index#serde@1.0.229","fresh":true}"#,
            "\n",
            r#"{"reason":"build-script-executed","package_id":"path+file:///w/host-sim#shimmy-sim@0.1.0"}"#,
            "\n",
            r#"{"reason":"compiler-artifact","package_id":"path+file:///w/host-sim#shimmy-sim@0.1.0","fresh":false}"#,
            "\n",
            r#"{"reason":"compiler-artifact","package_id":"path+file:///w/host-sim#shimmy-sim@0.1.0","fresh":false}"#,
            "\n",
            r#"{"reason":"compiler-artifact","package_id":"path+file:///w/python#shimmy-py@0.1.0","fresh":false}"#,
            "\n",
            r#"{"reason":"build-finished","success":true}"#,
        );
        assert_eq!(
            rebuilt_packages(lines),
            ["shimmy-py@0.1.0", "shimmy-sim@0.1.0"]
        );
    }
}
