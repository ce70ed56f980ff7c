//! The messages. Each frame carries a [`Header`] and one [`Request`] (host to device) or
//! [`Response`] (device to host); a response echoes its request's `seq`. Unsolicited frames
//! (the [`Response::Ready`] handshake, [`Response::Telemetry`] samples) have `seq` 0.
//!
//! Units are in the names; codes (`level`, `mode`, `kind`, `cause`) are the core's enums in
//! declaration order ([`level_code`], [`level_name`], ...), so the wire needs no second copy of
//! them.

use serde::{Deserialize, Serialize};
use shimmy_core::estimator::monitor::Level;
use shimmy_core::supervisor::faults::FaultKind;

use crate::PROTOCOL_VERSION;

/// The start of every frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Header {
    /// [`PROTOCOL_VERSION`] of the sender.
    pub version: u16,
    /// Request number (echoed in the response; 0 for unsolicited frames).
    pub seq: u16,
}

/// The header of this protocol version, `seq` 0.
pub const PROTOCOL_HEADER: Header = Header {
    version: PROTOCOL_VERSION,
    seq: 0,
};

/// Host to device.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum Request<'a> {
    /// Who are you? Answered with [`Response::Identity`].
    Identify,
    /// The stored vehicle configuration: [`Response::Config`].
    GetConfig,
    /// Store a vehicle configuration (the core's vehicle record): validated whole on the
    /// device, then stored; it takes effect at standstill. [`Response::ConfigStored`].
    SetConfig(&'a [u8]),
    /// Up to [`EVENTS_PER_PAGE`] log entries from index `first` (0 = oldest kept).
    ReadEvents {
        /// Index of the first entry wanted.
        first: u16,
    },
    /// Empty the event log: [`Response::Cleared`].
    ClearEvents,
    /// The fault record: [`Response::Faults`].
    ReadFaults,
    /// Start (`on`) or stop the telemetry stream of margin reports: [`Response::Streaming`].
    Telemetry {
        /// Stream on or off.
        on: bool,
    },
    /// The online model update's parameters and diagnosis: [`Response::Model`].
    ReadModel,
}

/// Entries per [`Response::Events`] page. A frame would hold 16 of the longest (`frame::tests`
/// checks a full page fits), which would halve the pages of a board's log, each a walk of its
/// flash log from the oldest entry; 8 keep the link task's reply 132 B smaller in flash, where
/// the board had 168 B left (`cargo xtask size`).
pub const EVENTS_PER_PAGE: usize = 8;

/// Device to host.
// One reply at a time lives on the stack and no_std has no Box: the page's size is the bound.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum Response<'a> {
    /// Sent once the device's serial port is enabled: it listens from now on.
    Ready(Identity<'a>),
    /// The device's identity.
    Identity(Identity<'a>),
    /// The stored vehicle record; `pending`: stored but not yet in effect (waits for
    /// standstill).
    Config {
        /// The core's vehicle record.
        record: &'a [u8],
        /// Not yet in effect.
        pending: bool,
    },
    /// The configuration was valid and is stored; `in_effect`: applied at once (standstill),
    /// else at the next standstill.
    ConfigStored {
        /// Applied already.
        in_effect: bool,
    },
    /// A page of the event log.
    Events(EventPage),
    /// The log was emptied; `removed` entries were in it.
    Cleared {
        /// Entries removed.
        removed: u16,
    },
    /// The fault record.
    Faults(FaultReport),
    /// The telemetry stream is now on or off.
    Streaming {
        /// Stream on.
        on: bool,
    },
    /// One margin report of the stream.
    Telemetry(Telemetry),
    /// The online model update's state.
    Model(ModelReport<'a>),
    /// The request was not carried out; the device's state is unchanged.
    Error(ErrorReply<'a>),
}

/// Firmware identity.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Identity<'a> {
    /// Firmware name and version.
    pub firmware: &'a str,
    /// `shimmy-core` version.
    pub core: &'a str,
    /// [`PROTOCOL_VERSION`] of the device.
    pub protocol: u16,
    /// The vehicle record schema the device reads (`shimmy_core::vehicles::car::board::record_schema`).
    pub vehicle_schema: u32,
    /// Entries the event log holds (on a board at least this many: its flash log filled with
    /// the longest entry; when full, the oldest go first).
    pub log_capacity: u16,
}

/// A page of the log: entries `first..first + entries.len()` of `kept`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EventPage {
    /// Entries in the log now.
    pub kept: u16,
    /// Entries dropped since the last clear because the log was full (oldest first).
    pub dropped: u32,
    /// Index of the first entry of this page.
    pub first: u16,
    /// The entries, oldest first.
    pub entries: heapless::Vec<LogEntry, EVENTS_PER_PAGE>,
}

/// One entry of the event log.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum LogEntry {
    /// A shimmy (warning) episode of the core monitor.
    Shimmy(ShimmyEvent),
    /// A supervisor fault became active, or latched.
    Fault(FaultEvent),
    /// The device started.
    Boot(BootEvent),
    /// The online model update's diagnosis named another part, or none any more.
    Diagnosis(DiagnosisEvent),
}

