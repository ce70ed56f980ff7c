//! Processor-in-the-loop board layer (QEMU `netduinoplus2`, `pil` feature): the sensors and the
//! coil are the host's plant (`shimmy-sim pil`). Everything above this layer is the board's
//! application unchanged.
//!
//! The link: two named pipes the host creates in QEMU's working directory, `pil.in` (host ->
//! image: one [`HostFrame`] per control step) and `pil.out` (image -> host: the
//! [`TargetFrame`]s), read and written with semihosting calls (`-semihosting-config
//! enable=on,target=native`). A semihosting call is one instruction to the guest, so with
//! `-icount shift=0,sleep=off` the host's time between frames costs no virtual time: every
//! run is the same instruction for instruction, and TIM5 at QEMU's 1 GHz timer clock counts
//! instructions ([`instructions`]).
//!
//! Instruction accounting: the control and meter tasks add what they spend (their reports
//! included) to a busy counter; the background loop subtracts it from the time of each of its
//! calls, so a model cycle's count excludes the preemptions.

use super::parts::BoardParts;
use crate::drivers::coil_pwm::CoilDriver;
use crate::hal::pac;
use crate::monitoring::ImageVehicle;
use crate::periph::{ControlTimer, LinkPort, Watchdog};
use crate::runtime::{finish, Outcome};
use crate::sensors::SampleSet;
use core::convert::Infallible;
use core::sync::atomic::{AtomicU32, Ordering};
use cortex_m_semihosting::{nr, syscall};
use shimmy_core::estimator::fusion::MarginReport;
use shimmy_core::estimator::model_margin::ModelPoint;
use shimmy_core::estimator::monitor::Level;
use shimmy_core::supervisor::safe_controller::SafeOutput;
use shimmy_core::vehicle::record_schema_of;
use shimmy_pil::{
    body_len, decode, encode, HostFrame, MarginFrame, ModelFrame, StepReport, TargetFrame,
    HEADER_BYTES, MAX_FRAME,
};

/// QEMU's stm32f405 clocks its timers at 1 GHz (see `board/qemu.rs`).
const TIMER_CLOCK_HZ: u32 = 1_000_000_000;

/// Semihosting handles of the two pipes (set once in [`init`]).
static HANDLE_IN: AtomicU32 = AtomicU32::new(u32::MAX);
static HANDLE_OUT: AtomicU32 = AtomicU32::new(u32::MAX);
/// Instructions spent by the control and meter tasks since boot (wrapping).
static BUSY: AtomicU32 = AtomicU32::new(0);
/// Model margins published to the meter task so far.
static PUBLISHED: AtomicU32 = AtomicU32::new(0);
/// The meter run's snapshot of [`PUBLISHED`], taken with the model margin it fuses.
static SEEN: AtomicU32 = AtomicU32::new(0);

/// The host's sensor frames as the sensor layer.
pub struct BoardSensors {
    /// Bytes read from `pil.in` (one semihosting read takes what the pipe holds, usually
    /// exactly one frame).
    buf: [u8; MAX_FRAME],
    len: usize,
    /// The coil drive the host's last frame reports (the host drives the plant's coil).
    coil_drive_a: Option<f32>,
}

impl super::parts::CoilDriveSource for BoardSensors {
    /// The drive of the host's last frame (this board's PWM goes nowhere).
    fn coil_drive_a(&self, _own_a: f32) -> Option<f32> {
        self.coil_drive_a
    }
}

impl BoardSensors {
    /// Waits for the host's next frame (no virtual time passes) and returns it as the drivers'
    /// results; a `Finish` frame ends the run.
    pub fn sample(&mut self, _dt_ticks: u32) -> SampleSet {
        match self.next_frame() {
            Ok(HostFrame::Sensors(raw)) => {
                self.coil_drive_a = raw.coil_drive_a;
                crate::pil::sample_set(&raw)
            }
            Ok(HostFrame::Finish) => {
                defmt::info!("pil: the host ended the run");
                send(&TargetFrame::Finished {
                    instructions: executed(),
                });
                finish(Outcome::Success)
            }
            Err(e) => {
                defmt::error!(
                    "pil: bad frame from the host: {}",
                    defmt::Display2Format(&e)
                );
                finish(Outcome::Failure)
            }
        }
    }
}

/// The coil PWM: the duty goes nowhere (the host's plant takes the command from the step
/// report, as with an ideal current drive).
pub struct Pwm {
    duty: u16,
}

impl embedded_hal::pwm::ErrorType for Pwm {
    type Error = Infallible;
}

