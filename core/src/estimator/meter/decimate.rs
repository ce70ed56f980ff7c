//! Anti-alias filtering and decimation (1 kHz -> 100 Hz by default).
//!
//! The anti-alias filter is an 8th-order inverse-Chebyshev (Chebyshev II) low-pass made of four
//! biquads (bilinear transform pre-warped at the stop-band edge; coefficients computed at
//! construction in the filter's precision, never typed in). Only what would fold INTO the shimmy
//! band must be removed: after decimation to f_out, input content at f folds to |f - m f_out|, so
//! the stop band starts at f_out - f_band_hi (80 Hz for 100 Hz out and a 20 Hz band) with >= 60 dB
//! attenuation there and above. Content between 50 and 80 Hz folds to 20-50 Hz, outside the band.
//! The pass band is maximally flat: < 1e-5 dB down at 20 Hz, -0.009 dB at 40 Hz, -0.65 dB at 50 Hz,
//! -3 dB at ~54.6 Hz. A flat pass band up to the output Nyquist matters for the mode meter: an
//! 8th-order Butterworth cut at 30 Hz (the first design) leaves a deep spectral roll-off between 30
//! and 50 Hz that a low-order AR model cannot represent; in an exploratory run (AR(6), 100 Hz) it
//! biased the 8 Hz damping by +0.035 (0.05 -> 0.085) and the 18 Hz one by -0.05; with this filter
//! the bias is within the accuracy-test tolerances. `AntiAliasFilter::gain_db` evaluates the
//! implemented response and a unit test checks it against the closed-form Chebyshev-II magnitude.

use super::real::Real;

/// Number of biquad sections (filter order = 2 x this).
pub const AA_SECTIONS: usize = 4;

/// One direct-form-II-transposed biquad section, normalised a0 = 1.
#[derive(Clone, Copy, Debug, Default)]
pub struct Biquad<T> {
    b: [T; 3],
    a: [T; 2],
    s: [T; 2],
}

impl<T: Real> Biquad<T> {
    /// Filters one sample.
    #[inline]
    pub fn step(&mut self, x: T) -> T {
        let y = self.b[0] * x + self.s[0];
        self.s[0] = self.b[1] * x - self.a[0] * y + self.s[1];
        self.s[1] = self.b[2] * x - self.a[1] * y;
        y
    }

    /// Clears the state.
    pub fn reset(&mut self) {
        self.s = [T::ZERO; 2];
    }

    /// Clears the state to the steady state of a constant input `x0` (DC gain 1 assumed).
    pub fn preset(&mut self, x0: T) {
        // Steady state of DF2T: y = x0, s1 = b2 x0 - a2 y, s0 = b1 x0 - a1 y + s1.
        self.s[1] = self.b[2] * x0 - self.a[1] * x0;
        self.s[0] = self.b[1] * x0 - self.a[0] * x0 + self.s[1];
    }

    fn coeffs_f64(&self) -> ([f64; 3], [f64; 2]) {
        (
            [self.b[0].to_f64(), self.b[1].to_f64(), self.b[2].to_f64()],
            [self.a[0].to_f64(), self.a[1].to_f64()],
        )
    }
}

/// Inverse-Chebyshev (Chebyshev type II) low-pass of order `2 * AA_SECTIONS` as a biquad
/// cascade: maximally flat pass band, equiripple stop band of a stated attenuation from a stated
/// edge frequency.
#[derive(Clone, Copy, Debug)]
pub struct AntiAliasFilter<T> {
    sections: [Biquad<T>; AA_SECTIONS],
    fs_hz: f64,
}

