//! The host link end to end under QEMU: the firmware application (`qemu,link-e2e`: the QEMU app
//! on its simulated sensors, not ending by itself) with its USART1 on a TCP socket, and the host
//! tool (`shimmy-sim device --tcp`) against it:
//!
//! 1. `info`: the firmware's identity (and the ready handshake: QEMU starts the guest only once
//!    the tool is connected, and the tool waits for the ready frame);
//! 2. `config set` a changed vehicle file (the tool reads it back and compares bit for bit), then
//!    `config get` writes it as a vehicle TOML that holds the changed value;
//! 3. the application's simulated sensors run their scenario after that: the wheels shimmy at
//!    8 Hz and the encoder faults come at 1.3, 1.5 and 2.6 s (`firmware/src/sim.rs`); the tool
//!    polls `faults` until the scenario is over;
//! 4. `events --csv`: the log holds the shimmy episode and each injected fault, all later than
//!    the configuration write.
//!
//! Virtual time: `-icount shift=3,sleep=on`, deterministic instruction timing with idle time
//! paced by the host's clock, so the guest does not race through its scenario before the tool
//! has written the configuration (the QEMU app's other runs skip idle time, `qemu::APP_ICOUNT`).
//! Measured: the 4 s scenario spans about 20 s of the session; the step takes 25 s alone, 45 s
//! inside a full `cargo xtask test` on a loaded machine.

use crate::qemu;
use std::io::Read;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// The changed field of the vehicle the tool writes, and its value.
const CHANGED: (&str, &str, f64) = ("plant", "k_d", 4321.5);
/// The scenario is over after this uptime, ms (`sim::SCENARIO_STEPS` at 1 kHz).
const SCENARIO_MS: f64 = 4000.0;
/// The faults the scenario injects, as the supervisor names them.
const FAULTS: [&str; 3] = ["left-flag", "right-flag", "right-stuck"];

struct Qemu(Child);

impl Drop for Qemu {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

pub fn step() -> Result<String, String> {
    let elf = crate::build_firmware(crate::FIRMWARE, &["qemu", "link-e2e"])?;
    let tool = crate::host_build()?.join("shimmy-sim");
    let dir = crate::root().join("target/xtask/link-e2e");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).map_err(|e| format!("create {}: {e}", dir.display()))?;

    let port = free_port()?;
    let addr = format!("127.0.0.1:{port}");
    let mut child = Command::new("qemu-system-arm")
        .args(["-machine", "netduinoplus2", "-cpu", "cortex-m4"])
        .args(["-display", "none", "-monitor", "none"])
        .args(["-serial", &format!("tcp:{addr},server=on,wait=on")])
        .args(["-semihosting-config", "enable=on,target=native"])
        .args(["-icount", "shift=3,sleep=on"])
        .arg("-kernel")
        .arg(&elf)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| format!("cannot start qemu-system-arm: {e}"))?;
    let mut stdout = child.stdout.take().ok_or("no stdout pipe")?;
    let log_thread = std::thread::spawn(move || {
        let mut buf = Vec::new();
        let _ = stdout.read_to_end(&mut buf);
        buf
    });
    let guard = Qemu(child);
    let result = session(&tool, &addr, &dir);
    drop(guard);
    let raw = log_thread.join().map_err(|_| "log reader panicked")?;
    let elf_bytes = std::fs::read(&elf).map_err(|e| format!("read {}: {e}", elf.display()))?;
    let log = qemu::decode_defmt(&elf_bytes, &raw)?;
    if let Some(bad) = log
        .iter()
        .find(|l| l.contains("panic") || l.contains("HardFault"))
    {
        return Err(format!("the firmware failed during the session: {bad}"));
    }
    result
}

