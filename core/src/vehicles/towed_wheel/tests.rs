#[cfg(test)]
mod model {
    use crate::eigen;
    use crate::model::{LinearModel, ModeShape};
    use crate::stability::{self, CrossingKind};
    use crate::vehicles::towed_wheel::*;
    use nalgebra::Complex;

    type C = Complex<f64>;

    /// The characteristic function of the undiscretised delay equation, Takács, Orosz & Stépán
    /// 2009, Eq. (31), in their dimensionless terms (time over the patch's delay `2a / V`,
    /// `V = v / (2 a omega_n)`, `L = l / a`, `Sigma = sigma / a`, `zeta = omega_n b / (2k)`):
    /// no collocation, an independent check of `linear.rs`.
    fn characteristic(lam: C, p: &TowedWheelParams, v_mps: f64) -> C {
        let (vv, ll, ss, z) = (
            p.dimensionless_speed(v_mps),
            p.l / p.a,
            p.sigma / p.a,
            p.damping_ratio(),
        );
        let kk = p.stiffness_factor();
        let e = (-lam).exp();
        let poly = lam * lam * lam * (ss * vv * vv)
            + lam * lam * (2.0 * vv * (vv + ss * z))
            + lam * (ss + 4.0 * z * vv)
            + 2.0;
        let memory = (lam * (ll - 1.0) + 2.0 - (lam * (ll + 1.0) + 2.0) * e) * 2.0 / (lam * lam);
        let c = ll - 1.0 - ss;
        let rest = (lam * (2.0 * ss * z * vv) + ss + 4.0 * z * vv) * c
            + (lam * (2.0 * ss * z * vv) + ss - 4.0 * z * vv) * e * (ll + 1.0 + ss);
        let damping = (lam * ss + 2.0) * (4.0 * z * vv * ll * (1.0 + ss));
        poly - (memory + rest) * (c / kk) - damping / kk
    }

    /// A root of [`characteristic`] near `s0` (1/s), by Newton's method with a difference
    /// derivative; `None` if it does not converge.
    fn root_near(s0: C, p: &TowedWheelParams, v_mps: f64) -> Option<C> {
        let tau = 2.0 * p.a / v_mps;
        let mut lam = s0 * tau;
        for _ in 0..50 {
            let f = characteristic(lam, p, v_mps);
            let h = 1e-7 * (1.0 + lam.norm());
            let df = (characteristic(lam + h, p, v_mps) - f) / h;
            let step = f / df;
            lam -= step;
            if step.norm() < 1e-12 * (1.0 + lam.norm()) {
                return Some(lam / tau);
            }
        }
        None
    }

    /// The shimmy mode of the collocated model: the wheel-yaw mode with the largest real part.
    fn shimmy(p: &TowedWheelParams, v_mps: f64) -> C {
        let a = p.linearise(v_mps, 0.0);
        let vals = eigen::eigenvalues(&a).unwrap();
        vals.iter()
            .filter(|s| s.im > 0.0)
            .filter(|s| {
                let v = eigen::eigenvector(&a, **s).unwrap();
                p.classify(&v).shape == ModeShape::InPhaseWheelYaw
            })
            .copied()
            .max_by(|x, y| x.re.total_cmp(&y.re))
            .unwrap()
    }

    /// The speed (m/s) where the delay equation's root continued from the collocated shimmy
    /// mode crosses the imaginary axis between `lo` and `hi` (stable at `lo`), by bisection.
    fn onset_of_delay_equation(p: &TowedWheelParams, mut lo: f64, mut hi: f64) -> f64 {
        let re = |v: f64| root_near(shimmy(p, v), p, v).unwrap().re;
        assert!(re(lo) < 0.0 && re(hi) > 0.0);
        while hi - lo > 1e-6 {
            let mid = 0.5 * (lo + hi);
            if re(mid) < 0.0 {
                lo = mid
            } else {
                hi = mid
            }
        }
        0.5 * (lo + hi)
    }

    #[test]
    fn the_field_table_covers_every_field_and_checks_ranges() {
        crate::vehicles::fields::assert_table_covers_every_field(TowedWheelSet::Benchmark.params());
    }

