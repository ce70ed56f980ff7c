//! AR polynomial roots -> continuous damping and frequency.
//!
//! Roots are found by the Aberth-Ehrlich simultaneous iteration with a hard iteration bound
//! (never hangs; failure is reported and turns the estimate invalid), in the estimator's own
//! float type: f32 on the target, f64 in the reference twin. It is warm-started from the
//! previous roots, so while tracking it usually converges in 2-4 sweeps. Rooting in f32 is safe
//! here because the polynomial is identified at the decimated rate (~100 Hz), where rounding the
//! coefficients to f32 moves zeta by ~1e-5 (`docs/margin-estimator.md`); the f32 iteration adds
//! rounding of the same order (tested against the f64 twin). An independent solver (nalgebra's
//! Schur decomposition of the companion matrix) checks it in the tests.

/// Largest AR order supported.
pub const MAX_ORDER: usize = 10;

use super::real::Real;

/// A complex number over the estimator's float type: just what the root finder needs.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Cx<T> {
    /// Real part.
    pub re: T,
    /// Imaginary part.
    pub im: T,
}

/// The f64 complex number (reference twin, tests).
pub type C64 = Cx<f64>;

impl<T: Real> Cx<T> {
    /// re + j im
    pub const fn new(re: T, im: T) -> Self {
        Self { re, im }
    }
    fn add(self, o: Self) -> Self {
        Self::new(self.re + o.re, self.im + o.im)
    }
    fn sub(self, o: Self) -> Self {
        Self::new(self.re - o.re, self.im - o.im)
    }
    fn mul(self, o: Self) -> Self {
        Self::new(
            self.re * o.re - self.im * o.im,
            self.re * o.im + self.im * o.re,
        )
    }
    // One division and two products instead of two divisions: a division is 14 cycles on
    // the M4's FPU against 1 for a product, and the Aberth sweep is mostly reciprocals.
    fn div(self, o: Self) -> Self {
        let inv = T::ONE / o.norm_sqr();
        Self::new(
            (self.re * o.re + self.im * o.im) * inv,
            (self.im * o.re - self.re * o.im) * inv,
        )
    }
    fn recip(self) -> Self {
        let inv = T::ONE / self.norm_sqr();
        Self::new(self.re * inv, -self.im * inv)
    }
    /// |z|^2 (no square root: the iteration compares squared magnitudes).
    pub fn norm_sqr(self) -> T {
        self.re * self.re + self.im * self.im
    }
    /// |z|
    pub fn abs(self) -> T {
        self.norm_sqr().sqrt()
    }
    fn is_finite(self) -> bool {
        self.re.is_finite() && self.im.is_finite()
    }
}

/// Root-finding failure.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum RootError {
    /// Order 0 or above `MAX_ORDER`.
    #[error("polynomial order is 0 or above MAX_ORDER")]
    BadOrder,
    /// Non-finite coefficient.
    #[error("a polynomial coefficient is NaN or infinite")]
    NonFinite,
    /// The iteration bound was reached without convergence.
    #[error("root iteration did not converge within its bound")]
    NoConvergence,
}

/// Roots of the monic polynomial `z^p + c[0] z^(p-1) + ... + c[p-1]`, in the float type of the
/// coefficients: f32 in the target's estimator (hardware FPU; f64 is software on the M4 and
/// made this step ~1.2 M instructions), f64 in the reference twin.
///
/// `roots[..p]` is used as the warm start when `warm` is true; on success it holds the roots.
/// Returns the number of sweeps used.
pub fn aberth<T: Real>(
    c: &[T],
    roots: &mut [Cx<T>; MAX_ORDER],
    warm: bool,
    max_iter: u32,
) -> Result<u32, RootError> {
    let p = c.len();
    if p == 0 || p > MAX_ORDER {
        return Err(RootError::BadOrder);
    }
    if c.iter().any(|v| !v.is_finite()) {
        return Err(RootError::NonFinite);
    }
    let warm_ok = warm && roots.iter().take(p).all(|r| r.is_finite()) && distinct(&roots[..p]);
    if !warm_ok {
        cold_start(c, roots);
    }
    match iterate(c, roots, max_iter) {
        Ok(n) => Ok(n),
        Err(e) if warm_ok => {
            cold_start(c, roots);
            iterate(c, roots, max_iter).map_err(|_| e)
        }
        Err(e) => Err(e),
    }
}

