//! Fault kinds, sets of faults and per-kind counters. Which check raises which kind:
//! [`super::checks`]; what a set of active faults means for the damper: [`super::policy`].

/// Number of fault kinds.
pub const N_FAULTS: usize = 22;

/// What went wrong.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum FaultKind {
    /// Left encoder: transaction failed.
    LeftRead = 0,
    /// Left encoder: parity or sensor error flag.
    LeftFlag,
    /// Left encoder: NaN/Inf.
    LeftNonFinite,
    /// Left encoder: beyond full lock.
    LeftRange,
    /// Left encoder: faster than physically possible.
    LeftRate,
    /// Left encoder: frozen while the right one moves.
    LeftStuck,
    /// Right encoder: transaction failed.
    RightRead,
    /// Right encoder: parity or sensor error flag.
    RightFlag,
    /// Right encoder: NaN/Inf.
    RightNonFinite,
    /// Right encoder: beyond full lock.
    RightRange,
    /// Right encoder: faster than physically possible.
    RightRate,
    /// Right encoder: frozen while the left one moves.
    RightStuck,
    /// Both encoders valid but inconsistent with the track-rod linkage.
    EncoderDisagree,
    /// Both encoders bit-identical for long at speed (cannot be proven; advisory).
    BothStuckSuspect,
    /// Speed: flag, NaN/Inf, negative or too high.
    SpeedInvalid,
    /// Speed: changes faster than a vehicle can accelerate.
    SpeedJump,
    /// Missing samples or a bad time stamp.
    Timing,
    /// Coil open (measured current far below the command).
    CoilOpen,
    /// Coil short (measured current above the command).
    CoilShort,
    /// Coil-current measurement NaN/Inf, or a reading the coil's voltage-current relation
    /// rules out (the coil is then driven open loop).
    CoilSensor,
    /// Margin estimate unavailable for long (advisory).
    MarginUnavailable,
    /// Speed: a low reading (standstill or below the controller's speed gate) reached faster
    /// than a vehicle can brake: the signal is lost (tone-wheel timeout) or frozen. Stays until
    /// the reading is back above the gate.
    SpeedLowImplausible,
}

impl FaultKind {
    /// Every kind, in bit order.
    pub const ALL: [FaultKind; N_FAULTS] = [
        FaultKind::LeftRead,
        FaultKind::LeftFlag,
        FaultKind::LeftNonFinite,
        FaultKind::LeftRange,
        FaultKind::LeftRate,
        FaultKind::LeftStuck,
        FaultKind::RightRead,
        FaultKind::RightFlag,
        FaultKind::RightNonFinite,
        FaultKind::RightRange,
        FaultKind::RightRate,
        FaultKind::RightStuck,
        FaultKind::EncoderDisagree,
        FaultKind::BothStuckSuspect,
        FaultKind::SpeedInvalid,
        FaultKind::SpeedJump,
        FaultKind::Timing,
        FaultKind::CoilOpen,
        FaultKind::CoilShort,
        FaultKind::CoilSensor,
        FaultKind::MarginUnavailable,
        FaultKind::SpeedLowImplausible,
    ];

