//! The effect catalogue: physically meaningful changes to a model, kept as data
//! (`spec/effects/*.toml`, compiled into the binary; a user's own catalogue adds
//! to it with `--effects DIR`).
//!
//! An effect file is read once into a typed [`Effect`] ([`definition`]: its
//! templates parsed, its parameters checked). [`Effect::applicability`] asks
//! what the *model* has (an explicit twist, no lateral velocity, steering
//! inputs, wheels on both sides, a gyro, exteroceptive sensors), never its
//! name ([`capability`]); [`Effect::with_values`] applies it to the typed
//! model, substituting expression trees ([`transform`]); the spec text of the
//! result is the user's file with only those changes written in ([`render`]:
//! comments, key order and formatting survive), which is what `add-effect`
//! writes.
//!
//! File format (see `spec/README.md`): `name`, `doc`, `requires` (capabilities),
//! `[[parameter]]` blocks as in specs (a parameter is added only when an applied
//! patch uses it; `bounds = "robot_size"` makes its bounds scale with the
//! robot's largest length), and patches: `[motion]` (templates over the original
//! `{vx}`, `{vy}`, `{omega}`), `[[each_input]]` (a template over `{input}` for
//! every input of a class: `steering`, `right_wheel`, `left_wheel`, `command`), and
//! `[observation.ROLE]` (ROLE = `pose`, `yaw_rate`, `range_bearing`; `expr`
//! templates over `{0}`, `{1}`..., `substitute` for state symbols).
mod add;
mod capability;
mod definition;
mod render;
pub use render::with_nominals;
mod transform;

pub use add::{add_effect, added_to, AddEffect, AddEffectError, Added};
pub use capability::{has, inputs_of, turn_signs, Capability, InputClass};
pub use definition::{Bounds, Effect, InputPatch, ObservationPatch, ParamTemplate, Template};

use crate::spec::{Model, ObservationRole};
use definition::parse_effect;
use std::path::{Path, PathBuf};

/// The bundled catalogue, compiled in so every command works from any directory.
const BUNDLED: &[(&str, &str)] = &[
    (
        "bearing_offset.toml",
        include_str!("../../../spec/effects/bearing_offset.toml"),
    ),
    (
        "command_deadband.toml",
        include_str!("../../../spec/effects/command_deadband.toml"),
    ),
    (
        "command_lag.toml",
        include_str!("../../../spec/effects/command_lag.toml"),
    ),
    (
        "gyro_bias.toml",
        include_str!("../../../spec/effects/gyro_bias.toml"),
    ),
    (
        "gyro_scale.toml",
        include_str!("../../../spec/effects/gyro_scale.toml"),
    ),
    (
        "input_delay.toml",
        include_str!("../../../spec/effects/input_delay.toml"),
    ),
    (
        "lateral_slip.toml",
        include_str!("../../../spec/effects/lateral_slip.toml"),
    ),
    (
        "longitudinal_slip.toml",
        include_str!("../../../spec/effects/longitudinal_slip.toml"),
    ),
    (
        "range_as_depth.toml",
        include_str!("../../../spec/effects/range_as_depth.toml"),
    ),
    (
        "range_scale.toml",
        include_str!("../../../spec/effects/range_scale.toml"),
    ),
    (
        "sensor_offset.toml",
        include_str!("../../../spec/effects/sensor_offset.toml"),
    ),
    (
        "steering_offset.toml",
        include_str!("../../../spec/effects/steering_offset.toml"),
    ),
    (
        "time_offset.toml",
        include_str!("../../../spec/effects/time_offset.toml"),
    ),
    (
        "wheel_misalignment.toml",
        include_str!("../../../spec/effects/wheel_misalignment.toml"),
    ),
    (
        "wheel_radius_asymmetry.toml",
        include_str!("../../../spec/effects/wheel_radius_asymmetry.toml"),
    ),
    (
        "wheelbase_scale.toml",
        include_str!("../../../spec/effects/wheelbase_scale.toml"),
    ),
];

#[derive(Debug, Clone, thiserror::Error)]
#[error("{file}: {message}")]
pub struct EffectError {
    pub file: PathBuf,
    pub message: String,
}

