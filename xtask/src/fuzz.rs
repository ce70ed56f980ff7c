//! `cargo xtask fuzz [--seconds N] [--target NAME]`: the coverage-guided fuzz targets in `fuzz/`
//! on the pinned *stable* toolchain, without cargo-fuzz and without nightly.
//!
//! cargo-fuzz is a thin driver: it builds the target with libfuzzer-sys (which compiles
//! libFuzzer's C++ sources with the system C++ compiler) and SanitizerCoverage instrumentation,
//! then runs the binary. The instrumentation flags it passes without `-Zsanitizer=address` are
//! all stable rustc flags, so this step passes the same ones:
//!
//! ```text
//! -Cpasses=sancov-module -Cllvm-args=-sanitizer-coverage-level=4
//! -Cllvm-args=-sanitizer-coverage-inline-8bit-counters -Cllvm-args=-sanitizer-coverage-pc-table
//! -Cllvm-args=-sanitizer-coverage-trace-compares --cfg fuzzing -Cdebug-assertions -Copt-level=3
//! ```
//!
//! What is lost against `cargo fuzz run` on nightly: AddressSanitizer, which for our code (no
//! `unsafe` in core) would only add checks that safe Rust already makes. Overflow checks and
//! `debug_assert!`s are on (`-Cdebug-assertions`), so arithmetic overflow is a crash too.
//!
//! The build goes to its own target dir (`target/fuzz/`), so the instrumented crates never mix
//! with the normal ones. The corpus is kept in `target/fuzz/corpus/NAME/` (reused by the next
//! run), crashes go to `target/fuzz/artifacts/NAME/`; a crash fails the step and prints the
//! reproducer and the command that replays it.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

/// The fuzz targets (binaries of `fuzz/Cargo.toml`).
pub const TARGETS: &[&str] = &["safe_step", "store_ops", "link_frames"];

/// Default length of the run in `cargo xtask test`, s: about as long as the QEMU steps it
/// runs alongside (at 60 s a cold CI run waited ~46 s for it at the end).
pub const CI_SECONDS: u64 = 30;

const SANCOV_FLAGS: &[&str] = &[
    "-Cpasses=sancov-module",
    "-Cllvm-args=-sanitizer-coverage-level=4",
    "-Cllvm-args=-sanitizer-coverage-inline-8bit-counters",
    "-Cllvm-args=-sanitizer-coverage-pc-table",
    "-Cllvm-args=-sanitizer-coverage-trace-compares",
    "--cfg",
    "fuzzing",
    "-Cdebug-assertions",
    "-Copt-level=3",
];

/// `cargo xtask fuzz [--seconds N] [--target NAME]`.
pub fn command(args: &[String]) -> Result<(), String> {
    let mut seconds = CI_SECONDS;
    let mut targets: Vec<String> = TARGETS.iter().map(|s| s.to_string()).collect();
    let mut it = args.iter();
    while let Some(a) = it.next() {
        match a.as_str() {
            "--seconds" => {
                seconds = it
                    .next()
                    .and_then(|v| v.parse().ok())
                    .ok_or("--seconds needs a whole number of seconds")?;
            }
            "--target" => {
                let t = it.next().ok_or("--target needs a name")?;
                if !TARGETS.contains(&t.as_str()) {
                    return Err(format!("unknown fuzz target {t}; known: {TARGETS:?}"));
                }
                targets = vec![t.clone()];
            }
            other => {
                return Err(format!(
                "unknown argument {other}; usage: cargo xtask fuzz [--seconds N] [--target NAME]"
            ))
            }
        }
    }
    for t in &targets {
        let summary = run(t, seconds)?;
        println!("xtask fuzz {t}: {summary}");
    }
    Ok(())
}

/// The step of `cargo xtask test`, in two parts: every target is built now (a build error
/// fails the step at once), then the fuzzing itself, [`CI_SECONDS`] in total, runs on a thread
/// of its own. libFuzzer keeps one core busy for a fixed time; `cargo xtask test` starts it
/// after the firmware builds, so on CI's two cores it shares the machine with the single-core
/// QEMU steps (a free core, so about the executions of a run alone) instead of adding its time
/// to the run, and joins the thread after its last step.
pub fn start_in_background() -> Result<std::thread::JoinHandle<Result<String, String>>, String> {
    let built = TARGETS
        .iter()
        .map(|t| build(t).map(|bin| (*t, bin)))
        .collect::<Result<Vec<_>, _>>()?;
    let per = (CI_SECONDS / TARGETS.len() as u64).max(1);
    Ok(std::thread::spawn(move || {
        let mut out = Vec::new();
        for (t, bin) in &built {
            out.push(format!("{t}: {}", run_built(t, bin, per)?));
        }
        Ok(out.join("; "))
    }))
}

fn host_triple() -> Result<String, String> {
    let out = Command::new("rustc")
        .arg("-vV")
        .current_dir(crate::root())
        .output()
        .map_err(|e| format!("cannot run rustc: {e}"))?;
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .find_map(|l| l.strip_prefix("host: ").map(str::to_string))
        .ok_or_else(|| "rustc -vV printed no host triple".into())
}

