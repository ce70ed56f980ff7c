//! Supervisor and SafeController tests: one scenario per check (each also shows the healthy
//! counterpart raises nothing), hysteresis, latches, and property tests over arbitrary input.

use super::checks::*;
use super::faults::*;
use super::frame::*;
use super::params::*;
use super::policy::*;
use super::safe_controller::*;
use crate::control::actuator::FAILSAFE_CURRENT_A;
use crate::control::{ControlInput, ControlParams, Controller, ControllerKind};
use proptest::prelude::*;

const I_MAX: f32 = 2.0;

/// A valid margin report far from the Hopf window.
const VALID_FAR: MarginStatus = MarginStatus::Valid(crate::control::schedule::MarginSignal {
    speed_margin_mps: 10.0,
    time_to_critical_s: f32::INFINITY,
    zeta_fast: 0.05,
});

fn safe() -> SafeController {
    safe_with(SupervisorParams::default())
}

fn safe_with(p: SupervisorParams) -> SafeController {
    SafeController::new(ControllerKind::Asmc, ControlParams::default(), p)
}

/// Encoders without noise: a healthy one may hold a value for long, so only the other
/// encoder's motion can prove a freeze (the synthetic frames here are noise-free too).
fn quiet_encoders() -> SupervisorParams {
    SupervisorParams {
        encoder_noise_lsb: 0.0,
        ..SupervisorParams::default()
    }
}

/// Shimmy-like in-phase yaw: 7 deg at 7 Hz plus a tiny anti-phase part (track-rod compliance).
fn yaw(k: u32) -> (f32, f32) {
    let t = k as f32 * 1e-3;
    let a = 7f32.to_radians() * libm::sinf(2.0 * core::f32::consts::PI * 7.0 * t);
    let d = 2e-4 * libm::sinf(2.0 * core::f32::consts::PI * 47.0 * t);
    (a + d, a - d)
}

fn frame(k: u32, speed: f32) -> RawFrame {
    let (l, r) = yaw(k);
    RawFrame::ok(k * NOMINAL_PERIOD_US, l, r, speed)
}

/// Runs `n` frames from `k0` through `f` (which may corrupt them); returns the last output.
fn run(
    s: &mut SafeController,
    k0: u32,
    n: u32,
    mut f: impl FnMut(u32, RawFrame) -> RawFrame,
) -> SafeOutput {
    let mut out = SafeOutput::default();
    for k in k0..k0 + n {
        out = s.step(&f(k, frame(k, 20.0)), MarginStatus::NotUsed);
        assert!(out.current_cmd_a.is_finite() && (0.0..=I_MAX).contains(&out.current_cmd_a));
    }
    out
}

#[test]
fn healthy_shimmy_raises_nothing_and_is_transparent() {
    // 7 deg at 7 Hz is above the no-damper limit cycle of the reference plant: a large healthy
    // signal. The supervised command equals the bare controller's.
    let mut s = safe();
    let mut bare = Controller::new(ControllerKind::Asmc, ControlParams::default());
    for k in 0..3000 {
        let f = frame(k, 20.0);
        let o = s.step(&f, VALID_FAR);
        let b = bare.step(&ControlInput {
            t_s: k as f32 * 1e-3,
            dt_s: 1e-3,
            psi_l_rad: f.left.angle_rad,
            psi_r_rad: f.right.angle_rad,
            speed_mps: 20.0,
            coil_current_a: None,
        });
        assert_eq!(o.verdict.mode, Mode::Normal, "k={k} {:?}", o.verdict);
        assert!(o.verdict.faults.is_empty());
        assert_eq!(o.current_cmd_a, b.current_cmd_a, "k={k}");
    }
    assert_eq!(s.supervisor().missed_samples(), 0);
}

#[test]
fn one_encoder_nan_degrades_to_the_other_with_a_floor() {
    let mut s = safe();
    run(&mut s, 0, 500, |_, f| f);
    let o = run(&mut s, 500, 10, |_, mut f| {
        f.left.angle_rad = f32::NAN;
        f
    });
    assert!(o.verdict.faults.contains(FaultKind::LeftNonFinite));
    assert_eq!(o.verdict.mode, Mode::Degraded);
    assert_eq!(o.verdict.safe_current_a, Some(FAILSAFE_CURRENT_A));
    let (l, r) = o.validated.angles_rad.expect("right stands in");
    assert_eq!(l, r);
    assert_eq!(r, yaw(509).1);
    assert!(o.current_cmd_a >= FAILSAFE_CURRENT_A.min(I_MAX) - 1e-6);
    assert!(o.control.is_some());
}

#[test]
fn both_encoders_lost_is_failsafe_and_zero_current_at_walking_pace() {
    let mut s = safe();
    run(&mut s, 0, 100, |_, f| f);
    let o = run(&mut s, 100, 5, |_, mut f| {
        f.left.read_ok = false;
        f.right.parity_ok = false;
        f
    });
    assert_eq!(o.verdict.mode, Mode::FailSafe);
    assert!(o.verdict.faults.contains(FaultKind::LeftRead));
    assert!(o.verdict.faults.contains(FaultKind::RightFlag));
    assert_eq!(o.current_cmd_a, FAILSAFE_CURRENT_A);
    assert!(o.control.is_none());
    // Same at a trusted 0.3 m/s: 0 A.
    let mut s = safe();
    let mut o = SafeOutput::default();
    for k in 0..100 {
        let mut f = frame(k, 0.3);
        if k >= 50 {
            f.left.error_flag = true;
            f.right.angle_rad = f32::INFINITY;
        }
        o = s.step(&f, MarginStatus::NotUsed);
    }
    assert_eq!(o.verdict.mode, Mode::FailSafe);
    assert_eq!(o.verdict.safe_current_a, Some(0.0));
    assert_eq!(o.current_cmd_a, 0.0);
}

#[test]
fn rate_check_catches_a_bit_flip_but_not_shimmy() {
    let mut s = safe();
    let o = run(&mut s, 0, 1000, |_, f| f);
    assert!(o.verdict.faults.is_empty());
    // 14-bit encoder, bit 12 flipped: + 2 pi / 4 rad... scaled to the limit: +0.3 rad.
    let o = run(&mut s, 1000, 1, |_, mut f| {
        f.right.angle_rad += 0.3;
        f
    });
    assert!(o.verdict.detected.contains(FaultKind::RightRate));
    assert!(!o.verdict.detected.contains(FaultKind::RightRange));
    // The next good sample is accepted again (rate reference was not moved by the bad one).
    let o = run(&mut s, 1001, 1, |_, f| f);
    assert!(o.verdict.detected.is_empty());
    assert!(
        o.verdict.faults.contains(FaultKind::RightRate),
        "hysteresis"
    );
}

#[test]
fn range_check() {
    let mut s = safe();
    let o = run(&mut s, 0, 2, |_, mut f| {
        f.left.angle_rad = 0.9;
        f
    });
    assert!(o.verdict.detected.contains(FaultKind::LeftRange));
}

