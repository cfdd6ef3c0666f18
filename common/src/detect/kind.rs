//! What a detector on the observer's residual is to the rest of fdi-mas: a [`ResidualDetector`]
//! that turns each watched tick's whitened residual into a statistic, and its [`Kind`] — its
//! name, how tables, figures and exports title and describe it, its threshold and how to make
//! one. The list of kinds is [`super::RESIDUAL`]: every table, export, report and sweep
//! iterates over it, so a new detector is its own file with its `KIND` and one entry there.

use std::fmt;

use nalgebra::DVector;

use super::config::DetectorsConfig;

/// A detector of one robot, fed the whitened residual `z = L⁻¹ r` of every watched tick in
/// order (finite; unit covariance and uncorrelated under the null hypothesis).
pub trait ResidualDetector: fmt::Debug + Send + Sync {
    /// The statistic after `z`, or `None` while the detector has not seen enough ticks (its
    /// verdict is then "calibrating").
    fn push(&mut self, z: &DVector<f64>) -> Option<f64>;

    /// A copy of its state (the evaluators that hold detectors are cloned).
    fn boxed_clone(&self) -> Box<dyn ResidualDetector>;
}

impl Clone for Box<dyn ResidualDetector> {
    fn clone(&self) -> Self {
        self.boxed_clone()
    }
}

/// One kind of detector on the residual.
#[derive(Clone, Copy)]
pub struct Kind {
    /// The name every table, column, export and file uses (`chi2`).
    pub name: &'static str,
    /// Its short title in tables and figure legends (`χ²`).
    pub title: &'static str,
    /// It in a sentence, with its article (`a χ² test`).
    pub phrase: &'static str,
    /// What its statistic is, in a phrase (the MCAP schema's field description).
    pub statistic: &'static str,
    /// What its threshold field holds (the MCAP schema's field description).
    pub threshold_doc: &'static str,
    /// Its parameters as configured, in words (the report's line on the detectors).
    pub describe: fn(&DetectorsConfig) -> String,
    /// Its threshold for a residual of `dim` entries, or why there is none.
    pub threshold: fn(&DetectorsConfig, usize) -> Result<f64, String>,
    /// A fresh detector for a residual of `dim` entries.
    pub build: fn(&DetectorsConfig, usize) -> Box<dyn ResidualDetector>,
}

impl fmt::Debug for Kind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Kind").field("name", &self.name).finish()
    }
}