fn session(tool: &Path, addr: &str, dir: &Path) -> Result<String, String> {
    // 1. Identity: the first connection starts the guest; the tool waits for the ready frame.
    let info = device(tool, addr, &["--ready-s", "10", "info"])?;
    if !info.contains("shimmy-firmware") || !info.contains("car-4dof vehicles") {
        return Err(format!("unexpected identity:\n{info}"));
    }
    // Later connections find the device running (no ready frame): ask for the identity.
    let again = ["--ready-s", "0.1"];

    // 2. A changed vehicle, written, read back identical, and got as a vehicle file.
    let (section, name, value) = CHANGED;
    let set_file = dir.join("set.toml");
    std::fs::write(
        &set_file,
        format!("base = \"nominal\"\n[{section}]\n{name} = {value:?}\n"),
    )
    .map_err(|e| format!("write {}: {e}", set_file.display()))?;
    let set = device(
        tool,
        addr,
        &[&again[..], &["config", "set", path(&set_file)?]].concat(),
    )?;
    if !set.contains("read back identical") {
        return Err(format!("config set: {set}"));
    }
    let t_set_ms = uptime_ms(&device(tool, addr, &[&again[..], &["faults"]].concat())?)?;
    let got_file = dir.join("got.toml");
    device(
        tool,
        addr,
        &[&again[..], &["config", "get", "--out", path(&got_file)?]].concat(),
    )?;
    let got = std::fs::read_to_string(&got_file).map_err(|e| format!("read got.toml: {e}"))?;
    let line = format!("{name} = {value:?}");
    if !got.contains(&line) {
        return Err(format!("config get does not hold `{line}`:\n{got}"));
    }

    // 3. The scenario runs on (shimmy, then the encoder faults); wait until it is over.
    let start = Instant::now();
    loop {
        let f = device(tool, addr, &[&again[..], &["faults"]].concat())?;
        if uptime_ms(&f)? > SCENARIO_MS {
            break;
        }
        if start.elapsed() > Duration::from_secs(90) {
            return Err(format!("the scenario did not end within 90 s:\n{f}"));
        }
        std::thread::sleep(Duration::from_millis(100));
    }

    // 4. The log as CSV: the shimmy episode and each injected fault, after the write.
    let csv_file = dir.join("events.csv");
    device(
        tool,
        addr,
        &[&again[..], &["events", "--csv", path(&csv_file)?]].concat(),
    )?;
    let csv = std::fs::read_to_string(&csv_file).map_err(|e| format!("read events.csv: {e}"))?;
    check_events(&csv, t_set_ms)
}

/// The CSV holds a shimmy episode and every injected fault raised after `t_set_ms`.
fn check_events(csv: &str, t_set_ms: f64) -> Result<String, String> {
    let mut rows = csv.lines();
    let header: Vec<&str> = rows.next().ok_or("empty CSV")?.split(',').collect();
    let col = |n: &str| {
        header
            .iter()
            .position(|h| *h == n)
            .ok_or(format!("CSV has no column {n}"))
    };
    let (kind, start, level, fault) = (col("kind")?, col("start_s")?, col("level")?, col("fault")?);
    let rows: Vec<Vec<&str>> = rows.map(|r| r.split(',').collect()).collect();
    let shimmy = rows
        .iter()
        .find(|r| r.get(kind) == Some(&"shimmy"))
        .ok_or(format!("no shimmy episode in the log:\n{csv}"))?;
    for f in FAULTS {
        let row = rows
            .iter()
            .find(|r| r.get(kind) == Some(&"fault") && r.get(fault) == Some(&f))
            .ok_or(format!("fault {f} not in the log:\n{csv}"))?;
        let t: f64 = row
            .get(start)
            .and_then(|s| s.parse().ok())
            .ok_or(format!("bad start_s in {row:?}"))?;
        if t * 1e3 < t_set_ms {
            return Err(format!(
                "fault {f} at {t} s came before the configuration write at {} s",
                t_set_ms * 1e-3
            ));
        }
    }
    Ok(format!(
        "identity, config written and read back identical, {} log entries as CSV: shimmy episode ({}) and faults {}",
        rows.len(),
        shimmy.get(level).unwrap_or(&"?"),
        FAULTS.join(", ")
    ))
}

/// Runs `shimmy-sim device --tcp ADDR ARGS`; its standard output, or the error with stderr.
fn device(tool: &Path, addr: &str, args: &[&str]) -> Result<String, String> {
    let out = Command::new(tool)
        .args(["device", "--tcp", addr])
        .args(args)
        .output()
        .map_err(|e| format!("cannot run {}: {e}", tool.display()))?;
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    if !out.status.success() {
        return Err(format!(
            "shimmy-sim device {}: {}",
            args.join(" "),
            String::from_utf8_lossy(&out.stderr).trim()
        ));
    }
    println!("  $ shimmy-sim device --tcp {addr} {}", args.join(" "));
    for l in stdout.lines() {
        println!("  | {l}");
    }
    Ok(stdout)
}

/// The uptime line of `faults`, ms.
fn uptime_ms(faults: &str) -> Result<f64, String> {
    faults
        .lines()
        .find_map(|l| l.strip_prefix("uptime"))
        .and_then(|r| r.split_whitespace().next())
        .and_then(|s| s.parse::<f64>().ok())
        .map(|s| s * 1e3)
        .ok_or(format!("no uptime in:\n{faults}"))
}

fn path(p: &Path) -> Result<&str, String> {
    p.to_str()
        .ok_or(format!("path {} is not UTF-8", p.display()))
}

/// A TCP port nobody listens on now (QEMU binds it right after).
fn free_port() -> Result<u16, String> {
    let l = std::net::TcpListener::bind("127.0.0.1:0").map_err(|e| format!("bind: {e}"))?;
    l.local_addr().map(|a| a.port()).map_err(|e| e.to_string())
}
