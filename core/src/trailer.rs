//! Trailer sway: a 2-DOF single-axle trailer (lateral and yaw motion) on a laterally compliant
//! hitch, after Diboll & Hagen, "Lateral stability of a highway or rail trailer" (J. Eng. Ind.
//! 91(4), 1969, 1069-1074), who found the sway a self-excited vibration governed by the lateral
//! springing at the towing pivot (`docs/trailer.md`; every number's source or reasoning is
//! there).
//!
//! The tow vehicle runs straight at V; the hitch (ball) is held to its path by a lateral spring
//! `k_y` and damper `c_y` (Diboll & Hagen's springing at the towing pivot; for a car-towed
//! caravan, the car's lateral compliance at the ball). Degrees of freedom `q = [y, psi]`:
//! - `y`: lateral displacement of the hitch from the tow path, m, positive to the left;
//! - `psi`: trailer yaw, rad, positive nose left; the tow vehicle does not yaw in this model, so
//!   `psi` is also the hitch (articulation) angle the sway damper and the sensor see.
//!
//! The trailer (mass `m`, yaw inertia `i_z` about its centre of gravity) has its centre of
//! gravity `a` and its axle `l` behind the hitch (nose load `m g (l - a) / l`). State vector (5):
//! `x = [y, psi, y', psi', alpha]` with the axle's lagged slip angle `alpha` (tyre force
//! `F = C_a alpha` to the left, relaxation length `sigma`):
//! `sigma alpha' = V (psi - alpha) - (y' - l psi')` (the axle's lateral velocity is
//! `y' - l psi'`). The lag keeps A(V) affine in V, as the family's trait requires (the lag-free
//! tyre's `1/V` damping is not), and it is physical: a trailer tyre's relaxation length is a
//! sizeable share of the sway's ~25-40 m wavelength.
//!
//! The damper is a sway-control damper at the hitch: a linear damper between the tow bar and
//! the drawbar at the lateral lever `l_d` from the ball, stroke rate `l_d psi'`, so its force
//! `F_d` puts the yaw moment `-l_d F_d` on the trailer (torsional coefficient `c l_d^2`).

use nalgebra::SVector;

use crate::model::{
    ComplexVector, LinearModel, Matrix, ModeShape, ModeShapeInfo, UpdatableModel, UpdateParam,
};

/// Standard gravity, m/s^2.
pub const G_MPS2: f64 = 9.80665;

/// Number of states of the trailer's linear model.
pub const N_STATES: usize = 5;
/// Number of mechanical degrees of freedom.
pub const N_DOF: usize = 2;

/// Hitch lateral displacement y, m.
pub const Y: usize = 0;
/// Trailer yaw (hitch angle) psi, rad.
pub const PSI: usize = 1;
/// Hitch lateral velocity, m/s.
pub const DY: usize = 2;
/// Trailer yaw rate, rad/s.
pub const DPSI: usize = 3;
/// Lagged slip angle of the axle, rad.
pub const ALPHA: usize = 4;

/// Short names of the states, for tables and CSV headers.
pub const STATE_NAMES: [&str; N_STATES] = ["y_m", "psi_rad", "dy_mps", "dpsi_radps", "alpha_rad"];

/// Physical parameters of the trailer and its hitch (`docs/trailer.md`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrailerParams {
    /// Laden trailer mass m, kg.
    pub m: f64,
    /// Yaw inertia about the centre of gravity I_z, kg m^2.
    pub i_z: f64,
    /// Hitch to axle l (Diboll & Hagen's length s in the Strouhal number), m.
    pub l: f64,
    /// Hitch to centre of gravity a (< l: a positive nose load), m.
    pub a: f64,
    /// Cornering stiffness of the axle (both tyres) per unit axle load C_a / F_z, 1/rad.
    pub c_a_per_fz: f64,
    /// Tyre relaxation length sigma, m.
    pub sigma: f64,
    /// Lateral stiffness of the hitch against the tow path k_y, N/m.
    pub k_y: f64,
    /// Lateral damping of the hitch against the tow path c_y, N s/m.
    pub c_y: f64,
    /// Lateral lever of the sway damper from the ball l_d, m.
    pub l_d: f64,
    /// Tyre-road friction coefficient mu (the simulator's tyre: peak force mu F_z).
    pub mu: f64,
    /// Magic-Formula shape factor C_s of the simulator's tyre.
    pub c_s: f64,
}

