//! Sequences of raw sensor frames into the combined 1 kHz core step (supervisor + controller +
//! limiter) and the margin estimator. Checks the output contract on every step.
//!
//! Run (needs `cargo install cargo-fuzz`; the installed nightly 1.97 is older than the crate's
//! rust-version 1.98, so the pinned 1.98 toolchain is used with nightly features unlocked):
//! `cd fuzz && RUSTC_BOOTSTRAP=1 cargo fuzz run safe_step -- -max_total_time=60`
#![no_main]

use libfuzzer_sys::fuzz_target;
use shimmy_core::control::schedule::MarginSignal;
use shimmy_core::control::{ControlParams, ControllerKind};
use shimmy_core::estimator::meter::mode_meter::{EstimatorConfig, MarginEstimator, WheelOrder};
use shimmy_core::supervisor::frame::{EncoderReading, MarginStatus, RawFrame};
use shimmy_core::supervisor::params::SupervisorParams;
use shimmy_core::supervisor::safe_controller::SafeController;

/// Bytes per frame: dt (2), left angle (4), right angle (4), speed (4), coil (4), flags (2).
const FRAME_BYTES: usize = 20;

fn f32_at(b: &[u8], i: usize) -> f32 {
    let mut w = [0u8; 4];
    w.copy_from_slice(&b[i..i + 4]);
    f32::from_le_bytes(w)
}

fuzz_target!(|data: &[u8]| {
    let Some((&sel, rest)) = data.split_first() else {
        return;
    };
    let kind = match sel % 6 {
        0 => ControllerKind::PassiveOff,
        1 => ControllerKind::PassiveOn {
            current_a: f32::from(sel) / 64.0,
        },
        2 => ControllerKind::Smc,
        3 => ControllerKind::Asmc,
        4 => ControllerKind::MarginAsmc,
        _ => ControllerKind::Skyhook,
    };
    let params = ControlParams::default();
    let i_max = params.limits.i_max_a;
    let mut safe = SafeController::new(kind, params, SupervisorParams::default());
    let mut est = MarginEstimator::<f32>::new(EstimatorConfig::default()).expect("config");
    let mut t_us = 0u32;
    for b in rest.chunks_exact(FRAME_BYTES) {
        let dt = u16::from_le_bytes([b[0], b[1]]);
        // Mostly nominal periods so long valid stretches happen; the rest any gap.
        t_us = t_us.wrapping_add(if dt < 0xC000 { 1000 } else { u32::from(dt) * 7 });
        let flags = u16::from_le_bytes([b[18], b[19]]);
        let enc = |a: f32, f: u16| EncoderReading {
            angle_rad: a,
            read_ok: f & 1 == 0,
            parity_ok: f & 2 == 0,
            error_flag: f & 4 != 0,
        };
        // Small perturbations of plausible values most of the time, raw bits otherwise.
        let plaus = |x: f32, scale: f32| {
            if flags & 0x100 == 0 && x.is_finite() {
                (x % 1.0) * scale
            } else {
                x
            }
        };
        let frame = RawFrame {
            t_us,
            left: enc(plaus(f32_at(b, 2), 0.1), flags),
            right: enc(plaus(f32_at(b, 6), 0.1), flags >> 3),
            speed_mps: plaus(f32_at(b, 10), 40.0).abs(),
            speed_valid: flags & 0x40 == 0,
            coil_current_a: (flags & 0x80 != 0).then(|| f32_at(b, 14)),
            coil_drive_a: (flags & 0x800 != 0).then(|| plaus(f32_at(b, 10), 3.0)),
        };
        let margin = match (flags >> 9) & 3 {
            0 => MarginStatus::NotUsed,
            1 => MarginStatus::Valid(MarginSignal {
                speed_margin_mps: f32_at(b, 2),
                time_to_critical_s: f32_at(b, 6),
                zeta_fast: f32_at(b, 10),
            }),
            _ => MarginStatus::Invalid,
        };
        let o = safe.step(&frame, margin);
        assert!(o.current_cmd_a.is_finite(), "NaN command");
        assert!(
            (0.0..=i_max).contains(&o.current_cmd_a),
            "command {}",
            o.current_cmd_a
        );
        assert!(safe.controller().adaptive_gain().is_finite());
        let wheel = WheelOrder::Speed {
            speed_mps: frame.speed_mps,
            radius_m: 0.35,
        };
        if let Some(s) = SafeController::estimator_sample(&o, wheel) {
            let _ = est.push(&s);
            for rls in [est.fast_rls(), est.slow_rls()] {
                assert!(rls.trace().is_finite());
                assert!(rls.asymmetry() == 0.0);
            }
        }
    }
});