#[test]
fn stuck_encoder_needs_the_other_to_move() {
    // Left frozen while the right follows shimmy: stuck after 100 samples.
    let mut s = safe_with(quiet_encoders());
    let frozen = yaw(0).0;
    let o = run(&mut s, 0, 99, |_, mut f| {
        f.left.angle_rad = frozen;
        f
    });
    assert!(!o.verdict.faults.contains(FaultKind::LeftStuck));
    let o = run(&mut s, 99, 30, |_, mut f| {
        f.left.angle_rad = frozen;
        f
    });
    assert!(o.verdict.faults.contains(FaultKind::LeftStuck));
    assert_eq!(o.verdict.mode, Mode::Degraded);
    // Smooth straight road: both constant and identical for 1.5 s at 20 m/s: no fault at all.
    let mut s = safe_with(quiet_encoders());
    let o = run(&mut s, 0, 1500, |_, mut f| {
        f.left.angle_rad = 0.001;
        f.right.angle_rad = 0.001;
        f
    });
    assert!(o.verdict.faults.is_empty(), "{:?}", o.verdict);
    assert_eq!(o.verdict.mode, Mode::Normal);
    // ... but after 2 s it is suspected: Degraded with the floor (safe, never FailSafe).
    let o = run(&mut s, 1500, 600, |_, mut f| {
        f.left.angle_rad = 0.001;
        f.right.angle_rad = 0.001;
        f
    });
    assert!(o.verdict.faults.contains(FaultKind::BothStuckSuspect));
    assert_eq!(o.verdict.mode, Mode::Degraded);
    assert_eq!(o.verdict.safe_current_a, Some(FAILSAFE_CURRENT_A));
    // Standing still: never suspected.
    let mut s = safe_with(quiet_encoders());
    for k in 0..5000 {
        let o = s.step(
            &RawFrame::ok(k * NOMINAL_PERIOD_US, 0.001, 0.001, 0.0),
            MarginStatus::NotUsed,
        );
        assert!(o.verdict.faults.is_empty());
    }
}

#[test]
fn disagreeing_encoders_are_failsafe() {
    let mut s = safe();
    let o = run(&mut s, 0, 1, |_, mut f| {
        f.left.angle_rad = 0.2;
        f.right.angle_rad = -0.2;
        f
    });
    assert!(o.verdict.faults.contains(FaultKind::EncoderDisagree));
    assert_eq!(o.verdict.mode, Mode::FailSafe);
}

#[test]
fn speed_checks() {
    type Corrupt = fn(&mut RawFrame);
    let cases: [(Corrupt, FaultKind); 5] = [
        (|f| f.speed_valid = false, FaultKind::SpeedInvalid),
        (|f| f.speed_mps = f32::NAN, FaultKind::SpeedInvalid),
        (|f| f.speed_mps = -3.0, FaultKind::SpeedInvalid),
        (|f| f.speed_mps = 90.0, FaultKind::SpeedInvalid),
        (|f| f.speed_mps = 25.0, FaultKind::SpeedJump),
    ];
    for (corrupt, kind) in cases {
        let mut s = safe();
        run(&mut s, 0, 100, |_, f| f);
        let o = run(&mut s, 100, 1, |_, mut f| {
            corrupt(&mut f);
            f
        });
        assert!(
            o.verdict.detected.contains(kind),
            "{kind:?}: {:?}",
            o.verdict
        );
        // The last trusted speed is held: Degraded, the controller runs on 20 m/s, no floor.
        assert_eq!(o.verdict.mode, Mode::Degraded);
        assert_eq!(o.verdict.safe_current_a, None);
        assert_eq!(o.validated.speed_mps, Some(20.0));
        assert!(o.control.is_some_and(|c| !c.flags.below_speed));
        if kind == FaultKind::SpeedInvalid {
            // Held for `speed_hold_s` (1 s), then unknown: the fail-safe current as a floor.
            let o = run(&mut s, 101, 999, |_, mut f| {
                corrupt(&mut f);
                f
            });
            assert_eq!(o.validated.speed_mps, Some(20.0));
            let o = run(&mut s, 1100, 1, |_, mut f| {
                corrupt(&mut f);
                f
            });
            assert_eq!(o.validated.speed_mps, None);
            assert_eq!(o.verdict.mode, Mode::Degraded);
            assert_eq!(o.verdict.safe_current_a, Some(FAILSAFE_CURRENT_A));
            assert!(o.current_cmd_a >= FAILSAFE_CURRENT_A - 1e-6);
        }
    }
    // A hard brake (1 g) is not a jump.
    let mut s = safe();
    for k in 0..2000u32 {
        let v = 30.0 - 9.81 * k as f32 * 1e-3;
        let (l, r) = yaw(k);
        let o = s.step(&RawFrame::ok(k * 1000, l, r, v), MarginStatus::NotUsed);
        assert!(o.verdict.faults.is_empty(), "k={k}");
    }
}

/// Runs frames `k0..k0 + n` with speed `v(k)` (shimmy-like yaw), returns the last output.
fn run_speed(s: &mut SafeController, k0: u32, n: u32, v: impl Fn(u32) -> f32) -> SafeOutput {
    run(s, k0, n, |k, mut f| {
        f.speed_mps = v(k);
        f
    })
}

const LOW: FaultKind = FaultKind::SpeedLowImplausible;

/// Lost pulse train (the decoder's valid 0 m/s standstill) at 12.5 m/s: raised at once, the
/// last trusted speed held for 1 s (controller running, not gated), then the 2 A floor; time
/// alone never makes the standstill plausible; the speed coming back clears it after the
/// recovery time.
#[test]
fn lost_speed_is_held_then_floored_and_recovers() {
    let mut s = safe();
    run_speed(&mut s, 0, 500, |_| 12.5);
    let o = run_speed(&mut s, 500, 1, |_| 0.0);
    assert!(o.verdict.detected.contains(LOW), "{:?}", o.verdict);
    assert_eq!(o.verdict.mode, Mode::Degraded);
    assert_eq!(o.verdict.safe_current_a, None);
    assert_eq!(o.validated.speed_mps, Some(12.5));
    assert!(o.control.is_some_and(|c| !c.flags.below_speed));
    // Held up to 1 s after the last trusted reading (frame 499), then unknown + floor.
    let o = run_speed(&mut s, 501, 999, |_| 0.0);
    assert_eq!(o.validated.speed_mps, Some(12.5));
    assert_eq!(o.verdict.safe_current_a, None);
    let o = run_speed(&mut s, 1500, 1, |_| 0.0);
    assert_eq!(o.validated.speed_mps, None);
    assert_eq!(o.verdict.safe_current_a, Some(FAILSAFE_CURRENT_A));
    assert!(o.current_cmd_a >= FAILSAFE_CURRENT_A - 1e-6);
    // 10 s later: still not trusted (the envelope reached 0 long ago, SpeedJump healed).
    let o = run_speed(&mut s, 1501, 9_999, |_| 0.0);
    assert!(o.verdict.detected.contains(LOW));
    assert!(!o.verdict.faults.contains(FaultKind::SpeedJump));
    assert_eq!(o.verdict.mode, Mode::Degraded);
    assert_eq!(o.verdict.safe_current_a, Some(FAILSAFE_CURRENT_A));
    // The speed comes back (12 m/s): no longer detected at once, cleared after the recovery
    // time (and the SpeedJump from 0 to 12 m/s, 0.8 s + 1 s), Normal again.
    let o = run_speed(&mut s, 11_500, 1, |_| 12.0);
    assert!(!o.verdict.detected.contains(LOW));
    assert!(o.verdict.faults.contains(LOW));
    let o = run_speed(&mut s, 11_501, 2000, |_| 12.0);
    assert!(o.verdict.faults.is_empty(), "{:?}", o.verdict);
    assert_eq!(o.verdict.mode, Mode::Normal);
    assert_eq!(o.validated.speed_mps, Some(12.0));
}

