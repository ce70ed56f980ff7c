//! The dual-front-axle truck's nonlinear plant (`docs/dual-axle-truck.md`): the linear model of
//! `shimmy_core::dual_axle` plus its two nonlinear elements, the tyres' saturation as its
//! departure from the linearisation (so that the small-motion limit is the linear model) and the
//! dry friction at the four kingpins, which the linear model does not have:
//!
//! - tyres: Magic-Formula force `F = D sin(C_s atan(B a))` of the lagged slip (`D = mu F_z`,
//!   `B = C_a / (C_s D)`: slope C_a at 0, saturating at D) in place of `C_a a`, in the yaw and
//!   roll equations;
//! - kingpins: Coulomb friction `-M_f sgn(psi')` on each wheel, smoothed for the integrator as
//!   `-M_f tanh(psi' / eps)` (a viscous slope `M_f / eps` below `|psi'| ~ eps`, the full
//!   torque above); the tests show that halving `eps` leaves the limit cycle and the friction's
//!   onset shift where they were.
//!
//! Fixed-step RK4, an integer number of steps per 1 ms sample, the step small enough for both
//! the fastest mode of A(V) and the friction's slope (`h max(|lambda|, M_f / (eps I_k)) <= 1`,
//! inside RK4's stability region, radius ~2.8).

use shimmy_core::eigen::eigenvalues;
use shimmy_core::model::{LinearModel, Matrix};
use shimmy_core::vehicles::dual_axle::{
    DualAxleOperatingPoint, DualAxleParams, DualAxleSet, A_1L as A_1L_, N_DOF, N_STATES, PSI_1L,
    PSI_1R, PSI_2L, PSI_2R, WHEELS,
};
use shimmy_core::vehicles::FieldTable;

use super::integrator::rk4_step;

/// Sample period of a run (the callbacks, the inputs held), s.
pub const SAMPLE_S: f64 = 1e-3;

/// The default friction smoothing: `tanh(psi' / eps)` with `eps` = 0.01 rad/s, 2 % of the yaw
/// rate of a 1-deg shimmy at 10 Hz.
pub const DEFAULT_EPS_RADPS: f64 = 0.01;

/// The dual-axle truck driven at a speed (constant or ramped), damper off.
pub struct DualAxleSim {
    t: DualAxleParams,
    op: DualAxleOperatingPoint,
    /// The nonzeros of A(0) and dA/dV as (row, column, value): A(V) x = A(0) x + V dA/dV x.
    a0: Vec<(usize, usize, f64)>,
    da: Vec<(usize, usize, f64)>,
    /// Kingpin friction torque in use, N m (0: friction off).
    m_f: f64,
    eps: f64,
    substeps: usize,
    /// Time, s.
    pub time_s: f64,
    /// State (the linear model's order).
    pub x: [f64; N_STATES],
}

impl DualAxleSim {
    /// A simulation of `t` from `x0`, with kingpin friction `t.m_f` smoothed by `eps_radps`
    /// (`friction` false: none), its step fitted to speeds up to `v_max_mps`.
    pub fn new(
        t: &DualAxleParams,
        x0: [f64; N_STATES],
        friction: bool,
        eps_radps: f64,
        v_max_mps: f64,
    ) -> anyhow::Result<Self> {
        anyhow::ensure!(
            eps_radps > 0.0 && eps_radps.is_finite(),
            "friction smoothing eps = {eps_radps} rad/s must be above 0"
        );
        t.validate()
            .map_err(|e| anyhow::anyhow!("dual-axle: {e}"))?;
        let m_f = if friction { t.m_f } else { 0.0 };
        let fastest = eigenvalues(&t.linearise(v_max_mps, 0.0))
            .map_err(|e| anyhow::anyhow!("eigenvalues at {v_max_mps} m/s: {e:?}"))?
            .iter()
            .map(|l| l.norm())
            .fold(m_f / (eps_radps * t.i_k), f64::max);
        let substeps = (SAMPLE_S * fastest).ceil().max(1.0) as usize;
        Ok(Self {
            t: *t,
            op: t.operating_point(),
            a0: nonzeros(&t.linearise(0.0, 0.0)),
            da: nonzeros(&t.dlinearise_dv()),
            m_f,
            eps: eps_radps,
            substeps,
            time_s: 0.0,
            x: x0,
        })
    }

    /// RK4 steps per 1 ms sample.
    pub fn substeps(&self) -> usize {
        self.substeps
    }

    /// Overrides the step rule (the tests' negative case).
    #[cfg(test)]
    fn set_substeps(&mut self, n: usize) {
        self.substeps = n;
    }

