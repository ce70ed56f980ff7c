//! Processor in the loop: the firmware image under QEMU (`netduinoplus2`, `-icount
//! shift=0,sleep=off`) closes the simulator's loop in lockstep, in place of the in-process
//! `SafeController` ([`closed_loop::run_on`](crate::sim::run::closed_loop::run_on)); the frames are
//! `shimmy_pil`'s, the image is built with the firmware's `pil` feature (`board/pil.rs`).
//!
//! - [`Qemu`]: the QEMU process with its two named pipes in a fresh directory (QEMU's working
//!   directory, where the image opens them by name; read here with `poll`, so a silent image
//!   is noticed), its defmt log (semihosting stdout) and stderr collected on threads. It is killed when dropped, and with `PR_SET_PDEATHSIG` also
//!   when this process dies without unwinding: never an orphan QEMU.
//! - [`PilFirmware`]: one [`FirmwareStep`] per control period over that link: sends the sensor
//!   frame, collects the image's frames up to its step report ([`Period`]); a missing answer
//!   within [`FRAME_TIMEOUT`] is an error that carries the last frames and the decoded log.
//! - [`SilFirmware`]: the same application's tasks natively (`shimmy_firmware::pil::HostApp`),
//!   the software-in-the-loop side; [`compare`] checks the two runs bit for bit.

use crate::model::board::BoardModel;
use crate::model::family::FamilyVehicle;
use crate::model::registry::{image_elfs, schema_model};
use crate::sim::input::vehicle_file::FileModel;
use crate::sim::run::closed_loop::{Arm, FirmwareStep, LoopConfig};
use shimmy_core::model::{LinearModel, UpdatableModel};
use shimmy_core::supervisor::checks::Supervisor;
use shimmy_core::supervisor::frame::RawFrame;
use shimmy_core::supervisor::safe_controller::SafeOutput;
use shimmy_core::vehicle::BoardVehicle;
use shimmy_firmware::monitoring::{BoardCalibration, CONTROLLER};
use shimmy_firmware::pil::HostApp;
use shimmy_pil::{
    body_len, decode, encode, HostFrame, StepReport, TargetFrame, HEADER_BYTES, MAX_FRAME,
};
use std::collections::VecDeque;
use std::fs::File;
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// The QEMU binary, from the Debian package of the same name.
pub const QEMU: &str = "qemu-system-arm";
/// Longest wait for the image's next frame (a step takes microseconds of host time): past it
/// the image is taken as hung.
pub const FRAME_TIMEOUT: Duration = Duration::from_secs(10);
/// Frames kept for the diagnosis of a hang or crash.
const LAST_FRAMES: usize = 12;
/// Decoded log lines shown with a hang or crash.
const LAST_LOG_LINES: usize = 40;

/// A vehicle model a PIL image is built for ([`BoardModel`]) whose vehicle files the
/// simulator reads.
pub trait PilModel<const N: usize>: FileModel<N> + BoardModel<N> {}

impl<M: FileModel<N> + BoardModel<N>, const N: usize> PilModel<N> for M {}

/// The image runs the firmware's own controller and parameters
/// (`shimmy_firmware::monitoring::CONTROLLER`, the margin-scheduled ASMC; its compiled-in
/// vehicle, [`BoardVehicle::compiled_in`]: its controller, supervisor and model-margin model):
/// a loop whose firmware believes anything else (`believed`) cannot be closed by it.
pub fn check_firmware_matches<M: PilModel<N>, const N: usize>(
    cfg: &LoopConfig<M, N>,
    believed: &FamilyVehicle<M>,
) -> Result<(), String> {
    let image = Arm::Mr(CONTROLLER);
    if cfg.arm != image {
        return Err(format!(
            "field `controller.kind`: `{}`, but the PIL image runs `{}`",
            cfg.arm.name(),
            image.name()
        ));
    }
    let compiled_in = M::Board::compiled_in();
    if M::board_vehicle(believed) != compiled_in
        || cfg.control != compiled_in.controller_params()
        || cfg.supervisor != compiled_in.supervisor_params()
    {
        return Err(format!(
            "fields `[model]` (else `[plant]`): the firmware must believe the default {} \
             vehicle the image is built with",
            <M::Linear as LinearModel<N>>::NAME
        ));
    }
    Ok(())
}

/// What the image sent in one control period: its step report, then the frames of its
/// lower-priority tasks before the next step.
#[derive(Clone, Debug)]
pub struct Period {
    /// The control task's report.
    pub step: StepReport,
    /// The meter task's and the background loop's frames that followed it.
    pub after: Vec<TargetFrame>,
}

