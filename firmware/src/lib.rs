//! shimmy firmware for the STM32F405RG (Cortex-M4F).
//!
//! The decisions live in `shimmy-core`; this crate holds the board glue. The runtime module
//! (logger, panic and fault handling, exit) exists only on the target, so `cargo test
//! --workspace` on the host never needs the thumbv7em toolchain.
#![cfg_attr(target_os = "none", no_std)]

pub mod background;
pub mod calibration;
pub mod clock;
pub mod control;
pub mod drivers;
pub mod fault_memory;
pub mod link;
pub mod monitoring;
pub mod pil;
pub mod replay;
pub mod sensors;
pub mod sim;
pub mod store;

#[cfg(target_os = "none")]
pub mod board;
#[cfg(target_os = "none")]
pub mod periph;
#[cfg(all(target_os = "none", not(feature = "panic-check")))]
pub mod runtime;
#[cfg(target_os = "none")]
pub mod stack;

/// Firmware identification logged at boot.
pub const BANNER: &str = concat!("shimmy-firmware ", env!("CARGO_PKG_VERSION"));

// The device crate provides the interrupt vector table (and RTIC's `device`).
#[cfg(target_os = "none")]
pub use stm32f4xx_hal as hal;
