//! The bounded Hessenberg QR eigen-solver of `shimmy_core::eigen` against an independent
//! solver (nalgebra's dense real Schur decomposition, unbalanced, with its own Householder
//! reduction and Francis steps: no code in common with the core's solver) on A(V) of every
//! named parameter set, 1..150 km/h. [`reference_eigenvalues`] is the reference solve of the
//! other cross-crate checks of the model margin too.
use nalgebra::Complex;
use shimmy_core::eigen;
use shimmy_core::units::kmh_to_mps;
use shimmy_core::vehicles::car::{linearise, N_STATES};
use shimmy_core::vehicles::car::{ParamSet, PlantParams};

/// The eigenvalues of A(V, c) from nalgebra's Schur decomposition of the matrix as it is.
pub fn reference_eigenvalues(p: &PlantParams, v_mps: f64, c: f64) -> Vec<Complex<f64>> {
    let a = linearise(p, v_mps, c);
    let theirs: Vec<Complex<f64>> = a.complex_eigenvalues().iter().copied().collect();
    assert_eq!(theirs.len(), N_STATES);
    theirs
}

fn ab(c: Complex<f64>) -> f64 {
    c.re.hypot(c.im)
}

/// Worst relative error over the speed grid, matching each of our eigenvalues to the nearest
/// unused reference eigenvalue (greedy; the spectra here are well separated).
fn worst_relative_error(set: ParamSet, c_damper: f64) -> (f64, f64) {
    let p = set.params();
    let mut worst = (0.0, 0.0);
    for kmh10 in 10..=1500 {
        let kmh = kmh10 as f64 / 10.0;
        let a = linearise(&p, kmh_to_mps(kmh), c_damper);
        let ours = eigen::eigenvalues(&a).expect("bounded solver converges on A(V)");
        let theirs = reference_eigenvalues(&p, kmh_to_mps(kmh), c_damper);
        let mut used = [false; N_STATES];
        for l in ours {
            let (j, d) = theirs
                .iter()
                .enumerate()
                .filter(|(j, _)| !used[*j])
                .map(|(j, t)| (j, ab(*t - l)))
                .min_by(|x, y| x.1.total_cmp(&y.1))
                .expect("an unused eigenvalue");
            used[j] = true;
            let rel = d / ab(l).max(1.0);
            if rel > worst.0 {
                worst = (rel, kmh);
            }
        }
    }
    worst
}

#[test]
fn eigenvalues_agree_with_nalgebras_schur_for_every_named_set() {
    // Tolerance 1e-9 relative to max(|lambda|, 1 s^-1): both solvers are backward stable
    // (error ~ eps ||A|| cond); ||A|| ~ 5e4 after balancing is much smaller, and the spectra
    // are well conditioned away from V = 0, so ~1e-12 is expected; 1e-9 leaves margin but
    // still catches any real disagreement (a wrong pair, a missed conjugate, a sign).
    for set in ParamSet::ALL {
        for c in [0.0, 2000.0] {
            let (worst, at) = worst_relative_error(set, c);
            println!(
                "{} c={c}: worst relative error {worst:.2e} at {at} km/h",
                set.name()
            );
            assert!(worst < 1e-9, "{} c={c}: {worst:e} at {at} km/h", set.name());
        }
    }
}