    /// The tyre's lateral force on axle `axle` (0, 1) at lagged slip `a`, N.
    pub fn tyre_force_n(&self, axle: usize, a: f64) -> f64 {
        tyre_force_n(&self.t, &self.op, axle, a)
    }

    /// The smoothed kingpin friction torque at yaw rate `w`, N m (resisting).
    pub fn friction_nm(&self, w: f64) -> f64 {
        -self.m_f * (w / self.eps).tanh()
    }

    fn rhs(&self, x: &[f64; N_STATES], v: f64, tq: &[f64; 4], dx: &mut [f64; N_STATES]) {
        dx.fill(0.0);
        for &(i, j, a) in &self.a0 {
            dx[i] += a * x[j];
        }
        for &(i, j, a) in &self.da {
            dx[i] += v * a * x[j];
        }
        add_nonlinear(&self.t, &self.op, self.m_f, self.eps, x, dx);
        for (k, (wheel, _, _, _)) in WHEELS.into_iter().enumerate() {
            dx[N_DOF + wheel] += tq[k] / self.t.i_k;
        }
    }

    /// One 1 ms sample at speed `v_mps` with the yaw torques `tq_nm` on the four wheels (1L,
    /// 1R, 2L, 2R; road disturbances) held over it.
    pub fn sample(&mut self, v_mps: f64, tq_nm: [f64; 4]) {
        let h = SAMPLE_S / self.substeps as f64;
        let mut f =
            |_t: f64, y: &[f64; N_STATES], dy: &mut [f64; N_STATES]| self.rhs(y, v_mps, &tq_nm, dy);
        let mut x = self.x;
        for _ in 0..self.substeps {
            rk4_step(&mut f, self.time_s, &mut x, h);
        }
        self.x = x;
        self.time_s += SAMPLE_S;
    }

    /// Axle 1's in-phase wheel yaw `(psi_1L + psi_1R) / 2`, rad (what its encoders measure).
    pub fn wheel_yaw_rad(&self) -> f64 {
        0.5 * (self.x[PSI_1L] + self.x[PSI_1R])
    }
}

/// The Magic-Formula lateral force of a tyre of axle `axle` at lagged slip `a`, N: `D sin(C_s
/// atan(B a))`, `D = mu F_z`, `B = C_a / (C_s D)` (slope `C_a` at 0).
fn tyre_force_n(t: &DualAxleParams, op: &DualAxleOperatingPoint, axle: usize, a: f64) -> f64 {
    let d = t.mu * op.f_z[axle];
    let b = op.c_a[axle] / (t.c_s * d);
    super::tyre::magic_formula_n(d, t.c_s, b, a)
}

/// The tyres' saturation (as its departure from `C_a a`) and the kingpin friction
/// `-m_f tanh(psi' / eps)`, added to the linear model's `dx` (the first [`N_STATES`] entries).
fn add_nonlinear(
    t: &DualAxleParams,
    op: &DualAxleOperatingPoint,
    m_f: f64,
    eps: f64,
    x: &[f64],
    dx: &mut [f64],
) {
    let lever = t.e + t.t_p;
    for (wheel, roll, slip, axle) in WHEELS {
        let extra = tyre_force_n(t, op, axle, x[slip]) - op.c_a[axle] * x[slip];
        let (dw, dr) = (N_DOF + wheel, N_DOF + roll);
        dx[dw] += (-lever * extra - m_f * (x[dw] / eps).tanh()) / t.i_k;
        dx[dr] += t.h_r * extra / t.i_phi;
    }
}

/// The nonzero entries of `m`, row by row.
fn nonzeros(m: &Matrix<N_STATES>) -> Vec<(usize, usize, f64)> {
    (0..N_STATES)
        .flat_map(|i| (0..N_STATES).map(move |j| (i, j)))
        .filter(|&(i, j)| m[(i, j)] != 0.0)
        .map(|(i, j)| (i, j, m[(i, j)]))
        .collect()
}

/// An in-phase start of `psi_rad` on axle 1 in the linkage's kinematic pattern: axle 2's
/// wheels and the rocker at `n_2 psi`, the pitman arm at `psi` (only the gear's spring is
/// stretched), everything else at rest.
pub fn yaw_start(t: &DualAxleParams, psi_rad: f64) -> [f64; N_STATES] {
    let n2 = t.operating_point().n_2 * psi_rad;
    let mut x = [0.0; N_STATES];
    x[..N_DOF].copy_from_slice(&[psi_rad, psi_rad, n2, n2, 0.0, 0.0, psi_rad, n2]);
    x
}

/// Summary of a constant-speed run: the wheel-yaw amplitude (peak |(psi_1L + psi_1R)/2|) over
/// the last window and the window before it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CycleSummary {
    /// Speed, m/s.
    pub v_mps: f64,
    /// Initial in-phase yaw, rad.
    pub psi0_rad: f64,
    /// Peak over the last window, rad.
    pub amp_end_rad: f64,
    /// Peak over the window before, rad.
    pub amp_prev_rad: f64,
}

