//! Range-bearing innovations along a dead-reckoned track: each observation
//! predicted through the model's `landmark` observation (seed 001 eq. 6) at the
//! track interpolated to its time, so the innovations (seed 001's EKF update)
//! measure the model's error.
use crate::logs::log::wrap;
use crate::model_on_log::deadreckon::Track;
use crate::model_on_log::interp::lerp3;
use crate::model_on_log::model::Runner;
use crate::model_on_log::robust::robust_sd;
use crate::model_on_log::run::{LandmarkObs, Run};
use crate::model_on_log::track_rows::{Cursor, TrackRows};
use kinegen_model::decl::ObservationRole::RangeBearing;
use kinegen_model::ir::Function;
use serde::Serialize;
use std::collections::HashMap;

/// Where time `t` falls among a run's steps: (step j, fraction a of it),
/// within the run (an observation before the first row or after the last is
/// seen at the track's end).
pub fn step_at(run: &Run, t: f64) -> (usize, f64) {
    let (j, a) = run.locate(t);
    (j, a.clamp(0.0, 1.0))
}

/// Where an observation falls on a track: (step j, fraction a, interpolated pose).
pub fn locate_on(run: &Run, track: &Track, t: f64) -> (usize, f64, [f64; 3]) {
    let (j, a) = step_at(run, t);
    (j, a, lerp3(&track.pose[j], &track.pose[j + 1], a))
}

/// The range and bearing the observation `h` predicts for `o` from body
/// pose `x`, during step `j` of `run`.
fn predict(
    r: &Runner,
    h: &Function,
    p: &[f64],
    run: &Run,
    j: usize,
    x: &[f64; 3],
    o: &LandmarkObs,
) -> [f64; 2] {
    let u = &run.u[j.min(run.steps() - 1)];
    let v = r.eval(h, &Runner::obs_args(h, x, u, p, &[o.xl, o.yl]));
    [v[0], v[1]]
}

/// One innovation: measured minus predicted.
#[derive(Debug, Clone, Serialize)]
pub struct Innovation {
    pub t: f64,
    pub id: String,
    pub range_m: f64,
    pub bearing_rad: f64,
}

impl Innovation {
    /// Sighting `o` minus its `predicted` range and bearing.
    fn of(o: &LandmarkObs, predicted: [f64; 2]) -> Innovation {
        Innovation {
            t: o.t,
            id: o.id.to_string(),
            range_m: o.range - predicted[0],
            bearing_rad: wrap(o.bearing - predicted[1]),
        }
    }
}

/// Innovation summary over runs.
#[derive(Debug, Clone, Serialize, Default)]
pub struct InnovationStats {
    pub observations: usize,
    pub landmarks: usize,
    pub range_rmse_m: f64,
    pub bearing_rmse_rad: f64,
    pub range_bias_m: f64,
    pub bearing_bias_rad: f64,
    /// Robust standard deviations ([`crate::model_on_log::robust::robust_sd`]): the spread
    /// of most sightings, which a few misread ones do not move as they move
    /// the RMSE.
    pub range_robust_sd_m: f64,
    pub bearing_robust_sd_rad: f64,
    /// The landmark with the largest RMS range innovation, and that RMS.
    pub worst_landmark: Option<(String, f64)>,
}

/// The innovations of a run's observations along `track`, in the run's
/// order; read off the track as it passes them, in time order.
pub fn innovations(r: &Runner, p: &[f64], run: &Run, track: &dyn TrackRows) -> Vec<Innovation> {
    (run.landmarks.iter())
        .zip(predicted_along(r, p, run, track))
        .filter_map(|(o, v)| Some(Innovation::of(o, v?)))
        .collect()
}

/// The range and bearing the model predicts for each of a run's
/// observations (in the run's order) from `track` interpolated to its time;
/// None where the track does not reach it, or where the model has no
/// landmark observation.
pub fn predicted_along(
    r: &Runner,
    p: &[f64],
    run: &Run,
    track: &dyn TrackRows,
) -> Vec<Option<[f64; 2]>> {
    let mut out = vec![None; run.landmarks.len()];
    let Some(h) = r.ir.observation_kernels(RangeBearing).map(|o| o.value) else {
        return out;
    };
    let mut order: Vec<usize> = (0..run.landmarks.len()).collect();
    order.sort_by(|&a, &b| run.landmarks[a].t.total_cmp(&run.landmarks[b].t));
    let mut cursor = Cursor::new(track, run);
    for i in order {
        let o = &run.landmarks[i];
        let (j, a) = step_at(run, o.t);
        let (Some(next), Some(at)) = (cursor.get(j + 1), cursor.get(j)) else {
            continue;
        };
        out[i] = Some(predict(r, h, p, run, j, &lerp3(&at.pose, &next.pose, a), o));
    }
    out
}

