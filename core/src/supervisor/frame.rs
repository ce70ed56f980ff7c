//! What comes in every 1 ms: the raw sensor frame (both wheel-yaw encoders, vehicle speed,
//! coil current, time stamp) and the validity of the latest margin report.
//!
//! Time is an input: a free-running microsecond counter (`t_us`, wrapping u32; differences are
//! taken with wrapping arithmetic, so the 71.6 min wrap is harmless).

use crate::control::schedule::MarginSignal;
use crate::estimator::fusion::MarginReport;

/// Nominal sample period, us.
pub const NOMINAL_PERIOD_US: u32 = 1000;

/// One wheel-yaw encoder reading.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct EncoderReading {
    /// Wheel yaw about the kingpin, rad (already converted from counts).
    pub angle_rad: f32,
    /// The bus transaction completed (SPI/SSI frame received).
    pub read_ok: bool,
    /// The frame's parity bit matched.
    pub parity_ok: bool,
    /// The sensor's own error flag (magnetic field out of range, internal error).
    pub error_flag: bool,
}

impl EncoderReading {
    /// A healthy reading of `angle_rad`.
    pub const fn ok(angle_rad: f32) -> Self {
        EncoderReading {
            angle_rad,
            read_ok: true,
            parity_ok: true,
            error_flag: false,
        }
    }
}

/// One raw sensor frame, as delivered every 1 ms.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct RawFrame {
    /// Free-running time stamp, us (wraps).
    pub t_us: u32,
    /// Left wheel-yaw encoder.
    pub left: EncoderReading,
    /// Right wheel-yaw encoder.
    pub right: EncoderReading,
    /// Vehicle speed, m/s.
    pub speed_mps: f32,
    /// The speed source marks its value valid (e.g. CAN signal qualifier).
    pub speed_valid: bool,
    /// Measured coil current in A, if the board measures it.
    pub coil_current_a: Option<f32>,
    /// The drive over the period in which `coil_current_a` was measured, as the steady current
    /// it pushes through the nominal coil: PWM duty x supply voltage / coil resistance, A. With
    /// the measured current it gives the coil's voltage-current relation, which tells a lying
    /// sensor from a coil fault. `None`: the coil is fed by an ideal current source (the drive
    /// is the command).
    pub coil_drive_a: Option<f32>,
}

impl RawFrame {
    /// A healthy frame.
    pub const fn ok(t_us: u32, psi_l_rad: f32, psi_r_rad: f32, speed_mps: f32) -> Self {
        RawFrame {
            t_us,
            left: EncoderReading::ok(psi_l_rad),
            right: EncoderReading::ok(psi_r_rad),
            speed_mps,
            speed_valid: true,
            coil_current_a: None,
            coil_drive_a: None,
        }
    }
}

/// Input of the margin check and of the margin schedule: the latest margin report.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum MarginStatus {
    /// No margin estimator in this build / not checked.
    NotUsed,
    /// The latest [`crate::estimator::fusion::MarginReport`] is valid; what the controller's
    /// margin schedule needs of it.
    Valid(MarginSignal),
    /// The latest report is invalid (frozen, warming up, no mode in band).
    Invalid,
}

impl MarginStatus {
    /// The status of a fused report: `Valid` with its speed margin, time to critical and fast
    /// damping (absent ones as +infinity) when the report is valid, else `Invalid`.
    pub fn of_report(r: &MarginReport) -> Self {
        match (r.valid, r.speed_margin_mps) {
            (true, Some(dv)) => MarginStatus::Valid(MarginSignal {
                speed_margin_mps: dv,
                time_to_critical_s: r.time_to_critical_s.unwrap_or(f32::INFINITY),
                zeta_fast: if r.fast_valid {
                    r.zeta_fast
                } else {
                    f32::INFINITY
                },
            }),
            _ => MarginStatus::Invalid,
        }
    }

    /// The margin signal of a valid report.
    pub fn signal(&self) -> Option<MarginSignal> {
        match self {
            MarginStatus::Valid(m) => Some(*m),
            _ => None,
        }
    }
}