/// A warning episode as the core monitor logs it (`shimmy_core::estimator::monitor::Event`),
/// with what the controller did during it.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ShimmyEvent {
    /// Start time since boot, s.
    pub start_s: f64,
    /// Speed at the start, m/s.
    pub speed_mps: f32,
    /// Shimmy frequency, Hz.
    pub freq_hz: f32,
    /// Peak wheel-yaw amplitude, rad.
    pub peak_amplitude_rad: f32,
    /// Duration, s (so far, if `open`).
    pub duration_s: f32,
    /// Time at the shimmy-present level within it, s.
    pub shimmy_s: f32,
    /// Highest warning level reached ([`level_code`]).
    pub level: u8,
    /// The episode is still going on.
    pub open: bool,
    /// Controller action: highest damper current command during the episode, A.
    pub peak_current_a: f32,
    /// Controller action: mean damper current command during the episode, A.
    pub mean_current_a: f32,
}

/// A supervisor fault that became active, or latched while active.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct FaultEvent {
    /// Time since boot, ms.
    pub t_ms: u32,
    /// The fault ([`fault_code`]).
    pub kind: u8,
    /// The supervisor latched it (kept across resets until the next power-on).
    pub latched: bool,
}

/// The online model update's diagnosis changed
/// (`shimmy_core::estimator::model_update::ModelUpdater::diagnosis`): the parameter furthest
/// outside its plausible band, with its estimate, or none any more.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct DiagnosisEvent {
    /// Time since boot, ms.
    pub t_ms: u32,
    /// The parameter's index in the model's update set, the order of [`ModelReport::params`]
    /// (`None`: every part within its band again; the numbers below are then 0).
    pub param: Option<u8>,
    /// The factor on the vehicle file's value.
    pub factor: f32,
    /// One-sigma uncertainty of ln(factor).
    pub sigma_ln: f32,
    /// The factor's plausible band, low end.
    pub band_low: f32,
    /// The factor's plausible band, high end.
    pub band_high: f32,
}

/// A start of the device.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct BootEvent {
    /// Why it started ([`cause_name`]).
    pub cause: u8,
    /// Resets since power-on (the reset record's count).
    pub resets_since_power_on: u32,
    /// Starts of this board, counted in its flash (kept across power-offs).
    pub boot_count: u32,
}

/// The fault record: the reset record (`firmware::fault_memory`) and the supervisor's faults.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct FaultReport {
    /// Resets since power-on.
    pub resets: u32,
    /// Cause of the last reset (`firmware::fault_memory::ResetCause` code).
    pub last_cause: u8,
    /// Abnormal resets in a row, each after a short run.
    pub quick_resets: u8,
    /// Uptime of the current run, ms.
    pub uptime_ms: u32,
    /// Latched faults (bit i = `FaultKind::ALL[i]`).
    pub latched: u32,
    /// Faults active now (same bits).
    pub active: u32,
    /// Fault activations since boot.
    pub raised: u32,
}

/// Most parameters a model update reports.
pub const MODEL_PARAMS: usize = shimmy_core::estimator::model_update::MAX_UPDATE_PARAMS;

/// The online model update (`shimmy_core::estimator::model_update`) as the device runs it: how
/// many measurements it used, and each parameter's factor on the vehicle file with its
/// uncertainty; `params` is empty while the update is off or the model has none.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ModelReport<'a> {
    /// The update runs.
    pub enabled: bool,
    /// Measurement updates applied.
    pub updates: u32,
    /// Measurements dropped by the innovation gate.
    pub gated: u32,
    /// Model solves that failed.
    pub failures: u32,
    /// The parameters, in the model's order.
    #[serde(borrow)]
    pub params: heapless::Vec<ParamReport<'a>, MODEL_PARAMS>,
}

/// One updated parameter (`shimmy_core::estimator::model_update::ParamEstimate`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ParamReport<'a> {
    /// The vehicle file's field name.
    pub field: &'a str,
    /// What it is, in words.
    pub what: &'a str,
    /// The factor on the file's value.
    pub factor: f32,
    /// One-sigma uncertainty of ln(factor).
    pub sigma_ln: f32,
    /// The factor's plausible band, low end.
    pub band_low: f32,
    /// The factor's plausible band, high end.
    pub band_high: f32,
    /// Outside its band by more than two sigmas: a diagnosis.
    pub out_of_band: bool,
}

/// One margin report of the telemetry stream.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Telemetry {
    /// Time since boot, s.
    pub t_s: f64,
    /// Trusted speed, m/s (NaN: not trusted).
    pub speed_mps: f32,
    /// Shimmy-mode damping ratio from the data (slow estimate).
    pub zeta_data: f32,
    /// Its standard deviation.
    pub sigma_zeta_data: f32,
    /// Fast damping estimate.
    pub zeta_fast: f32,
    /// Shimmy frequency, Hz.
    pub freq_hz: f32,
    /// Damping ratio of the model (NaN: none yet).
    pub zeta_model: f32,
    /// Speed margin to the critical speed, m/s (NaN: unknown).
    pub speed_margin_mps: f32,
    /// Warning level ([`level_code`]).
    pub level: u8,
    /// The fused report is valid.
    pub valid: bool,
}

