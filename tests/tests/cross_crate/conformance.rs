//! Host/target conformance, host side.
//!
//! 1. The sensor trace `tests/fixtures/conformance-trace.bin` is recorded from the host
//!    simulator ([`record_trace`]: nominal plant with the MR damper at a constant 0.3 A, speed
//!    ramp 6 -> 12 m/s through the Hopf onset (8.15 m/s without damper), seeded road noise and
//!    an initial yaw kick; 6 s at 1 kHz; encoder angles quantised to 14 bit like the AS5047P,
//!    speed as f32). This test re-records it and checks that the committed file is that trace
//!    (within one encoder count, see [`trace_matches_the_simulator`]). Regenerate with
//!    `SHIMMY_BLESS=1 cargo test -p shimmy-tests --test cross_crate conformance::`.
//! 2. [`host_digest`] replays the committed trace through `shimmy_firmware::replay::replay`
//!    (the core's `SafeController` (supervisor + ASMC + limiter) with injected encoder faults,
//!    the core's `DataPipeline` (mode meter, fusion, monitor) and the `ModelMarginTracker` with
//!    the firmware's configuration (f32 eigen-solves, 1 s refresh)) on the host
//!    and writes each channel's digest (FNV-1a over the f32/f64 bit patterns) to
//!    `target/conformance/host.txt`. `cargo xtask test` runs the same replay on the target
//!    under QEMU (`firmware/src/bin/conformance.rs`) and requires identical digests: the
//!    tolerance is zero ulp (see docs/testing.md, "Conformance").

use shimmy_core::vehicles::car::PlantParams;
use shimmy_firmware::monitoring::MODEL_REFRESH_S;
use shimmy_firmware::replay::{self, CHANNELS, SAMPLE_BYTES, ZERO_COUNTS};
use shimmy_sim::model::disturbance::{initial_yaw, RoadNoise, Scenario, SpeedProfile};
use shimmy_sim::model::plant::{idx, Plant, Simulator};
use std::path::PathBuf;

const DURATION_S: f64 = 6.0;
const DT_S: f64 = 1e-3;
const CURRENT_A: f64 = 0.3;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("workspace root")
        .to_path_buf()
}

fn fixture() -> PathBuf {
    root().join("tests/fixtures/conformance-trace.bin")
}

/// Raw 14-bit count of an angle (what an AS5047P at zero `ZERO_COUNTS` reports).
fn counts(psi_rad: f64) -> u16 {
    let c = f64::from(ZERO_COUNTS) + (psi_rad * 16384.0 / (2.0 * std::f64::consts::PI)).round();
    c.rem_euclid(16384.0) as u16
}

/// Records the trace from the simulator (deterministic: fixed seed, fixed-step output).
fn record_trace() -> Vec<u8> {
    let p = PlantParams::nominal();
    let mut sim = Simulator::new(Plant::with_mr_damper(p), initial_yaw(1.0_f64.to_radians()));
    let mut sc = Scenario::new(SpeedProfile::Ramp {
        v0_mps: 6.0,
        v1_mps: 12.0,
        t0_s: 0.0,
        t1_s: DURATION_S,
    });
    sc.current_a = CURRENT_A;
    sc.noise = Some(RoadNoise::new(20.0, 10.0, 0.8, 42));
    let n = (DURATION_S / DT_S).round() as usize;
    let mut out = Vec::with_capacity(n * SAMPLE_BYTES);
    for k in 0..n {
        // Sample at the start of the period (what the 1 kHz task reads), then advance.
        let x = sim.state();
        let u = sc.inputs(k as f64 * DT_S, DT_S);
        out.extend_from_slice(&counts(x[idx::PSI_L]).to_le_bytes());
        out.extend_from_slice(&counts(x[idx::PSI_R]).to_le_bytes());
        out.extend_from_slice(&(u.speed_mps as f32).to_bits().to_le_bytes());
        sim.advance(DT_S, &u).expect("simulation");
    }
    out
}