/// The QEMU process of one PIL run and its link.
pub struct Qemu {
    child: Child,
    dir: PathBuf,
    to_image: File,
    from_image: File,
    /// Bytes read from `pil.out` and not yet taken as frames.
    pending: Vec<u8>,
    stdout: Arc<Mutex<Vec<u8>>>,
    stderr: Arc<Mutex<String>>,
    elf: Vec<u8>,
}

fn mkfifo(path: &Path) -> Result<(), String> {
    use std::os::unix::ffi::OsStrExt;
    let c = std::ffi::CString::new(path.as_os_str().as_bytes())
        .map_err(|_| format!("{}: NUL in the path", path.display()))?;
    // SAFETY: `c` is a valid NUL-terminated path.
    if unsafe { libc::mkfifo(c.as_ptr(), 0o600) } == 0 {
        Ok(())
    } else {
        Err(format!(
            "mkfifo {}: {}",
            path.display(),
            std::io::Error::last_os_error()
        ))
    }
}

/// Opens a FIFO read-write: on Linux that never blocks, whether or not QEMU has its end open,
/// so a QEMU that dies before opening cannot hang the host.
fn open_fifo(path: &Path) -> Result<File, String> {
    std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .open(path)
        .map_err(|e| format!("open {}: {e}", path.display()))
}

/// Takes the first complete frame off `pending`, if there is one.
fn take_frame(pending: &mut Vec<u8>) -> Result<Option<TargetFrame>, String> {
    let [a, b, ..] = pending[..] else {
        return Ok(None);
    };
    let n = body_len([a, b]).map_err(|e| format!("image frame: {e}"))?;
    if pending.len() < HEADER_BYTES + n {
        return Ok(None);
    }
    let f =
        decode(&pending[HEADER_BYTES..HEADER_BYTES + n]).map_err(|e| format!("image frame: {e}"));
    pending.drain(..HEADER_BYTES + n);
    f.map(Some)
}

/// Waits up to `ms` for `f` to be readable.
fn readable(f: &File, ms: i32) -> Result<bool, String> {
    use std::os::fd::AsRawFd;
    let mut p = libc::pollfd {
        fd: f.as_raw_fd(),
        events: libc::POLLIN,
        revents: 0,
    };
    // SAFETY: one valid pollfd.
    match unsafe { libc::poll(&mut p, 1, ms) } {
        n if n < 0 => {
            let e = std::io::Error::last_os_error();
            if e.kind() == std::io::ErrorKind::Interrupted {
                Ok(false)
            } else {
                Err(format!("poll pil.out: {e}"))
            }
        }
        n => Ok(n > 0 && p.revents & libc::POLLIN != 0),
    }
}

fn drain<R: Read + Send + 'static>(mut r: R) -> JoinHandle<Vec<u8>> {
    std::thread::spawn(move || {
        let mut buf = Vec::new();
        let _ = r.read_to_end(&mut buf);
        buf
    })
}

impl Qemu {
    /// Starts `elf` (a `pil` build) under [`QEMU`] with its pipes in a new directory.
    pub fn start(elf: &Path) -> Result<Self, String> {
        Self::start_program(QEMU, elf)
    }

