#[cfg(test)]
mod model {
    use crate::eigen;
    #[allow(unused_imports)]
    use crate::model::{LinearModel, ModeShape};
    use crate::stability::{self, CrossingKind};
    use crate::vehicles::trailer::*;
    use crate::vehicles::FieldTable;
    #[allow(unused_imports)]
    use nalgebra::SVector;

    fn onset(p: &TrailerParams, c: f64) -> Option<stability::HopfCrossing> {
        stability::hopf_crossings(p, c, 1.0, 70.0, 0.5, 1e-7)
            .unwrap()
            .iter()
            .find(|x| x.kind == CrossingKind::Onset)
            .copied()
    }

    /// Every field is in the table, reads back what was set, and a value out of range or a
    /// tail-heavy centre of gravity is rejected naming the field.
    #[test]
    fn the_field_table_covers_every_field_and_checks_ranges() {
        let mut t = TrailerSet::Caravan.params();
        t.validate().unwrap();
        crate::vehicles::fields::assert_table_covers_every_field(t);
        t.set("a", 7.0).unwrap();
        let e = t.validate().unwrap_err();
        assert!(matches!(e, TrailerFieldError::TailHeavy { .. }), "{e}");
        assert!(e.to_string().contains("field `a`"), "{e}");
    }

    #[test]
    fn a_is_affine_in_speed_with_the_stated_derivative() {
        let t = TrailerSet::Caravan.params();
        let a0 = t.linearise(3.0, 2.0e4);
        let a1 = t.linearise(31.0, 2.0e4);
        let err = (a1 - a0 - t.dlinearise_dv() * 28.0).amax();
        assert!(err < 1e-12 * a0.amax(), "{err}");
    }

    /// The mass and stiffness recovered from A: `M A_rows = -K` and the damper column is
    /// `M^-1 [0, -l_d]`; checked by multiplying back with M built from its definition.
    #[test]
    fn structure_matches_the_equations() {
        let t = TrailerSet::Caravan.params();
        let c = 3.0e4;
        let a = t.linearise(20.0, c);
        let mass = nalgebra::Matrix2::new(t.m, -t.m * t.a, -t.m * t.a, t.i_hitch());
        let rows = nalgebra::Matrix2x5::from_fn(|i, j| a[(N_DOF + i, j)]);
        let q = mass * rows;
        // generalised forces per unit state: -K, -D, G
        let ca = t.cornering_stiffness();
        let want = nalgebra::Matrix2x5::from_row_slice(&[
            -t.k_y,
            0.0,
            -t.c_y,
            0.0,
            ca,
            0.0,
            0.0,
            0.0,
            -c * t.l_d * t.l_d,
            -t.l * ca,
        ]);
        assert!((q - want).amax() < 1e-9 * want.amax(), "{q} vs {want}");
        let bd =
            mass * nalgebra::Vector2::new(t.damper_force_input()[DY], t.damper_force_input()[DPSI]);
        assert!((bd - nalgebra::Vector2::new(0.0, -t.l_d)).amax() < 1e-12);
        assert!((a[(ALPHA, DPSI)] - t.l / t.sigma).abs() < 1e-12 * t.l / t.sigma);
    }

    /// The reference caravan sways (0.5-1.5 Hz, yaw-dominated) from a critical speed on
    /// European roads: stable below, unstable above; the sway damper raises it.
    #[test]
    fn the_caravan_has_a_sway_onset_that_the_damper_raises() {
        let t = TrailerSet::Caravan.params();
        let x = onset(&t, 0.0).expect("an onset below 252 km/h");
        assert_eq!(x.shape, ModeShape::Sway);
        assert!(x.freq_hz > 0.5 && x.freq_hz < 1.5, "{}", x.freq_hz);
        assert!(x.speed_mps > 20.0 && x.speed_mps < 40.0, "{}", x.speed_mps);
        let below = stability::critical_mode_at(&t, x.speed_mps - 1.0, 0.0).unwrap();
        let above = stability::critical_mode_at(&t, x.speed_mps + 1.0, 0.0).unwrap();
        assert!(below.re < 0.0 && above.re > 0.0);
        let damped = onset(&t, t.damper_of_zeta(0.05)).map_or(f64::INFINITY, |x| x.speed_mps);
        assert!(damped > x.speed_mps + 2.0, "{damped} vs {}", x.speed_mps);
        // the shimmy selector of the family picks the sway mode
        let sway = stability::mode_at(&t, x.speed_mps, 0.0, stability::ModeSelect::Shimmy).unwrap();
        assert!((sway.freq_hz - x.freq_hz).abs() < 1e-6);
    }

