#[cfg(test)]
mod model {
    #[allow(unused_imports)]
    use crate::model::{LinearModel, ModeShape};
    use crate::stability::{self, CrossingKind};
    use crate::vehicles::dual_axle::*;
    use crate::vehicles::FieldTable;
    #[allow(unused_imports)]
    use nalgebra::SVector;

    #[test]
    fn a_is_affine_in_speed_with_the_stated_derivative() {
        let t = DualAxleSet::Rated.params();
        let a0 = t.linearise(3.0, 2.0e3);
        let a1 = t.linearise(17.0, 2.0e3);
        let err = (a1 - a0 - t.dlinearise_dv() * 14.0).amax();
        assert!(err < 1e-9 * a0.amax(), "{err}");
    }

    /// Stiffness symmetric, gyroscopic part skew, a rigid linkage (every rod infinitely stiff
    /// against the gear) steering axle 2 at n_2 times axle 1: the transition rod's term
    /// carries the steer ratio.
    #[test]
    fn structure_matches_the_equations() {
        let t = DualAxleSet::Rated.params();
        let a = t.linearise(12.0, 0.0);
        for i in 0..N_DOF {
            for j in 0..N_DOF {
                let kij = -a[(N_DOF + i, j)] * t.inertia(i);
                let kji = -a[(N_DOF + j, i)] * t.inertia(j);
                assert!((kij - kji).abs() <= 1e-9 * kij.abs().max(1.0), "K {i}{j}");
            }
        }
        let h = t.spin_momentum(12.0);
        for (w, r, _, _) in WHEELS {
            assert!((-a[(N_DOF + w, N_DOF + r)] * t.i_k - h).abs() < 1e-9 * h);
            assert!((a[(N_DOF + r, N_DOF + w)] * t.i_phi - h).abs() < 1e-9 * h);
        }
        // the kinematic steer pattern (every wheel of axle 1 at 1, of axle 2 at n_2, the
        // pitman arm at 1, the rocker at n_2) stretches no rod: only the gear's spring holds it
        let n2 = t.operating_point().n_2;
        let q = [1.0, 1.0, n2, n2, 0.0, 0.0, 1.0, n2];
        let k = t.stiffness();
        for (i, row) in k.iter().enumerate() {
            let f: f64 = row.iter().zip(q).map(|(kij, qj)| kij * qj).sum();
            let want = if i == THETA_G { t.k_g } else { 0.0 };
            assert!((f - want).abs() < 1e-6 * t.k_g, "row {i}: {f}");
        }
    }

    /// Every field is in the table, reads back what was set, and a value out of range or a
    /// second axle behind the bogie is rejected naming the field.
    #[test]
    fn the_field_table_covers_every_field_and_checks_ranges() {
        let mut t = DualAxleSet::Rated.params();
        t.validate().unwrap();
        crate::vehicles::fields::assert_table_covers_every_field(t);
        t.set("axle_spacing", 4.0).unwrap();
        t.set("wheelbase", 3.0).unwrap();
        assert!(matches!(
            t.validate(),
            Err(DualAxleFieldError::AxleOrder { .. })
        ));
    }

    /// The named set has a shimmy onset of the in-phase wheel-yaw mode in the truck's speed
    /// range, and the paper's directions hold in the linear model: a stiffer transition rod,
    /// a smaller pneumatic trail or caster trail raise it.
    #[test]
    fn the_onset_moves_in_the_papers_directions() {
        let onset = |t: &DualAxleParams| {
            stability::hopf_crossings(t, 0.0, 1.0, 40.0, 0.5, 1e-7)
                .unwrap()
                .iter()
                .find(|c| c.kind == CrossingKind::Onset)
                .map(|c| (c.speed_mps, c.shape))
        };
        let t = DualAxleSet::Rated.params();
        let (v0, shape) = onset(&t).expect("an onset");
        assert_eq!(shape, ModeShape::InPhaseWheelYaw);
        assert!(v0 > 5.0 && v0 < 30.0, "{v0}");
        for (name, f) in [("k_t", 1.2), ("t_p", 0.8), ("e", 0.8)] {
            let mut u = t;
            u.set(name, t.get(name).unwrap() * f).unwrap();
            let (v, _) = onset(&u).expect("an onset");
            assert!(v > v0 + 0.1, "{name} x{f}: {v} vs {v0}");
        }
    }
}

#[cfg(test)]
mod meter_signal_tests {
    #[allow(unused_imports)]
    use crate::model::{LinearModel, ModeShape};
    use crate::vehicles::dual_axle::*;
    #[allow(unused_imports)]
    use nalgebra::SVector;

