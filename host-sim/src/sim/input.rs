//! What the user hands the simulator: the one way files are read and written ([`files`]), the
//! vehicle and measured-log files, and the allowed ranges of the commands' numeric options
//! ([`arg_range`]). Everything here is checked before any work starts.

pub mod arg_range;
pub mod files;
pub mod log_file;
pub mod vehicle_file;
