//! The output layer: everything that writes files -- plot primitives and the shared run plots,
//! the Markdown/CSV report, and the one file-name sanitiser.
//!
//! Rule: uses only `sim` and `model`, never `cmd`.

pub mod file_name;
pub mod plot_util;
pub mod plots;
pub mod report;
pub mod table;