/// The deceleration bound: braking at 14 m/s^2 (below the 15 m/s^2 bound) to standstill is
/// trusted, and the standstill then allows 0 A in FailSafe; at 20 m/s^2 the reading is below
/// the 2 m/s gate after 525 ms, when the envelope is at 12.5 - 15 x 0.525 = 4.6 m/s: caught
/// there (not before: above the gate a fast drop is only `SpeedJump`'s business), and it stays
/// caught at standstill.
#[test]
fn low_speed_is_trusted_only_within_the_deceleration_bound() {
    let brake = |a: f32| move |k: u32| (12.5 - a * (k.saturating_sub(500)) as f32 * 1e-3).max(0.0);
    // The shimmy lives inside the Hopf window (from 8 m/s on, full at 12.5 m/s); quiet
    // encoders, so a wheel at rest is not a frozen one.
    let run_speed = |s: &mut SafeController, k0: u32, n: u32, v: &dyn Fn(u32) -> f32| {
        run(s, k0, n, |k, mut f| {
            f.speed_mps = v(k);
            let shimmy = ((f.speed_mps - 8.0) / 4.5).clamp(0.0, 1.0);
            f.left.angle_rad *= shimmy;
            f.right.angle_rad *= shimmy;
            f
        })
    };
    let mut s = safe_with(quiet_encoders());
    run_speed(&mut s, 0, 500, &|_| 12.5);
    let o = run_speed(&mut s, 500, 2000, &brake(14.0));
    assert!(o.verdict.faults.is_empty(), "{:?}", o.verdict);
    assert_eq!(o.validated.speed_mps, Some(0.0));
    assert_eq!(s.supervisor().record(LOW).frames, 0);
    // Trusted standstill: both encoders lost gives 0 A.
    let o = run(&mut s, 2500, 10, |_, mut f| {
        f.speed_mps = 0.0;
        f.left.angle_rad = f32::NAN;
        f.right.angle_rad = f32::NAN;
        f
    });
    assert_eq!(o.verdict.mode, Mode::FailSafe);
    assert_eq!(o.verdict.safe_current_a, Some(0.0));

    let mut s = safe_with(quiet_encoders());
    run_speed(&mut s, 0, 500, &|_| 12.5);
    let o = run_speed(&mut s, 500, 525, &brake(20.0));
    assert!(!o.verdict.faults.contains(LOW));
    let o = run_speed(&mut s, 1025, 2, &brake(20.0));
    assert!(o.verdict.detected.contains(LOW));
    let o = run_speed(&mut s, 1027, 3000, &brake(20.0));
    assert!(o.verdict.detected.contains(LOW));
    assert_eq!(o.verdict.safe_current_a, Some(FAILSAFE_CURRENT_A));
}

/// A speed frozen at a plausible low value (6 km/h) while driving 45 km/h: caught at once,
/// and a frozen value is never trusted; with both encoders lost as well the fail-safe current
/// is 2 A, not the 0 A of a trusted low speed.
#[test]
fn frozen_low_speed_never_allows_zero_current() {
    let mut s = safe();
    run_speed(&mut s, 0, 500, |_| 12.5);
    let o = run_speed(&mut s, 500, 1, |_| 6.0 / 3.6);
    assert!(o.verdict.detected.contains(LOW));
    let o = run_speed(&mut s, 501, 5000, |_| 6.0 / 3.6);
    assert!(o.verdict.detected.contains(LOW));
    assert_eq!(o.verdict.safe_current_a, Some(FAILSAFE_CURRENT_A));
    // Lost speed (standstill reading) and both encoders lost: FailSafe at 2 A.
    let mut s = safe();
    run_speed(&mut s, 0, 500, |_| 12.5);
    let o = run(&mut s, 500, 3000, |_, mut f| {
        f.speed_mps = 0.0;
        f.left.angle_rad = f32::NAN;
        f.right.angle_rad = f32::NAN;
        f
    });
    assert_eq!(o.verdict.mode, Mode::FailSafe);
    assert_eq!(o.verdict.safe_current_a, Some(FAILSAFE_CURRENT_A));
    assert_eq!(o.current_cmd_a, FAILSAFE_CURRENT_A);
}

#[test]
fn timing_gap_fails_safe_and_recovers_after_the_hysteresis() {
    let mut s = safe();
    run(&mut s, 0, 100, |_, f| f);
    // 10 samples missing.
    let o = run(&mut s, 110, 1, |_, f| f);
    assert!(o.verdict.detected.contains(FaultKind::Timing));
    assert_eq!(o.verdict.mode, Mode::FailSafe);
    assert_eq!(s.supervisor().missed_samples(), 10);
    // Still fail-safe 0.9 s later, normal after 1 s.
    let o = run(&mut s, 111, 900, |_, f| f);
    assert_eq!(o.verdict.mode, Mode::FailSafe);
    let o = run(&mut s, 1011, 101, |_, f| f);
    assert_eq!(o.verdict.mode, Mode::Normal, "{:?}", o.verdict);
    assert!(o.control.is_some());
    let ev: heapless::Vec<SupervisorEvent, 8> = s.supervisor_mut().drain_events().collect();
    assert!(
        matches!(
            ev.as_slice(),
            [
                SupervisorEvent::Raised {
                    kind: FaultKind::Timing,
                    ..
                },
                SupervisorEvent::ModeChange {
                    to: Mode::FailSafe,
                    ..
                },
                SupervisorEvent::Cleared {
                    kind: FaultKind::Timing,
                    ..
                },
                SupervisorEvent::ModeChange {
                    to: Mode::Normal,
                    ..
                },
            ]
        ),
        "{ev:?}"
    );
    // Without hysteresis the mode would flap: show the recovery time matters.
    let mut p = SupervisorParams {
        recovery_s: 0.0,
        ..SupervisorParams::default()
    };
    p.max_gap_us = 5000;
    let mut s0 = SafeController::new(ControllerKind::Asmc, ControlParams::default(), p);
    run(&mut s0, 0, 10, |_, f| f);
    run(&mut s0, 20, 1, |_, f| f);
    let o = run(&mut s0, 21, 1, |_, f| f);
    assert_eq!(o.verdict.mode, Mode::Normal, "no hysteresis: back at once");
}

#[test]
fn time_stamp_wrap_is_not_a_fault() {
    let mut s = safe();
    let t0 = u32::MAX - 5000;
    for k in 0..20u32 {
        let (l, r) = yaw(k);
        let f = RawFrame::ok(t0.wrapping_add(k * 1000), l, r, 20.0);
        let o = s.step(&f, MarginStatus::NotUsed);
        assert!(o.verdict.faults.is_empty(), "k={k}: {:?}", o.verdict);
    }
    // A repeated stamp is.
    let o = s.step(
        &RawFrame::ok(t0.wrapping_add(19 * 1000), 0.0, 0.0, 20.0),
        MarginStatus::NotUsed,
    );
    assert!(o.verdict.detected.contains(FaultKind::Timing));
}

/// First-order coil: i' = (i_cmd - i) / tau, tau = L/R = 1/190 s.
fn coil(i: &mut f32, cmd: f32) -> f32 {
    *i += (cmd - *i) * (1e-3 * 190.0);
    *i
}

