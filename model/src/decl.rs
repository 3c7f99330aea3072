//! Declarations: the plain-data description of a model's signals, parameters
//! and observations. The spec language parses them and the IR carries them, so
//! the IR depends on no spec type (no expression, no source span): a loaded IR
//! is complete without the spec it came from.
use serde::{Deserialize, Serialize};

/// How a log column feeds an input symbol.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum InputKind {
    /// Cumulative counter or wheel angle; the input symbol is its rate over the step
    /// (increment / dt), constant within the step.
    Cumulative,
    /// Absolute value: a velocity command, a steering angle (see [`Between`]).
    Absolute,
}

/// What an absolute input does between two rows of a log.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Between {
    /// The value holds from its row until the next row, as a command does
    /// (the robot executes the last command it received).
    Hold,
    /// A sampled continuous signal (a steering encoder's angle): the value
    /// moves linearly from one row's sample to the next.
    Linear,
}

impl Input {
    /// What the input does between rows: as declared; otherwise a position
    /// (an angle or an absolute encoder's reading: unit rad, deg, tick or
    /// count) is a sampled continuous signal and anything else (a speed or
    /// turn-rate command) holds, as CONTRACT.md section 1 says of commands.
    /// Cumulative inputs spread their difference over the interval either way.
    pub fn between(&self) -> Between {
        if let Some(b) = self.between {
            return b;
        }
        let unit = self.unit.trim().to_ascii_lowercase();
        let position = [
            "rad", "deg", "degree", "degrees", "tick", "ticks", "count", "counts",
        ]
        .contains(&unit.as_str());
        if position {
            Between::Linear
        } else {
            Between::Hold
        }
    }

    /// Whether the input counts whole events (encoder ticks, counts,
    /// pulses): its unit's first word, before any `/s`, names one. Such a
    /// counter reads integers, and `simulate` writes them so.
    pub fn counts_events(&self) -> bool {
        let unit = self.unit.trim().to_ascii_lowercase();
        let head = unit.split('/').next().unwrap_or("");
        const EVENTS: [&str; 9] = [
            "count", "counts", "tick", "ticks", "pulse", "pulses", "cnt", "step", "steps",
        ];
        head.split(|c: char| !c.is_ascii_alphanumeric())
            .any(|w| EVENTS.contains(&w))
    }

