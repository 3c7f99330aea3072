//! The model's own discretisation error at a log's sample rate, estimated from
//! the log itself. Dead reckoning holds each step's twist constant (absolute
//! inputs moving linearly, see `deadreckon::substeps`); how far that is from
//! the continuous motion depends on how fast the inputs change between
//! samples, which only the log knows. Richardson, after calibration: the
//! step's error is second order in its length, e(2h) = 4 e(h), and the sensor
//! noise per row is the same at either rate, so the calibrated error at half
//! the rate exceeds the one at the full rate by 15 e(h)^2 in mean square.
//! Calibrating at both rates matters: a fit absorbs part of the step's error
//! into its parameters (a fast-steering tricycle's wheelbase, seen), and what
//! is left is what could be mistaken for a missing effect. Diagnosis counts it
//! with the sensor noise, so structure the model's own step leaves is never
//! blamed on the robot (issue 12 item 3).
use crate::estimation::fit::{fit, rms_with_fitted_starts, FitOptions, Search};
use crate::model_on_log::model::Runner;
use crate::model_on_log::run::Run;
use serde::Serialize;

/// Most iterations of each of the two refinements. Both start from the
/// calibrated model's optimum; a model close to the noise floor (where the
/// step's error matters) is back at its pose-only optimum in a few, while a
/// badly misspecified one creeps on along its valley (an omni_caster log
/// missing a steering and a time offset: 40 iterations at the full rate, 35
/// at half, 1.3 s of its diagnosis), where the estimate is capped by the
/// model's excess over the noise anyway and a percent of either error left
/// changes it by a few percent.
const REFINEMENT_ITERATIONS: usize = 20;

#[derive(Debug, Clone, Copy, Serialize)]
pub struct Discretisation {
    /// The log's median sample rate.
    pub rate_hz: f64,
    /// RMS of the discretisation error left after calibration, in the units of
    /// the fit's weighted pose residuals (as errors and the noise floor are
    /// given in diagnosis).
    pub error: f64,
    /// Whether `error` was measured, or is 0 by construction (a log of held
    /// commands, whose step is exact); false for a log without a ground
    /// truth or too short to halve, of which `error` says nothing.
    pub measured: bool,
}

/// The discretisation error of `r` calibrated at `p` (with start offsets
/// `starts`, see [`Search::From`]) on `runs`: pose residuals of fits at the logs'
/// rate and at half of it, refined from there. Logs without ground truth, or
/// too short to halve, give 0.
pub fn estimate(
    r: &Runner,
    p: &[f64],
    starts: &[[f64; 3]],
    runs: &[Run],
    o: &FitOptions,
) -> Discretisation {
    let mut dts: Vec<f64> = runs.iter().flat_map(|x| x.dt.iter().copied()).collect();
    dts.sort_by(f64::total_cmp);
    let rate_hz = dts.get(dts.len() / 2).map_or(0.0, |d| 1.0 / d);
    let exact = runs.iter().all(commands_only);
    if runs.iter().any(|x| x.gt.is_none() || x.t.len() < 10) || exact {
        return Discretisation {
            rate_hz,
            error: 0.0,
            measured: exact,
        };
    }
    let pose = FitOptions {
        use_gyro: false,
        use_landmarks: false,
        max_iter: o.max_iter.min(REFINEMENT_ITERATIONS),
        ..o.clone()
    };
    let mut from = r.clone();
    from.p = p.to_vec();
    let rms_at = |runs: &[Run]| {
        fit(&from, runs, &pose, Search::From(starts))
            .map(|f| rms_with_fitted_starts(&from, &f.p, runs, &pose))
            .unwrap_or(f64::NAN)
    };
    let half: Vec<Run> = runs.iter().map(Run::halved).collect();
    // independent refinements: one per core
    let (full, coarse) = rayon::join(|| rms_at(runs), || rms_at(&half));
    let e2 = (coarse * coarse - full * full) / 15.0;
    Discretisation {
        rate_hz,
        error: if e2.is_finite() {
            e2.max(0.0).sqrt()
        } else {
            0.0
        },
        measured: true,
    }
}

/// Whether every input of `run` is a command held from its row (no counter,
/// no sampled angle). The twist is then constant over each step and the
/// step exact: no discretisation error. Halving such a log would not show
/// one either, only the commands the coarser log lost (1.9x the noise floor
/// on a real velocity-commanded robot, said as a step error the model does
/// not have).
fn commands_only(run: &Run) -> bool {
    run.rate_inputs.iter().all(|rate| !rate) && run.swing.is_none()
}
