//! A first estimate of a measurement delay, from the data alone: where the
//! motion measured lines up with the motion the inputs drive (see
//! [`crate::model_on_log::timeline`] for what the delay means). Diagnosis starts the
//! `time_offset` effect's calibration from it.
use crate::model_on_log::model::Runner;
use crate::model_on_log::run::Run;

/// Lags tried by [`delay_estimate`] on each side of zero, at most: longer
/// series are averaged over blocks of rows first, so the search costs a few
/// passes over the log whatever its rate and bound.
const MAX_LAGS: usize = 32;

/// A first estimate of the measurement delay, s, within `bounds`: the lag at
/// which the motion measured (the yaw rate and speed differenced from the
/// logged poses; the gyro is not delayed) best correlates with the motion the
/// inputs drive under parameters `p` (the model's body twist).
/// Correlation does not care about the scale errors of `p`, so this holds
/// where calibration does not: a model calibrated without a delay absorbs
/// part of it into its other parameters, and from there a local refinement
/// of the delay stays near zero (omni_caster logs lagging 0.05-0.2 s: the
/// cost along the delay alone is lowest at 0). None when the motion lines up
/// best unshifted (to the log's row, or block of rows), without a measured
/// motion channel or without a positive time step.
pub fn delay_estimate(r: &Runner, p: &[f64], runs: &[Run], bounds: (f64, f64)) -> Option<f64> {
    let (rows, span) = runs.iter().fold((0usize, 0.0), |(n, s), x| {
        (
            n + x.steps(),
            s + x.t.last().copied().unwrap_or(0.0) - x.t.first().copied().unwrap_or(0.0),
        )
    });
    let dt = span / rows.max(1) as f64;
    if !(dt.is_finite() && dt > 0.0) {
        return None;
    }
    let reach = bounds.0.abs().max(bounds.1.abs()).min(1e3) / dt;
    let block = ((reach / MAX_LAGS as f64).ceil() as usize).max(1);
    let lags = (reach / block as f64).ceil() as isize;
    // per channel: (measured, model), each averaged over blocks of rows
    let mut channels: Vec<(Vec<f64>, Vec<f64>)> = Vec::new();
    for run in runs.iter().filter(|x| x.steps() > 1) {
        let twist = crate::model_on_log::deadreckon::run(r, p, run, false).twist;
        let model_yaw: Vec<f64> = twist.iter().map(|w| w[2]).collect();
        let model_speed: Vec<f64> = twist.iter().map(|w| w[0].hypot(w[1])).collect();
        if let Some(g) = &run.gt {
            let step = |k: usize| (g[k + 1], g[k], run.dt[k]);
            let yaw = (0..run.steps()).map(|k| {
                let (b, a, h) = step(k);
                crate::logs::log::wrap(b[2] - a[2]) / h
            });
            let speed = (0..run.steps()).map(|k| {
                let (b, a, h) = step(k);
                (b[0] - a[0]).hypot(b[1] - a[1]) / h
            });
            channels.push((blocks(yaw, block), blocks(model_yaw.iter().copied(), block)));
            channels.push((
                blocks(speed, block),
                blocks(model_speed.iter().copied(), block),
            ));
        }
    }
    let score = |lag: isize| -> f64 { channels.iter().map(|(m, s)| correlation(m, s, lag)).sum() };
    let scores: Vec<f64> = (-lags..=lags).map(score).collect();
    let best = (0..scores.len()).max_by(|&a, &b| scores[a].total_cmp(&scores[b]))?;
    if !scores[best].is_finite() || channels.is_empty() || best as isize == lags {
        return None;
    }
    // parabolic refinement between the neighbouring lags
    let offset = match (best.checked_sub(1).map(|i| scores[i]), scores.get(best + 1)) {
        (Some(a), Some(&c)) => {
            let curve = a - 2.0 * scores[best] + c;
            if curve < 0.0 {
                0.5 * (a - c) / curve
            } else {
                0.0
            }
        }
        _ => 0.0,
    };
    let lag = (best as f64 - lags as f64 + offset) * (block as f64) * dt;
    Some(lag.clamp(bounds.0, bounds.1))
}

/// Means of `values` over consecutive blocks of `block` rows.
fn blocks(values: impl Iterator<Item = f64>, block: usize) -> Vec<f64> {
    let v: Vec<f64> = values.collect();
    v.chunks(block)
        .map(|c| c.iter().sum::<f64>() / c.len() as f64)
        .collect()
}

/// Correlation of `measured[k + lag]` with `model[k]` over the rows both
/// have, means removed; 0 where either does not vary.
fn correlation(measured: &[f64], model: &[f64], lag: isize) -> f64 {
    let pairs: Vec<(f64, f64)> = (0..model.len())
        .filter_map(|k| {
            let j = usize::try_from(k as isize + lag).ok()?;
            Some((*measured.get(j)?, model[k]))
        })
        .filter(|(a, b)| a.is_finite() && b.is_finite())
        .collect();
    let n = pairs.len() as f64;
    if n < 3.0 {
        return 0.0;
    }
    let (ma, mb) = pairs
        .iter()
        .fold((0.0, 0.0), |(x, y), (a, b)| (x + a / n, y + b / n));
    let (mut ab, mut aa, mut bb) = (0.0, 0.0, 0.0);
    for (a, b) in &pairs {
        ab += (a - ma) * (b - mb);
        aa += (a - ma) * (a - ma);
        bb += (b - mb) * (b - mb);
    }
    if aa > 0.0 && bb > 0.0 {
        ab / (aa * bb).sqrt()
    } else {
        0.0
    }
}
