//! One problem of a scenario's values, with the path of its field: what every piece's
//! validation returns, and what [`crate::scenario::ScenarioError`] collects.

/// One problem of a scenario, with the path of the field it concerns.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Problem {
    pub path: String,
    pub message: String,
}

impl std::fmt::Display for Problem {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}: {}", self.path, self.message)
    }
}
