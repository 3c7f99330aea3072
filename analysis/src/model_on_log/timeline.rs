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
//! takes them from [`executed`], so the shift is made in one place; and so
//! is the robot's first-order response to them (`input_lag = true`; the
//! catalogue's `command_lag` effect), which follows the delay.
use crate::logs::rows::Rows;
use crate::model_on_log::model::Runner;
use crate::model_on_log::run::Run;
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

/// The time constant of the robot's response to its commands under
/// parameters `p`, s (0 when the spec declares none).
pub fn input_lag(r: &Runner, p: &[f64]) -> f64 {
    r.input_lag.map_or(0.0, |i| p[i])
}

/// Inputs a delay and a lag apply to: commands (absolute inputs that hold
/// between rows).
fn commands(r: &Runner) -> Vec<usize> {
    (0..r.ir.inputs.len())
        .filter(|&i| r.ir.inputs[i].is_command())
        .collect()
}

/// One command as the robot executed it, step by step: its mean over the
/// step, and that mean's derivatives in the input delay and in the lag.
struct ExecutedCommand {
    mean: Vec<f64>,
    by_delay: Vec<f64>,
    by_lag: Vec<f64>,
}

/// The first-order response `y` (and its derivative `dy` in the lag)
/// following a target that holds its value for a while.
pub(crate) struct Response {
    pub(crate) y: f64,
    pub(crate) dy: f64,
}

impl Response {
    /// Follow target `c` for `h` seconds with time constant `lag`: the
    /// integral of the response over them and its derivative in the lag.
    /// y(t) = c + (y0 - c) exp(-t/lag) is exact for a held target. At lag 0
    /// the response is the target itself, and the derivative is the limit
    /// as the lag grows from 0 (y0 - c per change of target: a small lag
    /// acts as a delay of that size, which is where a fit starts from).
    pub(crate) fn follow(&mut self, c: f64, h: f64, lag: f64) -> (f64, f64) {
        let gap = self.y - c;
        if lag <= 0.0 {
            (self.y, self.dy) = (c, 0.0);
            return (c * h, gap);
        }
        // past 700 time constants the memory is below 1e-304: exactly none,
        // not subnormal numbers (slow, and 1/size of them overflows)
        let x = h / lag;
        let e = if x > 700.0 { 0.0 } else { (-x).exp() };
        let g = 1.0 - e;
        let integral = c * h + gap * lag * g;
        let by_lag = self.dy * lag * g + gap * (g - e * x);
        self.dy = self.dy * e + gap * e * x / lag;
        if self.dy.abs() < 1e-300 {
            self.dy = 0.0;
        }
        self.y = c + gap * e;
        (integral, by_lag)
    }
}

/// Command `i` of `run` as executed under `delay` and `lag`: the robot
/// targets, at time s, the command of the last row logged at or before s -
/// delay (the first row's before the log began, which it was already
/// executing) and follows it with the first-order response.
///
/// The delay's derivative of a step's mean is (y(a) - y(b)) / (b - a): the
/// response is a function of t - delay, so shifting it by the delay
/// subtracts its rate, whose mean over the step is that difference (at lag
/// 0, the command in force just before each end of the step).
fn execute(run: &Run, i: usize, delay: f64, lag: f64) -> ExecutedCommand {
    let steps = run.steps();
    let cmd = |j: usize| run.u[j][i];
    let mut j = run
        .t
        .partition_point(|t| *t <= run.t[0] - delay)
        .saturating_sub(1)
        .min(steps - 1);
    let mut resp = Response { y: cmd(j), dy: 0.0 };
    let mut out = ExecutedCommand {
        mean: Vec::with_capacity(steps),
        by_delay: Vec::with_capacity(steps),
        by_lag: Vec::with_capacity(steps),
    };
    for k in 0..steps {
        let (a, b) = (run.t[k], run.t[k + 1]);
        let y_start = resp.y;
        let (mut s, mut sum, mut dsum) = (a, 0.0, 0.0);
        while s < b {
            while j + 1 < steps && run.t[j + 1] + delay <= s {
                j += 1;
            }
            let end = if j + 1 < steps {
                (run.t[j + 1] + delay).min(b)
            } else {
                b
            };
            let (integral, by_lag) = resp.follow(cmd(j), end - s, lag);
            sum += integral;
            dsum += by_lag;
            s = end;
        }
        let dt = b - a;
        out.mean.push(if dt > 0.0 { sum / dt } else { resp.y });
        out.by_lag.push(if dt > 0.0 { dsum / dt } else { 0.0 });
        out.by_delay.push(if dt > 0.0 {
            (y_start - resp.y) / dt
        } else {
            0.0
        });
    }
    out
}