impl CycleSummary {
    /// Shimmy at the end of the run: an oscillation that is not dying out (the last window at
    /// least 0.98 of the one before) and larger than 1e-4 rad; a stuck or decaying wheel is not.
    pub fn shimmies(&self) -> bool {
        self.amp_end_rad >= 0.98 * self.amp_prev_rad && self.amp_end_rad > 1e-4
    }
}

/// A run at constant `v_mps` from the in-phase start `psi0_rad`, `duration_s` long, amplitude
/// over the last `window_s` and the one before.
pub fn run_cycle(
    t: &DualAxleParams,
    v_mps: f64,
    psi0_rad: f64,
    friction: bool,
    eps_radps: f64,
    duration_s: f64,
    window_s: f64,
) -> anyhow::Result<CycleSummary> {
    let mut sim = DualAxleSim::new(t, yaw_start(t, psi0_rad), friction, eps_radps, v_mps)?;
    let n = (duration_s / SAMPLE_S).round() as usize;
    let w = (window_s / SAMPLE_S).round() as usize;
    let (mut end, mut prev) = (0.0_f64, 0.0_f64);
    for k in 0..n {
        sim.sample(v_mps, [0.0; 4]);
        let y = sim.wheel_yaw_rad().abs();
        anyhow::ensure!(y.is_finite(), "the run at {v_mps} m/s diverged");
        if k + w >= n {
            end = end.max(y);
        } else if k + 2 * w >= n {
            prev = prev.max(y);
        }
    }
    Ok(CycleSummary {
        v_mps,
        psi0_rad,
        amp_end_rad: end,
        amp_prev_rad: prev,
    })
}

/// Growth rate of the wheel-yaw envelope without friction, 1/s: the log ratio of the largest
/// |(psi_1L + psi_1R)/2| in the last and the first `window_s` after `settle_s`, over their
/// distance in time.
pub fn envelope_growth_1ps(
    t: &DualAxleParams,
    v_mps: f64,
    psi0_rad: f64,
    settle_s: f64,
    duration_s: f64,
    window_s: f64,
) -> anyhow::Result<f64> {
    let mut sim = DualAxleSim::new(t, yaw_start(t, psi0_rad), false, DEFAULT_EPS_RADPS, v_mps)?;
    let (mut first, mut last) = (0.0_f64, 0.0_f64);
    let (w0, w1) = (settle_s + window_s, duration_s - window_s);
    let n = (duration_s / SAMPLE_S).round() as usize;
    for _ in 0..n {
        sim.sample(v_mps, [0.0; 4]);
        let (time, yaw) = (sim.time_s, sim.wheel_yaw_rad().abs());
        if time > settle_s && time <= w0 {
            first = first.max(yaw);
        }
        if time > w1 {
            last = last.max(yaw);
        }
    }
    Ok((last / first).ln() / (w1 - settle_s))
}

