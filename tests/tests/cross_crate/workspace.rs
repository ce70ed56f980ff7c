//! The simulator and the core agree on the parameter sets they both name.
use shimmy_core::vehicles::car::{ParamSet, PlantParams};

#[test]
fn every_named_set_is_valid_and_distinct() {
    let sets: Vec<PlantParams> = ParamSet::ALL.iter().map(|s| s.params()).collect();
    for (i, a) in sets.iter().enumerate() {
        assert!(a.validate().is_ok());
        for b in &sets[i + 1..] {
            assert_ne!(a, b);
        }
    }
}