impl<T: Real> AntiAliasFilter<T> {
    /// Designs the filter with stop band from `f_stop_hz` up, attenuated by at least
    /// `atten_db`, at sample rate `fs_hz` (bilinear transform pre-warped at `f_stop_hz`).
    /// Returns `None` unless 0 < f_stop < fs/2 and atten_db > 0.
    ///
    /// Computed in the filter's precision `T`, in the bilinear transform's own unit (analog
    /// frequencies divided by 2 fs), where every intermediate is of order one: the f32 design
    /// keeps its coefficients within a few ulps of the f64 design's (a unit test), and the
    /// target links no f64 arithmetic for it.
    pub fn design(f_stop_hz: f64, atten_db: f64, fs_hz: f64) -> Option<Self> {
        let (f_stop, atten, fs) = (
            T::from_f64(f_stop_hz),
            T::from_f64(atten_db),
            T::from_f64(fs_hz),
        );
        let half = T::from_f32(0.5);
        if !(f_stop > T::ZERO && fs > T::ZERO && f_stop < half * fs && atten > T::ZERO) {
            return None;
        }
        let pi = T::from_f64(core::f64::consts::PI);
        let two = T::from_f32(2.0);
        let n = T::from_f32((2 * AA_SECTIONS) as f32);
        // Stop edge pre-warped, in units of 2 fs: tan(pi f_stop / fs).
        let ws = (pi * f_stop / fs).tan();
        // 1/eps^2 = 10^(A/10) - 1; mu = asinh(1/eps) / n.
        let inv_eps = ((atten / T::from_f32(10.0) * T::from_f64(core::f64::consts::LN_10)).exp()
            - T::ONE)
            .sqrt();
        // mu = asinh(1/eps) / n, and its sinh and cosh from e^mu: e^asinh(x) = x + sqrt(x^2 + 1)
        // adds positive terms, and e^mu - e^-mu loses about eps/mu relative, a few ulps for any
        // stop band attenuated by 3 dB or more (1/eps >= 1, mu >= asinh(1)/8 = 0.11; the
        // meter's is 60 dB, mu = 0.95). Exp and ln instead of libm's sinh, cosh and asinh:
        // 1.3 KB less flash on the target (`cargo xtask size`), the same response (tests below).
        let e_mu = ((inv_eps + (inv_eps * inv_eps + T::ONE).sqrt()).ln() / n).exp();
        let (sinh_mu, cosh_mu) = (half * (e_mu - T::ONE / e_mu), half * (e_mu + T::ONE / e_mu));
        let mut sections = [Biquad::default(); AA_SECTIONS];
        for (i, sec) in sections.iter_mut().enumerate() {
            // theta = pi k / (2 n), k = 2 i + 1. cos theta as sin(pi (n - k) / (2 n)): near
            // pi/2 the cosine of a rounded angle loses digits, the sine of its complement does not.
            let k = 2 * i + 1;
            let angle = |j: usize| pi * T::from_f32(j as f32) / (two * n);
            let (sin_th, cos_th) = (angle(k).sin(), angle(2 * AA_SECTIONS - k).sin());
            // Chebyshev-I pole, its reciprocal (scaled to ws) is the Chebyshev-II pole.
            let (pr, pim) = (-sinh_mu * sin_th, cosh_mu * cos_th);
            let m2 = pr * pr + pim * pim;
            let (qr, qi) = (ws * pr / m2, -ws * pim / m2);
            let a1 = -two * qr; // s^2 + a1 s + a0, s in units of 2 fs
            let a0 = qr * qr + qi * qi;
            let wz = ws / cos_th; // zeros at +-j wz
            let wz2 = wz * wz;
            // unit DC gain; then the z-domain (s = (z - 1) / (z + 1) in this unit), a0 = 1
            let g = a0 / wz2;
            let d0 = T::ONE + a1 + a0;
            let bn = g * (T::ONE + wz2) / d0;
            *sec = Biquad {
                b: [bn, g * two * (wz2 - T::ONE) / d0, bn],
                a: [two * (a0 - T::ONE) / d0, (T::ONE - a1 + a0) / d0],
                s: [T::ZERO; 2],
            };
        }
        Some(Self { sections, fs_hz })
    }

    /// Filters one sample.
    #[inline]
    pub fn step(&mut self, x: T) -> T {
        let mut y = x;
        for s in self.sections.iter_mut() {
            y = s.step(y);
        }
        y
    }

    /// Clears the state.
    pub fn reset(&mut self) {
        self.sections.iter_mut().for_each(Biquad::reset);
    }

    /// Presets the state to the steady state of a constant input.
    pub fn preset(&mut self, x0: T) {
        self.sections.iter_mut().for_each(|s| s.preset(x0));
    }