/// Why an effect cannot be added to a model.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ApplyError {
    #[error("unknown effect `{name}` (the catalogue has: {known})")]
    Unknown { name: String, known: String },
    #[error(
        "the effect `{effect}` has no parameter `{parameter}` for this model (it adds: {adds})"
    )]
    NoSuchParameter {
        effect: String,
        parameter: String,
        adds: String,
    },
    #[error("does not apply: {0}")]
    NotApplicable(String),
    /// The spec's text is not the TOML document its model was parsed from.
    #[error("the spec is not a TOML document: {0}")]
    NotToml(String),
    /// A table of the spec does not have the shape the effect edits.
    #[error("{0}")]
    Shape(&'static str),
    #[error("an observation of role {0:?} cannot be created by an effect")]
    CannotCreate(ObservationRole),
    /// The spec with the effect added does not parse; `from` is the effect
    /// file's line that brings the offending symbol, when found.
    #[error("adding it gives an invalid spec: {message}{}", from.as_ref().map_or(String::new(), |l| format!(" (from {l})")))]
    InvalidResult {
        message: String,
        from: Option<String>,
    },
    /// A chain names an effect the catalogue does not have.
    #[error("unknown effect `{0}`")]
    Unlisted(String),
    /// An effect of a chain does not go on the model with the ones before it.
    #[error("{0} (on the model with the effects found before it)")]
    InChain(Box<ApplyError>),
}

/// `spec` with the catalogue effects `effects` added in order, each at its
/// nominal values.
pub fn with_chain(spec: &Model, cat: &[Effect], effects: &[String]) -> Result<Model, ApplyError> {
    effects.iter().try_fold(spec.clone(), |m, name| {
        let eff = cat
            .iter()
            .find(|e| &e.name == name)
            .ok_or_else(|| ApplyError::Unlisted(name.clone()))?;
        eff.added_to(&m)
            .map_err(|why| ApplyError::InChain(Box::new(why)))
    })
}

/// Whether an effect applies to a model, and if not, why (for people).
#[derive(Debug, Clone, PartialEq)]
pub enum Applicability {
    Applies,
    NotApplicable(String),
    AlreadyIn,
}

/// The bundled catalogue plus every `*.toml` of the `extra` directories; a user
/// effect with a bundled effect's name replaces it.
pub fn catalogue(extra: &[PathBuf]) -> Result<Vec<Effect>, EffectError> {
    let mut out: Vec<Effect> = Vec::new();
    let mut add = |e: Effect| match out.iter_mut().find(|x| x.name == e.name) {
        Some(slot) => *slot = e,
        None => out.push(e),
    };
    for (file, text) in BUNDLED {
        add(parse_effect(
            Path::new(&format!("(bundled) spec/effects/{file}")),
            text,
        )?);
    }
    for dir in extra {
        let err = |m: String| EffectError {
            file: dir.clone(),
            message: m,
        };
        let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
            .map_err(|x| err(format!("cannot read the effect catalogue directory: {x}")))?
            .filter_map(|d| d.ok().map(|d| d.path()))
            .filter(|p| p.extension().is_some_and(|x| x == "toml"))
            .collect();
        if files.is_empty() {
            return Err(err("no effect files (*.toml) in this directory".into()));
        }
        files.sort();
        // two files of one directory naming the same effect: which one the
        // user meant is not ours to guess (a directory may still replace a
        // bundled effect, or one of an earlier directory)
        let mut here: Vec<(String, PathBuf)> = Vec::new();
        for f in files {
            let text = crate::files::read_text(&f).map_err(|e| EffectError {
                file: f.clone(),
                message: crate::files::unreadable(e),
            })?;
            let e = parse_effect(&f, &text)?;
            if let Some((_, first)) = here.iter().find(|(n, _)| *n == e.name) {
                return Err(EffectError {
                    file: f.clone(),
                    message: format!(
                        "effect `{}` is defined here and in {} (one directory, one file an effect)",
                        e.name,
                        first.display()
                    ),
                });
            }
            here.push((e.name.clone(), f.clone()));
            add(e);
        }
    }
    Ok(out)
}

/// What adding effects to `before` changed in its spec text, giving
/// `after` ([`Effect::with_values`]), for people: the lines that differ.
pub fn spec_change(before: &Model, after: &Model) -> String {
    render::line_change(&before.source, &after.source)
}

/// Find an effect by name in a catalogue.
pub fn find<'a>(cat: &'a [Effect], name: &str) -> Result<&'a Effect, ApplyError> {
    cat.iter()
        .find(|e| e.name == name)
        .ok_or_else(|| ApplyError::Unknown {
            name: name.to_string(),
            known: cat
                .iter()
                .map(|e| e.name.as_str())
                .collect::<Vec<_>>()
                .join(", "),
        })
}

#[cfg(test)]
mod tests;
