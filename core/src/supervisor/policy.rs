//! The mode policy: from the active faults to the operating [`Mode`] and the safe current.
//!
//! * **FailSafe** (controller output ignored, fixed current): no trustworthy wheel yaw (both
//!   encoders faulted, or they disagree), timing fault, coil fault. The current is
//!   [`FAILSAFE_CURRENT_A`] (stabilises every analysed plant variant at every speed, see
//!   `tests/tests/cross_crate/failsafe_current.rs`), or 0 A when the speed is trusted (no speed fault
//!   active, so not a held or implausibly low reading) and below
//!   [`ZERO_CURRENT_SAFE_BELOW_MPS`] (below the lowest Hopf onset: no shimmy possible, parking
//!   stays light). A coil fault commands 0 A (driving current into a short only heats it; an
//!   open coil cannot be driven): the damper is then passive-off, and the verdict says so with
//!   `damper_available == false`.
//! * **Degraded** (controller runs, possibly with a current floor):
//!   - one encoder lost: the healthy one stands in for both. The controller acts on the
//!     in-phase yaw (psi_L + psi_R)/2, which the track rod makes equal to either wheel's yaw up
//!     to the tiny anti-phase part, so control quality is kept; but the cross-check is gone, so
//!     the command is floored at [`FAILSAFE_CURRENT_A`] (the controller can only add damping);
//!   - speed untrusted (`SpeedInvalid`, `SpeedJump`, `SpeedLowImplausible`): the last trusted
//!     speed is held for `speed_hold_s` (controller runs on it, no floor); after that the speed
//!     is unknown: the speed gate is disabled and the floor applied (the safe current does not
//!     depend on speed);
//!   - `BothStuckSuspect`: floor;
//!   - coil-current sensor lost or margin estimate unavailable: advisory, no floor (the coil is
//!     then driven open loop; the controller does not use the margin).
//! * **Recovery with hysteresis**: a fault leaves the active set only after it has been absent
//!   for `recovery_s`. Coil open/short are latched until [`Supervisor::clear_latched`] (a burnt
//!   coil does not heal; retrying into a short is harmful). After FailSafe the controller is
//!   reset (its filters restart from the next sample).
//!
//! [`FAILSAFE_CURRENT_A`]: crate::control::actuator::FAILSAFE_CURRENT_A
//! [`ZERO_CURRENT_SAFE_BELOW_MPS`]: super::params::ZERO_CURRENT_SAFE_BELOW_MPS
//! [`Supervisor::clear_latched`]: super::checks::Supervisor::clear_latched

use super::faults::{FaultKind, FaultSet};
use super::params::SupervisorParams;

/// Operating mode.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum Mode {
    /// All inputs trusted: the controller's command is used.
    #[default]
    Normal,
    /// Reduced information: the controller runs, possibly with a current floor.
    Degraded,
    /// Inputs not trusted: fixed safe current, controller output ignored.
    FailSafe,
}

impl Mode {
    /// Short name.
    pub const fn name(self) -> &'static str {
        match self {
            Mode::Normal => "normal",
            Mode::Degraded => "degraded",
            Mode::FailSafe => "fail-safe",
        }
    }
}

/// The supervisor's decision for one frame.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct SupervisorVerdict {
    /// Mode.
    pub mode: Mode,
    /// FailSafe: the current to command, A; Degraded: a floor under the controller's command
    /// (if any); Normal: `None`.
    pub safe_current_a: Option<f32>,
    /// Active faults (detected now or not yet recovered).
    pub faults: FaultSet,
    /// Faults detected in this frame.
    pub detected: FaultSet,
    /// False when the coil cannot be driven (open/short): the damper is passive-off.
    pub damper_available: bool,
    /// The coil test pulse: the command is raised to at least this, A (`None`: no pulse).
    pub test_current_a: Option<f32>,
}

/// The speed the policy may use for one frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum SpeedUse {
    /// No speed fault active: the reading, m/s.
    Trusted(f32),
    /// A speed fault is active: the last trusted reading, within `speed_hold_s`, m/s.
    Held(f32),
    /// No trusted speed (none yet, or held for longer than `speed_hold_s`).
    Unknown,
}

/// The verdict for one frame from the active faults `active`, the faults detected in this frame
/// `det`, and the speed the policy may use, `speed`.
pub(super) fn decide(
    active: FaultSet,
    det: FaultSet,
    speed: SpeedUse,
    p: &SupervisorParams,
) -> SupervisorVerdict {
    let a = active;
    let coil_dead = a.contains(FaultKind::CoilOpen) || a.contains(FaultKind::CoilShort);
    // 0 A only for a trusted low speed: a held or unknown speed never lowers the safe current.
    let fixed = match speed {
        SpeedUse::Trusted(v) if v < p.zero_current_below_mps => 0.0,
        _ => p.failsafe_current_a,
    };
    let no_yaw = (a.left() && a.right()) || a.contains(FaultKind::EncoderDisagree);
    let fail = no_yaw || a.contains(FaultKind::Timing) || coil_dead;
    let (mode, safe) = if coil_dead {
        (Mode::FailSafe, Some(0.0))
    } else if fail {
        (Mode::FailSafe, Some(fixed))
    } else {
        let floor = a.left()
            || a.right()
            || speed == SpeedUse::Unknown
            || a.contains(FaultKind::BothStuckSuspect);
        let advisory = a.speed()
            || a.contains(FaultKind::CoilSensor)
            || a.contains(FaultKind::MarginUnavailable);
        if floor {
            (Mode::Degraded, Some(fixed))
        } else if advisory {
            (Mode::Degraded, None)
        } else {
            (Mode::Normal, None)
        }
    };
    SupervisorVerdict {
        mode,
        safe_current_a: safe,
        faults: a,
        detected: det,
        damper_available: !coil_dead,
        test_current_a: None,
    }
}
