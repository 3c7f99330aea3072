//! A parameter set judged on runs: each run dead-reckoned from its start, the
//! errors against the ground truth and the landmark innovations. What every
//! job reports before and after it changes the parameters.
use crate::model_on_log::innovations::{self, Innovation, InnovationStats};
use crate::model_on_log::metrics::{errors_each, Errors};
use crate::model_on_log::model::Runner;
use crate::model_on_log::run::Run;
use crate::model_on_log::track_rows::{Heading, Recipe, TrackRows};

/// Parameters `p` on `runs`: the dead-reckoned tracks, the errors they make and
/// the landmark innovations.
pub struct Evaluation<'r> {
    pub tracks: Vec<Recipe<'r>>,
    /// Error summary; on logs without ground truth but with landmarks, `rmse` is
    /// the landmark range innovation RMSE.
    pub errors: Errors,
    /// Each run's own error summary.
    pub per_run: Vec<Errors>,
    pub landmarks: Option<InnovationStats>,
    /// The sightings seen from the ground truth: the sensor's own error
    /// ([`innovations::from_truth`]).
    pub landmarks_from_truth: Option<InnovationStats>,
}

/// Dead-reckoned tracks of every run with parameters `p`, each from its
/// measured start plus its offset in `offsets` (none: the measured start):
/// described, and computed each time they are read (a long log's tracks are
/// never held, see [`crate::model_on_log::track_rows`]).
pub fn tracks<'r>(r: &'r Runner, p: &[f64], runs: &[Run], offsets: &[[f64; 3]]) -> Vec<Recipe<'r>> {
    (0..runs.len())
        .map(|i| Recipe {
            r,
            p: p.to_vec(),
            offset: offsets.get(i).copied().unwrap_or([0.0; 3]),
            heading: Heading::Model,
        })
        .collect()
}

/// Each run with its track, as the metrics read them.
pub fn pairs<'a>(runs: &'a [Run], tracks: &'a [Recipe<'_>]) -> Vec<(&'a Run, &'a dyn TrackRows)> {
    runs.iter()
        .zip(tracks)
        .map(|(run, t)| (run, t as &dyn TrackRows))
        .collect()
}

/// Parameters `p` on `runs`, each from its measured start.
pub fn evaluation<'r>(r: &'r Runner, p: &[f64], runs: &[Run]) -> Evaluation<'r> {
    evaluation_from(r, p, runs, &[])
}

/// [`evaluation`] with each run started at its measured start plus its offset
/// in `offsets` (the start headings a fit refined).
pub fn evaluation_from<'r>(
    r: &'r Runner,
    p: &[f64],
    runs: &[Run],
    offsets: &[[f64; 3]],
) -> Evaluation<'r> {
    let tracks = tracks(r, p, runs, offsets);
    let (mut errors, per_run) = errors_each(&pairs(runs, &tracks));
    let all: Vec<Innovation> = runs
        .iter()
        .zip(&tracks)
        .flat_map(|(run, t)| innovations::innovations(r, p, run, t))
        .collect();
    let landmarks = innovations::stats(&all);
    if !runs.iter().any(|x| x.gt.is_some()) {
        if let Some(s) = &landmarks {
            errors.rmse = s.range_rmse_m;
        }
    }
    Evaluation {
        tracks,
        errors,
        per_run,
        landmarks,
        landmarks_from_truth: innovations::stats_from_truth(r, p, runs),
    }
}

/// The error summary of [`evaluation`].
pub fn evaluate(r: &Runner, p: &[f64], runs: &[Run]) -> Errors {
    evaluation(r, p, runs).errors
}

/// The metric `rmse` reports (CONTRACT section 4 leaves its name to us).
pub fn metric_name(runs: &[Run]) -> &'static str {
    if runs.iter().any(|x| x.gt.is_some()) || !runs.iter().any(|x| !x.landmarks.is_empty()) {
        "position_rmse_m"
    } else {
        "landmark_range_rmse_m"
    }
}
