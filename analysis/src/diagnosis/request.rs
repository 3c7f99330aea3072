//! A diagnosis from the user's files, the one call `kinegen diagnose` makes:
//! the spec read and derived, its logs loaded (pieces too short to diagnose
//! pooled away), the catalogue read (bundled and the user's own effect
//! directories), and [`diagnose_job`] run on them.
//!
//! ```ignore
//! let files = Files { sources: &sources, effect_dirs: &[] };
//! let request = Request { files, for_report: false };
//! let done = diagnose_files(&request, &my_deriver, &|_| Box::new(|_, _| {}), &Hooks::none())?;
//! println!("{:?}", done.outcome.diagnosis.verdict());
//! ```
use crate::diagnosis::diagnose::{DiagnoseError, MIN_ROWS};
use crate::diagnosis::diagnose_job::{diagnose_job, Hooks, Job, Outcome};
use crate::model_on_log::derivation::{Deriver, EffectChains};
use crate::model_on_log::files::{read_files, Files, FilesError, Read};
use crate::model_on_log::load::{Loaded, ReadProgress};
use crate::model_on_log::model::{parse_sets, ModelError, Runner};
use crate::model_on_log::run::Run;
use kinegen_model::spec::Model;
use std::time::{Duration, Instant};

/// What to diagnose: the spec and logs, the user's effect directories, and
/// whether what a report draws is wanted ([`Job::for_report`]).
pub struct Request<'a> {
    pub files: Files<'a>,
    pub for_report: bool,
}

/// A diagnosis done: the logs as loaded (their warnings included) and the
/// outcome, with the time each part took.
pub struct Diagnosed {
    pub loaded: Loaded,
    pub outcome: Outcome,
    /// Reading the spec, the catalogue and the logs.
    pub preparing: Duration,
    pub diagnosing: Duration,
}

/// Why a diagnosis could not be made.
#[derive(Debug, thiserror::Error)]
pub enum RequestError {
    #[error(transparent)]
    Files(#[from] FilesError),
    #[error(transparent)]
    Sets(#[from] ModelError),
    /// A robot that never moves shows no effect (every ratio would be 0/0).
    #[error("{paths}: the inputs ({columns}) never change: the model robot never moves, so there is nothing to diagnose")]
    NeverMoves { paths: String, columns: String },
    #[error(transparent)]
    Diagnose(#[from] DiagnoseError),
}

/// Diagnose the logs of `req` against the bundled catalogue and the user's
/// effects, deriving the spec and its candidates with `deriver`.
pub fn diagnose_files(
    req: &Request,
    deriver: &dyn Deriver,
    progress: ReadProgress,
    hooks: &Hooks,
) -> Result<Diagnosed, RequestError> {
    let t0 = Instant::now();
    let Read {
        spec,
        catalogue: cat,
        mut loaded,
    } = read_files(&req.files, deriver, progress)?;
    pool_pieces(&mut loaded);
    (hooks.warnings)(&loaded.warnings);
    check_moves(&loaded)?;
    let sets = parse_sets(&req.files.sources.sets)?;
    let preparing = t0.elapsed();
    let t1 = Instant::now();
    let outcome = diagnose_runs(
        &spec,
        (&loaded.runner, &loaded.runs),
        (&cat, deriver),
        &sets,
        req.for_report,
        hooks,
    )?;
    Ok(Diagnosed {
        loaded,
        outcome,
        preparing,
        diagnosing: t1.elapsed(),
    })
}

/// Diagnose `runs` of the spec's `runner` against the effects of `cat`,
/// each derived by `deriver`; `sets` are the user's values, kept on every
/// candidate. What [`diagnose_files`] does once the files are read, for a
/// caller with logs of its own (the recovery benchmark's simulated ones).
pub fn diagnose_runs(
    spec: &Model,
    (runner, runs): (&Runner, &[Run]),
    (cat, deriver): (&[kinegen_model::effects::Effect], &dyn Deriver),
    sets: &[(String, f64)],
    for_report: bool,
    hooks: &Hooks,
) -> Result<Outcome, DiagnoseError> {
    let chains = EffectChains {
        spec,
        catalogue: cat,
        deriver,
        sets,
    };
    let job = Job {
        runner,
        runs,
        chains: &chains,
        for_report,
    };
    diagnose_job(&job, hooks)
}

/// Pieces of a log cut at its gaps that are too short to diagnose are left
/// out (with a warning), as long as the log leaves enough: diagnosis pools
/// the rest.
fn pool_pieces(loaded: &mut Loaded) {
    if loaded.runs.iter().any(|r| r.t.len() >= MIN_ROWS) {
        let (keep, short): (Vec<_>, Vec<_>) =
            loaded.runs.drain(..).partition(|r| r.t.len() >= MIN_ROWS);
        if !short.is_empty() {
            loaded.warnings.push(format!(
                "{} piece(s) under {MIN_ROWS} rows left out of the diagnosis ({}); it pools the other {}",
                short.len(),
                short.iter().take(3).map(|r| r.path.as_str()).collect::<Vec<_>>().join(", "),
                keep.len()
            ));
        }
        loaded.runs = keep;
    }
}

/// A robot that never moves: refused.
fn check_moves(loaded: &Loaded) -> Result<(), RequestError> {
    if loaded.runs.iter().all(|r| r.rest_steps() == r.steps()) {
        let columns: Vec<&str> = loaded
            .runner
            .ir
            .inputs
            .iter()
            .map(|i| i.column.as_str())
            .collect();
        return Err(RequestError::NeverMoves {
            paths: loaded
                .runs
                .iter()
                .map(|r| r.path.as_str())
                .collect::<Vec<_>>()
                .join(", "),
            columns: columns.join(", "),
        });
    }
    Ok(())
}
