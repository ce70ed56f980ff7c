//! Eigenvalues only of a real square matrix: Householder reduction to upper Hessenberg form,
//! then the implicit double-shift (Francis) QR iteration with deflation.
//!
//! Why not nalgebra's `Schur`: it accumulates the orthogonal Schur vectors and keeps the whole
//! quasi-triangular factor up to date, work that eigenvalues do not need. Here each QR sweep
//! updates only the unreduced active block, and nothing is accumulated: the firmware's f32
//! solve of the 10x10 state matrix takes less than half the instructions (`cargo xtask bench`,
//! eigen update row) and less code. On fixed arrays, no heap, bounded work.

use crate::sqrt::Sqrt;
use nalgebra::{Complex, RealField};

/// Sweeps without a deflation after which one exceptional shift breaks a possible cycle of
/// the standard shifts (the usual choice: every 10th).
const EXCEPTIONAL_EVERY: usize = 10;

/// The eigenvalues of `h` (any real matrix; overwritten), in the order of the diagonal blocks
/// they come from, a complex pair as two adjacent entries with +Im first; `None` when
/// `max_niter` QR sweeps did not converge. `eps` is the relative deflation threshold.
/// (Generic over nalgebra's `RealField`, not the solver's `SolveFloat`: this file imports
/// nothing from the module that uses it.)
pub fn eigenvalues<T: RealField + Copy + Sqrt, const N: usize>(
    mut h: [[T; N]; N],
    eps: T,
    max_niter: usize,
) -> Option<[Complex<T>; N]> {
    let zero = Complex::new(T::zero(), T::zero());
    let amax = h.iter().flatten().fold(T::zero(), |m, x| m.max(x.abs()));
    if amax == T::zero() {
        return Some([zero; N]);
    }
    // Scale by a power of two (exact) to max |h_ij| near 1: the shift polynomial squares
    // entries, which must not overflow for entries near the type's range. The exponent from
    // the f64 bits (no libm frexp/ldexp linked), within +-100 so 2^e exists in f32 too.
    let bits = amax.to_subset().unwrap_or(1.0f64).to_bits();
    let e = (((bits >> 52) & 0x7ff) as i64 - 1022).clamp(-100, 100);
    let pow2 = |k: i64| f64::from_bits(((k + 1023) as u64) << 52);
    let down: T = nalgebra::convert(pow2(-e));
    let up: T = nalgebra::convert(pow2(e));
    for x in h.iter_mut().flatten() {
        *x *= down;
    }
    reduce_to_hessenberg(&mut h);

    let mut out = [zero; N];
    let tiny = eps * eps;
    let (mut niter, mut since_deflation) = (0, 0);
    // the active block is lo..=n; everything below and right of it is done
    let mut end = N;
    while end > 0 {
        let n = end - 1;
        let mut lo = n;
        while lo > 0 {
            let sub = h[lo][lo - 1].abs();
            if sub <= tiny || sub <= eps * (h[lo - 1][lo - 1].abs() + h[lo][lo].abs()) {
                h[lo][lo - 1] = T::zero();
                break;
            }
            lo -= 1;
        }
        if lo == n {
            out[n] = Complex::new(h[n][n] * up, T::zero());
            end -= 1;
            since_deflation = 0;
        } else if lo + 1 == n {
            let (a, b) = two_by_two(h[n - 1][n - 1], h[n - 1][n], h[n][n - 1], h[n][n]);
            out[n - 1] = a * up;
            out[n] = b * up;
            end -= 2;
            since_deflation = 0;
        } else {
            if niter == max_niter {
                return None;
            }
            niter += 1;
            since_deflation += 1;
            francis_sweep(&mut h, lo, n, since_deflation % EXCEPTIONAL_EVERY == 0);
        }
    }
    Some(out)
}

