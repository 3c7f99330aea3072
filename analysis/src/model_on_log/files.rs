//! A job's files read in one step: the effect catalogue (the bundled one and
//! the user's directories), the spec, its IR through the caller's
//! [`Deriver`], and the logs for that model. Every command that works on
//! logs (compare, fit, diagnose, localize) starts its one library call here.
use crate::model_on_log::derivation::{DerivationFailed, Deriver};
use crate::model_on_log::load::{load, LoadError, Loaded, ReadProgress, Sources};
use kinegen_model::effects::{catalogue, Effect, EffectError};
use kinegen_model::error::SourceError;
use kinegen_model::spec::Model;
use std::path::PathBuf;

/// What a job reads: the spec and its logs, and the user's effect
/// directories (read whatever the job, so a broken effect file is said the
/// day it is given, not the day diagnose first reads it).
#[derive(Clone, Copy)]
pub struct Files<'a> {
    pub sources: &'a Sources,
    pub effect_dirs: &'a [PathBuf],
}

/// The files read: the spec as parsed, the effect catalogue, and the logs
/// loaded for the spec's model.
pub struct Read {
    pub spec: Model,
    pub catalogue: Vec<Effect>,
    pub loaded: Loaded,
}

/// Why a job's files could not be read, in the order they are read.
#[derive(Debug, thiserror::Error)]
pub enum FilesError {
    #[error(transparent)]
    Catalogue(#[from] EffectError),
    #[error(transparent)]
    Spec(#[from] SourceError),
    #[error(transparent)]
    Derivation(#[from] DerivationFailed),
    #[error(transparent)]
    Load(#[from] LoadError),
}

/// Read the catalogue, the spec (derived by `deriver`) and the logs of
/// `files`, telling `progress` of each log.
pub fn read_files(
    files: &Files,
    deriver: &dyn Deriver,
    progress: ReadProgress,
) -> Result<Read, FilesError> {
    // the user's effects first: a broken effect file is said before the logs
    // are read
    let catalogue = catalogue(files.effect_dirs)?;
    let spec_path = &files.sources.spec;
    let spec = Model::load(spec_path)?;
    let ir = deriver.derive(&spec, &spec_path.display().to_string())?;
    let loaded = load(ir, files.sources, progress)?;
    Ok(Read {
        spec,
        catalogue,
        loaded,
    })
}
