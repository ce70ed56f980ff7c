//! A vehicle model a firmware image is built for (the firmware's cargo feature picks the
//! model; `docs/firmware.md`): the vehicle its image stores and boots with, where `cargo xtask
//! pil` puts its image, and the drive of the in-process simulated device. Each such model
//! implements [`BoardModel`] in its plant file; the registry marks it `study`.

use shimmy_core::vehicle::BoardVehicle;
use shimmy_firmware::monitoring::BoardCalibration;

use super::family::{FamilyVehicle, SimModel};

/// A model with a firmware image.
pub trait BoardModel<const N: usize>: SimModel<N> {
    /// The image's vehicle (its record, its compiled-in default).
    type Board: BoardVehicle<N, Model = Self::Linear> + BoardCalibration + Copy;
    /// The PIL image `cargo xtask pil` builds for this model.
    const PIL_ELF: &'static str;
    /// Top speed of the simulated device's drive, km/h (the drive ramps up from 20 km/h
    /// through the model's Hopf window).
    const DEVICE_TOP_KMH: f64;
    /// Whether the simulated device's drive has the demo's pothole at the speed of fastest
    /// shimmy growth (else road noise and the wheels' imbalance only).
    const DEVICE_POTHOLE: bool;
    /// The simulator's vehicle of this model as the image's.
    fn board_vehicle(v: &FamilyVehicle<Self>) -> Self::Board;
    /// The image's vehicle as the simulator runs it (the inverse of [`Self::board_vehicle`]).
    fn from_board(b: &Self::Board) -> Self::Vehicle;
}
