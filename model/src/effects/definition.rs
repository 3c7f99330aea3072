//! An effect file (`spec/effects/*.toml`, or a user's `--effects DIR`) read
//! once into a typed [`Effect`]: its parameters as parameter templates, its
//! patches as parsed expression [`Template`]s, its capability test as
//! [`Capability`] values. A template that does not parse, a hole it may not
//! hold, or a parameter the spec language would refuse is an error at the
//! effect file's line when the catalogue is read, not when the effect is
//! applied.
use super::{Capability, EffectError, InputClass};
use crate::expr::{self, Expr, ExprKind};
use crate::spec::ObservationRole;
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::Path;

/// Why an effect's template is refused.
#[derive(Debug, Clone, thiserror::Error)]
enum TemplateError {
    #[error("`{text}`: {why}")]
    Syntax { text: String, why: String },
    #[error("`{text}`: `{hole}` is not a hole of this patch (it may use {may})")]
    NotAHole {
        text: String,
        hole: String,
        may: String,
    },
}

/// A parsed expression with holes: variables named `{hole}` stand for
/// expressions (`{vx}`, `{0}`, `{inverse}`, `{input}`), and `{input}` inside a
/// longer name (`deadband_{input}`) for the input the patch is applied to.
#[derive(Debug, Clone)]
pub struct Template {
    expr: Expr,
}

impl Template {
    fn parse(text: &str, holes: &[&str]) -> Result<Template, TemplateError> {
        let expr = expr::parse_template(text).map_err(|e| TemplateError::Syntax {
            text: text.to_string(),
            why: e.message,
        })?;
        for (v, _) in expr.variables() {
            let allowed = match v.strip_prefix('{').and_then(|h| h.strip_suffix('}')) {
                _ if !v.contains('{') => true,
                // a whole-name hole; `{0}`, `{1}`... where `{0}` is one
                Some(h) if !h.contains(['{', '}']) => {
                    holes.contains(&h) || (holes.contains(&"0") && h.parse::<usize>().is_ok())
                }
                // a name built from the input's: one parameter per input
                _ => holes.contains(&"input") && !v.replace("{input}", "i").contains(['{', '}']),
            };
            if !allowed {
                let may = holes.iter().map(|h| format!("{{{h}}}")).collect::<Vec<_>>();
                return Err(TemplateError::NotAHole {
                    text: text.to_string(),
                    hole: v.to_string(),
                    may: if may.is_empty() {
                        "none".to_string()
                    } else {
                        may.join(", ")
                    },
                });
            }
        }
        Ok(Template { expr })
    }

    /// The expression with every hole filled: `fill(hole)` for a whole-name
    /// hole, and `{input}` inside names replaced by `input`.
    pub fn fill(&self, input: Option<&str>, fill: &dyn Fn(&str) -> Option<Expr>) -> Expr {
        self.expr.substitute(&|v| {
            if let Some(h) = v.strip_prefix('{').and_then(|h| h.strip_suffix('}')) {
                if h == "input" {
                    return input.map(|i| var(i, self.expr.span));
                }
                return fill(h);
            }
            match input {
                Some(i) if v.contains("{input}") => {
                    Some(var(&v.replace("{input}", i), self.expr.span))
                }
                _ => None,
            }
        })
    }

    /// The parameter names the template uses (with `{input}` replaced).
    pub fn names(&self, input: Option<&str>) -> Vec<String> {
        self.expr
            .variables()
            .into_iter()
            .filter(|(v, _)| !v.starts_with('{'))
            .map(|(v, _)| match input {
                Some(i) => v.replace("{input}", i),
                None => v.to_string(),
            })
            .collect()
    }
}

fn var(name: &str, span: (usize, usize)) -> Expr {
    Expr {
        kind: ExprKind::Var(name.to_string()),
        span,
    }
}

/// How an effect parameter's bounds are set.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Bounds {
    /// ± the reach of a sensor on the robot: ten times its largest length,
    /// at least 2 m (a mounting offset).
    RobotSize,
    /// ± an eighth of the input's declared range (a steering lock); the
    /// template's `min` and `max` where the input declares none.
    InputRange,
}

