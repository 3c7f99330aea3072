//! The error an absolute input carries from the log's own resolution, for
//! the drift-aware standard deviations ([`super::drift`]).
//!
//! A steering angle read by an encoder, or a command printed with three
//! decimals, is the true value rounded to a step: an error of variance
//! step^2 / 12 on every row, which the model turns into a twist error and
//! the track integrates into a walk. That walk is too small to stand out in
//! the residuals beside the motion capture's noise, yet it is what limits a
//! steering offset: on clean 200 s tricycle logs at 50 Hz from a simulator
//! other than kinegen's, with an 11-bit steering encoder, the offset's
//! spread over 30 seeds was 2.2x its reported standard deviation (one
//! estimate 10 standard deviations off); counted, 1.02x
//! (`analysis/tests/results/calibration.rs`).
//! The step is read from the log: the finest gap between the distinct values
//! of the input. A cumulative input (a wheel's count) is left out: its
//! rounding does not add up along the track, the next count takes it back.
use crate::model_on_log::model::Runner;
use crate::model_on_log::run::Run;
use kinegen_model::decl::InputKind;

/// Per input, the variance of its rounding error (0: a cumulative input, or
/// one whose values show no step).
pub(super) fn variances(r: &Runner, runs: &[Run]) -> Vec<f64> {
    (0..r.ir.inputs.len())
        .map(|i| {
            if r.ir.inputs[i].kind != InputKind::Absolute {
                return 0.0;
            }
            finest_step(runs.iter().flat_map(|run| run.u.iter().map(move |u| u[i])))
                .map_or(0.0, |q| q * q / 12.0)
        })
        .collect()
}

/// The finest gap between the distinct values of `values` (None: fewer than
/// two). Values within a millionth of the larger magnitude count as one: a
/// log printed as text reads back with that much of the decimal conversion.
fn finest_step(values: impl Iterator<Item = f64>) -> Option<f64> {
    let mut v: Vec<f64> = values.filter(|x| x.is_finite()).collect();
    v.sort_by(f64::total_cmp);
    let span = v.last()?.abs().max(v.first()?.abs());
    let same = 1e-6 * span.max(f64::MIN_POSITIVE);
    v.windows(2)
        .map(|w| w[1] - w[0])
        .filter(|d| *d > same)
        .min_by(f64::total_cmp)
}

/// Per row of an input's logged `values`, whether its rounding error is
/// shared with the rows around it that log the same value. Where the true
/// value passes through one step of the encoder (the value before the run
/// of equal rows is below it and the one after above, or the other way
/// round), the error sweeps the step from one edge to the other and its sum
/// over the run is near zero: each row is taken as its own error. Where it
/// turns back inside the step, or rests there, the error stays: the run
/// shares one. (Measured on the same simulated tricycle: shared throughout,
/// a 10-bit steering encoder's offset was reported 1.8x too uncertain; each
/// row its own error throughout, a 12-bit one's 1.4x too certain.)
pub(super) fn held(values: impl Iterator<Item = f64>) -> Vec<bool> {
    let v: Vec<f64> = values.collect();
    let mut out = vec![false; v.len()];
    let mut start = 0;
    while start < v.len() {
        let mut end = start + 1;
        while end < v.len() && v[end] == v[start] {
            end += 1;
        }
        let before = start.checked_sub(1).map(|j| v[j]);
        let after = v.get(end).copied();
        let through = match (before, after) {
            (Some(a), Some(b)) => (a < v[start]) == (v[start] < b),
            _ => false,
        };
        out[start..end].fill(!through);
        start = end;
    }
    out
}

/// The pose change (world frame: x, y in m, heading in rad) of step `k` of
/// `run` per unit error of input `i`, by central difference of the step from
/// the origin turned to the step's heading `heading`.
pub(super) fn effect(r: &Runner, run: &Run, k: usize, i: usize, heading: f64) -> [f64; 3] {
    let u = &run.u[k];
    let h = 1e-6 * u[i].abs().max(1e-3);
    let step = |du: f64| {
        let mut v = u.to_vec();
        v[i] += du;
        let (x, dt, zeros) = ([0.0; 3], [run.dt[k]], [0.0; 16]);
        let args = Runner::step_args(&r.step_twist, &x, &v, &r.p, &dt, &zeros);
        let out = r.step_twist.eval(&args);
        [out[0], out[1], out[2]]
    };
    let (plus, minus) = (step(h), step(-h));
    let d: Vec<f64> = (0..3).map(|c| (plus[c] - minus[c]) / (2.0 * h)).collect();
    let (s, c) = heading.sin_cos();
    [c * d[0] - s * d[1], s * d[0] + c * d[1], d[2]]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_run_shares_its_error_where_the_value_turns_back_or_rests() {
        // up through 2, turning back at 3, resting at 1 to the end
        let held = held([1.0, 2.0, 2.0, 3.0, 3.0, 2.0, 1.0, 1.0].into_iter());
        assert_eq!(held, [true, false, false, true, true, false, true, true]);
    }

    #[test]
    fn the_finest_step_is_the_encoders() {
        let q = std::f64::consts::TAU / 4096.0;
        let values = [3.0, -2.0, 7.0, 4.0, 5.0, 3.0].map(|k| k * q);
        let step = finest_step(values.into_iter()).unwrap();
        assert!((step - q).abs() < 1e-12, "{step}");
        // printed with six decimals and read back: the same step
        let printed = values.map(|v| format!("{v:.6}").parse::<f64>().unwrap());
        let step = finest_step(printed.into_iter()).unwrap();
        assert!((step / q - 1.0).abs() < 1e-3, "{step}");
        assert_eq!(finest_step([1.0, 1.0].into_iter()), None);
    }
}
