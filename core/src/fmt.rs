//! Logging shim: forwards to `defmt` when the `defmt` feature is on and to nothing otherwise,
//! so host builds never need a defmt logger. Arguments are still type-checked on the host.
#![allow(unused_macros)]

#[cfg(feature = "defmt")]
macro_rules! log_info { ($($t:tt)*) => { ::defmt::info!($($t)*) }; }
#[cfg(feature = "defmt")]
macro_rules! log_warn { ($($t:tt)*) => { ::defmt::warn!($($t)*) }; }
#[cfg(feature = "defmt")]
macro_rules! log_error { ($($t:tt)*) => { ::defmt::error!($($t)*) }; }

#[cfg(not(feature = "defmt"))]
macro_rules! log_info { ($($t:tt)*) => {{ let _ = || { $crate::fmt::__fmt_sink(format_args!($($t)*)) }; }}; }
#[cfg(not(feature = "defmt"))]
macro_rules! log_warn { ($($t:tt)*) => {{ let _ = || { $crate::fmt::__fmt_sink(format_args!($($t)*)) }; }}; }
#[cfg(not(feature = "defmt"))]
macro_rules! log_error { ($($t:tt)*) => {{ let _ = || { $crate::fmt::__fmt_sink(format_args!($($t)*)) }; }}; }

/// Type-checks the arguments of a disabled log statement; never called.
#[cfg(not(feature = "defmt"))]
#[doc(hidden)]
pub fn __fmt_sink(_: core::fmt::Arguments<'_>) {}
