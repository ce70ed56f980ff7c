#[cfg(test)]
mod model {
    #[allow(unused_imports)]
    use crate::model::{LinearModel, ModeShape};
    use crate::stability::{self, CrossingKind};
    use crate::vehicles::truck::*;
    use crate::vehicles::FieldTable;
    #[allow(unused_imports)]
    use nalgebra::SVector;

    /// The strut's stiffness is the derivative of its force: central differences of the gas
    /// law at small and large strokes (where the spring stiffens several-fold).
    #[test]
    fn hps_stiffness_is_the_derivative_of_the_gas_force() {
        let hps = TruckSet::Full.params().hps;
        let x_max = (1.0 - 2.0 * Hps::MIN_VOLUME_FRAC) * hps.v0_m3 / hps.area_m2;
        let h = 1e-6;
        for i in 0..=20 {
            let x = x_max * f64::from(i) / 20.0;
            let fd = (hps.force_n(x + h) - hps.force_n(x - h)) / (2.0 * h);
            let k = hps.stiffness_npm(x);
            assert!((fd - k).abs() < 1e-6 * k, "x {x}: fd {fd} analytic {k}");
        }
        // large-stroke nonlinearity: at 80 % of the gas volume compressed, over 9x the
        // initial stiffness (n = 1.4: (1/0.2)^2.4 = 47)
        assert!(hps.stiffness_npm(x_max) > 9.0 * hps.stiffness_npm(0.0));
    }

    /// The static point carries the load (F(x_s) = load) and its stiffness is F'(x_s); loads
    /// below the pre-charge or past the stop are errors naming the limit.
    #[test]
    fn hps_static_point_carries_the_load() {
        let t = TruckSet::Full.params();
        let load = t.strut_load_n();
        let sp = t.hps.static_point(load).unwrap();
        assert!((t.hps.force_n(sp.stroke_m) - load).abs() < 1e-9 * load);
        assert!(
            (t.hps.stiffness_npm(sp.stroke_m) - sp.stiffness_npm).abs() < 1e-9 * sp.stiffness_npm
        );
        assert!(matches!(
            t.hps.static_point(0.5 * t.hps.p0_pa * t.hps.area_m2),
            Err(HpsError::ToppedOut { .. })
        ));
        assert!(matches!(
            t.hps.static_point(1e4 * load),
            Err(HpsError::BottomedOut { .. })
        ));
        // more gas, softer strut; more load, stiffer
        let soft = t
            .with_gas_volume(2.0 * t.hps.v0_m3)
            .operating_point()
            .unwrap();
        let base = t.operating_point().unwrap();
        let empty = TruckSet::Empty.params().operating_point().unwrap();
        assert!(soft.strut.stiffness_npm < base.strut.stiffness_npm);
        assert!(empty.strut.stiffness_npm < base.strut.stiffness_npm);
    }

    /// Every field is in the table, reads back what was set, and a value out of range or a
    /// charge the struts cannot carry is rejected naming the field.
    #[test]
    fn the_field_table_covers_every_field_and_checks_ranges() {
        let mut t = TruckSet::Full.params();
        t.validate().unwrap();
        crate::vehicles::fields::assert_table_covers_every_field(t);
        t.set("hps_p0_pa", 2.0e7).unwrap();
        assert!(matches!(
            t.validate(),
            Err(TruckFieldError::Strut(HpsError::ToppedOut { .. }))
        ));
    }

    #[test]
    fn a_is_affine_in_speed_with_the_stated_derivative() {
        let t = TruckSet::Full.params();
        let a0 = t.linearise(3.0, 2.0e4);
        let a1 = t.linearise(11.0, 2.0e4);
        let err = (a1 - a0 - t.dlinearise_dv() * 8.0).amax();
        assert!(err < 1e-9 * a0.amax(), "{err}");
    }

    /// Stiffness symmetric, gyroscopic part skew, tyre rows as the slip kinematics: checked on
    /// the second-order form recovered from A.
    #[test]
    fn structure_matches_the_equations() {
        let t = TruckSet::Full.params();
        let a = t.linearise(8.0, 0.0);
        let m = [t.i_k, t.i_k, t.i_phi, t.j_c, t.m_axle];
        for i in 0..N_DOF {
            for j in 0..N_DOF {
                let kij = -a[(N_DOF + i, j)] * m[i];
                let kji = -a[(N_DOF + j, i)] * m[j];
                assert!((kij - kji).abs() <= 1e-9 * kij.abs().max(1.0), "K {i}{j}");
            }
        }
        let h = t.spin_momentum(8.0);
        assert!((-a[(DPSI_L, DPHI)] * t.i_k - h).abs() < 1e-9 * h);
        assert!((-a[(DPHI, DPSI_L)] * t.i_phi + h).abs() < 1e-9 * h);
        assert_eq!(a[(A_L, DY)], -1.0 / t.sigma);
    }

