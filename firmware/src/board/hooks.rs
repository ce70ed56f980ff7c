//! What the application does beside its work, per build: the board sleeps when the background
//! loop has nothing to do and reports nothing; the `pil` build reports each task's frames and
//! instruction counts to the host and starts the next step at once (`pil.rs`). The RTIC app
//! (`main.rs`) calls [`AppHooks`] through the build's `board::Hooks`; the board's methods are
//! empty and inline to nothing.

use crate::background::ModelHooks;
use shimmy_core::estimator::fusion::MarginReport;
use shimmy_core::estimator::model_margin::ModelPoint;
use shimmy_core::estimator::monitor::Level;
use shimmy_core::supervisor::safe_controller::SafeOutput;

/// The application's hooks, beside those of the model task's calls ([`ModelHooks`], which
/// the shared [`crate::background::model_pass`] calls).
pub trait AppHooks: ModelHooks {
    /// What a task's entry is measured by (the `pil` build: the instruction counter).
    type Entry: Copy;
    /// At a task's entry.
    fn entry() -> Self::Entry;
    /// The background loop has nothing due (`busy`: a model cycle is under way): the board
    /// sleeps until the next interrupt unless busy.
    fn idle(busy: bool);
    /// End of control step `step` that began at `entry`, with its output.
    fn report_step(step: u32, out: &SafeOutput, entry: Self::Entry);
    /// Inside the meter task's lock of the shared model margin, when it takes it.
    fn meter_took_model();
    /// A margin update of the meter task (sample `step`).
    fn report_margin(step: u32, report: &MarginReport, level: Level);
    /// End of a meter run spawned by control step `step` that began at `entry`.
    fn report_meter_run(step: u32, entry: Self::Entry);
    /// Inside the background loop's lock of the shared model margin, when it publishes one.
    fn model_published();
}

/// The board's hooks: sleep when idle, report nothing.
pub struct BoardHooks;

/// The board measures nothing (a zero-sized mark).
#[derive(Clone, Copy, Debug)]
pub struct Unmeasured;

impl AppHooks for BoardHooks {
    type Entry = Unmeasured;
    #[inline(always)]
    fn entry() -> Unmeasured {
        Unmeasured
    }
    #[inline(always)]
    fn idle(busy: bool) {
        if !busy {
            cortex_m::asm::wfi();
        }
    }
    #[inline(always)]
    fn report_step(_: u32, _: &SafeOutput, _: Unmeasured) {}
    #[inline(always)]
    fn meter_took_model() {}
    #[inline(always)]
    fn report_margin(_: u32, _: &MarginReport, _: Level) {}
    #[inline(always)]
    fn report_meter_run(_: u32, _: Unmeasured) {}
    #[inline(always)]
    fn model_published() {}
}

impl ModelHooks for BoardHooks {
    type Call = Unmeasured;
    #[inline(always)]
    fn model_call_start() -> Unmeasured {
        Unmeasured
    }
    #[inline(always)]
    fn model_call_end(_: Unmeasured, _: Option<&ModelPoint>) {}
}