    /// The shimmy mode's gain (per unit modal energy) in a signal with weights `w` on the
    /// axles' in-phase yaw, and each oscillatory mode's gain relative to it, at the meter's
    /// reference speed: (frequency Hz, share).
    fn shares(t: &DualAxleParams, w: [f64; 2]) -> (f64, heapless::Vec<(f64, f64), 10>) {
        let v = t.meter_reference_speed_mps();
        let a = t.linearise(v, 0.0);
        let vals = crate::eigen::eigenvalues(&a).unwrap();
        let shimmy =
            crate::stability::select_mode(t, &a, &vals, crate::stability::ModeSelect::Shimmy)
                .unwrap()
                .eigenvalue();
        let gain = |l: nalgebra::Complex<f64>| {
            let x = crate::eigen::eigenvector(&a, l).unwrap();
            let e: f64 = (0..N_DOF)
                .map(|i| t.inertia(i) * x[N_DOF + i].norm_sqr())
                .sum();
            ((x[PSI_1L] + x[PSI_1R]) * (0.5 * w[0]) + (x[PSI_2L] + x[PSI_2R]) * (0.5 * w[1])).norm()
                / libm::sqrt(e)
        };
        let g_s = gain(shimmy);
        let mut out = heapless::Vec::new();
        for l in vals
            .iter()
            .filter(|l| l.im > 0.0 && crate::eigen::is_oscillatory(**l))
        {
            out.push((l.im / (2.0 * core::f64::consts::PI), gain(*l) / g_s))
                .unwrap();
        }
        (g_s, out)
    }

    /// The meter's weights come from the model's mode shapes: on the named set the lightly
    /// damped ~15 Hz mode (the axles yawing against each other, as large as the shimmy on
    /// axle 1 alone) falls below a tenth of the shimmy's share, no other mode gains more than
    /// 0.02 of share over axle 1 alone (the 93-Hz linkage mode gains 0.018, outside the meter's
    /// band), a shimmy reads as axle 1's in-phase yaw, and the output row is the weights.
    #[test]
    fn the_weights_isolate_the_shimmy_mode() {
        let t = DualAxleSet::Rated.params();
        let w = t.meter_weights();
        assert!(w[0] > 0.0 && w[1] > 0.0, "{w:?}");
        let ((g_w, with), (g_1, alone)) = (shares(&t, w), shares(&t, [1.0, 0.0]));
        // |w . u_s| = |u_s1| up to the shape's small imaginary part (the weights are real)
        assert!((g_w / g_1 - 1.0).abs() < 0.01, "{g_w} vs {g_1}");
        let near15 = |s: &[(f64, f64)]| {
            s.iter()
                .find(|(f, _)| (13.0..17.0).contains(f))
                .map(|p| p.1)
                .unwrap()
        };
        std::println!(
            "weights {w:?} at {:.2} km/h; shares (Hz, modal filter, axle 1 alone): {:?}",
            t.meter_reference_speed_mps() * 3.6,
            with.iter()
                .zip(alone.iter())
                .map(|(a, b)| (a.0, a.1, b.1))
                .collect::<heapless::Vec<_, 10>>()
        );
        assert!(near15(&alone) > 0.8, "{alone:?}");
        assert!(near15(&with) < 0.1, "{with:?}");
        for ((f, g), (_, g1)) in with.iter().zip(alone.iter()) {
            assert!(*g <= g1 + 0.02, "{f} Hz: {g} vs axle 1 alone {g1}");
        }
        let c = t.wheel_yaw_output();
        assert_eq!(
            [c[PSI_1L], c[PSI_1R], c[PSI_2L], c[PSI_2R]],
            [0.5 * w[0], 0.5 * w[0], 0.5 * w[1], 0.5 * w[1]]
        );
        assert_eq!(c.iter().filter(|x| **x != 0.0).count(), 4);
        // the weights follow the model: a softer transition rod changes the shapes and them
        let mut soft = t;
        soft.k_t *= 0.5;
        let ws = soft.meter_weights();
        assert!((ws[1] - w[1]).abs() > 1e-3, "{ws:?} vs {w:?}");
    }
}

#[cfg(test)]
mod tracker_tests {
    use crate::eigen::SolveFloat;
    use crate::estimator::model_margin::{ModelMarginConfig, ModelMarginTracker};
    #[allow(unused_imports)]
    use crate::model::{LinearModel, ModeShape};
    use crate::stability::{self, CrossingKind};
    use crate::vehicles::dual_axle::*;
    #[allow(unused_imports)]
    use nalgebra::SVector;

    /// The model-margin tracker runs on the dual-axle truck (20 states) in both precisions:
    /// its onset above the current speed is the scan's Hopf crossing.
    #[test]
    fn the_tracker_finds_the_onset() {
        fn check<T: SolveFloat>() {
            let t = DualAxleSet::Rated.params();
            let scan = stability::hopf_crossings(&t, 0.0, 1.0, 40.0, 0.5, 1e-7).unwrap();
            let onset = scan.iter().find(|c| c.kind == CrossingKind::Onset).unwrap();
            let mut tr = ModelMarginTracker::<T, DualAxleParams, N_STATES>::in_precision(
                t,
                ModelMarginConfig::default(),
            );
            let p = (0..400u16)
                .find_map(|k| tr.step(f64::from(k) * 1e-3, 8.0, 0.0))
                .expect("a cycle completes");
            let above = p.above.expect("an onset above 8 m/s");
            assert_eq!(above.kind, CrossingKind::Onset);
            assert!(
                (above.speed_mps - onset.speed_mps).abs() < 2e-3,
                "{}: {} vs {}",
                T::NAME,
                above.speed_mps,
                onset.speed_mps
            );
            assert!(p.shimmy_found, "{}", T::NAME);
        }
        check::<f64>();
        check::<f32>();
    }
}
