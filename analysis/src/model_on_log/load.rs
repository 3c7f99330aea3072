//! The logs a job works on, read for one model: every `--data` and
//! `--holdout` file (CSV or ROS 2 bag) as runs, landmark sightings attached,
//! split at gaps longer than `max_gap`, and refused where the model's
//! dead reckoning would stop being numbers. What compare, fit, diagnose and
//! localize start from.
use crate::logs::bag::{Detection, TopicMap};
use crate::logs::log::{typical, LogError};
use crate::model_on_log::evaluation::tracks;
use crate::model_on_log::input_range;
use crate::model_on_log::landmarks::{
    from_detections, read_map, read_observations, Map, Sightings,
};
use crate::model_on_log::model::{parse_sets, ModelError, Runner};
use crate::model_on_log::run::Run;
use crate::model_on_log::sighting_units::{spacing, turning};
use crate::model_on_log::track_rows::first_non_finite;
use kinegen_model::decl::ObservationRole::RangeBearing;
use kinegen_model::ir::ModelIr;
use std::path::{Path, PathBuf};

/// Where a job's logs come from (the CLI's common options, as values).
#[derive(Debug, Clone, Default)]
pub struct Sources {
    /// The spec the model was derived from, named in messages.
    pub spec: PathBuf,
    pub data: Vec<PathBuf>,
    pub holdout: Vec<PathBuf>,
    /// `--set NAME=VALUE` overrides of the nominal values, as written.
    pub sets: Vec<String>,
    /// The topic mapping of ROS 2 bags, if given.
    pub topics: Option<PathBuf>,
    /// Range-bearing observations, the k-th for the k-th `data` log.
    pub observations: Vec<PathBuf>,
    pub landmarks: Option<PathBuf>,
    /// Split a log only at gaps longer than this, s.
    pub max_gap: f64,
    /// Ground truth only scores the job (localisation): rows where the motion
    /// capture lost the robot stay in the run instead of cutting it (the job
    /// runs through them and scores the rows that have it).
    pub truth_scores_only: bool,
}

/// The model and its logs, ready for a job.
pub struct Loaded {
    pub runner: Runner,
    pub runs: Vec<Run>,
    pub holdout: Vec<Run>,
    /// Things the user should know before reading any result (inputs outside
    /// their declared range, logs split at gaps), said by every command and
    /// kept in its JSON.
    pub warnings: Vec<String>,
    /// The landmark map (`--landmarks`), where one was given.
    pub map: Option<Map>,
}

