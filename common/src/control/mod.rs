//! The control center's math, per agent: observer (22)–(24), NN attack estimator (32), (37),
//! (38), controller (12), (14) and the detection alarm. Pure: no I/O, no clocks.

pub mod center;
pub mod computed_torque;
pub mod config;
pub mod controller;
pub mod detection;
pub mod estimator;
pub mod external;
pub mod gated;
mod list;
pub mod observer;
pub mod paper;
pub mod pd;

pub use center::{AnyCenterAgent, CenterAgent, CenterOutput, CenterParams, Question};
pub use config::{
    ControllerConfig, ControllerMode, DetectionConfig, GainScaling, ObserverInput, UpdateLaw,
};
pub use controller::{Answer, Command, Controller, Estimate, Tick};
pub use detection::Detector;
pub use estimator::{NnEstimator, NnParams};
pub use observer::Observer;
