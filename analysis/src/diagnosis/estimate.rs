//! What diagnosis says of an effect's parameters: each one's estimate and
//! standard deviation. Its own module because the motion's ranking
//! ([`super::diagnose`]) and the sensor's ([`super::sensor`]) both report
//! them, and neither should reach the other for it.
use serde::Serialize;

/// A calibrated parameter: its estimate and standard deviation.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Estimate {
    pub estimate: f64,
    pub std: f64,
}

/// An effect's parameters by name, as calibrated.
pub type Estimates = std::collections::BTreeMap<String, Estimate>;
