//! Synthetic "truth" for the estimator tests: continuous second-order modes driven by white
//! noise, discretised EXACTLY (Van Loan's matrix-exponential method, nalgebra `Matrix::exp`),
//! measured with white noise at a given SNR, optionally with a wheel-order line. Independent of
//! the estimator's AR structure.
#![allow(dead_code)]

use nalgebra::DMatrix;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use shimmy_core::estimator::meter::mode_meter::{
    EstimatorConfig, MarginEstimator, MeterOutput, Sample, WheelOrder,
};
use shimmy_core::estimator::meter::real::Real;

pub const FS: f64 = 1000.0;
pub const PI2: f64 = 2.0 * std::f64::consts::PI;

/// One continuous mode x'' + 2 zeta w x' + w^2 x = w^2 * noise, output gain `gain`.
#[derive(Clone, Copy, Debug)]
pub struct ModeSpec {
    pub zeta: f64,
    pub f_hz: f64,
    pub gain: f64,
}

impl ModeSpec {
    /// A mode with unit output gain.
    pub fn unit(zeta: f64, f_hz: f64) -> Self {
        Self {
            zeta,
            f_hz,
            gain: 1.0,
        }
    }
}

type M4 = nalgebra::SMatrix<f64, 4, 4>;
type V4 = nalgebra::SVector<f64, 4>;

/// Exactly discretised block-diagonal system of up to two modes (fixed 4 states; a missing
/// second mode has output gain 0).
pub struct Truth {
    pub ad: M4,
    pub l: M4, // Cholesky factor of Qd
    pub c: V4,
    pub x: V4,
    pub y_var: f64,
}

/// Van Loan: exp([[-A, B Q B'], [0, A']] T) = [[., G12], [0, G22]]; Ad = G22', Qd = Ad G12.
pub fn discretise(a: &DMatrix<f64>, bqb: &DMatrix<f64>, t: f64) -> (DMatrix<f64>, DMatrix<f64>) {
    let n = a.nrows();
    let mut m = DMatrix::<f64>::zeros(2 * n, 2 * n);
    m.view_mut((0, 0), (n, n)).copy_from(&(-a * t));
    m.view_mut((0, n), (n, n)).copy_from(&(bqb * t));
    m.view_mut((n, n), (n, n)).copy_from(&(a.transpose() * t));
    let e = m.exp();
    let g12 = e.view((0, n), (n, n)).into_owned();
    let g22 = e.view((n, n), (n, n)).into_owned();
    let ad = g22.transpose();
    let qd = &ad * g12;
    let qd = (&qd + qd.transpose()) * 0.5;
    (ad, qd)
}

impl Truth {
    /// Unit-intensity white noise into each mode's acceleration, scaled by w^2; output variance
    /// from the closed form var(x) = w^4 / (4 zeta w^3) per mode (modes independent).
    pub fn new(modes: &[ModeSpec], dt: f64) -> Self {
        assert!(!modes.is_empty() && modes.len() <= 2);
        let mut all = modes.to_vec();
        if all.len() == 1 {
            all.push(ModeSpec {
                zeta: 0.5,
                f_hz: 10.0,
                gain: 0.0,
            });
        }
        let n = 4;
        let mut a = DMatrix::<f64>::zeros(n, n);
        let mut bqb = DMatrix::<f64>::zeros(n, n);
        let mut c = V4::zeros();
        let mut y_var = 0.0;
        for (i, m) in all.iter().enumerate() {
            let w = PI2 * m.f_hz;
            a[(2 * i, 2 * i + 1)] = 1.0;
            a[(2 * i + 1, 2 * i)] = -w * w;
            a[(2 * i + 1, 2 * i + 1)] = -2.0 * m.zeta * w;
            bqb[(2 * i + 1, 2 * i + 1)] = w.powi(4);
            c[2 * i] = m.gain;
            y_var += m.gain * m.gain * w.powi(4) / (4.0 * m.zeta * w.powi(3));
        }
        let (ad, qd) = discretise(&a, &bqb, dt);
        let l = qd.cholesky().expect("Qd positive definite").l();
        Self {
            ad: M4::from_iterator(ad.iter().copied()),
            l: M4::from_iterator(l.iter().copied()),
            c,
            x: V4::zeros(),
            y_var,
        }
    }

    /// Changes the dynamics keeping the state (for the damping-step test).
    pub fn retune(&mut self, modes: &[ModeSpec], dt: f64) {
        let x = self.x;
        *self = Self::new(modes, dt);
        self.x = x;
    }

    pub fn step(&mut self, rng: &mut ChaCha8Rng) -> f64 {
        let e = V4::from_fn(|_, _| rng.sample(StandardNormal));
        self.x = self.ad * self.x + self.l * e;
        self.c.dot(&self.x)
    }

