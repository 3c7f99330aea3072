//! When each measurement was taken, relative to the inputs.
//!
//! A spec may declare one parameter as the delay of its measurements
//! (`measurement_delay = true`; the catalogue's `time_offset` effect adds one):
//! measurement k, logged at t_k, is compared with the model at t_k - delay,
//! interpolated between rows. Dead reckoning, calibration, diagnosis and
//! simulation all ask here, so a delay is handled the same way everywhere and
//! found by what the spec declares, never by a parameter's name.
//!
//! A spec may also declare the delay with which the robot executes its
//! commands (`input_delay = true`; the catalogue's `input_delay` effect): the
//! command logged at t acts from t + delay. Every consumer of a run's inputs
//! takes them from [`executed`], so the shift is made in one place.
use crate::model::Runner;
use crate::rows::Rows;
use crate::run::Run;
use kinegen_model::decl::{Between, InputKind};
use std::borrow::Cow;

/// The measurement delay under parameters `p`, s (0 when the spec declares none).
pub fn delay(r: &Runner, p: &[f64]) -> f64 {
    r.delay.map_or(0.0, |i| p[i])
}

/// Where the model is when measurement `k` was taken: (row j, fraction a) of
/// the instant t_k - `delay` (see [`Run::locate`]).
pub fn model_instant(run: &Run, k: usize, delay: f64) -> (usize, f64) {
    run.locate(run.t[k] - delay)
}

/// The input delay under parameters `p`, s (0 when the spec declares none).
pub fn input_delay(r: &Runner, p: &[f64]) -> f64 {
    r.input_delay.map_or(0.0, |i| p[i])
}

/// Inputs a delay applies to: commands (absolute inputs that hold between rows).
fn commands(r: &Runner) -> Vec<usize> {
    (0..r.ir.inputs.len())
        .filter(|&i| {
            let inp = &r.ir.inputs[i];
            inp.kind == InputKind::Absolute && inp.between() == Between::Hold
        })
        .collect()
}

/// Command `i` of `run` in force just before time `s` (a row's value holds
/// from its time until the next row's; at a row's time, the row before it):
/// what a window ending at `s` loses or gains as the delay grows. Before the
/// first row, the first row's (what the robot did before the log is not in
/// it); after the last step, the last.
fn command_before(run: &Run, i: usize, s: f64) -> f64 {
    let steps = run.steps();
    let j = run
        .t
        .partition_point(|t| *t < s)
        .saturating_sub(1)
        .min(steps - 1);
    run.u[j][i]
}

/// The mean of command `i` over [a, b] (a < b), held piecewise.
fn mean_command(run: &Run, i: usize, a: f64, b: f64) -> f64 {
    let steps = run.steps();
    let mut j = run
        .t
        .partition_point(|t| *t <= a)
        .saturating_sub(1)
        .min(steps - 1);
    let (mut s, mut sum) = (a, 0.0);
    while s < b {
        let end = if j + 1 < steps {
            run.t[j + 1].min(b)
        } else {
            b
        };
        let end = if end <= s { b } else { end };
        sum += run.u[j][i] * (end - s);
        s = end;
        j = (j + 1).min(steps - 1);
    }
    sum / (b - a)
}

/// The inputs the robot executed: under an input delay tau, each step's
/// command is the mean, over the step, of the commands logged tau earlier.
/// Without one (or tau = 0), the run as it is.
pub fn executed<'a>(r: &Runner, p: &[f64], run: &'a Run) -> Cow<'a, Run> {
    let tau = input_delay(r, p);
    if tau == 0.0 || run.steps() == 0 {
        return Cow::Borrowed(run);
    }
    let held = commands(r);
    if held.is_empty() {
        return Cow::Borrowed(run);
    }
    let width = run.u.width();
    let mut u = Vec::with_capacity(run.steps() * width);
    for k in 0..run.steps() {
        let row = &run.u[k];
        let (a, b) = (run.t[k] - tau, run.t[k + 1] - tau);
        u.extend((0..width).map(|i| {
            if held.contains(&i) {
                mean_command(run, i, a, b)
            } else {
                row[i]
            }
        }));
    }
    Cow::Owned(Run {
        u: Rows::from_flat(run.steps(), width, u),
        ..run.clone()
    })
}

/// d (executed inputs of step k) / d tau, as tau grows: the command the
/// step's shifted window gains at its start minus the one it loses at its
/// end, over the step (zero for inputs that are not commands; at tau = 0 the
/// cost has a kink, and a delay is positive). None without an input delay.
pub fn executed_rate(r: &Runner, p: &[f64], run: &Run, k: usize) -> Option<Vec<f64>> {
    r.input_delay?;
    let tau = input_delay(r, p);
    let held = commands(r);
    let (a, b) = (run.t[k] - tau, run.t[k + 1] - tau);
    Some(
        (0..run.u.width())
            .map(|i| {
                if held.contains(&i) {
                    (command_before(run, i, a) - command_before(run, i, b)) / (b - a)
                } else {
                    0.0
                }
            })
            .collect(),
    )
}
