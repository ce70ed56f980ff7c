//! AR polynomial roots -> continuous damping and frequency.
//!
//! Roots are found by the Aberth-Ehrlich simultaneous iteration in f64 with a hard iteration
//! bound (never hangs; failure is reported and turns the estimate invalid). It is warm-started
//! from the previous roots, so while tracking it usually converges in 2-4 sweeps. The AR
//! coefficients come from the (f32 or f64) RLS; converting them to f64 is exact, so the root
//! step adds no rounding beyond what the coefficients already carry. An independent solver
//! (nalgebra's Schur decomposition of the companion matrix) checks it in the tests.

/// Largest AR order supported.
pub const MAX_ORDER: usize = 8;

/// A complex number (f64), just what the root finder needs.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct C64 {
    /// Real part.
    pub re: f64,
    /// Imaginary part.
    pub im: f64,
}

impl C64 {
    /// re + j im
    pub const fn new(re: f64, im: f64) -> Self {
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
    fn div(self, o: Self) -> Self {
        let d = o.re * o.re + o.im * o.im;
        Self::new(
            (self.re * o.re + self.im * o.im) / d,
            (self.im * o.re - self.re * o.im) / d,
        )
    }
    /// |z|
    pub fn abs(self) -> f64 {
        libm::hypot(self.re, self.im)
    }
    fn is_finite(self) -> bool {
        self.re.is_finite() && self.im.is_finite()
    }
}

/// Root-finding failure.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RootError {
    /// Order 0 or above `MAX_ORDER`.
    BadOrder,
    /// Non-finite coefficient.
    NonFinite,
    /// The iteration bound was reached without convergence.
    NoConvergence,
}

/// Roots of the monic polynomial z^p + c[0] z^(p-1) + ... + c[p-1].
///
/// `roots[..p]` is used as the warm start when `warm` is true; on success it holds the roots.
/// Returns the number of sweeps used.
pub fn aberth(
    c: &[f64],
    roots: &mut [C64; MAX_ORDER],
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

fn distinct(r: &[C64]) -> bool {
    for i in 0..r.len() {
        for j in (i + 1)..r.len() {
            if r[i].sub(r[j]).abs() < 1e-9 {
                return false;
            }
        }
    }
    true
}

fn cold_start(c: &[f64], roots: &mut [C64; MAX_ORDER]) {
    let p = c.len();
    // Radius: geometric mean of the root magnitudes |c_p|^(1/p), kept away from 0.
    let r0 = libm::pow(libm::fabs(c[p - 1]), 1.0 / p as f64).max(0.5);
    for (k, r) in roots.iter_mut().take(p).enumerate() {
        let a = 0.4 + 2.0 * core::f64::consts::PI * k as f64 / p as f64;
        *r = C64::new(r0 * libm::cos(a), r0 * libm::sin(a));
    }
}

fn eval(c: &[f64], z: C64) -> (C64, C64) {
    // Horner for p(z) and p'(z), monic leading coefficient.
    let mut pv = C64::new(1.0, 0.0);
    let mut dp = C64::new(0.0, 0.0);
    for &ck in c {
        dp = dp.mul(z).add(pv);
        pv = pv.mul(z).add(C64::new(ck, 0.0));
    }
    (pv, dp)
}

fn iterate(c: &[f64], roots: &mut [C64; MAX_ORDER], max_iter: u32) -> Result<u32, RootError> {
    let p = c.len();
    for it in 1..=max_iter {
        let mut max_step = 0.0f64;
        for i in 0..p {
            let zi = roots[i];
            let (pv, dp) = eval(c, zi);
            if pv.re == 0.0 && pv.im == 0.0 {
                continue; // exact root
            }
            let ratio = pv.div(dp);
            let mut sum = C64::default();
            for (j, zj) in roots.iter().take(p).enumerate() {
                if j != i {
                    sum = sum.add(C64::new(1.0, 0.0).div(zi.sub(*zj)));
                }
            }
            let w = ratio.div(C64::new(1.0, 0.0).sub(ratio.mul(sum)));
            if !w.is_finite() {
                return Err(RootError::NoConvergence);
            }
            roots[i] = zi.sub(w);
            let rel = w.abs() / zi.abs().max(1.0);
            if rel > max_step {
                max_step = rel;
            }
        }
        if max_step < 1e-13 {
            return Ok(it);
        }
    }
    Err(RootError::NoConvergence)
}

/// One oscillatory mode of the identified model, in continuous time.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Mode {
    /// Damping ratio zeta = -Re(s)/|s| (negative when unstable).
    pub zeta: f64,
    /// Damped frequency Im(s) / 2 pi, Hz.
    pub freq_hz: f64,
    /// Natural frequency |s| / 2 pi, Hz.
    pub wn_hz: f64,
}

/// Maps a discrete pole z (upper half plane) at sample rate `fs_hz` to a continuous mode via
/// s = ln(z) fs. Returns `None` for |z| ~ 0 (s -> -inf) or a real pole.
pub fn mode_of_root(z: C64, fs_hz: f64) -> Option<Mode> {
    let r = z.abs();
    if r.is_nan() || r <= 1e-9 || !r.is_finite() {
        return None;
    }
    let sr = libm::log(r) * fs_hz;
    let si = libm::atan2(z.im, z.re) * fs_hz;
    if si.is_nan() || si <= 0.0 {
        return None;
    }
    let mag = libm::hypot(sr, si);
    Some(Mode {
        zeta: -sr / mag,
        freq_hz: si / (2.0 * core::f64::consts::PI),
        wn_hz: mag / (2.0 * core::f64::consts::PI),
    })
}

/// Chooses the mode to report among the AR roots: the least-damped pair with damped frequency
/// in `[f_lo, f_hi]`; for continuity a pair within `track_tol_hz` of the previous frequency is
/// preferred when its damping is within `track_zeta_tol` of the least-damped one.
pub fn select_mode(
    roots: &[C64],
    fs_hz: f64,
    f_lo_hz: f64,
    f_hi_hz: f64,
    last_freq_hz: Option<f64>,
    track_tol_hz: f64,
    track_zeta_tol: f64,
) -> Option<Mode> {
    let mut best: Option<Mode> = None;
    for z in roots {
        if let Some(m) = mode_of_root(*z, fs_hz) {
            if m.freq_hz >= f_lo_hz && m.freq_hz <= f_hi_hz && best.is_none_or(|b| m.zeta < b.zeta)
            {
                best = Some(m);
            }
        }
    }
    let best = best?;
    let Some(last) = last_freq_hz else {
        return Some(best);
    };
    let mut tracked: Option<Mode> = None;
    for z in roots {
        if let Some(m) = mode_of_root(*z, fs_hz) {
            let df = libm::fabs(m.freq_hz - last);
            if m.freq_hz >= f_lo_hz
                && m.freq_hz <= f_hi_hz
                && df <= track_tol_hz
                && m.zeta <= best.zeta + track_zeta_tol
                && tracked.is_none_or(|t| df < libm::fabs(t.freq_hz - last))
            {
                tracked = Some(m);
            }
        }
    }
    Some(tracked.unwrap_or(best))
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

    #[test]
    fn aberth_agrees_with_schur_on_random_ar_polynomials() {
        // Pole sets like a decimated mode meter sees: pairs near the unit circle + real poles.
        let mut seed = 12345u64;
        let mut rnd = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
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
}
