//! `kinegen localize` from the user's files, the one call the command
//! makes: the files read ([`read_files`]) with the ground truth only
//! scoring (the filter runs through rows the motion capture missed), the
//! filter's options checked against the model, the filter over every run
//! ([`localize_runs`]), and the noise sweep of seed 001 Figs 6-7 when asked.
//!
//! ```ignore
//! let files = Files { sources: &sources, effect_dirs: &[] };
//! let request = LocalizeRequest { files, options: EkfOptions::default(), sweep: false, for_report: false };
//! let done = localize_files(&request, &my_deriver, &|_| Box::new(|_, _| {}), &|_| {})?;
//! println!("{}", done.localized.note);
//! ```
use crate::applications::localize::figures::{run_figures, RunFigures};
use crate::applications::localize::timing::Timing;
use crate::applications::localize::{localize_runs, EkfOptions, LocalizeError, Localized};
use crate::applications::sweep::{sweep, SweepError, SweepPoint, LEVELS};
use crate::model_on_log::derivation::Deriver;
use crate::model_on_log::files::{read_files, Files, FilesError};
use crate::model_on_log::load::{Loaded, ReadProgress, Sources};
use crate::model_on_log::model::Runner;
use std::path::PathBuf;

/// What to localise: the files, the filter's options (`noise_sigma` names
/// the spec's `[[noise]]`; whether the spec's input delay is estimated is
/// decided here: unless `--set` fixes it), whether to sweep the noise,
/// and whether to compute what a report draws.
pub struct LocalizeRequest<'a> {
    pub files: Files<'a>,
    pub options: EkfOptions,
    pub sweep: bool,
    pub for_report: bool,
}

/// A localisation done: the logs as loaded, the filter over them, the
/// sweep (empty unless asked), and the map's landmarks no log sights (one
/// warning naming them and their lines in the map).
pub struct LocalizedFiles {
    pub loaded: Loaded,
    /// The options the filter ran with.
    pub options: EkfOptions,
    pub localized: Localized,
    pub sweep: Vec<SweepPoint>,
    pub unseen_landmarks: Option<String>,
    /// What a report draws of each run, in `localized.runs`' order (empty
    /// unless [`LocalizeRequest::for_report`]).
    pub figures: Vec<RunFigures>,
}

/// Why a localisation could not be made from the files.
#[derive(Debug, thiserror::Error)]
pub enum LocalizeRequestError {
    #[error(transparent)]
    Files(#[from] FilesError),
    #[error("--noise {name}: the spec has no [[noise]] `{name}` (it has: {known})")]
    UnknownNoise { name: String, known: String },
    #[error("--noise {name}={sigma}: a standard deviation is 0 or more")]
    NegativeNoise { name: String, sigma: f64 },
    #[error("{}: no landmark observations for these logs (give --observations OBS.csv --landmarks MAP.csv, one OBS per --data)", .0.display())]
    NoSightings(PathBuf),
    #[error(transparent)]
    Localize(#[from] LocalizeError),
    #[error(transparent)]
    Sweep(#[from] SweepError),
}

/// Read the files of `req` (the spec derived by `deriver`; `loaded` hears
/// the logs as soon as they are read, before the filter runs) and localise
/// every run with one noise: estimated on the `--data` runs, used on the
/// held-out ones too.
pub fn localize_files(
    req: &LocalizeRequest,
    deriver: &dyn Deriver,
    progress: ReadProgress,
    loaded: &dyn Fn(&Loaded),
) -> Result<LocalizedFiles, LocalizeRequestError> {
    // the ground truth only scores the filter: where the motion capture lost
    // the robot, the filter runs on
    let sources = Sources {
        truth_scores_only: true,
        ..req.files.sources.clone()
    };
    let files = Files {
        sources: &sources,
        ..req.files
    };
    let prep = read_files(&files, deriver, progress)?.loaded;
    loaded(&prep);
    let options = checked_options(&prep.runner, &sources, &req.options)?;
    let unseen_landmarks = unseen_landmarks(&sources, &prep);
    if prep.runs.iter().all(|r| r.landmarks.is_empty()) {
        return Err(LocalizeRequestError::NoSightings(sources.data[0].clone()));
    }
    let localized = localize_runs(&prep.runner, &prep.runs, &prep.holdout, &options)?;
    let sweep = match (req.sweep, prep.runs.first()) {
        (true, Some(first)) => sweep(&prep.runner, first, &LEVELS, &options)?,
        _ => Vec::new(),
    };
    let figures = if req.for_report {
        let runs = prep.runs.iter().chain(&prep.holdout);
        (runs.zip(&localized.runs))
            .map(|(run, (loc, summary))| run_figures(&prep.runner, run, (loc, summary)))
            .collect()
    } else {
        Vec::new()
    };
    Ok(LocalizedFiles {
        loaded: prep,
        options,
        localized,
        sweep,
        unseen_landmarks,
        figures,
    })
}

/// The filter's options with its `--noise` checked against the spec, and
/// the spec's command timing (input delay, command lag) estimated unless
/// `--set` fixes it.
fn checked_options(
    r: &Runner,
    sources: &Sources,
    o: &EkfOptions,
) -> Result<EkfOptions, LocalizeRequestError> {
    for (name, sigma) in &o.noise_sigma {
        if !r.ir.noise.iter().any(|x| &x.name == name) {
            let known: Vec<&str> = r.ir.noise.iter().map(|x| x.name.as_str()).collect();
            return Err(LocalizeRequestError::UnknownNoise {
                name: name.clone(),
                known: known.join(", "),
            });
        }
        if *sigma < 0.0 {
            return Err(LocalizeRequestError::NegativeNoise {
                name: name.clone(),
                sigma: *sigma,
            });
        }
    }
    let set_by_user = |i: usize| {
        sources
            .sets
            .iter()
            .any(|s| s.split('=').next().map(str::trim) == Some(r.names[i].as_str()))
    };
    let estimate_timing = (Timing::ALL.into_iter())
        .filter(|t| t.parameter(r).is_some_and(|i| !set_by_user(i)))
        .collect();
    Ok(EkfOptions {
        estimate_timing,
        ..o.clone()
    })
}

/// The map's landmarks that no log sights (a map for another arena, or ids
/// spelled differently in the map and the observations), in one sentence
/// naming their lines in the map; none when every landmark is sighted.
fn unseen_landmarks(sources: &Sources, prep: &Loaded) -> Option<String> {
    let (path, map) = (sources.landmarks.as_ref()?, prep.map.as_ref()?);
    let sighted = |id: &String| {
        (prep.runs.iter().chain(&prep.holdout)).any(|r| r.landmarks.iter().any(|z| *z.id == **id))
    };
    let unseen: Vec<String> = (map.ids.iter().enumerate())
        .filter(|(_, id)| !sighted(id))
        .map(|(i, id)| format!("`{id}` (line {})", map.first_line + i))
        .collect();
    (!unseen.is_empty()).then(|| {
        format!(
            "{}: {} of its {} landmarks are never observed in the --observations files: {}",
            path.display(),
            unseen.len(),
            map.ids.len(),
            unseen.join(", ")
        )
    })
}
