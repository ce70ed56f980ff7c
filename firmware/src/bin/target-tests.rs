//! On-target test harness: runs each test on the Cortex-M4F (under QEMU in CI), logs each
//! result with defmt and exits through semihosting. A failing assertion panics, the panic
//! handler logs it and exits non-zero, so the run fails.
//!
//! Expected values are the same as in the host tests of `shimmy-core`, so a difference between
//! the host and the target (soft-float f64, libm) shows up here.
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
mod harness {
    use shimmy_core::params::{Param, ParamSet, PlantParams};
    use shimmy_firmware::runtime::{finish, Outcome};

    struct Test {
        name: &'static str,
        run: fn(),
    }

    const TESTS: &[Test] = &[
        Test {
            name: "params::named_sets",
            run: named_sets,
        },
        Test {
            name: "params::tyre_slope",
            run: tyre_slope,
        },
        Test {
            name: "params::validation",
            run: validation,
        },
        #[cfg(feature = "deliberate-failure")]
        Test {
            name: "harness::deliberate_failure",
            run: deliberate_failure,
        },
    ];

    fn named_sets() {
        let g = ParamSet::Gentle.params();
        let h = ParamSet::Hard.params();
        assert_eq!(g.c_sw, 2.0);
        assert_eq!(h.k_d, 0.5e4);
        assert!((PlantParams::nominal().k_tr - 194_045.0).abs() < 1.0);
    }

    fn tyre_slope() {
        let p = PlantParams::nominal();
        let slope = p.tyre_peak_force() * p.c_s * p.tyre_stiffness_factor();
        assert!((slope - p.c_a).abs() < 1e-9 * p.c_a);
    }

    fn validation() {
        let bad = PlantParams::nominal().with(Param::Sigma, -0.1);
        assert!(bad.validate() == Err((Param::Sigma, -0.1)));
        assert!(ParamSet::Hard.params().validate().is_ok());
    }

    #[cfg(feature = "deliberate-failure")]
    fn deliberate_failure() {
        let two = core::hint::black_box(1) + 1;
        assert_eq!(
            two, 3,
            "deliberate failure: proves that a failing assertion fails the run"
        );
    }

    #[cortex_m_rt::entry]
    fn main() -> ! {
        defmt::info!("running {=usize} on-target tests", TESTS.len());
        for t in TESTS {
            (t.run)();
            defmt::info!("test {=str} ... ok", t.name);
        }
        defmt::info!("target: {=usize} passed, 0 failed", TESTS.len());
        finish(Outcome::Success)
    }
}

#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!("target-tests runs on the Cortex-M4F: use `cargo xtask test` (QEMU).");
    std::process::exit(2);
}
