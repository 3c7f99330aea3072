//! What the fitted runs exercise, compared with the runs a calibration is
//! applied to. A fit learns only what its runs excite: parameters fitted on a
//! turn in place have seen no forward speed (a unicycle's speed scale, fitted
//! on the input noise of a robot that does not drive, shrank to a third and
//! the held-out error went 0.74 m -> 17.6 m). When a calibration makes runs it
//! was not fitted on worse, this names the motions and inputs those runs use
//! and the fitted ones do not, so that the user knows which runs to add.
use crate::model_on_log::metrics::{sample_every, sampled_twists};
use crate::model_on_log::model::Runner;
use crate::model_on_log::run::Run;
use crate::model_on_log::track_rows::TrackRows;

/// A held-out motion counts as not covered when its typical size is this many
/// times the fitted runs'.
const UNCOVERED_RATIO: f64 = 3.0;

/// Twist sizes below which a component counts as not driven at all (the
/// thresholds of `metrics::regime`): m/s, m/s, rad/s.
const DRIVEN: [f64; 3] = [0.02, 0.02, 0.05];

/// Quantile of the absolute values (their "typical largest" size, robust to a
/// glitch).
const Q: f64 = 0.95;

fn quantile(mut v: Vec<f64>, q: f64) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    let k = ((v.len() - 1) as f64 * q).round() as usize;
    *v.select_nth_unstable_by(k, f64::total_cmp).1
}

/// Per twist component, the `Q` quantile of its absolute value over the
/// tracks (of every k-th step of a long log, see [`sampled_twists`]).
fn twist_sizes(tracks: &[(&Run, &dyn TrackRows)]) -> [f64; 3] {
    let twists = sampled_twists(tracks);
    std::array::from_fn(|c| {
        quantile(
            twists
                .iter()
                .map(|w| w[c].abs())
                .filter(|x| x.is_finite())
                .collect(),
            Q,
        )
    })
}

/// The (2.5%, 97.5%) range of absolute input `i` over `runs` (of every k-th
/// step of long logs, see [`sample_every`]).
fn input_range(runs: &[&Run], i: usize) -> (f64, f64) {
    let every = sample_every(runs.iter().map(|run| run.steps()).sum());
    let v: Vec<f64> = runs
        .iter()
        .flat_map(|x| x.u.iter().map(move |u| u[i]))
        .step_by(every)
        .filter(|x| x.is_finite())
        .collect();
    (quantile(v.clone(), 0.025), quantile(v, 0.975))
}

/// Motions and absolute inputs (a steering angle) that the `held` runs use and
/// the `fitted` runs do not, in words (empty: the fitted runs cover them).
/// Each set is its runs and their dead reckoning with one parameter set (the
/// twist is what matters).
pub fn uncovered(
    r: &Runner,
    fitted: &[(&Run, &dyn TrackRows)],
    held: &[(&Run, &dyn TrackRows)],
) -> Vec<String> {
    let (f, h) = (twist_sizes(fitted), twist_sizes(held));
    let motion = ["forward speed", "sideways speed", "turn rate"];
    let unit = ["m/s", "m/s", "rad/s"];
    let mut found = Vec::new();
    for c in 0..3 {
        if h[c] > DRIVEN[c] && h[c] > UNCOVERED_RATIO * f[c] {
            found.push(format!(
                "{} up to {:.3} {} in the held-out runs, {:.3} in the fitted ones",
                motion[c], h[c], unit[c], f[c]
            ));
        }
    }
    let fr: Vec<&Run> = fitted.iter().map(|x| x.0).collect();
    let hr: Vec<&Run> = held.iter().map(|x| x.0).collect();
    let absolute = fr
        .first()
        .map(|x| x.rate_inputs.clone())
        .unwrap_or_default();
    for (i, input) in r.ir.inputs.iter().enumerate() {
        if absolute.get(i).copied().unwrap_or(true) {
            continue; // rates are covered through the twist
        }
        let ((flo, fhi), (hlo, hhi)) = (input_range(&fr, i), input_range(&hr, i));
        let width = hhi - hlo;
        // the held-out range reaches a quarter of its width beyond the fitted one
        if width > 0.0 && (flo - hlo).max(hhi - fhi) > 0.25 * width {
            found.push(format!(
                "{} ({}) spans {hlo:.3} .. {hhi:.3} in the held-out runs, {flo:.3} .. {fhi:.3} in the fitted ones",
                input.name, input.column
            ));
        }
    }
    found
}
