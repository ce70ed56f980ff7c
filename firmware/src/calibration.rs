//! Calibration of the reference board's sensors: one definition, used by the board layer and by
//! the simulated sensors (which compile on the host too).

use crate::drivers::coil_current::ShuntConfig;
use crate::drivers::wheel_speed::SpeedConfig;

/// Tone wheel and tyre of the reference vehicle.
/// TODO(vehicle): measured rolling radius and tooth count of the actual axle.
pub const WHEEL_SPEED: SpeedConfig = SpeedConfig {
    pulses_per_rev: 48,
    rolling_radius_m: 0.35,
    tick_hz: 1_000_000,
    timeout_s: 0.5,
    max_accel_mps2: 12.0,
    jump_margin_mps: 0.5,
};

/// Shunt chain: 15 mOhm, INA240A2 (gain 50; 0.75 V/A, so +-2.2 A around mid-rail covers the
/// coil's 2 A maximum), 3.3 V reference, 12 bit, mid-rail offset.
/// TODO(calibration): measure `offset_counts` at boot with the coil off.
pub const SHUNT: ShuntConfig = ShuntConfig {
    shunt_ohm: 0.015,
    amp_gain: 50.0,
    vref_v: 3.3,
    bits: 12,
    offset_counts: 2048.0,
};