#[test]
fn coil_open_and_short_are_latched_failsafe_at_zero_current() {
    // Healthy coil with its lag: passive-on 0.5 A steps, no fault.
    let mut s = SafeController::new(
        ControllerKind::PassiveOn { current_a: 0.5 },
        ControlParams::default(),
        SupervisorParams::default(),
    );
    let mut i = 0.0;
    for k in 0..500 {
        let mut f = frame(k, 20.0);
        f.coil_current_a = Some(coil(&mut i, s.last_command_a()));
        let o = s.step(&f, MarginStatus::NotUsed);
        assert!(o.verdict.faults.is_empty(), "k={k} {:?}", o.verdict);
    }
    // Open: measured 0.
    for k in 500..600 {
        let mut f = frame(k, 20.0);
        f.coil_current_a = Some(0.0);
        s.step(&f, MarginStatus::NotUsed);
    }
    let mut f = frame(600, 20.0);
    f.coil_current_a = Some(0.0);
    let o = s.step(&f, MarginStatus::NotUsed);
    assert!(o.verdict.faults.contains(FaultKind::CoilOpen));
    assert_eq!(o.verdict.mode, Mode::FailSafe);
    assert!(!o.verdict.damper_available);
    assert_eq!(o.current_cmd_a, 0.0);
    // Latched: 3 s of a healthy coil later it is still there.
    let mut i = 0.0;
    for k in 601..3600 {
        let mut f = frame(k, 20.0);
        f.coil_current_a = Some(coil(&mut i, s.last_command_a()));
        s.step(&f, MarginStatus::NotUsed);
    }
    assert!(s.supervisor().faults().contains(FaultKind::CoilOpen));
    s.supervisor_mut().clear_latched();
    let mut f = frame(3600, 20.0);
    f.coil_current_a = Some(coil(&mut i, s.last_command_a()));
    let o = s.step(&f, MarginStatus::NotUsed);
    assert_eq!(o.verdict.mode, Mode::Normal);
    // Short: the ADC saturated at 2.5 A while commanding 0.5 A (more than three times what
    // the drive pushes through the coil).
    for k in 3601..3700 {
        let mut f = frame(k, 20.0);
        f.coil_current_a = Some(2.5);
        s.step(&f, MarginStatus::NotUsed);
    }
    assert!(s.supervisor().faults().contains(FaultKind::CoilShort));
    assert_eq!(s.last_command_a(), 0.0);
    assert_eq!(s.supervisor().record(FaultKind::CoilShort).activations, 1);
}

#[test]
fn margin_unavailable_is_advisory() {
    let mut s = safe();
    let mut o = SafeOutput::default();
    for k in 0..10_001 {
        o = s.step(&frame(k, 20.0), MarginStatus::Invalid);
    }
    assert!(o.verdict.faults.contains(FaultKind::MarginUnavailable));
    assert_eq!(o.verdict.mode, Mode::Degraded);
    assert_eq!(o.verdict.safe_current_a, None);
}

#[test]
fn event_log_drops_oldest() {
    // Recurrence escalation off (a window of 0 s): every parity error is a new activation.
    let mut s = SafeController::new(
        ControllerKind::Asmc,
        ControlParams::default(),
        SupervisorParams {
            intermittent_window_s: 0.0,
            ..SupervisorParams::default()
        },
    );
    // Alternate a parity error and 1.1 s of health: raise/clear/mode events.
    let mut k = 0;
    for _ in 0..20 {
        run(&mut s, k, 1, |_, mut f| {
            f.left.parity_ok = false;
            f
        });
        run(&mut s, k + 1, 1100, |_, f| f);
        k += 1101;
    }
    assert_eq!(s.supervisor().events().count(), EVENT_CAPACITY);
    assert_eq!(s.supervisor().dropped_events(), 80 - EVENT_CAPACITY as u32);
    assert_eq!(s.supervisor().record(FaultKind::LeftFlag).activations, 20);
}

// ---- property tests ----------------------------------------------------------------------

fn any_f32() -> impl Strategy<Value = f32> {
    prop_oneof![
        4 => -1.0f32..1.0,
        1 => Just(f32::NAN),
        1 => Just(f32::INFINITY),
        1 => Just(f32::NEG_INFINITY),
        1 => Just(f32::MAX),
        1 => Just(-f32::MAX),
        1 => Just(f32::MIN_POSITIVE),
        2 => any::<f32>(),
    ]
}

fn any_enc() -> impl Strategy<Value = EncoderReading> {
    (any_f32(), any::<bool>(), any::<bool>(), any::<bool>()).prop_map(|(a, r, p, e)| {
        EncoderReading {
            angle_rad: a,
            read_ok: r,
            parity_ok: p,
            error_flag: e,
        }
    })
}

/// (time step in us, frame without its stamp). Time steps: mostly nominal, sometimes 0,
/// gaps, or huge (backwards after wrap).
fn any_step() -> impl Strategy<Value = (u32, RawFrame)> {
    let dt = prop_oneof![6 => Just(1000u32), 1 => Just(0u32), 1 => 0u32..20_000, 1 => any::<u32>()];
    let speed = prop_oneof![3 => 0.0f32..70.0, 1 => any_f32(), 1 => any::<f32>()];
    let coil = prop_oneof![2 => Just(None), 1 => any_f32().prop_map(Some), 1 => (0.0f32..3.0).prop_map(Some)];
    let drive = prop_oneof![2 => Just(None), 1 => any_f32().prop_map(Some), 1 => (0.0f32..3.0).prop_map(Some)];
    (
        dt,
        any_enc(),
        any_enc(),
        speed,
        any::<bool>(),
        (coil, drive),
    )
        .prop_map(|(dt, l, r, v, vok, (c, d))| {
            (
                dt,
                RawFrame {
                    t_us: 0,
                    left: l,
                    right: r,
                    speed_mps: v,
                    speed_valid: vok,
                    coil_current_a: c,
                    coil_drive_a: d,
                },
            )
        })
}

fn any_kind() -> impl Strategy<Value = ControllerKind> {
    prop_oneof![
        Just(ControllerKind::PassiveOff),
        any_f32().prop_map(|c| ControllerKind::PassiveOn { current_a: c }),
        Just(ControllerKind::Smc),
        Just(ControllerKind::Asmc),
        Just(ControllerKind::Skyhook),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]

    /// Whatever arrives: no panic, the command is finite and in [0, I_max], the internal state
    /// stays finite, and a FailSafe verdict is obeyed.
    #[test]
    fn safe_step_contract(
        kind in any_kind(),
        steps in proptest::collection::vec(any_step(), 1..400),
        margin in prop_oneof![Just(MarginStatus::NotUsed), Just(VALID_FAR), Just(MarginStatus::Invalid),
            (any::<f32>(), any::<f32>(), any::<f32>()).prop_map(|(a, b, c)| MarginStatus::Valid(
                crate::control::schedule::MarginSignal { speed_margin_mps: a, time_to_critical_s: b, zeta_fast: c }))],
    ) {
        let mut s = SafeController::new(kind, ControlParams::default(), SupervisorParams::default());
        let mut t = 0u32;
        for (dt, mut f) in steps {
            t = t.wrapping_add(dt);
            f.t_us = t;
            let prev = s.last_command_a();
            let o = s.step(&f, margin);
            prop_assert!(o.current_cmd_a.is_finite());
            prop_assert!((0.0..=I_MAX).contains(&o.current_cmd_a));
            prop_assert!(o.validated.dt_s.is_finite() && o.validated.dt_s > 0.0);
            prop_assert!(s.controller().adaptive_gain().is_finite());
            if let Some(c) = o.control {
                prop_assert!(c.s_radps.is_finite());
                prop_assert!(c.desired_force_n.is_finite());
                prop_assert!(c.conditioned.psi_rad.is_finite() && c.conditioned.rate_radps.is_finite());
                prop_assert!(o.verdict.mode != Mode::FailSafe);
            }
            if let Some((l, r)) = o.validated.angles_rad {
                prop_assert!(l.is_finite() && r.is_finite() && l.abs() <= 0.8 && r.abs() <= 0.8);
            }
            if o.verdict.mode == Mode::FailSafe {
                prop_assert!(o.control.is_none());
                let target = o.verdict.safe_current_a.unwrap_or(FAILSAFE_CURRENT_A);
                // Moves toward the safe current at the slew limit (2000 A/s).
                let max_step = 2000.0 * o.validated.dt_s;
                prop_assert!((o.current_cmd_a - target).abs() <= ((prev - target).abs() - max_step).max(0.0) + 1e-5);
            }
            if let Some(floor) = o.verdict.safe_current_a {
                if o.verdict.mode == Mode::Degraded {
                    let max_step = 2000.0 * o.validated.dt_s;
                    prop_assert!(o.current_cmd_a >= (prev + max_step).min(floor) - 1e-5);
                }
            }
        }
    }

    /// The margin estimator under arbitrary input: no panic, the RLS covariances stay finite,
    /// symmetric, and within the trace bound.
    #[test]
    fn rls_covariance_stays_finite_and_symmetric(
        samples in proptest::collection::vec((any_f32(), any_f32(), any_f32(), any_f32()), 1..2000),
    ) {
        use crate::estimator::meter::mode_meter::{EstimatorConfig, MarginEstimator, Sample, WheelOrder};
        let cfg = EstimatorConfig::default();
        let mut est = MarginEstimator::<f32>::new(cfg).expect("default config");
        for (i, (l, r, v, c)) in samples.into_iter().enumerate() {
            let wheel = if i % 3 == 0 {
                WheelOrder::Speed { speed_mps: v, radius_m: 0.35 }
            } else {
                WheelOrder::Phase { phase_rad: v }
            };
            if let Some(out) = est.push(&Sample { psi_l_rad: l, psi_r_rad: r, wheel, damper_cmd: c }) {
                prop_assert!(out.fast.zeta.is_finite() || !out.fast.valid);
                prop_assert!(out.slow.zeta.is_finite() || !out.slow.valid);
            }
            for rls in [est.fast_rls(), est.slow_rls()] {
                let tr = rls.trace();
                prop_assert!(tr.is_finite() && tr >= 0.0, "trace {}", tr);
                prop_assert!(tr <= cfg.trace_max.unwrap_or(f32::MAX) * 1.0001, "trace {}", tr);
                prop_assert!(rls.asymmetry() == 0.0, "asymmetry {}", rls.asymmetry());
                for j in 0..rls.dim() {
                    prop_assert!(rls.p(j, j) >= 0.0);
                    prop_assert!(rls.theta().iter().all(|x| x.is_finite()));
                }
            }
        }
    }
}

