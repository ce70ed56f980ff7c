//! On-target test harness: runs each test on the Cortex-M4F (under QEMU in CI), logs each
//! result with defmt and exits through semihosting. A failing assertion panics, the panic
//! handler logs it and exits non-zero, so the run fails.
//!
//! Expected values are the same as in the host tests of `shimmy-core`, so a difference between
//! the host and the target (soft-float f64, libm) shows up here.
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
mod harness {
    use shimmy_core::vehicles::car::{Param, ParamSet, PlantParams};
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
        Test {
            name: "as5047p::command_frames",
            run: as5047p_frames,
        },
        Test {
            name: "as5047p::unwrap_across_wrap",
            run: as5047p_unwrap,
        },
        Test {
            name: "wheel_speed::period_timeout_jump",
            run: wheel_speed,
        },
        Test {
            name: "coil::shunt_scaling_pwm_clamp_and_current_loop",
            run: coil,
        },
        Test {
            name: "sim::closed_loop_faults_counted",
            run: closed_loop,
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

    // Driver logic, the same cases as the host tests (which use embedded-hal-mock): a
    // difference between host and target arithmetic shows up here.

    fn as5047p_frames() {
        use shimmy_firmware::drivers::as5047p::{decode_response, read_command, Error};
        assert_eq!(read_command(0x3FFF), 0xFFFF);
        assert_eq!(read_command(0x0000), 0xC000);
        assert_eq!(read_command(0x0001), 0x4001);
        // 0x3039 (12345) has 6 ones: parity 0; flipping a bit breaks it.
        assert_eq!(decode_response::<()>(0x3039), Ok((false, 12345)));
        assert_eq!(
            decode_response::<()>(0x3038),
            Err(Error::Parity { frame: 0x3038 })
        );
    }

    fn as5047p_unwrap() {
        use core::f32::consts::PI;
        use shimmy_firmware::drivers::as5047p::AngleTracker;
        let mut t = AngleTracker::new(16380, 100);
        for (raw, counts) in [(16380u16, 0i32), (16383, 3), (2, 6), (50, 54), (16370, -10)] {
            let a = t.update(raw).unwrap_or(f32::NAN);
            assert!((a - counts as f32 * 2.0 * PI / 16384.0).abs() < 1e-6);
        }
        assert!(t.update(16370 - 200).is_err());
    }

    fn wheel_speed() {
        use shimmy_firmware::drivers::wheel_speed::{PulseSample, SpeedStatus, WheelSpeed};
        use shimmy_firmware::sim::SPEED_CONFIG;
        let mut w = WheelSpeed::new(SPEED_CONFIG);
        let r = w.update(
            PulseSample {
                new_period_ticks: Some(2291),
                ticks_since_edge: 0,
            },
            1000,
        );
        assert!((r.speed_mps - 20.0).abs() < 0.01);
        let r = w.update(
            PulseSample {
                new_period_ticks: Some(1145),
                ticks_since_edge: 0,
            },
            1000,
        );
        assert!(r.status == SpeedStatus::Implausible);
        let r = w.update(
            PulseSample {
                new_period_ticks: None,
                ticks_since_edge: 600_000,
            },
            1000,
        );
        assert!(r.status == SpeedStatus::Standstill && r.speed_mps == 0.0);
    }

    fn coil() {
        use shimmy_firmware::drivers::coil_pwm::{CoilDriver, FAILSAFE_CURRENT_A};
        use shimmy_firmware::sim::{coil_current_after, SimCoil, SimPwm, SimWorld, COIL, SHUNT};
        static WORLD: SimWorld = SimWorld::new();
        let Ok(mut d) = CoilDriver::new(SimPwm::new(&WORLD), COIL);
        assert!(d.commanded_a() == FAILSAFE_CURRENT_A);
        let _ = d.set_current_a(7.0, None, 1e-3);
        assert!(d.commanded_a() == COIL.max_current_a);
        let _ = d.set_current_a(f32::NAN, None, 1e-3);
        assert!(d.commanded_a() == FAILSAFE_CURRENT_A);
        // Closed current loop: 2 A into a hot coil (+50 % R) within 2 %, where open loop
        // gives 1.33 A.
        static HOT: SimWorld = SimWorld::new();
        let hot = SimCoil {
            r_ohm: 1.5 * COIL.coil_ohm,
            ..SimCoil::NOMINAL
        };
        let closed = coil_current_after(&HOT, hot, true, 300);
        let open = coil_current_after(&HOT, hot, false, 300);
        assert!((closed - 2.0).abs() < 0.04);
        assert!((open - 4.0 / 3.0).abs() < 0.02);
        // 1 A = 0.75 V at the ADC = 931 counts of 3.3 V / 4096.
        assert!((SHUNT.amps_per_count() * 931.0 - 1.0).abs() < 1e-3);
        // The ADC range covers the coil's maximum current.
        assert!(SHUNT.amps_per_count() * (4095.0 - SHUNT.offset_counts) > COIL.max_current_a);
    }

    fn closed_loop() {
        use shimmy_firmware::monitoring::safe_controller;
        use shimmy_firmware::sim::{
            expected_faults, run_closed_loop, SimWorld, EXPECTED_FAILSAFE_STEPS,
            EXPECTED_FAULTS_RAISED, SCENARIO_STEPS,
        };
        static WORLD: SimWorld = SimWorld::new();
        let mut c = safe_controller();
        let h = run_closed_loop(&WORLD, &mut c, SCENARIO_STEPS);
        let (par, ef, glitch) = expected_faults(SCENARIO_STEPS);
        assert!((h.enc_parity, h.enc_error_flag, h.speed_implausible) == (par, ef, glitch));
        assert!(h.failsafe_steps == EXPECTED_FAILSAFE_STEPS && h.steps == SCENARIO_STEPS);
        assert!(h.faults_raised == EXPECTED_FAULTS_RAISED && h.active_faults == 0);
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
