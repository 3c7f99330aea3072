//! The JSON document of a diagnosis: what `kinegen diagnose --json` writes,
//! its report embeds and the Python package's `to_json()` returns. Built
//! here, once, so the three are the same document.
use crate::diagnosis::diagnose::Diagnosis;
use crate::diagnosis::next_steps::NextSteps;
use crate::diagnosis::request::Diagnosed;
use serde_json::{json, Value};

/// What the diagnosis's errors are measured in (the document's `metric`).
pub const METRIC: &str =
    "weighted_residual_rms (pose residuals / 0.01 m and 0.01 rad, gyro / 0.01 rad/s)";

/// The share of the noise floor above which the model's own discretisation
/// error is no longer "far below the noise": a warning, and structure of
/// that size may be the step's, not the robot's.
pub const DISCRETISATION_WARN: f64 = 0.3;

/// How far the model's own step errs at the log's rate, as a multiple of
/// the noise floor.
pub fn discretisation_ratio(d: &Diagnosis) -> f64 {
    d.discretisation.error / d.noise_floor.max(1e-300)
}

/// The whole document: the nominal and calibrated errors, every candidate,
/// the verdict with the commands that act on it, the discretisation, the
/// clocks, the sensor's candidates, what was not tested and the timing.
pub fn diagnose_document(done: &Diagnosed, steps: &NextSteps) -> Value {
    let (prep, d) = (&done.loaded, &done.outcome.diagnosis);
    let r = &prep.runner;
    let disc = &d.discretisation;
    let ratio = discretisation_ratio(d);
    let (t_prep, t_diag) = (done.preparing.as_secs_f64(), done.diagnosing.as_secs_f64());
    let per_candidate = match done.outcome.tried {
        0 => 0.0,
        n => t_diag / n as f64,
    };
    let calibrated = d
        .base_fit
        .free
        .iter()
        .map(|&i| (r.names[i].clone(), json!(d.base_fit.p[i])));
    json!({
        "model": r.ir.name,
        "metric": METRIC,
        "baseline": {"rmse": d.baseline_rmse},
        "calibrated": {"rmse": d.calibrated_rmse, "holdout_rmse": d.base_holdout_rmse,
            "parameters": calibrated.collect::<serde_json::Map<_, _>>()},
        "candidates": d.candidates,
        "verdict": {"effect": d.verdict(), "effects": d.chain, "unexplained_structure": d.structure.structured,
            "structure": d.structure.findings, "proposed": d.proposed,
            "apply": steps.apply, "calibrate": steps.calibrate, "alternatives": steps.alternatives},
        "discretisation": {"rate_hz": disc.rate_hz, "error": disc.error, "measured": disc.measured,
            "noise_floor": d.noise_floor, "ratio": ratio,
            "far_below_noise": disc.measured.then_some(ratio <= DISCRETISATION_WARN)},
        "warnings": prep.warnings,
        "clock": d.clock,
        "clock_unmeasured": d.clock_unmeasured,
        "spec_clock": d.spec_clock,
        "sensor_candidates": d.sensor_candidates,
        "sensor_unmeasured": d.sensor_unmeasured.as_ref().map(|w| w.to_string()),
        "skipped": d.skipped.iter().map(|(n, w)| json!({"effect": n, "reason": w})).collect::<Vec<_>>(),
        "timing": {"prepare_s": t_prep, "diagnose_s": t_diag, "per_candidate_s": per_candidate},
    })
}