/// A wheel-speed signal with 0.05 m/s rms noise per 1 ms sample (the simulator's sensor model)
/// raises no `SpeedJump` with the 0.5 m/s noise tolerance; without it (tolerance 0) the same
/// signal is flagged almost at once (1.5 g x 2 ms = 0.03 m/s is below the noise).
#[test]
fn speed_noise_is_not_a_jump_but_needs_the_tolerance() {
    // Deterministic pseudo-noise, uniform in +-0.0866 m/s (0.05 m/s rms).
    let mut state = 12345u32;
    let mut noise = move || {
        state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        (state >> 8) as f32 / (1u32 << 24) as f32 * 0.1732 - 0.0866
    };
    let mut jumps = [0u32; 2];
    for (i, tol) in [0.5f32, 0.0].into_iter().enumerate() {
        let p = SupervisorParams {
            speed_noise_tol_mps: tol,
            ..SupervisorParams::default()
        };
        let mut s = SafeController::new(ControllerKind::Asmc, ControlParams::default(), p);
        for k in 0..2000 {
            let f = frame(k, 20.0 + noise());
            let o = s.step(&f, MarginStatus::NotUsed);
            if o.verdict.detected.contains(FaultKind::SpeedJump) {
                jumps[i] += 1;
            }
        }
    }
    assert_eq!(jumps[0], 0, "with the tolerance");
    assert!(jumps[1] > 100, "without the tolerance: {}", jumps[1]);
}

/// A PWM channel that only keeps its duty (the board's coil drive without a coil).
struct Duty(u16);

impl embedded_hal::pwm::ErrorType for Duty {
    type Error = core::convert::Infallible;
}

impl embedded_hal::pwm::SetDutyCycle for Duty {
    fn max_duty_cycle(&self) -> u16 {
        8400
    }
    fn set_duty_cycle(&mut self, duty: u16) -> Result<(), Self::Error> {
        self.0 = duty;
        Ok(())
    }
}

/// What a coil-current test run ended with.
struct CoilRun {
    faults: FaultSet,
    damper_available: bool,
    /// Mean true coil current / command over the last second where the command was >= 0.5 A.
    delivered_ratio: f32,
}

/// 3.5 s of the supervised ASMC on a quiet road (0.1 mrad of yaw: the controller rests at
/// 0 A) and from 1.5 s on a 7 deg shimmy signal (the command mostly at 2 A), the coil behind
/// the board's current
/// loop (core's `CoilDriver`, closed on the trusted reading, open loop otherwise, off when the
/// damper is unavailable), a coil of `r_factor` x the nominal resistance (L/R = 1/190 s at
/// the nominal one). From 0.5 s the shunt reads `shunt(coil current, drive)`; `short`: the
/// current bypasses the coil (reading = 5 x drive, no lag, the coil carries nothing).
fn coil_run(
    p: SupervisorParams,
    shunt: impl Fn(f32, f32) -> f32,
    short: bool,
    r_factor: f32,
) -> CoilRun {
    use crate::control::actuator::{CoilDriver, CoilParams};
    let mut s = safe_with(p);
    let mut drv = CoilDriver::new(Duty(0), CoilParams::DEFAULT);
    let mut coil = 0.0f32;
    let (mut sum, mut n) = (0.0f32, 0u32);
    let mut out = SafeOutput::default();
    for k in 0..3500u32 {
        let faulty = k >= 500;
        let drive = drv.drive_a();
        coil = if faulty && short {
            0.0
        } else {
            lagged_coil(&mut coil, drive / r_factor, 1.0 / (190.0 * r_factor))
        };
        let mut f = frame(k, 20.0);
        if k < 1500 {
            let (l, r) = yaw(k);
            (f.left.angle_rad, f.right.angle_rad) = (1e-3 * l, 1e-3 * r);
        }
        f.coil_drive_a = Some(drive);
        f.coil_current_a = Some(match (faulty, short) {
            (false, _) => coil,
            (true, true) => (5.0 * drive).min(2.5),
            (true, false) => shunt(coil, drive).clamp(0.0, 2.5),
        });
        out = s.step(&f, MarginStatus::NotUsed);
        if out.verdict.damper_available {
            let Ok(_) = drv.drive(out.current_cmd_a, out.validated.coil_current_a, 1e-3);
        } else {
            let Ok(()) = drv.off();
        }
        if k >= 2500 && out.current_cmd_a >= 0.5 {
            // The coil settles towards the steady current of this period's drive.
            sum += drv.drive_a() / r_factor / out.current_cmd_a;
            n += 1;
        }
    }
    CoilRun {
        faults: out.verdict.faults,
        damper_available: out.verdict.damper_available,
        delivered_ratio: if n > 0 { sum / n as f32 } else { f32::NAN },
    }
}

/// A coil-current sensor that lies (offset +0.3/+0.6 A, gain x2 or x0.4) is a sensor fault,
/// never a coil fault: `CoilSensor` latched, the damper kept and driven open loop, so the
/// coil carries the command (within 5 %). With the sensor's plausibility rules disabled the
/// same sensors go unnoticed and the current loop delivers what the lie makes it deliver.
#[test]
fn a_lying_current_sensor_is_a_sensor_fault_not_a_coil_fault() {
    let blind = SupervisorParams {
        coil_sensor_zero_a: f32::INFINITY,
        coil_sensor_lo: 0.0,
        coil_sensor_hi: f32::INFINITY,
        ..SupervisorParams::default()
    };
    type Shunt = fn(f32, f32) -> f32;
    let cases: [(&str, Shunt, f32); 4] = [
        ("offset +0.3", |i, _| i + 0.3, 0.1),
        ("offset +0.6", |i, _| i + 0.6, 0.2),
        ("gain x2", |i, _| 2.0 * i, 0.4),
        ("gain x0.4", |i, _| 0.4 * i, 0.4),
    ];
    for (name, shunt, err) in cases {
        let r = coil_run(SupervisorParams::default(), shunt, false, 1.0);

        assert!(
            r.faults.contains(FaultKind::CoilSensor),
            "{name}: {:?}",
            r.faults
        );
        assert!(
            !r.faults.contains(FaultKind::CoilShort) && !r.faults.contains(FaultKind::CoilOpen),
            "{name}: {:?}",
            r.faults
        );
        assert!(r.damper_available, "{name}");
        assert!(
            (r.delivered_ratio - 1.0).abs() < 0.05,
            "{name}: {}",
            r.delivered_ratio
        );
        let b = coil_run(blind, shunt, false, 1.0);
        std::eprintln!(
            "{name}: coil-sensor, {:.3} x the command delivered; blind: {:.3} x",
            r.delivered_ratio,
            b.delivered_ratio
        );
        assert!(b.faults.is_empty(), "{name} blind: {:?}", b.faults);
        assert!(
            (b.delivered_ratio - 1.0).abs() > err,
            "{name} blind: delivers {} of the command",
            b.delivered_ratio
        );
    }
}