/// A Householder reflector P = I - beta u u^T with P x = alpha e1 for x = (x0, x1, x2), as
/// (u, beta, alpha); `None` when x = 0. u0 = x0 - alpha with alpha of the opposite sign of x0
/// (no cancellation), and beta = 2 / |u|^2 = -1 / (alpha u0).
fn reflector<T: RealField + Copy + Sqrt>(x0: T, x1: T, x2: T) -> Option<([T; 3], T, T)> {
    let norm = (x0 * x0 + x1 * x1 + x2 * x2).sqrt_rounded();
    if norm == T::zero() {
        return None;
    }
    let alpha = if x0 > T::zero() { -norm } else { norm };
    let u0 = x0 - alpha;
    Some(([u0, x1, x2], -T::one() / (alpha * u0), alpha))
}

/// Reduces `h` to upper Hessenberg form by a similarity with Householder reflectors (n - 2 of
/// them, each zeroing one column below the subdiagonal).
#[allow(clippy::needless_range_loop)] // i and j index rows, columns and the reflector alike
fn reduce_to_hessenberg<T: RealField + Copy + Sqrt, const N: usize>(h: &mut [[T; N]; N]) {
    for k in 0..N.saturating_sub(2) {
        let tail2 = (k + 2..N).fold(T::zero(), |s, i| s + h[i][k] * h[i][k]);
        if tail2 == T::zero() {
            continue; // already Hessenberg in this column
        }
        let x0 = h[k + 1][k];
        let norm = (x0 * x0 + tail2).sqrt_rounded();
        let alpha = if x0 > T::zero() { -norm } else { norm };
        let mut u = [T::zero(); N];
        u[k + 1] = x0 - alpha;
        for i in k + 2..N {
            u[i] = h[i][k];
        }
        let beta = -T::one() / (alpha * u[k + 1]);
        // from the left: rows k+1.. of columns k+1.. (column k becomes alpha e1 exactly)
        for j in k + 1..N {
            let s = (k + 1..N).fold(T::zero(), |s, i| s + u[i] * h[i][j]) * beta;
            for i in k + 1..N {
                h[i][j] -= s * u[i];
            }
        }
        h[k + 1][k] = alpha;
        for i in k + 2..N {
            h[i][k] = T::zero();
        }
        // from the right: columns k+1.. of every row
        for row in h.iter_mut() {
            let s = (k + 1..N).fold(T::zero(), |s, j| s + row[j] * u[j]) * beta;
            for j in k + 1..N {
                row[j] -= s * u[j];
            }
        }
    }
}

