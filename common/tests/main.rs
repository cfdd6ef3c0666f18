//! The integration tests of `fdi-common`, one binary: each file is a module.

mod attacker;
mod covert;
mod stealthy;
