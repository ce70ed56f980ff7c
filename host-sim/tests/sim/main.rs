//! The simulator's integration tests, one test binary (`cargo test -p shimmy-sim --test sim`;
//! one file's tests: `cargo test -p shimmy-sim --test sim golden::`). Each file used to be a
//! binary of its own that linked the whole simulator; one binary compiles and links once.

mod common;

mod analyze;
mod cli;
mod closed_loop;
mod device_link;
mod faults;
mod files;
mod golden;
mod hopf_type;
mod markdown_tables;
mod meter_accuracy;
mod plant_time_domain;
mod reference_line;
mod trailer_time_domain;
mod truck_commands;
mod truck_time_domain;
mod vehicle;
