//! Running a firmware ELF under QEMU (`netduinoplus2`, an STM32F405) with semihosting, always
//! inside a timeout, and decoding its defmt log with the table from the same ELF.

use std::io::Read;
use std::path::Path;
use std::process::{Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

const QEMU: &str = "qemu-system-arm";
/// Far longer than any of our images needs; a hung image is killed and the run fails.
const TIMEOUT: Duration = Duration::from_secs(120);

/// Installs qemu-system-arm with apt when it is missing and we are root; otherwise explains.
pub fn ensure_installed() -> Result<(), String> {
    if Command::new(QEMU)
        .arg("--version")
        .output()
        .is_ok_and(|o| o.status.success())
    {
        return Ok(());
    }
    crate::apt_install(
        "qemu-system-arm",
        &format!("{QEMU} is missing"),
        "install it with: apt-get install qemu-system-arm (Debian/Ubuntu)",
    )
}

/// Deterministic time for the application: 8 ns of virtual time per instruction (a 125 MIPS
/// core, roughly a 168 MHz Cortex-M4 with flash wait states), and idle time (WFI) skipped
/// instead of waited for, so a 2 s run of the 1 kHz loop takes well under a second and its
/// timing counters do not depend on the host's load.
pub const APP_ICOUNT: &[&str] = &["-icount", "shift=3,sleep=off"];

/// Instruction counting for the benchmark: 1 ns per instruction, so a timer clocked at QEMU's
/// 1 GHz counts instructions.
pub const BENCH_ICOUNT: &[&str] = &["-icount", "shift=0,sleep=off"];

/// What a QEMU run produced.
pub struct Run {
    /// QEMU's exit status (the semihosting exit code of the image).
    pub status: ExitStatus,
    /// Decoded defmt log, one line per frame, prefixed with its level.
    pub log: Vec<String>,
    /// Whatever QEMU itself printed on stderr.
    pub stderr: String,
}

impl Run {
    pub fn success(&self) -> bool {
        self.status.success()
    }

    pub fn print(&self) {
        for line in &self.log {
            println!("  | {line}");
        }
        if !self.stderr.trim().is_empty() {
            eprintln!("  qemu stderr: {}", self.stderr.trim());
        }
    }

    pub fn expect_success(&self) -> Result<(), String> {
        if self.success() {
            Ok(())
        } else {
            Err(format!("the image exited with {}", self.status))
        }
    }
}

/// Runs `elf` to completion (semihosting exit) or until the timeout, then decodes its log.
pub fn run(elf: &Path) -> Result<Run, String> {
    run_with(elf, &[])
}

/// [`run`] with extra QEMU arguments (e.g. `-icount shift=0` for deterministic instruction
/// counting).
pub fn run_with(elf: &Path, extra: &[&str]) -> Result<Run, String> {
    let elf_bytes = std::fs::read(elf).map_err(|e| format!("read {}: {e}", elf.display()))?;
    let mut child = Command::new(QEMU)
        .args(["-machine", "netduinoplus2", "-cpu", "cortex-m4"])
        .args(["-display", "none", "-monitor", "none", "-serial", "none"])
        .args(["-semihosting-config", "enable=on,target=native"])
        .args(extra)
        .arg("-kernel")
        .arg(elf)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| format!("cannot start {QEMU}: {e}"))?;

    // Drain both pipes on threads so a chatty image cannot block on a full pipe.
    let mut stdout = child.stdout.take().ok_or("no stdout pipe")?;
    let mut stderr = child.stderr.take().ok_or("no stderr pipe")?;
    let out_thread = std::thread::spawn(move || {
        let mut buf = Vec::new();
        let _ = stdout.read_to_end(&mut buf);
        buf
    });
    let err_thread = std::thread::spawn(move || {
        let mut buf = String::new();
        let _ = stderr.read_to_string(&mut buf);
        buf
    });

    let start = Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait().map_err(|e| e.to_string())? {
            break status;
        }
        if start.elapsed() > TIMEOUT {
            let _ = child.kill();
            let _ = child.wait();
            return Err(format!(
                "{} did not exit within {TIMEOUT:?} (hung?)",
                elf.display()
            ));
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    let raw = out_thread.join().map_err(|_| "stdout reader panicked")?;
    let stderr = err_thread.join().map_err(|_| "stderr reader panicked")?;
    let log = decode_defmt(&elf_bytes, &raw)?;
    Ok(Run {
        status,
        log,
        stderr,
    })
}

/// Decodes a defmt byte stream with the table of the ELF that produced it (the one decoder,
/// shared with `shimmy-sim pil`).
pub fn decode_defmt(elf: &[u8], stream: &[u8]) -> Result<Vec<String>, String> {
    shimmy_pil::defmt_log::decode(elf, stream)
}

/// Checks the supervisor's story in the application's decoded log: the mode changes it logged
/// (`supervisor: mode A -> B`) must chain and give exactly the sequence the simulated scenario
/// announces (`scenario: expected supervisor modes a b c`, `firmware/src/sim.rs`), it must
/// pass through `fail-safe` and end in `normal`, and every fault raised must be cleared again.
pub fn check_supervisor(log: &[String]) -> Result<String, String> {
    let expected: Vec<&str> = log
        .iter()
        .find_map(|l| l.split_once("scenario: expected supervisor modes "))
        .map(|(_, m)| m.split_whitespace().collect())
        .ok_or("the run did not announce its expected supervisor modes")?;
    let mut seen: Vec<&str> = Vec::new();
    for l in log {
        let Some((_, rest)) = l.split_once("supervisor: mode ") else {
            continue;
        };
        let (from, to) = rest
            .split_once(" -> ")
            .ok_or_else(|| format!("unreadable mode change: {l}"))?;
        match seen.last() {
            None => seen.push(from.trim()),
            Some(prev) if *prev != from.trim() => {
                return Err(format!("mode change from {from} but the mode was {prev}"))
            }
            Some(_) => {}
        }
        seen.push(to.trim());
    }
    if seen != expected {
        return Err(format!("supervisor modes {seen:?}, expected {expected:?}"));
    }
    if !seen.contains(&"fail-safe") || seen.last() != Some(&"normal") {
        return Err(format!(
            "the supervisor must reach fail-safe and recover to normal: {seen:?}"
        ));
    }
    let count = |what: &str| {
        let mut v: Vec<String> = log
            .iter()
            .filter_map(|l| l.split_once("supervisor: fault "))
            .filter_map(|(_, r)| r.strip_suffix(what))
            .map(|k| k.trim().to_string())
            .collect();
        v.sort();
        v
    };
    let (raised, cleared) = (count(" raised"), count(" cleared"));
    if raised.is_empty() || raised != cleared {
        return Err(format!("faults raised {raised:?} but cleared {cleared:?}"));
    }
    Ok(format!(
        "supervisor modes {} ({} faults raised and cleared)",
        seen.join(" -> "),
        raised.len()
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn log(s: &str) -> Vec<String> {
        s.lines().map(str::to_string).collect()
    }

    #[test]
    fn supervisor_story_is_checked() {
        let good = "WARN supervisor: fault left-flag raised\n\
                    WARN supervisor: mode normal -> fail-safe\n\
                    INFO supervisor: fault left-flag cleared\n\
                    WARN supervisor: mode fail-safe -> normal\n\
                    INFO scenario: expected supervisor modes normal fail-safe normal";
        assert!(check_supervisor(&log(good)).is_ok());
        // Not recovered.
        let stuck = "WARN supervisor: fault left-flag raised\n\
                     WARN supervisor: mode normal -> fail-safe\n\
                     INFO scenario: expected supervisor modes normal fail-safe";
        assert!(check_supervisor(&log(stuck)).is_err());
        // A different sequence than announced.
        let other = good.replace(
            "modes normal fail-safe normal",
            "modes normal degraded normal",
        );
        assert!(check_supervisor(&log(&other)).is_err());
        // A fault that never clears.
        let open = good.replace("INFO supervisor: fault left-flag cleared", "");
        assert!(check_supervisor(&log(&open)).is_err());
        // No announcement.
        assert!(check_supervisor(&log("WARN supervisor: mode normal -> fail-safe")).is_err());
    }
}
