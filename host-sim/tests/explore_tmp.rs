use shimmy_core::params::*;
use shimmy_sim::plant::*;
use shimmy_sim::bifurcation::*;
#[test]
fn explore() {
    let p = PlantParams::nominal();
    for vk in (5..=130).step_by(5) {
        let v = kmh_to_mps(vk as f64);
        let m = least_damped_mode(&p, v).unwrap();
        let t = std::time::Instant::now();
        let s = run_speed(&p, DamperSetting::Off, v, 0.05f64.to_radians(), 10.0, 1.0).unwrap();
        let s3 = run_speed(&p, DamperSetting::Current(0.0), v, 3f64.to_radians(), 10.0, 1.0).unwrap();
        let s2 = run_speed(&p, DamperSetting::Current(2.0), v, 3f64.to_radians(), 10.0, 1.0).unwrap();
        println!("{vk} eig re {:.3} f {:.3} Hz | off small {:.4} {:?} | 0A large {:.4} {:?} | 2A large {:.4} {:?} | {:?}", m.0, m.1/6.2832, s.amp_end_rad.to_degrees(), s.trend, s3.amp_end_rad.to_degrees(), s3.trend, s2.amp_end_rad.to_degrees(), s2.trend, t.elapsed());
    }
}