#[derive(Debug, thiserror::Error)]
pub enum LoadError {
    #[error("{0}")]
    Model(#[from] ModelError),
    #[error("{0}")]
    Log(#[from] LogError),
    #[error("{path}: [inputs] maps `{column}`, which is no input column of the spec (it reads: {reads})", path = .path.display())]
    UnknownTopicColumn {
        path: PathBuf,
        column: String,
        reads: String,
    },
    #[error("no run of 3 rows or more between the gaps of the logs (--data)")]
    NoRun,
    #[error("--holdout {path}: no ground truth ({columns}) to score it against; a held-out run needs one (pass it as --data to fit on it instead)")]
    HoldoutWithoutTruth { path: String, columns: String },
    #[error("the bag's landmark topic (--topics [landmarks]) needs --landmarks MAP.csv (the landmark positions)")]
    BagLandmarksWithoutMap,
    #[error("--observations needs --landmarks MAP.csv (the landmark positions)")]
    ObservationsWithoutMap,
    #[error("--landmarks {} given without --observations (or a bag with a [landmarks] topic in --topics)", .0.display())]
    MapWithoutObservations(PathBuf),
    #[error("{}: the model has no `landmark` observation to predict range-bearing data with", .0.display())]
    NoLandmarkObservation(PathBuf),
    #[error("{files} --observations files for {logs} --data logs (one per log, in order)")]
    TooManyObservationFiles { files: usize, logs: usize },
    #[error("{run}: the run has landmark observations from its bag's topic `{topic}` and from --observations {}: give one", .file.display())]
    TwoObservationSources {
        run: String,
        topic: String,
        file: PathBuf,
    },
    #[error("{source_name}: no observation falls inside the log's time span {t0:.3}-{t1:.3} s{}", .seen.map_or(String::new(), |(a, b)| format!(" (the sightings span {a:.3}-{b:.3} s: is their time counted from the same origin as the log's?)")))]
    NoObservationInSpan {
        source_name: String,
        t0: f64,
        t1: f64,
        /// The sightings' own time span.
        seen: Option<(f64, f64)>,
    },
    #[error("{source_name}: columns `range` and `bearing`: landmarks seen together lie {ratio:.3}x as far apart by their ranges and bearings (the law of cosines) as the map {} places them (the median of {pairs} pairs): the ranges must be in the map's unit and the bearings in radians{}", .map.display(), .hint.as_ref().map_or(String::new(), |h| format!(" ({h})")))]
    SightingSpacing {
        source_name: String,
        map: PathBuf,
        ratio: f64,
        pairs: usize,
        hint: Option<String>,
    },
    #[error("{source_name}: column `bearing`: as the robot turns, the bearings change against the way the spec's landmark observation predicts them (slope {slope:.2} +- {standard_error:.2} over {pairs} pairs of sightings of one landmark under a second apart, against 1): the column's sign is the other way round from the spec's bearing (counter-clockwise from the robot's heading): negate the column, or the spec's bearing expression (unless the model turns the other way than the robot: `compare` without the sightings shows that in its heading error)")]
    BearingsTurnAgainst {
        source_name: String,
        slope: f64,
        standard_error: f64,
        pairs: usize,
    },
    /// A track that stops being numbers: the log, its line, what happened,
    /// and the `--set` values as suspects.
    #[error("{log}:{line}: {what}{suspects}")]
    NonFinite {
        log: String,
        line: usize,
        what: String,
        suspects: String,
    },
}

/// Told of each log before it is read; returns the callback that hears how
/// many of a bag's messages are read (done, total).
pub type ReadProgress<'a> = &'a dyn Fn(&Path) -> Box<dyn Fn(usize, usize)>;

/// Read `sources` for the model `ir`, telling `progress` of each log.
pub fn load(ir: ModelIr, sources: &Sources, progress: ReadProgress) -> Result<Loaded, LoadError> {
    let sets = parse_sets(&sources.sets)?;
    let runner = Runner::new(ir, &sets)?;
    let topics = topic_map(sources, &runner)?;
    let mut warnings: Vec<String> = Vec::new();
    let mut read = |paths: &[PathBuf]| -> Result<(Vec<Run>, Vec<Vec<Detection>>), LogError> {
        let mut out = (Vec::new(), Vec::new());
        for p in paths {
            let read = Run::read_with(p, &runner, &topics, &*progress(p))?;
            warnings.extend(read.note);
            out.0.push(read.run);
            out.1.push(read.detections);
        }
        Ok(out)
    };
    let (mut runs, found) = read(&sources.data)?;
    let (mut holdout, found_holdout) = read(&sources.holdout)?;
    // a held-out run is scored against its ground truth: without one its
    // error would read 0, a score it never earned
    if let Some(run) = holdout.iter().find(|r| r.gt.is_none()) {
        return Err(LoadError::HoldoutWithoutTruth {
            path: run.path.clone(),
            columns: runner.ir.pose_columns().join(", "),
        });
    }
    let mut logs = Logs {
        runs: &mut runs,
        found: &found,
        holdout: &mut holdout,
        found_holdout: &found_holdout,
    };
    // a log in another unit of time would have no sighting in its span either
    for run in logs.runs.iter().chain(logs.holdout.iter()) {
        seconds_apart(run, sources.max_gap)?;
    }
    let (said, map) = logs.attach_landmarks(sources, &runner)?;
    warnings.extend(said);
    // a log with gaps becomes one run per piece between them
    let mut split = |set: Vec<Run>| -> Vec<Run> {
        set.into_iter()
            .flat_map(|run| {
                let (pieces, warning) = if sources.truth_scores_only {
                    run.split_at_time_gaps_only(sources.max_gap)
                } else {
                    run.split_at_gaps(sources.max_gap)
                };
                warnings.extend(warning);
                pieces
            })
            .collect()
    };
    let (runs, holdout) = (split(runs), split(holdout));
    if runs.is_empty() {
        return Err(LoadError::NoRun);
    }
    warnings.extend(
        runs.iter()
            .chain(&holdout)
            .filter_map(|run| crate::model_on_log::deadreckon::start_note(&runner, &runner.p, run)),
    );
    // results that would be NaN or infinite are refused here, with the row
    for set in [&runs, &holdout] {
        if sources.truth_scores_only {
            // rows without ground truth are the job's to skip: what must be
            // finite is the model on the inputs
            let unscored: Vec<Run> = set.iter().map(Run::inputs_only).collect();
            check_finite(&runner, &unscored, &sources.sets)?;
        } else {
            check_finite(&runner, set, &sources.sets)?;
        }
    }
    warnings.extend(
        runs.iter()
            .chain(&holdout)
            .flat_map(|run| input_range::excursions(run, &runner.ir.inputs))
            .map(|e| e.to_string()),
    );
    Ok(Loaded {
        runner,
        runs,
        holdout,
        warnings,
        map,
    })
}

/// A log whose rows are typically further apart than `max_gap` has no run
/// at all between its gaps: its time is in another unit than seconds (a
/// log at 100 Hz in milliseconds steps by 10), which the error says, with
/// the unit that would make the steps a robot's.
fn seconds_apart(run: &Run, max_gap: f64) -> Result<(), LogError> {
    let Some(median) = typical(run.dt.to_vec()).filter(|m| *m > max_gap) else {
        return Ok(());
    };
    let hint = [
        ("milliseconds", 1e3),
        ("microseconds", 1e6),
        ("nanoseconds", 1e9),
    ]
    .into_iter()
    .find(|(_, per_s)| (1e-4..=1.0).contains(&(median / per_s)))
    .map(|(unit, per_s)| {
        format!(
            " (as {unit}, the rows would be {:.3} s apart: divide `t` by {per_s:.0})",
            median / per_s
        )
    })
    .unwrap_or_default();
    // rows a second or less apart are a robot's log in seconds: the gap
    // allowed is what is too small
    let remedy = if median <= 1.0 {
        format!("raise --max-gap above {median:.3} s")
    } else {
        format!("`t` must be in seconds{hint}, or --max-gap above {median:.3} s if the rows are that many seconds apart")
    };
    // rounded: the median of differences of decimal times carries their
    // binary noise (0.010000000000047748)
    let median = (median * 1e4).round() / 1e4;
    Err(LogError::new(
        Path::new(&run.path),
        None,
        Some("t"),
        format!("the rows are a median {median} apart, more than --max-gap {max_gap} s, so no stretch of the log is a run: {remedy}"),
    ))
}

/// The bags' topic mapping (`--topics`), its input columns checked against
/// the spec's: an entry for a column the spec does not read would be ignored,
/// most likely a misspelt column.
fn topic_map(sources: &Sources, runner: &Runner) -> Result<TopicMap, LoadError> {
    let Some(path) = &sources.topics else {
        return Ok(TopicMap::default());
    };
    let t = TopicMap::read(path)?;
    let columns: Vec<&str> = runner.ir.inputs.iter().map(|i| i.column.as_str()).collect();
    if let Some(c) = t.inputs.keys().find(|k| !columns.contains(&k.as_str())) {
        return Err(LoadError::UnknownTopicColumn {
            path: path.clone(),
            column: c.clone(),
            reads: columns.join(", "),
        });
    }
    Ok(t)
}

/// Refuse tracks with the nominal parameters that stop being numbers (see
/// `track_rows::first_non_finite`), naming the log and its line; `sets` are
/// the --set values, named as suspects.
fn check_finite(r: &Runner, runs: &[Run], sets: &[String]) -> Result<(), LoadError> {
    for (run, track) in runs.iter().zip(tracks(r, &r.p, runs, &[])) {
        if let Some((k, what)) = first_non_finite(&track, run) {
            let suspects = if sets.is_empty() {
                String::new()
            } else {
                format!(" (with --set {})", sets.join(" --set "))
            };
            return Err(LoadError::NonFinite {
                log: run.path.clone(),
                line: run.first_line + k,
                what,
                suspects,
            });
        }
    }
    Ok(())
}

/// The runs as read, with the landmark detections each bag held.
struct Logs<'a> {
    runs: &'a mut [Run],
    found: &'a [Vec<Detection>],
    holdout: &'a mut [Run],
    found_holdout: &'a [Vec<Detection>],
}

impl Logs<'_> {
    /// Read --landmarks and attach range-bearing observations to the runs: the
    /// k-th --observations file to the k-th run, or the detections of a bag's
    /// landmark topic (--topics `[landmarks]`) to its run. Returns what the
    /// user should know (sightings left out: for ids the map does not have,
    /// written twice, or outside their log's time span) and the map.
    fn attach_landmarks(
        &mut self,
        s: &Sources,
        r: &Runner,
    ) -> Result<(Vec<String>, Option<Map>), LoadError> {
        let from_bags = self
            .found
            .iter()
            .chain(self.found_holdout)
            .any(|d| !d.is_empty());
        let map_path = match (&s.landmarks, s.observations.is_empty(), from_bags) {
            (None, true, false) => return Ok((Vec::new(), None)),
            (None, _, true) => return Err(LoadError::BagLandmarksWithoutMap),
            (None, false, false) => return Err(LoadError::ObservationsWithoutMap),
            (Some(m), true, false) => return Err(LoadError::MapWithoutObservations(m.clone())),
            (Some(m), _, _) => m,
        };
        if r.ir
            .observation_kernels(RangeBearing)
            .map(|o| o.value)
            .is_none()
        {
            return Err(LoadError::NoLandmarkObservation(s.spec.clone()));
        }
        if s.observations.len() > self.runs.len() {
            return Err(LoadError::TooManyObservationFiles {
                files: s.observations.len(),
                logs: self.runs.len(),
            });
        }
        let map = read_map(map_path)?;
        let files = s
            .observations
            .iter()
            .map(Some)
            .chain(std::iter::repeat(None));
        let all = self.runs.iter_mut().zip(self.found).zip(files).chain(
            self.holdout
                .iter_mut()
                .zip(self.found_holdout)
                .zip(std::iter::repeat(None)),
        );
        let mut warnings = Vec::new();
        for ((run, found), file) in all {
            let (obs, source_name) = match (file, found.is_empty()) {
                (Some(path), false) => {
                    return Err(LoadError::TwoObservationSources {
                        run: run.path.clone(),
                        topic: found[0].topic.clone(),
                        file: path.clone(),
                    })
                }
                (Some(path), true) => (
                    read_observations(path, &map, map_path),
                    path.display().to_string(),
                ),
                (None, false) => (
                    from_detections(Path::new(&run.path), found, &map, map_path),
                    format!("{} (topic `{}`)", run.path, found[0].topic),
                ),
                (None, true) => continue,
            };
            let (t0, t1) = (run.t[0], *run.t.last().unwrap());
            let sightings = obs?;
            warnings.extend(left_out(&sightings, &source_name, map_path, (t0, t1)));
            let seen = (sightings.obs.first())
                .zip(sightings.obs.last())
                .map(|(a, b)| (a.t, b.t));
            let inside: Vec<_> = (sightings.obs.into_iter())
                .filter(|o| o.t >= t0 && o.t <= t1)
                .collect();
            if inside.is_empty() {
                return Err(LoadError::NoObservationInSpan {
                    source_name,
                    t0,
                    t1,
                    seen,
                });
            }
            run.landmarks = inside;
            warnings.extend(units_checked(run, r, &source_name, map_path)?);
        }
        Ok((warnings, Some(map)))
    }
}