/// One implicit double-shift QR sweep on the unreduced Hessenberg block lo..=n (n - lo >= 2):
/// the shifts are the eigenvalues of its trailing 2x2 (or an exceptional pair), the bulge is
/// chased down with 3-element reflectors, and only the block itself is updated.
#[allow(clippy::needless_range_loop)] // j indexes the same column of two or three rows
fn francis_sweep<T: RealField + Copy + Sqrt, const N: usize>(
    h: &mut [[T; N]; N],
    lo: usize,
    n: usize,
    exceptional: bool,
) {
    let m = n - 1;
    // shift polynomial s^2 - trace s + det
    let (trace, det) = if exceptional {
        let s = h[n][m].abs() + h[m][m - 1].abs();
        let h11 = nalgebra::convert::<f64, T>(0.75) * s + h[n][n];
        let h12 = nalgebra::convert::<f64, T>(-0.4375) * s;
        (h11 + h11, h11 * h11 - h12 * s)
    } else {
        (h[m][m] + h[n][n], h[m][m] * h[n][n] - h[m][n] * h[n][m])
    };
    // first column of (H - s1 I)(H - s2 I)
    let (h00, h01, h10, h11, h21) = (
        h[lo][lo],
        h[lo][lo + 1],
        h[lo + 1][lo],
        h[lo + 1][lo + 1],
        h[lo + 2][lo + 1],
    );
    let mut x = [
        h00 * h00 + h01 * h10 - trace * h00 + det,
        h10 * (h00 + h11 - trace),
        h10 * h21,
    ];
    for k in lo..=n - 2 {
        if let Some((u, beta, alpha)) = reflector(x[0], x[1], x[2]) {
            // left: rows k..k+2 of the block's columns (the bulge column k-1 becomes alpha e1)
            let first = if k > lo {
                h[k][k - 1] = alpha;
                h[k + 1][k - 1] = T::zero();
                h[k + 2][k - 1] = T::zero();
                k
            } else {
                lo
            };
            for j in first..=n {
                let s = (u[0] * h[k][j] + u[1] * h[k + 1][j] + u[2] * h[k + 2][j]) * beta;
                h[k][j] -= s * u[0];
                h[k + 1][j] -= s * u[1];
                h[k + 2][j] -= s * u[2];
            }
            // right: columns k..k+2 of the block's rows down to the new bulge
            for row in h.iter_mut().take((k + 3).min(n) + 1).skip(lo) {
                let s = (row[k] * u[0] + row[k + 1] * u[1] + row[k + 2] * u[2]) * beta;
                row[k] -= s * u[0];
                row[k + 1] -= s * u[1];
                row[k + 2] -= s * u[2];
            }
        }
        x = [
            h[k + 1][k],
            h[k + 2][k],
            if k + 3 <= n { h[k + 3][k] } else { T::zero() },
        ];
    }
    // the last, 2-element reflector on rows n-1, n
    if let Some((u, beta, alpha)) = reflector(x[0], x[1], T::zero()) {
        h[m][m - 1] = alpha;
        h[n][m - 1] = T::zero();
        for j in m..=n {
            let s = (u[0] * h[m][j] + u[1] * h[n][j]) * beta;
            h[m][j] -= s * u[0];
            h[n][j] -= s * u[1];
        }
        for row in h.iter_mut().take(n + 1).skip(lo) {
            let s = (row[m] * u[0] + row[n] * u[1]) * beta;
            row[m] -= s * u[0];
            row[n] -= s * u[1];
        }
    }
}

