#[cfg(test)]
mod params {
    #[allow(unused_imports)]
    use crate::model::{LinearModel, ModeShape};
    use crate::vehicles::car::*;
    #[allow(unused_imports)]
    use nalgebra::SVector;

    #[test]
    fn named_sets_differ_only_where_documented() {
        let n = ParamSet::Nominal.params();
        let g = ParamSet::Gentle.params();
        let h = ParamSet::Hard.params();
        for p in Param::ALL {
            if p != Param::CSw {
                assert_eq!(n.get(p), g.get(p), "{}", p.name());
            }
            if p != Param::KD {
                assert_eq!(n.get(p), h.get(p), "{}", p.name());
            }
        }
        assert_eq!(g.c_sw, 2.0);
        assert_eq!(h.k_d, 0.5e4);
        assert!((n.k_tr - 194_045.0).abs() < 1.0);
    }

    #[test]
    fn names_round_trip_and_validation_names_the_offender() {
        for p in Param::ALL {
            assert_eq!(Param::from_name(p.name()), Some(p));
        }
        for s in ParamSet::ALL {
            assert_eq!(ParamSet::from_name(s.name()), Some(s));
            assert!(s.params().validate().is_ok());
        }
        let bad = PlantParams::nominal().with(Param::Sigma, -0.1);
        assert_eq!(bad.validate(), Err((Param::Sigma, -0.1)));
        let nan = PlantParams::nominal().with(Param::KD, f64::NAN);
        assert!(matches!(nan.validate(), Err((Param::KD, _))));
    }

    #[test]
    fn tyre_slope_at_origin_is_cornering_stiffness() {
        let p = PlantParams::nominal();
        // d/da [D sin(C atan(B a))] at a = 0 is D C B.
        let slope = p.tyre_peak_force() * p.c_s * p.tyre_stiffness_factor();
        assert!((slope - p.c_a).abs() < 1e-9 * p.c_a);
    }
}

#[cfg(test)]
mod linear {
    #[allow(unused_imports)]
    use crate::model::{LinearModel, ModeShape};
    use crate::vehicles::car::ParamSet;
    use crate::vehicles::car::*;
    #[allow(unused_imports)]
    use nalgebra::SVector;

    #[test]
    fn kinematic_rows_are_identity_blocks_and_v0_has_no_tyre_stiffness() {
        let p = ParamSet::Nominal.params();
        let a = linearise(&p, 0.0, 0.0);
        for i in 0..N_DOF {
            for j in 0..N_STATES {
                let want = if j == N_DOF + i { 1.0 } else { 0.0 };
                assert_eq!(a[(i, j)], want, "row {i} col {j}");
            }
        }
        // At V = 0 the tyre rows have no V/sigma terms and there is no gyroscopic coupling.
        assert_eq!(a[(A_L, PSI_L)], 0.0);
        assert_eq!(a[(A_L, A_L)], 0.0);
        assert_eq!(a[(DPSI_L, DPHI)], 0.0);
        assert_eq!(a[(DPHI, DPSI_L)], 0.0);
        assert_eq!(a[(A_L, DPSI_L)], p.e / p.sigma);
    }

    #[test]
    fn a_is_affine_in_speed_with_the_stated_derivative() {
        let p = ParamSet::Hard.params();
        let a0 = linearise(&p, 10.0, 500.0);
        let a1 = linearise(&p, 13.0, 500.0);
        let d = dlinearise_dv(&p);
        let err = (a1 - a0 - d * 3.0).amax();
        assert!(err < 1e-9, "{err}");
    }

    #[test]
    fn second_order_structure_matches_the_reference_equations() {
        let p = ParamSet::Nominal.params();
        let v = 20.0;
        let so = second_order(&p, v, 0.0);
        // K symmetric, gyroscopic part skew.
        assert_eq!(so.k, so.k.transpose());
        let h = p.i_p * v / p.r;
        assert_eq!(so.c[(0, 2)], h);
        assert_eq!(so.c[(2, 0)], -h);
        // The in-phase rigid steering motion (psi_L = psi_R = theta_sw / i_s) has no mechanical
        // stiffness: only the tyres hold it.
        let q = nalgebra::Vector4::new(1.0, 1.0, 0.0, p.i_s);
        assert!((so.k * q).amax() < 1e-9);
    }

    #[test]
    fn viscous_damper_adds_c_lt2_over_4_to_the_four_wheel_entries() {
        let p = ParamSet::Nominal.params();
        let c = 1234.0;
        let d = second_order(&p, 15.0, c).c - second_order(&p, 15.0, 0.0).c;
        let want = c * p.l_t * p.l_t / 4.0;
        for (i, j) in [(0, 0), (0, 1), (1, 0), (1, 1)] {
            assert!((d[(i, j)] - want).abs() < 1e-12 * want);
        }
        assert!((d.abs().sum() - 4.0 * want).abs() < 1e-12 * want);
        // Same as feeding F_d = c v_d through the damper input column.
        let a_c = linearise(&p, 15.0, c);
        let a_0 = linearise(&p, 15.0, 0.0);
        let b = damper_force_input(&p);
        let mut x = SVector::<f64, N_STATES>::zeros();
        x[DPSI_L] = 0.3;
        x[DPSI_R] = -0.1;
        let via_input = a_0 * x + b * (c * damper_stroke_rate_mps(&p, &x));
        assert!((a_c * x - via_input).amax() < 1e-9);
    }
}
