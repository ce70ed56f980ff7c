//! Open-loop scenarios: speed profiles, driver torque profiles and road disturbances, turned into
//! the plant's per-period [`Inputs`] (zero-order hold; each input is evaluated at the middle of
//! its control period).
//!
//! Disturbances: an initial yaw perturbation ([`initial_yaw`]), impulses (pothole / road joint:
//! a half-sine yaw-torque pulse), broadband random yaw torque (road: seeded Gaussian samples,
//! first-order low-pass, reproducible with `rand_chacha`), and wheel imbalance (once per wheel
//! revolution, f_w = V / (2 pi R), with amplitude and phase per wheel).

use crate::model::plant::{idx, Inputs, State, N_STATE};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use std::f64::consts::PI;

/// Forward speed as a function of time.
#[derive(Clone, Debug, PartialEq)]
pub enum SpeedProfile {
    /// Constant speed, m/s.
    Constant(f64),
    /// Linear ramp from `v0_mps` at `t0_s` to `v1_mps` at `t1_s`, constant outside.
    Ramp {
        /// Start speed, m/s.
        v0_mps: f64,
        /// End speed, m/s.
        v1_mps: f64,
        /// Ramp start, s.
        t0_s: f64,
        /// Ramp end, s.
        t1_s: f64,
    },
    /// Piecewise linear through `(t_s, v_mps)` points (sorted by time), constant outside.
    Piecewise(Vec<(f64, f64)>),
}

impl SpeedProfile {
    /// Speed (m/s) at `t_s`.
    pub fn at(&self, t_s: f64) -> f64 {
        match self {
            SpeedProfile::Constant(v) => *v,
            SpeedProfile::Ramp {
                v0_mps,
                v1_mps,
                t0_s,
                t1_s,
            } => SpeedProfile::Piecewise(vec![(*t0_s, *v0_mps), (*t1_s, *v1_mps)]).at(t_s),
            SpeedProfile::Piecewise(pts) => {
                let Some(first) = pts.first() else {
                    return 0.0;
                };
                if t_s <= first.0 {
                    return first.1;
                }
                for w in pts.windows(2) {
                    let ((ta, va), (tb, vb)) = (w[0], w[1]);
                    if t_s <= tb {
                        let span = tb - ta;
                        return if span > 0.0 {
                            va + (vb - va) * (t_s - ta) / span
                        } else {
                            vb
                        };
                    }
                }
                pts.last().map_or(0.0, |p| p.1)
            }
        }
    }
}

/// Driver torque at the steering wheel.
#[derive(Clone, Debug, PartialEq)]
pub enum DriverTorque {
    /// Hands off / no driver input.
    None,
    /// Single lane change: one full sine period of `amplitude_nm` and length `period_s`
    /// starting at `t0_s` (steer one way, then back), zero elsewhere.
    LaneChange {
        /// Peak torque, N m.
        amplitude_nm: f64,
        /// Length of the manoeuvre, s.
        period_s: f64,
        /// Start, s.
        t0_s: f64,
    },
    /// Slalom: continuous sine from `t0_s`.
    Slalom {
        /// Peak torque, N m.
        amplitude_nm: f64,
        /// Frequency, Hz.
        freq_hz: f64,
        /// Start, s.
        t0_s: f64,
    },
}

impl DriverTorque {
    /// Torque (N m) at `t_s`.
    pub fn at(&self, t_s: f64) -> f64 {
        match *self {
            DriverTorque::None => 0.0,
            DriverTorque::LaneChange {
                amplitude_nm,
                period_s,
                t0_s,
            } => {
                let tau = t_s - t0_s;
                if tau >= 0.0 && tau <= period_s {
                    amplitude_nm * (2.0 * PI * tau / period_s).sin()
                } else {
                    0.0
                }
            }
            DriverTorque::Slalom {
                amplitude_nm,
                freq_hz,
                t0_s,
            } => {
                if t_s >= t0_s {
                    amplitude_nm * (2.0 * PI * freq_hz * (t_s - t0_s)).sin()
                } else {
                    0.0
                }
            }
        }
    }
}

/// A short yaw-torque pulse on the wheels (pothole, road joint): a half sine.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Impulse {
    /// Start, s.
    pub t0_s: f64,
    /// Duration, s.
    pub duration_s: f64,
    /// Peak yaw torque on `[left, right]`, N m.
    pub peak_nm: [f64; 2],
}

