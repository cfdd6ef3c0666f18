//! The integration tests, one module per file of this folder, in one test binary: one link
//! instead of one per file (CI's build time). Run one file's tests with
//! `cargo nextest run --release -p fdi-tests -E 'test(/^faults::/)'`.
// A test reads top to bottom: the limit on long functions (clippy.toml) is for the rest.
#![allow(clippy::too_many_lines)]

mod attacks_table;
mod controllers;
mod detect;
mod diverged_report;
mod docs;
mod edges;
mod engine;
mod external;
mod faults;
mod hostile_files;
mod interrupted_counts;
mod live;
mod long_horizon;
mod machine;
mod model;
mod multihost;
mod paper;
mod protocol;
mod replay;
mod report;
mod runs_list;
mod runtime;
mod scenarios;
mod schema;
mod score;
mod set_overrides;
mod shards;
mod slurm;
mod sweep;
mod threads;
mod traces;