/// The named trailer parameter sets.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TrailerSet {
    /// A laden single-axle touring caravan behind a car.
    Caravan,
}

impl TrailerSet {
    /// Every named set.
    pub const ALL: [TrailerSet; 1] = [TrailerSet::Caravan];

    /// The set's name (vehicle files, command lines).
    pub const fn name(self) -> &'static str {
        match self {
            TrailerSet::Caravan => "trailer",
        }
    }

    /// Looks a set up by name.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|s| s.name() == name)
    }

    /// The set's parameters.
    pub fn params(self) -> TrailerParams {
        match self {
            TrailerSet::Caravan => TrailerParams::reference(),
        }
    }
}

impl TrailerParams {
    /// The reference caravan, every value explained in `docs/trailer.md`.
    pub fn reference() -> Self {
        let m = 1400.0;
        // radius of gyration: a uniform 5.5 m x 2.3 m box has sqrt((5.5^2 + 2.3^2)/12) = 1.72 m;
        // end-heavy loading (gas locker at the nose, washroom at the back) puts it at 1.8 m
        let k_g = 1.8;
        let l = 4.3;
        // nose load 6 % of the laden mass (the towing clubs' 5-7 %)
        let nose_frac = 0.06;
        Self {
            m,
            i_z: m * k_g * k_g,
            l,
            a: (1.0 - nose_frac) * l,
            c_a_per_fz: 7.0,
            sigma: 0.4,
            k_y: 5.0e3,
            c_y: 1.0e3,
            l_d: 0.3,
            mu: 0.9,
            c_s: 1.3,
        }
    }

    /// Static load on the axle (both tyres) F_z = m g a / l, N.
    pub fn axle_load_n(&self) -> f64 {
        self.m * G_MPS2 * self.a / self.l
    }

    /// Static nose load on the hitch m g (l - a) / l, N (negative: a tail-heavy trailer).
    pub fn nose_load_n(&self) -> f64 {
        self.m * G_MPS2 * (self.l - self.a) / self.l
    }

    /// Cornering stiffness of the axle C_a = (C_a/F_z) F_z, N/rad.
    pub fn cornering_stiffness(&self) -> f64 {
        self.c_a_per_fz * self.axle_load_n()
    }

    /// Yaw inertia about the hitch I_z + m a^2, kg m^2.
    pub fn i_hitch(&self) -> f64 {
        self.i_z + self.m * self.a * self.a
    }

    /// Natural frequency of the hitch's lateral springing sqrt(k_y / m), rad/s (the omega of
    /// the Strouhal number, `docs/trailer.md`).
    pub fn hitch_omega_radps(&self) -> f64 {
        libm::sqrt(self.k_y / self.m)
    }

    /// Diboll & Hagen's Strouhal number s omega / V with s = l and omega the hitch frequency.
    pub fn strouhal(&self, v_mps: f64) -> f64 {
        self.l * self.hitch_omega_radps() / v_mps
    }

    /// Diboll & Hagen's energy term mu G z / V^2 with mu = C_a/F_z, G = g and z = a:
    /// `C_a l / (m V^2)`, the tyres' yaw stiffness about the hitch over the kinetic energy.
    pub fn energy_term(&self, v_mps: f64) -> f64 {
        self.c_a_per_fz * G_MPS2 * self.a / (v_mps * v_mps)
    }

    /// Damping ratio of a sway damper of coefficient `c_nspm`: its torsional coefficient
    /// `c l_d^2` over `2 I_hitch omega` (the hitch frequency).
    pub fn damper_zeta(&self, c_nspm: f64) -> f64 {
        c_nspm * self.l_d * self.l_d / (2.0 * self.i_hitch() * self.hitch_omega_radps())
    }

    /// The sway damper coefficient of damping ratio `zeta` ([`Self::damper_zeta`]'s inverse),
    /// N s/m.
    pub fn damper_of_zeta(&self, zeta: f64) -> f64 {
        zeta * 2.0 * self.i_hitch() * self.hitch_omega_radps() / (self.l_d * self.l_d)
    }
}

/// One field of the trailer's parameters in a vehicle file: name, unit, plausible range (both
/// ends included: from a laboratory model trailer to a heavy car trailer, narrow enough to
/// reject a typo by orders of magnitude).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrailerField {
    /// Field name (`[trailer]` section of a vehicle file).
    pub name: &'static str,
    /// SI unit.
    pub unit: &'static str,
    /// Plausible range (lo, hi).
    pub range: (f64, f64),
}