/// libfuzzer-sys compiles libFuzzer (C++): a C++ compiler must be there. Installs g++ with
/// apt-get when it is missing and we are root; otherwise explains.
fn ensure_cxx() -> Result<(), String> {
    let cxx = std::env::var("CXX").unwrap_or_else(|_| "c++".into());
    let works = |c: &str| {
        Command::new(c)
            .arg("--version")
            .output()
            .is_ok_and(|o| o.status.success())
    };
    if works(&cxx) || works("g++") || works("clang++") {
        return Ok(());
    }
    crate::apt_install(
        "g++",
        "no C++ compiler (libFuzzer is C++)",
        "install a C++ compiler, e.g. apt-get install g++ (Debian/Ubuntu)",
    )
}

/// Builds the instrumented fuzz target; returns the binary.
pub fn build(target: &str) -> Result<PathBuf, String> {
    ensure_cxx()?;
    let root = crate::root();
    let triple = host_triple()?;
    let target_dir = root.join("target").join("fuzz");
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    // With an explicit --target the flags reach only the fuzz binary and its dependencies, not
    // build scripts or proc macros. CARGO_ENCODED_RUSTFLAGS wins over any RUSTFLAGS around.
    let status = Command::new(cargo)
        .args([
            "build",
            "--release",
            "--manifest-path",
            "fuzz/Cargo.toml",
            "--bin",
            target,
            "--target",
            &triple,
            "--target-dir",
        ])
        .arg(&target_dir)
        .env("CARGO_ENCODED_RUSTFLAGS", SANCOV_FLAGS.join("\u{1f}"))
        .env_remove("RUSTFLAGS")
        .current_dir(&root)
        .status()
        .map_err(|e| format!("cannot start cargo: {e}"))?;
    if !status.success() {
        return Err(format!(
            "building the fuzz target {target} failed ({status})"
        ));
    }
    Ok(target_dir.join(&triple).join("release").join(target))
}

/// Builds and runs `target` for `seconds`; returns a one-line summary (runs, coverage).
pub fn run(target: &str, seconds: u64) -> Result<String, String> {
    let bin = build(target)?;
    run_built(target, &bin, seconds)
}

/// Runs the built fuzz binary `bin` of `target` for `seconds`.
fn run_built(target: &str, bin: &Path, seconds: u64) -> Result<String, String> {
    let base = crate::root().join("target").join("fuzz");
    let corpus = base.join("corpus").join(target);
    let artifacts = base.join("artifacts").join(target);
    for d in [&corpus, &artifacts] {
        std::fs::create_dir_all(d).map_err(|e| format!("creating {}: {e}", d.display()))?;
    }
    let before = list(&artifacts);
    println!(
        "xtask: fuzzing {target} for {seconds} s (corpus {})",
        corpus.display()
    );
    let out = Command::new(bin)
        .arg(&corpus)
        .arg(format!("-max_total_time={seconds}"))
        .arg(format!("-artifact_prefix={}/", artifacts.display()))
        .arg("-print_final_stats=1")
        .stdout(Stdio::inherit())
        .stderr(Stdio::piped())
        .output()
        .map_err(|e| format!("cannot start {}: {e}", bin.display()))?;
    let log = String::from_utf8_lossy(&out.stderr);
    let summary = summarise(&log);
    if out.status.success() {
        return Ok(summary);
    }
    // Show the end of libFuzzer's report (the panic message and the stack) and the reproducer.
    let lines: Vec<&str> = log.lines().collect();
    for l in &lines[lines.len().saturating_sub(40)..] {
        eprintln!("  | {l}");
    }
    let new: Vec<PathBuf> = list(&artifacts)
        .into_iter()
        .filter(|p| !before.contains(p))
        .collect();
    let repro = match new.first() {
        Some(p) => format!(
            "reproducer {} (replay: {} {})",
            p.display(),
            bin.display(),
            p.display()
        ),
        None => "no reproducer written".into(),
    };
    Err(format!(
        "fuzz target {target} failed ({}): {repro}; {summary}",
        out.status
    ))
}

fn list(dir: &Path) -> Vec<PathBuf> {
    std::fs::read_dir(dir)
        .map(|rd| rd.filter_map(|e| e.ok().map(|e| e.path())).collect())
        .unwrap_or_default()
}

/// "N runs, cov X, ft Y, corpus Z" from libFuzzer's output.
fn summarise(log: &str) -> String {
    let stat = |key: &str| {
        log.lines()
            .rev()
            .find_map(|l| l.strip_prefix(key).map(|v| v.trim().to_string()))
    };
    let last_status = log
        .lines()
        .rev()
        .find(|l| l.starts_with('#') && l.contains("cov:"))
        .unwrap_or("");
    let field = |name: &str| {
        let mut it = last_status.split_whitespace();
        it.by_ref().find(|w| *w == name);
        it.next().unwrap_or("?").to_string()
    };
    format!(
        "{} runs ({} exec/s), cov {}, ft {}, corpus {}",
        stat("stat::number_of_executed_units:").unwrap_or_else(|| "?".into()),
        stat("stat::average_exec_per_sec:").unwrap_or_else(|| "?".into()),
        field("cov:"),
        field("ft:"),
        field("corp:")
    )
}