    /// Start near the stationary distribution: run 5 slowest time constants.
    pub fn settle(&mut self, rng: &mut ChaCha8Rng, modes: &[ModeSpec], dt: f64) {
        let tc = modes
            .iter()
            .map(|m| 1.0 / (m.zeta * PI2 * m.f_hz))
            .fold(0.0, f64::max);
        for _ in 0..((5.0 * tc / dt) as usize) {
            self.step(rng);
        }
    }
}

/// Scenario of one synthetic run.
#[derive(Clone, Debug)]
pub struct Scenario {
    pub modes: Vec<ModeSpec>,
    pub snr_db: f64,
    /// RMS of the modal yaw response, rad.
    pub y_rms_rad: f64,
    /// Wheel-order line: (frequency Hz, amplitude relative to the modal RMS).
    pub line: Option<(f64, f64)>,
    /// Pass the wheel phase to the estimator.
    pub give_phase: bool,
}

impl Scenario {
    /// Ambient (road-noise) excitation only: no wheel-order line, modal yaw RMS 2 mrad.
    pub fn ambient(modes: Vec<ModeSpec>, snr_db: f64) -> Self {
        Self {
            modes,
            snr_db,
            y_rms_rad: 2e-3,
            line: None,
            give_phase: false,
        }
    }
}

pub struct Run<'a> {
    pub sc: &'a Scenario,
    pub truth: Truth,
    pub rng: ChaCha8Rng,
    pub scale: f64,
    pub noise_sd: f64,
    pub t: f64,
    pub line_phase0: f64,
}

impl<'a> Run<'a> {
    pub fn new(sc: &'a Scenario, seed: u64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut truth = Truth::new(&sc.modes, 1.0 / FS);
        truth.settle(&mut rng, &sc.modes, 1.0 / FS);
        let scale = sc.y_rms_rad / truth.y_var.sqrt();
        // measured yaw = (psi_L + psi_R)/2 with independent noise on each: var = sd^2 / 2
        let noise_var = sc.y_rms_rad.powi(2) / 10f64.powf(sc.snr_db / 10.0);
        let noise_sd = (2.0 * noise_var).sqrt();
        let line_phase0 = rng.random::<f64>() * PI2;
        Self {
            sc,
            truth,
            rng,
            scale,
            noise_sd,
            t: 0.0,
            line_phase0,
        }
    }

    /// Next 1 kHz sample.
    pub fn sample(&mut self) -> Sample {
        let mut y = self.truth.step(&mut self.rng) * self.scale;
        let mut wheel = WheelOrder::None;
        if let Some((f, a)) = self.sc.line {
            let ph = PI2 * f * self.t;
            y += a * self.sc.y_rms_rad * (ph + self.line_phase0).sin();
            if self.sc.give_phase {
                wheel = WheelOrder::Phase {
                    phase_rad: (ph % PI2) as f32,
                };
            }
        }
        let n1: f64 = self.rng.sample(StandardNormal);
        let n2: f64 = self.rng.sample(StandardNormal);
        self.t += 1.0 / FS;
        Sample {
            psi_l_rad: (y + self.noise_sd * n1) as f32,
            psi_r_rad: (y + self.noise_sd * n2) as f32,
            wheel,
            damper_cmd: 0.0,
        }
    }
}

/// Accuracy bound sqrt(zeta / (w_n T_eff)), T_eff = 2 / ((1 - lambda) f_s).
pub fn bound(zeta: f64, f_hz: f64, lambda: f64, fs_dec: f64) -> f64 {
    let t_eff = 2.0 / ((1.0 - lambda) * fs_dec);
    (zeta / (PI2 * f_hz * t_eff)).sqrt()
}

/// Runs `secs` seconds, returns slow/fast estimates sampled every `every_s` after `warm_s`.
pub fn collect<T: Real>(
    cfg: EstimatorConfig,
    sc: &Scenario,
    seed: u64,
    secs: f64,
    warm_s: f64,
    every_s: f64,
) -> Vec<MeterOutput> {
    let mut est = MarginEstimator::<T>::new(cfg).unwrap();
    let mut run = Run::new(sc, seed);
    let mut out = Vec::new();
    let mut next = warm_s;
    let n = (secs * FS) as usize;
    for k in 0..n {
        let s = run.sample();
        if let Some(o) = est.push(&s) {
            let t = k as f64 / FS;
            if t >= next {
                out.push(o);
                next += every_s;
            }
        }
    }
    out
}

pub fn mean_sd(v: &[f64]) -> (f64, f64) {
    let n = v.len() as f64;
    let m = v.iter().sum::<f64>() / n;
    let var = v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0);
    (m, var.sqrt())
}

pub fn median(v: &mut [f64]) -> f64 {
    v.sort_by(|a, b| a.partial_cmp(b).unwrap());
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}