    fn start_program(qemu: &str, elf: &Path) -> Result<Self, String> {
        let elf_bytes =
            crate::sim::input::files::read_bytes(elf, crate::sim::input::files::DATA_LIMIT)
                .map_err(|e| format!("PIL image: {e:#}"))?;
        static RUN: std::sync::atomic::AtomicU32 = std::sync::atomic::AtomicU32::new(0);
        let n = RUN.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let dir = std::env::temp_dir().join(format!("shimmy-pil-{}-{n}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).map_err(|e| format!("create {}: {e}", dir.display()))?;
        let (fifo_in, fifo_out) = (dir.join("pil.in"), dir.join("pil.out"));
        mkfifo(&fifo_in)?;
        mkfifo(&fifo_out)?;
        let to_image = open_fifo(&fifo_in)?;
        let from_image = open_fifo(&fifo_out)?;
        let elf_abs = std::fs::canonicalize(elf).map_err(|e| format!("{}: {e}", elf.display()))?;
        let mut cmd = Command::new(qemu);
        cmd.args(["-machine", "netduinoplus2", "-cpu", "cortex-m4"])
            .args(["-display", "none", "-monitor", "none", "-serial", "none"])
            .args(["-semihosting-config", "enable=on,target=native"])
            .args(["-icount", "shift=0,sleep=off"])
            .arg("-kernel")
            .arg(&elf_abs)
            .current_dir(&dir)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped());
        // SAFETY: only an async-signal-safe prctl between fork and exec.
        unsafe {
            use std::os::unix::process::CommandExt;
            cmd.pre_exec(|| {
                // QEMU dies with this process, even when it is killed without unwinding.
                libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGKILL);
                Ok(())
            });
        }
        let mut child = cmd.spawn().map_err(|e| match e.kind() {
            std::io::ErrorKind::NotFound => format!(
                "{qemu} not found: install the Debian package `qemu-system-arm` (apt-get install qemu-system-arm)"
            ),
            _ => format!("cannot start {qemu}: {e}"),
        })?;
        let stdout = Arc::new(Mutex::new(Vec::new()));
        let stderr = Arc::new(Mutex::new(String::new()));
        if let Some(mut out) = child.stdout.take() {
            let sink = Arc::clone(&stdout);
            std::thread::spawn(move || {
                let mut buf = [0u8; 4096];
                while let Ok(n) = out.read(&mut buf) {
                    if n == 0 {
                        break;
                    }
                    if let Ok(mut s) = sink.lock() {
                        s.extend_from_slice(&buf[..n]);
                    }
                }
            });
        }
        if let Some(err) = child.stderr.take() {
            let sink = Arc::clone(&stderr);
            std::thread::spawn(move || {
                let text = drain(err).join().unwrap_or_default();
                if let Ok(mut s) = sink.lock() {
                    s.push_str(&String::from_utf8_lossy(&text));
                }
            });
        }
        Ok(Qemu {
            child,
            dir,
            to_image,
            from_image,
            pending: Vec::new(),
            stdout,
            stderr,
            elf: elf_bytes,
        })
    }

    fn send(&mut self, frame: &HostFrame) -> Result<(), String> {
        let mut buf = [0u8; MAX_FRAME];
        let bytes = encode(frame, &mut buf).map_err(|e| e.to_string())?;
        self.to_image
            .write_all(bytes)
            .map_err(|e| format!("writing to the image: {e}"))
    }

    /// Reads what `pil.out` holds now (after waiting up to `ms` for it); false if nothing.
    fn fill(&mut self, ms: i32) -> Result<bool, String> {
        if !readable(&self.from_image, ms)? {
            return Ok(false);
        }
        let mut buf = [0u8; 4096];
        let n = self
            .from_image
            .read(&mut buf)
            .map_err(|e| format!("reading pil.out: {e}"))?;
        self.pending.extend_from_slice(&buf[..n]);
        Ok(n > 0)
    }

    /// The next frame of the image, or why none came.
    fn next(&mut self) -> Result<TargetFrame, String> {
        let deadline = Instant::now() + FRAME_TIMEOUT;
        loop {
            if let Some(f) = take_frame(&mut self.pending)? {
                return Ok(f);
            }
            if self.fill(50)? {
                continue;
            }
            if let Ok(Some(status)) = self.child.try_wait() {
                return Err(format!("QEMU exited ({status}) in the middle of the run"));
            }
            if Instant::now() > deadline {
                return Err(format!(
                    "no frame from the image within {FRAME_TIMEOUT:?}: hung"
                ));
            }
        }
    }

    /// The image's defmt log so far, decoded.
    pub fn log(&self) -> Vec<String> {
        let raw = self.stdout.lock().map(|s| s.clone()).unwrap_or_default();
        shimmy_pil::defmt_log::decode(&self.elf, &raw)
            .unwrap_or_else(|e| vec![format!("(defmt log not decodable: {e})")])
    }

    fn stderr(&self) -> String {
        self.stderr.lock().map(|s| s.clone()).unwrap_or_default()
    }

    /// Waits up to [`FRAME_TIMEOUT`] for QEMU to exit.
    fn wait_exit(&mut self) -> Result<ExitStatus, String> {
        let deadline = Instant::now() + FRAME_TIMEOUT;
        loop {
            if let Some(s) = self.child.try_wait().map_err(|e| e.to_string())? {
                return Ok(s);
            }
            if Instant::now() > deadline {
                return Err(format!(
                    "QEMU did not exit within {FRAME_TIMEOUT:?} of the end of the run"
                ));
            }
            std::thread::sleep(Duration::from_millis(5));
        }
    }
}

