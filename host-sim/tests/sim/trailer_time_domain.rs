//! The trailer (`docs/trailer.md`) through the family's simulator: its `SimModel` plant (the
//! saturating tyres, the MR sway damper at the hitch) grows just above the linear model's sway
//! onset and decays just below it at the eigenvalues' rate; and the margin estimator (the mode
//! meter slowed ten times to the 0.64 Hz sway, the model tracker on the trailer's linear model)
//! warns before the onset on a speed ramp where the plant differs from the model, and not at
//! 70 % of the onset at constant speed.
use shimmy_core::params::kmh_to_mps;
use shimmy_core::stability::{self, CrossingKind, DEFAULT_TOL_MPS};
use shimmy_core::trailer::{TrailerParams, TrailerSet, PSI};
use shimmy_sim::model::family::{FamilyVehicle, SimModel, SimPlant};
use shimmy_sim::model::plant::{Damper, Inputs, Method};
use shimmy_sim::model::trailer_plant::trailer_vehicle;
use shimmy_sim::sim::margin_run::{self, onset_kmh, MarginScenario};

fn onset_mps(t: &TrailerParams, c: f64) -> f64 {
    stability::hopf_crossings(t, c, 1.0, 70.0, 0.5, DEFAULT_TOL_MPS)
        .unwrap()
        .iter()
        .find(|x| x.kind == CrossingKind::Onset)
        .unwrap()
        .speed_mps
}

/// Growth rate of the family plant's yaw envelope at `v_mps` with `damper` from a 0.1 deg
/// start: log ratio of the peak |psi| over the last and the first 6 s after 10 s, 1/s.
fn growth(t: &TrailerParams, damper: Damper, v_mps: f64) -> f64 {
    let mut p = t.plant(damper, Method::default());
    p.set_wheel_yaw(0.1_f64.to_radians(), 0.1_f64.to_radians());
    let u = Inputs {
        speed_mps: v_mps,
        ..Inputs::default()
    };
    let (settle, dur, win, dt) = (10.0, 60.0, 6.0, 1e-2);
    let (mut first, mut last) = (0.0_f64, 0.0_f64);
    for k in 1..=(dur / dt) as usize {
        p.advance(dt, &u).unwrap();
        let (tk, yaw) = (k as f64 * dt, p.state()[PSI].abs());
        if tk > settle && tk <= settle + win {
            first = first.max(yaw);
        }
        if tk > dur - win {
            last = last.max(yaw);
        }
    }
    (last / first).ln() / (dur - win - settle)
}

/// The family plant's Hopf speed: 3 km/h on either side of the linear onset its envelope
/// decays and grows at the rate of the eigenvalues (10 % + 2e-3 1/s), without damper and with
/// a viscous sway damper of damping ratio 0.05 at the hitch.
#[test]
fn the_family_plant_grows_above_and_decays_below_the_linear_onset() {
    let t = TrailerSet::Caravan.params();
    for c in [0.0, t.damper_of_zeta(0.05)] {
        let damper = if c == 0.0 {
            Damper::None
        } else {
            Damper::Viscous(c)
        };
        let onset = onset_mps(&t, c);
        for dv_kmh in [-3.0, 3.0] {
            let v = onset + kmh_to_mps(dv_kmh);
            let g = growth(&t, damper, v);
            let re = stability::critical_mode_at(&t, v, c).unwrap().re;
            println!(
                "damper {c:.0} N s/m, onset {:.3} km/h, at {:+} km/h: envelope {g:.5} 1/s, \
                 eigenvalue {re:.5} 1/s",
                onset * 3.6,
                dv_kmh
            );
            assert_eq!(g > 0.0, dv_kmh > 0.0, "{dv_kmh} km/h: {g}");
            assert!((g - re).abs() < 0.1 * re.abs() + 2e-3, "{g} vs {re}");
        }
    }
}