/// Every field of [`TrailerParams`], in the order of `docs/trailer.md`'s table.
pub const TRAILER_FIELDS: [TrailerField; 11] = [
    TrailerField {
        name: "m",
        unit: "kg",
        range: (1.0, 20000.0),
    },
    TrailerField {
        name: "i_z",
        unit: "kg m^2",
        range: (0.01, 500000.0),
    },
    TrailerField {
        name: "l",
        unit: "m",
        range: (0.1, 15.0),
    },
    TrailerField {
        name: "a",
        unit: "m",
        range: (0.05, 15.0),
    },
    TrailerField {
        name: "c_a_per_fz",
        unit: "1/rad",
        range: (0.5, 30.0),
    },
    TrailerField {
        name: "sigma",
        unit: "m",
        range: (0.001, 3.0),
    },
    TrailerField {
        name: "k_y",
        unit: "N/m",
        range: (1.0, 100000000.0),
    },
    TrailerField {
        name: "c_y",
        unit: "N s/m",
        range: (0.0, 1000000.0),
    },
    TrailerField {
        name: "l_d",
        unit: "m",
        range: (0.01, 2.0),
    },
    TrailerField {
        name: "mu",
        unit: "-",
        range: (0.05, 1.5),
    },
    TrailerField {
        name: "c_s",
        unit: "-",
        range: (0.5, 3.0),
    },
];

/// Why a trailer parameter set is rejected.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum TrailerFieldError {
    /// No field of that name.
    #[error("no trailer field of that name")]
    Unknown,
    /// A value outside its field's plausible range (or not finite).
    #[error("field `{name}` = {value} {unit} is outside {lo} ..= {hi} {unit}")]
    OutOfRange {
        /// The field.
        name: &'static str,
        /// The value given.
        value: f64,
        /// Lower end of the range.
        lo: f64,
        /// Upper end of the range.
        hi: f64,
        /// The field's unit.
        unit: &'static str,
    },
    /// The centre of gravity is too far behind the axle for a single-axle trailer on a ball.
    #[error(
        "field `a` = {a} m: the centre of gravity must lie ahead of 1.5 l = {max:.3} m (at most a \
         tail load of half the mass on the hitch)"
    )]
    TailHeavy {
        /// Hitch to centre of gravity, m.
        a: f64,
        /// 1.5 l, m.
        max: f64,
    },
}

impl TrailerParams {
    fn field_mut(&mut self, name: &str) -> Option<&mut f64> {
        Some(match name {
            "m" => &mut self.m,
            "i_z" => &mut self.i_z,
            "l" => &mut self.l,
            "a" => &mut self.a,
            "c_a_per_fz" => &mut self.c_a_per_fz,
            "sigma" => &mut self.sigma,
            "k_y" => &mut self.k_y,
            "c_y" => &mut self.c_y,
            "l_d" => &mut self.l_d,
            "mu" => &mut self.mu,
            "c_s" => &mut self.c_s,
            _ => return None,
        })
    }

    /// The value of the field `name`.
    pub fn get(&self, name: &str) -> Option<f64> {
        let mut copy = *self;
        copy.field_mut(name).map(|v| *v)
    }

    /// Sets the field `name` to `value` if it is inside the field's range.
    pub fn set(&mut self, name: &str, value: f64) -> Result<(), TrailerFieldError> {
        let field = TRAILER_FIELDS
            .iter()
            .find(|f| f.name == name)
            .ok_or(TrailerFieldError::Unknown)?;
        check(field, value)?;
        *self.field_mut(name).ok_or(TrailerFieldError::Unknown)? = value;
        Ok(())
    }

    /// Every field inside its range, and a centre of gravity ahead of 1.5 l; the first
    /// offender.
    pub fn validate(&self) -> Result<(), TrailerFieldError> {
        for f in &TRAILER_FIELDS {
            check(f, self.get(f.name).ok_or(TrailerFieldError::Unknown)?)?;
        }
        let max = 1.5 * self.l;
        if self.a > max {
            return Err(TrailerFieldError::TailHeavy { a: self.a, max });
        }
        Ok(())
    }
}

fn check(f: &TrailerField, value: f64) -> Result<(), TrailerFieldError> {
    let (lo, hi) = f.range;
    if (lo..=hi).contains(&value) {
        Ok(())
    } else {
        Err(TrailerFieldError::OutOfRange {
            name: f.name,
            value,
            lo,
            hi,
            unit: f.unit,
        })
    }
}