/// A healthy coil behind the current loop raises nothing; a coil shorted behind it (the loop
/// lowers the duty until the reading matches the command, so the reading alone looks
/// plausible) is found through the drive: the coil is off, the damper unavailable.
#[test]
fn a_short_behind_the_current_loop_is_found_through_the_drive() {
    let r = coil_run(SupervisorParams::default(), |i, _| i, false, 1.0);
    assert!(r.faults.is_empty(), "healthy: {:?}", r.faults);
    assert!(
        (r.delivered_ratio - 1.0).abs() < 0.05,
        "healthy: {}",
        r.delivered_ratio
    );
    let r = coil_run(SupervisorParams::default(), |i, _| i, true, 1.0);
    assert!(r.faults.contains(FaultKind::CoilShort), "{:?}", r.faults);
    assert!(!r.damper_available);
}

/// A healthy coil hot (R x1.5, 150 C) or cold (R x0.76, -40 C) behind the current loop, the
/// drive in the frame: the reading sits at 0.67 / 1.31 x what the drive pushes through the
/// nominal coil, inside the sensor's band, so nothing is raised and the loop delivers the
/// command.
#[test]
fn a_hot_or_cold_coil_is_no_sensor_fault() {
    for r_factor in [1.5f32, 0.76] {
        let r = coil_run(SupervisorParams::default(), |i, _| i, false, r_factor);
        assert!(r.faults.is_empty(), "R x{r_factor}: {:?}", r.faults);
        assert!(
            (r.delivered_ratio - 1.0).abs() < 0.05,
            "R x{r_factor}: {}",
            r.delivered_ratio
        );
    }
}

/// Without a drive in the frame (an ideal current source) the drive is the command; a reading
/// with no command is the sensor's (no coil fault makes current flow without voltage), and a
/// negative one too.
#[test]
fn a_reading_without_drive_is_the_sensor() {
    for reading in [0.3f32, -0.3] {
        let mut sup = Supervisor::new(SupervisorParams::default());
        let mut v = SupervisorVerdict::default();
        for k in 0..100u32 {
            let mut f = frame(k, 20.0);
            f.coil_current_a = Some(reading);
            v = sup.check(&f, 0.0, MarginStatus::NotUsed).0;
        }
        assert!(v.faults.contains(FaultKind::CoilSensor), "{reading}: {v:?}");
        assert!(v.damper_available && !v.faults.contains(FaultKind::CoilShort));
    }
}

// ---- coil checks over a window, test pulse, escalation of intermittent faults --------------

/// Coil with an exact first-order lag of time constant `tau_s` (the supervisor's model of it is
/// a backward-Euler lag of the nominal L/R).
fn lagged_coil(i: &mut f32, cmd: f32, tau_s: f32) -> f32 {
    *i += (cmd - *i) * (1.0 - libm::expf(-1e-3 / tau_s));
    *i
}

fn coil_faults(s: &SafeController) -> (bool, bool) {
    let f = s.supervisor().faults();
    (
        f.contains(FaultKind::CoilOpen),
        f.contains(FaultKind::CoilShort),
    )
}

/// A healthy coil under ASMC on a large shimmy signal (the command switches between 0 and 2 A
/// all the time) raises no coil fault, for a coil faster or slower than the model (hot: R
/// +50 % makes L/R shorter; cold: R -20 %).
#[test]
fn healthy_coil_under_chattering_commands_raises_no_coil_fault() {
    for tau in [1.0 / 190.0, 1.0 / 285.0, 1.0 / 152.0] {
        let mut s = safe();
        let mut i = 0.0;
        let mut switches = 0;
        let mut last = 0.0;
        for k in 0..10_000 {
            let mut f = frame(k, 20.0);
            f.coil_current_a = Some(lagged_coil(&mut i, s.last_command_a(), tau));
            let o = s.step(&f, MarginStatus::NotUsed);
            if (o.current_cmd_a - last).abs() > 0.5 {
                switches += 1;
            }
            last = o.current_cmd_a;
            assert!(
                o.verdict.faults.is_empty(),
                "tau {tau}, k={k}: {:?}",
                o.verdict
            );
        }
        assert!(
            switches > 100,
            "the command chatters: {switches} steps > 0.5 A"
        );
    }
}

/// A connector that is open 30 ms of every 50 ms (the shunt reads 0 A then) while 1.5 A is
/// commanded: never 50 ms in a row, but 60 % of the time. The accumulating window flags it;
/// the old rule (the mismatch timer restarts at the first good sample: an infinite drain
/// rate) never does.
#[test]
fn chattering_coil_connector_is_flagged() {
    for (heal, expect) in [(0.25f32, true), (f32::INFINITY, false)] {
        let mut s = SafeController::new(
            ControllerKind::PassiveOn { current_a: 1.5 },
            ControlParams::default(),
            SupervisorParams {
                coil_heal_ratio: heal,
                ..SupervisorParams::default()
            },
        );
        let mut i = 0.0;
        let mut found = None;
        for k in 0..3000u32 {
            let mut f = frame(k, 20.0);
            let open = k >= 500 && (k - 500) % 50 < 30;
            let cmd = if open { 0.0 } else { s.last_command_a() };
            f.coil_current_a = Some(lagged_coil(&mut i, cmd, 1.0 / 190.0));
            s.step(&f, MarginStatus::NotUsed);
            if found.is_none() && coil_faults(&s).0 {
                found = Some(k);
            }
        }
        assert_eq!(found.is_some(), expect, "drain {heal}: {found:?}");
        if let Some(k) = found {
            // Each 50 ms cycle adds ~30 ms - 20 ms x 0.25 = 25 ms (less the coil's decay).
            assert!(k < 500 + 200, "found at {k}");
        }
    }
}

/// The coil opens while the controller demands nothing (quiet road, ASMC at 0 A). Without a
/// command above 0.2 A no check can run; the test pulse (0.4 A for 80 ms after 1 s without a
/// check) finds it within about a second. With the pulse disabled it is never found.
#[test]
fn open_coil_at_idle_is_found_by_the_test_pulse() {
    for (pulse_a, expect) in [(0.4f32, true), (0.0, false)] {
        let mut s = SafeController::new(
            ControllerKind::Asmc,
            ControlParams::default(),
            SupervisorParams {
                coil_test_current_a: pulse_a,
                ..SupervisorParams::default()
            },
        );
        let mut i = 0.0;
        let mut pulses = 0;
        let mut found = None;
        for k in 0..10_000u32 {
            // A quiet road: 0.1 mrad of yaw (inside the controller's quiet zone, but moving, so
            // not a frozen pair).
            let (l, r) = yaw(k);
            let mut f = RawFrame::ok(k * 1000, 1e-3 * l, 1e-3 * r, 20.0);
            let open = k >= 3000;
            let cmd = if open { 0.0 } else { s.last_command_a() };
            f.coil_current_a = Some(lagged_coil(&mut i, cmd, 1.0 / 190.0));
            let o = s.step(&f, MarginStatus::NotUsed);
            if o.verdict.test_current_a.is_some() && o.current_cmd_a > 0.0 && k < 3000 {
                pulses += 1;
            }
            if found.is_none() && o.verdict.faults.contains(FaultKind::CoilOpen) {
                found = Some(k);
            }
            if k < 3000 {
                assert!(o.verdict.faults.is_empty(), "healthy idle coil, k={k}");
            }
        }
        if expect {
            // Healthy: a pulse of 80 steps roughly every 1.09 s.
            assert!(pulses >= 2 * 80, "pulses {pulses}");
            let k = found.expect("found by the pulse");
            assert!(k < 3000 + 1200, "found {} ms after the opening", k - 3000);
        } else {
            assert_eq!((pulses, found), (0, None));
        }
    }
}