/// Refuse sightings in another unit than the map's, or with a bearing of
/// the other sign than the spec's (see [`crate::model_on_log::sighting_units`]); warn of
/// bearings that do not follow the robot's turns at all.
fn units_checked(
    run: &Run,
    r: &Runner,
    source_name: &str,
    map_path: &Path,
) -> Result<Option<String>, LoadError> {
    if let Some(s) = spacing(&run.landmarks).filter(|s| s.in_another_unit()) {
        return Err(LoadError::SightingSpacing {
            source_name: source_name.to_string(),
            map: map_path.to_path_buf(),
            ratio: s.ratio,
            pairs: s.pairs,
            hint: s.unit_hint(),
        });
    }
    let Some(turn) = turning(r, run) else {
        return Ok(None);
    };
    if turn.against() {
        return Err(LoadError::BearingsTurnAgainst {
            source_name: source_name.to_string(),
            slope: turn.slope,
            standard_error: turn.standard_error,
            pairs: turn.pairs,
        });
    }
    Ok(turn.unrelated().then(|| {
        format!(
            "{source_name}: the bearings do not follow the robot's turns as the model predicts them (slope {:.2} +- {:.2} over {} pairs of sightings of one landmark under a second apart, against 1): is their time counted from the log's origin, and are they this log's? (Or the model at its nominal parameters turns far otherwise than the robot: `compare` shows that in its heading error.)",
            turn.slope, turn.standard_error, turn.pairs
        )
    }))
}

