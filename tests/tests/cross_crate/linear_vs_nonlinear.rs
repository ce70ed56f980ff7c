//! The core's analytic linearisation A(V) (what the firmware's margin estimator uses) against
//! the simulator's nonlinear right-hand side differentiated numerically (central differences),
//! for every named set over the speed range. Two independent derivations of the same model.
use shimmy_core::units::kmh_to_mps;
use shimmy_core::vehicles::car::ParamSet;

#[test]
fn analytic_a_of_v_equals_the_jacobian_of_the_nonlinear_plant() {
    for set in ParamSet::ALL {
        let p = set.params();
        for v_kmh in [0.5, 10.0, 29.35, 55.0, 84.15, 130.0] {
            let v = kmh_to_mps(v_kmh);
            let a = shimmy_core::vehicles::car::linearise(&p, v, 0.0);
            let j = shimmy_sim::model::plant::jacobian_fd(&p, v);
            for r in 0..10 {
                for c in 0..10 {
                    // Central differences with h = 1e-7: truncation ~h^2 |f'''|, rounding
                    // ~eps |f| / h; 1e-6 of the entry scale covers both for these magnitudes.
                    let scale = a[(r, c)].abs().max(1.0);
                    let diff = (a[(r, c)] - j[(r, c)]).abs();
                    assert!(
                        diff <= 1e-6 * scale.max(1e3),
                        "{} at {v_kmh} km/h: A[{r},{c}] = {} vs FD {}",
                        set.name(),
                        a[(r, c)],
                        j[(r, c)]
                    );
                }
            }
        }
    }
}