/// The dual-axle truck in the registry (`super::registry`): its files have the `[dual_axle]`
/// section only; its shared sections are [`dual_axle_parts`].
impl super::registry::ModelEntry<N_STATES> for DualAxleParams {
    type File = super::family::FamilyVehicle<DualAxleParams>;
    const SECTION: Option<&'static str> = Some("dual_axle");
    const SHARED_SECTIONS: bool = false;
    const DEFAULT_SET: &'static str = DualAxleSet::Rated.name();
    const SCENARIOS: bool = false;
    /// The kingpin friction and the simulator tyre's friction and shape are not in the linear
    /// model, the damper lever has no effect without a damper (the friction's effect is
    /// `bifurcation`'s, nonlinear).
    const NO_LINEAR_EFFECT: &'static [&'static str] = &["m_f", "mu", "c_s", "l_t"];

    fn set_names() -> Vec<&'static str> {
        DualAxleSet::ALL.iter().map(|s| s.name()).collect()
    }
    fn set(name: &str) -> Option<Self> {
        DualAxleSet::from_name(name).map(DualAxleSet::params)
    }
    fn assemble(
        model: Self,
        parts: Option<shimmy_core::vehicle::Vehicle>,
    ) -> anyhow::Result<Self::File> {
        Ok(super::family::FamilyVehicle {
            model,
            parts: match parts {
                Some(p) => p,
                None => dual_axle_parts()?,
            },
        })
    }
    fn fields() -> &'static [shimmy_core::vehicles::ModelField] {
        <Self as FieldTable>::FIELDS
    }
    fn field(&self, name: &str) -> Option<f64> {
        FieldTable::get(self, name)
    }
    fn set_field(
        &mut self,
        name: &str,
        value: f64,
    ) -> Result<(), shimmy_core::vehicles::FieldError> {
        FieldTable::set(self, name, value)
    }
    fn check(&self) -> Result<(), String> {
        self.validate().map_err(|e| e.to_string())
    }
    fn check_in_file(&self) -> anyhow::Result<()> {
        self.validate().map_err(|e| {
            anyhow::anyhow!("{}", e.to_string().replace("field `", "field `dual_axle."))
        })
    }
    fn model_of(f: &Self::File) -> Self {
        f.model
    }
    fn model_mut(f: &mut Self::File) -> &mut Self {
        &mut f.model
    }
    fn parts_of(f: &Self::File) -> Option<&shimmy_core::vehicle::Vehicle> {
        Some(&f.parts)
    }
    fn parts_of_mut(f: &mut Self::File) -> Option<&mut shimmy_core::vehicle::Vehicle> {
        Some(&mut f.parts)
    }
    fn vehicle(f: Self::File) -> anyhow::Result<Self::File> {
        Ok(f)
    }
    fn file_of(v: &Self::File) -> Self::File {
        *v
    }
    fn with_params(v: &Self::File, model: Self) -> Self::File {
        super::family::FamilyVehicle { model, ..*v }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use shimmy_core::stability::{self, CrossingKind, DEFAULT_TOL_MPS};
    use shimmy_core::units::{kmh_to_mps, mps_to_kmh};
    use shimmy_core::vehicles::dual_axle::DualAxleSet;

    /// The tyre has the linear model's slope at 0 and saturates; the smoothed friction is odd,
    /// reaches the full torque above a few eps and is off when friction is off.
    #[test]
    fn the_nonlinear_elements() {
        let t = DualAxleSet::Rated.params();
        let sim = DualAxleSim::new(&t, [0.0; N_STATES], true, 0.01, 20.0).unwrap();
        let h = 1e-7;
        for axle in 0..2 {
            let slope = (sim.tyre_force_n(axle, h) - sim.tyre_force_n(axle, -h)) / (2.0 * h);
            assert!((slope - sim.op.c_a[axle]).abs() < 1e-6 * sim.op.c_a[axle]);
            assert!(sim.tyre_force_n(axle, 0.3) < 0.5 * sim.op.c_a[axle] * 0.3);
        }
        assert!((sim.friction_nm(0.05) + 0.9999 * t.m_f).abs() < 1e-3 * t.m_f);
        assert_eq!(sim.friction_nm(-0.2), -sim.friction_nm(0.2));
        let off = DualAxleSim::new(&t, [0.0; N_STATES], false, 0.01, 20.0).unwrap();
        assert_eq!(off.friction_nm(1.0), 0.0);
        // the step follows the friction's slope: halving eps doubles the substeps
        let fine = DualAxleSim::new(&t, [0.0; N_STATES], true, 0.0025, 20.0).unwrap();
        assert!(
            fine.substeps() >= 2 * sim.substeps(),
            "{} {}",
            fine.substeps(),
            sim.substeps()
        );
    }

    fn onset_mps(t: &DualAxleParams) -> f64 {
        stability::hopf_crossings(t, 0.0, 1.0, 40.0, 0.5, DEFAULT_TOL_MPS)
            .unwrap()
            .iter()
            .find(|c| c.kind == CrossingKind::Onset)
            .unwrap()
            .speed_mps
    }

    /// Friction off: from a small start the envelope grows 2 km/h above the linear model's
    /// Hopf speed and decays 2 km/h below it, at the eigenvalue's rate (within 5 % + 0.005 1/s).
    #[test]
    fn hopf_speed_matches_the_time_domain_onset() {
        let t = DualAxleSet::Rated.params();
        let onset = onset_mps(&t);
        for dv_kmh in [-2.0, 2.0] {
            let v = onset + kmh_to_mps(dv_kmh);
            let g = envelope_growth_1ps(&t, v, 0.02_f64.to_radians(), 3.0, 18.0, 1.5).unwrap();
            let re = stability::critical_mode_at(&t, v, 0.0).unwrap().re;
            println!(
                "onset {:.3} km/h, at {:.3} km/h: envelope {g:.5} 1/s, eigenvalue {re:.5} 1/s",
                mps_to_kmh(onset),
                mps_to_kmh(v)
            );
            assert_eq!(g > 0.0, dv_kmh > 0.0, "{dv_kmh} km/h: growth {g}");
            assert!(
                (g - re).abs() < 0.05 * re.abs() + 5e-3,
                "envelope {g} vs eigenvalue {re}"
            );
        }
    }

    /// The step rule is what keeps a sharp friction right: at eps = 0.5 mrad/s the slope
    /// M_f / (eps I_k) is ~5,400 1/s; one RK4 step per millisecond (h rho ~ 5.4, outside RK4's
    /// region) chatters through the sticking phases and ends somewhere else than the rule's
    /// substeps, which agree with twice as many.
    #[test]
    fn the_step_rule_keeps_a_sharp_friction_converged() {
        let t = DualAxleSet::Rated.params();
        let v = kmh_to_mps(90.0);
        let run = |substeps: Option<usize>| {
            let mut sim = DualAxleSim::new(&t, yaw_start(&t, 0.02), true, 5e-4, v).unwrap();
            let ruled = sim.substeps();
            if let Some(n) = substeps {
                sim.set_substeps(n);
            }
            for _ in 0..2000 {
                sim.sample(v, [0.0; 4]);
            }
            (ruled, sim.x)
        };
        let (ruled, x) = run(None);
        assert!(ruled >= 5, "{ruled}");
        let (_, fine) = run(Some(2 * ruled));
        let (_, coarse) = run(Some(1));
        let dist = |a: &[f64; N_STATES]| {
            (a[PSI_1L] - fine[PSI_1L]).abs() + (a[PSI_1R] - fine[PSI_1R]).abs()
        };
        println!(
            "{ruled} substeps: |psi - psi(2x substeps)| = {:e} rad; one step per ms: {:e} rad",
            dist(&x),
            dist(&coarse)
        );
        assert!(dist(&x) < 3e-6, "{}", dist(&x));
        assert!(dist(&coarse) > 3e-5, "{}", dist(&coarse));
    }
}