/// The inputs the robot executed: each step's command is the mean, over the
/// step, of the response to the commands logged `input_delay` earlier
/// (instant without a lag). Without a delay or a lag, the run as it is.
pub fn executed<'a>(r: &Runner, p: &[f64], run: &'a Run) -> Cow<'a, Run> {
    executed_with_rates(r, p, run, false).0
}

/// [`executed`], and with `rates` the derivatives of the executed inputs of
/// each step, d u / d q, for each timing parameter q the spec declares (the
/// input delay, the lag), with q's index in `p` (zero for inputs that are
/// not commands), from the same pass over the commands. At a delay the cost
/// has a kink where a command changes; a lag is 0 or more, and its
/// derivative at 0 is the limit from above.
pub fn executed_with_rates<'a>(
    r: &Runner,
    p: &[f64],
    run: &'a Run,
    rates: bool,
) -> (Cow<'a, Run>, Vec<(usize, Rows)>) {
    let (delay, lag) = (input_delay(r, p), input_lag(r, p));
    let held = commands(r);
    let (steps, width) = (run.steps(), run.u.width());
    let shifted = delay != 0.0 || lag != 0.0;
    let timed = rates && (r.input_delay.is_some() || r.input_lag.is_some());
    if steps == 0 || held.is_empty() || !(shifted || timed) {
        return (Cow::Borrowed(run), Vec::new());
    }
    let rows = |q: Option<usize>| q.filter(|_| timed).map(|q| (q, vec![0.0; steps * width]));
    let (mut delay_rows, mut lag_rows) = (rows(r.input_delay), rows(r.input_lag));
    // at no delay and no lag the logged commands, exactly (not their means)
    let mut u: Option<Vec<f64>> =
        shifted.then(|| (0..steps).flat_map(|k| run.u[k].to_vec()).collect());
    for &i in &held {
        let e = execute(run, i, delay, lag);
        for k in 0..steps {
            if let Some(u) = u.as_mut() {
                u[k * width + i] = e.mean[k];
            }
            if let Some((_, d)) = delay_rows.as_mut() {
                d[k * width + i] = e.by_delay[k];
            }
            if let Some((_, l)) = lag_rows.as_mut() {
                l[k * width + i] = e.by_lag[k];
            }
        }
    }
    let inputs = match u {
        Some(u) => Cow::Owned(Run {
            u: Rows::from_flat(steps, width, u),
            ..run.clone()
        }),
        None => Cow::Borrowed(run),
    };
    let rates = delay_rows
        .into_iter()
        .chain(lag_rows)
        .map(|(q, v)| (q, Rows::from_flat(steps, width, v)))
        .collect();
    (inputs, rates)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One command logged at irregular times (0.01-0.5 s apart), stepping
    /// between levels as a velocity-commanded robot's does.
    fn commanded() -> Run {
        let mut t = vec![0.0];
        for k in 0..300 {
            let gap = [0.01, 0.13, 0.5, 0.04, 0.27][k % 5];
            t.push(t[k] + gap);
        }
        let u: Vec<Vec<f64>> = (0..t.len() - 1)
            .map(|k| vec![[0.0, 0.4, -0.2, 0.4, 0.1, 0.0, 0.3][(k / 3) % 7]])
            .collect();
        Run::bare(t, u)
    }

    /// The derivatives the fit's Jacobian takes from [`execute`] against
    /// central differences of the executed means: in the lag (also from
    /// lag 0, the one-sided limit a fit starts from) and in the delay
    /// (smooth once there is a lag).
    #[test]
    fn executed_commands_have_the_derivatives_the_fit_uses() {
        let run = commanded();
        let mean = |delay: f64, lag: f64| execute(&run, 0, delay, lag).mean;
        for (delay, lag) in [(0.0, 0.3), (0.17, 0.05), (0.25, 1.1), (-0.1, 0.2)] {
            let e = execute(&run, 0, delay, lag);
            // small: where a command changes at a step's end, the delay's
            // second derivative jumps, and a central difference errs by h
            // times that jump (1/(lag * step) per unit of command)
            let h = 1e-8;
            let (lag_up, lag_down) = (mean(delay, lag + h), mean(delay, lag - h));
            let (delay_up, delay_down) = (mean(delay + h, lag), mean(delay - h, lag));
            for k in 0..run.steps() {
                let by_lag = (lag_up[k] - lag_down[k]) / (2.0 * h);
                let by_delay = (delay_up[k] - delay_down[k]) / (2.0 * h);
                assert!(
                    (by_lag - e.by_lag[k]).abs() < 1e-5,
                    "lag {lag} step {k}: {by_lag} vs {}",
                    e.by_lag[k]
                );
                assert!(
                    (by_delay - e.by_delay[k]).abs() < 1e-5,
                    "delay {delay} step {k}: {by_delay} vs {}",
                    e.by_delay[k]
                );
            }
        }
        // from lag 0, the limit from above
        let at0 = execute(&run, 0, 0.1, 0.0);
        let h = 1e-7;
        let up = mean(0.1, h);
        for (k, (up, at0)) in up.iter().zip(at0.mean.iter().zip(&at0.by_lag)).enumerate() {
            let by_lag = (up - at0.0) / h;
            assert!(
                (by_lag - at0.1).abs() < 1e-4,
                "step {k}: {by_lag} vs {}",
                at0.1
            );
        }
    }

    /// Without a lag the executed command is the delayed held one; with a lag
    /// it approaches each new command as 1 - exp(-t/lag), so a long-held
    /// command is reached and a short one is not.
    #[test]
    fn a_lag_follows_each_command_with_a_first_order_response() {
        let run = commanded();
        let plain = execute(&run, 0, 0.0, 0.0);
        for k in 0..run.steps() {
            assert!((plain.mean[k] - run.u[k][0]).abs() < 1e-15, "step {k}");
        }
        // one change of command, 0 -> 1 at t = 1, held for 5 s in steps of 0.1 s
        let t: Vec<f64> = (0..=60).map(|k| k as f64 * 0.1).collect();
        let step = Run {
            u: (0..60)
                .map(|k| vec![if k >= 10 { 1.0 } else { 0.0 }])
                .collect(),
            dt: t.windows(2).map(|w| w[1] - w[0]).collect(),
            t: t.into(),
            ..run.clone()
        };
        let lag = 0.4;
        let e = execute(&step, 0, 0.0, lag);
        for k in 10..60 {
            let (a, b) = ((k - 10) as f64 * 0.1, (k - 9) as f64 * 0.1);
            // mean of 1 - exp(-s/lag) over [a, b]
            let exact = 1.0 - lag * ((-a / lag).exp() - (-b / lag).exp()) / 0.1;
            assert!(
                (e.mean[k] - exact).abs() < 1e-12,
                "step {k}: {} vs {exact}",
                e.mean[k]
            );
        }
        assert!(e.mean[10] < 0.2 && e.mean[59] > 0.999);
    }
}