/// What the user should hear of the sightings of one source that are not
/// used: ids the map does not have, sightings written twice, and sightings
/// outside the log's time span `(t0, t1)` (a camera log that runs on after the
/// odometry stopped, or one from another log).
fn left_out(s: &Sightings, source: &str, map_path: &Path, (t0, t1): (f64, f64)) -> Vec<String> {
    let mut said = Vec::new();
    if s.unmapped.count > 0 {
        said.push(format!(
            "{source}: {} sighting(s) of {} left out: not in the map {} (the first at {})",
            s.unmapped.count,
            s.unmapped.some_ids(),
            map_path.display(),
            s.unmapped.first
        ));
    }
    if s.repeated.count > 0 {
        said.push(format!(
            "{source}: {} sighting(s) left out: each repeats the one before it at the same time exactly (the first at {})",
            s.repeated.count, s.repeated.first
        ));
    }
    let before = s.obs.iter().filter(|o| o.t < t0).count();
    let after = s.obs.iter().filter(|o| o.t > t1).count();
    if before + after > 0 {
        said.push(format!(
            "{source}: {} sighting(s) left out: outside the log's time span {t0:.3}-{t1:.3} s ({before} before it, {after} after it)",
            before + after
        ));
    }
    said
}

#[cfg(test)]
mod tests {
    use super::*;

    fn message(step: f64, max_gap: f64) -> String {
        let t: Vec<f64> = (0..50).map(|k| k as f64 * step).collect();
        let run = Run::bare(t, (0..50).map(|_| [0.0]));
        seconds_apart(&run, max_gap).unwrap_err().to_string()
    }

    #[test]
    fn rows_further_apart_than_the_gap_say_what_to_change() {
        // a log at 100 Hz in seconds: the gap allowed is what is too small
        let m = message(0.01, 0.001);
        assert!(
            m.contains("a median 0.01 apart") && m.contains("raise --max-gap above 0.010 s"),
            "{m}"
        );
        // the same log in milliseconds: its unit is
        let m = message(10.0, 3.0);
        assert!(
            m.contains("divide `t` by 1000") && m.contains("--max-gap above 10.000 s"),
            "{m}"
        );
        assert!(seconds_apart(&Run::bare(vec![0.0, 0.01, 0.02], [[0.0]; 3]), 3.0).is_ok());
    }
}
