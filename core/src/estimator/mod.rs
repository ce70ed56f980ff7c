//! The margin path: how far the shimmy mode is from instability, from measured data and from the
//! plant model, fused, turned into warnings, and packaged as one per-tick pipeline
//! (`docs/margin-estimator.md`). The modules, in the order the data flows:
//!
//! 1. [`meter`]: the data-driven mode meter. Every 1 kHz sample of wheel yaw goes in
//!    ([`meter::mode_meter::MarginEstimator::push`]); at 100 Hz it reports the damping ratio of
//!    the shimmy-band mode from a fast and a slow RLS ([`meter::mode_meter::MeterOutput`]);
//! 2. [`model_margin`]: the model-based margin at the current speed (damping, its slope over
//!    speed, the onset speed), updated incrementally so one call costs at most one eigen-solve
//!    ([`model_margin::ModelMargin`]);
//! 3. [`model_update`]: optional online model updating. The slow meter's frequency and damping
//!    at each speed update a few physical parameters of the model (an extended Kalman filter on
//!    their log-factors, evidence kept over the whole drive), so the model margin follows the
//!    vehicle's slope and curvature, not only its offset
//!    ([`model_update::ModelUpdater`]);
//! 4. [`fusion`]: the model for the shape, the data for the level: the model's speed margin,
//!    corrected by the measured damping offset when data and model disagree, time to critical
//!    and a data/model consistency flag ([`fusion::MarginReport`]);
//! 5. [`monitor`]: warning levels with hysteresis and an event log, from the report and the
//!    meter's yaw amplitude ([`monitor::Level`]);
//! 6. [`pipeline`]: the one object the firmware and the simulator call every control tick
//!    (meter -> fusion with the latest model margin -> monitor).
//!
//! Each module imports only the ones before it. Constant work per call; no allocation; nothing
//! blocks.

pub mod fusion;
pub mod meter;
pub mod model_margin;
pub mod model_update;
pub mod monitor;
pub mod pipeline;
