//! Which names an expression of a model may read, by where it stands.
//!
//! One rule for both ways a model comes to be: read from its spec file
//! ([`super::Model::parse`], which names the symbol's line and column) and
//! built in memory ([`super::Model::check_names`], an effect applied to a
//! typed model, whose error the effect then places in its own file).
use crate::expr::CONSTANTS;
use std::fmt;

/// What a declared name is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NameKind {
    State,
    Input,
    Parameter,
    Noise,
    Definition,
}

impl fmt::Display for NameKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            NameKind::State => "state",
            NameKind::Input => "input",
            NameKind::Parameter => "parameter",
            NameKind::Noise => "noise",
            NameKind::Definition => "definition",
        })
    }
}

/// Where an expression stands in a model.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Place {
    /// A `[[define]]`: anything declared but the pose.
    Definition,
    /// A `[motion]` twist row: as a definition (noise enters here).
    Twist,
    /// A `[constraints]` row: neither the pose nor the noise.
    Constraint,
    /// An observation: the pose, the twist, the declared names but the
    /// noise, and a landmark's position when it has one.
    Observation { landmark: bool },
    /// The `[inverse]`: the twist and the parameters only.
    Inverse,
    /// A `[controller.values]` entry: the parameters only.
    Controller,
}

/// Why a name may not stand where it does.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Refusal {
    /// Nothing declares it (and the language does not reserve it).
    Unknown,
    /// Declared (or reserved), but not readable here.
    NotHere,
    /// `xl`/`yl` in an observation without `landmark = true`.
    NeedsLandmark,
    /// The inverse reads the twist and the parameters only.
    InverseOnly,
    /// A controller value is a function of the parameters only.
    ParametersOnly,
}

const TWIST: [&str; 3] = ["vx", "vy", "omega"];
const LANDMARK: [&str; 2] = ["xl", "yl"];

impl Place {
    /// Whether `v`, declared as `kind` (`None`: not declared), may stand
    /// here.
    pub fn admits(self, v: &str, kind: Option<NameKind>) -> Result<(), Refusal> {
        use NameKind::*;
        if CONSTANTS.contains(&v) {
            return Ok(());
        }
        let ok = match self {
            Place::Definition | Place::Twist => kind.is_some_and(|k| k != State),
            Place::Constraint => kind.is_some_and(|k| k != State && k != Noise),
            Place::Observation { landmark } => {
                if LANDMARK.contains(&v) && !landmark {
                    return Err(Refusal::NeedsLandmark);
                }
                TWIST.contains(&v) || LANDMARK.contains(&v) || kind.is_some_and(|k| k != Noise)
            }
            Place::Inverse => {
                return (TWIST.contains(&v) || kind == Some(Parameter))
                    .then_some(())
                    .ok_or(Refusal::InverseOnly);
            }
            Place::Controller => {
                return (kind == Some(Parameter))
                    .then_some(())
                    .ok_or(Refusal::ParametersOnly);
            }
        };
        match (ok, kind) {
            (true, _) => Ok(()),
            (false, Some(_)) => Err(Refusal::NotHere),
            (false, None) if super::RESERVED.contains(&v) => Err(Refusal::NotHere),
            (false, None) => Err(Refusal::Unknown),
        }
    }
}

impl Refusal {
    /// The message for name `v`, with the name in backticks (an effect finds
    /// its line by it).
    pub fn message(self, v: &str) -> String {
        match self {
            Refusal::Unknown => format!("unknown symbol `{v}`"),
            Refusal::NotHere => format!("`{v}` cannot be used here"),
            Refusal::NeedsLandmark => format!("`{v}` needs `landmark = true` on this observation"),
            Refusal::InverseOnly => {
                format!("inverse may use vx, vy, omega and parameters only, not `{v}`")
            }
            Refusal::ParametersOnly => {
                format!("a controller value is computed from parameters only, not `{v}`")
            }
        }
    }
}

/// A model built in memory whose names do not add up (a spec file's
/// errors are [`crate::error::SourceError`]s at the symbol instead).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum NameError {
    #[error("`{name}` is declared twice (a {first} and a {then})")]
    DeclaredTwice {
        name: String,
        first: NameKind,
        then: NameKind,
    },
    #[error("{}", why.message(name))]
    Refused { name: String, why: Refusal },
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_place_reads_what_the_spec_language_says() {
        use NameKind::*;
        let twist = Place::Twist;
        assert_eq!(twist.admits("k", Some(Parameter)), Ok(()));
        assert_eq!(twist.admits("dv", Some(Noise)), Ok(()));
        assert_eq!(twist.admits("x", Some(State)), Err(Refusal::NotHere));
        assert_eq!(twist.admits("vx", None), Err(Refusal::NotHere));
        assert_eq!(twist.admits("k_zz", None), Err(Refusal::Unknown));
        assert_eq!(twist.admits("pi", None), Ok(()));
        assert_eq!(
            Place::Constraint.admits("dv", Some(Noise)),
            Err(Refusal::NotHere)
        );
        let seen = Place::Observation { landmark: false };
        assert_eq!(seen.admits("theta", Some(State)), Ok(()));
        assert_eq!(seen.admits("omega", None), Ok(()));
        assert_eq!(seen.admits("xl", None), Err(Refusal::NeedsLandmark));
        assert_eq!(seen.admits("dv", Some(Noise)), Err(Refusal::NotHere));
        assert_eq!(
            Place::Observation { landmark: true }.admits("yl", None),
            Ok(())
        );
        assert_eq!(Place::Inverse.admits("k", Some(Parameter)), Ok(()));
        assert_eq!(
            Place::Inverse.admits("u", Some(Input)),
            Err(Refusal::InverseOnly)
        );
    }
}
