//! Parameters of the 4-DOF solid-axle steering plant (`docs/plant-model.md`), in one place.
//!
//! SI units throughout (rad, m, s, N, N m). Named sets are built by functions here and nowhere
//! else; studies derive variants with [`PlantParams::with`] / [`PlantParams::scaled`].

#[allow(unused_imports)]
use super::*;

/// Physical parameters of the steering plant. Field names follow the symbols of the reference
/// document; the unit of each field is in its doc comment.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlantParams {
    /// Wheel-assembly yaw inertia about the kingpin I_k, kg m^2.
    pub i_k: f64,
    /// Wheel spin inertia I_p, kg m^2 (gyroscopic coupling).
    pub i_p: f64,
    /// Rolling radius R, m.
    pub r: f64,
    /// Roll-centre height h_r, m.
    pub h_r: f64,
    /// Axle roll inertia I_phi, kg m^2.
    pub i_phi: f64,
    /// Tramp (roll) stiffness K_phi, N m/rad.
    pub k_phi: f64,
    /// Tramp damping c_phi, N m s/rad.
    pub c_phi: f64,
    /// Cornering stiffness per tyre C_a, N/rad.
    pub c_a: f64,
    /// Tyre relaxation length sigma, m.
    pub sigma: f64,
    /// Caster (mechanical) trail e, m.
    pub e: f64,
    /// Pneumatic trail t_p, m.
    pub t_p: f64,
    /// Steering-arm length l_t, m.
    pub l_t: f64,
    /// Track-rod stiffness referred to the kingpin K_tr, N m/rad.
    pub k_tr: f64,
    /// Drag link + gear stiffness at the kingpin K_d, N m/rad.
    pub k_d: f64,
    /// Overall steering ratio i_s.
    pub i_s: f64,
    /// Steering-wheel inertia J_sw, kg m^2.
    pub j_sw: f64,
    /// Steering-wheel damping c_sw, N m s/rad.
    pub c_sw: f64,
    /// Kingpin damping c_k, N m s/rad.
    pub c_k: f64,
    /// Static load per front wheel F_z, N.
    pub f_z: f64,
    /// Tyre-road friction coefficient mu (Magic Formula peak D = mu F_z).
    pub mu: f64,
    /// Magic-Formula shape factor C_s.
    pub c_s: f64,
}

/// One named parameter, for overrides and sensitivity studies.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Param {
    /// [`PlantParams::i_k`]
    IK,
    /// [`PlantParams::i_p`]
    IP,
    /// [`PlantParams::r`]
    R,
    /// [`PlantParams::h_r`]
    HR,
    /// [`PlantParams::i_phi`]
    IPhi,
    /// [`PlantParams::k_phi`]
    KPhi,
    /// [`PlantParams::c_phi`]
    CPhi,
    /// [`PlantParams::c_a`]
    CA,
    /// [`PlantParams::sigma`]
    Sigma,
    /// [`PlantParams::e`]
    E,
    /// [`PlantParams::t_p`]
    TP,
    /// [`PlantParams::l_t`]
    LT,
    /// [`PlantParams::k_tr`]
    KTr,
    /// [`PlantParams::k_d`]
    KD,
    /// [`PlantParams::i_s`]
    IS,
    /// [`PlantParams::j_sw`]
    JSw,
    /// [`PlantParams::c_sw`]
    CSw,
    /// [`PlantParams::c_k`]
    CK,
    /// [`PlantParams::f_z`]
    FZ,
    /// [`PlantParams::mu`]
    Mu,
    /// [`PlantParams::c_s`]
    CS,
}

impl Param {
    /// Every parameter, in the order of the reference table.
    pub const ALL: [Param; 21] = [
        Param::IK,
        Param::IP,
        Param::R,
        Param::HR,
        Param::IPhi,
        Param::KPhi,
        Param::CPhi,
        Param::CA,
        Param::Sigma,
        Param::E,
        Param::TP,
        Param::LT,
        Param::KTr,
        Param::KD,
        Param::IS,
        Param::JSw,
        Param::CSw,
        Param::CK,
        Param::FZ,
        Param::Mu,
        Param::CS,
    ];