    /// Short name for logs and tables.
    pub const fn name(self) -> &'static str {
        match self {
            FaultKind::LeftRead => "left-read",
            FaultKind::LeftFlag => "left-flag",
            FaultKind::LeftNonFinite => "left-nonfinite",
            FaultKind::LeftRange => "left-range",
            FaultKind::LeftRate => "left-rate",
            FaultKind::LeftStuck => "left-stuck",
            FaultKind::RightRead => "right-read",
            FaultKind::RightFlag => "right-flag",
            FaultKind::RightNonFinite => "right-nonfinite",
            FaultKind::RightRange => "right-range",
            FaultKind::RightRate => "right-rate",
            FaultKind::RightStuck => "right-stuck",
            FaultKind::EncoderDisagree => "encoder-disagree",
            FaultKind::BothStuckSuspect => "both-stuck-suspect",
            FaultKind::SpeedInvalid => "speed-invalid",
            FaultKind::SpeedJump => "speed-jump",
            FaultKind::Timing => "timing",
            FaultKind::CoilOpen => "coil-open",
            FaultKind::CoilShort => "coil-short",
            FaultKind::CoilSensor => "coil-sensor",
            FaultKind::MarginUnavailable => "margin-unavailable",
            FaultKind::SpeedLowImplausible => "speed-low-implausible",
        }
    }

    pub(super) const fn bit(self) -> u32 {
        1 << (self as u8)
    }

    /// Latched until [`Supervisor::clear_latched`](super::checks::Supervisor::clear_latched).
    pub const fn latched(self) -> bool {
        matches!(
            self,
            FaultKind::CoilOpen | FaultKind::CoilShort | FaultKind::CoilSensor
        )
    }

    /// Latched when it recurs (`SupervisorParams::intermittent_count` activations within the
    /// window): every fault except the two suspicions that a healthy vehicle can raise
    /// repeatedly (`BothStuckSuspect` on a smooth road, `MarginUnavailable` at low excitation)
    /// and the kinds that latch at once.
    pub const fn escalates(self) -> bool {
        !matches!(
            self,
            FaultKind::BothStuckSuspect
                | FaultKind::MarginUnavailable
                | FaultKind::CoilOpen
                | FaultKind::CoilShort
                | FaultKind::CoilSensor
        )
    }
}

/// A set of faults (bit set over [`FaultKind`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct FaultSet(pub(super) u32);

const LEFT_MASK: u32 = 0b11_1111;
const RIGHT_MASK: u32 = 0b11_1111 << 6;

impl FaultSet {
    /// No fault.
    pub const EMPTY: FaultSet = FaultSet(0);

    /// Whether `k` is in the set.
    pub const fn contains(self, k: FaultKind) -> bool {
        self.0 & k.bit() != 0
    }

    /// Adds `k`.
    pub fn insert(&mut self, k: FaultKind) {
        self.0 |= k.bit();
    }

    /// Whether the set is empty.
    pub const fn is_empty(self) -> bool {
        self.0 == 0
    }

    /// The set of raw bits (bit i = `FaultKind::ALL[i]`; bits beyond the kinds are dropped).
    pub const fn from_bits(bits: u32) -> FaultSet {
        FaultSet(bits & ((1 << N_FAULTS) - 1))
    }

    /// The raw bits (bit i = `FaultKind::ALL[i]`).
    pub const fn bits(self) -> u32 {
        self.0
    }

    /// Number of faults in the set.
    pub const fn len(self) -> u32 {
        self.0.count_ones()
    }

    /// Any left-encoder fault.
    pub const fn left(self) -> bool {
        self.0 & LEFT_MASK != 0
    }

    /// Any right-encoder fault.
    pub const fn right(self) -> bool {
        self.0 & RIGHT_MASK != 0
    }

    /// Any speed fault (`SpeedInvalid`, `SpeedJump`, `SpeedLowImplausible`): the speed reading
    /// is not trusted.
    pub const fn speed(self) -> bool {
        self.0
            & (FaultKind::SpeedInvalid.bit()
                | FaultKind::SpeedJump.bit()
                | FaultKind::SpeedLowImplausible.bit())
            != 0
    }

    /// The kinds in the set.
    pub fn iter(self) -> impl Iterator<Item = FaultKind> {
        FaultKind::ALL
            .into_iter()
            .filter(move |k| self.contains(*k))
    }
}

/// Counters of one fault kind.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FaultRecord {
    /// Frames in which the fault was detected.
    pub frames: u32,
    /// Times the fault became active.
    pub activations: u32,
    /// Time stamp of the first detection, us.
    pub first_t_us: Option<u32>,
    /// Time stamp of the last detection, us.
    pub last_t_us: Option<u32>,
    /// Currently active.
    pub active: bool,
}