    /// The named set is the rig of Table 1: its natural frequency and damping ratio.
    #[test]
    fn the_benchmark_has_the_rigs_frequency_and_damping() {
        let p = TowedWheelSet::Benchmark.params();
        assert!((p.natural_frequency_radps() - 15.29).abs() < 1e-9);
        let z = p.damping_ratio();
        assert!((z - 0.0200).abs() < 5e-4, "{z}");
        assert!((p.l / p.a - 2.0).abs() < 1e-12 && (p.sigma / p.a - 1.8).abs() < 1e-12);
    }

    #[test]
    fn a_is_affine_in_speed_with_the_stated_derivative() {
        let p = TowedWheelSet::Benchmark.params();
        let a0 = p.linearise(0.3, 5.0);
        let a1 = p.linearise(3.3, 5.0);
        let err = (a1 - a0 - p.dlinearise_dv() * 3.0).amax();
        assert!(err < 1e-12 * a0.amax(), "{err}");
    }

    /// The collocated shimmy mode is a root of the delay equation's characteristic function:
    /// Newton from it lands within 1e-4 (relative) at every speed of the benchmark's chart.
    #[test]
    fn the_collocated_shimmy_mode_is_a_root_of_the_delay_equation() {
        let p = TowedWheelSet::Benchmark.params();
        let v_of = |vv: f64| vv * 2.0 * p.a * p.natural_frequency_radps();
        for vv in [0.25, 0.4, 0.6, 1.0, 2.0, 4.0] {
            let v = v_of(vv);
            let s = shimmy(&p, v);
            let r = root_near(s, &p, v).unwrap();
            let rel = (r - s).norm() / s.norm();
            assert!(
                rel < 1e-4,
                "V = {vv}: collocation {s}, delay equation {r}: {rel:.2e}"
            );
        }
    }

    /// The main stability boundary of the benchmark's chart (speed against caster at the
    /// rig's natural frequency and tyre damping, `Sigma = 1.8`, `zeta = 0.02`): the last onset
    /// from the collocated model's eigenvalues (the stability module's Hopf search) against
    /// the delay equation's own crossing, within 0.1 %, at four casters. The printed
    /// dimensionless speeds are the table of `docs/towed-wheel.md`.
    #[test]
    fn the_charts_boundary_agrees_with_the_delay_equation() {
        for big_l in [0.5, 1.0, 2.0, 2.5] {
            let mut p = TowedWheelSet::Benchmark.params();
            p.l = big_l * p.a;
            p.j_a = p.inertia_for_frequency(BENCHMARK_OMEGA_N_RADPS);
            let hopf = stability::hopf_crossings(&p, 0.0, 0.05, 10.0, 0.01, 1e-7).unwrap();
            let on = hopf
                .iter()
                .rfind(|x| x.kind == CrossingKind::Onset && x.shape == ModeShape::InPhaseWheelYaw)
                .copied()
                .unwrap();
            let d = onset_of_delay_equation(&p, on.speed_mps - 0.01, on.speed_mps + 0.01);
            let rel = (on.speed_mps - d).abs() / d;
            let off = hopf
                .iter()
                .find(|x| x.kind == CrossingKind::Offset && x.speed_mps > on.speed_mps)
                .map_or(f64::NAN, |x| p.dimensionless_speed(x.speed_mps));
            std::println!(
                "L = {big_l}: onset V = {:.3} ({:.3} m/s, {:.2} Hz), delay equation V = {:.3}; \
                 stable again from V = {off:.3}",
                p.dimensionless_speed(on.speed_mps),
                on.speed_mps,
                on.freq_hz,
                p.dimensionless_speed(d),
            );
            assert!(rel < 1e-3, "L = {big_l}: {} against {d}", on.speed_mps);
        }
    }

    /// Without tyre damping, fast rolling is stable exactly when the caster exceeds the
    /// patch's half length plus the relaxation length (`L > 1 + Sigma`: the high-speed limit
    /// of Eq. 31, where the memory term vanishes): a negative test on each side.
    #[test]
    fn fast_rolling_is_stable_only_beyond_a_plus_sigma() {
        let mut p = TowedWheelSet::Benchmark.params();
        p.b = 0.0;
        for (f, stable) in [(0.95, false), (1.05, true)] {
            p.l = f * (p.a + p.sigma);
            let v = 30.0 * 2.0 * p.a * p.natural_frequency_radps();
            let s = shimmy(&p, v);
            assert_eq!(s.re < 0.0, stable, "l = {f} (a + sigma): {s}");
        }
    }
}
