//! The plant against a second, independent implementation: NumPy/SciPy code written from
//! `docs/plant-model.md` (`host-sim/reference/plant_scipy.py`). Trajectories of the nonlinear plant
//! with the MR damper sliding and the eigenvalues of the linearisation must agree; the mining
//! truck's eigenvalues against the same file's truck, written from `docs/mining-truck.md`, and the
//! trailer's against its trailer, written from `docs/trailer.md`.
//! Needs python3 with numpy and scipy (`cargo xtask test` installs them).
use nalgebra::Complex;
use shimmy_core::eigen::eigenvalues;
use shimmy_core::model::LinearModel;
use shimmy_core::units::kmh_to_mps;
use shimmy_core::vehicles::dual_axle;
use shimmy_core::vehicles::dual_axle::{DualAxleSet, DUAL_AXLE_FIELDS};
use shimmy_core::vehicles::trailer;
use shimmy_core::vehicles::trailer::{TrailerParams, TrailerSet};
use shimmy_core::vehicles::truck;
use shimmy_core::vehicles::truck::{TruckParams, TruckSet};
use shimmy_core::vehicles::FieldTable;
use shimmy_sim::cmd::reference_bench::{compare, ReferenceBenchArgs};

#[test]
fn nonlinear_trajectory_and_eigenvalues_match_the_scipy_implementation() {
    let out = std::env::temp_dir().join(format!("shimmy-scipy-ref-{}", std::process::id()));
    let args = ReferenceBenchArgs {
        vehicle: shimmy_sim::cmd::VehicleArg::new("nominal"),
        duration_s: 2.0,
        speed_kmh: 60.0,
        current_a: 0.5,
        initial_yaw_deg: 3.0,
        sweep_points: 150,
        scipy_methods: vec!["LSODA".into(), "RK45".into()],
        python: "python3".into(),
        out: shimmy_sim::cmd::OutArg::new(&out),
        cl_ramp_s: 6.0,
        cl_gain_a_per_radps: 4.0,
    };
    let (r, _out) =
        compare(&args).expect("the SciPy reference runs (python3 with numpy and scipy)");
    let _ = std::fs::remove_dir_all(&out);
    // Rust Dopri5 at rtol 1e-7 against SciPy's LSODA at rtol 1e-10: the trajectories of a
    // 0.05 rad motion must agree to 1e-6 rad.
    assert!(r.max_psi_rad > 0.02, "the damper must be exercised: {r:?}");
    assert!(r.max_traj_diff_rad < 1e-6, "{r:?}");
    // Two eigen-solvers (nalgebra Schur, LAPACK geev) on matrices built independently.
    assert!(r.max_eig_diff < 1e-9, "{r:?}");
    // Closed-loop row: the Python side rebuilt the demo's drive (ramp, imbalance, pothole) from
    // the case file. The largest wheel yaw of both runs is the response to the 1000 N m pothole,
    // set by the plant and the pulse more than by the current law, so both sides must see it at
    // the same size (within 25 %); a pothole at the wrong time or of the wrong size, or a
    // missing one (< 0.5 deg otherwise), fails.
    let (rust, py) = r.cl_peak_psi_rad;
    assert!(rust.to_degrees() > 1.0 && py.to_degrees() > 1.0, "{r:?}");
    assert!((rust - py).abs() < 0.25 * rust, "{r:?}");
    assert!(r.rust_cl_rate > 0.0 && r.scipy_cl_rate > 0.0);
    // Every method was timed and the peer is the fastest of them.
    assert_eq!(r.scipy_methods.len(), 2, "{r:?}");
    let best = r.scipy_methods.iter().map(|m| m.1).fold(0.0, f64::max);
    assert!(
        r.scipy_methods
            .iter()
            .any(|m| m.0 == r.scipy_fastest && m.1 == best),
        "{r:?}"
    );
}

/// The truck's case file for `plant_scipy.py truck`: its physical inputs (shortest round-trip
/// decimal, so Python reads the same doubles) and the speeds.
fn truck_case(t: &TruckParams, speeds_mps: &[f64]) -> String {
    let fields = [
        ("i_k", t.i_k),
        ("i_p", t.i_p),
        ("r", t.r),
        ("h_r", t.h_r),
        ("sigma", t.sigma),
        ("e", t.e),
        ("t_p", t.t_p),
        ("c_a_per_fz", t.c_a_per_fz),
        ("l_t", t.l_t),
        ("k_tr", t.k_tr),
        ("c_k", t.c_k),
        ("i_phi", t.i_phi),
        ("m_axle", t.m_axle),
        ("k_y", t.k_y),
        ("c_y", t.c_y),
        ("track", t.track),
        ("k_tz", t.k_tz),
        ("strut_spacing", t.strut_spacing),
        ("c_strut", t.c_strut),
        ("hps_v0_m3", t.hps.v0_m3),
        ("hps_p0_pa", t.hps.p0_pa),
        ("hps_area_m2", t.hps.area_m2),
        ("hps_n", t.hps.n),
        ("j_c", t.j_c),
        ("k_d", t.k_d),
        ("k_h", t.k_h),
        ("c_h", t.c_h),
        ("front_empty_kg", t.front_empty_kg),
        ("payload_kg", t.payload_kg),
        ("payload_front_share", t.payload_front_share),
    ];
    let mut s = String::from("[truck]\n");
    for (k, v) in fields {
        s += &format!("{k} = {v:?}\n");
    }
    let speeds: Vec<String> = speeds_mps.iter().map(|v| format!("{v:?}")).collect();
    s + &format!("[case]\nspeeds_mps = [{}]\n", speeds.join(", "))
}

