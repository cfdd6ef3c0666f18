//! Reporting: run directories and summaries ([`output`]), figures ([`plot`]) and the run report
//! ([`report`]), the paper's tables ([`tables`]), the attack-class table ([`attacks`]), trace export ([`export`]).

pub mod attacks;
pub mod export;
pub mod io_cause;
pub mod output;
pub mod plot;
pub mod report;
pub mod tables;
