//! Sensor models as the firmware sees them: a 14-bit magnetic angle encoder on each kingpin,
//! the vehicle speed from a wheel-speed sensor and the coil current from a shunt and an ADC.
//!
//! Everything is seeded (`rand_chacha`), so a run is reproducible bit for bit. Faults (stuck,
//! dropout, NaN, spikes, ...) are not modelled here: [`Sensors::fault`] is the place where a
//! [`FaultInjector`] rewrites a [`Measurement`] after the healthy sensor models ran, and where
//! the closed loop asks for the state of the coil ([`CoilState`]). The fault models implement
//! that trait in the sibling `faults` module, which depends on this one (not the other way).

use crate::model::coil_drive::DriveCondition;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use shimmy_core::vehicle::SensorCalibration;
use std::collections::VecDeque;
use std::f64::consts::PI;

/// Sensor configuration.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SensorConfig {
    /// Encoder resolution, bits (quantisation 2 pi / 2^bits). 0 = no quantisation.
    pub encoder_bits: u32,
    /// Gaussian encoder noise before quantisation, standard deviation, rad.
    pub encoder_noise_rad: f64,
    /// Encoder delay, samples (SPI read + filtering in the sensor).
    pub encoder_delay_samples: usize,
    /// Wheel-speed noise, standard deviation, m/s.
    pub speed_noise_mps: f64,
    /// Wheel-speed scale error (tyre wear, pressure): measured = (1 + this) V.
    pub speed_scale_error: f64,
    /// Wheel-speed delay, samples.
    pub speed_delay_samples: usize,
    /// Coil-current measurement: ADC full scale, A.
    pub current_full_scale_a: f64,
    /// Coil-current ADC resolution, bits (0 = no quantisation).
    pub current_adc_bits: u32,
    /// Shunt amplifier + ADC noise, standard deviation, A.
    pub current_noise_a: f64,
    /// Seed of the noise generator.
    pub seed: u64,
}

impl Default for SensorConfig {
    /// A 14-bit encoder (LSB 0.022 deg = 3.8e-4 rad) with 0.5 LSB rms noise and one sample of
    /// delay; wheel speed with 0.05 m/s rms noise; a 12-bit ADC over 0-2.5 A with 5 mA rms noise.
    fn default() -> Self {
        SensorConfig {
            encoder_bits: 14,
            encoder_noise_rad: 0.5 * 2.0 * PI / 16384.0,
            encoder_delay_samples: 1,
            speed_noise_mps: 0.05,
            speed_scale_error: 0.0,
            speed_delay_samples: 0,
            current_full_scale_a: 2.5,
            current_adc_bits: 12,
            current_noise_a: 0.005,
            seed: 1,
        }
    }
}

impl SensorConfig {
    /// The sensors of a vehicle (its encoder resolution and noise, speed calibration error and
    /// current full scale); delays, speed and current noise and the seed as in [`Default`].
    /// The reference vehicle's sensors are exactly the default.
    pub fn from_vehicle(cal: &SensorCalibration) -> Self {
        let bits = u32::from(cal.encoder_bits);
        SensorConfig {
            encoder_bits: bits,
            encoder_noise_rad: f64::from(cal.encoder_noise_lsb) * 2.0 * PI
                / f64::from(1u32 << bits.min(31)),
            speed_scale_error: f64::from(cal.speed_scale_error),
            current_full_scale_a: f64::from(cal.current_full_scale_a),
            ..SensorConfig::default()
        }
    }

    /// Ideal sensors: no quantisation, no noise, no delay.
    pub fn ideal() -> Self {
        SensorConfig {
            encoder_bits: 0,
            encoder_noise_rad: 0.0,
            encoder_delay_samples: 0,
            speed_noise_mps: 0.0,
            speed_scale_error: 0.0,
            speed_delay_samples: 0,
            current_full_scale_a: 2.5,
            current_adc_bits: 0,
            current_noise_a: 0.0,
            seed: 1,
        }
    }

    /// Encoder quantum 2 pi / 2^bits, rad (0 without quantisation).
    pub fn encoder_lsb_rad(&self) -> f64 {
        if self.encoder_bits == 0 {
            0.0
        } else {
            2.0 * PI / f64::from(1u32 << self.encoder_bits.min(31))
        }
    }
}