impl Impulse {
    /// Torques (N m) at `t_s`.
    pub fn at(&self, t_s: f64) -> [f64; 2] {
        let tau = t_s - self.t0_s;
        if tau >= 0.0 && tau <= self.duration_s && self.duration_s > 0.0 {
            let s = (PI * tau / self.duration_s).sin();
            [self.peak_nm[0] * s, self.peak_nm[1] * s]
        } else {
            [0.0; 2]
        }
    }
}

/// Broadband random yaw torque (road): independent Gaussian samples per control period on each
/// wheel, passed through a first-order low-pass with corner `corner_hz`, scaled so the filtered
/// torque has standard deviation `std_nm` (for a corner well below the sample rate).
#[derive(Clone, Debug)]
pub struct RoadNoise {
    /// Standard deviation of the filtered torque, N m.
    pub std_nm: f64,
    /// Low-pass corner, Hz.
    pub corner_hz: f64,
    /// Fraction of the torque common to both wheels (0 = independent, 1 = identical).
    pub common: f64,
    rng: ChaCha8Rng,
    state: [f64; 2],
}

impl RoadNoise {
    /// Seeded road noise: the same seed gives the same torque sequence.
    pub fn new(std_nm: f64, corner_hz: f64, common: f64, seed: u64) -> Self {
        RoadNoise {
            std_nm,
            corner_hz,
            common: common.clamp(0.0, 1.0),
            rng: ChaCha8Rng::seed_from_u64(seed),
            state: [0.0; 2],
        }
    }

    /// Draws the torques, N m for the next period of length `dt_s`.
    pub fn next(&mut self, dt_s: f64) -> [f64; 2] {
        // Exact discretisation of x' = -w x + w sqrt(2/w) s w_noise so that var(x) = s^2:
        // x_{k+1} = a x_k + s sqrt(1 - a^2) n_k, a = exp(-w dt).
        let a = (-2.0 * PI * self.corner_hz * dt_s).exp();
        let g = self.std_nm * (1.0 - a * a).sqrt();
        let n_c: f64 = StandardNormal.sample(&mut self.rng);
        let n_l: f64 = StandardNormal.sample(&mut self.rng);
        let n_r: f64 = StandardNormal.sample(&mut self.rng);
        let (c, ind) = (self.common.sqrt(), (1.0 - self.common).sqrt());
        self.state[0] = a * self.state[0] + g * (c * n_c + ind * n_l);
        self.state[1] = a * self.state[1] + g * (c * n_c + ind * n_r);
        self.state
    }
}

/// Wheel imbalance: yaw torque `amplitude_nm[i] sin(theta_w + phase_rad[i])` with the wheel's
/// rotation angle theta_w = integral of V / R dt (once per revolution: f_w = V / (2 pi R)).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Imbalance {
    /// Torque amplitude per wheel, N m.
    pub amplitude_nm: [f64; 2],
    /// Phase per wheel, rad.
    pub phase_rad: [f64; 2],
    /// Rolling radius R, m.
    pub radius_m: f64,
}

/// An open-loop scenario: everything the plant sees except its own state.
#[derive(Clone, Debug)]
pub struct Scenario {
    /// Forward speed.
    pub speed: SpeedProfile,
    /// Constant coil current command, A (open loop).
    pub current_a: f64,
    /// Driver torque.
    pub driver: DriverTorque,
    /// Yaw-torque pulses.
    pub impulses: Vec<Impulse>,
    /// Road noise.
    pub noise: Option<RoadNoise>,
    /// Wheel imbalance.
    pub imbalance: Option<Imbalance>,
    wheel_angle_rad: f64,
}

impl Scenario {
    /// Constant speed, no current, no driver torque, no disturbance.
    pub fn constant_speed(v_mps: f64) -> Self {
        Self::new(SpeedProfile::Constant(v_mps))
    }

    /// A quiet scenario with a speed profile.
    pub fn new(speed: SpeedProfile) -> Self {
        Scenario {
            speed,
            current_a: 0.0,
            driver: DriverTorque::None,
            impulses: Vec::new(),
            noise: None,
            imbalance: None,
            wheel_angle_rad: 0.0,
        }
    }

