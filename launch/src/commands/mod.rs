//! One file per command that does more than call a library function, with its command-line
//! arguments (`main.rs` wires every command to its code).

pub mod bench;
pub mod certs;
pub mod detect;
pub mod layout;
pub mod model;
pub mod report;
pub mod run;
pub mod runs;
pub mod score;
pub mod serve;
pub mod sweep;
pub mod tables;
pub mod validate;
pub mod values;
