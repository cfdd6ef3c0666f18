//! fdi-report: what a run directory says, made readable. It reads a run directory
//! ([`fdi_common::run_dir::RunDir`]) and writes its RMSE tables and summary ([`output`]), its
//! figures ([`plot`]) and `report.md` ([`report`]), the ROC and delay figures of `detect`
//! ([`detect_figures`]) and its exports for other tools ([`export`]: CSV, MCAP). It joins the
//! processes' traces tick by tick ([`join`]) and knows what a run recorded ([`traces`]). It
//! runs nothing: the runs are `fdi-orchestrator`'s.

pub mod columns;
#[cfg(feature = "figures")]
pub mod detect;
#[cfg(feature = "figures")]
pub mod detect_figures;
#[cfg(feature = "figures")]
pub mod export;
pub mod io_cause;
pub mod join;
pub mod output;
#[cfg(feature = "figures")]
pub mod plot;
#[cfg(feature = "figures")]
pub mod report;
#[cfg(feature = "figures")]
pub mod team;
pub mod topics;
pub mod traces;
