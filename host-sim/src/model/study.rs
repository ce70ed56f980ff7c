//! What the studies vary on a vehicle model and where they run it (`mismatch`, `compare`'s
//! robustness variants, `meter-accuracy`'s speeds, the standard set's slalom): one trait,
//! [`StudyModel`], on top of [`SimModel`], so that each study is written once for every model
//! and only these model facts differ. Each model's impl is in its plant file.

use anyhow::Result;

use super::board::BoardModel;
use super::family::SimModel;

/// A model of the family the studies run on (a model with a firmware image: the studies run
/// its board's pipeline).
pub trait StudyModel<const N: usize>: BoardModel<N> {
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