impl LinearModel<N_STATES> for TrailerParams {
    const NAME: &'static str = "trailer-2dof";
    const STATE_NAMES: [&'static str; N_STATES] = STATE_NAMES;
    const DOF: usize = 2;

    /// `M q'' + D q' + K q = G alpha + b F_d` with `M = [[m, -m a], [-m a, I_z + m a^2]]`
    /// (the centre of gravity's lateral position is `y - a psi`), `K = diag(k_y, 0)`,
    /// `D = diag(c_y, c l_d^2)`, `G = C_a [1, -l]`; `M^-1 = [[I_h, m a], [m a, m]] / (m I_z)`
    /// written out entry by entry; the last row is the tyre lag.
    fn linearise(&self, v_mps: f64, c_damper_nspm: f64) -> Matrix<N_STATES> {
        let ct = c_damper_nspm * self.l_d * self.l_d;
        let ca = self.cornering_stiffness();
        let b = self.l - self.a;
        let (m, iz, a) = (self.m, self.i_z, self.a);
        // M^-1 entries
        let m00 = self.i_hitch() / (m * iz);
        let m01 = a / iz;
        let m11 = 1.0 / iz;
        let mut x = Matrix::<N_STATES>::zeros();
        x[(Y, DY)] = 1.0;
        x[(PSI, DPSI)] = 1.0;
        // generalised forces: Q_y = -k_y y - c_y y' + C_a alpha, Q_psi = -c_t psi' - l C_a alpha
        x[(DY, Y)] = -self.k_y * m00;
        x[(DY, DY)] = -self.c_y * m00;
        x[(DY, DPSI)] = -ct * m01;
        x[(DY, ALPHA)] = ca * (iz - m * a * b) / (m * iz);
        x[(DPSI, Y)] = -self.k_y * m01;
        x[(DPSI, DY)] = -self.c_y * m01;
        x[(DPSI, DPSI)] = -ct * m11;
        x[(DPSI, ALPHA)] = -ca * b / iz;
        // tyre lag: sigma alpha' = V (psi - alpha) - y' + l psi'
        let inv_sigma = 1.0 / self.sigma;
        x[(ALPHA, PSI)] = v_mps * inv_sigma;
        x[(ALPHA, ALPHA)] = -v_mps * inv_sigma;
        x[(ALPHA, DY)] = -inv_sigma;
        x[(ALPHA, DPSI)] = self.l * inv_sigma;
        x
    }

    fn dlinearise_dv(&self) -> Matrix<N_STATES> {
        let mut d = Matrix::<N_STATES>::zeros();
        d[(ALPHA, PSI)] = 1.0 / self.sigma;
        d[(ALPHA, ALPHA)] = -1.0 / self.sigma;
        d
    }

    /// The yaw moment `-l_d F_d` through `M^-1`.
    fn damper_force_input(&self) -> SVector<f64, N_STATES> {
        let mut b = SVector::<f64, N_STATES>::zeros();
        b[DY] = -self.l_d * self.a / self.i_z;
        b[DPSI] = -self.l_d / self.i_z;
        b
    }

    /// The trailer yaw, which is the hitch angle here (the tow vehicle does not yaw).
    fn wheel_yaw_output(&self) -> SVector<f64, N_STATES> {
        let mut c = SVector::<f64, N_STATES>::zeros();
        c[PSI] = 1.0;
        c
    }

    /// 10: the sway at its onset (0.64 Hz for the caravan) is ten times slower than the car's
    /// ~6 Hz shimmy; the car's 3-20 Hz band becomes 0.3-2 Hz, the decimation 100 (a 10 Hz
    /// meter rate) and its memories ten times longer in seconds, the same in sway cycles.
    fn meter_time_scale(&self) -> u16 {
        10
    }

    /// By the modal kinetic energy of yaw about the hitch (`I_h |psi'|^2`) against the hitch's
    /// lateral motion (`m |y'|^2`): [`ModeShape::Sway`] when yaw has the larger share,
    /// [`ModeShape::HitchLateral`] otherwise; [`ModeShape::TyreLag`] when the slip angle
    /// exceeds three times the largest displacement (psi, or y over l, the yaw it makes).
    /// Fields of the family's [`ModeShapeInfo`]: `wheel_energy_frac` is the yaw share (the
    /// measured motion), `steering_wheel_energy_frac` the hitch-lateral share,
    /// `steering_wheel_ratio` `|y| / (l |psi|)`, `wheel_phase_rad` the phase of y against psi;
    /// tramp does not exist (0).
    fn classify(&self, v: &ComplexVector<N_STATES>) -> ModeShapeInfo {
        let e_yaw = self.i_hitch() * v[DPSI].norm_sqr();
        let e_hitch = self.m * v[DY].norm_sqr();
        let e_tot = e_yaw + e_hitch;
        let frac = |e: f64| if e_tot > 0.0 { e / e_tot } else { 0.0 };
        let psi = libm::sqrt(v[PSI].norm_sqr());
        let y_over_l = libm::sqrt(v[Y].norm_sqr()) / self.l;
        let disp = psi.max(y_over_l);
        let tyre = libm::sqrt(v[ALPHA].norm_sqr());
        let tyre_ratio = if disp > 0.0 {
            tyre / disp
        } else {
            f64::INFINITY
        };
        let shape = if tyre_ratio > 3.0 || e_tot == 0.0 {
            ModeShape::TyreLag
        } else if e_yaw >= e_hitch {
            ModeShape::Sway
        } else {
            ModeShape::HitchLateral
        };
        let ratio = if psi > 0.0 {
            y_over_l / psi
        } else {
            f64::INFINITY
        };
        let phase = if psi > 0.0 {
            let r = v[Y] / v[PSI];
            libm::atan2(r.im, r.re)
        } else {
            0.0
        };
        ModeShapeInfo {
            shape,
            wheel_energy_frac: frac(e_yaw),
            tramp_energy_frac: 0.0,
            steering_wheel_energy_frac: frac(e_hitch),
            steering_wheel_ratio: ratio,
            wheel_phase_rad: phase,
            tyre_ratio,
        }
    }
}

/// No parameter is updated online yet: this model's identifiability study has not been run, so
/// its margin stays the vehicle file's (corrected by the fusion's measured damping offset).
impl UpdatableModel<N_STATES> for TrailerParams {
    const UPDATE_PARAMS: &'static [UpdateParam] = &[];