impl Drop for Qemu {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

/// The firmware image under QEMU as the loop's supervised step.
pub struct PilFirmware {
    qemu: Qemu,
    periods: Vec<Period>,
    last: VecDeque<Seen>,
    finished: Option<u64>,
    host_cpu_at_start_s: f64,
}

/// A finished PIL run.
#[derive(Debug)]
pub struct PilRun {
    /// Every period's frames, in order.
    pub periods: Vec<Period>,
    /// The image's decoded defmt log.
    pub log: Vec<String>,
    /// Instructions the image executed from reset to the end of the run.
    pub instructions: Option<u64>,
    /// CPU time QEMU used (user + system), s.
    pub qemu_cpu_s: f64,
    /// CPU time this process used meanwhile (plant, sensors, frames; user + system), s.
    pub host_cpu_s: f64,
}

/// CPU time (user + system) of this process (`RUSAGE_SELF`) or of its waited-for children
/// (`RUSAGE_CHILDREN`), s.
fn cpu_s(who: libc::c_int) -> f64 {
    // SAFETY: an all-zero `rusage` is valid; getrusage fills it.
    let mut u: libc::rusage = unsafe { std::mem::zeroed() };
    // SAFETY: `u` is a valid, writable rusage.
    if unsafe { libc::getrusage(who, &mut u) } != 0 {
        return f64::NAN;
    }
    let s = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 * 1e-6;
    s(u.ru_utime) + s(u.ru_stime)
}

impl PilFirmware {
    /// Starts the image `elf` (a `pil` build) and takes its hello: the image must be built for
    /// the vehicle model whose record has the schema id `vehicle_schema`.
    pub fn start(elf: &Path, vehicle_schema: u32) -> Result<Self, String> {
        let host_cpu_at_start_s = cpu_s(libc::RUSAGE_SELF);
        let mut fw = PilFirmware {
            qemu: Qemu::start(elf)?,
            periods: Vec::new(),
            last: VecDeque::new(),
            finished: None,
            host_cpu_at_start_s,
        };
        let first = fw.qemu.next().map_err(|e| fw.failure(&e))?;
        fw.remember(Seen::Received(first));
        match first {
            TargetFrame::Hello { vehicle_schema: s } if s == vehicle_schema => Ok(fw),
            TargetFrame::Hello { vehicle_schema: s } => Err(format!(
                "the PIL image {} is built for the {} model, the scenario's vehicle is a {}: \
                 pass the image built for it (`cargo xtask pil` builds {})",
                elf.display(),
                schema_model(s),
                schema_model(vehicle_schema),
                image_elfs()
            )),
            other => Err(fw.failure(&format!(
                "the image's first frame is not its hello but {}",
                summary(&other)
            ))),
        }
    }

    fn remember(&mut self, what: Seen) {
        if self.last.len() == LAST_FRAMES {
            self.last.pop_front();
        }
        self.last.push_back(what);
    }

    /// A failure with what is known: the last frames, the decoded log's tail, QEMU's stderr.
    fn failure(&self, what: &str) -> String {
        let mut s = format!(
            "PIL run failed after {} step(s): {what}\n  last frames (oldest first):\n",
            self.periods.len()
        );
        for f in &self.last {
            s.push_str(&format!("    {}\n", f.line()));
        }
        let log = self.qemu.log();
        s.push_str(&format!(
            "  defmt log of the image (last {} of {} lines):\n",
            LAST_LOG_LINES.min(log.len()),
            log.len()
        ));
        for l in log.iter().skip(log.len().saturating_sub(LAST_LOG_LINES)) {
            s.push_str(&format!("    | {l}\n"));
        }
        let err = self.qemu.stderr();
        if !err.trim().is_empty() {
            s.push_str(&format!("  QEMU stderr: {}\n", err.trim()));
        }
        s
    }

    fn file(&mut self, f: TargetFrame) {
        self.remember(Seen::Received(f));
        match (f, self.periods.last_mut()) {
            (TargetFrame::Finished { instructions }, _) => self.finished = Some(instructions),
            (TargetFrame::Step(step), _) => self.periods.push(Period {
                step,
                after: Vec::new(),
            }),
            (other, Some(p)) => p.after.push(other),
            // Before the first step nothing else can come: the meter and model tasks start
            // from the first step's data.
            (other, None) => self.remember(Seen::Unexpected(other)),
        }
    }

