//! All sensors of one control step, read through the drivers, with each failure kept as a
//! typed [`SensorFault`] for the validation in [`crate::control`].

use crate::drivers::as5047p::{self, AngleTracker, As5047p};
use crate::drivers::coil_current::{self, AdcChannel, CoilCurrentSensor};
use crate::drivers::wheel_speed::{PulseCapture, SpeedReading, WheelSpeed};
use embedded_hal::spi::SpiDevice;

/// Why a sensor value is missing.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(target_os = "none", derive(defmt::Format))]
pub enum SensorFault {
    /// Bus (SPI/ADC peripheral) error.
    Bus,
    /// Encoder response with a wrong parity bit.
    Parity,
    /// Encoder error flag; the ERRFL contents.
    ErrorFlag(u16),
    /// The angle tracker could not unwrap the step (half a turn in one sample).
    Jump,
    /// Current ADC at full scale.
    Saturated,
}

impl<E> From<as5047p::Error<E>> for SensorFault {
    fn from(e: as5047p::Error<E>) -> Self {
        match e {
            as5047p::Error::Spi(_) => SensorFault::Bus,
            as5047p::Error::Parity { .. } => SensorFault::Parity,
            as5047p::Error::ErrorFlag(f) => SensorFault::ErrorFlag(f.0),
        }
    }
}

impl<E> From<coil_current::Error<E>> for SensorFault {
    fn from(e: coil_current::Error<E>) -> Self {
        match e {
            coil_current::Error::Adc(_) => SensorFault::Bus,
            coil_current::Error::Saturated => SensorFault::Saturated,
        }
    }
}

/// Raw results of one sampling of every sensor.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SampleSet {
    /// Time stamp of the sampling, us: the free-running 1 MHz capture timer (TIM5 on the
    /// board), so a late or missed control period shows in the supervisor's `timing` check.
    pub t_us: u32,
    /// Left wheel yaw, rad.
    pub psi_l_rad: Result<f32, SensorFault>,
    /// Right wheel yaw, rad.
    pub psi_r_rad: Result<f32, SensorFault>,
    /// Vehicle speed.
    pub speed: SpeedReading,
    /// Measured coil current, A.
    pub coil_current_a: Result<f32, SensorFault>,
}

/// One wheel-yaw channel: the encoder and its unwrapping tracker.
pub struct YawChannel<SPI> {
    /// The encoder.
    pub encoder: As5047p<SPI>,
    /// Unwrapping and zero.
    pub tracker: AngleTracker,
}

impl<SPI: SpiDevice> YawChannel<SPI> {
    /// Reads and unwraps one angle.
    pub fn read_rad(&mut self) -> Result<f32, SensorFault> {
        let raw = self.encoder.read_angle_counts()?;
        self.tracker.update(raw).map_err(|_| SensorFault::Jump)
    }
}

/// Every sensor of the control loop.
pub struct Sensors<SL, SR, P, A> {
    /// Left wheel yaw.
    pub left: YawChannel<SL>,
    /// Right wheel yaw.
    pub right: YawChannel<SR>,
    /// Wheel-speed pulse capture.
    pub pulses: P,
    /// Speed computation.
    pub speed: WheelSpeed,
    /// Coil current.
    pub current: CoilCurrentSensor<A>,
}

impl<SL: SpiDevice, SR: SpiDevice, P: PulseCapture, A: AdcChannel> Sensors<SL, SR, P, A> {
    /// Reads everything once; `dt_ticks` is the control period in capture-timer ticks.
    pub fn sample(&mut self, dt_ticks: u32) -> SampleSet {
        // The capture timer counts at `SpeedConfig::tick_hz` = 1 MHz (calibration test).
        let t_us = self.pulses.now_ticks();
        let psi_l_rad = self.left.read_rad();
        let psi_r_rad = self.right.read_rad();
        let speed = self.speed.update(self.pulses.take(), dt_ticks);
        let coil_current_a = self.current.read_a().map_err(SensorFault::from);
        SampleSet {
            t_us,
            psi_l_rad,
            psi_r_rad,
            speed,
            coil_current_a,
        }
    }
}
