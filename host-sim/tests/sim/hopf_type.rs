//! `shimmy-sim stability` gives every Hopf crossing its type: the first Lyapunov coefficient of
//! the nonlinear plant and the small cycle it predicts (`shimmy_sim::model::hopf_type`), or the
//! reason there is none (a non-smooth plant).

use crate::common::{run_in, temp_dir};

fn stability(args: &[&str]) -> (String, String) {
    let dir = temp_dir("hopf-type");
    let mut all = vec!["stability", "--out", "o"];
    all.extend_from_slice(args);
    let o = run_in(&dir, &all);
    let out = String::from_utf8_lossy(&o.stdout).into_owned();
    assert!(
        o.status.success(),
        "{all:?}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    let csv = std::fs::read_to_string(dir.join("o/crossings.csv")).unwrap();
    (out, csv)
}

/// The car without damper: its onset and offset are supercritical, the table says so with l1
/// and the cycle 1 km/h into the window, the CSV carries them; the library's value is the
/// table's. With the MR damper (any current) and on the dual-axle truck with kingpin
/// friction there is no number, and the table says why.
#[test]
fn stability_prints_the_hopf_type_of_every_crossing() {
    let (out, csv) = stability(&["--v-min-kmh", "20", "--v-max-kmh", "100"]);
    let lines: Vec<&str> = out.lines().filter(|l| l.contains("l1 = ")).collect();
    assert_eq!(lines.len(), 2, "{out}");
    for l in &lines {
        assert!(l.contains("supercritical") && l.contains("deg at"), "{l}");
    }
    let p = shimmy_core::vehicles::car::ParamSet::Nominal.params();
    let v_c = shimmy_sim::model::family::onset_kmh(&p).unwrap();
    let want = shimmy_sim::model::hopf_type::hopf_type_at(
        &p,
        shimmy_sim::model::plant::Damper::None,
        shimmy_core::units::kmh_to_mps(v_c),
        6.03,
    )
    .unwrap();
    let shown = format!("l1 = {:.4e}", want.lyapunov.l1);
    assert!(lines[0].contains(&shown), "{} vs {shown}", lines[0]);
    let rows: Vec<&str> = csv.lines().collect();
    assert!(rows[0].ends_with("hopf_type,l1,l1_err,dmu_dv_per_m,cycle_side,cycle_amp_deg_1kmh"));
    assert!(
        rows[1].starts_with("onset,") && rows[1].contains(",supercritical,-1.1"),
        "{}",
        rows[1]
    );

    let (out, csv) = stability(&[
        "--v-min-kmh",
        "20",
        "--v-max-kmh",
        "100",
        "--damper-current-a",
        "0",
    ]);
    assert!(out.contains("non-smooth (MR damper"), "{out}");
    assert!(!out.contains("l1 = "), "{out}");
    assert!(
        csv.lines().nth(1).unwrap().contains(",non-smooth,"),
        "{csv}"
    );

    let (out, _) = stability(&[
        "--vehicle",
        "dual-axle",
        "--v-min-kmh",
        "40",
        "--v-max-kmh",
        "60",
    ]);
    assert!(out.contains("non-smooth (kingpin dry friction)"), "{out}");
}