    /// Exact gain (dB) of the implemented coefficients at frequency `f_hz`.
    pub fn gain_db(&self, f_hz: f64) -> f64 {
        let w = 2.0 * core::f64::consts::PI * f_hz / self.fs_hz;
        let (c1, s1) = (libm::cos(w), -libm::sin(w)); // z^-1
        let (c2, s2) = (libm::cos(2.0 * w), -libm::sin(2.0 * w)); // z^-2
        let mut mag2 = 1.0;
        for sec in &self.sections {
            let (b, a) = sec.coeffs_f64();
            let nr = b[0] + b[1] * c1 + b[2] * c2;
            let ni = b[1] * s1 + b[2] * s2;
            let dr = 1.0 + a[0] * c1 + a[1] * c2;
            let di = a[0] * s1 + a[1] * s2;
            mag2 *= (nr * nr + ni * ni) / (dr * dr + di * di);
        }
        10.0 * libm::log10(mag2)
    }
}

/// Anti-alias filter + keep-one-in-`factor` decimator.
#[derive(Clone, Copy, Debug)]
pub struct Decimator<T> {
    filter: Option<AntiAliasFilter<T>>,
    factor: u16,
    count: u16,
    primed: bool,
}

impl<T: Real> Decimator<T> {
    /// `factor` = 1 disables both filtering and decimation (used by the negative test that fits
    /// at the full rate). Returns `None` for `factor` = 0 or an invalid cut-off.
    pub fn new(fs_in_hz: f64, factor: u16, f_stop_hz: f64, atten_db: f64) -> Option<Self> {
        if factor == 0 {
            return None;
        }
        let filter = if factor > 1 {
            Some(AntiAliasFilter::design(f_stop_hz, atten_db, fs_in_hz)?)
        } else {
            None
        };
        Some(Self {
            filter,
            factor,
            count: 0,
            primed: false,
        })
    }

    /// Feeds one input sample; returns the filtered sample on every `factor`-th call.
    #[inline]
    pub fn push(&mut self, x: T) -> Option<T> {
        let y = match self.filter.as_mut() {
            Some(f) => {
                if !self.primed {
                    // Avoid a start-up transient from a non-zero offset (steering angle).
                    f.preset(x);
                    self.primed = true;
                }
                f.step(x)
            }
            None => x,
        };
        self.count += 1;
        if self.count >= self.factor {
            self.count = 0;
            Some(y)
        } else {
            None
        }
    }

    /// True when the next `push` produces an output sample.
    pub fn next_is_output(&self) -> bool {
        self.count + 1 >= self.factor
    }

    /// The anti-alias filter, if any.
    pub fn filter(&self) -> Option<&AntiAliasFilter<T>> {
        self.filter.as_ref()
    }

