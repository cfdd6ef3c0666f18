//! Reporting: run directories and summaries ([`output`]), figures ([`plot`]) and the run report
//! ([`report`]), the paper's tables ([`tables`]), trace export ([`export`]).

pub mod export;
pub mod output;
pub mod plot;
pub mod report;
pub mod tables;