fn distinct<T: Real>(r: &[Cx<T>]) -> bool {
    // Coincident starting points make the Aberth correction singular.
    let min_sep_sqr = T::ROOT_TOL * T::ROOT_TOL;
    for i in 0..r.len() {
        for j in (i + 1)..r.len() {
            if r[i].sub(r[j]).norm_sqr() <= min_sep_sqr {
                return false;
            }
        }
    }
    true
}

fn cold_start<T: Real>(c: &[T], roots: &mut [Cx<T>; MAX_ORDER]) {
    let p = c.len();
    // Radius: geometric mean of the root magnitudes |c_p|^(1/p), kept away from 0 (NaN too).
    // Computed once per cold start (rare: reset or lost track), in T throughout: on the
    // target no soft-float f64 (`cargo xtask size`), the f64 twin as before.
    // as exp(ln|c_p| / p): no pow function linked for it (1.4 KB of flash)
    let n = T::from_f32(p as f32);
    let (half, r0) = (T::from_f64(0.5), (c[p - 1].abs().ln() / n).exp());
    let r0 = if r0 > half { r0 } else { half };
    let two_pi = T::from_f64(2.0 * core::f64::consts::PI);
    for (k, r) in roots.iter_mut().take(p).enumerate() {
        let a = T::from_f64(0.4) + two_pi * T::from_f32(k as f32) / n;
        *r = Cx::new(r0 * a.cos(), r0 * a.sin());
    }
}

fn eval<T: Real>(c: &[T], z: Cx<T>) -> (Cx<T>, Cx<T>) {
    // Horner for p(z) and p'(z), monic leading coefficient.
    let mut pv = Cx::new(T::ONE, T::ZERO);
    let mut dp = Cx::new(T::ZERO, T::ZERO);
    for &ck in c {
        dp = dp.mul(z).add(pv);
        pv = pv.mul(z).add(Cx::new(ck, T::ZERO));
    }
    (pv, dp)
}

fn iterate<T: Real>(
    c: &[T],
    roots: &mut [Cx<T>; MAX_ORDER],
    max_iter: u32,
) -> Result<u32, RootError> {
    let p = c.len();
    let tol_sqr = T::ROOT_TOL * T::ROOT_TOL;
    // Rounding floor: a step that no longer shrinks while below 100 x the tolerance is
    // rounding noise (near-multiple roots in f32), not progress still to be made.
    let floor_sqr = T::from_f64(1e4) * tol_sqr;
    let mut last_sqr: Option<T> = None;
    // A root whose correction fell below the tolerance is kept where it is: the Newton ratio
    // that decides its correction is already tiny, and its value still enters the others'
    // sums. While tracking, most roots converge a sweep before the slowest one.
    let mut converged = [false; MAX_ORDER];
    for it in 1..=max_iter {
        let mut max_sqr = T::ZERO;
        for i in 0..p {
            if converged[i] {
                continue;
            }
            let zi = roots[i];
            let (pv, dp) = eval(c, zi);
            if pv.re == T::ZERO && pv.im == T::ZERO {
                converged[i] = true;
                continue; // exact root
            }
            let ratio = pv.div(dp);
            let mut sum = Cx::default();
            for (j, zj) in roots.iter().take(p).enumerate() {
                if j != i {
                    sum = sum.add(zi.sub(*zj).recip());
                }
            }
            let w = ratio.div(Cx::new(T::ONE, T::ZERO).sub(ratio.mul(sum)));
            if !w.is_finite() {
                return Err(RootError::NoConvergence);
            }
            roots[i] = zi.sub(w);
            let mag = zi.norm_sqr();
            let rel_sqr = w.norm_sqr() / if mag > T::ONE { mag } else { T::ONE };
            converged[i] = rel_sqr < tol_sqr;
            if rel_sqr > max_sqr {
                max_sqr = rel_sqr;
            }
        }
        if max_sqr < tol_sqr {
            return Ok(it);
        }
        if let Some(last) = last_sqr {
            // not shrinking by 2 (4 in squares) any more, and already tiny
            if max_sqr < floor_sqr && max_sqr * T::from_f64(4.0) > last {
                return Ok(it);
            }
        }
        last_sqr = Some(max_sqr);
    }
    Err(RootError::NoConvergence)
}