    /// The closed form of the lag-free, undamped 2-DOF limit (`docs/trailer.md`): the quartic's
    /// Hurwitz determinant is `u^2 C_a^2 k_y l D (k_y l D + C_a I_ax)` with `u = 1/V`,
    /// `D = m a b - I_z` and `I_ax = I_z + m b^2`, so stability does not depend on speed and a
    /// trailer with `I_z > m a b` needs `k_y > C_a I_ax / (l |D|)`. Checked on the eigenvalues
    /// with sigma = 1 mm and no damping, 2 % on either side of that stiffness, at three speeds.
    #[test]
    fn the_lag_free_limit_has_the_closed_form_hitch_stiffness_threshold() {
        let mut t = TrailerSet::Caravan.params();
        t.sigma = 1e-3;
        t.c_y = 0.0;
        let b = t.l - t.a;
        let d = t.m * t.a * b - t.i_z;
        assert!(d < 0.0);
        let i_ax = t.i_z + t.m * b * b;
        let k_star = t.cornering_stiffness() * i_ax / (t.l * d.abs());
        for (factor, stable) in [(0.98, false), (1.02, true)] {
            t.k_y = factor * k_star;
            for v in [10.0, 25.0, 40.0] {
                let g = stability::critical_mode_at(&t, v, 0.0).unwrap().re;
                assert_eq!(g < 0.0, stable, "k_y {factor} k*, V {v}: growth {g}");
            }
        }
    }