impl embedded_hal::pwm::SetDutyCycle for Pwm {
    fn max_duty_cycle(&self) -> u16 {
        1000
    }
    fn set_duty_cycle(&mut self, duty: u16) -> Result<(), Infallible> {
        self.duty = duty;
        Ok(())
    }
}

/// The parts of this variant the application gets.
pub type Board = BoardParts<BoardSensors, Pwm>;

/// Opens the pipes, starts the instruction counter, brings up the coil (fail-safe current, or
/// off for a latched coil fault), the timers and the host link's port (nothing is connected to
/// it in a PIL run).
pub fn init(dp: pac::Peripherals, coil_off: bool) -> (Board, LinkPort) {
    let open = |name: &[u8], mode: usize| {
        // SAFETY: `name` is NUL-terminated; the length excludes the NUL (semihosting SYS_OPEN).
        let h = unsafe { syscall!(OPEN, name.as_ptr(), mode, name.len() - 1) };
        if h == usize::MAX {
            defmt::error!(
                "pil: cannot open {=[u8]:a} (run the image through `shimmy-sim pil`)",
                name
            );
            finish(Outcome::Failure)
        }
        h as u32
    };
    HANDLE_IN.store(open(b"pil.in\0", nr::open::R_BINARY), Ordering::Relaxed);
    HANDLE_OUT.store(
        open(b"pil.out\0", nr::open::W_TRUNC_BINARY),
        Ordering::Relaxed,
    );
    // TIM5 free-running at prescaler 0: one tick per instruction under `-icount shift=0`.
    // SAFETY: TIM5 is not used otherwise in this variant; any value is valid for these
    // registers.
    unsafe {
        let t = &*pac::TIM5::ptr();
        t.psc().write(|w| w.bits(0));
        t.arr().write(|w| w.bits(u32::MAX));
        t.egr().write(|w| w.bits(1));
        t.cr1().write(|w| w.bits(1));
    }
    let pwm = Pwm { duty: 0 };
    let coil = match if coil_off {
        CoilDriver::new_off(pwm, crate::calibration::COIL)
    } else {
        CoilDriver::new(pwm, crate::calibration::COIL)
    } {
        Ok(c) => c,
        Err(e) => match e {},
    };
    send(&TargetFrame::Hello {
        vehicle_schema: record_schema_of::<ImageVehicle>(),
    });
    defmt::info!("pil: link open, waiting for the host's frames");
    let board = Board {
        sensors: BoardSensors {
            buf: [0; MAX_FRAME],
            len: 0,
            coil_drive_a: None,
        },
        coil,
        timer: ControlTimer::start(dp.TIM2, TIMER_CLOCK_HZ),
        watchdog: Watchdog::start(dp.IWDG),
    };
    // The control steps come from `background_pass`, not from TIM2's update (see there).
    // SAFETY: DIER = 0 masks TIM2's update interrupt; the counter keeps running.
    unsafe { (*pac::TIM2::ptr()).dier().write(|w| w.bits(0)) };
    (board, LinkPort::start(dp.USART1, TIMER_CLOCK_HZ))
}

/// Instructions of one control period: 1 ms at QEMU's 1 GHz virtual clock, one instruction
/// per nanosecond under `-icount shift=0`.
const PERIOD_INSTRUCTIONS: u32 = TIMER_CLOCK_HZ / 1000;
/// SysTick ticks per instruction: SysTick runs on the 168 MHz core clock, QEMU's virtual
/// clock at 1 GHz (`cargo xtask bench` checks the ratio), as (numerator, denominator).
const SYSTICK_PER_INSTRUCTION: (u32, u32) = (168, 1000);
/// Instruction count at the entry of the latest control step.
static STEP_ENTRY: AtomicU32 = AtomicU32::new(0);
/// Wraps of the instruction counter seen by the control steps (one step every < 2^32
/// instructions: a period is 10^6, a cold model cycle ~5.4 x 10^6).
static WRAPS: AtomicU32 = AtomicU32::new(0);

/// Instructions executed since reset, 64-bit.
fn executed() -> u64 {
    let now = instructions();
    let wraps = WRAPS.load(Ordering::Relaxed) + u32::from(now < STEP_ENTRY.load(Ordering::Relaxed));
    (u64::from(wraps) << 32) | u64::from(now)
}

