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