/// One bad encoder read (parity) every 1,500 frames. Old rule (the recurrence window off):
/// Normal/Degraded toggle forever (two mode changes per glitch). With escalation the third
/// glitch within 10 s latches `left-flag`: Degraded (2 A floor) for good, reported once, until
/// `clear_latched`. One glitch every 15 s (outside the 10 s window) is never latched.
#[test]
fn intermittent_encoder_fault_escalates_instead_of_toggling() {
    let run_glitches = |window_s: f32, every: u32, n: u32| {
        let mut s = SafeController::new(
            ControllerKind::Asmc,
            ControlParams::default(),
            SupervisorParams {
                intermittent_window_s: window_s,
                ..SupervisorParams::default()
            },
        );
        let mut changes = Vec::new();
        let mut mode = Mode::Normal;
        for k in 0..n {
            let o = run(&mut s, k, 1, |k, mut f| {
                if k % every == every - 1 {
                    f.left.parity_ok = false;
                }
                f
            });
            if o.verdict.mode != mode {
                changes.push(k);
                mode = o.verdict.mode;
            }
        }
        (s, changes, mode)
    };
    // 20 glitches in 31.1 s, each one Degraded and, 1 s later, Normal again.
    let (_, old, _) = run_glitches(0.0, 1500, 31_100);
    assert_eq!(old.len(), 40, "old rule: toggles at every glitch: {old:?}");
    let (mut s, new, mode) = run_glitches(10.0, 1500, 31_100);
    // Degraded, Normal, Degraded, Normal, then latched Degraded at the third glitch.
    assert_eq!(new.len(), 5, "{new:?}");
    assert_eq!(new.last(), Some(&4499));
    assert_eq!(mode, Mode::Degraded);
    assert!(s.supervisor().escalated().contains(FaultKind::LeftFlag));
    assert!(s.supervisor().latched().contains(FaultKind::LeftFlag));
    let latched_events = s
        .supervisor()
        .events()
        .filter(|e| matches!(e, SupervisorEvent::Latched { .. }))
        .count();
    assert_eq!(latched_events, 1);
    s.supervisor_mut().clear_latched();
    let o = run(&mut s, 31_100, 1, |_, f| f);
    assert_eq!(o.verdict.mode, Mode::Normal);
    // Rare glitches are not escalated: every one recovers.
    let (s, rare, mode) = run_glitches(10.0, 15_000, 61_100);
    assert_eq!(rare.len(), 8, "{rare:?}");
    assert_eq!(mode, Mode::Normal);
    assert!(s.supervisor().escalated().is_empty());
}

/// Latched faults remembered across a reset are active from the first frame: a coil found
/// shorted before the reset gets 0 A (FailSafe), never the fail-safe 2 A; an escalated encoder
/// fault keeps its Degraded floor; both stay until `clear_latched`.
#[test]
fn restored_latched_faults_hold_from_the_first_frame() {
    let mut set = FaultSet::EMPTY;
    set.insert(FaultKind::CoilShort);
    let mut s = safe();
    s.supervisor_mut().restore_latched(set);
    let mut f = frame(0, 20.0);
    f.coil_current_a = Some(0.0);
    let o = s.step(&f, MarginStatus::NotUsed);
    assert_eq!((o.verdict.mode, o.current_cmd_a), (Mode::FailSafe, 0.0));
    assert!(!o.verdict.damper_available);
    let o = run(&mut s, 1, 3000, |_, mut f| {
        f.coil_current_a = Some(0.0);
        f
    });
    assert_eq!((o.verdict.mode, o.current_cmd_a), (Mode::FailSafe, 0.0));
    let mut s = safe();
    let mut set = FaultSet::EMPTY;
    set.insert(FaultKind::LeftRead);
    // Kinds that neither latch nor escalate are not restored.
    set.insert(FaultKind::MarginUnavailable);
    s.supervisor_mut().restore_latched(set);
    let o = run(&mut s, 0, 3000, |_, f| f);
    assert_eq!(o.verdict.mode, Mode::Degraded);
    assert_eq!(o.verdict.safe_current_a, Some(FAILSAFE_CURRENT_A));
    assert!(!o.verdict.faults.contains(FaultKind::MarginUnavailable));
    assert_eq!(
        FaultSet::from_bits(s.supervisor().latched().bits()).len(),
        1
    );
    s.supervisor_mut().clear_latched();
    let o = run(&mut s, 3000, 1, |_, f| f);
    assert_eq!(o.verdict.mode, Mode::Normal);
}

// ---- motion evidence, dithering encoders, coil shorts under a chattering command ----------

/// The 14-bit encoder's quantum, rad.
const LSB: f32 = 2.0 * core::f32::consts::PI / 16384.0;

/// `x` read by a 14-bit encoder with about 0.5 LSB rms of noise (a deterministic uniform
/// +-0.87 LSB from `seed`), quantised.
fn encoder(x: f32, seed: &mut u32) -> f32 {
    *seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
    let u = (*seed >> 8) as f32 / (1u32 << 24) as f32 - 0.5;
    libm::roundf((x + 1.73 * u * LSB) / LSB) * LSB
}

/// An encoder that holds one value is stuck after 100 samples when the encoders dither, even
/// on a quiet road where the other one moves only by its noise (a heavy vehicle's wheels move
/// by a few quanta under control); with quiet encoders that freeze cannot be told from a
/// still wheel. Healthy dithering encoders are never stuck, moving or still.
#[test]
fn a_dithering_encoder_that_holds_one_value_is_stuck() {
    let quiet_road =
        |k: u32| 2e-4 * libm::sinf(2.0 * core::f32::consts::PI * 3.0 * k as f32 * 1e-3);
    for (params, expect) in [
        (SupervisorParams::default(), true),
        (quiet_encoders(), false),
    ] {
        let mut s = safe_with(params);
        let mut seed = 7;
        let mut found = None;
        for k in 0..3000u32 {
            let r = encoder(quiet_road(k), &mut seed);
            let l = if k >= 1000 {
                0.0
            } else {
                encoder(quiet_road(k), &mut seed)
            };
            let o = s.step(&RawFrame::ok(k * 1000, l, r, 20.0), MarginStatus::NotUsed);
            if k < 1000 {
                assert!(o.verdict.faults.is_empty(), "k={k}: {:?}", o.verdict);
            }
            if found.is_none() && o.verdict.faults.contains(FaultKind::LeftStuck) {
                found = Some(k);
            }
        }
        assert_eq!(found.is_some(), expect, "{params:?}: {found:?}");
        if let Some(k) = found {
            assert!((1099..=1101).contains(&k), "found at {k}");
        }
    }
    // Dithering and still (parked), and dithering on a large shimmy: nothing for 10 s.
    for amplitude in [0.0f32, 0.1] {
        let mut s = safe();
        let mut seed = 11;
        for k in 0..10_000u32 {
            let y = amplitude * libm::sinf(2.0 * core::f32::consts::PI * 7.0 * k as f32 * 1e-3);
            let (l, r) = (encoder(y, &mut seed), encoder(y, &mut seed));
            let speed = if amplitude > 0.0 { 20.0 } else { 0.0 };
            let o = s.step(&RawFrame::ok(k * 1000, l, r, speed), MarginStatus::NotUsed);
            assert!(
                o.verdict.faults.is_empty(),
                "amplitude {amplitude}, k={k}: {:?}",
                o.verdict
            );
        }
    }
}