/// The innovations of a run's observations seen from its ground truth (the
/// measured pose interpolated to each sighting's time; none without one, nor
/// for a sighting outside the run's time or where the truth lost the robot):
/// the range-bearing sensor's own error, which the sightings along a
/// dead-reckoned track mix with that track's drift (on MRCLAM's 15-minute
/// logs metres of it against the camera's centimetres). What `fit`
/// calibrates a sensor-only effect on ([`crate::estimation::fit::sensor`]).
pub fn from_truth(r: &Runner, p: &[f64], run: &Run) -> Vec<Innovation> {
    let (Some(h), Some(gt)) = (
        r.ir.observation_kernels(RangeBearing).map(|o| o.value),
        &run.gt,
    ) else {
        return Vec::new();
    };
    run.landmarks
        .iter()
        .filter_map(|o| {
            let (j, x) = truth_at(run, gt, o.t)?;
            Some(Innovation::of(o, predict(r, h, p, run, j, &x, o)))
        })
        .collect()
}

/// The ground-truth pose `gt` of `run` at time `t` and the step it falls
/// in: interpolated between the rows around `t`, and None outside the run's
/// time (the nearest row's pose is not where the robot was then) or where
/// the motion capture has lost the robot. The one place a sighting is "seen
/// from the truth", for compare's figures and fit's sensor calibration alike.
pub fn truth_at(run: &Run, gt: &[[f64; 3]], t: f64) -> Option<(usize, [f64; 3])> {
    let (j, a) = run.locate(t);
    let x = lerp3(&gt[j], &gt[j + 1], a);
    ((0.0..=1.0).contains(&a) && x.iter().all(|v| v.is_finite())).then_some((j, x))
}

/// The sightings of `runs` seen from their ground truth, summarised (None
/// where no run has both).
pub fn stats_from_truth(r: &Runner, p: &[f64], runs: &[Run]) -> Option<InnovationStats> {
    let all: Vec<Innovation> = runs.iter().flat_map(|run| from_truth(r, p, run)).collect();
    stats(&all)
}

pub fn stats(all: &[Innovation]) -> Option<InnovationStats> {
    if all.is_empty() {
        return None;
    }
    let n = all.len() as f64;
    let mut per: HashMap<&str, (f64, usize)> = HashMap::new();
    for i in all {
        let e = per.entry(&i.id).or_default();
        e.0 += i.range_m * i.range_m;
        e.1 += 1;
    }
    let worst = per
        .iter()
        .map(|(id, (s, k))| (id.to_string(), (s / *k as f64).sqrt()))
        .max_by(|a, b| a.1.total_cmp(&b.1));
    Some(InnovationStats {
        observations: all.len(),
        landmarks: per.len(),
        range_rmse_m: (all.iter().map(|i| i.range_m * i.range_m).sum::<f64>() / n).sqrt(),
        bearing_rmse_rad: (all
            .iter()
            .map(|i| i.bearing_rad * i.bearing_rad)
            .sum::<f64>()
            / n)
            .sqrt(),
        range_bias_m: all.iter().map(|i| i.range_m).sum::<f64>() / n,
        bearing_bias_rad: all.iter().map(|i| i.bearing_rad).sum::<f64>() / n,
        range_robust_sd_m: robust_sd(all.iter().map(|i| i.range_m)),
        bearing_robust_sd_rad: robust_sd(all.iter().map(|i| i.bearing_rad)),
        worst_landmark: worst,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Three rows 0.1 s apart, the truth moving 1 m per row along x, lost
    /// (NaN) at the last row.
    fn run() -> Run {
        Run {
            gt: Some(vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [f64::NAN; 3]].into()),
            ..Run::bare(vec![0.0, 0.1, 0.2], [[0.0]; 2])
        }
    }

    #[test]
    fn the_truth_places_a_sighting_only_inside_the_run_where_it_has_the_robot() {
        let r = run();
        let gt = r.gt.clone().unwrap();
        let (j, x) = truth_at(&r, &gt, 0.05).expect("inside, tracked");
        assert_eq!(j, 0);
        assert!((x[0] - 0.5).abs() < 1e-12, "{x:?}");
        // at a row exactly: that row's pose
        assert_eq!(truth_at(&r, &gt, 0.0).map(|(_, x)| x), Some([0.0; 3]));
        // before the run, after it: the nearest rows' pose would be a guess
        assert!(truth_at(&r, &gt, -0.01).is_none());
        assert!(truth_at(&r, &gt, 0.21).is_none());
        // where the motion capture lost the robot
        assert!(truth_at(&r, &gt, 0.15).is_none());
    }
}