/// The period clock of the PIL build, in place of the board's WFI until TIM2's update: called
/// on every pass of the background loop with whether the model task has work due.
///
/// - Nothing due: the next control step starts now (the control task is bound to TIM2's
///   interrupt, pended here by software); it waits for the host's frame anyway.
/// - Work due: the step starts at the end of the period, one period of instructions after the
///   last step's entry, so the model cycle gets the share of the CPU it would get on a 1 kHz
///   timer: SysTick, armed here only while the model is busy, pends it.
///
/// Why: with `-icount sleep=off` each WFI costs no virtual time but a hand-over inside QEMU
/// (the halted vCPU is woken by QEMU's main loop when the timer expires), which was most of
/// the wall time of a step (docs/testing.md, "Processor in the loop"). TIM2's own update interrupt is
/// off in this build ([`init`]): QEMU 7.2's STM32 timer neither keeps the period nor restarts
/// at a counter write, so it cannot mark the period's end. Every control step still consumes
/// one host frame and answers with one report, so lockstep and the results are unchanged.
pub fn background_pass(busy: bool) {
    // SAFETY: SysTick is used by nothing else in this build; these are its documented
    // registers (ARMv7-M ARM B3.3), any value is valid.
    let syst = unsafe { &*cortex_m::peripheral::SYST::PTR };
    let armed = syst.csr.read() & 1 != 0;
    if !busy {
        // SAFETY: as above.
        unsafe { syst.csr.write(0) };
        next_step();
        return;
    }
    if armed {
        return;
    }
    let elapsed = instructions().wrapping_sub(STEP_ENTRY.load(Ordering::Relaxed));
    let left = PERIOD_INSTRUCTIONS.saturating_sub(elapsed);
    let ticks = left / SYSTICK_PER_INSTRUCTION.1 * SYSTICK_PER_INSTRUCTION.0;
    if ticks == 0 {
        next_step();
        return;
    }
    // SAFETY: as above; RVR takes 24 bits (a period is 168,000 ticks), CVR is cleared by any
    // write, CSR = ENABLE | TICKINT | CLKSOURCE (core clock).
    unsafe {
        syst.rvr.write(ticks.min(0x00FF_FFFF));
        syst.cvr.write(0);
        syst.csr.write(0b111);
    }
}

/// Pends the control task and lets it run before the caller goes on.
fn next_step() {
    cortex_m::peripheral::NVIC::pend(pac::Interrupt::TIM2);
    cortex_m::asm::dsb();
    cortex_m::asm::isb();
}

/// The end of a period in which the model task was busy: one shot, the control step.
#[cortex_m_rt::exception]
fn SysTick() {
    // SAFETY: see `background_pass`.
    unsafe { (*cortex_m::peripheral::SYST::PTR).csr.write(0) };
    next_step();
}

/// The instruction counter (TIM5, wrapping).
pub fn instructions() -> u32 {
    // SAFETY: a read of TIM5 CNT.
    unsafe { (*pac::TIM5::ptr()).cnt().read().bits() }
}

impl BoardSensors {
    /// The length of the first complete frame in the buffer, header included.
    fn complete(&self) -> Result<Option<usize>, shimmy_pil::FrameError> {
        if self.len < HEADER_BYTES {
            return Ok(None);
        }
        let (Some(&a), Some(&b)) = (self.buf.first(), self.buf.get(1)) else {
            return Ok(None);
        };
        let n = HEADER_BYTES + body_len([a, b])?;
        Ok((self.len >= n).then_some(n))
    }

    /// The next frame from the host, read with as few semihosting calls as the pipe allows.
    fn next_frame(&mut self) -> Result<HostFrame, shimmy_pil::FrameError> {
        let h = HANDLE_IN.load(Ordering::Relaxed) as usize;
        loop {
            if let Some(n) = self.complete()? {
                let f = decode::<HostFrame>(self.buf.get(HEADER_BYTES..n).unwrap_or_default());
                self.buf.copy_within(n..self.len, 0);
                self.len -= n;
                return f;
            }
            let Some(rest) = self.buf.get_mut(self.len..).filter(|r| !r.is_empty()) else {
                return Err(shimmy_pil::FrameError::TooLong);
            };
            // SAFETY: `rest` is valid for writes of its length (semihosting SYS_READ returns
            // the count *not* read; on a pipe it returns what the pipe holds).
            let left = unsafe { syscall!(READ, h, rest.as_mut_ptr(), rest.len()) };
            let got = rest.len().saturating_sub(left);
            if got == 0 {
                // End of file or an error: the host is gone.
                return Err(shimmy_pil::FrameError::BadLength(0));
            }
            self.len += got;
        }
    }
}

/// Sends one frame (one semihosting write, so frames of different tasks never interleave).
fn send(frame: &TargetFrame) {
    let mut buf = [0u8; MAX_FRAME];
    let Ok(bytes) = encode(frame, &mut buf) else {
        defmt::error!("pil: frame too long");
        finish(Outcome::Failure)
    };
    let h = HANDLE_OUT.load(Ordering::Relaxed) as usize;
    // SAFETY: `bytes` is valid for reads of its length.
    let left = unsafe { syscall!(WRITE, h, bytes.as_ptr(), bytes.len()) };
    if left != 0 {
        defmt::error!("pil: the host stopped reading");
        finish(Outcome::Failure)
    }
}

