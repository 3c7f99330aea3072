//! `kinegen fit` from the user's files, the one call the command makes: the
//! files read ([`read_files`]), the known true values checked against the
//! model, then the Levenberg-Marquardt calibration judged
//! ([`calibrate`]) or several methods compared ([`compare_methods`]).
//!
//! ```ignore
//! let files = Files { sources: &sources, effect_dirs: &[] };
//! let request = FitRequest::Calibrate { options: &FitOptions::default(), truth: &[] };
//! let rmse = fit_files(&files, &request, &my_deriver, &|_| Box::new(|_, _| {}), &FitHooks::none(),
//!     |loaded, fitted| match fitted {
//!         Fitted::Calibrated(c) => c.after.errors.rmse,
//!         Fitted::Methods(m) => m.before.errors.rmse,
//!     })?;
//! ```
use crate::estimation::fit::FitOptions;
use crate::estimation::fit_job::{
    calibrate, compare_methods, Calibrated, FitJobError, MethodsJob, MethodsOutcome,
};
use crate::model_on_log::derivation::Deriver;
use crate::model_on_log::files::{read_files, Files, FilesError};
use crate::model_on_log::load::{Loaded, ReadProgress};

/// What to calibrate with.
pub enum FitRequest<'a> {
    /// The Levenberg-Marquardt calibration, judged. Known true values are
    /// only checked against the model here (a method comparison uses them).
    Calibrate {
        options: &'a FitOptions,
        truth: &'a [(String, f64)],
    },
    /// The methods the job names, compared.
    Methods(MethodsJob<'a>),
}

/// A calibration done, for its caller to render.
pub enum Fitted<'r> {
    // boxed: both are large, and of unequal size
    Calibrated(Box<Calibrated<'r>>),
    Methods(Box<MethodsOutcome<'r>>),
}

/// Told when the logs are read (before the calibration, the long part,
/// starts), and each method's name before it runs.
pub struct FitHooks<'a> {
    pub loaded: &'a dyn Fn(&Loaded),
    pub method: &'a dyn Fn(&str),
}

impl FitHooks<'_> {
    /// Nothing told.
    pub fn none() -> FitHooks<'static> {
        FitHooks {
            loaded: &|_| {},
            method: &|_| {},
        }
    }
}

/// Why a calibration could not be made from the files.
#[derive(Debug, thiserror::Error)]
pub enum FitRequestError {
    #[error(transparent)]
    Files(#[from] FilesError),
    #[error("--truth {name}: the spec has no parameter `{name}` (it has: {known})")]
    UnknownTruth { name: String, known: String },
    #[error(transparent)]
    Job(#[from] FitJobError),
}

/// Read `files` (the spec derived by `deriver`), calibrate as `request`
/// asks, and give the logs and the result to `then` (the result's tracks
/// borrow the logs' model).
pub fn fit_files<T>(
    files: &Files,
    request: &FitRequest,
    deriver: &dyn Deriver,
    progress: ReadProgress,
    hooks: &FitHooks,
    then: impl FnOnce(&Loaded, Fitted) -> T,
) -> Result<T, FitRequestError> {
    let loaded = read_files(files, deriver, progress)?.loaded;
    let truth = match request {
        FitRequest::Calibrate { truth, .. } => truth,
        FitRequest::Methods(job) => job.truth,
    };
    let r = &loaded.runner;
    if let Some((name, _)) = truth.iter().find(|(n, _)| r.param_index(n).is_none()) {
        return Err(FitRequestError::UnknownTruth {
            name: name.clone(),
            known: r.names.join(", "),
        });
    }
    (hooks.loaded)(&loaded);
    let fitted = match request {
        FitRequest::Calibrate { options, .. } => {
            Fitted::Calibrated(Box::new(calibrate(&loaded, options)?))
        }
        FitRequest::Methods(job) => {
            Fitted::Methods(Box::new(compare_methods(&loaded, job, hooks.method)?))
        }
    };
    Ok(then(&loaded, fitted))
}