    /// Inputs for the period `[t_s, t_s + dt_s)`; call once per period, in order (road noise and
    /// the wheel angle advance).
    pub fn inputs(&mut self, t_s: f64, dt_s: f64) -> Inputs {
        let tm = t_s + 0.5 * dt_s;
        let v = self.speed.at(tm);
        let mut yaw = [0.0; 2];
        for imp in &self.impulses {
            let y = imp.at(tm);
            yaw[0] += y[0];
            yaw[1] += y[1];
        }
        if let Some(n) = &mut self.noise {
            let y = n.next(dt_s);
            yaw[0] += y[0];
            yaw[1] += y[1];
        }
        if let Some(im) = &self.imbalance {
            // Wheel angle at the middle of the period (speed piecewise constant per period).
            let th = self.wheel_angle_rad + 0.5 * dt_s * v / im.radius_m;
            for (i, y) in yaw.iter_mut().enumerate() {
                *y += im.amplitude_nm[i] * (th + im.phase_rad[i]).sin();
            }
            self.wheel_angle_rad += dt_s * v / im.radius_m;
        }
        Inputs {
            current_cmd_a: self.current_a,
            driver_torque_nm: self.driver.at(tm),
            yaw_torque_nm: yaw,
            speed_mps: v,
        }
    }
}

/// Initial yaw perturbation: both wheels yawed by `psi_rad` (in phase), tyres undeflected
/// (a = 0), everything else at rest.
pub fn initial_yaw(psi_rad: f64) -> State {
    let mut x = [0.0; N_STATE];
    x[idx::PSI_L] = psi_rad;
    x[idx::PSI_R] = psi_rad;
    x
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn piecewise_speed_interpolates_and_holds_ends() {
        let s = SpeedProfile::Piecewise(vec![(1.0, 10.0), (3.0, 20.0), (4.0, 0.0)]);
        assert_eq!(s.at(0.0), 10.0);
        assert_eq!(s.at(2.0), 15.0);
        assert_eq!(s.at(3.5), 10.0);
        assert_eq!(s.at(9.0), 0.0);
        let r = SpeedProfile::Ramp {
            v0_mps: 5.0,
            v1_mps: 25.0,
            t0_s: 0.0,
            t1_s: 10.0,
        };
        assert_eq!(r.at(5.0), 15.0);
    }

    #[test]
    fn road_noise_is_reproducible_and_has_the_stated_spread() {
        let mut a = RoadNoise::new(2.0, 20.0, 0.0, 7);
        let mut b = RoadNoise::new(2.0, 20.0, 0.0, 7);
        let mut c = RoadNoise::new(2.0, 20.0, 0.0, 8);
        let n = 200_000;
        let (mut s2, mut cross, mut differs) = (0.0, 0.0, false);
        for _ in 0..n {
            let x = a.next(1e-3);
            assert_eq!(x, b.next(1e-3));
            differs |= x != c.next(1e-3);
            s2 += x[0] * x[0];
            cross += x[0] * x[1];
        }
        assert!(differs);
        let std = (s2 / n as f64).sqrt();
        // 200 s of a 20 Hz process: ~8000 correlation times, std estimate within ~3 %.
        assert!((std - 2.0).abs() < 0.1, "std {std}");
        // Independent wheels: correlation near zero.
        assert!((cross / s2).abs() < 0.05, "corr {}", cross / s2);
    }

    #[test]
    fn imbalance_is_once_per_revolution() {
        let r = 0.372;
        let v = 25.0;
        let mut s = Scenario::constant_speed(v);
        s.imbalance = Some(Imbalance {
            amplitude_nm: [1.0, 0.0],
            phase_rad: [0.0, 0.0],
            radius_m: r,
        });
        let dt = 1e-4;
        let f_w = v / (2.0 * PI * r);
        // Count upward zero crossings over 2 s.
        let (mut prev, mut ups) = (0.0, 0);
        let n = (2.0 / dt) as usize;
        for k in 0..n {
            let y = s.inputs(k as f64 * dt, dt).yaw_torque_nm[0];
            if prev < 0.0 && y >= 0.0 {
                ups += 1;
            }
            prev = y;
        }
        let expect = 2.0 * f_w;
        assert!((f64::from(ups) - expect).abs() <= 1.0, "{ups} vs {expect}");
    }

    #[test]
    fn lane_change_and_impulse_are_confined_to_their_windows() {
        let d = DriverTorque::LaneChange {
            amplitude_nm: 5.0,
            period_s: 2.0,
            t0_s: 1.0,
        };
        assert_eq!(d.at(0.5), 0.0);
        assert!((d.at(1.5) - 5.0).abs() < 1e-12);
        assert_eq!(d.at(3.5), 0.0);
        let i = Impulse {
            t0_s: 1.0,
            duration_s: 0.02,
            peak_nm: [100.0, 50.0],
        };
        assert_eq!(i.at(0.99), [0.0; 2]);
        assert!((i.at(1.01)[0] - 100.0).abs() < 1e-9);
        assert_eq!(i.at(1.03), [0.0; 2]);
    }
}