/// One oscillatory mode of the identified model, in continuous time.
/// In the precision `T` of the pole it was mapped from.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Mode<T = f64> {
    /// Damping ratio zeta = -Re(s)/|s| (negative when unstable).
    pub zeta: T,
    /// Damped frequency Im(s) / 2 pi, Hz.
    pub freq_hz: T,
    /// Natural frequency |s| / 2 pi, Hz.
    pub wn_hz: T,
    /// Index of the root in the slice [`select_mode`] chose from (0 from [`mode_of_root`]).
    pub root_index: usize,
}

/// Maps a discrete pole z (upper half plane) at sample rate `fs` (Hz) to a continuous mode via
/// s = ln(z) fs, computed in the pole's float type. Returns `None` for |z| ~ 0 (s -> -inf) or
/// a real pole.
pub fn mode_of_root<T: Real>(z: Cx<T>, fs: T) -> Option<Mode<T>> {
    let r2 = z.norm_sqr();
    if r2.is_finite() && z.im > T::ZERO && r2 > T::from_f64(1e-18) {
        // ln|z| = ln(|z|^2) / 2: no square root, no hypot
        let sr = T::from_f64(0.5) * r2.ln() * fs;
        let si = z.im.atan2(z.re) * fs;
        let mag = (sr * sr + si * si).sqrt();
        let two_pi = T::from_f64(2.0 * core::f64::consts::PI);
        if si > T::ZERO && mag.is_finite() {
            return Some(Mode {
                zeta: -sr / mag,
                freq_hz: si / two_pi,
                wn_hz: mag / two_pi,
                root_index: 0,
            });
        }
    }
    None
}

/// Undoes the finite-memory bias that exponentially weighted least squares puts into a lightly
/// damped AR pole.
///
/// RLS with forgetting factor lambda shrinks a pole rho towards the origin. To second order in
/// the estimation error (the ratio expansion E[N/D] ~ -E[N (D - E D)] / (E D)^2 of the weighted
/// LS estimate of a circular complex AR(1), which is what a lightly damped real pair is away
/// from 0 Hz and Nyquist):
///
/// `E[rho_hat] = rho (1 - beta)`, `beta = kappa (1 - |rho|^2) / (1 - lambda |rho|^2)`,
/// `kappa = lambda (1 - lambda) / (1 + lambda)`.
///
/// `kappa` is 1/N of a window N = (1 + lambda) / (1 - lambda) (the classic -rho/N bias of the
/// complex AR(1)); the second factor is the local-to-unity term: ~1 when the mode decays well
/// within the window, -> 0 as |rho| -> 1 (a mode that outlives the window). Only the radius is
/// biased, the angle (frequency) is not. In damping terms the shift is
/// `zeta omega_n = -ln(1 - beta) f_s`, about 0.0023 at zeta = 0.01, 5 Hz, lambda = 0.998,
/// 100 Hz: 0.4 of the accuracy bound, which is why it is removed rather than tolerated.
/// Roots on or outside the unit circle are returned unchanged (the stationary expansion does
/// not apply there and beta -> 0 at |rho| = 1, so the map is continuous and monotone in |rho|).
#[derive(Clone, Copy, Debug)]
pub struct ForgettingBias<T> {
    lambda: T,
    kappa: T,
}

impl<T: Real> ForgettingBias<T> {
    /// For an RLS with forgetting factor `lambda` (0 < lambda < 1).
    pub fn new(lambda: f64) -> Self {
        Self {
            lambda: T::from_f64(lambda),
            kappa: T::from_f64(lambda * (1.0 - lambda) / (1.0 + lambda)),
        }
    }

