//! The vehicle models, one folder each and laid out alike:
//!
//! - `params.rs`: the model's parameters and their field table (names, units, plausible ranges;
//!   reading and setting by name through [`fields::FieldTable`]);
//! - `linear.rs`: the linear model (states, A(V), inputs, mode shapes: [`crate::model::LinearModel`]);
//! - `sets.rs`: the named parameter sets;
//! - `board.rs`, where the model runs on the board: its stored vehicle record and the board's
//!   configuration of it (controller, supervisor and margin-pipeline parameters);
//! - `tests.rs`: the model's unit tests.
//!
//! The model files use only the model family and the numeric layers below it; only `board.rs`
//! reaches up to the vehicle, controller and estimator layers.

pub mod car;
pub mod dual_axle;
pub mod fields;
pub mod towed_wheel;
pub mod trailer;
pub mod truck;

pub use fields::{FieldError, FieldTable, ModelField};
