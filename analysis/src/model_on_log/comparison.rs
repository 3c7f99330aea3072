//! `kinegen compare` as one library call: the model with its current
//! parameters dead-reckoned over every run, where its error grows, the
//! landmark innovations, and gyrodometry (seed 000 eq. 13-18) on the runs
//! that log a gyro.
use crate::model_on_log::derivation::Deriver;
use crate::model_on_log::evaluation::{pairs, tracks};
use crate::model_on_log::files::{read_files, Files, FilesError};
use crate::model_on_log::innovations::{self, Innovation, InnovationStats};
use crate::model_on_log::load::ReadProgress;
use crate::model_on_log::metrics::{
    self, errors_each, where_it_fails, Errors, RegimeShare, Segment,
};
use crate::model_on_log::model::Runner;
use crate::model_on_log::run::Run;
use crate::model_on_log::track_rows::{Heading, Recipe, TrackRows};

/// The model against its logs.
pub struct Comparison<'r> {
    /// The runs compared (fitted and held-out alike).
    pub runs: Vec<Run>,
    pub tracks: Vec<Recipe<'r>>,
    pub errors: Errors,
    pub per_run: Vec<Errors>,
    /// Each driving regime's share of the error growth.
    pub regimes: Vec<RegimeShare>,
    /// The worst 1 s segments.
    pub segments: Vec<Segment>,
    /// Each run's landmark innovations.
    pub innovations: Vec<Vec<Innovation>>,
    pub landmarks: Option<InnovationStats>,
    /// The sightings seen from the ground truth: the sensor's own error.
    pub landmarks_from_truth: Option<InnovationStats>,
    /// Gyrodometry's track of each run that logs a gyro.
    pub gyro_tracks: Vec<Option<Recipe<'r>>>,
    /// Gyrodometry's errors on the runs with a gyro and ground truth, and
    /// how many runs that is.
    pub gyrodometry: Option<(usize, Errors)>,
}

impl Comparison<'_> {
    /// Whether any run has ground truth to compare the track with.
    pub fn has_ground_truth(&self) -> bool {
        self.runs.iter().any(|x| x.gt.is_some())
    }

    /// The headline figure: the position RMSE, or without ground truth the
    /// landmark range innovation RMSE.
    pub fn rmse(&self) -> f64 {
        match (&self.landmarks, self.has_ground_truth()) {
            (Some(s), false) => s.range_rmse_m,
            _ => self.errors.rmse,
        }
    }
}

/// What [`compare_files`] hands its caller to render: the model with the
/// user's values, what the logs' reading found that the user should know,
/// and the comparison (whose tracks borrow the model).
pub struct Compared<'r> {
    pub runner: &'r Runner,
    pub warnings: &'r [String],
    pub comparison: Comparison<'r>,
}

/// Read `files` (the spec derived by `deriver`), compare the model with its
/// current parameters on every run, fitted and held-out alike, and give the
/// result to `then`.
pub fn compare_files<T>(
    files: &Files,
    deriver: &dyn Deriver,
    progress: ReadProgress,
    then: impl FnOnce(Compared) -> T,
) -> Result<T, FilesError> {
    let mut loaded = read_files(files, deriver, progress)?.loaded;
    // moved, not cloned: a long log's runs are most of the memory
    let mut all: Vec<Run> = std::mem::take(&mut loaded.runs);
    all.append(&mut loaded.holdout);
    let comparison = compare(&loaded.runner, all);
    Ok(then(Compared {
        runner: &loaded.runner,
        warnings: &loaded.warnings,
        comparison,
    }))
}

/// Compare `r` with its current parameters on `runs`.
pub fn compare(r: &Runner, runs: Vec<Run>) -> Comparison<'_> {
    let tracks = tracks(r, &r.p, &runs, &[]);
    let read = pairs(&runs, &tracks);
    let (errors, per_run) = errors_each(&read);
    let (regimes, segments) = where_it_fails(&read);
    let innovations: Vec<Vec<Innovation>> = runs
        .iter()
        .zip(&tracks)
        .map(|(run, t)| innovations::innovations(r, &r.p, run, t))
        .collect();
    let landmarks = innovations::stats(&innovations.concat());
    let landmarks_from_truth = innovations::stats_from_truth(r, &r.p, &runs);
    let gyro_tracks: Vec<Option<Recipe>> = runs
        .iter()
        .map(|run| {
            run.gyro.is_some().then(|| Recipe {
                r,
                p: r.p.clone(),
                offset: [0.0; 3],
                heading: Heading::Gyro,
            })
        })
        .collect();
    let gyro_pairs: Vec<(&Run, &dyn TrackRows)> = runs
        .iter()
        .zip(&gyro_tracks)
        .filter_map(|(run, t)| t.as_ref().map(|t| (run, t as &dyn TrackRows)))
        // errors need the ground truth to compare with
        .filter(|(run, _)| run.gt.is_some())
        .collect();
    let gyrodometry =
        (!gyro_pairs.is_empty()).then(|| (gyro_pairs.len(), metrics::errors(&gyro_pairs)));
    Comparison {
        runs,
        tracks,
        errors,
        per_run,
        regimes,
        segments,
        innovations,
        landmarks,
        landmarks_from_truth,
        gyro_tracks,
        gyrodometry,
    }
}

/// `compare --json`: the comparison as one document (CONTRACT section 4),
/// built here so the command line and the Python package write the same.
#[derive(Debug, serde::Serialize)]
pub struct CompareDocument<'a> {
    pub model: &'a str,
    pub metric: &'static str,
    pub errors: &'a Errors,
    pub rmse: f64,
    pub landmarks: &'a Option<InnovationStats>,
    pub landmarks_from_truth: &'a Option<InnovationStats>,
    pub regimes: &'a [RegimeShare],
    pub worst_segments: &'a [Segment],
    pub runs: Vec<RunErrors<'a>>,
    pub gyrodometry: Option<GyroErrors<'a>>,
    pub parameters: std::collections::BTreeMap<&'a str, f64>,
    pub warnings: &'a [String],
}

/// One run's errors in [`CompareDocument`].
#[derive(Debug, serde::Serialize)]
pub struct RunErrors<'a> {
    pub run: &'a str,
    pub errors: &'a Errors,
}

/// Gyrodometry's errors in [`CompareDocument`].
#[derive(Debug, serde::Serialize)]
pub struct GyroErrors<'a> {
    pub rmse: f64,
    pub errors: &'a Errors,
}

impl Compared<'_> {
    /// The document `compare --json` writes.
    pub fn document(&self) -> CompareDocument<'_> {
        let (r, cmp) = (self.runner, &self.comparison);
        CompareDocument {
            model: &r.ir.name,
            metric: crate::model_on_log::evaluation::metric_name(&cmp.runs),
            errors: &cmp.errors,
            rmse: cmp.rmse(),
            landmarks: &cmp.landmarks,
            landmarks_from_truth: &cmp.landmarks_from_truth,
            regimes: &cmp.regimes,
            worst_segments: &cmp.segments,
            runs: cmp
                .runs
                .iter()
                .zip(&cmp.per_run)
                .map(|(run, errors)| RunErrors {
                    run: &run.name,
                    errors,
                })
                .collect(),
            gyrodometry: cmp.gyrodometry.as_ref().map(|(_, g)| GyroErrors {
                rmse: g.rmse,
                errors: g,
            }),
            parameters: r
                .names
                .iter()
                .map(String::as_str)
                .zip(r.p.iter().copied())
                .collect(),
            warnings: self.warnings,
        }
    }
}