/// States of [`DualAxlePlant`]: the linear model's 20, then the MR damper's filtered coil
/// input `u`, internal displacement `y` and Bouc-Wen `z` (as the car's and the truck's).
pub const N_SIM: usize = N_STATES + 3;
const U: usize = N_STATES;

/// Names of [`DualAxlePlant`]'s states.
pub const SIM_STATE_NAMES: [&str; N_SIM] = {
    let mut n = [""; N_SIM];
    let mut i = 0;
    while i < N_STATES {
        n[i] = shimmy_core::vehicles::dual_axle::STATE_NAMES[i];
        i += 1;
    }
    n[U] = "u_V";
    n[U + 1] = "damper_y_m";
    n[U + 2] = "damper_z_m";
    n
};

/// The dual-axle truck as the family's nonlinear plant (`model::family::SimPlant`): the
/// model of [`DualAxleSim`] (tyre saturation and kingpin friction at `DEFAULT_EPS_RADPS`) with
/// a damper across axle 1's track rod (none, viscous or the MR damper's Spencer model) and the
/// scenario's yaw torques on axle 1's wheels, integrated by Dopri5 (the MR damper's Bouc-Wen
/// state is stiff, as on the truck).
#[derive(Clone, Debug)]
pub struct DualAxlePlant {
    t: DualAxleParams,
    op: DualAxleOperatingPoint,
    damper: super::plant::Damper,
    a0: Matrix<N_STATES>,
    da: Matrix<N_STATES>,
    /// The mode meter's output row on the four wheel yaws (1L, 1R, 2L, 2R), the linear
    /// model's `wheel_yaw_output`.
    meter_row: [f64; 4],
    v: f64,
    x: [f64; N_SIM],
    t_s: f64,
    dopri: super::integrator::Dopri5<N_SIM>,
}

impl DualAxlePlant {
    /// The truck `t` at rest with `damper`, at relative tolerance `rtol`.
    pub fn new(t: &DualAxleParams, damper: super::plant::Damper, rtol: f64) -> Self {
        let mut atol = [0.0; N_SIM];
        for (i, a) in atol.iter_mut().enumerate() {
            // the car's scales: angles 1e-3 rad, rates 1e-1 rad/s, coil 1 V, damper 1e-4 m
            let scale = match i {
                0..N_DOF | A_1L_..N_STATES => 1e-3,
                N_DOF..A_1L_ => 1e-1,
                U => 1.0,
                _ => 1e-4,
            };
            *a = rtol * scale;
        }
        Self {
            t: *t,
            op: t.operating_point(),
            damper,
            a0: t.linearise(0.0, 0.0),
            da: t.dlinearise_dv(),
            meter_row: {
                let c = t.wheel_yaw_output();
                [c[PSI_1L], c[PSI_1R], c[PSI_2L], c[PSI_2R]]
            },
            v: 0.0,
            x: [0.0; N_SIM],
            t_s: 0.0,
            dopri: super::integrator::Dopri5::new(rtol, atol),
        }
    }