/// A parameter an effect adds, before it meets a model: its name and unit
/// may name the input it belongs to (`deadband_{input}`, `{input_unit}`).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ParamTemplate {
    pub name: String,
    pub nominal: f64,
    #[serde(default)]
    pub unit: String,
    #[serde(default)]
    pub doc: String,
    pub min: Option<f64>,
    pub max: Option<f64>,
    #[serde(default)]
    pub bounds: Option<Bounds>,
    #[serde(default = "yes")]
    pub free: bool,
    #[serde(default, rename = "const")]
    pub constant: bool,
    #[serde(default)]
    pub measurement_delay: bool,
    #[serde(default)]
    pub input_delay: bool,
    #[serde(default)]
    pub input_lag: bool,
    /// One standard deviation, in the parameter's unit (a spec's relative
    /// `"2%"` means nothing for an effect whose nominal value is 0).
    #[serde(default)]
    pub tolerance: Option<f64>,
    /// Where the parameter means what the effect says, `[low, high]` (a
    /// share between 0 and 1), when its bounds are wider for the
    /// calibration's sake: diagnosis never names an effect whose estimate
    /// lies outside this by more than two standard deviations.
    #[serde(default)]
    pub physical: Option<[f64; 2]>,
}

fn yes() -> bool {
    true
}

impl ParamTemplate {
    /// Is this the parameter the analysis reads as a timing (a delay or a
    /// time constant) rather than one an expression uses?
    pub fn is_timing(&self) -> bool {
        self.measurement_delay || self.input_delay || self.input_lag
    }
}

/// `[[each_input]]`: every input of a class replaced by a template of it.
#[derive(Debug, Clone)]
pub struct InputPatch {
    pub class: InputClass,
    /// The input's new expression, over `{input}`.
    pub expr: Template,
    /// How a declared `[inverse]` expression of such an input changes, over
    /// `{inverse}` (the old expression) and `{input}`: the inverse of `expr`
    /// applied to it. None: a declared inverse is dropped when the effect is
    /// added (it would no longer invert the motion).
    pub inverse: Option<Template>,
}

/// `[observation.ROLE]`: the observation of that role rewritten.
#[derive(Debug, Clone)]
pub struct ObservationPatch {
    pub role: ObservationRole,
    /// Templates over the observation's expressions `{0}`, `{1}`...; empty:
    /// the expressions are kept.
    pub expr: Vec<Template>,
    /// State symbols (`x`, `y`) replaced in the observation's expressions.
    pub substitute: Vec<(String, Template)>,
    /// When the model has no observation of this role, add one on the
    /// contract's columns with identity expressions.
    pub create: bool,
}

/// A catalogue effect, typed.
#[derive(Debug, Clone)]
pub struct Effect {
    pub name: String,
    pub doc: String,
    pub requires: Vec<Capability>,
    pub parameters: Vec<ParamTemplate>,
    /// Twist components (0 vx, 1 vy, 2 omega) rewritten over the original
    /// twist's `{vx}`, `{vy}`, `{omega}`.
    pub motion: Vec<(usize, Template)>,
    pub each_input: Vec<InputPatch>,
    pub observation: Vec<ObservationPatch>,
    /// Where the catalogue file came from (bundled, or a user's directory).
    pub origin: String,
}