    /// The critical speed by Routh-Hurwitz on the characteristic polynomial, built without
    /// any eigen-solve: `p(s) = (sigma s + V) det Q(s) - r(s)^T adj Q(s) g` with
    /// `Q = M s^2 + D s + K`, `g = C_a [1, -l]` and `r(s) = [-s, V + l s]` (the lag equation in
    /// Laplace form). Its Hurwitz sign change, found by bisection, must be the eigenvalue
    /// crossing to 1e-6 relative, without and with the damper.
    #[test]
    fn routh_hurwitz_on_the_characteristic_polynomial_gives_the_same_critical_speed() {
        let t = TrailerSet::Caravan.params();
        for c in [0.0, t.damper_of_zeta(0.05)] {
            let eig = onset(&t, c).unwrap().speed_mps;
            let stable = |v: f64| hurwitz_stable(&char_poly(&t, v, c));
            assert!(stable(eig - 0.5) && !stable(eig + 0.5), "c {c}");
            let (mut lo, mut hi) = (eig - 0.5, eig + 0.5);
            for _ in 0..60 {
                let mid = 0.5 * (lo + hi);
                if stable(mid) {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            let rh = 0.5 * (lo + hi);
            assert!(
                (rh - eig).abs() < 1e-6 * eig,
                "c {c}: Routh-Hurwitz {rh}, eigen {eig}"
            );
        }
    }

    /// Polynomial coefficients, lowest power first.
    fn mul(p: &[f64], q: &[f64]) -> [f64; 7] {
        let mut r = [0.0; 7];
        for (i, a) in p.iter().enumerate() {
            for (j, b) in q.iter().enumerate() {
                r[i + j] += a * b;
            }
        }
        r
    }

    fn char_poly(t: &TrailerParams, v: f64, c: f64) -> [f64; 7] {
        let ca = t.cornering_stiffness();
        // Q(s) entries as polynomials [s^0, s^1, s^2]
        let q00 = [t.k_y, t.c_y, t.m];
        let q01 = [0.0, 0.0, -t.m * t.a];
        let q11 = [0.0, c * t.l_d * t.l_d, t.i_hitch()];
        let det: Vec<f64> = mul(&q00, &q11)
            .iter()
            .zip(mul(&q01, &q01))
            .map(|(x, y)| x - y)
            .collect();
        let mut p = mul(&[v, t.sigma], &det[..5]);
        // r^T adj(Q) g with adj(Q) = [[q11, -q01], [-q01, q00]], g = ca [1, -l], r = [-s, V + l s]
        let g0 = [ca];
        let g1 = [-t.l * ca];
        let adj_g0: Vec<f64> = mul(&q11, &g0)
            .iter()
            .zip(mul(&q01, &g1))
            .map(|(x, y)| x - y)
            .collect();
        let adj_g1: Vec<f64> = mul(&q00, &g1)
            .iter()
            .zip(mul(&q01, &g0))
            .map(|(x, y)| x - y)
            .collect();
        let term0 = mul(&[0.0, -1.0], &adj_g0[..3]);
        let term1 = mul(&[v, t.l], &adj_g1[..3]);
        for i in 0..7 {
            p[i] -= term0[i] + term1[i];
        }
        p
    }

    /// Routh's criterion: every entry of the first column has the leading coefficient's sign.
    fn hurwitz_stable(p: &[f64; 7]) -> bool {
        let deg = (0..7).rev().find(|&i| p[i] != 0.0).unwrap();
        let coef: Vec<f64> = (0..=deg).rev().map(|i| p[i]).collect();
        let mut r0: Vec<f64> = coef.iter().step_by(2).copied().collect();
        let mut r1: Vec<f64> = coef.iter().skip(1).step_by(2).copied().collect();
        let sign = coef[0].signum();
        if r0[0] * sign <= 0.0 {
            return false;
        }
        for _ in 0..deg {
            if r1.is_empty() || r1[0] * sign <= 0.0 {
                return false;
            }
            let next: Vec<f64> = (0..r0.len() - 1)
                .map(|j| {
                    let x = r0.get(j + 1).copied().unwrap_or(0.0);
                    let y = r1.get(j + 1).copied().unwrap_or(0.0);
                    (r1[0] * x - r0[0] * y) / r1[0]
                })
                .collect();
            r0 = r1;
            r1 = next;
            if r1.is_empty() {
                break;
            }
        }
        true
    }

    /// The eigenvalues are those of the polynomial's roots: its value at every eigenvalue is
    /// zero to rounding (relative to the size of its terms).
    #[test]
    fn the_characteristic_polynomial_vanishes_at_the_eigenvalues() {
        let t = TrailerSet::Caravan.params();
        for v in [5.0, 28.0, 45.0] {
            let p = char_poly(&t, v, 1.0e4);
            for l in eigen::eigenvalues(&t.linearise(v, 1.0e4)).unwrap() {
                let (mut val, mut scale, mut pow) = (
                    nalgebra::Complex::new(0.0, 0.0),
                    0.0,
                    nalgebra::Complex::new(1.0, 0.0),
                );
                for c in p {
                    val += pow * c;
                    scale += (pow * c).norm();
                    pow *= l;
                }
                assert!(val.norm() < 1e-10 * scale, "V {v}, {l}: {val} of {scale}");
            }
        }
    }

    /// Diboll & Hagen's groups: scaling the trailer (masses x2.7, lengths x1.6) and choosing
    /// the hitch stiffness and the speed that keep s omega / V and mu G z / V^2 leaves the
    /// damping ratio of every mode unchanged (the dimensionless problem is the same).
    #[test]
    fn the_dimensionless_groups_make_similar_trailers_behave_alike() {
        let t = TrailerSet::Caravan.params();
        let v = 30.0;
        let (fm, fl) = (2.7, 1.6);
        let mut s = t;
        s.m *= fm;
        s.i_z *= fm * fl * fl;
        s.l *= fl;
        s.a *= fl;
        s.sigma *= fl;
        s.l_d *= fl;
        // same energy term: V^2 scales with a; same Strouhal: omega scales with V / l
        let vs = v * libm::sqrt(fl);
        s.k_y = s.m * libm::pow(t.strouhal(v) * vs / s.l, 2.0);
        // same lateral damping ratio c_y / (2 sqrt(k_y m)) and same damper ratio
        s.c_y = t.c_y / libm::sqrt(t.k_y * t.m) * libm::sqrt(s.k_y * s.m);
        let c = t.damper_of_zeta(0.03);
        let cs = s.damper_of_zeta(0.03);
        assert!((s.strouhal(vs) - t.strouhal(v)).abs() < 1e-12);
        assert!((s.energy_term(vs) - t.energy_term(v)).abs() < 1e-12);
        let z = |p: &TrailerParams, v: f64, c: f64| {
            let mut zs: Vec<f64> = eigen::eigenvalues(&p.linearise(v, c))
                .unwrap()
                .iter()
                .filter(|l| l.im > 0.0)
                .map(|l| -l.re / l.norm())
                .collect();
            zs.sort_by(f64::total_cmp);
            zs
        };
        let (a, b) = (z(&t, v, c), z(&s, vs, cs));
        assert_eq!(a.len(), b.len());
        for (x, y) in a.iter().zip(&b) {
            assert!((x - y).abs() < 1e-9, "{a:?} vs {b:?}");
        }
    }
}

#[cfg(test)]
mod tracker_tests {
    use crate::eigen::SolveFloat;
    use crate::estimator::model_margin::{ModelMarginConfig, ModelMarginTracker};
    #[allow(unused_imports)]
    use crate::model::{LinearModel, ModeShape};
    use crate::stability::{self, CrossingKind};
    use crate::vehicles::trailer::*;
    #[allow(unused_imports)]
    use nalgebra::SVector;

    /// The model-margin tracker runs on the trailer (5 states) in both precisions: its onset
    /// above the current speed is the scan's Hopf crossing, of the sway mode.
    #[test]
    fn the_tracker_finds_the_trailers_onset() {
        fn check<T: SolveFloat>() {
            let t = TrailerSet::Caravan.params();
            let scan = stability::hopf_crossings(&t, 0.0, 1.0, 70.0, 0.5, 1e-7).unwrap();
            let onset = scan.iter().find(|c| c.kind == CrossingKind::Onset).unwrap();
            let mut tr = ModelMarginTracker::<T, TrailerParams, N_STATES>::in_precision(
                t,
                ModelMarginConfig::default(),
            );
            let p = (0..200u16)
                .find_map(|k| tr.step(f64::from(k) * 1e-3, 20.0, 0.0))
                .expect("a cycle completes");
            let above = p.above.expect("an onset above 20 m/s");
            assert_eq!(above.kind, CrossingKind::Onset);
            assert!(
                (above.speed_mps - onset.speed_mps).abs() < 2e-3,
                "{}: {} vs {}",
                T::NAME,
                above.speed_mps,
                onset.speed_mps
            );
            assert!(p.shimmy_found && p.slope_valid, "{}", T::NAME);
        }
        check::<f64>();
        check::<f32>();
    }
}
