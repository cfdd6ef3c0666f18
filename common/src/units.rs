//! Angle units of scenario values.

use serde::{Deserialize, Serialize};

/// Units of angles (and, for rates, of angles per second) in a scenario section.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum AngleUnit {
    Deg,
    Rad,
}

impl AngleUnit {
    /// Factor that converts a value in these units to radians.
    pub fn to_rad(self) -> f64 {
        match self {
            Self::Deg => std::f64::consts::PI / 180.0,
            Self::Rad => 1.0,
        }
    }
}