    /// Full load has a shimmy onset in the haul-road speed range, of the in-phase wheel-yaw
    /// mode; the empty truck's is higher or absent; more gas moves the full truck's onset up.
    #[test]
    fn full_load_has_an_onset_that_more_gas_raises() {
        let onset = |t: &TruckParams| {
            stability::hopf_crossings(t, 0.0, 0.5, 25.0, 0.25, 1e-6)
                .unwrap()
                .iter()
                .find(|c| c.kind == CrossingKind::Onset)
                .map(|c| (c.speed_mps, c.shape))
        };
        let full = TruckSet::Full.params();
        let (v_full, shape) = onset(&full).expect("full load has an onset");
        assert_eq!(shape, ModeShape::InPhaseWheelYaw);
        assert!(v_full > 2.0 && v_full < 16.7, "{v_full}");
        let (v_more_gas, _) = onset(&full.with_gas_volume(3.0 * full.hps.v0_m3)).unwrap();
        assert!(v_more_gas > v_full + 0.5, "{v_more_gas} vs {v_full}");
        if let Some((v_empty, _)) = onset(&TruckSet::Empty.params()) {
            assert!(v_empty > v_full, "{v_empty} vs {v_full}");
        }
    }
}

#[cfg(test)]
mod tracker_tests {
    use crate::eigen::{self, SolveFloat};
    use crate::estimator::model_margin::{ModelMarginConfig, ModelMarginTracker};
    #[allow(unused_imports)]
    use crate::model::{LinearModel, ModeShape};
    use crate::stability::{self, CrossingKind};
    use crate::vehicles::truck::*;
    #[allow(unused_imports)]
    use nalgebra::SVector;

    /// The model-margin tracker runs on the truck (12 states) in both precisions: its onset
    /// above the current speed is the scan's Hopf crossing.
    #[test]
    fn the_tracker_finds_the_trucks_onset() {
        fn check<T: SolveFloat>() {
            let t = TruckSet::Full.params();
            let scan = stability::hopf_crossings(&t, 0.0, 0.5, 25.0, 0.25, 1e-7).unwrap();
            let onset = scan.iter().find(|c| c.kind == CrossingKind::Onset).unwrap();
            let mut tr = ModelMarginTracker::<T, TruckParams, N_STATES>::in_precision(
                t,
                ModelMarginConfig::default(),
            );
            let p = (0..200u16)
                .find_map(|k| tr.step(f64::from(k) * 1e-3, 2.0, 0.0))
                .expect("a cycle completes");
            let above = p.above.expect("an onset above 2 m/s");
            assert_eq!(above.kind, CrossingKind::Onset);
            // The crossing is as exact as the solver's Re s near it allows: the tolerance plus
            // the speed that the worst error of T's Re s (against f64, sampled within 1 mm/s of
            // the onset) amounts to at the f64 slope. In f32 that is ~1e-4 1/s at 0.08 1/s per
            // m/s, ~1e-3 m/s; in f64 nothing.
            let re = |v: f64| {
                let vals = eigen::eigenvalues_of::<T, N_STATES>(&t.linearise(v, 0.0)).unwrap();
                eigen::critical_oscillatory_mode(&vals).unwrap().re
            };
            let re64 = |v: f64| {
                let vals = eigen::eigenvalues_of::<f64, N_STATES>(&t.linearise(v, 0.0)).unwrap();
                eigen::critical_oscillatory_mode(&vals).unwrap().re
            };
            let slope = (re64(onset.speed_mps + 1e-3) - re64(onset.speed_mps - 1e-3)) / 2e-3;
            let noise = (-10..=10)
                .map(|k| onset.speed_mps + f64::from(k) * 1e-4)
                .map(|v| (re(v) - re64(v)).abs())
                .fold(0.0, f64::max);
            let tol = 2e-4 + 2.0 * noise / slope.abs();
            assert!(
                (above.speed_mps - onset.speed_mps).abs() < tol,
                "{}: {} vs {} (tolerance {tol:e} m/s)",
                T::NAME,
                above.speed_mps,
                onset.speed_mps
            );
            assert!(p.shimmy_found && p.slope_valid, "{}", T::NAME);
            assert_eq!(p.margin().v_crit_onset_mps, Some(above.speed_mps));
        }
        check::<f64>();
        check::<f32>();
    }
}
