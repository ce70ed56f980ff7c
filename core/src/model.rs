//! The vehicle-model family: what the eigen solver, the stability analysis and the model-margin
//! tracker need of a linear steering model with `N` states (`docs/architecture.md`, "Vehicle
//! models").
//!
//! A member gives its state matrix A(V, c) about straight running at forward speed V with a
//! viscous steering damper c, the (constant) speed derivative dA/dV, the damper's input column,
//! the measured output row (the wheel yaw the mode meter sees) and the classification of a mode
//! by its shape (which pair is the shimmy mode). Everything else (eigenvalues, Hopf crossings,
//! sensitivities, the incremental margin) is written once, generic over the member, with the
//! state count a const generic so that every buffer stays on the stack.
//!
//! Members: the 4-DOF car-class solid axle ([`crate::vehicles::car::PlantParams`], 10 states), the
//! 5-DOF mining dump truck ([`crate::vehicles::truck::TruckParams`], 12 states), the 8-DOF
//! dual-front-axle truck ([`crate::vehicles::dual_axle::DualAxleParams`], 20 states) and the 2-DOF
//! trailer on a compliant hitch ([`crate::vehicles::trailer::TrailerParams`], 5 states).

use crate::float::{widened, SolveFloat};
use nalgebra::{Complex, SMatrix, SVector};

/// A real N x N matrix (a state matrix or its speed derivative).
pub type Matrix<const N: usize> = SMatrix<f64, N, N>;
/// A complex state vector (an eigenvector) of a model with N states.
pub type ComplexVector<const N: usize> = SVector<Complex<f64>, N>;

/// A linear steering model with `N` states, linearised about straight running.
///
/// Contract: A is affine in the speed, `linearise(v) = linearise(0) + v dlinearise_dv()` (tyre
/// lag and gyroscopic terms are linear in V), which the tracker's Newton steps and the
/// sensitivities rely on; every member's tests check it.
pub trait LinearModel<const N: usize> {
    /// The model's name in vehicle files and reports (e.g. `car-4dof`).
    const NAME: &'static str;
    /// Short names of the states, for tables and CSV headers.
    const STATE_NAMES: [&'static str; N];
    /// Mechanical degrees of freedom (the states less the velocities and the tyre-lag states),
    /// for tables (`shimmy-sim vehicles`).
    const DOF: usize;

    /// State matrix A(V) at forward speed `v_mps` with a viscous steering damper of coefficient
    /// `c_damper_nspm` in N s/m (0 = no damper force).
    fn linearise(&self, v_mps: f64, c_damper_nspm: f64) -> Matrix<N>;

    /// dA/dV, 1/m per entry unit: the (constant) speed derivative of [`Self::linearise`].
    fn dlinearise_dv(&self) -> Matrix<N>;

    /// Column of dx/dt per unit damper force F_d in N (positive resisting a positive stroke
    /// rate).
    fn damper_force_input(&self) -> SVector<f64, N>;

    /// The measured output row: the wheel yaw the sensors see, rad, as `y = row . x`.
    fn wheel_yaw_output(&self) -> SVector<f64, N>;

    /// The shape of the mode with right eigenvector `v`: which motion dominates, by modal
    /// kinetic energy; [`ModeShape::is_shimmy`] marks the shimmy mode (the trailer's: sway).
    fn classify(&self, v: &ComplexVector<N>) -> ModeShapeInfo;

    /// [`Self::classify`] of an eigenvector in the solver's precision `T`, as the eigen
    /// solver leaves it: the firmware's tracker classifies its f32 vectors without soft-float
    /// f64 (the car's classification in f32 is ~1 KB less flash, `cargo xtask size`). By
    /// default the vector is widened to f64 and classified there; a member overrides it with
    /// its classification written once, generic over `T`.
    fn classify_in<T: SolveFloat>(&self, v: &[Complex<T>; N]) -> ModeShapeInfo {
        self.classify(&widened(v))
    }

    /// How many times slower the model's shimmy (or sway) mode is than the car's ~6 Hz shimmy
    /// the mode meter is tuned for: the data-driven meter on this model runs
    /// `EstimatorConfig::time_scaled(k)` (a whole number, because it scales the decimation).
    /// 1 (the car's meter) unless the model says otherwise.
    fn meter_time_scale(&self) -> u16 {
        1
    }
}

/// Which motion dominates a mode.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ModeShape {
    /// Both wheels yaw together (|psi_L + psi_R| > |psi_L - psi_R|): the shimmy mode.
    InPhaseWheelYaw,
    /// The wheels yaw against each other (track-rod mode).
    AntiPhaseWheelYaw,
    /// Axle roll (tramp) dominates.
    Tramp,
    /// The steering wheel (the car) or the steering linkage (the truck) dominates.
    SteeringWheel,
    /// The lagged slip angles dominate (tyre relaxation mode).
    TyreLag,
    /// The axle's lateral motion dominates (models with that degree of freedom).
    AxleLateral,
    /// The trailer's yaw about the hitch dominates: the sway mode (`trailer-2dof`).
    Sway,
    /// The hitch's lateral motion on its springing dominates (`trailer-2dof`).
    HitchLateral,
}