    fn scaled_update_param(&self, _index: usize, _factor: f64) -> Self {
        *self
    }

    fn update_param(&self, _index: usize) -> f64 {
        f64::NAN
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::eigen;
    use crate::stability::{self, CrossingKind};

    fn onset(p: &TrailerParams, c: f64) -> Option<stability::HopfCrossing> {
        stability::hopf_crossings(p, c, 1.0, 70.0, 0.5, 1e-7)
            .unwrap()
            .iter()
            .find(|x| x.kind == CrossingKind::Onset)
            .copied()
    }

    /// Every field is in the table, reads back what was set, and a value out of range or a
    /// tail-heavy centre of gravity is rejected naming the field.
    #[test]
    fn the_field_table_covers_every_field_and_checks_ranges() {
        let mut t = TrailerSet::Caravan.params();
        t.validate().unwrap();
        for f in &TRAILER_FIELDS {
            let v = t.get(f.name).unwrap();
            let mid = 0.5 * (f.range.0 + f.range.1);
            let mut u = t;
            u.set(f.name, mid).unwrap();
            assert_eq!(u.get(f.name), Some(mid), "{}", f.name);
            assert!(u != t || v == mid, "{} sets nothing", f.name);
        }
        let e = t.set("k_y", -5.0).unwrap_err();
        assert!(
            matches!(e, TrailerFieldError::OutOfRange { name: "k_y", .. }),
            "{e}"
        );
        assert!(t.set("sigma", f64::NAN).is_err());
        assert_eq!(t.set("no_such", 1.0), Err(TrailerFieldError::Unknown));
        t.set("a", 7.0).unwrap();
        let e = t.validate().unwrap_err();
        assert!(matches!(e, TrailerFieldError::TailHeavy { .. }), "{e}");
        assert!(e.to_string().contains("field `a`"), "{e}");
    }

    #[test]
    fn a_is_affine_in_speed_with_the_stated_derivative() {
        let t = TrailerSet::Caravan.params();
        let a0 = t.linearise(3.0, 2.0e4);
        let a1 = t.linearise(31.0, 2.0e4);
        let err = (a1 - a0 - t.dlinearise_dv() * 28.0).amax();
        assert!(err < 1e-12 * a0.amax(), "{err}");
    }

    /// The mass and stiffness recovered from A: `M A_rows = -K` and the damper column is
    /// `M^-1 [0, -l_d]`; checked by multiplying back with M built from its definition.
    #[test]
    fn structure_matches_the_equations() {
        let t = TrailerSet::Caravan.params();
        let c = 3.0e4;
        let a = t.linearise(20.0, c);
        let mass = nalgebra::Matrix2::new(t.m, -t.m * t.a, -t.m * t.a, t.i_hitch());
        let rows = nalgebra::Matrix2x5::from_fn(|i, j| a[(N_DOF + i, j)]);
        let q = mass * rows;
        // generalised forces per unit state: -K, -D, G
        let ca = t.cornering_stiffness();
        let want = nalgebra::Matrix2x5::from_row_slice(&[
            -t.k_y,
            0.0,
            -t.c_y,
            0.0,
            ca,
            0.0,
            0.0,
            0.0,
            -c * t.l_d * t.l_d,
            -t.l * ca,
        ]);
        assert!((q - want).amax() < 1e-9 * want.amax(), "{q} vs {want}");
        let bd =
            mass * nalgebra::Vector2::new(t.damper_force_input()[DY], t.damper_force_input()[DPSI]);
        assert!((bd - nalgebra::Vector2::new(0.0, -t.l_d)).amax() < 1e-12);
        assert!((a[(ALPHA, DPSI)] - t.l / t.sigma).abs() < 1e-12 * t.l / t.sigma);
    }

    /// The reference caravan sways (0.5-1.5 Hz, yaw-dominated) from a critical speed on
    /// European roads: stable below, unstable above; the sway damper raises it.
    #[test]
    fn the_caravan_has_a_sway_onset_that_the_damper_raises() {
        let t = TrailerSet::Caravan.params();
        let x = onset(&t, 0.0).expect("an onset below 252 km/h");
        assert_eq!(x.shape, ModeShape::Sway);
        assert!(x.freq_hz > 0.5 && x.freq_hz < 1.5, "{}", x.freq_hz);
        assert!(x.speed_mps > 20.0 && x.speed_mps < 40.0, "{}", x.speed_mps);
        let below = stability::critical_mode_at(&t, x.speed_mps - 1.0, 0.0).unwrap();
        let above = stability::critical_mode_at(&t, x.speed_mps + 1.0, 0.0).unwrap();
        assert!(below.re < 0.0 && above.re > 0.0);
        let damped = onset(&t, t.damper_of_zeta(0.05)).map_or(f64::INFINITY, |x| x.speed_mps);
        assert!(damped > x.speed_mps + 2.0, "{damped} vs {}", x.speed_mps);
        // the shimmy selector of the family picks the sway mode
        let sway = stability::mode_at(&t, x.speed_mps, 0.0, stability::ModeSelect::Shimmy).unwrap();
        assert!((sway.freq_hz - x.freq_hz).abs() < 1e-6);
    }

    /// The closed form of the lag-free, undamped 2-DOF limit (`docs/trailer.md`): the quartic's
    /// Hurwitz determinant is `u^2 C_a^2 k_y l D (k_y l D + C_a I_ax)` with `u = 1/V`,
    /// `D = m a b - I_z` and `I_ax = I_z + m b^2`, so stability does not depend on speed and a
    /// trailer with `I_z > m a b` needs `k_y > C_a I_ax / (l |D|)`. Checked on the eigenvalues
    /// with sigma = 1 mm and no damping, 2 % on either side of that stiffness, at three speeds.
    #[test]
    fn the_lag_free_limit_has_the_closed_form_hitch_stiffness_threshold() {
        let mut t = TrailerSet::Caravan.params();
        t.sigma = 1e-3;
        t.c_y = 0.0;
        let b = t.l - t.a;
        let d = t.m * t.a * b - t.i_z;
        assert!(d < 0.0);
        let i_ax = t.i_z + t.m * b * b;
        let k_star = t.cornering_stiffness() * i_ax / (t.l * d.abs());
        for (factor, stable) in [(0.98, false), (1.02, true)] {
            t.k_y = factor * k_star;
            for v in [10.0, 25.0, 40.0] {
                let g = stability::critical_mode_at(&t, v, 0.0).unwrap().re;
                assert_eq!(g < 0.0, stable, "k_y {factor} k*, V {v}: growth {g}");
            }
        }
    }

    /// The critical speed by Routh-Hurwitz on the characteristic polynomial, built without
    /// any eigen-solve: `p(s) = (sigma s + V) det Q(s) - r(s)^T adj Q(s) g` with
    /// `Q = M s^2 + D s + K`, `g = C_a [1, -l]` and `r(s) = [-s, V + l s]` (the lag equation in
    /// Laplace form). Its Hurwitz sign change, found by bisection, must be the eigenvalue
    /// crossing to 1e-6 relative, without and with the damper.
    #[test]
    fn routh_hurwitz_on_the_characteristic_polynomial_gives_the_same_critical_speed() {
        let t = TrailerSet::Caravan.params();
        for c in [0.0, t.damper_of_zeta(0.05)] {
            let eig = onset(&t, c).unwrap().speed_mps;
            let stable = |v: f64| hurwitz_stable(&char_poly(&t, v, c));
            assert!(stable(eig - 0.5) && !stable(eig + 0.5), "c {c}");
            let (mut lo, mut hi) = (eig - 0.5, eig + 0.5);
            for _ in 0..60 {
                let mid = 0.5 * (lo + hi);
                if stable(mid) {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            let rh = 0.5 * (lo + hi);
            assert!(
                (rh - eig).abs() < 1e-6 * eig,
                "c {c}: Routh-Hurwitz {rh}, eigen {eig}"
            );
        }
    }

    /// Polynomial coefficients, lowest power first.
    fn mul(p: &[f64], q: &[f64]) -> [f64; 7] {
        let mut r = [0.0; 7];
        for (i, a) in p.iter().enumerate() {
            for (j, b) in q.iter().enumerate() {
                r[i + j] += a * b;
            }
        }
        r
    }

    fn char_poly(t: &TrailerParams, v: f64, c: f64) -> [f64; 7] {
        let ca = t.cornering_stiffness();
        // Q(s) entries as polynomials [s^0, s^1, s^2]
        let q00 = [t.k_y, t.c_y, t.m];
        let q01 = [0.0, 0.0, -t.m * t.a];
        let q11 = [0.0, c * t.l_d * t.l_d, t.i_hitch()];
        let det: Vec<f64> = mul(&q00, &q11)
            .iter()
            .zip(mul(&q01, &q01))
            .map(|(x, y)| x - y)
            .collect();
        let mut p = mul(&[v, t.sigma], &det[..5]);
        // r^T adj(Q) g with adj(Q) = [[q11, -q01], [-q01, q00]], g = ca [1, -l], r = [-s, V + l s]
        let g0 = [ca];
        let g1 = [-t.l * ca];
        let adj_g0: Vec<f64> = mul(&q11, &g0)
            .iter()
            .zip(mul(&q01, &g1))
            .map(|(x, y)| x - y)
            .collect();
        let adj_g1: Vec<f64> = mul(&q00, &g1)
            .iter()
            .zip(mul(&q01, &g0))
            .map(|(x, y)| x - y)
            .collect();
        let term0 = mul(&[0.0, -1.0], &adj_g0[..3]);
        let term1 = mul(&[v, t.l], &adj_g1[..3]);
        for i in 0..7 {
            p[i] -= term0[i] + term1[i];
        }
        p
    }

    /// Routh's criterion: every entry of the first column has the leading coefficient's sign.
    fn hurwitz_stable(p: &[f64; 7]) -> bool {
        let deg = (0..7).rev().find(|&i| p[i] != 0.0).unwrap();
        let coef: Vec<f64> = (0..=deg).rev().map(|i| p[i]).collect();
        let mut r0: Vec<f64> = coef.iter().step_by(2).copied().collect();
        let mut r1: Vec<f64> = coef.iter().skip(1).step_by(2).copied().collect();
        let sign = coef[0].signum();
        if r0[0] * sign <= 0.0 {
            return false;
        }
        for _ in 0..deg {
            if r1.is_empty() || r1[0] * sign <= 0.0 {
                return false;
            }
            let next: Vec<f64> = (0..r0.len() - 1)
                .map(|j| {
                    let x = r0.get(j + 1).copied().unwrap_or(0.0);
                    let y = r1.get(j + 1).copied().unwrap_or(0.0);
                    (r1[0] * x - r0[0] * y) / r1[0]
                })
                .collect();
            r0 = r1;
            r1 = next;
            if r1.is_empty() {
                break;
            }
        }
        true
    }

    /// The eigenvalues are those of the polynomial's roots: its value at every eigenvalue is
    /// zero to rounding (relative to the size of its terms).
    #[test]
    fn the_characteristic_polynomial_vanishes_at_the_eigenvalues() {
        let t = TrailerSet::Caravan.params();
        for v in [5.0, 28.0, 45.0] {
            let p = char_poly(&t, v, 1.0e4);
            for l in eigen::eigenvalues(&t.linearise(v, 1.0e4)).unwrap() {
                let (mut val, mut scale, mut pow) = (
                    nalgebra::Complex::new(0.0, 0.0),
                    0.0,
                    nalgebra::Complex::new(1.0, 0.0),
                );
                for c in p {
                    val += pow * c;
                    scale += (pow * c).norm();
                    pow *= l;
                }
                assert!(val.norm() < 1e-10 * scale, "V {v}, {l}: {val} of {scale}");
            }
        }
    }

    /// Diboll & Hagen's groups: scaling the trailer (masses x2.7, lengths x1.6) and choosing
    /// the hitch stiffness and the speed that keep s omega / V and mu G z / V^2 leaves the
    /// damping ratio of every mode unchanged (the dimensionless problem is the same).
    #[test]
    fn the_dimensionless_groups_make_similar_trailers_behave_alike() {
        let t = TrailerSet::Caravan.params();
        let v = 30.0;
        let (fm, fl) = (2.7, 1.6);
        let mut s = t;
        s.m *= fm;
        s.i_z *= fm * fl * fl;
        s.l *= fl;
        s.a *= fl;
        s.sigma *= fl;
        s.l_d *= fl;
        // same energy term: V^2 scales with a; same Strouhal: omega scales with V / l
        let vs = v * libm::sqrt(fl);
        s.k_y = s.m * libm::pow(t.strouhal(v) * vs / s.l, 2.0);
        // same lateral damping ratio c_y / (2 sqrt(k_y m)) and same damper ratio
        s.c_y = t.c_y / libm::sqrt(t.k_y * t.m) * libm::sqrt(s.k_y * s.m);
        let c = t.damper_of_zeta(0.03);
        let cs = s.damper_of_zeta(0.03);
        assert!((s.strouhal(vs) - t.strouhal(v)).abs() < 1e-12);
        assert!((s.energy_term(vs) - t.energy_term(v)).abs() < 1e-12);
        let z = |p: &TrailerParams, v: f64, c: f64| {
            let mut zs: Vec<f64> = eigen::eigenvalues(&p.linearise(v, c))
                .unwrap()
                .iter()
                .filter(|l| l.im > 0.0)
                .map(|l| -l.re / l.norm())
                .collect();
            zs.sort_by(f64::total_cmp);
            zs
        };
        let (a, b) = (z(&t, v, c), z(&s, vs, cs));
        assert_eq!(a.len(), b.len());
        for (x, y) in a.iter().zip(&b) {
            assert!((x - y).abs() < 1e-9, "{a:?} vs {b:?}");
        }
    }
}

#[cfg(test)]
mod tracker_tests {
    use super::*;
    use crate::eigen::SolveFloat;
    use crate::estimator::model_margin::{ModelMarginConfig, ModelMarginTracker};
    use crate::stability::{self, CrossingKind};

    /// The model-margin tracker runs on the trailer (5 states) in both precisions: its onset
    /// above the current speed is the scan's Hopf crossing, of the sway mode.
    #[test]
    fn the_tracker_finds_the_trailers_onset() {
        fn check<T: SolveFloat>() {
            let t = TrailerSet::Caravan.params();
            let scan = stability::hopf_crossings(&t, 0.0, 1.0, 70.0, 0.5, 1e-7).unwrap();
            let onset = scan.iter().find(|c| c.kind == CrossingKind::Onset).unwrap();
            let mut tr = ModelMarginTracker::<T, TrailerParams, N_STATES>::in_precision(
                t,
                ModelMarginConfig::default(),
            );
            let p = (0..200u16)
                .find_map(|k| tr.step(f64::from(k) * 1e-3, 20.0, 0.0))
                .expect("a cycle completes");
            let above = p.above.expect("an onset above 20 m/s");
            assert_eq!(above.kind, CrossingKind::Onset);
            assert!(
                (above.speed_mps - onset.speed_mps).abs() < 2e-3,
                "{}: {} vs {}",
                T::NAME,
                above.speed_mps,
                onset.speed_mps
            );
            assert!(p.shimmy_found && p.slope_valid, "{}", T::NAME);
        }
        check::<f64>();
        check::<f32>();
    }
}