/// Both (quiet) encoders freeze in the middle of a 3 deg shimmy: suspected within half a
/// period of the band's lower edge (167 ms), not after 2 s, with the fail-safe floor. The same
/// pair coming to rest through a damped decay (time constant 0.3 s) raises nothing for 2 s.
#[test]
fn a_pair_that_freezes_mid_oscillation_is_suspected_at_once() {
    let p = quiet_encoders();
    assert!((p.pair_freeze_s() - 1.0 / 6.0).abs() < 1e-6);
    let q = |x: f32| libm::roundf(x / LSB) * LSB;
    let shimmy = |k: u32, decay: bool| {
        let t = k as f32 * 1e-3;
        let env = if decay && k > 1000 {
            libm::expf(-(t - 1.0) / 0.3)
        } else {
            1.0
        };
        q(3f32.to_radians() * env * libm::sinf(2.0 * core::f32::consts::PI * 7.0 * t))
    };
    let mut s = safe_with(p);
    let mut found = None;
    for k in 0..3000u32 {
        let y = if k >= 1000 {
            shimmy(1000, false)
        } else {
            shimmy(k, false)
        };
        let o = s.step(&RawFrame::ok(k * 1000, y, y, 20.0), MarginStatus::NotUsed);
        if found.is_none() && o.verdict.faults.contains(FaultKind::BothStuckSuspect) {
            found = Some(k);
            assert_eq!(o.verdict.safe_current_a, Some(FAILSAFE_CURRENT_A));
        }
    }
    let k = found.expect("suspected");
    assert!((1100..=1170).contains(&k), "suspected at {k}");
    let mut s = safe_with(p);
    for k in 0..3500u32 {
        let y = shimmy(k, true);
        let o = s.step(&RawFrame::ok(k * 1000, y, y, 20.0), MarginStatus::NotUsed);
        assert!(
            o.verdict.faults.is_empty(),
            "damped decay, k={k}: {:?}",
            o.verdict
        );
    }
}

/// The speed reads 0 m/s (valid) from the first frame while the wheels shimmy (a tone wheel
/// lost before the vehicle set off): no trusted history can show it, the oscillation does.
/// Within two cycles the speed is unknown: the speed gate off (the controller runs) and the
/// fail-safe floor. A parked vehicle whose driver steers (0.3 rad at 0.5 Hz, or sawing at 1 Hz)
/// raises nothing: too slow for the shimmy band.
#[test]
fn a_low_speed_reading_while_the_wheels_shimmy_is_contradicted() {
    let mut s = safe_with(quiet_encoders());
    let mut found = None;
    for k in 0..1000u32 {
        let t = k as f32 * 1e-3;
        let y = 0.5f32.to_radians() * libm::sinf(2.0 * core::f32::consts::PI * 6.0 * t);
        let o = s.step(&RawFrame::ok(k * 1000, y, y, 0.0), MarginStatus::NotUsed);
        if found.is_none() && o.verdict.detected.contains(LOW) {
            found = Some(k);
        }
        if let Some(k0) = found {
            assert_eq!(o.validated.speed_mps, None, "k={k}");
            assert_eq!(o.verdict.safe_current_a, Some(FAILSAFE_CURRENT_A));
            assert!(
                o.control.is_some_and(|c| !c.flags.below_speed),
                "k={k0}..{k}"
            );
        }
    }
    let k = found.expect("contradicted");
    assert!(k <= 400, "contradicted at {k} ms");
    // Braking out of shimmy: the wheels still oscillate (1 deg) when the reading passes the
    // gate, then come to rest. Still wheels prove nothing (the floor damps them), so the
    // standstill stays untrusted (2 A floor while parked) until the reading is back above the
    // gate; then Normal after the recovery time.
    let mut s = safe_with(quiet_encoders());
    let drive = |s: &mut SafeController, k0: u32, n: u32, v: &dyn Fn(f32) -> f32| {
        let mut last = SafeOutput::default();
        for k in k0..k0 + n {
            let t = k as f32 * 1e-3;
            // Decaying from 0.8 s on (time constant 0.1 s): a wheel coming to rest.
            let env = libm::expf(-(t - 0.8).max(0.0) / 0.1);
            let y = 1f32.to_radians() * env * libm::sinf(2.0 * core::f32::consts::PI * 6.0 * t);
            last = s.step(&RawFrame::ok(k * 1000, y, y, v(t)), MarginStatus::NotUsed);
        }
        last
    };
    let o = drive(&mut s, 0, 5000, &|t| (2.5 - 2.5 * t).max(0.0));
    assert!(o.verdict.detected.contains(LOW), "{:?}", o.verdict);
    assert_eq!(o.validated.speed_mps, None);
    assert_eq!(o.verdict.safe_current_a, Some(FAILSAFE_CURRENT_A));
    let o = drive(&mut s, 5000, 3000, &|_| 3.0);
    assert!(o.verdict.faults.is_empty(), "{:?}", o.verdict);
    assert_eq!(o.validated.speed_mps, Some(3.0));
    for (amplitude, hz) in [(0.3f32, 0.5f32), (0.05, 1.0)] {
        let mut s = safe_with(quiet_encoders());
        for k in 0..10_000u32 {
            let t = k as f32 * 1e-3;
            let y = amplitude * libm::sinf(2.0 * core::f32::consts::PI * hz * t);
            let o = s.step(&RawFrame::ok(k * 1000, y, y, 0.0), MarginStatus::NotUsed);
            assert!(
                o.verdict.faults.is_empty(),
                "{hz} Hz, k={k}: {:?}",
                o.verdict
            );
        }
    }
}

/// A shorted coil under a chattering command (single-sample 2 A spikes every 300 ms, 0 A
/// otherwise: ASMC on a heavy vehicle's quantised yaw). The shunt reads 5 x the command with
/// no lag, so after each spike it drops to 0 while the lagged expected current is still high:
/// that must not count as an open coil. The spikes must not postpone the test pulse either:
/// the pulse finds the short within about a second.
#[test]
fn a_short_under_a_chattering_command_is_found_as_a_short() {
    let mut sup = Supervisor::new(SupervisorParams::default());
    let mut seed = 3;
    let mut found = None;
    let mut cmd = 0.0f32;
    let mut pulses = 0;
    for k in 0..4000u32 {
        let mut f = RawFrame::ok(
            k * 1000,
            encoder(0.0, &mut seed),
            encoder(0.0, &mut seed),
            20.0,
        );
        f.coil_current_a = Some((5.0 * cmd).min(2.5));
        let (v, _) = sup.check(&f, cmd, MarginStatus::NotUsed);
        assert!(!v.faults.contains(FaultKind::CoilOpen), "k={k}: {v:?}");
        if found.is_none() && v.faults.contains(FaultKind::CoilShort) {
            found = Some(k);
        }
        let spike = if k % 300 == 150 { 2.0 } else { 0.0 };
        pulses += u32::from(v.test_current_a.is_some());
        cmd = if !v.damper_available {
            0.0
        } else {
            v.test_current_a.unwrap_or(0.0).max(spike)
        };
    }
    let k = found.expect("the short is found");
    assert!(
        pulses > 0 && k < 1200,
        "found at {k} ms after {pulses} pulse samples"
    );
}