    /// Right-hand side under held inputs; returns the damper force, N.
    fn rhs(&self, x: &[f64; N_SIM], u: &super::plant::Inputs, dx: &mut [f64; N_SIM]) -> f64 {
        use super::plant::Damper;
        let a = self.a0 + self.da * u.speed_mps;
        let lin = a * nalgebra::SVector::<f64, N_STATES>::from_column_slice(&x[..N_STATES]);
        dx[..N_STATES].copy_from_slice(lin.as_slice());
        add_nonlinear(
            &self.t,
            &self.op,
            self.t.m_f,
            DEFAULT_EPS_RADPS,
            &x[..N_STATES],
            &mut dx[..N_STATES],
        );
        let half = 0.5 * self.t.l_t;
        let (xd, vd) = (
            half * (x[PSI_1L] + x[PSI_1R]),
            half * (x[N_DOF + PSI_1L] + x[N_DOF + PSI_1R]),
        );
        let f_d = match &self.damper {
            Damper::None => {
                dx[U..].fill(0.0);
                0.0
            }
            Damper::Viscous(c) => {
                dx[U..].fill(0.0);
                c * vd
            }
            Damper::Mr(sp) => {
                let st = shimmy_core::mr_damper::SpencerState {
                    u: x[U],
                    y: x[U + 1],
                    z: x[U + 2],
                };
                let r = shimmy_core::mr_damper::rates(sp, &st, xd, vd, u.current_cmd_a);
                dx[U] = r.du;
                dx[U + 1] = r.dy;
                dx[U + 2] = r.dz;
                r.force_n
            }
        };
        for (i, wheel) in [PSI_1L, PSI_1R].into_iter().enumerate() {
            dx[N_DOF + wheel] += (u.yaw_torque_nm[i] - half * f_d) / self.t.i_k;
        }
        f_d
    }
}

impl super::family::SimPlant for DualAxlePlant {
    fn set_wheel_yaw(&mut self, psi_l_rad: f64, psi_r_rad: f64) {
        self.x = [0.0; N_SIM];
        self.x[PSI_1L] = psi_l_rad;
        self.x[PSI_1R] = psi_r_rad;
    }

    fn set_state(&mut self, x: &[f64]) {
        self.x.copy_from_slice(x);
    }

    fn advance(
        &mut self,
        dt_s: f64,
        inputs: &super::plant::Inputs,
    ) -> Result<(), super::integrator::IntegrateError> {
        self.v = inputs.speed_mps;
        let me = &*self;
        let (t_s, mut x) = (me.t_s, me.x);
        let mut dopri = me.dopri.clone();
        let mut f = |_t: f64, y: &[f64; N_SIM], dy: &mut [f64; N_SIM]| {
            me.rhs(y, inputs, dy);
        };
        dopri.integrate_fsal(&mut f, t_s, &mut x, dt_s, false)?;
        self.dopri = dopri;
        self.x = x;
        self.t_s += dt_s;
        Ok(())
    }

    fn wheel_yaw_rad(&self) -> [f64; 2] {
        [self.x[PSI_1L], self.x[PSI_1R]]
    }

    /// Both axles' wheel yaw through the linear model's output row (the modal filter of
    /// `DualAxleParams::meter_weights`), as a pair of equal angles.
    fn meter_yaw_rad(&self) -> [f64; 2] {
        let y: f64 = self
            .meter_row
            .iter()
            .zip([PSI_1L, PSI_1R, PSI_2L, PSI_2R])
            .map(|(c, i)| c * self.x[i])
            .sum();
        [y, y]
    }

    fn steering_angle_rad(&self) -> f64 {
        self.x[shimmy_core::vehicles::dual_axle::THETA_G]
    }

    fn coil_input_a(&self) -> f64 {
        match self.damper {
            super::plant::Damper::Mr(_) => self.x[U],
            _ => 0.0,
        }
    }

    fn damper_force_n(&self, inputs: &super::plant::Inputs) -> f64 {
        let mut dx = [0.0; N_SIM];
        self.rhs(&self.x, inputs, &mut dx)
    }

    fn state(&self) -> &[f64] {
        &self.x
    }

    fn state_names(&self) -> &'static [&'static str] {
        &SIM_STATE_NAMES
    }

    fn time_s(&self) -> f64 {
        self.t_s
    }

    fn vector_field(&self, x: &[f64], inputs: &super::plant::Inputs, dx: &mut [f64]) {
        let mut s = [0.0; N_SIM];
        s.copy_from_slice(x);
        let mut ds = [0.0; N_SIM];
        self.rhs(&s, inputs, &mut ds);
        dx.copy_from_slice(&ds);
    }
}