    /// Ends the run: the image logs and exits through semihosting; its exit status must be
    /// success.
    pub fn finish(mut self) -> Result<PilRun, String> {
        self.qemu
            .send(&HostFrame::Finish)
            .map_err(|e| self.failure(&e))?;
        let status = self.qemu.wait_exit().map_err(|e| self.failure(&e))?;
        let host_cpu_s = cpu_s(libc::RUSAGE_SELF) - self.host_cpu_at_start_s;
        // QEMU is this run's only child process, and it has been waited for.
        let qemu_cpu_s = cpu_s(libc::RUSAGE_CHILDREN);
        // What the image wrote before it exited is in the pipe now.
        loop {
            match take_frame(&mut self.qemu.pending) {
                Ok(Some(f)) => self.file(f),
                Ok(None) => match self.qemu.fill(0) {
                    Ok(true) => {}
                    Ok(false) => break,
                    Err(e) => return Err(self.failure(&e)),
                },
                Err(e) => return Err(self.failure(&e)),
            }
        }
        if !status.success() {
            return Err(self.failure(&format!("the image exited with {status}")));
        }
        Ok(PilRun {
            log: self.qemu.log(),
            periods: std::mem::take(&mut self.periods),
            instructions: self.finished,
            qemu_cpu_s,
            host_cpu_s,
        })
    }
}

/// A frame of the link kept for the diagnosis of a failure (formatted only then: a line per
/// frame and step cost more host time than the plant).
#[derive(Clone, Copy, Debug)]
enum Seen {
    Sent(RawFrame),
    Received(TargetFrame),
    Unexpected(TargetFrame),
}

impl Seen {
    fn line(&self) -> String {
        match self {
            Seen::Sent(frame) => format!(
                "-> sensors t {} us: yaw {} / {} rad, {} m/s",
                frame.t_us, frame.left.angle_rad, frame.right.angle_rad, frame.speed_mps
            ),
            Seen::Received(f) => format!("<- {}", summary(f)),
            Seen::Unexpected(f) => format!("(unexpected before the first step: {f:?})"),
        }
    }
}

/// One line per frame for the diagnosis.
fn summary(f: &TargetFrame) -> String {
    match f {
        TargetFrame::Step(s) => format!(
            "step {}: command {} A, mode {}, faults {:#x}, {} instructions",
            s.step,
            s.out.current_cmd_a,
            s.out.verdict.mode.name(),
            s.out.verdict.faults.bits(),
            s.instructions
        ),
        TargetFrame::Margin(m) => format!(
            "margin at step {}: t {} s, zeta {} (valid {}), level {:?}",
            m.step, m.report.t_s, m.report.zeta_data, m.report.valid, m.level
        ),
        TargetFrame::MeterRun { step, instructions } => {
            format!("meter run of step {step}: {instructions} instructions")
        }
        TargetFrame::Model(m) => format!(
            "model cycle {}: zeta {}, onset {:?} m/s, {} instructions",
            m.cycle, m.margin.zeta, m.margin.v_crit_onset_mps, m.instructions
        ),
        TargetFrame::Finished { instructions } => {
            format!("finished after {instructions} instructions")
        }
        TargetFrame::Hello { vehicle_schema } => {
            format!(
                "hello: built for the {} model",
                schema_model(*vehicle_schema)
            )
        }
    }
}

impl FirmwareStep for PilFirmware {
    type Error = String;

    fn step(&mut self, frame: &RawFrame) -> Result<SafeOutput, String> {
        self.remember(Seen::Sent(*frame));
        self.qemu
            .send(&HostFrame::Sensors(*frame))
            .map_err(|e| self.failure(&e))?;
        loop {
            let f = self.qemu.next().map_err(|e| self.failure(&e))?;
            let out = match &f {
                TargetFrame::Step(s) => Some(s.out),
                _ => None,
            };
            self.file(f);
            if let Some(out) = out {
                return Ok(out);
            }
        }
    }

    fn supervisor(&mut self) -> Option<&mut Supervisor> {
        None
    }
}

/// The application's tasks natively, as the loop's supervised step: the SIL side. The model
/// margin each meter run fuses is taken from the PIL run's frames when given (when a cycle of
/// the background loop completes depends on its instruction count, known only on the target;
/// the values are computed here).
pub struct SilFirmware<'a, L: UpdatableModel<N>, const N: usize> {
    app: HostApp<L, N>,
    pil: Option<&'a [Period]>,
    periods: Vec<Period>,
}

impl<'a, L: UpdatableModel<N>, const N: usize> SilFirmware<'a, L, N> {
    /// The application after a power-on with the compiled-in vehicle of `V` (the image boots
    /// with an empty RAM flash); `pil`: the PIL run to take the model timing from.
    pub fn new<V: BoardVehicle<N, Model = L> + BoardCalibration>(
        pil: Option<&'a [Period]>,
    ) -> Result<Self, String> {
        Ok(SilFirmware {
            app: HostApp::new(&V::compiled_in())
                .map_err(|e| format!("estimator configuration: {e:?}"))?,
            pil,
            periods: Vec::new(),
        })
    }