    /// Clears the filter state and the phase counter.
    pub fn reset(&mut self) {
        if let Some(f) = self.filter.as_mut() {
            f.reset();
        }
        self.count = 0;
        self.primed = false;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Closed-form magnitude of a bilinear-transformed Chebyshev-II low-pass:
    /// |H|^2 = 1 / (1 + 1 / (eps^2 T_N(W_s / W)^2)), W = tan(pi f / fs), 1/eps^2 = 10^(A/10) - 1.
    fn closed_form_db(f: f64, f_stop: f64, atten: f64, fs: f64, order: i32) -> f64 {
        let w = (core::f64::consts::PI * f / fs).tan();
        let ws = (core::f64::consts::PI * f_stop / fs).tan();
        let x = ws / w;
        let t = if x.abs() <= 1.0 {
            (order as f64 * x.acos()).cos()
        } else {
            (order as f64 * x.acosh()).cosh()
        };
        let inv_eps2 = 10f64.powf(atten / 10.0) - 1.0;
        -10.0 * (1.0 + inv_eps2 / (t * t)).log10()
    }

    #[test]
    fn aa_filter_matches_closed_form_and_stated_attenuation() {
        let f = AntiAliasFilter::<f64>::design(80.0, 60.0, 1000.0).unwrap();
        for &fr in &[1.0, 10.0, 20.0, 40.0, 50.0, 60.0, 80.0, 95.0, 200.0, 450.0] {
            let g = f.gain_db(fr);
            let c = closed_form_db(fr, 80.0, 60.0, 1000.0, 8);
            assert!((g - c).abs() < 1e-6 * (1.0 + c.abs()), "f={fr}: {g} vs {c}");
        }
        // flat up to the top of the shimmy band, >= 60 dB wherever content folds into it
        assert!(
            f.gain_db(20.0).abs() < 0.001,
            "passband at 20 Hz: {}",
            f.gain_db(20.0)
        );
        let worst_stop = (0..=4200)
            .map(|k| 80.0 + k as f64 * 0.1)
            .map(|fr| f.gain_db(fr))
            .fold(f64::NEG_INFINITY, f64::max);
        assert!(worst_stop <= -60.0 + 1e-6, "stop band: {worst_stop}");
        // the -3 dB point sits just above the output Nyquist (50 Hz)
        assert!(f.gain_db(50.0) > -3.0 && f.gain_db(60.0) < -3.0);
    }

    #[test]
    fn f32_design_keeps_the_stated_response() {
        // The target's filter is designed with f32 transcendentals and stores f32 coefficients:
        // its implemented response must still be the closed form's to well under the margins.
        let f = AntiAliasFilter::<f32>::design(80.0, 60.0, 1000.0).unwrap();
        for &fr in &[1.0, 10.0, 20.0, 40.0, 50.0, 60.0, 80.0, 95.0, 200.0, 450.0] {
            let g = f.gain_db(fr);
            let c = closed_form_db(fr, 80.0, 60.0, 1000.0, 8);
            assert!((g - c).abs() < 0.01, "f={fr}: {g} vs {c}");
        }
        assert!(f.gain_db(20.0).abs() < 0.001);
    }

    #[test]
    fn f32_design_is_the_f64_design_to_a_few_ulps() {
        // The design runs in the filter's precision: in f32 every coefficient must be the f64
        // design's to within a few ulps (measured 5.5 with the f32 `crate::trig`, 2.6 with
        // libm's f64-internal one; the cosine of the angle near pi/2 taken directly gives 12.9).
        // The f64 design itself is checked against the closed form above.
        for (f_stop, atten, fs) in [
            (80.0, 60.0, 1000.0),
            (40.0, 60.0, 500.0),
            (160.0, 40.0, 2000.0),
        ] {
            let d32 = AntiAliasFilter::<f32>::design(f_stop, atten, fs).unwrap();
            let d64 = AntiAliasFilter::<f64>::design(f_stop, atten, fs).unwrap();
            for (s32, s64) in d32.sections.iter().zip(&d64.sections) {
                let (b32, a32) = s32.coeffs_f64();
                let (b64, a64) = s64.coeffs_f64();
                for (c32, c64) in b32.iter().chain(&a32).zip(b64.iter().chain(&a64)) {
                    let ulp = f64::from(f32::EPSILON) * c64.abs().max(1e-30);
                    let off = (c32 - c64).abs() / ulp;
                    assert!(off <= 8.0, "{f_stop} Hz: {c32} vs {c64} ({off:.1} ulp)");
                }
            }
        }
    }

    #[test]
    fn f32_filter_time_domain_gain_matches_design() {
        // Independent check of the implemented recursion: steady-state sine amplitude.
        for &fr in &[10.0f64, 45.0, 85.0] {
            let mut d = AntiAliasFilter::<f32>::design(80.0, 60.0, 1000.0).unwrap();
            let mut peak = 0.0f64;
            for n in 0..6000 {
                let x = (2.0 * core::f64::consts::PI * fr * n as f64 / 1000.0).sin();
                let y = d.step(x as f32) as f64;
                if n > 3000 {
                    peak = peak.max(y.abs());
                }
            }
            let db = 20.0 * peak.log10();
            let exact = AntiAliasFilter::<f64>::design(80.0, 60.0, 1000.0)
                .unwrap()
                .gain_db(fr);
            assert!(
                (db - exact).abs() < 0.5,
                "f={fr}: measured {db} dB, design {exact} dB"
            );
        }
    }

    #[test]
    fn decimator_outputs_every_tenth_sample() {
        let mut d = Decimator::<f32>::new(1000.0, 10, 80.0, 60.0).unwrap();
        let outs = (0..100).filter(|_| d.push(1.0).is_some()).count();
        assert_eq!(outs, 10);
        assert!(Decimator::<f32>::new(1000.0, 0, 80.0, 60.0).is_none());
        assert!(Decimator::<f32>::new(1000.0, 10, 600.0, 60.0).is_none());
    }
}
