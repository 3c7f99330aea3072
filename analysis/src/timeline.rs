//! When each measurement was taken, relative to the inputs.
//!
//! A spec may declare one parameter as the delay of its measurements
//! (`measurement_delay = true`; the catalogue's `time_offset` effect adds one):
//! measurement k, logged at t_k, is compared with the model at t_k - delay,
//! interpolated between rows. Dead reckoning, calibration, diagnosis and
//! simulation all ask here, so a delay is handled the same way everywhere and
//! found by what the spec declares, never by a parameter's name.
use crate::model::Runner;
use crate::run::Run;

/// The measurement delay under parameters `p`, s (0 when the spec declares none).
pub fn delay(r: &Runner, p: &[f64]) -> f64 {
    r.delay.map_or(0.0, |i| p[i])
}

/// Where the model is when measurement `k` was taken: (row j, fraction a) of
/// the instant t_k - `delay` (see [`Run::locate`]).
pub fn model_instant(run: &Run, k: usize, delay: f64) -> (usize, f64) {
    run.locate(run.t[k] - delay)
}
