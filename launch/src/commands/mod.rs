//! One file per command that does more than call a library function, with its command-line
//! arguments (`main.rs` wires every command to its code).

pub mod detect;
pub mod run;
pub mod validate;
