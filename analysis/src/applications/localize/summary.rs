//! One localised run's figures: position RMSE of the filter, of the
//! smoother and of dead reckoning against the ground truth, and the mean
//! NIS and NEES with their chi-square bounds.
use super::{mean_bounds, nees_of, truth_noise, Localization, Sensed};
use crate::model::Runner;
use crate::run::Run;

/// One run's figures: errors against ground truth, consistency.
#[derive(Debug, Clone, PartialEq)]
pub struct Summary {
    pub rmse: Option<f64>,
    pub dead_reckoning: Option<f64>,
    pub nis: Option<f64>,
    pub nis_bounds: Option<(f64, f64)>,
    pub nees: Option<f64>,
    pub nees_bounds: Option<(f64, f64)>,
    /// The smoother's position RMSE and mean NEES.
    pub smoothed: Option<(Option<f64>, Option<f64>)>,
    /// The ground truth's own noise the NEES counts ([`truth_noise`]), when
    /// there is a NEES.
    pub truth_noise: Option<[f64; 3]>,
}

/// Position RMSE of `track` against the run's ground truth, if it has one,
/// where the motion capture sees the robot ([`Sensed`]), over the rows that
/// have it (the motion capture may lose the robot).
pub fn position_rmse(r: &Runner, run: &Run, track: &[[f64; 3]]) -> Option<f64> {
    let g = run.gt.as_ref()?;
    let sensor = Sensed::new(r, run);
    let (n, s) = track
        .iter()
        .zip(g)
        .enumerate()
        .filter(|(_, (_, g))| g[0].is_finite() && g[1].is_finite())
        .fold((0usize, 0.0), |(n, s), (k, (x, g))| {
            let m = sensor.at(k, x).0;
            (n + 1, s + (m[0] - g[0]).powi(2) + (m[1] - g[1]).powi(2))
        });
    (n > 0).then(|| (s / n as f64).sqrt())
}

fn mean(v: impl Iterator<Item = f64>) -> Option<f64> {
    let (n, s) = v.fold((0usize, 0.0), |(n, s), x| (n + 1, s + x));
    (n > 0).then(|| s / n as f64)
}

/// The figures of `loc`, the filter's output on `run`.
pub fn summarise(r: &Runner, run: &Run, loc: &Localization) -> Summary {
    // dead reckoning from the filter's start, scored as the filter is (the
    // same figure as `evaluate`'s to rounding, and it skips the rows where
    // the motion capture lost the robot)
    let dead_reckoning = position_rmse(r, run, &crate::deadreckon::run(r, &r.p, run, false).pose);
    let smoothed = loc.smoothed.as_ref().map(|(track, cov)| {
        let nees = nees_of(r, run, track, cov);
        (position_rmse(r, run, track), mean(nees.iter().map(|n| n.1)))
    });
    Summary {
        rmse: position_rmse(r, run, &loc.track),
        dead_reckoning,
        nis: mean(loc.nis.iter().map(|n| n.1)),
        nis_bounds: (!loc.nis.is_empty()).then(|| mean_bounds(loc.nis.len(), 2.0)),
        nees: mean(loc.nees.iter().map(|n| n.1)),
        truth_noise: truth_noise(run).filter(|_| !loc.nees.is_empty()),
        nees_bounds: (!loc.nees.is_empty()).then(|| mean_bounds(loc.nees.len(), 3.0)),
        smoothed,
    }
}