/// The true quantities the sensors look at, at one sample.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Truth {
    /// Left wheel yaw, rad.
    pub psi_l_rad: f64,
    /// Right wheel yaw, rad.
    pub psi_r_rad: f64,
    /// Vehicle speed, m/s.
    pub speed_mps: f64,
    /// Coil current, A (the damper's filtered coil input).
    pub coil_current_a: f64,
}

/// One control period's sensing ([`Sensors::period`]).
#[derive(Clone, Copy, Debug)]
pub struct Period {
    /// What the sensors read.
    pub meas: Measurement,
    /// The coil's state (healthy without a coil).
    pub coil: CoilState,
    /// The coil driver's condition (the true coil and supply).
    pub drive: DriveCondition,
}

/// Status bits of one encoder transaction (as in the AS5047P frame).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct EncoderStatus {
    /// The bus transaction completed.
    pub read_ok: bool,
    /// The frame's parity matched.
    pub parity_ok: bool,
    /// The sensor's own error flag.
    pub error_flag: bool,
}

impl Default for EncoderStatus {
    /// A healthy transaction.
    fn default() -> Self {
        EncoderStatus {
            read_ok: true,
            parity_ok: true,
            error_flag: false,
        }
    }
}

/// What the firmware reads at one sample (f32, as on the target).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Measurement {
    /// Left encoder angle in rad, wrapped to (-pi, pi].
    pub psi_l_rad: f32,
    /// Right encoder angle, rad.
    pub psi_r_rad: f32,
    /// Speed, m/s.
    pub speed_mps: f32,
    /// Coil current, A (`None`: no current sensor or a read failure).
    pub coil_current_a: Option<f32>,
    /// Left encoder status bits.
    pub left_status: EncoderStatus,
    /// Right encoder status bits.
    pub right_status: EncoderStatus,
    /// The speed source marks its value valid (CAN signal qualifier / tone-wheel timeout).
    pub speed_valid: bool,
    /// The whole frame is lost (the 1 kHz task did not get this sample; the command is held).
    pub lost: bool,
}

impl Default for Measurement {
    /// Zero readings with healthy status bits.
    fn default() -> Self {
        Measurement {
            psi_l_rad: 0.0,
            psi_r_rad: 0.0,
            speed_mps: 0.0,
            coil_current_a: None,
            left_status: EncoderStatus::default(),
            right_status: EncoderStatus::default(),
            speed_valid: true,
            lost: false,
        }
    }
}

impl Measurement {
    /// The core's raw frame of this measurement at time stamp `t_us`, with the board's coil
    /// drive over the period just measured (`None`: an ideal current source).
    pub fn raw_frame(
        &self,
        t_us: u32,
        coil_drive_a: Option<f32>,
    ) -> shimmy_core::supervisor::frame::RawFrame {
        use shimmy_core::supervisor::frame::{EncoderReading, RawFrame};
        let enc = |a: f32, s: EncoderStatus| EncoderReading {
            angle_rad: a,
            read_ok: s.read_ok,
            parity_ok: s.parity_ok,
            error_flag: s.error_flag,
        };
        RawFrame {
            t_us,
            left: enc(self.psi_l_rad, self.left_status),
            right: enc(self.psi_r_rad, self.right_status),
            speed_mps: self.speed_mps,
            speed_valid: self.speed_valid,
            coil_current_a: self.coil_current_a,
            coil_drive_a,
        }
    }
}

/// State of the coil and its drive (a plant-side fault the measurement then shows).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum CoilState {
    /// The coil carries the commanded current (through its L/R lag).
    #[default]
    Healthy,
    /// Open circuit: no current flows, the damper is passive-off, the shunt reads ~0.
    Open,
    /// Terminals shorted: the driver's current bypasses the coil (the damper is passive-off)
    /// and the shunt reads `ratio` x the command (the short's resistance is `1/ratio` of the
    /// coil's), up to the ADC's full scale.
    Short {
        /// Measured / commanded current.
        ratio: f64,
    },
}

/// A fault injector: rewrites the healthy measurement (sample index `k`, time `t_s`).
/// Implemented by the fault-campaign code; the sensor models here are healthy.
pub trait FaultInjector: Send {
    /// Applies the fault(s) active at this sample.
    fn apply(&mut self, k: u64, t_s: f64, m: &mut Measurement);

