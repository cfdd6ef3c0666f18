//! fdi-tables: what is measured by running the paper's system: its Tables I and II
//! ([`tables`]), the table of every shipped attack class under both controllers ([`attacks`]),
//! and the benchmarks of the runtime: latency, the transport floor, lockstep speed ([`bench`]).
//! Each is made of runs (`fdi-orchestrator`), writes its folder (`fdi-report` makes the files)
//! and returns what it measured; the command line prints it.
// A test reads top to bottom: the limit on long functions (clippy.toml) is for the rest.
#![cfg_attr(test, allow(clippy::too_many_lines))]

pub mod attacks;
pub mod bench;
pub mod tables;