    /// The field name (as in scenario files and CSV headers).
    pub const fn name(self) -> &'static str {
        match self {
            Param::IK => "i_k",
            Param::IP => "i_p",
            Param::R => "r",
            Param::HR => "h_r",
            Param::IPhi => "i_phi",
            Param::KPhi => "k_phi",
            Param::CPhi => "c_phi",
            Param::CA => "c_a",
            Param::Sigma => "sigma",
            Param::E => "e",
            Param::TP => "t_p",
            Param::LT => "l_t",
            Param::KTr => "k_tr",
            Param::KD => "k_d",
            Param::IS => "i_s",
            Param::JSw => "j_sw",
            Param::CSw => "c_sw",
            Param::CK => "c_k",
            Param::FZ => "f_z",
            Param::Mu => "mu",
            Param::CS => "c_s",
        }
    }

    /// The SI unit of the parameter.
    pub const fn unit(self) -> &'static str {
        match self {
            Param::IK | Param::IP | Param::IPhi | Param::JSw => "kg m^2",
            Param::R | Param::HR | Param::Sigma | Param::E | Param::TP | Param::LT => "m",
            Param::KPhi | Param::KTr | Param::KD => "N m/rad",
            Param::CPhi | Param::CSw | Param::CK => "N m s/rad",
            Param::CA => "N/rad",
            Param::FZ => "N",
            Param::IS | Param::Mu | Param::CS => "-",
        }
    }

    /// Looks a parameter up by its field name.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|p| p.name() == name)
    }

    /// The physically plausible range `(lo, hi)`, both included, that [`PlantParams::validate`]
    /// accepts: wide enough for a small car's and a heavy truck's front axle (the named sets sit
    /// well inside), narrow enough to reject a typo by orders of magnitude (mu = 1000,
    /// F_z = 1e12). Dampings, the spin inertia, the trails and the roll-centre height may be 0.
    pub const fn range(self) -> (f64, f64) {
        match self {
            Param::IK => (0.1, 200.0),
            Param::IP => (0.0, 200.0),
            Param::R => (0.1, 1.5),
            Param::HR => (0.0, 2.0),
            Param::IPhi => (1.0, 1.0e4),
            Param::KPhi => (1.0e3, 1.0e8),
            Param::CPhi => (0.0, 1.0e6),
            Param::CA => (1.0e3, 2.0e6),
            Param::Sigma => (0.02, 3.0),
            Param::E => (0.0, 0.5),
            Param::TP => (0.0, 0.5),
            Param::LT => (0.02, 1.0),
            Param::KTr => (1.0e3, 1.0e8),
            Param::KD => (10.0, 1.0e8),
            Param::IS => (1.0, 60.0),
            Param::JSw => (1.0e-3, 5.0),
            Param::CSw => (0.0, 1.0e3),
            Param::CK => (0.0, 1.0e4),
            Param::FZ => (100.0, 1.0e5),
            Param::Mu => (0.05, 1.5),
            Param::CS => (0.5, 3.0),
        }
    }
}

impl PlantParams {
    /// The value of one parameter.
    pub fn get(&self, p: Param) -> f64 {
        *self.field(p)
    }

    /// A copy with one parameter set to `value`.
    #[must_use]
    pub fn with(mut self, p: Param, value: f64) -> Self {
        *self.field_mut(p) = value;
        self
    }

    /// A copy with one parameter multiplied by `factor` (e.g. 1.2 for +20 %).
    #[must_use]
    pub fn scaled(self, p: Param, factor: f64) -> Self {
        let v = self.get(p);
        self.with(p, v * factor)
    }

    /// Checks that every parameter is finite and inside its plausible range ([`Param::range`]).
    /// Returns the first offender.
    pub fn validate(&self) -> Result<(), (Param, f64)> {
        for p in Param::ALL {
            let v = self.get(p);
            let (lo, hi) = p.range();
            // NaN is in no range; infinities fail the bounds.
            if !(lo..=hi).contains(&v) {
                return Err((p, v));
            }
        }
        Ok(())
    }

    /// Magic-Formula peak lateral force D = mu F_z, N.
    pub fn tyre_peak_force(&self) -> f64 {
        self.mu * self.f_z
    }

    /// Magic-Formula stiffness factor B = C_a / (C_s D) in 1/rad, so that the initial slope is C_a.
    pub fn tyre_stiffness_factor(&self) -> f64 {
        self.c_a / (self.c_s * self.tyre_peak_force())
    }

    /// Spin angular momentum of one wheel H = I_p V / R in N m s at forward speed `v_mps`.
    pub fn spin_momentum(&self, v_mps: f64) -> f64 {
        self.i_p * v_mps / self.r
    }

    fn field(&self, p: Param) -> &f64 {
        match p {
            Param::IK => &self.i_k,
            Param::IP => &self.i_p,
            Param::R => &self.r,
            Param::HR => &self.h_r,
            Param::IPhi => &self.i_phi,
            Param::KPhi => &self.k_phi,
            Param::CPhi => &self.c_phi,
            Param::CA => &self.c_a,
            Param::Sigma => &self.sigma,
            Param::E => &self.e,
            Param::TP => &self.t_p,
            Param::LT => &self.l_t,
            Param::KTr => &self.k_tr,
            Param::KD => &self.k_d,
            Param::IS => &self.i_s,
            Param::JSw => &self.j_sw,
            Param::CSw => &self.c_sw,
            Param::CK => &self.c_k,
            Param::FZ => &self.f_z,
            Param::Mu => &self.mu,
            Param::CS => &self.c_s,
        }
    }

    pub(crate) fn field_mut(&mut self, p: Param) -> &mut f64 {
        match p {
            Param::IK => &mut self.i_k,
            Param::IP => &mut self.i_p,
            Param::R => &mut self.r,
            Param::HR => &mut self.h_r,
            Param::IPhi => &mut self.i_phi,
            Param::KPhi => &mut self.k_phi,
            Param::CPhi => &mut self.c_phi,
            Param::CA => &mut self.c_a,
            Param::Sigma => &mut self.sigma,
            Param::E => &mut self.e,
            Param::TP => &mut self.t_p,
            Param::LT => &mut self.l_t,
            Param::KTr => &mut self.k_tr,
            Param::KD => &mut self.k_d,
            Param::IS => &mut self.i_s,
            Param::JSw => &mut self.j_sw,
            Param::CSw => &mut self.c_sw,
            Param::CK => &mut self.c_k,
            Param::FZ => &mut self.f_z,
            Param::Mu => &mut self.mu,
            Param::CS => &mut self.c_s,
        }
    }
}
