//! The simulator's files under trouble, through the built binary: an output folder another run
//! is writing, an input file too large (or endless), a disk that fills up mid-write. Each is
//! refused with an error that names the file, and leaves no half-written file behind.

use crate::common::{run_in, temp_dir};
use std::fs::OpenOptions;
use std::path::Path;
use std::process::Output;

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
