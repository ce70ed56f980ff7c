//! Calibration of the reference board's sensors: one definition, used by the board layer and by
//! the simulated sensors (which compile on the host too).

use crate::drivers::coil_current::ShuntConfig;
use crate::drivers::coil_pwm::CoilConfig;
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

/// Coil drive of the reference damper: 4 ohm hot, 21 mH (L/R = 1/190 s, the simulator's coil
/// lag), 12 V nominal supply, 2 A maximum (the damper's u_max); current loop at 2 pi 50 Hz (a
/// tenth of the 1 kHz sample rate). The current loop makes the true R and V matter only for the
/// duty headroom: 2 A needs 12 V into a +50 % hot coil.
/// TODO(calibration): measured coil resistance and inductance.
pub const COIL: CoilConfig = CoilConfig {
    coil_ohm: 4.0,
    coil_h: 4.0 / 190.0,
    supply_v: 12.0,
    max_current_a: 2.0,
    loop_bandwidth_radps: 2.0 * core::f32::consts::PI * 50.0,
};

#[cfg(test)]
mod tests {
    /// The frame time stamp is the capture timer's count taken as microseconds.
    #[test]
    fn the_capture_timer_counts_microseconds() {
        assert_eq!(super::WHEEL_SPEED.tick_hz, 1_000_000);
    }
}