    /// Every period's frames.
    pub fn periods(self) -> Vec<Period> {
        self.periods
    }
}

impl<L: UpdatableModel<N>, const N: usize> FirmwareStep for SilFirmware<'_, L, N> {
    type Error = String;

    fn step(&mut self, frame: &RawFrame) -> Result<SafeOutput, String> {
        let k = self.periods.len();
        let model_cycles = self.pil.and_then(|p| p.get(k)).and_then(|p| {
            p.after.iter().find_map(|f| match f {
                TargetFrame::Margin(m) => Some(m.model_cycles),
                _ => None,
            })
        });
        let mut frames = Vec::new();
        let _ = self
            .app
            .period(frame, model_cycles, &mut |f| frames.push(f));
        let mut it = frames.into_iter();
        let Some(TargetFrame::Step(step)) = it.next() else {
            return Err("the host app did not start the period with a step report".into());
        };
        self.periods.push(Period {
            step,
            after: it.collect(),
        });
        Ok(step.out)
    }

    fn supervisor(&mut self) -> Option<&mut Supervisor> {
        None
    }
}

/// What the two runs have in common, when they agree.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Agreement {
    /// Control steps compared (coil command, verdict, validated inputs, controller output).
    pub steps: usize,
    /// Margin updates compared (the fused report and the warning level).
    pub margin_updates: usize,
    /// Model-margin cycles compared.
    pub model_cycles: usize,
}

fn bits<T: serde::Serialize>(x: &T) -> Vec<u8> {
    let mut buf = [0u8; MAX_FRAME];
    encode(x, &mut buf).map(<[u8]>::to_vec).unwrap_or_default()
}

/// Compares a PIL run with a SIL run of the same scenario bit for bit (the floats' bit
/// patterns, through their encoding): each step's `SafeOutput`, each margin update (report,
/// level, in the same period), each meter run, each model cycle's margin (in order: when a
/// cycle completes is target timing, not a result). Instruction counts are not compared.
pub fn compare(pil: &[Period], sil: &[Period]) -> Result<Agreement, String> {
    if pil.len() != sil.len() {
        return Err(format!(
            "{} PIL steps but {} SIL steps",
            pil.len(),
            sil.len()
        ));
    }
    let mut a = Agreement::default();
    let models = |ps: &[Period]| -> Vec<_> {
        ps.iter()
            .flat_map(|p| &p.after)
            .filter_map(|f| match f {
                TargetFrame::Model(m) => Some((m.cycle, m.margin)),
                _ => None,
            })
            .collect()
    };
    for (k, (p, s)) in pil.iter().zip(sil).enumerate() {
        if p.step.step != s.step.step || bits(&p.step.out) != bits(&s.step.out) {
            return Err(format!(
                "period {k}: the step reports differ\n  PIL: {:?}\n  SIL: {:?}",
                p.step, s.step
            ));
        }
        a.steps += 1;
        let rest = |x: &Period| -> Vec<Vec<u8>> {
            x.after
                .iter()
                .filter_map(|f| match f {
                    TargetFrame::Margin(m) => Some(bits(m)),
                    TargetFrame::MeterRun { step, .. } => Some(bits(step)),
                    _ => None,
                })
                .collect()
        };
        if rest(p) != rest(s) {
            return Err(format!(
                "period {k} (step {}): the meter task's output differs\n  PIL: {:?}\n  SIL: {:?}",
                p.step.step, p.after, s.after
            ));
        }
        a.margin_updates += p
            .after
            .iter()
            .filter(|f| matches!(f, TargetFrame::Margin(_)))
            .count();
    }
    let (mp, ms) = (models(pil), models(sil));
    for (i, (p, s)) in mp.iter().zip(&ms).enumerate() {
        if p.0 != s.0 || bits(&p.1) != bits(&s.1) {
            return Err(format!(
                "model cycle {}: the model margins differ\n  PIL: {p:?}\n  SIL: {s:?}",
                i + 1
            ));
        }
    }
    // The SIL completes each cycle at once; the target may still be in its last one.
    if ms.len() < mp.len() || ms.len() > mp.len() + 1 {
        return Err(format!(
            "{} model cycles on the target, {} on the host",
            mp.len(),
            ms.len()
        ));
    }
    a.model_cycles = mp.len();
    Ok(a)
}

/// Instruction counts of one task (QEMU `-icount shift=0`: one per executed instruction).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TaskCost {
    /// Per run, in order.
    pub counts: Vec<u32>,
}

impl TaskCost {
    /// Largest count.
    pub fn max(&self) -> u32 {
        self.counts.iter().copied().max().unwrap_or(0)
    }