/// The truck's eigenvalues against the NumPy implementation written from
/// `docs/mining-truck.md` (load chain, gas spring and matrices built there independently): every
/// eigenvalue matched to the nearest of the other side within 1e-9 relative, for both named
/// sets, a gas volume three times the charge and a half payload, from 1 to 60 km/h.
#[test]
fn truck_eigenvalues_match_the_scipy_implementation() {
    let dir = std::env::temp_dir().join(format!("shimmy-scipy-truck-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let script = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../host-sim/reference/plant_scipy.py"
    );
    let speeds: Vec<f64> = (0..=12)
        .map(|i| kmh_to_mps(1.0 + 59.0 * f64::from(i) / 12.0))
        .collect();
    let full = TruckSet::Full.params();
    let cases = [
        TruckSet::Empty.params(),
        full,
        full.with_gas_volume(3.0 * full.hps.v0_m3),
        full.with_payload(0.5 * TruckParams::RATED_PAYLOAD_KG),
    ];
    let mut worst = 0.0_f64;
    for (n, t) in cases.iter().enumerate() {
        let case = dir.join(format!("truck-{n}.toml"));
        let out = dir.join(format!("truck-{n}.txt"));
        std::fs::write(&case, truck_case(t, &speeds)).unwrap();
        let status = std::process::Command::new("python3")
            .arg(script)
            .arg("truck")
            .arg(&case)
            .arg(&out)
            .status()
            .expect("python3 runs");
        assert!(status.success(), "plant_scipy.py truck failed");
        let text = std::fs::read_to_string(&out).unwrap();
        for &v in &speeds {
            let theirs: Vec<Complex<f64>> = text
                .lines()
                .map(|l| {
                    l.split_whitespace()
                        .map(|x| x.parse::<f64>().unwrap())
                        .collect::<Vec<_>>()
                })
                .filter(|f| f[0] == v)
                .map(|f| Complex::new(f[1], f[2]))
                .collect();
            assert_eq!(theirs.len(), truck::N_STATES);
            let ours = eigenvalues(&t.linearise(v, 0.0)).unwrap();
            let rel = worst_nearest_match(&ours, &theirs);
            worst = worst.max(rel);
            assert!(rel < 1e-9, "case {n} V={v}: {rel:e}");
        }
    }
    println!("truck eigenvalues: worst relative difference {worst:e}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// The trailer's case file for `plant_scipy.py trailer`: its fields (shortest round-trip
/// decimal), the speeds and the sway damper.
fn trailer_case(t: &TrailerParams, speeds_mps: &[f64], c_damper: f64) -> String {
    let mut s = String::from("[trailer]\n");
    for f in &trailer::TRAILER_FIELDS {
        s += &format!("{} = {:?}\n", f.name, t.get(f.name).unwrap());
    }
    let speeds: Vec<String> = speeds_mps.iter().map(|v| format!("{v:?}")).collect();
    s + &format!(
        "[case]\nspeeds_mps = [{}]\ndamper_nspm = {c_damper:?}\n",
        speeds.join(", ")
    )
}

/// The trailer's eigenvalues against the NumPy implementation written from `docs/trailer.md`
/// (mass, damping and stiffness matrices and the lag row built there, M inverted numerically):
/// every eigenvalue matched to the nearest of the other side within 1e-9 relative, for the
/// named set with the sway damper, a soft hitch on tyres of short relaxation length and a stiff
/// hitch with a tail-heavy load and a damper, from 5 to 200 km/h.
#[test]
fn trailer_eigenvalues_match_the_scipy_implementation() {
    let dir = std::env::temp_dir().join(format!("shimmy-scipy-trailer-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let script = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../host-sim/reference/plant_scipy.py"
    );
    let speeds: Vec<f64> = (0..=13)
        .map(|i| kmh_to_mps(5.0 + 195.0 * f64::from(i) / 13.0))
        .collect();
    let base = TrailerSet::Caravan.params();
    let with = |fields: &[(&str, f64)]| {
        let mut t = base;
        for (name, x) in fields {
            t.set(name, *x).unwrap();
        }
        t
    };
    // three python runs (each one's start-up dominates the test's time)
    let cases = [
        (base, base.damper_of_zeta(0.05)),
        (with(&[("k_y", 0.3 * base.k_y), ("sigma", 0.05)]), 0.0),
        (
            with(&[("k_y", 40.0 * base.k_y), ("a", 1.1 * base.l)]),
            2.0e4,
        ),
    ];
    let mut worst = 0.0_f64;
    for (n, (t, c)) in cases.iter().enumerate() {
        t.validate().unwrap();
        let case = dir.join(format!("trailer-{n}.toml"));
        let out = dir.join(format!("trailer-{n}.txt"));
        std::fs::write(&case, trailer_case(t, &speeds, *c)).unwrap();
        let status = std::process::Command::new("python3")
            .arg(script)
            .arg("trailer")
            .arg(&case)
            .arg(&out)
            .status()
            .expect("python3 runs");
        assert!(status.success(), "plant_scipy.py trailer failed");
        let text = std::fs::read_to_string(&out).unwrap();
        for &v in &speeds {
            let theirs: Vec<Complex<f64>> = text
                .lines()
                .map(|l| {
                    l.split_whitespace()
                        .map(|x| x.parse::<f64>().unwrap())
                        .collect::<Vec<_>>()
                })
                .filter(|f| f[0] == v)
                .map(|f| Complex::new(f[1], f[2]))
                .collect();
            assert_eq!(theirs.len(), trailer::N_STATES);
            let ours = eigenvalues(&t.linearise(v, *c)).unwrap();
            let rel = worst_nearest_match(&ours, &theirs);
            worst = worst.max(rel);
            assert!(rel < 1e-9, "case {n} V={v}: {rel:e}");
        }
    }
    println!("trailer eigenvalues: worst relative difference {worst:e}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// Every eigenvalue of `ours` matched to the nearest unused one of `theirs`: the worst
/// difference relative to max(|lambda|, 1).
fn worst_nearest_match(ours: &[Complex<f64>], theirs: &[Complex<f64>]) -> f64 {
    assert_eq!(ours.len(), theirs.len());
    let mut used = vec![false; theirs.len()];
    let mut worst = 0.0_f64;
    for l in ours {
        let (j, d) = theirs
            .iter()
            .enumerate()
            .filter(|(j, _)| !used[*j])
            .map(|(j, m)| (j, (m - l).norm()))
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .unwrap();
        used[j] = true;
        worst = worst.max(d / l.norm().max(1.0));
    }
    worst
}

/// The dual-front-axle truck's eigenvalues against the NumPy implementation written from
/// `docs/dual-axle-truck.md` (its own loads, roll stiffness, steer ratio and the stiffness matrix
/// as the Hessian of the rods' energy): within 1e-9 relative, for the named set, a soft and a
/// stiff transition rod and an unequal axle load, from 1 to 120 km/h.
#[test]
fn dual_axle_eigenvalues_match_the_scipy_implementation() {
    let dir = std::env::temp_dir().join(format!("shimmy-scipy-dual-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let script = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../host-sim/reference/plant_scipy.py"
    );
    let speeds: Vec<f64> = (0..=12)
        .map(|i| kmh_to_mps(1.0 + 119.0 * f64::from(i) / 12.0))
        .collect();
    let base = DualAxleSet::Rated.params();
    let mut soft = base;
    soft.k_t *= 0.3;
    let mut stiff = base;
    stiff.k_t *= 3.0;
    let mut unequal = base;
    unequal.axle_load_2_kg = 6500.0;
    unequal.c_m = 300.0;
    let mut worst = 0.0_f64;
    for (n, t) in [base, soft, stiff, unequal].iter().enumerate() {
        t.validate().unwrap();
        let mut case = String::from("[dual]\n");
        for f in &DUAL_AXLE_FIELDS {
            case += &format!("{} = {:?}\n", f.name, t.get(f.name).unwrap());
        }
        let list: Vec<String> = speeds.iter().map(|v| format!("{v:?}")).collect();
        case += &format!("[case]\nspeeds_mps = [{}]\n", list.join(", "));
        let (case_path, out) = (
            dir.join(format!("dual-{n}.toml")),
            dir.join(format!("dual-{n}.txt")),
        );
        std::fs::write(&case_path, case).unwrap();
        let status = std::process::Command::new("python3")
            .arg(script)
            .arg("dual")
            .arg(&case_path)
            .arg(&out)
            .status()
            .expect("python3 runs");
        assert!(status.success(), "plant_scipy.py dual failed");
        let text = std::fs::read_to_string(&out).unwrap();
        for &v in &speeds {
            let theirs: Vec<Complex<f64>> = text
                .lines()
                .map(|l| {
                    l.split_whitespace()
                        .map(|x| x.parse::<f64>().unwrap())
                        .collect::<Vec<_>>()
                })
                .filter(|f| f[0] == v)
                .map(|f| Complex::new(f[1], f[2]))
                .collect();
            assert_eq!(theirs.len(), dual_axle::N_STATES);
            let ours = eigenvalues(&t.linearise(v, 0.0)).unwrap();
            let rel = worst_nearest_match(&ours, &theirs);
            worst = worst.max(rel);
            assert!(rel < 1e-9, "case {n} V={v}: {rel:e}");
        }
    }
    println!("dual-axle eigenvalues: worst relative difference {worst:e}");
    let _ = std::fs::remove_dir_all(&dir);
}