/// Why a request was not carried out.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum ErrorReply<'a> {
    /// The frame failed COBS, CRC or header checks (`frame::FrameError::text`).
    BadFrame(&'a str),
    /// The frame was longer than `frame::MAX_FRAME`.
    TooLong,
    /// The frame is of another protocol version.
    Version {
        /// The device's [`PROTOCOL_VERSION`].
        device: u16,
    },
    /// A request the device does not know (a newer host, or garbage behind a good CRC).
    UnknownRequest,
    /// The vehicle record was refused; nothing was stored.
    Config(ConfigProblem<'a>),
    /// The log page starts beyond the end of the log.
    NoSuchEntry {
        /// Entries in the log.
        kept: u16,
    },
    /// Clearing the log erases flash, which only happens with the vehicle stopped and the
    /// damper idle: nothing was removed.
    NotAtStandstill,
    /// The device could not read its log (a flash error); nothing was changed.
    Storage,
}

/// What is wrong with a vehicle record (`shimmy_core::vehicle::RecordError`, without text
/// formatting on the device).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum ConfigProblem<'a> {
    /// The record's length does not match its header (or this schema's field count).
    Length {
        /// Bytes expected.
        need: u32,
        /// Bytes received.
        have: u32,
    },
    /// Written under another field table.
    Schema {
        /// The record's schema id.
        found: u32,
        /// The device's.
        expected: u32,
    },
    /// A field out of its range, not whole, or against a rule between fields (`rule`, empty
    /// for the range checks).
    Field {
        /// Section of the field.
        section: &'a str,
        /// Name of the field.
        name: &'a str,
        /// The value refused.
        value: f64,
        /// The broken rule between fields, or empty.
        rule: &'a str,
    },
}

impl<'a> ConfigProblem<'a> {
    /// The wire form of the core's record error.
    pub fn of(e: shimmy_core::vehicle::RecordError) -> ConfigProblem<'static> {
        use shimmy_core::vehicle::{Problem, RecordError};
        let wide = |x: usize| u32::try_from(x).unwrap_or(u32::MAX);
        match e {
            RecordError::BufferTooSmall { need, have } | RecordError::Length { need, have } => {
                ConfigProblem::Length {
                    need: wide(need),
                    have: wide(have),
                }
            }
            RecordError::Schema { found, expected } => ConfigProblem::Schema { found, expected },
            RecordError::Invalid(v) => ConfigProblem::Field {
                section: v.section,
                name: v.name,
                value: v.value,
                rule: match v.problem {
                    Problem::Inconsistent(rule) => rule,
                    Problem::OutOfRange { .. } | Problem::NotInteger { .. } => "",
                },
            },
        }
    }
}

/// The wire code of a warning level.
pub const fn level_code(l: Level) -> u8 {
    match l {
        Level::Normal => 0,
        Level::MarginLow => 1,
        Level::ApproachingCritical => 2,
        Level::ShimmyPresent => 3,
    }
}

/// The name of a level code (`?` for an unknown one).
pub const fn level_name(code: u8) -> &'static str {
    match code {
        0 => "normal",
        1 => "margin-low",
        2 => "approaching-critical",
        3 => "shimmy-present",
        _ => "?",
    }
}

/// The name of a reset-cause code (`firmware::fault_memory::ResetCause` in declaration order;
/// `?` for an unknown one).
pub const fn cause_name(code: u8) -> &'static str {
    match code {
        0 => "power-on",
        1 => "watchdog",
        2 => "software (panic or fault handler)",
        3 => "reset pin",
        4 => "other",
        5 => "restart (a new configuration)",
        _ => "?",
    }
}

/// The wire code of a fault kind: its bit in `FaultKind::ALL`.
pub fn fault_code(k: FaultKind) -> u8 {
    let i = FaultKind::ALL
        .iter()
        .position(|&x| x == k)
        .unwrap_or(usize::MAX);
    u8::try_from(i).unwrap_or(u8::MAX)
}

/// The name of a fault code (`?` for an unknown one).
pub fn fault_name(code: u8) -> &'static str {
    FaultKind::ALL
        .get(usize::from(code))
        .map_or("?", |k| k.name())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn codes_name_every_level_and_fault() {
        use Level::*;
        for l in [Normal, MarginLow, ApproachingCritical, ShimmyPresent] {
            assert_ne!(level_name(level_code(l)), "?");
        }
        for k in FaultKind::ALL {
            assert_eq!(fault_name(fault_code(k)), k.name());
        }
        assert_eq!(level_name(9), "?");
        assert_eq!(fault_name(200), "?");
    }
}