    /// The coil's state at `t_s` (coil open/short faults; healthy by default).
    fn coil_state(&self, _t_s: f64) -> CoilState {
        CoilState::Healthy
    }

    /// The true coil resistance and supply at `t_s` (a hot coil, another supply; nominal by
    /// default). Only a board drive (`coil_drive`) sees them.
    fn drive_condition(&self, _t_s: f64) -> DriveCondition {
        DriveCondition::default()
    }

    /// The coil-current sensor's error at `t_s`, (gain, offset A): the shunt amplifier reads
    /// gain x current + offset before the ADC (exact by default).
    fn coil_sensor_error(&self, _t_s: f64) -> (f64, f64) {
        (1.0, 0.0)
    }
}

/// The sensor set of one vehicle.
pub struct Sensors {
    cfg: SensorConfig,
    rng: ChaCha8Rng,
    enc_buf: VecDeque<(f64, f64)>,
    speed_buf: VecDeque<f64>,
    k: u64,
    /// Optional fault injector, applied after the healthy models.
    pub fault: Option<Box<dyn FaultInjector>>,
}

impl std::fmt::Debug for Sensors {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Sensors")
            .field("cfg", &self.cfg)
            .field("k", &self.k)
            .field("fault", &self.fault.is_some())
            .finish()
    }
}

/// Rounds `x` to the nearest multiple of `q` (`q <= 0`: unchanged).
pub fn quantise(x: f64, q: f64) -> f64 {
    if q > 0.0 {
        (x / q).round() * q
    } else {
        x
    }
}

/// Wraps an angle to (-pi, pi].
pub fn wrap_pi(a: f64) -> f64 {
    let w = a.rem_euclid(2.0 * PI);
    if w > PI {
        w - 2.0 * PI
    } else {
        w
    }
}

impl Sensors {
    /// Healthy sensors with configuration `cfg`.
    pub fn new(cfg: SensorConfig) -> Self {
        Sensors {
            cfg,
            rng: ChaCha8Rng::seed_from_u64(cfg.seed),
            enc_buf: VecDeque::with_capacity(cfg.encoder_delay_samples + 1),
            speed_buf: VecDeque::with_capacity(cfg.speed_delay_samples + 1),
            k: 0,
            fault: None,
        }
    }

    /// The configuration.
    pub fn config(&self) -> &SensorConfig {
        &self.cfg
    }

    /// One control period's sensing at `t_s`, the one place the closed loop asks the fault
    /// plan: the coil's state and the coil driver's condition, and the measurement of `truth`.
    /// What the shunt sees: `truth.coil_current_a`, or with a shorted coil the driver's current
    /// through the short (no L/R lag), `ratio` x `drive_a` (what the drive of the last period
    /// pushes through the coil). Without a coil (`no_coil`) the coil is taken as healthy and
    /// there is no current sensor.
    pub fn period(&mut self, t_s: f64, truth: &Truth, drive_a: f64, no_coil: bool) -> Period {
        let coil = self.coil_state(t_s);
        let coil_current_a = match coil {
            CoilState::Short { ratio } if !no_coil => ratio * drive_a,
            _ => truth.coil_current_a,
        };
        let mut meas = self.sample(
            t_s,
            &Truth {
                coil_current_a,
                ..*truth
            },
        );
        if no_coil {
            meas.coil_current_a = None;
        }
        Period {
            meas,
            coil: if no_coil { CoilState::Healthy } else { coil },
            drive: self.drive_condition(t_s),
        }
    }

    /// The coil's state at `t_s` according to the fault injector (healthy without one).
    pub fn coil_state(&self, t_s: f64) -> CoilState {
        self.fault
            .as_ref()
            .map_or(CoilState::Healthy, |f| f.coil_state(t_s))
    }

    /// The true coil and supply at `t_s` according to the fault injector (nominal without one).
    pub fn drive_condition(&self, t_s: f64) -> DriveCondition {
        self.fault
            .as_ref()
            .map_or(DriveCondition::default(), |f| f.drive_condition(t_s))
    }

    fn normal(&mut self) -> f64 {
        StandardNormal.sample(&mut self.rng)
    }

