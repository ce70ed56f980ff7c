//! The board layer: everything that differs between the STM32F405RG board and QEMU.
//! The application (`main.rs`) sees only [`Board`] (the variant's [`parts::BoardParts`]) and
//! the types in it.
//!
//! - board build (`stm32f405.rs`): 168 MHz from an 8 MHz HSE, two AS5047P on SPI1/SPI2,
//!   wheel-speed input capture on TIM5, coil current on ADC1, coil PWM on TIM4;
//! - `qemu` build (`qemu.rs`): QEMU has no RCC/GPIO model, so no clock setup (timers run at
//!   QEMU's 1 GHz), and the sensors are the simulated devices of [`crate::sim`]; the run ends
//!   after [`QEMU_STEPS`] control steps;
//! - `pil` build (`pil.rs`, QEMU too): the sensors and the coil are the host's plant in
//!   lockstep (processor in the loop, `shimmy-sim pil`).

pub mod hooks;
pub mod parts;

#[cfg(not(feature = "qemu"))]
mod stm32f405;
#[cfg(not(feature = "qemu"))]
pub use stm32f405::{init, Board, BoardSensors, Pwm};

#[cfg(all(feature = "qemu", not(feature = "pil")))]
mod qemu;
#[cfg(all(feature = "qemu", not(feature = "pil")))]
pub use qemu::{init, Board, BoardSensors, Pwm, QEMU_STEPS, WORLD};

#[cfg(feature = "pil")]
pub mod pil;
#[cfg(feature = "pil")]
pub use pil::{init, Board, BoardSensors, Pwm};

/// The application's hooks of this build ([`hooks::AppHooks`]).
#[cfg(not(feature = "pil"))]
pub use hooks::BoardHooks as Hooks;
/// The application's hooks of this build ([`hooks::AppHooks`]).
#[cfg(feature = "pil")]
pub use pil::PilHooks as Hooks;