    /// The relative shrink `beta` expected for a pole of squared radius `r2` (0 outside the
    /// unit disc).
    pub fn shrink(&self, r2: T) -> T {
        if r2 < T::ONE && r2 >= T::ZERO {
            self.kappa * (T::ONE - r2) / (T::ONE - self.lambda * r2)
        } else {
            T::ZERO
        }
    }

    /// The root with its expected shrink undone: `z / (1 - beta(|z|^2))`.
    pub fn correct(&self, z: Cx<T>) -> Cx<T> {
        let g = T::ONE / (T::ONE - self.shrink(z.norm_sqr()));
        Cx::new(z.re * g, z.im * g)
    }
}

/// Chooses the mode to report among the AR roots: the least-damped pair with damped frequency
/// in `[f_lo, f_hi]`; for continuity a pair within `track_tol_hz` of the previous frequency is
/// preferred when its damping is within `track_zeta_tol` of the least-damped one. In the roots'
/// precision `T` throughout (the target's f32: no soft-float f64 in the 100 Hz meter run).
pub fn select_mode<T: Real>(
    roots: &[Cx<T>],
    fs_hz: T,
    f_lo_hz: T,
    f_hi_hz: T,
    last_freq_hz: Option<T>,
    track_tol_hz: T,
    track_zeta_tol: T,
) -> Option<Mode<T>> {
    // Each root is mapped once (ln and atan2 are the costly part).
    let mut in_band = [Mode::<T>::default(); MAX_ORDER];
    let mut n = 0;
    for (i, z) in roots.iter().enumerate().take(MAX_ORDER) {
        if let Some(m) = mode_of_root(*z, fs_hz) {
            if m.freq_hz >= f_lo_hz && m.freq_hz <= f_hi_hz {
                if let Some(slot) = in_band.get_mut(n) {
                    *slot = Mode { root_index: i, ..m };
                    n += 1;
                }
            }
        }
    }
    let modes = in_band.get(..n).unwrap_or(&[]);
    let best = modes
        .iter()
        .copied()
        .reduce(|b, m| if m.zeta < b.zeta { m } else { b })?;
    let Some(last) = last_freq_hz else {
        return Some(best);
    };
    let mut tracked: Option<Mode<T>> = None;
    for m in modes {
        let df = (m.freq_hz - last).abs();
        if df <= track_tol_hz
            && m.zeta <= best.zeta + track_zeta_tol
            && tracked.is_none_or(|t| df < (t.freq_hz - last).abs())
        {
            tracked = Some(*m);
        }
    }
    Some(tracked.unwrap_or(best))
}