    /// Samples the sensors at time `t_s` (call once per control period, in order).
    pub fn sample(&mut self, t_s: f64, truth: &Truth) -> Measurement {
        let c = self.cfg;
        // Always draw the same number of normals per sample, so that changing one noise level
        // does not reshuffle the others.
        let (n_l, n_r, n_v, n_i) = (self.normal(), self.normal(), self.normal(), self.normal());
        // Encoders: the delay line holds true angles; noise and quantisation at read-out.
        self.enc_buf.push_back((truth.psi_l_rad, truth.psi_r_rad));
        while self.enc_buf.len() > c.encoder_delay_samples + 1 {
            self.enc_buf.pop_front();
        }
        let (pl, pr) = self
            .enc_buf
            .front()
            .copied()
            .unwrap_or((truth.psi_l_rad, truth.psi_r_rad));
        let lsb = c.encoder_lsb_rad();
        let enc = |a: f64, n: f64| wrap_pi(quantise(a + c.encoder_noise_rad * n, lsb)) as f32;
        // Speed.
        self.speed_buf.push_back(truth.speed_mps);
        while self.speed_buf.len() > c.speed_delay_samples + 1 {
            self.speed_buf.pop_front();
        }
        let v = self.speed_buf.front().copied().unwrap_or(truth.speed_mps);
        let v_meas = ((1.0 + c.speed_scale_error) * v + c.speed_noise_mps * n_v).max(0.0);
        // Coil current: shunt + ADC, clamped to the ADC range.
        let i_q = if c.current_adc_bits == 0 {
            0.0
        } else {
            c.current_full_scale_a / f64::from(1u32 << c.current_adc_bits.min(31))
        };
        let (gain, offset) = self
            .fault
            .as_ref()
            .map_or((1.0, 0.0), |f| f.coil_sensor_error(t_s));
        let shunt = gain * truth.coil_current_a + offset;
        let i_meas =
            quantise(shunt + c.current_noise_a * n_i, i_q).clamp(0.0, c.current_full_scale_a);
        let mut m = Measurement {
            psi_l_rad: enc(pl, n_l),
            psi_r_rad: enc(pr, n_r),
            speed_mps: v_meas as f32,
            coil_current_a: Some(i_meas as f32),
            ..Measurement::default()
        };
        if let Some(f) = &mut self.fault {
            f.apply(self.k, t_s, &mut m);
        }
        self.k += 1;
        m
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_reference_vehicles_sensors_are_the_default() {
        let v = shimmy_core::vehicle::Vehicle::nominal();
        assert_eq!(
            SensorConfig::from_vehicle(&v.sensors),
            SensorConfig::default()
        );
    }

    #[test]
    fn encoder_quantises_to_14_bits_and_wraps() {
        let mut s = Sensors::new(SensorConfig {
            encoder_noise_rad: 0.0,
            encoder_delay_samples: 0,
            ..SensorConfig::default()
        });
        let lsb = 2.0 * PI / 16384.0;
        let m = s.sample(
            0.0,
            &Truth {
                psi_l_rad: 0.4 * lsb,
                psi_r_rad: 0.6 * lsb,
                ..Truth::default()
            },
        );
        assert_eq!(m.psi_l_rad, 0.0);
        assert_eq!(f64::from(m.psi_r_rad), f64::from(lsb as f32));
        assert!((wrap_pi(3.0 * PI / 2.0) + PI / 2.0).abs() < 1e-12);
    }

    #[test]
    fn delay_and_reproducibility() {
        let cfg = SensorConfig {
            encoder_delay_samples: 2,
            ..SensorConfig::default()
        };
        let (mut a, mut b) = (Sensors::new(cfg), Sensors::new(cfg));
        let mut outs = Vec::new();
        for k in 0..6 {
            let tr = Truth {
                psi_l_rad: 0.01 * f64::from(k),
                psi_r_rad: 0.0,
                speed_mps: 20.0,
                coil_current_a: 1.0,
            };
            let ma = a.sample(f64::from(k) * 1e-3, &tr);
            assert_eq!(ma, b.sample(f64::from(k) * 1e-3, &tr));
            outs.push(ma.psi_l_rad);
        }
        // Two samples late: reading k shows the angle of sample k-2 (within the noise, 1 LSB).
        for (k, &o) in outs.iter().enumerate().skip(2) {
            let want = 0.01 * (k - 2) as f64;
            assert!(
                (f64::from(o) - want).abs() < 4e-3 * 0.25,
                "{k}: {o} vs {want}"
            );
        }
    }
}