impl super::family::SimModel<N_STATES> for DualAxleParams {
    type Linear = DualAxleParams;
    type Plant = DualAxlePlant;
    type State = [f64; N_SIM];
    type Vehicle = super::family::FamilyVehicle<DualAxleParams>;
    const STEERING: &'static str = "pitman arm";

    fn family_vehicle(v: &Self::Vehicle) -> super::family::FamilyVehicle<Self> {
        *v
    }

    fn parts_mut(v: &mut Self::Vehicle) -> &mut shimmy_core::vehicle::Vehicle {
        &mut v.parts
    }

    fn linear(&self) -> Self {
        *self
    }

    fn plant(&self, damper: super::plant::Damper, method: super::plant::Method) -> DualAxlePlant {
        let rtol = method.rtol();
        DualAxlePlant::new(self, damper, rtol)
    }

    fn rolling_radius_m(&self) -> f64 {
        self.r
    }

    fn steering_arm_m(&self) -> f64 {
        self.l_t
    }

    fn nominal_plant(&self) -> shimmy_core::control::smc::NominalPlant {
        shimmy_core::control::smc::NominalPlant {
            i_k_kgm2: self.i_k as f32,
            c_k_nms_per_rad: self.c_k as f32,
            l_t_m: self.l_t as f32,
        }
    }

    fn host_app_model(&self) -> Option<(Self::Linear, f32)> {
        None
    }

    fn yaw_torque_scale(&self) -> f64 {
        self.i_k / shimmy_core::vehicle::Vehicle::nominal().plant.i_k
    }

    fn params() -> Vec<super::family::ParamInfo> {
        super::family::table_params::<Self>()
    }

    fn param(&self, name: &str) -> Option<f64> {
        FieldTable::get(self, name)
    }

    fn with_param(&self, name: &str, value: f64) -> anyhow::Result<Self> {
        super::family::with_table_param::<Self, N_STATES>(self, name, value)
    }

    /// The kingpins' dry friction (smoothed for the integrator, but a Coulomb torque in the
    /// model), and the MR damper's Bouc-Wen `|z|`.
    fn non_smooth(&self, damper: &super::plant::Damper) -> Option<&'static str> {
        if self.m_f > 0.0 {
            Some("kingpin dry friction")
        } else {
            matches!(damper, super::plant::Damper::Mr(_)).then_some("MR damper: Bouc-Wen |z|")
        }
    }
}

/// The shared sections (damper, sensors, gains, thresholds) of a dual-axle vehicle, sized for
/// this truck from the car's reference set against the named set `dual-axle`
/// (`docs/dual-axle-truck.md`, "Damper, gains and thresholds"):
/// - the damper (across axle 1's track rod) and the skyhook coefficient scaled as the mining
///   truck's are (`damper_sizing::damper_scale_like_the_cars`);
/// - the damping-ratio thresholds times the ratio of the shimmy mode's damping slope dzeta/dV
///   at the onset, this truck's over the `nominal` car's, so that each stands for the same
///   speed distance to the onset as on the car (the speed-margin and time thresholds are that
///   distance already and stay);
/// - the ASMC's boundary layer `phi` (a rate: a quarter of a 0.01-rad shimmy's at the car's
///   6 Hz) times the ratio of the shimmy frequencies at the onsets; the other gains are
///   angular accelerations of the wheel and stay (the force comes from `2 I_k / l_t`).
pub fn dual_axle_parts() -> anyhow::Result<shimmy_core::vehicle::Vehicle> {
    static PARTS: std::sync::OnceLock<Result<shimmy_core::vehicle::Vehicle, String>> =
        std::sync::OnceLock::new();
    PARTS
        .get_or_init(|| compute_dual_axle_parts().map_err(|e| format!("{e:#}")))
        .clone()
        .map_err(|e| anyhow::anyhow!(e))
}

/// The shimmy mode at `m`'s onset: (dzeta/dV in s/m, frequency in Hz).
fn onset_slope_and_freq<M: LinearModel<N>, const N: usize>(m: &M) -> anyhow::Result<(f64, f64)> {
    use shimmy_core::stability::{dzeta_dv, ModeSelect};
    let onset = crate::model::family::onset_kmh(m).ok_or_else(|| {
        anyhow::anyhow!("{}: no Hopf onset in 1-150 km/h to size against", M::NAME)
    })?;
    let (mode, slope, _) = dzeta_dv(
        m,
        shimmy_core::units::kmh_to_mps(onset),
        0.0,
        ModeSelect::Shimmy,
    )
    .map_err(|e| anyhow::anyhow!("{}: shimmy mode at the onset: {e:?}", M::NAME))?;
    Ok((slope, mode.freq_hz))
}

