//! The output layer: everything that writes files -- plot primitives and the shared run plots,
//! the Markdown/CSV report, its self-contained HTML page and provenance, and the one file-name
//! sanitiser.
//!
//! Rule: uses only `sim` and `model`, never `cmd`.

pub mod analysis;
pub mod file_name;
pub mod html;
pub mod plot_util;
pub mod plots;
pub mod progress;
pub mod provenance;
pub mod report;
pub mod table;
