//! A robot with physical effects hidden in it: the model the user declared,
//! and the same model with catalogue effects added at given values, which is
//! what the simulated robot really does. `kinegen simulate --effect` and the
//! recovery benchmark (`bench-diagnose`) drive the second and calibrate or
//! diagnose the first.
//!
//! ```ignore
//! let hidden: Hidden = "lateral_slip.k_slip=0.02".parse()?;
//! let robots = with_hidden(&spec, &[hidden], &[], &[], &my_deriver)?;
//! let log = simulate(&robots.spec, &robots.robot, &SimOptions::default());
//! ```
use crate::model_on_log::derivation::{DerivationFailed, Deriver};
use crate::model_on_log::model::{ModelError, Runner};
use kinegen_model::effects::{catalogue, find, Applicability, EffectError};
use kinegen_model::spec::Model;
use std::path::PathBuf;
use std::str::FromStr;

/// One hidden effect: a catalogue effect, which of its parameters (None: the
/// first it adds to the model) and that parameter's value; `text` is how
/// the user wrote it (`NAME=VALUE` or `NAME.PARAM=VALUE`), for messages.
#[derive(Debug, Clone, PartialEq)]
pub struct Hidden {
    pub effect: String,
    pub param: Option<String>,
    pub value: f64,
    pub text: String,
}

impl Hidden {
    /// The effect `effect`'s parameter `param` at `value`.
    pub fn new(effect: &str, param: &str, value: f64) -> Hidden {
        Hidden {
            effect: effect.to_string(),
            param: Some(param.to_string()),
            value,
            text: format!("{effect}.{param}={value}"),
        }
    }
}

/// Why hidden effects cannot be added to a model.
#[derive(Debug, thiserror::Error)]
pub enum HiddenError {
    #[error("--effect {0}: expected NAME=VALUE or NAME.PARAM=VALUE")]
    Syntax(String),
    #[error("--effect {text}: `{value}` is not a finite number")]
    NotANumber { text: String, value: String },
    #[error(transparent)]
    Catalogue(#[from] EffectError),
    #[error("--effect {text}: {message}")]
    Unknown { text: String, message: String },
    #[error("--effect {text}: the effect `{effect}` adds no parameter `{param}` to this model (it adds: {adds})")]
    NoSuchParameter {
        text: String,
        effect: String,
        param: String,
        adds: String,
    },
    #[error("--effect {text}: on {spec}, `{effect}` {why}")]
    DoesNotApply {
        text: String,
        spec: String,
        effect: String,
        why: String,
    },
    #[error(transparent)]
    Derivation(#[from] DerivationFailed),
    #[error(transparent)]
    Model(#[from] ModelError),
}

impl FromStr for Hidden {
    type Err = HiddenError;

    /// `NAME=VALUE` (the effect's first parameter) or `NAME.PARAM=VALUE`.
    fn from_str(text: &str) -> Result<Hidden, HiddenError> {
        let (key, v) = text
            .split_once('=')
            .ok_or_else(|| HiddenError::Syntax(text.to_string()))?;
        let value = v
            .parse()
            .ok()
            .filter(|v: &f64| v.is_finite())
            .ok_or_else(|| HiddenError::NotANumber {
                text: text.to_string(),
                value: v.to_string(),
            })?;
        let (effect, param) = key
            .split_once('.')
            .map_or((key, None), |(a, b)| (a, Some(b.to_string())));
        Ok(Hidden {
            effect: effect.to_string(),
            param,
            value,
            text: text.to_string(),
        })
    }
}

/// The model the user declared and the robot that hides effects from it.
pub struct Robots {
    /// The spec with `sets`: what the simulated robot is commanded by.
    pub spec: Runner,
    /// The spec with the hidden effects added at their values, and `sets`.
    pub robot: Runner,
}

/// `spec` (with the values `sets`) and the robot with `hidden` added, from
/// the bundled catalogue and the user's `effect_dirs`; both derived by
/// `deriver`.
pub fn with_hidden(
    spec: &Model,
    hidden: &[Hidden],
    sets: &[(String, f64)],
    effect_dirs: &[PathBuf],
    deriver: &dyn Deriver,
) -> Result<Robots, HiddenError> {
    let named = spec.path.display().to_string();
    let base = Runner::new(deriver.derive(spec, &named)?, sets)?;
    let (model, values) = added(spec, hidden, effect_dirs)?;
    let robot_ir = if hidden.is_empty() {
        base.ir.clone()
    } else {
        let texts: Vec<&str> = hidden.iter().map(|h| h.text.as_str()).collect();
        let label = format!("{named} with {} added", texts.join(", "));
        deriver.derive(&model, &label)?
    };
    let mut all = sets.to_vec();
    all.extend(values);
    let robot = Runner::new(robot_ir, &all)?;
    Ok(Robots { spec: base, robot })
}

/// `spec` with each hidden effect added, and each effect parameter's value.
fn added(
    spec: &Model,
    hidden: &[Hidden],
    effect_dirs: &[PathBuf],
) -> Result<(Model, Vec<(String, f64)>), HiddenError> {
    let cat = catalogue(effect_dirs)?;
    let mut model = spec.clone();
    let mut values = Vec::new();
    for h in hidden {
        let text = || h.text.clone();
        let eff = find(&cat, &h.effect).map_err(|m| HiddenError::Unknown {
            text: text(),
            message: m.to_string(),
        })?;
        let adds: Vec<String> = eff
            .parameters_for(&model)
            .into_iter()
            .map(|p| p.name)
            .collect();
        // the first parameter this model gets (a per-wheel effect adds only
        // the parameters of the wheels the model has)
        let param = h
            .param
            .clone()
            .unwrap_or_else(|| adds.first().cloned().unwrap_or_default());
        if eff.applicability(&model) == Applicability::Applies && !adds.contains(&param) {
            return Err(HiddenError::NoSuchParameter {
                text: text(),
                effect: h.effect.clone(),
                param,
                adds: adds.join(", "),
            });
        }
        model = eff
            .added_to(&model)
            .map_err(|why| HiddenError::DoesNotApply {
                text: text(),
                spec: spec.path.display().to_string(),
                effect: h.effect.clone(),
                why: why.to_string(),
            })?;
        values.push((param, h.value));
    }
    Ok((model, values))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hidden_effects_are_read_as_the_user_writes_them() {
        let h: Hidden = "lateral_slip=0.02".parse().unwrap();
        assert_eq!(
            (h.effect.as_str(), h.param, h.value),
            ("lateral_slip", None, 0.02)
        );
        let h: Hidden = "sensor_offset.sensor_dx=-0.1".parse().unwrap();
        assert_eq!(h.param.as_deref(), Some("sensor_dx"));
        assert_eq!(h.value, -0.1);
        assert_eq!(Hidden::new("sensor_offset", "sensor_dx", -0.1), h);
        for (bad, says) in [
            ("lateral_slip", "expected NAME=VALUE"),
            ("lateral_slip=abc", "`abc` is not a finite number"),
            ("lateral_slip=inf", "`inf` is not a finite number"),
        ] {
            let e = bad.parse::<Hidden>().unwrap_err().to_string();
            assert!(
                e.starts_with(&format!("--effect {bad}: ")) && e.contains(says),
                "{e}"
            );
        }
    }
}