    /// The `q` quantile (nearest rank), e.g. 0.99.
    pub fn quantile(&self, q: f64) -> u32 {
        let mut v = self.counts.clone();
        v.sort_unstable();
        if v.is_empty() {
            return 0;
        }
        let rank = ((q * v.len() as f64).ceil() as usize).clamp(1, v.len());
        v[rank - 1]
    }

    /// Sum of all counts.
    pub fn total(&self) -> u64 {
        self.counts.iter().map(|&c| u64::from(c)).sum()
    }

    /// Share of a `clock_hz` CPU at one cycle per instruction over `seconds`.
    pub fn cpu_share(&self, seconds: f64, clock_hz: f64) -> f64 {
        self.total() as f64 / seconds / clock_hz
    }

    /// `bins` equal-width bins from the minimum to the maximum: (lower edge, upper edge, count).
    pub fn histogram(&self, bins: usize) -> Vec<(u32, u32, usize)> {
        let (Some(&lo), Some(&hi)) = (self.counts.iter().min(), self.counts.iter().max()) else {
            return Vec::new();
        };
        let bins = bins.max(1);
        let width = ((hi - lo) as usize / bins + 1) as u32;
        let mut h: Vec<(u32, u32, usize)> = (0..bins as u32)
            .map(|i| (lo + i * width, lo + (i + 1) * width - 1, 0))
            .collect();
        for &c in &self.counts {
            let i = (((c - lo) / width) as usize).min(bins - 1);
            h[i].2 += 1;
        }
        h
    }
}

/// The three tasks' instruction counts of a PIL run.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Costs {
    /// The 1 kHz control task, per step.
    pub control: TaskCost,
    /// The 100 Hz meter task, per run.
    pub meter: TaskCost,
    /// The background model loop, per completed cycle.
    pub model: TaskCost,
}

/// The instruction counts of a PIL run's frames.
pub fn costs(periods: &[Period]) -> Costs {
    let mut c = Costs::default();
    for p in periods {
        c.control.counts.push(p.step.instructions);
        for f in &p.after {
            match f {
                TargetFrame::MeterRun { instructions, .. } => c.meter.counts.push(*instructions),
                TargetFrame::Model(m) => c.model.counts.push(m.instructions),
                _ => {}
            }
        }
    }
    c
}

#[cfg(test)]
mod tests {
    use super::*;
    use shimmy_core::vehicle::Vehicle;

    #[test]
    fn quantiles_histogram_and_share() {
        let t = TaskCost {
            counts: (1..=100).collect(),
        };
        assert_eq!((t.max(), t.quantile(0.99), t.quantile(0.5)), (100, 99, 50));
        let h = t.histogram(4);
        assert_eq!(h.iter().map(|b| b.2).sum::<usize>(), 100);
        assert_eq!((h[0].0, h[3].1 >= 100), (1, true));
        // 5050 instructions in 1 s of a 1 kHz clock: 5.05 times the CPU.
        assert!((t.cpu_share(1.0, 1000.0) - 5.05).abs() < 1e-12);
    }

    fn period(step: u32, cmd: f32) -> Period {
        let out = SafeOutput {
            current_cmd_a: cmd,
            ..SafeOutput::default()
        };
        Period {
            step: StepReport {
                step,
                out,
                instructions: 1000 + step,
            },
            after: Vec::new(),
        }
    }

    /// One ulp in one command is a disagreement; instruction counts are not compared.
    #[test]
    fn compare_is_bit_exact_and_ignores_instruction_counts() {
        let a: Vec<_> = (0..5).map(|k| period(k, 0.5)).collect();
        let mut b = a.clone();
        b[2].step.instructions = 7;
        assert_eq!(compare(&a, &b).map(|x| x.steps), Ok(5));
        b[3].step.out.current_cmd_a = f32::from_bits(0.5f32.to_bits() + 1);
        let e = compare(&a, &b).expect_err("one ulp differs");
        assert!(e.contains("period 3"), "{e}");
    }