impl ModeShape {
    /// Short label for tables and CSV.
    pub const fn name(self) -> &'static str {
        match self {
            ModeShape::InPhaseWheelYaw => "in-phase-wheel-yaw",
            ModeShape::AntiPhaseWheelYaw => "anti-phase-wheel-yaw",
            ModeShape::Tramp => "tramp",
            ModeShape::SteeringWheel => "steering-wheel",
            ModeShape::TyreLag => "tyre-lag",
            ModeShape::AxleLateral => "axle-lateral",
            ModeShape::Sway => "trailer-sway",
            ModeShape::HitchLateral => "hitch-lateral",
        }
    }

    /// Whether this is the mode the margin is about, the one the mode meter sees: the car's
    /// and the truck's shimmy ([`ModeShape::InPhaseWheelYaw`]), the trailer's sway
    /// ([`ModeShape::Sway`]).
    pub const fn is_shimmy(self) -> bool {
        matches!(self, ModeShape::InPhaseWheelYaw | ModeShape::Sway)
    }
}

/// A mode's shape: the dominant motion and the numbers it was decided on.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ModeShapeInfo {
    /// Dominant motion.
    pub shape: ModeShape,
    /// Share of the modal kinetic energy in wheel yaw (both wheels).
    pub wheel_energy_frac: f64,
    /// Share of the modal kinetic energy in axle roll.
    pub tramp_energy_frac: f64,
    /// Share of the modal kinetic energy in the steering wheel (the truck: steering linkage).
    pub steering_wheel_energy_frac: f64,
    /// |theta_sw| / (i_s max(|psi_L|, |psi_R|)): steering-wheel (linkage) swing relative to
    /// the kinematic (rigid-link) value.
    pub steering_wheel_ratio: f64,
    /// Phase of psi_R relative to psi_L, rad (0 = in phase, +-pi = anti-phase).
    pub wheel_phase_rad: f64,
    /// max(|a_L|, |a_R|) / the largest displacement amplitude (angles, or lengths over the
    /// model's reference length).
    pub tyre_ratio: f64,
}

/// A physical parameter of a model that the online model update
/// ([`crate::estimator::model_update`]) may move: the update estimates the factor by which the
/// vehicle differs from its file in each of a model's few effective parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UpdateParam {
    /// The field's short name (as in the vehicle file), e.g. `c_a`.
    pub field: &'static str,
    /// What it is, in plain words for a diagnosis ("tyre cornering stiffness").
    pub what: &'static str,
    /// Prior one-sigma uncertainty of ln(factor): how far a vehicle in service plausibly is
    /// from its file before any data.
    pub prior_sigma_ln: f64,
    /// The plausible band of the factor; outside it the diagnosis names the parameter.
    pub band: (f64, f64),
}

impl UpdateParam {
    /// The usual prior: one sigma of 15 % on the factor, the spread of tyres and steering
    /// linkages of one type in service (inflation, wear, play).
    pub const SERVICE_PRIOR_SIGMA_LN: f64 = 0.15;
}

/// A linear model whose effective parameters can be updated from data.
pub trait UpdatableModel<const N: usize>: LinearModel<N> + Copy {
    /// The parameters the update estimates (at most
    /// [`crate::estimator::model_update::MAX_UPDATE_PARAMS`]): those the model's
    /// identifiability study (`shimmy-sim identifiability`) separates from shimmy frequency and
    /// damping over speed.
    const UPDATE_PARAMS: &'static [UpdateParam];

    /// `self` with update parameter `index` multiplied by `factor` (and whatever the model
    /// derives from it).
    fn scaled_update_param(&self, index: usize, factor: f64) -> Self;

    /// The value of update parameter `index` (NaN for an index past the list).
    fn update_param(&self, index: usize) -> f64;
}

/// The larger of `a` and `b` (as `f64::max` for numbers; the squared magnitudes here are).
pub(crate) fn larger<T: PartialOrd>(a: T, b: T) -> T {
    if b > a {
        b
    } else {
        a
    }
}

/// Phase of the right wheel's yaw `psi_r` relative to the left one's `psi_l`, rad. In f32
/// (scaled into its range): ample for a phase, and the firmware links no f64 atan.
pub fn wheel_phase_rad<T: SolveFloat>(psi_l: Complex<T>, psi_r: Complex<T>) -> f64 {
    let rel = psi_r * psi_l.conj();
    let m = larger(rel.re.abs(), rel.im.abs());
    if m > T::zero() {
        let f = |x: T| (x / m).to_f64() as f32;
        f64::from(libm::atan2f(f(rel.im), f(rel.re)))
    } else {
        0.0
    }
}

/// In-phase (the shimmy mode) or anti-phase wheel yaw, from the two wheels' components.
pub fn wheel_yaw_shape<T: SolveFloat>(psi_l: Complex<T>, psi_r: Complex<T>) -> ModeShape {
    if (psi_l + psi_r).norm_sqr() >= (psi_l - psi_r).norm_sqr() {
        ModeShape::InPhaseWheelYaw
    } else {
        ModeShape::AntiPhaseWheelYaw
    }
}
