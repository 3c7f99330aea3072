//! The effect catalogue: physically meaningful changes to a model, kept as data
//! (`spec/effects/*.toml`, compiled into the binary; a user's own catalogue adds
//! to it with `--effects DIR`).
//!
//! An effect is a typed transform of a spec: [`Effect::applicability`] asks what
//! the *model* has (an explicit twist, no lateral velocity, steering inputs,
//! wheels on both sides, a gyro, exteroceptive sensors), never its name, and
//! [`Effect::apply`] edits the spec's text with `toml_edit`, so the user's
//! comments, key order and formatting survive and the only change is the effect.
//!
//! File format (see `spec/README.md`): `name`, `doc`, `requires` (capabilities),
//! `[[parameter]]` blocks as in specs (a parameter is added only when an applied
//! patch uses it; `bounds = "robot_size"` makes its bounds scale with the
//! robot's largest length), and patches: `[motion]` (templates over the original
//! `{vx}`, `{vy}`, `{omega}`), `[[each_input]]` (a template over `{input}` for
//! every input of a class: `steering`, `right_wheel`, `left_wheel`, `command`), and
//! `[observation.ROLE]` (ROLE = `pose`, `yaw_rate`, `range_bearing`; `expr`
//! templates over `{0}`, `{1}`..., `substitute` for state symbols).
use crate::expr::{self, Expr};
use crate::spec::{InputKind, Kinematics, Model, ObservationRole, DEFAULT_POSE_COLUMNS};
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use toml_edit::{value, Array, ArrayOfTables, DocumentMut, Item, Table, Value};

/// The bundled catalogue, compiled in so every command works from any directory.
const BUNDLED: &[(&str, &str)] = &[
    (
        "command_deadband.toml",
        include_str!("../../spec/effects/command_deadband.toml"),
    ),
    (
        "command_lag.toml",
        include_str!("../../spec/effects/command_lag.toml"),
    ),
    (
        "gyro_bias.toml",
        include_str!("../../spec/effects/gyro_bias.toml"),
    ),
    (
        "gyro_scale.toml",
        include_str!("../../spec/effects/gyro_scale.toml"),
    ),
    (
        "input_delay.toml",
        include_str!("../../spec/effects/input_delay.toml"),
    ),
    (
        "lateral_slip.toml",
        include_str!("../../spec/effects/lateral_slip.toml"),
    ),
    (
        "longitudinal_slip.toml",
        include_str!("../../spec/effects/longitudinal_slip.toml"),
    ),
    (
        "sensor_offset.toml",
        include_str!("../../spec/effects/sensor_offset.toml"),
    ),
    (
        "steering_offset.toml",
        include_str!("../../spec/effects/steering_offset.toml"),
    ),
    (
        "time_offset.toml",
        include_str!("../../spec/effects/time_offset.toml"),
    ),
    (
        "wheel_misalignment.toml",
        include_str!("../../spec/effects/wheel_misalignment.toml"),
    ),
    (
        "wheel_radius_asymmetry.toml",
        include_str!("../../spec/effects/wheel_radius_asymmetry.toml"),
    ),
    (
        "wheelbase_scale.toml",
        include_str!("../../spec/effects/wheelbase_scale.toml"),
    ),
];

/// What a model must have for an effect to mean anything.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Capability {
    /// An explicit body twist (`[motion]`), which twist templates patch.
    Twist,
    /// No lateral body velocity in the twist (wheels that cannot slide sideways).
    Nonholonomic,
    /// An absolute input: a steering angle read by an encoder.
    Steering,
    /// Cumulative inputs that turn the body both ways (left and right wheels).
    Differential,
    /// A yaw-rate observation (a gyro).
    YawRate,
}

/// Classes of inputs an `[[each_input]]` patch applies to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum InputClass {
    /// Absolute inputs (steering encoders).
    Steering,
    /// Cumulative inputs that turn the body counter-clockwise when they advance.
    RightWheel,
    /// Cumulative inputs that turn the body clockwise when they advance.
    LeftWheel,
    /// Commands: absolute inputs that hold from their row until the next
    /// (a velocity-commanded robot's speed and turn-rate set points).
    Command,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EachInput {
    pub class: InputClass,
    /// Template over `{input}` (the input's name); the parameters it names may
    /// contain `{input}` too (one parameter per input).
    pub expr: String,
    /// How the spec's declared `[inverse]` expression of such an input changes:
    /// a template over `{inverse}` (the old expression) and `{input}`; the
    /// inverse of `expr` applied to it (an offset u - c needs {inverse} + c).
    /// Without it a declared inverse is dropped when the effect is added (it
    /// would no longer invert the motion).
    #[serde(default)]
    pub inverse: Option<String>,
}