/// The eigenvalues of [[a, b], [c, d]]: a real pair without cancellation, or a complex pair
/// with +Im first.
fn two_by_two<T: RealField + Copy + Sqrt>(a: T, b: T, c: T, d: T) -> (Complex<T>, Complex<T>) {
    let half: T = nalgebra::convert(0.5);
    let p = half * (a - d);
    let disc = p * p + b * c;
    if disc >= T::zero() {
        let r = disc.sqrt_rounded();
        let z = if p >= T::zero() { p + r } else { p - r };
        let second = if z == T::zero() { d } else { d - b * c / z };
        (
            Complex::new(d + z, T::zero()),
            Complex::new(second, T::zero()),
        )
    } else {
        let im = (-disc).sqrt_rounded();
        (Complex::new(d + p, im), Complex::new(d + p, -im))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vehicles::car::PlantParams;
    use crate::vehicles::car::{linearise, N_STATES};

    type StateMatrix = nalgebra::SMatrix<f64, N_STATES, N_STATES>;

    fn arrays(a: &StateMatrix) -> [[f64; N_STATES]; N_STATES] {
        core::array::from_fn(|i| core::array::from_fn(|j| a[(i, j)]))
    }

    /// Sorted by (re, im) for comparing sets.
    fn sorted(mut v: Vec<Complex<f64>>) -> Vec<Complex<f64>> {
        v.sort_by(|a, b| a.re.total_cmp(&b.re).then(a.im.total_cmp(&b.im)));
        v
    }

    /// nalgebra's Schur (the solver this replaces), as the independent reference.
    fn reference(a: &StateMatrix) -> Vec<Complex<f64>> {
        let s = nalgebra::linalg::Schur::try_new(*a, f64::EPSILON, 10_000).expect("schur");
        sorted(s.complex_eigenvalues().iter().copied().collect())
    }

    /// Each wanted eigenvalue has its own computed one within `rel` of the spectral radius
    /// (matched nearest first, each used once).
    fn assert_close(got: &[Complex<f64>], want: &[Complex<f64>], rel: f64, what: &str) {
        assert_eq!(got.len(), want.len());
        let scale = want.iter().map(|c| c.norm()).fold(1.0, f64::max);
        let mut left: Vec<Complex<f64>> = got.to_vec();
        for w in want {
            let (i, d) = left
                .iter()
                .enumerate()
                .map(|(i, g)| (i, (g - w).norm()))
                .min_by(|a, b| a.1.total_cmp(&b.1))
                .expect("one left");
            assert!(d <= rel * scale, "{what}: {w} has no match ({left:?})");
            left.swap_remove(i);
        }
    }

    #[test]
    fn the_plant_across_speeds_matches_nalgebras_schur() {
        let p = PlantParams::nominal();
        for v in [0.5, 3.0, 8.15, 12.0, 23.4, 40.0, 60.0] {
            for c in [0.0, 400.0] {
                let a = linearise(&p, v, c);
                let got = eigenvalues::<f64, N_STATES>(arrays(&a), f64::EPSILON, 300).expect("ok");
                assert_close(&sorted(got.to_vec()), &reference(&a), 1e-10, "plant");
            }
        }
    }

    #[test]
    fn random_matrices_match_nalgebras_schur_and_pairs_are_plus_im_first() {
        let mut seed = 12345u64;
        let mut next = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((seed >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
        };
        for _ in 0..200 {
            let a = StateMatrix::from_fn(|_, _| next() * 10.0);
            let got = eigenvalues::<f64, N_STATES>(arrays(&a), f64::EPSILON, 300).expect("ok");
            for w in got.windows(2) {
                if w[0].im > 0.0 {
                    assert_eq!(w[1], w[0].conj(), "pair order");
                }
            }
            assert_close(&sorted(got.to_vec()), &reference(&a), 1e-9, "random");
        }
    }

    #[test]
    fn known_spectra_zero_and_huge_entries() {
        // companion matrix of (s + 1)(s + 2)(s^2 + 2 s + 5): -1, -2, -1 +- 2j
        let mut c = [[0.0f64; 4]; 4];
        let coef = [10.0, 19.0, 13.0, 5.0]; // s^4 + 5 s^3 + 13 s^2 + 19 s + 10
        for (j, k) in coef.iter().rev().enumerate() {
            c[0][j] = -k;
        }
        for i in 1..4 {
            c[i][i - 1] = 1.0;
        }
        let got = sorted(
            eigenvalues::<f64, 4>(c, f64::EPSILON, 100)
                .expect("ok")
                .to_vec(),
        );
        let want = sorted(vec![
            Complex::new(-2.0, 0.0),
            Complex::new(-1.0, -2.0),
            Complex::new(-1.0, 0.0),
            Complex::new(-1.0, 2.0),
        ]);
        assert_close(&got, &want, 1e-12, "companion");
        // f32 on the same matrix
        let c32 = c.map(|r| r.map(|x| x as f32));
        let got32 = eigenvalues::<f32, 4>(c32, f32::EPSILON, 100).expect("ok");
        let got32 = sorted(
            got32
                .iter()
                .map(|z| Complex::new(f64::from(z.re), f64::from(z.im)))
                .collect(),
        );
        assert_close(&got32, &want, 1e-5, "companion f32");
        assert_eq!(
            eigenvalues::<f64, 3>([[0.0; 3]; 3], f64::EPSILON, 10).expect("ok"),
            [Complex::new(0.0, 0.0); 3]
        );
        // entries near the f32 range: the power-of-two scaling keeps the squares finite
        let big = c32.map(|r| r.map(|x| x * 1e28));
        let got_big = eigenvalues::<f32, 4>(big, f32::EPSILON, 100).expect("ok");
        assert!(got_big.iter().all(|z| z.re.is_finite() && z.im.is_finite()));
    }

    #[test]
    fn the_sweep_bound_is_an_error_not_a_hang() {
        let a = linearise(&PlantParams::nominal(), 8.0, 0.0);
        assert_eq!(
            eigenvalues::<f64, N_STATES>(arrays(&a), f64::EPSILON, 1),
            None
        );
    }
}
