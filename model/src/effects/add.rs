//! An effect added to a user's spec file, checked: what `kinegen add-effect`
//! does in one call (the command only parses its options, writes the text
//! and prints the change), and what the tests' scenarios use.
use super::{catalogue, find, spec_change, Applicability, ApplyError, Effect, EffectError};
use crate::error::SourceError;
use crate::spec::Model;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// The spec, the effect by its catalogue name, its parameters' values
/// (`--value NAME=VALUE`, as given; the effect's nominal values otherwise),
/// and the user's own effect folders.
pub struct AddEffect<'a> {
    pub spec: &'a Path,
    pub effect: &'a str,
    pub values: &'a [(String, f64)],
    pub effect_dirs: &'a [PathBuf],
}

/// The spec with the effect: its text and the change, as a diff.
pub struct Added {
    pub source: String,
    pub change: String,
}

/// Why the effect was not added, naming the option or the file.
#[derive(Debug, thiserror::Error)]
pub enum AddEffectError {
    #[error(transparent)]
    Spec(#[from] SourceError),
    #[error(transparent)]
    Catalogue(#[from] EffectError),
    #[error("--effect: {0}")]
    Unknown(ApplyError),
    #[error("{}: the spec already has `{effect}`", .spec.display())]
    AlreadyIn { spec: PathBuf, effect: String },
    #[error("{}: `{effect}` does not apply to this model: {why}", .spec.display())]
    NotApplicable {
        spec: PathBuf,
        effect: String,
        why: String,
    },
    #[error(
        "--value {name}={value}: `{name}` is given twice (first {first}); give each parameter once"
    )]
    ValueTwice {
        name: String,
        value: f64,
        first: f64,
    },
    #[error("--value {name}={value}: outside the bounds of `{effect}`'s parameter `{name}` [{lo}, {hi}] ({origin})")]
    OutsideBounds {
        name: String,
        value: f64,
        effect: String,
        lo: f64,
        hi: f64,
        origin: String,
    },
    #[error("--value: {0}")]
    Values(ApplyError),
    #[error("adding `{effect}`{at} to {} gives an invalid spec: {message}", .spec.display())]
    Invalid {
        effect: String,
        at: String,
        spec: PathBuf,
        message: String,
    },
    #[error("--value {name}={value}: outside the effect's bounds [{min:?}, {max:?}]")]
    NominalOutside {
        name: String,
        value: f64,
        min: Option<f64>,
        max: Option<f64>,
    },
}

/// `req.spec` with the effect added at the values given, checked: the effect
/// applies, each value is given once and within its parameter's bounds,
/// and the result is a valid spec (a problem is the effect file's line
/// where the message's symbol is, else the user's file).
pub fn add_effect(req: &AddEffect) -> Result<Added, AddEffectError> {
    let model = Model::load(req.spec)?;
    let cat = catalogue(req.effect_dirs)?;
    let eff = find(&cat, req.effect).map_err(AddEffectError::Unknown)?;
    added_to(&model, eff, req.values)
}

/// `model` (a spec as read, from `model.path`) with `eff` added at `given`,
/// checked as [`add_effect`] checks it: what Python's `Model.with_effect`
/// calls on a spec it holds.
pub fn added_to(
    model: &Model,
    eff: &Effect,
    given: &[(String, f64)],
) -> Result<Added, AddEffectError> {
    let (spec, effect) = (model.path.clone(), eff.name.clone());
    match eff.applicability(model) {
        Applicability::Applies => {}
        Applicability::AlreadyIn => return Err(AddEffectError::AlreadyIn { spec, effect }),
        Applicability::NotApplicable(why) => {
            return Err(AddEffectError::NotApplicable { spec, effect, why })
        }
    }
    let values = checked_values(eff, model, given)?;
    let added = eff
        .with_values(model, &values)
        .map_err(AddEffectError::Values)?;
    let checked = Model::parse(&model.path, &added.source).map_err(|e| {
        let at = eff
            .locate(&e.message)
            .map_or(String::new(), |l| format!(" (from {l})"));
        AddEffectError::Invalid {
            effect: effect.clone(),
            at,
            spec: spec.clone(),
            message: e.message,
        }
    })?;
    let outside = |p: &&crate::spec::Param| {
        values.contains_key(&p.name)
            && (p.min.is_some_and(|m| p.nominal < m) || p.max.is_some_and(|m| p.nominal > m))
    };
    if let Some(p) = checked.params.iter().find(outside) {
        return Err(AddEffectError::NominalOutside {
            name: p.name.clone(),
            value: p.nominal,
            min: p.min,
            max: p.max,
        });
    }
    Ok(Added {
        change: spec_change(model, &added),
        source: added.source,
    })
}

/// The values given, each once and within the bounds of the effect's
/// parameter of that name for `model`.
fn checked_values(
    eff: &Effect,
    model: &Model,
    given: &[(String, f64)],
) -> Result<BTreeMap<String, f64>, AddEffectError> {
    let mut values: BTreeMap<String, f64> = BTreeMap::new();
    for (name, v) in given {
        if let Some(first) = values.insert(name.clone(), *v) {
            return Err(AddEffectError::ValueTwice {
                name: name.clone(),
                value: *v,
                first,
            });
        }
    }
    let params = eff.parameters_for(model);
    for (name, v) in &values {
        let Some(p) = params.iter().find(|p| &p.name == name) else {
            continue; // an unknown name is `with_values`' error
        };
        let (lo, hi) = (
            p.min.unwrap_or(f64::NEG_INFINITY),
            p.max.unwrap_or(f64::INFINITY),
        );
        if !(lo..=hi).contains(v) {
            return Err(AddEffectError::OutsideBounds {
                name: name.clone(),
                value: *v,
                effect: eff.name.clone(),
                lo,
                hi,
                origin: eff.origin.clone(),
            });
        }
    }
    Ok(values)
}