/// End of a control step that began at instruction `entry`: its report, and its instructions
/// (the report's cost included) booked as busy time.
pub fn report_step(step: u32, out: &SafeOutput, entry: u32) {
    let instructions = crate::board::pil::instructions().wrapping_sub(entry);
    if entry < STEP_ENTRY.load(Ordering::Relaxed) {
        WRAPS.fetch_add(1, Ordering::Relaxed);
    }
    STEP_ENTRY.store(entry, Ordering::Relaxed);
    send(&TargetFrame::Step(StepReport {
        step,
        out: *out,
        instructions,
    }));
    book_busy(entry);
}

fn book_busy(entry: u32) {
    let spent = instructions().wrapping_sub(entry);
    BUSY.fetch_add(spent, Ordering::Relaxed);
}

/// Called inside the meter task's lock of the shared model margin: remembers how many
/// margins had been published when it took the one it fuses.
pub fn meter_took_model() {
    SEEN.store(PUBLISHED.load(Ordering::Relaxed), Ordering::Relaxed);
}

/// A margin update of the meter task (sample `step`).
pub fn report_margin(step: u32, report: &MarginReport, level: Level) {
    send(&TargetFrame::Margin(MarginFrame {
        step,
        report: *report,
        level,
        model_cycles: SEEN.load(Ordering::Relaxed),
    }));
}

/// End of a meter run spawned by control step `step` that began at instruction `entry`.
pub fn report_meter_run(step: u32, entry: u32) {
    let instructions = crate::board::pil::instructions().wrapping_sub(entry);
    send(&TargetFrame::MeterRun { step, instructions });
    book_busy(entry);
}

/// Called inside the background loop's lock of the shared model margin when it publishes one.
pub fn model_published() {
    PUBLISHED.fetch_add(1, Ordering::Relaxed);
}

/// The cost of one background-loop call, the preemptions excluded; the cycle's total is
/// reported when a call completes it.
pub struct ModelCall {
    entry: u32,
    busy: u32,
}

/// Instructions of the model cycle in progress (only the background loop touches it).
static CYCLE: AtomicU32 = AtomicU32::new(0);
/// Completed model cycles.
static CYCLES: AtomicU32 = AtomicU32::new(0);

impl ModelCall {
    /// Before a call of the model task.
    pub fn start() -> Self {
        ModelCall {
            busy: BUSY.load(Ordering::Relaxed),
            entry: instructions(),
        }
    }

    /// After the call: books its instructions, reports a completed cycle.
    pub fn end(self, done: Option<&ModelPoint>) {
        let elapsed = instructions().wrapping_sub(self.entry);
        let preempted = BUSY.load(Ordering::Relaxed).wrapping_sub(self.busy);
        let total = CYCLE
            .load(Ordering::Relaxed)
            .wrapping_add(elapsed.wrapping_sub(preempted));
        match done {
            None => CYCLE.store(total, Ordering::Relaxed),
            Some(pt) => {
                CYCLE.store(0, Ordering::Relaxed);
                let cycle = CYCLES.fetch_add(1, Ordering::Relaxed).wrapping_add(1);
                send(&TargetFrame::Model(ModelFrame {
                    cycle,
                    margin: pt.margin(),
                    instructions: total,
                }));
            }
        }
    }
}

/// The PIL build's hooks ([`super::hooks::AppHooks`]): every task's frames and instruction
/// counts to the host; the background loop starts the next step at once where the board
/// would wait for the timer ([`background_pass`]).
pub struct PilHooks;

impl super::hooks::AppHooks for PilHooks {
    type Entry = u32;
    fn entry() -> u32 {
        instructions()
    }
    fn idle(busy: bool) {
        background_pass(busy);
    }
    fn report_step(step: u32, out: &SafeOutput, entry: u32) {
        report_step(step, out, entry);
    }
    fn meter_took_model() {
        meter_took_model();
    }
    fn report_margin(step: u32, report: &MarginReport, level: Level) {
        report_margin(step, report, level);
    }
    fn report_meter_run(step: u32, entry: u32) {
        report_meter_run(step, entry);
    }
    fn model_published() {
        model_published();
    }
}

impl crate::background::ModelHooks for PilHooks {
    type Call = ModelCall;
    fn model_call_start() -> ModelCall {
        ModelCall::start()
    }
    fn model_call_end(call: ModelCall, done: Option<&ModelPoint>) {
        call.end(done);
    }
}
