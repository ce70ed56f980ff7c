//! What the studies vary on a vehicle model and where they run it (`mismatch`, `compare`'s
//! robustness variants, `meter-accuracy`'s speeds, the standard set's slalom): one trait,
//! [`StudyModel`], on top of [`SimModel`], so that each study is written once for every model
//! and only these model facts differ. The car's impl is here; the mining truck's is in its plant
//! file (`super::truck_plant`).

use anyhow::Result;
use shimmy_core::vehicles::car::{Param, ParamSet, PlantParams};

use super::family::SimModel;

/// A model of the family the studies run on.
pub trait StudyModel<const N: usize>: SimModel<N> {
    /// Whether a driver torque reaches the steering (the car's steering wheel; the truck's
    /// hydrostatic steering: no): the standard set's slalom needs one.
    const DRIVER_TORQUE: bool;

    /// The folder of the model's shipped scenarios below `host-sim/scenarios/` (`""`: that
    /// folder itself).
    const SCENARIO_DIR: &'static str;

    /// The single-parameter uncertainties of `mismatch`: a label and the plant with that
    /// parameter (or group, e.g. the load) scaled by `factor`.
    fn single_variants(&self, factor: f64) -> Result<Vec<(&'static str, Self)>>;

    /// Further plants of `mismatch` next to the single-parameter ones (other named sets).
    fn other_plants() -> Vec<(String, Self)>;

    /// `compare`'s robustness plants (a 3 deg kick on each, the firmware believing `self`): a
    /// name and the plant.
    fn robustness_variants(&self) -> Result<Vec<(String, Self)>>;

    /// `meter-accuracy`'s default speeds, km/h: the damper-off arm (outside the Hopf window of
    /// the model's default vehicle) and the damper-on arm.
    fn meter_speeds_kmh() -> (&'static [f64], &'static [f64]);
}

impl StudyModel<{ shimmy_core::vehicles::car::N_STATES }> for PlantParams {
    const DRIVER_TORQUE: bool = true;
    const SCENARIO_DIR: &'static str = "";

    fn single_variants(&self, f: f64) -> Result<Vec<(&'static str, Self)>> {
        let groups: [(&str, &[Param]); 6] = [
            ("C_a", &[Param::CA]),
            ("sigma", &[Param::Sigma]),
            ("K_d", &[Param::KD]),
            ("e", &[Param::E]),
            ("t_p", &[Param::TP]),
            ("load (F_z, C_a)", &[Param::FZ, Param::CA]),
        ];
        Ok(groups
            .iter()
            .map(|&(name, ps)| (name, ps.iter().fold(*self, |p, &q| p.scaled(q, f))))
            .collect())
    }

    fn other_plants() -> Vec<(String, Self)> {
        [ParamSet::Hard, ParamSet::Gentle]
            .iter()
            .map(|s| (format!("`{}` plant", s.name()), s.params()))
            .collect()
    }

    fn robustness_variants(&self) -> Result<Vec<(String, Self)>> {
        let mut v = vec![("hard".to_string(), self.scaled(Param::KD, 0.5))];
        for q in [Param::CA, Param::Sigma, Param::E] {
            for f in [0.8, 1.2] {
                v.push((
                    format!("{}{:+.0}%", q.name(), (f - 1.0) * 100.0),
                    self.scaled(q, f),
                ));
            }
        }
        Ok(v)
    }

    fn meter_speeds_kmh() -> (&'static [f64], &'static [f64]) {
        (
            &[10.0, 20.0, 90.0, 105.0, 120.0],
            &[10.0, 40.0, 60.0, 90.0, 120.0],
        )
    }
}

/// `p` with the field `name` times `f`.
pub fn scaled<M: SimModel<N>, const N: usize>(p: &M, name: &str, f: f64) -> Result<M> {
    let x = p
        .param(name)
        .ok_or_else(|| anyhow::anyhow!("no parameter `{name}`"))?;
    p.with_param(name, x * f)
}

#[cfg(test)]
mod tests {
    use super::*;
    use shimmy_core::vehicles::truck::TruckSet;

    /// The truck's variants differ from the base in exactly the named field.
    #[test]
    fn a_trucks_variant_changes_its_field_only() {
        let t = TruckSet::Full.params();
        let v = t.single_variants(1.2).unwrap();
        let (_, ik) = v.iter().find(|(l, _)| *l == "I_k").unwrap();
        assert!((ik.i_k / t.i_k - 1.2).abs() < 1e-12);
        assert_eq!(ik.c_h, t.c_h);
        assert_eq!(t.robustness_variants().unwrap().len(), 7);
    }
}
