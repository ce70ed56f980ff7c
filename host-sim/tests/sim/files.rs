//! The simulator's files under trouble, through the built binary: an output folder another run
//! is writing, an input file too large (or endless), a disk that fills up mid-write. Each is
//! refused with an error that names the file, and leaves no half-written file behind.

use crate::common::{run_in, temp_dir};
use std::fs::{File, OpenOptions};
use std::path::Path;
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

/// A short scenario whose run writes a trace of about 300 KB.
const SCENARIO: &str =
    "duration_s = 1.0\n[speed]\nconstant_kmh = 40.0\n[output]\ntrace_every = 1\n";

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn names(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .map(|rd| {
            rd.map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
                .collect()
        })
        .unwrap_or_default();
    v.sort();
    v
}

#[test]
fn a_run_into_a_folder_another_run_holds_is_refused_naming_the_folder() {
    let dir = temp_dir("files-lock");
    std::fs::write(dir.join("s.toml"), SCENARIO).unwrap();
    // Another run holds the folder: its lock, as a running shimmy-sim holds it.
    std::fs::create_dir_all(dir.join("o")).unwrap();
    let lock = OpenOptions::new()
        .write(true)
        .create(true)
        .truncate(false)
        .open(dir.join("o/.shimmy-sim.lock"))
        .unwrap();
    lock.lock().unwrap();
    let o = run_in(&dir, &["run", "s.toml", "--out", "o"]);
    let err = stderr(&o);
    assert!(
        !o.status.success(),
        "a second run wrote into the folder another run holds: {err}"
    );
    assert!(
        err.contains("output folder o") && err.contains("in use"),
        "{err}"
    );
    assert_eq!(
        names(&dir.join("o")),
        [".shimmy-sim.lock"],
        "nothing written"
    );
    // Released (the other run ended): the folder is free again.
    drop(lock);
    let o = run_in(&dir, &["run", "s.toml", "--out", "o"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(dir.join("o/trace.csv").is_file());
    let _ = std::fs::remove_dir_all(&dir);
}

/// Holds `dir/o` as a running shimmy-sim does: its lock file, locked.
fn hold_folder(dir: &Path) -> File {
    std::fs::create_dir_all(dir.join("o")).unwrap();
    let lock = OpenOptions::new()
        .write(true)
        .create(true)
        .truncate(false)
        .open(dir.join("o/.shimmy-sim.lock"))
        .unwrap();
    lock.lock().unwrap();
    lock
}

/// `shimmy-sim args` in `dir`, killed after `limit` (then `None`): a command that does its
/// work before it looks at its folder would otherwise run for minutes.
fn run_within(dir: &Path, args: &[&str], limit: Duration) -> Option<(bool, String, String)> {
    let (so, se) = (dir.join("stdout.txt"), dir.join("stderr.txt"));
    let mut child = Command::new(env!("CARGO_BIN_EXE_shimmy-sim"))
        .args(args)
        .current_dir(dir)
        .env("RUST_BACKTRACE", "0")
        .stdout(File::create(&so).unwrap())
        .stderr(File::create(&se).unwrap())
        .spawn()
        .unwrap();
    let start = Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        if start.elapsed() > limit {
            child.kill().unwrap();
            child.wait().unwrap();
            return None;
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    let read = |p: &Path| std::fs::read_to_string(p).unwrap();
    Some((status.success(), read(&so), read(&se)))
}

/// Every command that writes an output folder claims it before its work: with the folder held
/// by another run, each stops at once, naming the folder, with no result printed and nothing
/// written (a command that claimed after its work ran it in full and printed its table first;
/// the campaigns ran for minutes).
#[test]
fn every_command_refuses_a_held_folder_before_its_work() {
    let dir = temp_dir("files-every");
    std::fs::write(dir.join("s.toml"), SCENARIO).unwrap();
    std::fs::write(
        dir.join("pil.toml"),
        "duration_s = 1.0\n[speed]\nconstant_kmh = 40.0\n[controller]\nkind = \"margin-asmc\"\n",
    )
    .unwrap();
    std::fs::write(
        dir.join("log.csv"),
        "t_s,psi_l_meas_rad,psi_r_meas_rad,speed_meas_mps\n0,0,0,10\n0.001,0,0,10\n",
    )
    .unwrap();
    let _held = hold_folder(&dir);
    let mut slow = Vec::new();
    for cmd in [
        &["bifurcation"][..],
        &["stability"],
        &["gas-charge"],
        &["sway-damping"],
        &["sensitivity"],
        &["vehicles"],
        &["reference-bench"],
        &["sweep"],
        &["sweep", "--controllers", "off,asmc"],
        &["compare"],
        &["run", "s.toml"],
        &["pil", "pil.toml"],
        &["margin"],
        &["meter-accuracy"],
        &["mismatch"],
        &["identifiability"],
        &["faults"],
        &["report"],
        &["analyze", "log.csv"],
    ] {
        let mut args = cmd.to_vec();
        args.extend(["--out", "o"]);
        let Some((ok, stdout, stderr)) = run_within(&dir, &args, Duration::from_secs(30)) else {
            slow.push(cmd[0]);
            continue;
        };
        assert!(!ok, "{cmd:?} wrote into a held folder: {stderr}");
        assert!(
            stderr.contains("output folder o") && stderr.contains("in use"),
            "{cmd:?}: {stderr}"
        );
        assert!(
            stdout.is_empty(),
            "{cmd:?} did its work before claiming its folder: it printed {:?} ...",
            stdout.lines().next()
        );
        assert_eq!(names(&dir.join("o")), [".shimmy-sim.lock"], "{cmd:?}");
    }
    assert!(
        slow.is_empty(),
        "still running after 30 s with their folder held: {slow:?}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// Two runs into one folder at once, the second started while the first works: the second is
/// refused naming the folder, and the folder holds the first run's files only (both used to
/// exit 0, leaving the campaigns' files mixed in one folder).
#[test]
fn of_two_runs_into_one_folder_at_once_the_second_is_refused() {
    let dir = temp_dir("files-two");
    let first = Command::new(env!("CARGO_BIN_EXE_shimmy-sim"))
        .args(["mismatch", "--only", "C_a -20", "--out", "o"])
        .current_dir(&dir)
        .env("RUST_BACKTRACE", "0")
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // The first run's claim creates the lock file and locks it at once; its study then takes
    // seconds.
    let start = Instant::now();
    while !dir.join("o/.shimmy-sim.lock").exists() {
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "the first run never claimed its folder"
        );
        std::thread::sleep(Duration::from_millis(5));
    }
    let second = run_in(&dir, &["faults", "--speeds-kmh", "45", "--out", "o"]);
    let first = first.wait_with_output().unwrap();
    assert!(first.status.success(), "{}", stderr(&first));
    let err = stderr(&second);
    assert!(
        !second.status.success(),
        "both runs wrote the folder: {:?}",
        names(&dir.join("o"))
    );
    assert!(
        err.contains("output folder o") && err.contains("in use"),
        "{err}"
    );
    assert_eq!(
        names(&dir.join("o")),
        [
            ".shimmy-sim.lock",
            "mismatch.csv",
            "mismatch.md",
            "summary.json"
        ]
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn input_files_over_the_size_limit_are_refused_naming_the_file_and_the_limit() {
    let dir = temp_dir("files-big");
    // Sparse files one byte over each limit: nothing of them is read.
    let big = |name: &str, len: u64| {
        let f = std::fs::File::create(dir.join(name)).unwrap();
        f.set_len(len).unwrap();
    };
    big("big.toml", (4 << 20) + 1);
    big("big.csv", (1 << 30) + 1);
    for (args, file, limit) in [
        (&["run", "big.toml"][..], "big.toml", "4 MiB"),
        (&["params", "big.toml"][..], "big.toml", "4 MiB"),
        (
            &["analyze", "big.csv", "--out", "a"][..],
            "big.csv",
            "1024 MiB",
        ),
    ] {
        let o = run_in(&dir, args);
        let err = stderr(&o);
        assert!(!o.status.success(), "{args:?}: {err}");
        assert!(
            err.contains(file) && err.contains("larger than the limit") && err.contains(limit),
            "{args:?}: {err}"
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// An endless input (a symlink to `/dev/zero`) is refused at the limit, not read until the
/// memory runs out.
#[cfg(target_os = "linux")]
#[test]
fn an_endless_input_file_is_refused_at_the_limit() {
    let dir = temp_dir("files-endless");
    std::os::unix::fs::symlink("/dev/zero", dir.join("zero.toml")).unwrap();
    let o = run_in(&dir, &["run", "zero.toml"]);
    let err = stderr(&o);
    assert!(!o.status.success());
    assert!(
        err.contains("zero.toml") && err.contains("larger than the limit of 4 MiB"),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// The disk fills up while the trace is written (a file-size limit of 32 KiB stands in for a
/// full disk: the write fails the same way, part-way through): the error names the file and no
/// truncated trace is left.
#[cfg(target_os = "linux")]
#[test]
fn a_full_disk_names_the_file_and_leaves_no_truncated_one() {
    let dir = temp_dir("files-full");
    std::fs::write(dir.join("s.toml"), SCENARIO).unwrap();
    // SIGXFSZ ignored: the write over the limit fails with EFBIG instead of killing the run.
    let o = std::process::Command::new("sh")
        .arg("-c")
        .arg(format!(
            "trap '' XFSZ; ulimit -f 64; exec '{}' run s.toml --out o",
            env!("CARGO_BIN_EXE_shimmy-sim")
        ))
        .current_dir(&dir)
        .env("RUST_BACKTRACE", "0")
        .output()
        .unwrap();
    let err = stderr(&o);
    assert!(!o.status.success(), "{err}");
    assert!(err.contains("writing o/trace.csv"), "{err}");
    assert_eq!(
        names(&dir.join("o")),
        [".shimmy-sim.lock"],
        "a truncated or temporary file was left"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// The standard output on a full disk (`/dev/full`): the printed table fails with an error
/// naming where it went and exit status 1 (it was a panic inside the standard library, 101).
#[cfg(target_os = "linux")]
#[test]
fn a_full_standard_output_is_an_error_naming_it() {
    let o = Command::new(env!("CARGO_BIN_EXE_shimmy-sim"))
        .arg("params")
        .env("RUST_BACKTRACE", "0")
        .stdout(OpenOptions::new().write(true).open("/dev/full").unwrap())
        .output()
        .unwrap();
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains("writing the standard output (/dev/full)")
            && err.contains("No space left on device")
            && !err.contains("panicked"),
        "{err}"
    );
}