#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ObservationPatch {
    /// Templates over the observation's expressions `{0}`, `{1}`...
    #[serde(default)]
    pub expr: Vec<String>,
    /// Replace state symbols (`x`, `y`) in the observation's expressions.
    #[serde(default)]
    pub substitute: BTreeMap<String, String>,
    /// When the model has no observation of this role, add one with these
    /// columns (the contract's defaults when empty) and identity expressions.
    #[serde(default)]
    pub create: bool,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Effect {
    pub name: String,
    pub doc: String,
    #[serde(default)]
    pub requires: Vec<Capability>,
    #[serde(default)]
    pub parameter: Vec<toml::Table>,
    #[serde(default)]
    pub motion: BTreeMap<String, String>,
    #[serde(default)]
    pub each_input: Vec<EachInput>,
    #[serde(default)]
    pub observation: BTreeMap<String, ObservationPatch>,
    /// Where the catalogue file came from (bundled, or a user's directory).
    #[serde(skip)]
    pub origin: String,
}

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
    /// An expression the substitution reads does not parse.
    #[error("`{text}`: {message}")]
    Expression { text: String, message: String },
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
            let text = crate::files::read_text(&f).map_err(|(at, message)| EffectError {
                file: f.clone(),
                message: match at {
                    Some((l, c)) => format!("line {l}, column {c}: {message}"),
                    None => message,
                },
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

fn parse_effect(file: &Path, text: &str) -> Result<Effect, EffectError> {
    let err = |m: String| EffectError {
        file: file.to_path_buf(),
        message: m,
    };
    let mut e: Effect = toml::from_str(text).map_err(|x| {
        let at = x
            .span()
            .map(|s| crate::SourcePos::from_offset(text, s.start));
        err(match at {
            Some(p) => format!("line {}, column {}: {}", p.line, p.column, x.message()),
            None => x.message().to_string(),
        })
    })?;
    for role in e.observation.keys() {
        role_of(role).ok_or_else(|| {
            err(format!(
                "[observation.{role}]: the role must be pose, yaw_rate or range_bearing"
            ))
        })?;
    }
    e.origin = file.display().to_string();
    Ok(e)
}

fn role_of(key: &str) -> Option<ObservationRole> {
    match key {
        "pose" => Some(ObservationRole::Pose),
        "yaw_rate" => Some(ObservationRole::YawRate),
        "range_bearing" => Some(ObservationRole::RangeBearing),
        _ => None,
    }
}

/// Which way advancing each input turns the body: the sign of d omega / d u_i at
/// the nominal parameters (0 for absolute inputs and for inputs that do not turn
/// the body). Evaluated numerically on the spec's own expressions; None for
/// constraint models, whose twist comes from a least-squares solve.
pub fn turn_signs(m: &Model) -> Option<Vec<i8>> {
    let Kinematics::Twist(tw) = &m.kinematics else {
        return None;
    };
    let omega = m.expand(&tw[2]);
    let at = |k: Option<usize>| {
        omega.eval(&|v: &str| {
            if let Some(p) = m.params.iter().find(|p| p.name == v) {
                return Some(p.nominal);
            }
            m.inputs
                .iter()
                .position(|i| i.name == v)
                .map(|i| if Some(i) == k { 1.0 } else { 0.0 })
                .or_else(|| m.noise.iter().any(|n| n.name == v).then_some(0.0))
        })
    };
    let w0 = at(None)?;
    Some(
        m.inputs
            .iter()
            .enumerate()
            .map(|(k, i)| {
                if i.kind != InputKind::Cumulative {
                    return 0;
                }
                match at(Some(k)).map(|w| w - w0) {
                    Some(d) if d > 1e-12 => 1,
                    Some(d) if d < -1e-12 => -1,
                    _ => 0,
                }
            })
            .collect(),
    )
}

/// Inputs of a class, by name.
pub fn inputs_of(m: &Model, class: InputClass) -> Vec<String> {
    let signs = turn_signs(m);
    m.inputs
        .iter()
        .enumerate()
        .filter(|(k, i)| match class {
            // an angle sampled from a joint (Between::Linear), not a command
            // that holds between rows: a speed command has no zero offset to read
            InputClass::Steering => {
                i.kind == InputKind::Absolute && i.between() == crate::decl::Between::Linear
            }
            InputClass::Command => i.is_command(),
            InputClass::RightWheel => signs.as_ref().is_some_and(|s| s[*k] > 0),
            InputClass::LeftWheel => signs.as_ref().is_some_and(|s| s[*k] < 0),
        })
        .map(|(_, i)| i.name.clone())
        .collect()
}

/// Whether the model has a capability, and if not, what it lacks (for people).
pub fn has(m: &Model, c: Capability) -> Result<(), &'static str> {
    let ok = match c {
        Capability::Twist => matches!(m.kinematics, Kinematics::Twist(_)),
        // vy is zero up to process noise
        Capability::Nonholonomic => matches!(&m.kinematics, Kinematics::Twist(t) if {
            let vy = m.expand(&t[1]);
            vy.variables().iter().all(|(v, _)| m.noise.iter().any(|n| n.name == *v)) && vy.eval(&|_| Some(0.0)) == Some(0.0)
        }),
        Capability::Steering => !inputs_of(m, InputClass::Steering).is_empty(),
        Capability::Differential => {
            !inputs_of(m, InputClass::RightWheel).is_empty()
                && !inputs_of(m, InputClass::LeftWheel).is_empty()
        }
        Capability::YawRate => m
            .observations
            .iter()
            .any(|o| o.role == ObservationRole::YawRate),
    };
    if ok {
        return Ok(());
    }
    Err(match c {
        Capability::Twist => "it patches an explicit body twist ([motion]) and this model is given by kinematic constraints",
        Capability::Nonholonomic => "it adds lateral velocity to a model whose twist has none (vy = 0), and this model already moves sideways",
        Capability::Steering => "the model has no absolute steering input (an angle read between rows; commands that hold are not)",
        Capability::Differential => "the model has no wheels that turn the body in opposite directions",
        Capability::YawRate => "the model has no yaw-rate (gyro) observation",
    })
}

/// Add an effect's parameters to the spec's `[[parameter]]` array, with the
/// nominal values `values` gives.
fn add_parameters(
    doc: &mut DocumentMut,
    params: &[AddedParameter],
    values: &BTreeMap<String, f64>,
) -> Result<(), ApplyError> {
    let arr = doc
        .entry("parameter")
        .or_insert(Item::ArrayOfTables(ArrayOfTables::new()))
        .as_array_of_tables_mut()
        .ok_or(ApplyError::Shape("`parameter` is not an array of tables"))?;
    for p in params {
        let mut t = Table::new();
        for (k, v) in &p.table {
            t.insert(k, value(to_edit(v)));
        }
        if let Some(v) = values.get(&p.name) {
            t.insert("nominal", value(*v));
        }
        arr.push(t);
    }
    Ok(())
}

/// Substitute inputs (`sub`) in the definitions, the twist and the
/// constraint rows.
fn substitute_inputs(
    doc: &mut DocumentMut,
    sub: &BTreeMap<String, String>,
) -> Result<(), ApplyError> {
    for d in doc
        .get_mut("define")
        .and_then(Item::as_array_of_tables_mut)
        .into_iter()
        .flat_map(|a| a.iter_mut())
    {
        edit_str(d.get_mut("expr"), |e| subst(e, sub))?;
    }
    if let Some(m) = doc.get_mut("motion").and_then(Item::as_table_like_mut) {
        for k in ["vx", "vy", "omega"] {
            edit_str(m.get_mut(k), |e| subst(e, sub))?;
        }
    }
    let rows = doc
        .get_mut("constraints")
        .and_then(|c| c.get_mut("row"))
        .and_then(Item::as_array_of_tables_mut);
    for row in rows.into_iter().flat_map(|a| a.iter_mut()) {
        if let Some(co) = row.get_mut("coeffs").and_then(Item::as_array_mut) {
            for c in co.iter_mut() {
                if let Some(e) = c.as_str() {
                    *c = subst(e, sub)?.into();
                }
            }
        }
    }
    Ok(())
}

/// A parameter of an effect, as it is added to a spec.
#[derive(Debug, Clone, PartialEq)]
pub struct AddedParameter {
    pub name: String,
    pub table: toml::Table,
}

impl Effect {
    pub fn applicability(&self, m: &Model) -> Applicability {
        if m.effects.iter().any(|e| e == &self.name) {
            return Applicability::AlreadyIn;
        }
        for c in &self.requires {
            if let Err(why) = has(m, *c) {
                return Applicability::NotApplicable(why.into());
            }
        }
        if !self.motion.is_empty() {
            if let Err(why) = has(m, Capability::Twist) {
                return Applicability::NotApplicable(why.into());
            }
        }
        let patches = self.substitutions(m).len()
            + self.motion.len()
            + self
                .observation
                .iter()
                .filter(|(role, p)| {
                    p.create || m.observations.iter().any(|o| Some(o.role) == role_of(role))
                })
                .count();
        let times = self.timing().is_some();
        if self.measurement_delay().is_some() {
            if let Some(d) = m.params.iter().find(|p| p.measurement_delay) {
                return Applicability::NotApplicable(format!(
                    "the model already declares a measurement delay (`{}`)",
                    d.name
                ));
            }
        }
        for (flag, declared, what, measured) in [
            (
                self.input_delay(),
                m.params.iter().find(|p| p.input_delay),
                "an input delay",
                "a delay of measured inputs is `time_offset`",
            ),
            (
                self.input_lag(),
                m.params.iter().find(|p| p.input_lag),
                "a command response lag",
                "measured inputs (encoders) follow the motion as it happens",
            ),
        ] {
            if flag.is_none() {
                continue;
            }
            if let Some(d) = declared {
                return Applicability::NotApplicable(format!(
                    "the model already declares {what} (`{}`)",
                    d.name
                ));
            }
            if inputs_of(m, InputClass::Command).is_empty() {
                return Applicability::NotApplicable(format!(
                    "the model has no commands (absolute inputs that hold between rows): {measured}"
                ));
            }
        }
        if patches == 0 && !times {
            return Applicability::NotApplicable(format!(
                "nothing to patch: {}",
                self.what_it_patches()
            ));
        }
        Applicability::Applies
    }

    /// What the effect patches, for messages.
    fn what_it_patches(&self) -> String {
        let mut v: Vec<String> = self
            .each_input
            .iter()
            .map(|e| format!("{:?} inputs", e.class).to_lowercase())
            .collect();
        v.extend(
            self.observation
                .keys()
                .map(|r| format!("the {r} observation")),
        );
        if v.is_empty() {
            v.push("the twist".into());
        }
        format!("it changes {} and the model has none", v.join(" and "))
    }

    /// The parameter the analysis reads as a measurement delay (the timeline
    /// shifts measurements by it); None for effects that patch expressions.
    pub fn measurement_delay(&self) -> Option<&str> {
        self.flagged("measurement_delay")
    }

    /// The parameter the analysis reads as the delay with which the robot
    /// executes its commands (see [`crate::decl::Param::input_delay`]).
    pub fn input_delay(&self) -> Option<&str> {
        self.flagged("input_delay")
    }

    /// The parameter the analysis reads as the time constant of the robot's
    /// response to its commands (see [`crate::decl::Param::input_lag`]).
    pub fn input_lag(&self) -> Option<&str> {
        self.flagged("input_lag")
    }

    /// The name of the parameter marked `flag = true`, for an effect that
    /// patches no expression (a timing effect); None otherwise.
    fn flagged(&self, flag: &str) -> Option<&str> {
        let patches =
            !self.motion.is_empty() || !self.each_input.is_empty() || !self.observation.is_empty();
        if patches {
            return None;
        }
        self.parameter
            .iter()
            .filter(|p| p.get(flag).and_then(|d| d.as_bool()) == Some(true))
            .find_map(|p| p.get("name").and_then(|n| n.as_str()))
    }

    /// The timing parameter of an effect that shifts a timeline instead of
    /// patching expressions (`time_offset`, `input_delay`, `command_lag`).
    pub fn timing(&self) -> Option<&str> {
        self.measurement_delay()
            .or(self.input_delay())
            .or(self.input_lag())
    }

    /// Observation roles this effect changes when it changes nothing else (a gyro
    /// bias is visible in gyro readings only, so a log without a gyro cannot test
    /// it). None for effects that change the motion or the timing.
    pub fn observation_only_roles(&self) -> Option<Vec<ObservationRole>> {
        (self.motion.is_empty()
            && self.each_input.is_empty()
            && self.timing().is_none()
            && !self.observation.is_empty())
        .then(|| self.observation.keys().filter_map(|k| role_of(k)).collect())
    }

    /// The declared `[inverse]` after this effect's input substitutions: each
    /// substituted input's expression rewritten by its `inverse` template, or
    /// the whole table removed when a substituted input has none.
    fn patch_inverse(&self, m: &Model, doc: &mut DocumentMut) {
        let Some(inputs) = doc
            .get_mut("inverse")
            .and_then(|i| i.get_mut("inputs"))
            .and_then(Item::as_array_mut)
        else {
            return;
        };
        let mut keep = true;
        for e in &self.each_input {
            for name in inputs_of(m, e.class) {
                let Some(k) = m.inputs.iter().position(|i| i.name == name) else {
                    continue;
                };
                match (&e.inverse, inputs.get_mut(k)) {
                    (Some(tpl), Some(v)) => {
                        if let Some(old) = v.as_str() {
                            let new = tpl
                                .replace("{inverse}", &format!("({old})"))
                                .replace("{input}", &name);
                            *v = new.into();
                        }
                    }
                    _ => keep = false,
                }
            }
        }
        if !keep {
            doc.remove("inverse");
        }
    }

    /// Input substitutions for this model: input name -> replacement text.
    fn substitutions(&self, m: &Model) -> BTreeMap<String, String> {
        let mut out = BTreeMap::new();
        for e in &self.each_input {
            for input in inputs_of(m, e.class) {
                out.insert(input.clone(), e.expr.replace("{input}", &input));
            }
        }
        out
    }

    /// The patch texts that will go into this model (to see which parameters they use).
    fn patch_texts(&self, m: &Model) -> Vec<String> {
        let mut texts: Vec<String> = self.substitutions(m).into_values().collect();
        texts.extend(self.motion.values().cloned());
        for (role, patch) in &self.observation {
            if patch.create || m.observations.iter().any(|o| Some(o.role) == role_of(role)) {
                texts.extend(patch.expr.iter().cloned());
                texts.extend(patch.substitute.values().cloned());
            }
        }
        texts
    }

    /// The parameters this effect adds to `m`, in catalogue order: those its
    /// applied patches use (a per-input effect adds one per input the model has).
    pub fn parameters_for(&self, m: &Model) -> Vec<AddedParameter> {
        let used: Vec<String> = self
            .patch_texts(m)
            .iter()
            .flat_map(|text| {
                // templates hold {vx}, {0}...: blank them out before parsing
                let clean: String = text
                    .split('{')
                    .enumerate()
                    .map(|(i, part)| {
                        if i == 0 {
                            part.to_string()
                        } else {
                            format!("0{}", part.split_once('}').map_or("", |x| x.1))
                        }
                    })
                    .collect();
                expr::parse(&clean)
                    .map(|e| {
                        e.variables()
                            .into_iter()
                            .map(|(v, _)| v.to_string())
                            .collect::<Vec<_>>()
                    })
                    .unwrap_or_default()
            })
            .collect();
        let mut out = Vec::new();
        for p in &self.parameter {
            let Some(name) = p.get("name").and_then(|n| n.as_str()) else {
                continue;
            };
            // one parameter per input when its name is a template
            let names: Vec<(String, Option<&crate::spec::Input>)> = if name.contains("{input}") {
                m.inputs
                    .iter()
                    .map(|i| (name.replace("{input}", &i.name), Some(i)))
                    .collect()
            } else {
                vec![(name.to_string(), None)]
            };
            for (n, input) in names {
                if used.contains(&n) || self.timing() == Some(n.as_str()) {
                    let mut t = p.clone();
                    t.insert("name".into(), toml::Value::String(n.clone()));
                    // `unit = "{input_unit}"`: the parameter is in its input's units
                    // (a steering encoder in ticks gets an offset in ticks)
                    if let (Some(i), Some("{input_unit}")) =
                        (input, t.get("unit").and_then(|u| u.as_str()))
                    {
                        t.insert("unit".into(), toml::Value::String(i.unit.clone()));
                    }
                    let bounds = t.remove("bounds");
                    let half = match bounds.as_ref().and_then(|b| b.as_str()) {
                        Some("robot_size") => Some(robot_size(m)),
                        // an eighth of the input's declared range (a steering lock),
                        // else the template's own min and max
                        Some("input_range") => input
                            .and_then(|i| i.range)
                            .map(|[lo, hi]| (hi - lo).abs() / 8.0),
                        _ => None,
                    };
                    if let Some(r) = half.filter(|r| r.is_finite() && *r > 0.0) {
                        t.insert("min".into(), toml::Value::Float(-r));
                        t.insert("max".into(), toml::Value::Float(r));
                    }
                    out.push(AddedParameter { name: n, table: t });
                }
            }
        }
        out
    }

    /// The spec text of `m` with this effect added; `values` set the effect
    /// parameters' nominal values (an unknown name is an error).
    pub fn apply(&self, m: &Model, values: &BTreeMap<String, f64>) -> Result<String, ApplyError> {
        let params = self.parameters_for(m);
        if let Some(k) = values
            .keys()
            .find(|k| !params.iter().any(|p| &p.name == *k))
        {
            return Err(ApplyError::NoSuchParameter {
                effect: self.name.clone(),
                parameter: k.clone(),
                adds: params
                    .iter()
                    .map(|p| p.name.as_str())
                    .collect::<Vec<_>>()
                    .join(", "),
            });
        }
        let mut doc: DocumentMut = m
            .source
            .parse()
            .map_err(|e: toml_edit::TomlError| ApplyError::NotToml(e.to_string()))?;
        add_parameters(&mut doc, &params, values)?;
        // input substitutions in definitions, the twist (or constraint rows) and observations
        let sub = self.substitutions(m);
        if !sub.is_empty() {
            substitute_inputs(&mut doc, &sub)?;
        }
        self.patch_inverse(m, &mut doc);
        if !self.motion.is_empty() {
            self.patch_motion(&mut doc)?;
        }
        self.patch_observations(m, &mut doc, &sub)?;
        // the effect list, a top-level key (rendered before the tables)
        match doc.get_mut("effects").and_then(Item::as_array_mut) {
            Some(a) => a.push(self.name.as_str()),
            None => {
                doc.insert("effects", value(Array::from_iter([self.name.as_str()])));
            }
        }
        Ok(doc.to_string())
    }

    /// Apply the twist templates over the (substituted) original twist.
    fn patch_motion(&self, doc: &mut DocumentMut) -> Result<(), ApplyError> {
        let motion = doc
            .get_mut("motion")
            .and_then(Item::as_table_like_mut)
            .ok_or(ApplyError::Shape("the spec has no [motion] twist to patch"))?;
        let orig: BTreeMap<&str, String> = ["vx", "vy", "omega"]
            .iter()
            .map(|k| {
                (
                    *k,
                    motion
                        .get(k)
                        .and_then(|v| v.as_str())
                        .unwrap_or("0")
                        .to_string(),
                )
            })
            .collect();
        for (k, tpl) in &self.motion {
            let new = orig.iter().fold(tpl.clone(), |acc, (n, e)| {
                acc.replace(&format!("{{{n}}}"), e)
            });
            match motion.get_mut(k) {
                Some(item) => edit_str(Some(item), |_| Ok(new.clone()))?,
                None => {
                    motion.insert(k, value(new));
                }
            }
        }
        Ok(())
    }

    /// Apply the observation patches, by role (creating an observation where
    /// the patch says so), then the input substitutions `sub` in them.
    fn patch_observations(
        &self,
        m: &Model,
        doc: &mut DocumentMut,
        sub: &BTreeMap<String, String>,
    ) -> Result<(), ApplyError> {
        for (role_key, patch) in &self.observation {
            let role = role_of(role_key).expect("checked when the catalogue was read");
            let target = m.observations.iter().position(|o| o.role == role);
            let obs = doc
                .entry("observation")
                .or_insert(Item::ArrayOfTables(ArrayOfTables::new()))
                .as_array_of_tables_mut()
                .ok_or(ApplyError::Shape("`observation` is not an array of tables"))?;
            let table = match target {
                Some(i) => obs
                    .get_mut(i)
                    .ok_or(ApplyError::Shape("observation table not found"))?,
                None if patch.create => {
                    obs.push(created_observation(m, role)?);
                    obs.get_mut(obs.len() - 1).expect("just pushed")
                }
                None => continue,
            };
            let old: Vec<String> = table
                .get("expr")
                .and_then(Item::as_array)
                .map(|a| {
                    a.iter()
                        .filter_map(|v| v.as_str().map(str::to_string))
                        .collect()
                })
                .unwrap_or_default();
            let mut new: Vec<String> = if patch.expr.is_empty() {
                old.clone()
            } else {
                patch
                    .expr
                    .iter()
                    .map(|t| {
                        old.iter()
                            .enumerate()
                            .fold(t.clone(), |acc, (i, e)| acc.replace(&format!("{{{i}}}"), e))
                    })
                    .collect()
            };
            for map in [&patch.substitute, sub] {
                if !map.is_empty() {
                    new = new
                        .iter()
                        .map(|e| subst(e, map))
                        .collect::<Result<_, _>>()?;
                }
            }
            table.insert("expr", value(new.into_iter().collect::<Array>()));
            // the patched expressions no longer show the role: declare it
            if !table.contains_key("role") {
                table.insert("role", value(role_key.as_str()));
            }
        }
        Ok(())
    }

    /// `FILE:LINE` of the first line of this effect's file that holds the
    /// symbol a spec error names in backticks (`unknown symbol `k_zz``),
    /// when it is there.
    pub fn locate(&self, message: &str) -> Option<String> {
        let symbol = message.split('`').nth(1).filter(|s| !s.is_empty())?;
        let text = std::fs::read_to_string(&self.origin).ok()?;
        let is_word = |c: char| c.is_alphanumeric() || c == '_';
        let line = text.lines().position(|l| {
            l.match_indices(symbol).any(|(i, _)| {
                let before = l[..i].chars().next_back().is_none_or(|c| !is_word(c));
                let after = l[i + symbol.len()..]
                    .chars()
                    .next()
                    .is_none_or(|c| !is_word(c));
                before && after
            })
        })?;
        Some(format!("{}:{}", self.origin, line + 1))
    }

    /// The model with this effect added at its nominal values (unchanged when
    /// it is already in); Err says why it does not apply or what went wrong.
    pub fn added_to(&self, m: &Model) -> Result<Model, ApplyError> {
        match self.applicability(m) {
            Applicability::AlreadyIn => Ok(m.clone()),
            Applicability::NotApplicable(why) => Err(ApplyError::NotApplicable(why)),
            Applicability::Applies => {
                let text = self.apply(m, &BTreeMap::new())?;
                Model::parse(&m.path, &text).map_err(|e| ApplyError::InvalidResult {
                    from: self.locate(&e.message),
                    message: e.message,
                })
            }
        }
    }

    /// What adding the effect changes, for people: the lines that differ.
    pub fn spec_change(
        &self,
        m: &Model,
        values: &BTreeMap<String, f64>,
    ) -> Result<String, ApplyError> {
        let after = self.apply(m, values)?;
        let before: Vec<&str> = m.source.lines().collect();
        let mut s = String::new();
        // a line diff is enough: the edit keeps every untouched line as it was
        let mut i = 0;
        for line in after.lines() {
            if i < before.len() && before[i] == line {
                i += 1;
                continue;
            }
            match before[i..].iter().position(|b| *b == line) {
                Some(skip) if skip < 3 => {
                    for b in &before[i..i + skip] {
                        s += &format!("- {b}\n");
                    }
                    i += skip + 1;
                }
                _ => s += &format!("+ {line}\n"),
            }
        }
        Ok(s)
    }
}

/// The largest length among the model's parameters (unit "m"), times ten, and
/// at least 2 m: the reach of a sensor mounted on the robot.
fn robot_size(m: &Model) -> f64 {
    let largest = m
        .params
        .iter()
        .filter(|p| p.unit == "m")
        .map(|p| p.nominal.abs())
        .fold(0.0, f64::max);
    (10.0 * largest).max(2.0)
}

/// A new observation of `role` measuring the body origin, on the contract's columns.
fn created_observation(m: &Model, role: ObservationRole) -> Result<Table, ApplyError> {
    if role != ObservationRole::Pose {
        return Err(ApplyError::CannotCreate(role));
    }
    let mut t = Table::new();
    let name = if m.observations.iter().any(|o| o.name == "pose") {
        "pose_tracker"
    } else {
        "pose"
    };
    t.insert("name", value(name));
    t.insert(
        "doc",
        value("Pose of the tracked point (added by an effect)."),
    );
    t.insert(
        "columns",
        value(DEFAULT_POSE_COLUMNS.iter().copied().collect::<Array>()),
    );
    t.insert("angle", value(Array::from_iter([false, false, true])));
    t.insert("expr", value(Array::from_iter(["x", "y", "theta"])));
    Ok(t)
}

fn to_edit(v: &toml::Value) -> Value {
    match v {
        toml::Value::String(s) => s.as_str().into(),
        toml::Value::Integer(i) => (*i).into(),
        toml::Value::Float(f) => (*f).into(),
        toml::Value::Boolean(b) => (*b).into(),
        toml::Value::Array(a) => a.iter().map(to_edit).collect::<Array>().into(),
        other => other.to_string().as_str().into(),
    }
}

/// Rewrite a string value in place, keeping its surrounding whitespace and comment.
fn edit_str(
    item: Option<&mut Item>,
    f: impl Fn(&str) -> Result<String, ApplyError>,
) -> Result<(), ApplyError> {
    if let Some(v) = item.and_then(Item::as_value_mut) {
        if let Some(s) = v.as_str() {
            let new = f(s)?;
            if new != s {
                let decor = v.decor().clone();
                *v = new.into();
                *v.decor_mut() = decor;
            }
        }
    }
    Ok(())
}

/// Substitute whole identifiers in an expression string (unchanged when none occurs).
fn subst(src: &str, map: &BTreeMap<String, String>) -> Result<String, ApplyError> {
    let unparsed = |text: &str, e: expr::ParseError| ApplyError::Expression {
        text: text.to_string(),
        message: e.message,
    };
    let e = expr::parse(src).map_err(|e| unparsed(src, e))?;
    if !e.variables().iter().any(|(v, _)| map.contains_key(*v)) {
        return Ok(src.to_string());
    }
    let parsed: BTreeMap<&str, Expr> = map
        .iter()
        .map(|(k, v)| Ok((k.as_str(), expr::parse(v).map_err(|e| unparsed(v, e))?)))
        .collect::<Result<_, ApplyError>>()?;
    Ok(e.substitute(&|v| parsed.get(v).cloned()).to_source())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The compiled-in catalogue is every file of `spec/effects/`, each by
    /// its own name and text: an effect added there and not here (or the
    /// reverse) would exist for the tests and not for users.
    #[test]
    fn the_bundled_catalogue_is_the_effects_folder() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../spec/effects");
        let mut files: Vec<(String, String)> = std::fs::read_dir(&dir)
            .unwrap()
            .flatten()
            .map(|e| e.path())
            .filter(|p| p.extension().is_some_and(|x| x == "toml"))
            .map(|p| {
                let name = p.file_name().unwrap().to_string_lossy().to_string();
                (name, std::fs::read_to_string(&p).unwrap())
            })
            .collect();
        files.sort();
        let mut bundled: Vec<(String, String)> = BUNDLED
            .iter()
            .map(|(f, t)| (f.to_string(), t.to_string()))
            .collect();
        bundled.sort();
        let names = |v: &[(String, String)]| v.iter().map(|x| x.0.clone()).collect::<Vec<_>>();
        assert_eq!(
            names(&bundled),
            names(&files),
            "BUNDLED against spec/effects/"
        );
        assert_eq!(bundled, files);
    }

    fn model(text: &str) -> Model {
        Model::parse(Path::new("robot.toml"), text).unwrap()
    }

    const SKID: &str = r#"# a user's skid steer
name = "skid4"
state = ["x", "y", "theta"]

[[input]]   # front right
name = "fr"
column = "enc_fr"
kind = "cumulative"

[[input]]
name = "rr"
column = "enc_rr"
kind = "cumulative"

[[input]]
name = "fl"
column = "enc_fl"
kind = "cumulative"

[[input]]
name = "rl"
column = "enc_rl"
kind = "cumulative"

[[parameter]]
name = "radius"
nominal = 0.1
unit = "m"
min = 0.0

[[parameter]]
name = "track"
nominal = 0.5
unit = "m"
min = 0.0

[motion]
vx = "radius*(fr + rr + fl + rl)/4"
vy = "0"
omega = "radius*(fr + rr - fl - rl)/(2*track)"   # effective track
"#;

    /// A spec that declares its own measurement delay (any name) is not offered
    /// a second one: the catalogue's time_offset says why, and a spec with a
    /// second delay is refused.
    #[test]
    fn a_declared_delay_rules_out_time_offset() {
        let cat = catalogue(&[]).unwrap();
        let delayed = SKID.replace(
            "[motion]",
            "[[parameter]]\nname = \"lag\"\nnominal = 0.0\nunit = \"s\"\nmeasurement_delay = true\n\n[motion]",
        );
        let m = model(&delayed);
        let eff = find(&cat, "time_offset").unwrap();
        assert!(
            matches!(eff.applicability(&m), Applicability::NotApplicable(w) if w.contains("already declares a measurement delay (`lag`)"))
        );
        assert_eq!(eff.applicability(&model(SKID)), Applicability::Applies);
    }

    #[test]
    fn applicability_follows_structure_not_names() {
        let cat = catalogue(&[]).unwrap();
        let m = model(SKID);
        let verdict = |n: &str| find(&cat, n).unwrap().applicability(&m);
        assert_eq!(inputs_of(&m, InputClass::RightWheel), ["fr", "rr"]);
        assert_eq!(inputs_of(&m, InputClass::LeftWheel), ["fl", "rl"]);
        for n in [
            "lateral_slip",
            "wheel_misalignment",
            "wheel_radius_asymmetry",
            "wheelbase_scale",
            "sensor_offset",
            "time_offset",
            "longitudinal_slip",
        ] {
            assert_eq!(verdict(n), Applicability::Applies, "{n}");
        }
        assert!(
            matches!(verdict("steering_offset"), Applicability::NotApplicable(w) if w.contains("steering"))
        );
        assert!(
            matches!(verdict("gyro_bias"), Applicability::NotApplicable(w) if w.contains("gyro"))
        );
    }

    #[test]
    fn apply_keeps_comments_and_order_and_patches_both_sides() {
        let cat = catalogue(&[]).unwrap();
        let m = model(SKID);
        let eff = find(&cat, "wheel_radius_asymmetry").unwrap();
        let vals = BTreeMap::from([("radius_asym".to_string(), 0.01)]);
        let out = eff.apply(&m, &vals).unwrap();
        assert!(
            out.starts_with("# a user's skid steer\nname = \"skid4\""),
            "{out}"
        );
        assert!(
            out.contains("[[input]]   # front right") && out.contains("# effective track"),
            "{out}"
        );
        let after = Model::parse(Path::new("robot.toml"), &out).unwrap();
        assert_eq!(after.effects, ["wheel_radius_asymmetry"]);
        let p = after
            .params
            .iter()
            .find(|p| p.name == "radius_asym")
            .unwrap();
        assert_eq!(p.nominal, 0.01);
        let Kinematics::Twist(t) = &after.kinematics else {
            panic!()
        };
        let w = t[2].to_source();
        assert!(
            w.contains("(fr * (1 + radius_asym))") && w.contains("(rl * (1 - radius_asym))"),
            "{w}"
        );
        let err = eff
            .apply(&m, &BTreeMap::from([("zz".to_string(), 1.0)]))
            .unwrap_err();
        assert!(
            matches!(&err, ApplyError::NoSuchParameter { parameter, .. } if parameter == "zz"),
            "{err}"
        );
        assert!(err.to_string().contains("no parameter `zz`"), "{err}");
        assert_eq!(eff.applicability(&after), Applicability::AlreadyIn);
    }

    /// A steering encoder in ticks: the offset is in ticks, bounded by an eighth
    /// of the declared range, and the declared inverse adds it back.
    #[test]
    fn steering_offset_is_in_the_encoders_units_and_keeps_the_inverse() {
        let cat = catalogue(&[]).unwrap();
        let m = model(include_str!("../../tests/user_specs/fwd_tricycle.toml"));
        let eff = find(&cat, "steering_offset").unwrap();
        let params = eff.parameters_for(&m);
        assert_eq!(params.len(), 1);
        let t = &params[0].table;
        assert_eq!(t["unit"].as_str(), Some("tick"));
        assert_eq!(t["max"].as_float(), Some(225.0)); // range [-900, 900] / 8
        let text = eff
            .apply(&m, &BTreeMap::from([("steer_offset_steer".into(), 40.0)]))
            .unwrap();
        let after = Model::parse(Path::new("robot.toml"), &text).unwrap();
        assert!(
            text.contains("/steer_gain) + steer_offset_steer)"),
            "inverse not patched:\n{text}"
        );
        assert_eq!(
            after
                .params
                .iter()
                .find(|p| p.name == "steer_offset_steer")
                .unwrap()
                .unit,
            "tick"
        );
        // an effect that substitutes the wheels without an inverse template drops it
        let mut bare = find(&cat, "wheel_radius_asymmetry").unwrap().clone();
        for e in &mut bare.each_input {
            e.inverse = None;
        }
        let skid = model(include_str!("../../tests/user_specs/skid4.toml"));
        assert!(skid.source.contains("[inverse]"));
        let text = bare.apply(&skid, &BTreeMap::new()).unwrap();
        assert!(!text.contains("[inverse]"), "{text}");
        // with the bundled templates it is kept, divided by the asymmetry
        let wra = find(&cat, "wheel_radius_asymmetry").unwrap();
        let text = wra.apply(&skid, &BTreeMap::new()).unwrap();
        assert!(
            text.contains("[inverse]") && text.contains("/(1 + radius_asym))"),
            "{text}"
        );
    }

    #[test]
    fn sensor_offset_moves_every_exteroceptive_sensor_with_bounds_that_scale() {
        let cat = catalogue(&[]).unwrap();
        let text = format!(
            "{SKID}\n[[observation]]\nname = \"lidar\"\nlandmark = true\ncolumns = [\"range\", \"bearing\"]\nexpr = [\"sqrt((xl - x)^2 + (yl - y)^2)\", \"atan2(yl - y, xl - x) - theta\"]\nangle = [false, true]\n"
        );
        let m = model(&text);
        let eff = find(&cat, "sensor_offset").unwrap();
        let names: Vec<String> = eff.parameters_for(&m).into_iter().map(|p| p.name).collect();
        assert_eq!(
            names,
            ["sensor_dx", "sensor_dy", "rb_sensor_dx", "rb_sensor_dy"]
        );
        let after = Model::parse(
            Path::new("robot.toml"),
            &eff.apply(&m, &BTreeMap::from([("sensor_dx".into(), 1.8)]))
                .unwrap(),
        )
        .unwrap();
        assert_eq!(
            after
                .observations
                .iter()
                .map(|o| o.role)
                .collect::<Vec<_>>(),
            [ObservationRole::RangeBearing, ObservationRole::Pose]
        );
        let pose = after
            .observations
            .iter()
            .find(|o| o.role == ObservationRole::Pose)
            .unwrap();
        assert_eq!(pose.columns, DEFAULT_POSE_COLUMNS);
        let lidar = after
            .observations
            .iter()
            .find(|o| o.name == "lidar")
            .unwrap();
        assert!(lidar.exprs[0].to_source().contains("rb_sensor_dx"));
        let dx = after.params.iter().find(|p| p.name == "sensor_dx").unwrap();
        assert_eq!((dx.nominal, dx.min, dx.max), (1.8, Some(-5.0), Some(5.0)));
    }
}