/// One-sigma uncertainty of the damping ratio of an AR root, from the covariance of the fitted
/// coefficients by first-order root sensitivity (the delta method).
///
/// `a` are the AR coefficients of z^p - a_1 z^(p-1) - ... - a_p, `z` one of its roots, `cov(i, j)`
/// the covariance of a_(i+1) and a_(j+1). A simple root moves by dz/da_k = z^(p-k) / F'(z); the
/// continuous pole s = fs ln z by ds = fs dz / z; and zeta = -Re(s)/|s| by
/// dzeta = (-Im(s)^2 dRe(s) + Re(s) Im(s) dIm(s)) / |s|^3. Returns `None` when the root is
/// (numerically) multiple or the result is not finite.
pub fn zeta_sigma<T: Real>(
    a: &[T],
    z: Cx<T>,
    fs_hz: f64,
    cov: impl Fn(usize, usize) -> T,
) -> Option<T> {
    let p = a.len().min(MAX_ORDER);
    // Horner for F and F' together
    let (mut f, mut d) = (Cx::new(T::ONE, T::ZERO), Cx::new(T::ZERO, T::ZERO));
    for ak in a.iter().take(p) {
        d = d.mul(z).add(f);
        f = f.mul(z).sub(Cx::new(*ak, T::ZERO));
    }
    let fs = T::from_f64(fs_hz);
    let dz_scale = Cx::new(fs, T::ZERO).div(d.mul(z));
    if !dz_scale.is_finite() {
        return None;
    }
    let sr = T::from_f64(0.5) * z.norm_sqr().ln() * fs;
    let si = z.im.atan2(z.re) * fs;
    let mag2 = sr * sr + si * si;
    let mag3 = mag2 * mag2.sqrt();
    let (g_re, g_im) = (-si * si / mag3, sr * si / mag3);
    // gradient of zeta over a_1..a_p; z^(p-k) built from k = p (z^0) downwards
    let mut g = [T::ZERO; MAX_ORDER];
    let mut pow = Cx::new(T::ONE, T::ZERO);
    for gk in g.iter_mut().take(p).rev() {
        let ds = pow.mul(dz_scale);
        *gk = g_re * ds.re + g_im * ds.im;
        pow = pow.mul(z);
    }
    let mut var = T::ZERO;
    for (i, gi) in g.iter().enumerate().take(p) {
        for (j, gj) in g.iter().enumerate().take(p) {
            var += *gi * cov(i, j) * *gj;
        }
    }
    let sigma = if var > T::ZERO { var.sqrt() } else { T::ZERO };
    sigma.is_finite().then_some(sigma)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Complex, DMatrix};

    fn companion_eigs(c: &[f64]) -> Vec<Complex<f64>> {
        let p = c.len();
        let mut m = DMatrix::<f64>::zeros(p, p);
        for j in 0..p {
            m[(0, j)] = -c[j];
        }
        for i in 1..p {
            m[(i, i - 1)] = 1.0;
        }
        let s = nalgebra::Schur::try_new(m, 1e-14, 10_000).unwrap();
        s.complex_eigenvalues().iter().copied().collect()
    }

    fn poly_from_roots(r: &[Complex<f64>]) -> Vec<f64> {
        let mut c = vec![Complex::new(1.0, 0.0)];
        for &z in r {
            let mut n = vec![Complex::new(0.0, 0.0); c.len() + 1];
            for (k, &ck) in c.iter().enumerate() {
                n[k] += ck;
                n[k + 1] -= ck * z;
            }
            c = n;
        }
        c[1..].iter().map(|v| v.re).collect()
    }

    /// Deterministic uniform [0, 1) numbers (64-bit LCG): the polynomial sets stay fixed.
    fn uniform(mut seed: u64) -> impl FnMut() -> f64 {
        move || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    #[test]
    fn aberth_agrees_with_schur_on_random_ar_polynomials() {
        // Pole sets like a decimated mode meter sees: pairs near the unit circle + real poles.
        let mut rnd = uniform(12345u64);
        for _ in 0..200 {
            let mut r = Vec::new();
            for _ in 0..2 {
                let rad = 0.6 + 0.399 * rnd();
                let ang = 0.1 + 2.9 * rnd();
                r.push(Complex::from_polar(rad, ang));
                r.push(Complex::from_polar(rad, -ang));
            }
            r.push(Complex::new(rnd() * 1.6 - 0.8, 0.0));
            r.push(Complex::new(rnd() * 1.6 - 0.8, 0.0));
            let c = poly_from_roots(&r);
            let mut roots = [C64::default(); MAX_ORDER];
            aberth(&c, &mut roots, false, 100).unwrap();
            let reference = companion_eigs(&c);
            for z in &roots[..6] {
                let d = reference
                    .iter()
                    .map(|w| (w - Complex::new(z.re, z.im)).norm())
                    .fold(f64::INFINITY, f64::min);
                assert!(d < 1e-7, "root {z:?} not in Schur set, distance {d}");
            }
        }
    }

    #[test]
    fn f32_roots_agree_with_f64_roots_on_decimated_ar6_polynomials() {
        // The target roots its f32 RLS coefficients in f32: on the same (f32-representable)
        // coefficients of decimated-rate AR(6) models, the in-band damping must match the f64
        // root within a small fraction of the ambient accuracy bound (~0.005 at best).
        let fs = 100.0;
        let mut rnd = uniform(777u64);
        let mut worst = 0.0f64;
        for _ in 0..300 {
            let pole = |zeta: f64, f: f64| {
                let w = 2.0 * core::f64::consts::PI * f;
                (Complex::new(-zeta * w, w * (1.0 - zeta * zeta).sqrt()) / fs).exp()
            };
            let (zeta, f) = (0.01 + 0.09 * rnd(), 5.0 + 13.0 * rnd());
            let (p1, p2) = (pole(zeta, f), pole(0.3 + 0.4 * rnd(), 25.0 + 20.0 * rnd()));
            let r = [
                p1,
                p1.conj(),
                p2,
                p2.conj(),
                Complex::new(rnd() * 1.2 - 0.6, 0.0),
                Complex::new(rnd() * 1.2 - 0.6, 0.0),
            ];
            let c64: Vec<f64> = poly_from_roots(&r)
                .iter()
                .map(|v| (*v as f32) as f64)
                .collect();
            let c32: Vec<f32> = c64.iter().map(|v| *v as f32).collect();
            let mut z64 = [C64::default(); MAX_ORDER];
            let mut z32 = [Cx::<f32>::default(); MAX_ORDER];
            aberth(&c64, &mut z64, false, 100).unwrap();
            aberth(&c32, &mut z32, false, 100).unwrap();
            let m64 = select_mode(&z64[..6], fs, 3.0, 20.0, None, 1.0, 0.02).unwrap();
            let m32 = select_mode(&z32[..6], fs as f32, 3.0, 20.0, None, 1.0, 0.02).unwrap();
            worst = worst.max((m64.zeta - f64::from(m32.zeta)).abs());
            assert!((m64.freq_hz - f64::from(m32.freq_hz)).abs() < 1e-3);
            // warm restart from the found roots converges at once in f32 too
            assert!(aberth(&c32, &mut z32, true, 100).unwrap() <= 3);
        }
        eprintln!("worst f32-vs-f64 zeta difference {worst:.2e}");
        assert!(worst < 1e-5, "worst f32-vs-f64 zeta difference {worst}");
    }

    #[test]
    fn warm_start_converges_fast_and_failure_is_reported() {
        let r = [
            Complex::from_polar(0.97, 0.5),
            Complex::from_polar(0.97, -0.5),
            Complex::new(0.3, 0.0),
            Complex::new(-0.2, 0.0),
        ];
        let c = poly_from_roots(&r);
        let mut roots = [C64::default(); MAX_ORDER];
        let cold = aberth(&c, &mut roots, false, 100).unwrap();
        let warm = aberth(&c, &mut roots, true, 100).unwrap();
        assert!(warm <= 2 && warm <= cold, "warm {warm}, cold {cold}");
        // One sweep is not enough from a cold start: must report, not hang.
        let mut roots = [C64::default(); MAX_ORDER];
        assert_eq!(
            aberth(&c, &mut roots, false, 1),
            Err(RootError::NoConvergence)
        );
        assert_eq!(
            aberth(&[f64::NAN; 4], &mut roots, false, 100),
            Err(RootError::NonFinite)
        );
        assert_eq!(
            aberth(&[0.0; MAX_ORDER + 1], &mut roots, false, 100),
            Err(RootError::BadOrder)
        );
    }

    #[test]
    fn mode_mapping_inverts_exact_discretisation() {
        let (zeta, f, fs) = (0.05f64, 8.0f64, 100.0f64);
        let wn = 2.0 * core::f64::consts::PI * f;
        let s = Complex::new(-zeta * wn, wn * (1.0 - zeta * zeta).sqrt());
        let z = (s / fs).exp();
        let m = mode_of_root(C64::new(z.re, z.im), fs).unwrap();
        assert!((m.zeta - zeta).abs() < 1e-12);
        assert!((m.wn_hz - f).abs() < 1e-12);
        assert!(mode_of_root(C64::new(z.re, -z.im), fs).is_none());
    }

    #[test]
    fn selection_prefers_least_damped_in_band_and_tracks_continuity() {
        let fs = 100.0;
        let root = |zeta: f64, f: f64| {
            let w = 2.0 * core::f64::consts::PI * f;
            let s = Complex::new(-zeta * w, w * (1.0 - zeta * zeta).sqrt());
            let z = (s / fs).exp();
            C64::new(z.re, z.im)
        };
        let roots = [
            root(0.05, 8.0),
            root(0.04, 12.0),
            root(0.001, 25.0),
            root(0.01, 2.0),
        ];
        // out-of-band poles (25 Hz, 2 Hz) are ignored even though they are less damped
        let m = select_mode(&roots, fs, 3.0, 20.0, None, 1.0, 0.02).unwrap();
        assert!((m.wn_hz - 12.0).abs() < 1e-9);
        // continuity: last frequency 8 Hz and 0.05 within 0.02 of 0.04 -> keep tracking 8 Hz
        let m = select_mode(&roots, fs, 3.0, 20.0, Some(8.1), 1.0, 0.02).unwrap();
        assert!((m.wn_hz - 8.0).abs() < 1e-9);
        // ... but not when the other pair is clearly less damped
        let m = select_mode(&roots, fs, 3.0, 20.0, Some(8.1), 1.0, 0.005).unwrap();
        assert!((m.wn_hz - 12.0).abs() < 1e-9);
        assert!(select_mode(&roots[2..], fs, 3.0, 20.0, None, 1.0, 0.02).is_none());
    }

    /// The forgetting-bias formula against a direct Monte Carlo of what it models: exponentially
    /// weighted least squares of a circular complex AR(1), rho_hat = sum w z_k z*_{k-1} /
    /// sum w |z_{k-1}|^2, on long simulated records. Covers the local-to-unity factor from
    /// ~0.56 (the 5 Hz, zeta = 0.01 pole under the fast lambda) to ~0.96.
    #[test]
    fn forgetting_bias_matches_weighted_ls_monte_carlo() {
        use rand::SeedableRng;
        use rand_distr::{Distribution, StandardNormal};
        // (pole radius, angle, lambda): the 5 Hz, zeta 0.01 and 8 Hz, zeta 0.05 poles at 100 Hz
        let cases = [
            (libm::exp(-0.01 * 0.1 * core::f64::consts::PI), 0.314, 0.998),
            (libm::exp(-0.01 * 0.1 * core::f64::consts::PI), 0.314, 0.995),
            (
                libm::exp(-0.05 * 0.16 * core::f64::consts::PI),
                0.503,
                0.998,
            ),
        ];
        for (ci, &(r, th, lambda)) in cases.iter().enumerate() {
            let rho = Cx::new(r * libm::cos(th), r * libm::sin(th));
            let fb = ForgettingBias::<f64>::new(lambda);
            let beta = fb.shrink(r * r);
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(41 + ci as u64);
            let mut z = Cx::new(0.0, 0.0);
            let (mut den, mut num) = (0.0, Cx::new(0.0, 0.0));
            let (mut sum, mut sum2, mut n) = (0.0, 0.0, 0.0);
            let mut raw_minus_corrected = 0.0;
            let window = (1.0 / (1.0 - lambda)) as usize;
            for k in 0..3_000_000usize {
                let e = Cx::new(
                    StandardNormal.sample(&mut rng),
                    StandardNormal.sample(&mut rng),
                );
                let z_new = rho.mul(z).add(e);
                den = lambda * den + z.norm_sqr();
                num =
                    Cx::new(lambda * num.re, lambda * num.im).add(z_new.mul(Cx::new(z.re, -z.im)));
                z = z_new;
                // skip 20 windows of burn-in, then take one estimate per window
                if k > 20 * window && k % window == 0 {
                    let est = Cx::new(num.re / den, num.im / den);
                    // radial part of rho_hat / rho - 1
                    let ratio = est.div(rho);
                    let shrink = 1.0 - ratio.re;
                    sum += shrink;
                    sum2 += shrink * shrink;
                    n += 1.0;
                    let c = fb.correct(est);
                    raw_minus_corrected += libm::sqrt(c.norm_sqr()) - libm::sqrt(est.norm_sqr());
                }
            }
            let mean = sum / n;
            // estimates one window apart are correlated ~exp(-1): count them as half
            let se = libm::sqrt((sum2 / n - mean * mean) / (0.5 * n));
            println!(
                "case {ci}: lambda {lambda}, |rho| {r:.5}: shrink {mean:.3e} +- {se:.1e}, formula {beta:.3e}"
            );
            assert!(
                mean > 8.0 * se,
                "the bias must be resolvable, or the test proves nothing"
            );
            assert!(
                (mean - beta).abs() < 0.1 * beta + 3.0 * se,
                "case {ci}: measured shrink {mean:.3e} vs formula {beta:.3e}"
            );
            // the correction moves the radius out by ~beta
            let moved = raw_minus_corrected / n;
            assert!(
                (moved - beta).abs() < 0.05 * beta,
                "{moved:.3e} vs {beta:.3e}"
            );
        }
        // outside the unit disc nothing is changed
        let fb = ForgettingBias::<f64>::new(0.998);
        assert_eq!(fb.shrink(1.0), 0.0);
        assert_eq!(fb.correct(Cx::new(0.0, 1.01)), Cx::new(0.0, 1.01));
    }

    /// The delta-method sigma against a Monte Carlo of the same coefficient covariance, rooted
    /// by an independent solver (nalgebra's Schur of the companion matrix): the spread of the
    /// perturbed polynomials' damping must match the first-order prediction.
    #[test]
    fn zeta_sigma_matches_monte_carlo_of_the_coefficients() {
        use rand::{RngExt, SeedableRng};
        use rand_distr::StandardNormal;
        let fs = 50.0;
        let pole = |zeta: f64, f: f64| {
            let wn = 2.0 * core::f64::consts::PI * f;
            let s = Complex::new(-zeta * wn, wn * (1.0 - zeta * zeta).sqrt());
            (s / fs).exp()
        };
        let (zs, z2) = (pole(0.05, 7.0), pole(0.25, 11.0));
        let roots = [
            zs,
            zs.conj(),
            z2,
            z2.conj(),
            Complex::new(0.5, 0.0),
            Complex::new(-0.3, 0.0),
        ];
        let c = poly_from_roots(&roots);
        let a: Vec<f64> = c.iter().map(|v| -v).collect();
        // a covariance with correlated neighbours (like the AR normal equations give)
        let sd = 2e-4;
        let cov = |i: usize, j: usize| -> f64 {
            let d = i.abs_diff(j) as i32;
            sd * sd * 0.6f64.powi(d)
        };
        let sigma = zeta_sigma(&a, Cx::new(zs.re, zs.im), fs, cov).unwrap();
        let p = a.len();
        let l = nalgebra::DMatrix::<f64>::from_fn(p, p, &cov)
            .cholesky()
            .unwrap()
            .l();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let z_true = mode_of_root(Cx::new(zs.re, zs.im), fs).unwrap().zeta;
        let n = 4000;
        let mut sum2 = 0.0;
        for _ in 0..n {
            let e = nalgebra::DVector::<f64>::from_fn(p, |_, _| rng.sample(StandardNormal));
            let d = &l * e;
            let cp: Vec<f64> = (0..p).map(|k| -(a[k] + d[k])).collect();
            let near = companion_eigs(&cp)
                .into_iter()
                .min_by(|x, y| (x - zs).norm().total_cmp(&(y - zs).norm()))
                .unwrap();
            let z = mode_of_root(Cx::new(near.re, near.im.abs()), fs)
                .unwrap()
                .zeta;
            sum2 += (z - z_true).powi(2);
        }
        let mc = (sum2 / n as f64).sqrt();
        assert!(
            (sigma / mc - 1.0).abs() < 0.06,
            "delta method {sigma:.3e} vs Monte Carlo {mc:.3e}"
        );
        // f32 gives the same to its precision
        let a32: Vec<f32> = a.iter().map(|v| *v as f32).collect();
        let s32 = zeta_sigma(&a32, Cx::new(zs.re as f32, zs.im as f32), fs, |i, j| {
            cov(i, j) as f32
        })
        .unwrap();
        assert!(
            (f64::from(s32) / sigma - 1.0).abs() < 1e-2,
            "f32 {s32} vs f64 {sigma}"
        );
    }
}