/// The committed fixture is the simulator's trace. One encoder count of slack on at most
/// 0.1 % of the samples: the simulator uses the platform's f64 `sin`/`exp`, so another
/// platform may round an angle that sits on a count boundary the other way. The replay
/// itself only ever uses the committed bytes, so this slack never reaches the comparison.
#[test]
fn trace_matches_the_simulator() {
    let fresh = record_trace();
    let path = fixture();
    if std::env::var_os("SHIMMY_BLESS").is_some() {
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        std::fs::write(&path, &fresh).unwrap();
        eprintln!("wrote {} ({} bytes)", path.display(), fresh.len());
    }
    let committed = std::fs::read(&path).expect("fixture (SHIMMY_BLESS=1 to create it)");
    assert_eq!(committed.len(), fresh.len());
    let n = fresh.len() / SAMPLE_BYTES;
    let mut differ = 0;
    for k in 0..n {
        let (a, b) = (
            replay::sample(&committed, k).unwrap(),
            replay::sample(&fresh, k).unwrap(),
        );
        assert_eq!(a.2.to_bits(), b.2.to_bits(), "speed at sample {k}");
        let d = |x: u16, y: u16| {
            ((i32::from(x) - i32::from(y)).rem_euclid(16384))
                .min((i32::from(y) - i32::from(x)).rem_euclid(16384))
        };
        let (dl, dr) = (d(a.0, b.0), d(a.1, b.1));
        assert!(dl <= 1 && dr <= 1, "sample {k}: {a:?} vs {b:?}");
        differ += usize::from(dl + dr > 0);
    }
    assert!(
        differ * 1000 <= n,
        "{differ} of {n} samples differ by a count"
    );
}

/// The replay digest of the committed trace on the host, written for `cargo xtask test`.
#[test]
fn host_digest() {
    let trace = std::fs::read(fixture()).expect("fixture");
    let d = replay::replay(&trace, &PlantParams::nominal()).expect("replay");
    let n = (trace.len() / SAMPLE_BYTES) as u32;
    assert_eq!(d.samples, n);
    // Record counts: every sample (command, supervisor), every 10th (meter, report, level),
    // one model cycle per refresh period (`MODEL_REFRESH_S`).
    let cycles = (f64::from(n) * 1e-3 / f64::from(MODEL_REFRESH_S)).round() as u32;
    let expect = [n, n, n / 10, n / 10, n / 10, n / 10, cycles];
    for ((name, c), e) in CHANNELS.iter().zip(d.channels.iter()).zip(expect) {
        assert_eq!(c.count, e, "{name}");
    }
    // The injected faults drive the supervisor through Degraded and FailSafe and back:
    // left parity at 1500 (Degraded), right error flag at 1700 (both lost: FailSafe) until the
    // left fault has been absent for the 1 s recovery time (1000 samples), Degraded until the
    // right one has; the right encoder frozen at 4000-4300 raises right-stuck after 100
    // samples (if the left moves by > 5 mrad meanwhile) and recovers 1 s after 4300.
    // Accumulating 1 ms steps in f32 may take one sample more or less than the exact 1 s.
    let (l, r) = (replay::FAULTS[0].0 as u32, replay::FAULTS[1].0 as u32);
    let failsafe = l + 1000 - r;
    assert!(
        d.failsafe.abs_diff(failsafe) <= 1,
        "{} vs {failsafe}",
        d.failsafe
    );
    assert!(d.degraded >= 2 * (r - l), "{}", d.degraded);
    assert!(d.mode_changes >= 4, "{}", d.mode_changes);
    let mut text = String::new();
    for (name, c) in CHANNELS.iter().zip(d.channels.iter()) {
        text.push_str(&format!(
            "conformance | {name} | {} | {:016x} | {:016x}\n",
            c.count, c.hash.0, c.last_bits
        ));
        eprintln!(
            "{name}: {} records, hash {:016x}, last {}",
            c.count,
            c.hash.0,
            f64::from_bits(c.last_bits)
        );
    }
    eprintln!(
        "worst level {:?}; supervisor: {} fail-safe, {} degraded samples, {} mode changes",
        d.worst_level, d.failsafe, d.degraded, d.mode_changes
    );
    let dir = root().join("target/conformance");
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("host.txt"), text).unwrap();
}
