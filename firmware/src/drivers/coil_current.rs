//! Coil current from a shunt resistor and an ADC channel.
//!
//! embedded-hal 1.0 has no ADC trait, so the firmware owns the small [`AdcChannel`] trait; the
//! board implements it on the STM32 ADC, the simulation on a table.

/// One ADC channel that returns raw counts.
pub trait AdcChannel {
    /// Error of a conversion.
    type Error: core::fmt::Debug;
    /// Converts once and returns the raw counts (right-aligned).
    fn read_counts(&mut self) -> Result<u16, Self::Error>;
}

/// The analog chain: shunt, current-sense amplifier, ADC.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ShuntConfig {
    /// Shunt resistance, ohm.
    pub shunt_ohm: f32,
    /// Voltage gain of the current-sense amplifier [V/V].
    pub amp_gain: f32,
    /// ADC reference voltage, V.
    pub vref_v: f32,
    /// ADC resolution, bits.
    pub bits: u8,
    /// Counts read at zero current (amplifier offset, measured at calibration).
    pub offset_counts: f32,
}

impl ShuntConfig {
    /// Amps per count: vref / (2^bits - 1) / (gain * shunt).
    pub fn amps_per_count(&self) -> f32 {
        let full = ((1u32 << self.bits) - 1) as f32;
        self.vref_v / full / (self.amp_gain * self.shunt_ohm)
    }

    /// The largest count (the ADC is saturated there).
    pub fn full_scale_counts(&self) -> u16 {
        ((1u32 << self.bits) - 1) as u16
    }
}

/// Errors of the current measurement.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Error<E> {
    /// The ADC reported an error.
    Adc(E),
    /// The reading is at full scale: the true current is unknown (at least this large).
    Saturated,
}

/// Coil current sensor.
pub struct CoilCurrentSensor<A> {
    adc: A,
    cfg: ShuntConfig,
    amps_per_count: f32,
}

impl<A: AdcChannel> CoilCurrentSensor<A> {
    /// Wraps an ADC channel.
    pub fn new(adc: A, cfg: ShuntConfig) -> Self {
        CoilCurrentSensor {
            adc,
            cfg,
            amps_per_count: cfg.amps_per_count(),
        }
    }

    /// The ADC channel (for inspection).
    pub fn adc(&self) -> &A {
        &self.adc
    }

    /// Converts raw counts to amps (offset removed).
    pub fn counts_to_a(&self, counts: u16) -> f32 {
        (f32::from(counts) - self.cfg.offset_counts) * self.amps_per_count
    }

    /// Reads the coil current, A.
    pub fn read_a(&mut self) -> Result<f32, Error<A::Error>> {
        let c = self.adc.read_counts().map_err(Error::Adc)?;
        if c >= self.cfg.full_scale_counts() {
            return Err(Error::Saturated);
        }
        Ok(self.counts_to_a(c))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    struct Fixed(Result<u16, ()>);
    impl AdcChannel for Fixed {
        type Error = ();
        fn read_counts(&mut self) -> Result<u16, ()> {
            self.0
        }
    }

    fn cfg() -> ShuntConfig {
        // 20 mOhm shunt, gain 50 (INA240A2), 3.3 V, 12 bit, offset 2048 (bidirectional, mid-rail).
        ShuntConfig {
            shunt_ohm: 0.02,
            amp_gain: 50.0,
            vref_v: 3.3,
            bits: 12,
            offset_counts: 2048.0,
        }
    }

    #[test]
    fn scaling() {
        // 1 A -> 20 mV -> 1.0 V after the amplifier -> 1.0/3.3*4095 = 1240.9 counts above offset.
        let s = CoilCurrentSensor::new(Fixed(Ok(2048 + 1241)), cfg());
        let a = s.counts_to_a(2048 + 1241);
        // Tolerance: one count is 0.8 mA.
        assert!((a - 1.0).abs() < 1e-3, "{a}");
        assert_eq!(s.counts_to_a(2048), 0.0);
        assert!(s.counts_to_a(0) < -1.6);
    }

    #[test]
    fn read_and_errors() {
        let mut s = CoilCurrentSensor::new(Fixed(Ok(2048)), cfg());
        assert_eq!(s.read_a(), Ok(0.0));
        let mut s = CoilCurrentSensor::new(Fixed(Ok(4095)), cfg());
        assert_eq!(s.read_a(), Err(Error::Saturated));
        let mut s = CoilCurrentSensor::new(Fixed(Err(())), cfg());
        assert_eq!(s.read_a(), Err(Error::Adc(())));
    }
}