/// The file as written; see `spec/README.md`, effects.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawEffect {
    name: String,
    doc: String,
    #[serde(default)]
    requires: Vec<Capability>,
    #[serde(default)]
    parameter: Vec<toml::Spanned<ParamTemplate>>,
    #[serde(default)]
    motion: BTreeMap<String, toml::Spanned<String>>,
    #[serde(default)]
    each_input: Vec<RawInputPatch>,
    #[serde(default)]
    observation: BTreeMap<toml::Spanned<String>, RawObservationPatch>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawInputPatch {
    class: InputClass,
    expr: toml::Spanned<String>,
    #[serde(default)]
    inverse: Option<toml::Spanned<String>>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawObservationPatch {
    #[serde(default)]
    expr: Vec<toml::Spanned<String>>,
    #[serde(default)]
    substitute: BTreeMap<String, toml::Spanned<String>>,
    #[serde(default)]
    create: bool,
}

const TWIST: [&str; 3] = ["vx", "vy", "omega"];

impl Effect {
    /// An effect file's text read as the catalogue reads one (`file` names
    /// it in errors): for effects made in memory, such as diagnose's
    /// proposals.
    pub fn parse(file: &Path, text: &str) -> Result<Effect, EffectError> {
        parse_effect(file, text)
    }
}

/// Read an effect file's text (`file` names it in errors).
pub(super) fn parse_effect(file: &Path, text: &str) -> Result<Effect, EffectError> {
    let at = |offset: usize, m: String| {
        let p = crate::SourcePos::from_offset(text, offset);
        EffectError {
            file: file.to_path_buf(),
            message: format!("line {}, column {}: {m}", p.line, p.column),
        }
    };
    let raw: RawEffect = toml::from_str(text).map_err(|x| match x.span() {
        Some(s) => at(s.start, x.message().to_string()),
        None => EffectError {
            file: file.to_path_buf(),
            message: x.message().to_string(),
        },
    })?;
    let template = |s: &toml::Spanned<String>, holes: &[&str]| {
        Template::parse(s.get_ref(), holes).map_err(|m| at(s.span().start, m.to_string()))
    };
    let mut motion = Vec::new();
    for (k, t) in &raw.motion {
        let Some(i) = TWIST.iter().position(|c| c == k) else {
            return Err(at(
                t.span().start,
                format!("[motion] patches vx, vy and omega, not `{k}`"),
            ));
        };
        motion.push((i, template(t, &TWIST)?));
    }
    let each_input = raw
        .each_input
        .iter()
        .map(|p| {
            Ok(InputPatch {
                class: p.class,
                expr: template(&p.expr, &["input"])?,
                inverse: p
                    .inverse
                    .as_ref()
                    .map(|t| template(t, &["inverse", "input"]))
                    .transpose()?,
            })
        })
        .collect::<Result<_, EffectError>>()?;
    let mut observation = Vec::new();
    for (key, p) in &raw.observation {
        let role = role_of(key.get_ref()).ok_or_else(|| {
            at(
                key.span().start,
                format!(
                    "[observation.{}]: the role must be pose, yaw_rate or range_bearing",
                    key.get_ref()
                ),
            )
        })?;
        observation.push(ObservationPatch {
            role,
            expr: p
                .expr
                .iter()
                .map(|t| template(t, &["0"]))
                .collect::<Result<_, _>>()?,
            substitute: p
                .substitute
                .iter()
                .map(|(k, t)| Ok((k.clone(), template(t, &[])?)))
                .collect::<Result<_, EffectError>>()?,
            create: p.create,
        });
    }
    let mut parameters = Vec::new();
    for p in raw.parameter {
        let span = p.span();
        let p = p.into_inner();
        check_parameter(&p).map_err(|m| at(span.start, m.to_string()))?;
        parameters.push(p);
    }
    Ok(Effect {
        name: raw.name,
        doc: raw.doc,
        requires: raw.requires,
        parameters,
        motion,
        each_input,
        observation,
        origin: file.display().to_string(),
    })
}

/// What the spec language would refuse in a parameter.
#[derive(Debug, Clone, thiserror::Error)]
enum ParameterError {
    #[error("parameter `{0}`: nominal, min, max and tolerance must be finite numbers")]
    NotFinite(String),
    #[error("parameter `{0}`: nominal {1} is outside its bounds")]
    OutsideBounds(String, f64),
    #[error("parameter `{0}`: a tolerance is a standard deviation above 0")]
    Tolerance(String),
    #[error("parameter `{0}`: `physical` is [low, high] with finite low < high")]
    Physical(String),
}

/// What the spec language would refuse in a parameter, refused here.
fn check_parameter(p: &ParamTemplate) -> Result<(), ParameterError> {
    let finite = |v: Option<f64>| v.is_none_or(f64::is_finite);
    if !(p.nominal.is_finite() && finite(p.min) && finite(p.max) && finite(p.tolerance)) {
        return Err(ParameterError::NotFinite(p.name.clone()));
    }
    if p.min.is_some_and(|m| p.nominal < m) || p.max.is_some_and(|m| p.nominal > m) {
        return Err(ParameterError::OutsideBounds(p.name.clone(), p.nominal));
    }
    if p.tolerance.is_some_and(|t| t <= 0.0) {
        return Err(ParameterError::Tolerance(p.name.clone()));
    }
    if p.physical
        .is_some_and(|[lo, hi]| !(lo.is_finite() && hi.is_finite() && lo < hi))
    {
        return Err(ParameterError::Physical(p.name.clone()));
    }
    Ok(())
}

pub(super) fn role_of(key: &str) -> Option<ObservationRole> {
    match key {
        "pose" => Some(ObservationRole::Pose),
        "yaw_rate" => Some(ObservationRole::YawRate),
        "range_bearing" => Some(ObservationRole::RangeBearing),
        _ => None,
    }
}

/// How an effect file names a role (`[observation.yaw_rate]`).
pub(super) fn role_key(role: ObservationRole) -> &'static str {
    match role {
        ObservationRole::Pose => "pose",
        ObservationRole::YawRate => "yaw_rate",
        ObservationRole::RangeBearing => "range_bearing",
        ObservationRole::Other => "other",
    }
}