    /// A margin report, a warning level or a model margin one bit off is a disagreement too; a
    /// model cycle the target has not finished yet at the end is not.
    #[test]
    fn compare_checks_margin_updates_and_model_cycles() {
        use shimmy_core::estimator::monitor::Level;
        use shimmy_pil::{MarginFrame, ModelFrame};
        let margin = TargetFrame::Margin(MarginFrame {
            step: 9,
            report: Default::default(),
            level: Level::Normal,
            model_cycles: 0,
        });
        let model = |cycle| {
            TargetFrame::Model(ModelFrame {
                cycle,
                margin: Default::default(),
                instructions: 5,
            })
        };
        let mut a: Vec<_> = (0..3).map(|k| period(k, 0.0)).collect();
        a[1].after = vec![margin, model(1)];
        let mut b = a.clone();
        b[2].after.push(model(2));
        assert_eq!(
            compare(&a, &b).map(|x| (x.margin_updates, x.model_cycles)),
            Ok((1, 1))
        );
        let mut c = a.clone();
        if let TargetFrame::Margin(m) = &mut c[1].after[0] {
            m.report.zeta_data = f32::from_bits(1);
        }
        let e = compare(&a, &c).expect_err("report differs");
        assert!(e.contains("meter task"), "{e}");
        let mut d = a.clone();
        if let TargetFrame::Margin(m) = &mut d[1].after[0] {
            m.level = Level::MarginLow;
        }
        assert!(compare(&a, &d).is_err());
        let mut m = a.clone();
        m[1].after[1] = TargetFrame::Model(ModelFrame {
            cycle: 1,
            margin: shimmy_core::estimator::model_margin::ModelMargin {
                zeta: f64::from_bits(1),
                ..Default::default()
            },
            instructions: 5,
        });
        let e = compare(&a, &m).expect_err("model differs");
        assert!(e.contains("model cycle 1"), "{e}");
    }

    /// The PIL demo is valid and fits the image; another controller or vehicle is refused,
    /// naming the field.
    #[test]
    fn the_demo_fits_the_image_and_other_firmware_beliefs_do_not() {
        use crate::sim::run::{scenario, scenario_file};
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenarios/pil/demo.toml");
        let mut spec = scenario_file::load(&path).expect("valid demo");
        let cfg = scenario::loop_config(&spec, spec.arm().expect("arm"));
        assert_eq!(check_firmware_matches(&cfg, &spec.model_family()), Ok(()));
        assert!(!spec.faults.is_empty() && spec.duration_s >= 10.0);
        for other in ["smc", "asmc"] {
            spec.controller = other.into();
            let cfg = scenario::loop_config(&spec, spec.arm().expect("arm"));
            let e = check_firmware_matches(&cfg, &spec.model_family()).expect_err(other);
            assert!(
                e.contains("controller.kind") && e.contains("margin-asmc"),
                "{e}"
            );
        }
        spec.controller = "margin-asmc".into();
        spec.model_vehicle =
            Some(crate::sim::input::vehicle_file::load("hard").expect("named set"));
        let cfg = scenario::loop_config(&spec, spec.arm().expect("arm"));
        let e = check_firmware_matches(&cfg, &spec.model_family()).expect_err("hard");
        assert!(e.contains("[model]"), "{e}");
    }

    /// The simulator's own closed loop on the margin-scheduled arm is the firmware's
    /// application (SIL, with each model cycle done at once): the same command on every step,
    /// bit for bit, so the simulator's studies show what the image does.
    #[test]
    fn the_simulators_closed_loop_runs_the_firmware_app() {
        use crate::sim::run::closed_loop::{self, run_on};
        use crate::sim::run::{scenario, scenario_file};
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenarios/pil/demo.toml");
        let mut spec = scenario_file::load(&path).expect("valid demo");
        spec.duration_s = 3.0;
        let cfg = scenario::loop_config(&spec, spec.arm().expect("arm"));
        let own = closed_loop::run(&cfg, &mut spec.scenario.clone(), None).expect("run");
        let mut sil = SilFirmware::new::<Vehicle>(None).expect("app");
        let app = run_on(&cfg, &mut spec.scenario.clone(), None, &mut sil).expect("run");
        let bits = |r: &closed_loop::LoopResult| -> Vec<u64> {
            r.series.cmd_a.iter().map(|x| x.to_bits()).collect()
        };
        assert_eq!(own.series.cmd_a.len(), 3000);
        assert!(
            own.series.cmd_a.iter().any(|&i| i > 0.1),
            "the coil engages"
        );
        assert_eq!(bits(&own), bits(&app));
    }

    #[test]
    fn a_missing_qemu_names_the_package() {
        let elf = std::env::temp_dir().join(format!("shimmy-pil-test-{}.elf", std::process::id()));
        std::fs::write(&elf, b"not an elf").expect("temp file");
        let r = Qemu::start_program("qemu-system-arm-not-installed", &elf).err();
        let _ = std::fs::remove_file(&elf);
        let e = r.expect("no such program");
        assert!(e.contains("apt-get install qemu-system-arm"), "{e}");
    }
}