    /// A command: an absolute input that holds between rows (a speed or
    /// turn-rate set point), which an input delay, a response lag and a
    /// deadband act on.
    pub fn is_command(&self) -> bool {
        self.kind == InputKind::Absolute && self.between() == Between::Hold
    }
}

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Input {
    pub name: String,
    pub column: String,
    pub kind: InputKind,
    /// Physical domain of the input's value (rate for cumulative inputs), e.g. a
    /// steering lock; verification samples inside it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub range: Option<[f64; 2]>,
    /// Bits of a cumulative counter that wraps around (e.g. 16 or 32: a count
    /// that passes 2^bits starts again at 0, or at -2^(bits-1) for a signed
    /// one): steps are differenced modulo 2^bits, so a wrap is not read as a
    /// huge backwards jump.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub wrap: Option<u32>,
    /// Actuator limit: the largest |rate| the input can deliver (a cumulative
    /// input's value is its rate; an absolute input's rate is how fast it can
    /// change, e.g. a steering servo's slew rate), in the input's unit (per
    /// second for an absolute input). `kinegen inverse` marks where a path
    /// needs more.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_rate: Option<f64>,
    /// An absolute input's value between rows, where the spec says
    /// (`between = "hold"` or `"linear"`); see [`Input::between`].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub between: Option<Between>,
    pub unit: String,
    pub doc: String,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Param {
    pub name: String,
    pub nominal: f64,
    pub unit: String,
    pub doc: String,
    pub min: Option<f64>,
    pub max: Option<f64>,
    /// Calibrated by `fit` unless false.
    pub free: bool,
    /// Folded into generated code; not a runtime argument.
    pub constant: bool,
    /// The delay, in s, of every measurement (poses, gyro) relative to the
    /// inputs: measurement k, logged at t_k, is compared with the model at
    /// t_k - delay. At most one parameter of a spec; the analysis handles it in
    /// one place (kinegen_analysis::model_on_log::timeline).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub measurement_delay: bool,
    /// The delay, in s, with which the robot executes its commands (absolute
    /// inputs that hold between rows): the command logged at t acts from t +
    /// delay. At most one parameter of a spec (kinegen_analysis::model_on_log::timeline).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub input_delay: bool,
    /// The time constant, in s, of the robot's first-order response to its
    /// commands: the executed command approaches each new one as 1 -
    /// exp(-t/lag) (a motor controller's response, an acceleration limit),
    /// after any input delay. At most one parameter of a spec
    /// (kinegen_analysis::model_on_log::timeline).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub input_lag: bool,
    /// How far from its nominal value the parameter is known to lie (one
    /// standard deviation, in its unit; a spec's `"2%"` is resolved against
    /// the nominal value): `fit` adds it as a Gaussian prior, so a log that
    /// says little about the parameter leaves it near nominal.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tolerance: Option<f64>,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Noise {
    pub name: String,
    pub doc: String,
    pub sigma: f64,
    /// The sigma's unit. A density (`m/s/sqrt(Hz)`, `rad/s/sqrt(Hz)`: see
    /// [`Noise::is_density`]) gives a variance that grows with elapsed time;
    /// anything else is seed 001's per-step sigma (eq. 5), whose variance
    /// grows with the number of rows.
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub unit: String,
}

impl Noise {
    /// Whether `sigma` is a spectral density (its unit has a `/sqrt(Hz)` or
    /// `sqrt(s)`): white noise whose variance over an interval is sigma^2
    /// times its length, whatever the log's rate.
    pub fn is_density(&self) -> bool {
        density_factors(&self.unit) > 0
    }
}

/// How many square roots of a frequency or a time a unit has (a density,
/// `m/s/sqrt(Hz)`, has one).
pub fn density_factors(unit: &str) -> usize {
    let u: String = unit
        .to_ascii_lowercase()
        .chars()
        .filter(|c| !c.is_whitespace())
        .collect();
    ["sqrt(hz)", "\u{221a}hz", "rthz", "sqrt(s)", "\u{221a}s"]
        .iter()
        .map(|d| u.matches(d).count())
        .sum()
}

/// What an observation measures. The analysis finds the pose tracker, the gyro
/// and the range-bearing sensor by role, never by observation name, and effects
/// patch observations by role.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ObservationRole {
    /// The pose (x, y, heading) of a body-fixed point, in the world frame: a
    /// motion-capture marker, a tracker. Three columns.
    Pose,
    /// The body yaw rate: a gyro. One column.
    YawRate,
    /// Range and bearing to a mapped landmark (`landmark = true`).
    RangeBearing,
    /// Anything else: derived and verified, not used by the analysis.
    Other,
}

impl ObservationRole {
    /// Exteroceptive observations see the robot from outside (or the world from
    /// the robot): where the sensor is mounted matters.
    pub fn is_exteroceptive(self) -> bool {
        matches!(self, ObservationRole::Pose | ObservationRole::RangeBearing)
    }
}

/// The log columns of a ground-truth pose when a spec declares no pose observation.
pub const DEFAULT_POSE_COLUMNS: [&str; 3] = ["gt_x", "gt_y", "gt_theta"];
/// The log column of the yaw rate when a spec declares no yaw-rate observation.
pub const DEFAULT_GYRO_COLUMN: &str = "gyro_z";

/// An observation as the IR carries it: what it measures and where its columns
/// are in a log; its expressions live in the derived `obs_*` kernels.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ObservationDecl {
    pub name: String,
    pub doc: String,
    /// Log columns, one per predicted value.
    pub columns: Vec<String>,
    /// Which values are angles (compared modulo 2 pi).
    pub angle: Vec<bool>,
    /// Noise standard deviation per value (0: undeclared).
    pub sigma: Vec<f64>,
    /// Whether the kernels take a landmark position `lm` = (xl, yl).
    pub landmark: bool,
    pub role: ObservationRole,
}

#[cfg(test)]
mod counting_tests {
    use super::*;

    fn input(unit: &str) -> Input {
        Input {
            unit: unit.into(),
            ..serde_json::from_str(
                r#"{"name": "u", "column": "u", "kind": "cumulative", "unit": "", "doc": ""}"#,
            )
            .unwrap()
        }
    }

    #[test]
    fn every_count_like_unit_counts_events_and_angles_do_not() {
        for u in [
            "count/s",
            "counts",
            "tick/s",
            "ticks",
            "pulse/s",
            "encoder count/s",
            "Tick/s",
        ] {
            assert!(input(u).counts_events(), "{u}");
        }
        for u in ["rad/s", "m/s", "rad", "", "1/s"] {
            assert!(!input(u).counts_events(), "{u}");
        }
    }
}