fn compute_dual_axle_parts() -> anyhow::Result<shimmy_core::vehicle::Vehicle> {
    use shimmy_core::vehicles::dual_axle::DualAxleSet;
    let t = DualAxleSet::Rated.params();
    let mut v = super::damper_sizing::car_parts_with_damper_scaled(
        super::damper_sizing::damper_scale_like_the_cars(&t)?,
    );
    let (slope_car, f_car) = onset_slope_and_freq(&shimmy_core::vehicle::Vehicle::nominal().plant)?;
    let (slope_t, f_t) = onset_slope_and_freq(&t)?;
    anyhow::ensure!(
        slope_car < 0.0 && slope_t < 0.0,
        "damping slopes at the onsets not negative: car {slope_car}, dual-axle {slope_t} s/m"
    );
    let k = (slope_t / slope_car) as f32;
    let th = &mut v.thresholds;
    for z in [
        &mut th.zeta_low_on,
        &mut th.zeta_low_off,
        &mut th.zeta_crit_on,
        &mut th.zeta_crit_off,
    ] {
        *z *= k;
    }
    v.controller.smc.phi_radps *= (f_t / f_car) as f32;
    v.validate()
        .map_err(|e| anyhow::anyhow!("dual-axle shared sections: {e}"))?;
    Ok(v)
}

#[cfg(test)]
mod parts_tests {
    use super::*;
    use crate::model::damper_equiv::{damper_equivalent, REF_WHEEL_YAW_AMPL_RAD};
    use crate::model::damper_sizing::{damper_scale_like_the_cars, least_stabilising_c};
    use shimmy_core::stability::{hopf_crossings, CrossingKind};
    use shimmy_core::units::kmh_to_mps;
    use shimmy_core::vehicles::car::ParamSet;
    use shimmy_core::vehicles::dual_axle::DualAxleSet;

    /// The truck's shared sections: checked on the eigenvalues (independent of the sizing
    /// rule), the damper leaves a Hopf window at 0 A and none at the rated current, as on the
    /// car; the damping thresholds stand for the car's speed distances (the threshold over the
    /// slope is the car's), the speed and time thresholds are the car's.
    #[test]
    fn the_shared_sections_are_sized_for_this_truck() {
        let t = DualAxleSet::Rated.params();
        let car = shimmy_core::vehicle::Vehicle::from_set(ParamSet::Nominal);
        let parts = dual_axle_parts().unwrap();
        let (v0, v1) = (kmh_to_mps(1.0), kmh_to_mps(150.0));
        let deg = REF_WHEEL_YAW_AMPL_RAD.to_degrees();
        let sp = &parts.damper.spencer;
        let at = |i: f64| damper_equivalent(&t, sp, i, deg, v0, v1).unwrap().c_eq_nspm;
        let onsets = |c: f64| {
            hopf_crossings(&t, c, v0, v1, kmh_to_mps(0.5), 1e-3)
                .unwrap()
                .iter()
                .filter(|x| x.kind == CrossingKind::Onset)
                .count()
        };
        let (slope_car, f_car) = onset_slope_and_freq(&car.plant).unwrap();
        let (slope_t, f_t) = onset_slope_and_freq(&t).unwrap();
        println!(
            "damper scale {:.3}; least stabilising c {:.1} N s/m; c_eq 0 A {:.1}, rated {:.1} N s/m; \
             dzeta/dV at the onset: car {:.5}, truck {:.5} s/m; f car {f_car:.2} Hz, truck \
             {f_t:.2} Hz; zeta_low_on {:.5}, zeta_crit_on {:.5}; phi {:.3} rad/s",
            damper_scale_like_the_cars(&t).unwrap(),
            least_stabilising_c(&t).unwrap(),
            at(0.0),
            at(sp.u_max),
            slope_car,
            slope_t,
            parts.thresholds.zeta_low_on,
            parts.thresholds.zeta_crit_on,
            parts.controller.smc.phi_radps
        );
        assert!(onsets(at(0.0)) > 0);
        assert_eq!(onsets(at(sp.u_max)), 0);
        let (tc, tt) = (car.thresholds, parts.thresholds);
        let dist = |z: f32, s: f64| f64::from(z) / s;
        for (zc, zt) in [
            (tc.zeta_low_on, tt.zeta_low_on),
            (tc.zeta_crit_off, tt.zeta_crit_off),
        ] {
            assert!((dist(zt, slope_t) / dist(zc, slope_car) - 1.0).abs() < 1e-5);
        }
        assert_eq!(tt.dv_low_on_mps, tc.dv_low_on_mps);
        assert_eq!(tt.ttc_on_s, tc.ttc_on_s);
        assert!(
            (f64::from(parts.controller.smc.phi_radps / car.controller.smc.phi_radps)
                - f_t / f_car)
                .abs()
                < 1e-5
        );
    }
}
