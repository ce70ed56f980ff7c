//! When the background loop has work. It wakes after every interrupt (~1 kHz: the control
//! step, with the meter run inside it every tenth step, and the link), but what it does (the
//! flash store's pass, saving a host-written vehicle, starting a model cycle) depends only on
//! what the meter task published: the time, speed and motion of its newest run (100 Hz). So a
//! full pass runs once per meter run, or on every wake while a model cycle is under way; the
//! other wakes only check (`cargo xtask bench`: a pass costs ~0.9 k instructions, at 1 kHz
//! 0.55 % of the CPU).
//!
//! Nothing waits longer for it than before but a latched fault or a host's vehicle seen by the
//! next meter run (10 ms): a cycle starts only at a new time, the store's standstill and retry
//! decisions read only the meter's time, and a model call between two cycles changes nothing.
//!
//! [`model_pass`] is the model task's share of a pass, the one sequence the RTIC app's `idle`
//! loop and the host's `pil::HostApp` both run; the gate, the store and the logging stay the
//! app's.

use crate::control::Health;
use crate::monitoring::{ModelTask, Published};
use rtic_core::Mutex;
use shimmy_core::estimator::model_margin::ModelPoint;
use shimmy_core::estimator::model_update::Measurement;
use shimmy_core::model::UpdatableModel;

/// What a build measures of the model task's calls (the `pil` build: their instructions, for
/// the host); the board and the host's application measure nothing (`()`).
pub trait ModelHooks {
    /// What a call is measured by.
    type Call;
    /// Before a call of the model task.
    fn model_call_start() -> Self::Call;
    /// After the call; `done`: the cycle it completed.
    fn model_call_end(call: Self::Call, done: Option<&ModelPoint>);
}

impl ModelHooks for () {
    type Call = ();
    #[inline(always)]
    fn model_call_start() {}
    #[inline(always)]
    fn model_call_end(_: (), _: Option<&ModelPoint>) {}
}

/// One call of the model task at the meter's newest time and speed `now`: the meter's due
/// `measurement` offered, one unit of work between the hooks `H`, `on_update` after a model
/// update was applied (before its cycle is published, so the link serves the model the next
/// cycle runs on), and a completed cycle given to `publish` and counted in `health`. Returns
/// the completed cycle and the count of cycles so far.
#[inline(always)]
pub fn model_pass<H: ModelHooks, M: UpdatableModel<N>, const N: usize>(
    task: &mut ModelTask<M, N>,
    now: (f64, f32),
    measurement: Option<Measurement>,
    health: &mut impl Mutex<T = Health>,
    on_update: impl FnOnce(&ModelTask<M, N>),
    publish: impl FnOnce(Published),
) -> Option<(ModelPoint, u32)> {
    let (t_s, speed_mps) = now;
    task.offer(measurement);
    let call = H::model_call_start();
    let done = task.step(t_s, speed_mps);
    H::model_call_end(call, done.as_ref());
    if task.take_applied() {
        on_update(task);
    }
    let pt = done?;
    publish(task.publish(&pt));
    let late = task.tracker().overruns();
    let cycles = health.lock(|h| {
        h.model_cycles = h.model_cycles.saturating_add(1);
        h.model_late = late;
        h.model_cycles
    });
    Some((pt, cycles))
}

/// Tells the background loop whether a pass has anything to do.
#[derive(Clone, Copy, Debug)]
pub struct PassGate {
    /// Bit pattern of the meter time the last pass saw.
    seen_t_bits: u64,
}

impl Default for PassGate {
    fn default() -> Self {
        Self::new()
    }
}

impl PassGate {
    /// A gate that lets the first pass through.
    pub const fn new() -> Self {
        PassGate {
            // a NaN pattern no meter time has
            seen_t_bits: u64::MAX,
        }
    }

    /// A pass is due: the meter published a run since the last pass (`t_s`: the newest run's
    /// time, compared by its bits: no soft-float compare per wake), or `busy` (a model cycle
    /// under way takes its next unit of work).
    pub fn due(&mut self, t_s: f64, busy: bool) -> bool {
        let bits = t_s.to_bits();
        let new = bits != self.seen_t_bits;
        self.seen_t_bits = bits;
        new || busy
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_pass_per_meter_run_or_while_busy() {
        let mut g = PassGate::new();
        assert!(g.due(0.0, false), "the first pass");
        assert!(!g.due(0.0, false), "no new meter run");
        assert!(g.due(0.0, true), "a model cycle under way");
        assert!(g.due(0.01, false), "a new meter run");
        assert!(!g.due(0.01, false));
    }
}
