//! The spec language: one TOML file per model (see `spec/README.md`).
//!
//! [`Model::load`] parses and validates a spec and reports every problem as a
//! [`SourceError`] naming the file, line and column.
pub use crate::decl::{
    Input, InputKind, Noise, ObservationDecl, ObservationRole, Param, DEFAULT_GYRO_COLUMN,
    DEFAULT_POSE_COLUMNS,
};
use crate::error::{SourceError, SourcePos};
use crate::expr::{self, Expr, ExprKind, CONSTANTS, FUNCTIONS};
use serde::Deserialize;
use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};
use toml::Spanned;

mod scope;
pub use scope::{NameError, NameKind, Place, Refusal};

/// Names every spec may use without declaring them.
/// `dt`: step length (s); `xl`, `yl`: landmark position of a landmark observation;
/// `vx`, `vy`, `omega`: the body twist (only inside observations).
pub const RESERVED: &[&str] = &["dt", "xl", "yl", "vx", "vy", "omega"];

/// The planar pose every model integrates.
pub const STATE: [&str; 3] = ["x", "y", "theta"];

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSpec {
    name: Spanned<String>,
    #[serde(default)]
    doc: String,
    #[serde(default)]
    seed: String,
    state: Spanned<Vec<String>>,
    #[serde(default)]
    input: Vec<RawInput>,
    #[serde(default)]
    parameter: Vec<RawParam>,
    #[serde(default)]
    noise: Vec<RawNoise>,
    #[serde(default)]
    define: Vec<RawDefine>,
    #[serde(default)]
    motion: Option<Spanned<RawMotion>>,
    #[serde(default)]
    constraints: Option<RawConstraints>,
    #[serde(default)]
    observation: Vec<RawObservation>,
    #[serde(default)]
    inverse: Option<RawInverse>,
    #[serde(default)]
    effects: Vec<String>,
    #[serde(default)]
    controller: Option<RawController>,
}

/// `[controller]`: where `fit --export ros2-yaml` writes calibrated values.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawController {
    node: String,
    #[serde(rename = "type")]
    type_name: String,
    #[serde(default)]
    file: String,
    #[serde(default)]
    values: std::collections::BTreeMap<String, Spanned<String>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawInput {
    name: Spanned<String>,
    column: String,
    kind: InputKind,
    #[serde(default)]
    range: Option<[f64; 2]>,
    #[serde(default)]
    wrap: Option<Spanned<u32>>,
    #[serde(default)]
    max_rate: Option<Spanned<f64>>,
    #[serde(default)]
    between: Option<Spanned<crate::decl::Between>>,
    #[serde(default)]
    unit: String,
    #[serde(default)]
    doc: String,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawParam {
    name: Spanned<String>,
    nominal: Spanned<f64>,
    #[serde(default)]
    unit: String,
    #[serde(default)]
    doc: String,
    min: Option<f64>,
    max: Option<f64>,
    #[serde(default = "yes")]
    free: bool,
    #[serde(default, rename = "const")]
    constant: bool,
    #[serde(default)]
    measurement_delay: bool,
    #[serde(default)]
    input_delay: bool,
    #[serde(default)]
    input_lag: bool,
    #[serde(default)]
    tolerance: Option<Spanned<RawTolerance>>,
}

/// `tolerance = 0.002` (in the parameter's unit) or `tolerance = "2%"` (of
/// its nominal value).
#[derive(Debug, Deserialize)]
#[serde(untagged)]
enum RawTolerance {
    Absolute(f64),
    Relative(String),
}

fn yes() -> bool {
    true
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawNoise {
    name: Spanned<String>,
    #[serde(default)]
    doc: String,
    #[serde(default)]
    sigma: f64,
    #[serde(default)]
    unit: Option<Spanned<String>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawDefine {
    name: Spanned<String>,
    expr: Spanned<String>,
    #[serde(default)]
    doc: String,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawMotion {
    #[serde(default)]
    doc: String,
    vx: Spanned<String>,
    vy: Spanned<String>,
    omega: Spanned<String>,
}

/// Kinematic constraints q' = S(q, p) R(theta) z' (seed 000 eq. 1, 3, 6-7): one row
/// per constrained input rate, the twist solved by least squares (eq. 9-10).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawConstraints {
    #[serde(default)]
    doc: String,
    /// Noise inputs added to the solved twist [vx, vy, omega] (empty: none).
    #[serde(default)]
    noise: Option<Spanned<Vec<String>>>,
    row: Vec<RawConstraintRow>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawConstraintRow {
    /// The constrained rate: a cumulative input.
    rate: Spanned<String>,
    /// The row of S: coefficients of vx, vy, omega.
    coeffs: Spanned<Vec<Spanned<String>>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawObservation {
    name: Spanned<String>,
    #[serde(default)]
    doc: String,
    columns: Spanned<Vec<String>>,
    expr: Vec<Spanned<String>>,
    #[serde(default)]
    angle: Vec<bool>,
    #[serde(default)]
    sigma: Option<Spanned<Vec<f64>>>,
    #[serde(default)]
    landmark: bool,
    /// What the observation measures; inferred from its expressions when absent.
    #[serde(default)]
    role: Option<ObservationRole>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawInverse {
    #[serde(default)]
    doc: String,
    /// One expression per input, in input order, in terms of vx, vy, omega and parameters.
    inputs: Spanned<Vec<Spanned<String>>>,
}

/// The role an undeclared observation plays, from its structure: a landmark
/// observation is range-bearing; a single expression of the yaw rate is a
/// gyro (also with a scale or bias written in); three expressions whose last
/// is the heading (an angle) are a pose.
fn infer_role(landmark: bool, exprs: &[Expr], angle: &[bool]) -> ObservationRole {
    let is_var = |e: &Expr, name: &str| matches!(&e.kind, ExprKind::Var(v) if v == name);
    if landmark {
        ObservationRole::RangeBearing
    } else if exprs.len() == 1
        && exprs[0].variables().iter().any(|(v, _)| *v == "omega")
        && !exprs[0]
            .variables()
            .iter()
            .any(|(v, _)| ["x", "y", "theta", "vx", "vy"].contains(v))
    {
        ObservationRole::YawRate
    } else if exprs.len() == 3 && angle.get(2) == Some(&true) && is_var(&exprs[2], "theta") {
        ObservationRole::Pose
    } else {
        ObservationRole::Other
    }
}

/// An observation as the spec declares it: what the IR carries
/// ([`ObservationDecl`], read through this type as if its own fields) and the
/// expressions the derivation turns into kernels.
#[derive(Debug, Clone)]
pub struct Observation {
    pub decl: ObservationDecl,
    pub exprs: Vec<Expr>,
}

impl std::ops::Deref for Observation {
    type Target = ObservationDecl;
    fn deref(&self) -> &ObservationDecl {
        &self.decl
    }
}

/// How the inputs determine the body twist.
#[derive(Debug, Clone)]
pub enum Kinematics {
    /// `[motion]`: the twist [vx, vy, omega] written out in terms of inputs,
    /// parameters, noise and definitions.
    Twist([Expr; 3]),
    /// `[constraints]`: rate_i = S_i . (vx, vy, omega) for every row; the twist is the
    /// least-squares solution (S^T S)^+ S^T rates, with a rank check (seed 000 eq. 9-10).
    Constraints(Constraints),
}

#[derive(Debug, Clone)]
pub struct Constraints {
    /// (name of the cumulative input whose rate is constrained, row of S).
    pub rows: Vec<(String, [Expr; 3])>,
    /// Noise inputs added to [vx, vy, omega] after the solve (None: no noise).
    pub noise: [Option<String>; 3],
}

/// A validated model: every expression parsed, every name resolved, definitions
/// ordered so each depends only on earlier ones.
#[derive(Debug, Clone)]
pub struct Model {
    pub path: PathBuf,
    pub source: String,
    pub name: String,
    pub doc: String,
    pub seed: String,
    pub inputs: Vec<Input>,
    pub params: Vec<Param>,
    pub noise: Vec<Noise>,
    /// (name, expression, doc), topologically ordered.
    pub defines: Vec<(String, Expr, String)>,
    pub motion_doc: String,
    /// The forward kinematics: an explicit twist or kinematic constraints.
    pub kinematics: Kinematics,
    /// Byte offset of the `[motion]` / `[constraints]` section (for messages).
    pub kinematics_at: usize,
    pub observations: Vec<Observation>,
    /// Hand-declared inverse (input values from a body twist) for models whose
    /// inputs do not enter the twist linearly; verified by the generator.
    pub inverse: Option<(Vec<Expr>, String)>,
    pub effects: Vec<String>,
    /// The ros2_control controller the calibrated values go to (`[controller]`).
    pub controller: Option<ControllerTarget>,
}

struct Ctx<'a> {
    path: &'a Path,
    text: &'a str,
}

impl Ctx<'_> {
    fn err_at(&self, offset: usize, msg: impl Into<String>) -> SourceError {
        SourceError::new(
            self.path,
            Some(SourcePos::from_offset(self.text, offset)),
            msg,
        )
    }
    fn err_span<T>(&self, s: &Spanned<T>, msg: impl Into<String>) -> SourceError {
        self.err_at(s.span().start, msg)
    }
    /// Parse an expression stored in a TOML string; positions inside it map back to
    /// the file (the +1 skips the opening quote).
    fn parse_expr(&self, s: &Spanned<String>) -> Result<Expr, SourceError> {
        let base = s.span().start + 1;
        let mut e =
            expr::parse(s.get_ref()).map_err(|pe| self.err_at(base + pe.offset, pe.message))?;
        shift_spans(&mut e, base);
        Ok(e)
    }
}

fn shift_spans(e: &mut Expr, by: usize) {
    e.span = (e.span.0 + by, e.span.1 + by);
    match &mut e.kind {
        ExprKind::Neg(a) => shift_spans(a, by),
        ExprKind::Bin(_, a, b) => {
            shift_spans(a, by);
            shift_spans(b, by);
        }
        ExprKind::Call(_, args) => args.iter_mut().for_each(|a| shift_spans(a, by)),
        _ => {}
    }
}

/// Rust keywords (all editions), which cannot name a generated module or function.
const RUST_KEYWORDS: &[&str] = &[
    "as", "async", "await", "break", "const", "continue", "crate", "dyn", "else", "enum", "extern",
    "false", "fn", "for", "gen", "if", "impl", "in", "let", "loop", "match", "mod", "move", "mut",
    "pub", "ref", "return", "self", "Self", "static", "struct", "super", "trait", "true", "type",
    "unsafe", "use", "where", "while", "abstract", "become", "box", "do", "final", "macro",
    "override", "priv", "try", "typeof", "unsized", "virtual", "yield",
];

/// Why a model name cannot be a module of the generated crate (None: it can).
fn reserved_module_name(name: &str) -> Option<&'static str> {
    if RUST_KEYWORDS.contains(&name) {
        Some("it is a Rust keyword")
    } else if ["lib", "linalg", "main", "std", "core", "alloc", "libm"].contains(&name) {
        Some("the generated crate uses that module or crate name itself")
    } else {
        None
    }
}

fn is_identifier(s: &str) -> bool {
    let mut c = s.chars();
    matches!(c.next(), Some(ch) if ch.is_ascii_alphabetic() || ch == '_')
        && c.all(|ch| ch.is_ascii_alphanumeric() || ch == '_')
}

impl Model {
    /// Read and validate a spec file.
    pub fn load(path: &Path) -> Result<Model, SourceError> {
        let bytes = crate::files::read_bounded(path)
            .map_err(|e| SourceError::new(path, None, format!("cannot read spec: {e}")))?;
        let text = std::str::from_utf8(&bytes).map_err(|e| {
            let ok = std::str::from_utf8(&bytes[..e.valid_up_to()]).unwrap_or_default();
            SourceError::new(
                path,
                Some(SourcePos::from_offset(ok, ok.len())),
                "the spec is not UTF-8 text",
            )
        })?;
        Model::parse(path, text)
    }

    /// Validate spec text (`path` is used in messages only).
    pub fn parse(path: &Path, text: &str) -> Result<Model, SourceError> {
        let cx = Ctx { path, text };
        let raw: RawSpec = toml::from_str(text).map_err(|e| {
            let pos = e.span().map(|s| SourcePos::from_offset(text, s.start));
            SourceError::new(path, pos, e.message().to_string())
        })?;
        check_header(&cx, &raw)?;
        let declared = declare_names(&cx, &raw)?;
        let params = parse_params(&cx, &raw.parameter)?;
        check_delays(&cx, &raw.parameter)?;
        let inputs: Vec<Input> = raw.input.iter().map(RawInput::to_input).collect();
        check_command_timing(&cx, &raw.parameter, &inputs)?;
        let names = Names {
            declared: &declared,
        };
        // Parse definitions, check names, then order them (and reject cycles).
        let def_names: HashSet<&str> = raw
            .define
            .iter()
            .map(|d| d.name.get_ref().as_str())
            .collect();
        let mut parsed_defs = Vec::new();
        for d in &raw.define {
            let e = cx.parse_expr(&d.expr)?;
            names.check(&cx, &e, Place::Definition)?;
            parsed_defs.push((d, e));
        }
        let defines = order_definitions(&cx, &parsed_defs, &def_names)?;
        let (kinematics, kinematics_at, motion_doc) = parse_kinematics(&cx, &raw, &names)?;
        let mut observations: Vec<Observation> = Vec::new();
        for o in &raw.observation {
            let parsed = parse_observation(&cx, o, &names, &observations)?;
            observations.push(parsed);
        }
        let inverse = parse_inverse(&cx, &raw, &names)?;
        let controller = parse_controller(&cx, &raw, &names)?;
        Ok(Model {
            path: path.to_path_buf(),
            source: text.to_string(),
            name: raw.name.get_ref().clone(),
            inputs,
            params,
            noise: raw
                .noise
                .iter()
                .map(|n| n.to_noise(&cx))
                .collect::<Result<_, _>>()?,
            doc: raw.doc,
            seed: raw.seed,
            defines,
            motion_doc,
            kinematics,
            kinematics_at,
            observations,
            inverse,
            effects: raw.effects,
            controller,
        })
    }

    /// Substitute definitions (recursively) so only inputs, parameters, noise, state
    /// and reserved names remain.
    pub fn expand(&self, e: &Expr) -> Expr {
        let map: HashMap<&str, &Expr> = self
            .defines
            .iter()
            .map(|(n, e, _)| (n.as_str(), e))
            .collect();
        fn go(e: &Expr, map: &HashMap<&str, &Expr>) -> Expr {
            e.substitute(&|v| map.get(v).map(|d| go(d, map)))
        }
        go(e, &map)
    }

    /// The IR of this model with its derived `functions`: what both
    /// derivations (symbolic and automatic) hand over.
    pub fn ir_file(
        &self,
        no_inverse: Option<String>,
        functions: Vec<crate::ir::Function>,
    ) -> crate::ir::IrFile {
        crate::ir::IrFile {
            name: self.name.clone(),
            doc: self.doc.clone(),
            seed: self.seed.clone(),
            spec_fingerprint: self.fingerprint(),
            inputs: self.inputs.clone(),
            params: self.params.clone(),
            noise: self.noise.clone(),
            observations: self.observations.iter().map(|o| o.decl.clone()).collect(),
            effects: self.effects.clone(),
            no_inverse,
            functions,
        }
    }

    /// Parameters that are runtime arguments (everything not `const`).
    pub fn runtime_params(&self) -> impl Iterator<Item = &Param> {
        self.params.iter().filter(|p| !p.constant)
    }

    /// Every name declared once and every expression's symbols declared
    /// where it may use them: what [`Model::parse`] checks of a spec's
    /// names, asked of a model built in memory (an effect added to it).
    /// The message names the symbol in backticks.
    pub fn check_names(&self) -> Result<(), NameError> {
        let mut kinds: HashMap<&str, NameKind> =
            STATE.iter().map(|s| (*s, NameKind::State)).collect();
        let declared = self
            .inputs
            .iter()
            .map(|i| (i.name.as_str(), NameKind::Input))
            .chain(
                self.params
                    .iter()
                    .map(|p| (p.name.as_str(), NameKind::Parameter)),
            )
            .chain(
                self.noise
                    .iter()
                    .map(|n| (n.name.as_str(), NameKind::Noise)),
            )
            .chain(
                self.defines
                    .iter()
                    .map(|d| (d.0.as_str(), NameKind::Definition)),
            );
        for (name, kind) in declared {
            if let Some(first) = kinds.insert(name, kind) {
                return Err(NameError::DeclaredTwice {
                    name: name.to_string(),
                    first,
                    then: kind,
                });
            }
        }
        let check = |e: &Expr, place: Place| {
            e.variables().into_iter().try_for_each(|(v, _)| {
                place
                    .admits(v, kinds.get(v).copied())
                    .map_err(|why| NameError::Refused {
                        name: v.to_string(),
                        why,
                    })
            })
        };
        for d in &self.defines {
            check(&d.1, Place::Definition)?;
        }
        match &self.kinematics {
            Kinematics::Twist(t) => t.iter().try_for_each(|e| check(e, Place::Twist))?,
            Kinematics::Constraints(c) => c
                .rows
                .iter()
                .flat_map(|r| r.1.iter())
                .try_for_each(|e| check(e, Place::Constraint))?,
        }
        for o in &self.observations {
            let place = Place::Observation {
                landmark: o.landmark,
            };
            o.exprs.iter().try_for_each(|e| check(e, place))?;
        }
        self.inverse
            .iter()
            .flat_map(|i| i.0.iter())
            .try_for_each(|e| check(e, Place::Inverse))
    }

    /// A stable fingerprint of the spec text (FNV-1a; not security relevant, only
    /// used to notice that generated code or a cached IR is stale).
    pub fn fingerprint(&self) -> String {
        fingerprint(&self.source)
    }
}

/// FNV-1a 64-bit of a text, as 16 hex digits.
pub fn fingerprint(text: &str) -> String {
    let mut h: u64 = 0xcbf29ce484222325;
    for b in text.bytes() {
        h ^= b as u64;
        h = h.wrapping_mul(0x100000001b3);
    }
    format!("{h:016x}")
}

/// Every declared name: where it was declared (a byte offset) and what it is.
type Declared = HashMap<String, (usize, NameKind)>;

/// The spec's state and model name.
fn check_header(cx: &Ctx, raw: &RawSpec) -> Result<(), SourceError> {
    if raw.state.get_ref().iter().map(String::as_str).ne(STATE) {
        return Err(cx.err_span(
            &raw.state,
            "state must be [\"x\", \"y\", \"theta\"] (the planar pose)",
        ));
    }
    if !is_identifier(raw.name.get_ref()) {
        return Err(cx.err_span(
            &raw.name,
            "model name must be an identifier (letters, digits, _)",
        ));
    }
    if let Some(why) = reserved_module_name(raw.name.get_ref()) {
        return Err(cx.err_span(
            &raw.name,
            format!("model name `{}` cannot be used: {why}", raw.name.get_ref()),
        ));
    }
    Ok(())
}

/// Declare `name` as `what`: an identifier, not reserved, not declared before.
fn declare(
    cx: &Ctx,
    declared: &mut Declared,
    name: &Spanned<String>,
    what: NameKind,
) -> Result<(), SourceError> {
    let n = name.get_ref();
    if !is_identifier(n) {
        return Err(cx.err_span(name, format!("`{n}` is not a valid name")));
    }
    if RESERVED.contains(&n.as_str())
        || CONSTANTS.contains(&n.as_str())
        || FUNCTIONS.iter().any(|f| f.0 == n)
    {
        return Err(cx.err_span(name, format!("`{n}` is a reserved name")));
    }
    if let Some((at, other)) = declared.get(n) {
        let p = SourcePos::from_offset(cx.text, *at);
        return Err(cx.err_span(
            name,
            format!(
                "duplicate name `{n}`: already declared as {other} at line {}",
                p.line
            ),
        ));
    }
    declared.insert(n.clone(), (name.span().start, what));
    Ok(())
}

/// The state, inputs (each checked), parameters, noise and definitions, declared.
fn declare_names(cx: &Ctx, raw: &RawSpec) -> Result<Declared, SourceError> {
    let mut declared = Declared::new();
    for s in STATE {
        declared.insert(s.to_string(), (raw.state.span().start, NameKind::State));
    }
    for i in &raw.input {
        declare(cx, &mut declared, &i.name, NameKind::Input)?;
        i.check(cx)?;
    }
    for p in &raw.parameter {
        declare(cx, &mut declared, &p.name, NameKind::Parameter)?;
    }
    for n in &raw.noise {
        declare(cx, &mut declared, &n.name, NameKind::Noise)?;
    }
    for d in &raw.define {
        declare(cx, &mut declared, &d.name, NameKind::Definition)?;
    }
    Ok(declared)
}

impl RawInput {
    /// `wrap`, `between` and `max_rate` where they mean something.
    fn check(&self, cx: &Ctx) -> Result<(), SourceError> {
        if let Some(w) = &self.wrap {
            if self.kind != InputKind::Cumulative {
                return Err(cx.err_span(w, "`wrap` is for cumulative counters only"));
            }
            if !(2..=64).contains(w.get_ref()) {
                return Err(cx.err_span(w, "`wrap` is the counter's width in bits (2 to 64)"));
            }
        }
        if let Some(b) = &self.between {
            if self.kind != InputKind::Absolute {
                return Err(cx.err_span(
                    b,
                    "`between` is for absolute inputs (a cumulative input's difference always spreads over the interval)",
                ));
            }
        }
        if let Some(m) = &self.max_rate {
            if !(m.get_ref().is_finite() && *m.get_ref() > 0.0) {
                return Err(cx.err_span(
                    m,
                    "`max_rate` is the actuator's largest |rate|: a finite number above 0",
                ));
            }
        }
        Ok(())
    }

    fn to_input(&self) -> Input {
        Input {
            name: self.name.get_ref().clone(),
            column: self.column.clone(),
            kind: self.kind,
            range: self.range,
            wrap: self.wrap.as_ref().map(|w| *w.get_ref()),
            max_rate: self.max_rate.as_ref().map(|m| *m.get_ref()),
            between: self.between.as_ref().map(|b| *b.get_ref()),
            unit: self.unit.clone(),
            doc: self.doc.clone(),
        }
    }
}

impl RawNoise {
    fn to_noise(&self, cx: &Ctx) -> Result<Noise, SourceError> {
        if self.sigma.is_finite() && self.sigma >= 0.0 {
            let noise = Noise {
                name: self.name.get_ref().clone(),
                doc: self.doc.clone(),
                sigma: self.sigma,
                unit: self
                    .unit
                    .as_ref()
                    .map(|u| u.get_ref().clone())
                    .unwrap_or_default(),
            };
            // a unit that means a density but is not read as one would make
            // the filter add the noise per row, silently
            match &self.unit {
                Some(u) if crate::decl::density_factors(u.get_ref()) > 1 => Err(cx.err_span(
                    u,
                    format!(
                        "noise `{}`: unit `{}` has {} density factors; a density has one: `m/s/sqrt(Hz)`",
                        noise.name,
                        u.get_ref(),
                        crate::decl::density_factors(u.get_ref())
                    ),
                )),
                Some(u) if !noise.is_density() && looks_like_density(u.get_ref()) => Err(cx.err_span(
                    u,
                    format!(
                        "noise `{}`: unit `{}` reads as a per-row sigma: a density is written `.../sqrt(Hz)` or `...*sqrt(s)`",
                        noise.name,
                        u.get_ref()
                    ),
                )),
                _ => Ok(noise),
            }
        } else {
            Err(cx.err_span(
                &self.name,
                format!(
                    "noise `{}`: sigma {} must be a finite number >= 0",
                    self.name.get_ref(),
                    self.sigma
                ),
            ))
        }
    }
}

/// Whether a noise unit speaks of a spectral density (a square root, hertz)
/// in some form [`Noise::is_density`] does not read.
fn looks_like_density(unit: &str) -> bool {
    let u = unit.to_ascii_lowercase();
    ["sqrt", "hz", "\u{221a}"].iter().any(|d| u.contains(d))
}

/// The parameters: finite nominal values within finite, ordered bounds, and
/// their tolerances.
fn parse_params(cx: &Ctx, raw: &[RawParam]) -> Result<Vec<Param>, SourceError> {
    raw.iter()
        .map(|p| {
            let nominal = *p.nominal.get_ref();
            if !nominal.is_finite() {
                return Err(cx.err_span(&p.nominal, "nominal value must be finite"));
            }
            if p.min.is_some_and(|m| !m.is_finite()) || p.max.is_some_and(|m| !m.is_finite()) {
                return Err(cx.err_span(
                    &p.name,
                    "`min` and `max` must be finite numbers (leave one out for no bound)",
                ));
            }
            if let (Some(a), Some(b)) = (p.min, p.max) {
                if a >= b {
                    return Err(
                        cx.err_span(&p.name, format!("`min` ({a}) must be below `max` ({b})"))
                    );
                }
            }
            if p.min.is_some_and(|m| nominal < m) || p.max.is_some_and(|m| nominal > m) {
                return Err(cx.err_span(
                    &p.nominal,
                    format!("nominal {nominal} is outside the declared bounds"),
                ));
            }
            let tolerance = match &p.tolerance {
                None => None,
                Some(t) => Some(tolerance(cx, t, nominal)?),
            };
            Ok(Param {
                name: p.name.get_ref().clone(),
                nominal,
                unit: p.unit.clone(),
                doc: p.doc.clone(),
                min: declared_min(p.input_lag, p.min),
                max: p.max,
                free: p.free && !p.constant,
                constant: p.constant,
                measurement_delay: p.measurement_delay,
                input_delay: p.input_delay,
                input_lag: p.input_lag,
                tolerance,
            })
        })
        .collect()
}

/// A parameter's lower bound: a time constant is 0 or more even where the
/// spec gives no bound, so `--set` and the fit refuse a negative one.
pub(crate) fn declared_min(input_lag: bool, min: Option<f64>) -> Option<f64> {
    if input_lag {
        Some(min.unwrap_or(0.0))
    } else {
        min
    }
}

/// An `input_delay` or `input_lag` acts on the commands (absolute inputs
/// that hold between rows): a model without any has nothing for it to
/// delay, and the analysis would ignore it without a word (`add-effect`
/// refuses `input_delay` there for the same reason).
fn check_command_timing(cx: &Ctx, raw: &[RawParam], inputs: &[Input]) -> Result<(), SourceError> {
    if inputs.iter().any(Input::is_command) {
        return Ok(());
    }
    match raw.iter().find(|p| p.input_delay || p.input_lag) {
        Some(p) => Err(cx.err_span(
            &p.name,
            format!(
                "`{}` is an `{}`, but the model has no commands (absolute inputs that hold between rows): measured inputs follow the motion as it happens; a delay of the measurements is a `measurement_delay`",
                p.name.get_ref(),
                if p.input_delay { "input_delay" } else { "input_lag" }
            ),
        )),
        None => Ok(()),
    }
}

/// At most one `measurement_delay`, one `input_delay` and one `input_lag`
/// parameter, each free to change at run time and in seconds; a lag is a time
/// constant, not negative.
fn check_delays(cx: &Ctx, raw: &[RawParam]) -> Result<(), SourceError> {
    for (flag, is, what) in [
        (
            "measurement_delay",
            (|p: &RawParam| p.measurement_delay) as fn(&RawParam) -> bool,
            "the measurements",
        ),
        ("input_delay", |p: &RawParam| p.input_delay, "the commands"),
        (
            "input_lag",
            |p: &RawParam| p.input_lag,
            "the commands' response",
        ),
    ] {
        let delays: Vec<&RawParam> = raw.iter().filter(|p| is(p)).collect();
        if let Some(second) = delays.get(1) {
            return Err(cx.err_span(
                &second.name,
                format!(
                    "a second `{flag}` parameter (`{}` is one already): {what} have one delay",
                    delays[0].name.get_ref()
                ),
            ));
        }
        if let Some(d) = delays.first() {
            if d.constant {
                return Err(cx.err_span(
                    &d.name,
                    format!("a `{flag}` parameter cannot be `const`: the analysis shifts {what} by its value at run time"),
                ));
            }
            if [d.measurement_delay, d.input_delay, d.input_lag]
                .iter()
                .filter(|f| **f)
                .count()
                > 1
            {
                return Err(cx.err_span(
                    &d.name,
                    "a parameter is one of `measurement_delay`, `input_delay` and `input_lag`, not several",
                ));
            }
            if d.input_lag && *d.nominal.get_ref() < 0.0 {
                return Err(cx.err_span(
                    &d.nominal,
                    "an `input_lag` is a time constant: its nominal value is 0 or more",
                ));
            }
            if d.input_lag && d.min.is_some_and(|m| m < 0.0) {
                return Err(cx.err_span(
                    &d.name,
                    "an `input_lag` is a time constant: its `min` is 0 or more",
                ));
            }
            if !matches!(d.unit.as_str(), "s" | "") {
                return Err(cx.err_span(
                    &d.name,
                    format!("a `{flag}` is in seconds (unit \"s\"), not \"{}\"", d.unit),
                ));
            }
        }
    }
    Ok(())
}

/// What an expression may name: the declared names and what each is.
struct Names<'a> {
    declared: &'a Declared,
}

impl Names<'_> {
    /// Every symbol of `e` one that `place` may read ([`scope`]), or an
    /// error at the first that is not.
    fn check(&self, cx: &Ctx, e: &Expr, place: Place) -> Result<(), SourceError> {
        for (v, span) in e.variables() {
            let kind = self.declared.get(v).map(|d| d.1);
            place
                .admits(v, kind)
                .map_err(|why| cx.err_at(span.0, why.message(v)))?;
        }
        Ok(())
    }

    /// The noise inputs' names.
    fn noise(&self) -> HashSet<&str> {
        self.declared
            .iter()
            .filter(|(_, d)| d.1 == NameKind::Noise)
            .map(|(n, _)| n.as_str())
            .collect()
    }
}

/// The kinematics ([motion] or [constraints]), where they start in the file,
/// and their doc.
fn parse_kinematics(
    cx: &Ctx,
    raw: &RawSpec,
    names: &Names,
) -> Result<(Kinematics, usize, String), SourceError> {
    match (&raw.motion, &raw.constraints) {
        (Some(m), None) => {
            let mo = m.get_ref();
            let twist_exprs = [&mo.vx, &mo.vy, &mo.omega].map(|s| {
                cx.parse_expr(s)
                    .and_then(|e| names.check(cx, &e, Place::Twist).map(|_| e))
            });
            let [vx, vy, omega] = twist_exprs;
            Ok((
                Kinematics::Twist([vx?, vy?, omega?]),
                mo.vx.span().start + 1,
                mo.doc.clone(),
            ))
        }
        (None, Some(c)) => {
            let k = parse_constraints(cx, c, &raw.input, &names.noise(), &|e: &Expr| {
                names.check(cx, e, Place::Constraint)
            })?;
            let at = c.row.first().map_or(0, |r| r.rate.span().start);
            Ok((Kinematics::Constraints(k), at, c.doc.clone()))
        }
        (Some(m), Some(_)) => {
            Err(cx.err_span(m, "give either [motion] or [constraints], not both"))
        }
        (None, None) => Err(cx.err_at(
            0,
            "missing [motion] (the body twist) or [constraints] (rate = S . twist rows)",
        )),
    }
}

/// One `[[observation]]`, checked against the names and the observations
/// before it (one per role).
fn parse_observation(
    cx: &Ctx,
    o: &RawObservation,
    names: &Names,
    before: &[Observation],
) -> Result<Observation, SourceError> {
    declare_free_name(cx, &o.name, names.declared)?;
    if before.iter().any(|x| &x.name == o.name.get_ref()) {
        return Err(cx.err_span(
            &o.name,
            format!("duplicate observation name `{}`", o.name.get_ref()),
        ));
    }
    let ncols = o.columns.get_ref().len();
    if o.expr.len() != ncols {
        return Err(cx.err_span(
            &o.columns,
            format!(
                "observation `{}` has {ncols} column(s) but {} expression(s)",
                o.name.get_ref(),
                o.expr.len()
            ),
        ));
    }
    let sigma: &[f64] = o.sigma.as_ref().map_or(&[], |s| s.get_ref());
    if !o.angle.is_empty() && o.angle.len() != ncols || !sigma.is_empty() && sigma.len() != ncols {
        return Err(cx.err_span(
            &o.columns,
            "`angle` and `sigma` must have one entry per column",
        ));
    }
    let exprs = o
        .expr
        .iter()
        .map(|s| observation_expr(cx, s, o.landmark, names))
        .collect::<Result<Vec<_>, _>>()?;
    // a sigma of 0 would claim an exact sensor, which no filter or fit can
    // weigh (the analysis took the defaults instead, without a word)
    if let Some((s, at)) = o.sigma.as_ref().and_then(|at| {
        Some((
            at.get_ref().iter().find(|s| !s.is_finite() || **s <= 0.0)?,
            at,
        ))
    }) {
        return Err(cx.err_span(
            at,
            format!(
                "observation `{}`: sigma {s} must be a finite number above 0 (leave `sigma` out for the defaults)",
                o.name.get_ref()
            ),
        ));
    }
    let angle = if o.angle.is_empty() {
        vec![false; ncols]
    } else {
        o.angle.clone()
    };
    let role = o
        .role
        .unwrap_or_else(|| infer_role(o.landmark, &exprs, &angle));
    check_role(cx, o, role, before)?;
    Ok(Observation {
        decl: ObservationDecl {
            name: o.name.get_ref().clone(),
            doc: o.doc.clone(),
            columns: o.columns.get_ref().clone(),
            angle,
            sigma: if sigma.is_empty() {
                vec![0.0; ncols]
            } else {
                sigma.to_vec()
            },
            landmark: o.landmark,
            role,
        },
        exprs,
    })
}

/// One expression of an observation ([`Place::Observation`]).
fn observation_expr(
    cx: &Ctx,
    s: &Spanned<String>,
    landmark: bool,
    names: &Names,
) -> Result<Expr, SourceError> {
    let e = cx.parse_expr(s)?;
    names.check(cx, &e, Place::Observation { landmark })?;
    Ok(e)
}

/// An observation's columns fit its role, and no observation before it has
/// the role (other than `Other`).
fn check_role(
    cx: &Ctx,
    o: &RawObservation,
    role: ObservationRole,
    before: &[Observation],
) -> Result<(), SourceError> {
    let ncols = o.columns.get_ref().len();
    let (want, what) = match role {
        ObservationRole::Pose => (3, "a pose observation has 3 columns (x, y, heading)"),
        ObservationRole::YawRate => (1, "a yaw-rate observation has 1 column"),
        ObservationRole::RangeBearing => (
            2,
            "a range-bearing observation has 2 columns (range, bearing) and `landmark = true`",
        ),
        ObservationRole::Other => (ncols, ""),
    };
    if ncols != want
        || (role == ObservationRole::RangeBearing) != o.landmark && role != ObservationRole::Other
    {
        return Err(cx.err_span(
            &o.columns,
            format!("observation `{}`: {what}", o.name.get_ref()),
        ));
    }
    if role != ObservationRole::Other {
        if let Some(other) = before.iter().find(|x| x.role == role) {
            return Err(cx.err_span(&o.name, format!("observation `{}` has the role {role:?} of `{}` already: one observation per role", o.name.get_ref(), other.name)));
        }
    }
    Ok(())
}

/// The `[inverse]` section: one expression per input, of the twist and the
/// parameters only.
fn parse_inverse(
    cx: &Ctx,
    raw: &RawSpec,
    names: &Names,
) -> Result<Option<(Vec<Expr>, String)>, SourceError> {
    let Some(inv) = &raw.inverse else {
        return Ok(None);
    };
    if inv.inputs.get_ref().len() != raw.input.len() {
        return Err(cx.err_span(
            &inv.inputs,
            format!(
                "inverse gives {} expression(s) for {} input(s)",
                inv.inputs.get_ref().len(),
                raw.input.len()
            ),
        ));
    }
    let mut es = Vec::new();
    for s in inv.inputs.get_ref() {
        let e = cx.parse_expr(s)?;
        names.check(cx, &e, Place::Inverse)?;
        es.push(e);
    }
    Ok(Some((es, inv.doc.clone())))
}

/// The ros2_control controller node a spec's calibrated values belong to
/// (`[controller]`, written by `kinegen init`): `fit --export ros2-yaml`
/// sets each key of the node's `ros__parameters` to its expression's value.
#[derive(Debug, Clone, PartialEq)]
pub struct ControllerTarget {
    pub node: String,
    /// The controller's plugin type (`diff_drive_controller/DiffDriveController`).
    pub type_name: String,
    /// The controller file it was read from, relative to the spec ("" when none).
    pub file: String,
    /// Key (dotted for nested maps) and its value over the parameters.
    pub values: Vec<(String, Expr)>,
}

/// Validate `[controller]`: every value an expression over the parameters.
fn parse_controller(
    cx: &Ctx,
    raw: &RawSpec,
    names: &Names,
) -> Result<Option<ControllerTarget>, SourceError> {
    let Some(c) = &raw.controller else {
        return Ok(None);
    };
    let mut values = Vec::new();
    for (key, text) in &c.values {
        let e = cx.parse_expr(text)?;
        names.check(cx, &e, Place::Controller)?;
        values.push((key.clone(), e));
    }
    Ok(Some(ControllerTarget {
        node: c.node.clone(),
        type_name: c.type_name.clone(),
        file: c.file.clone(),
        values,
    }))
}

/// Validate a `[constraints]` section: every row constrains a distinct cumulative
/// input and has three coefficients; at least three rows (three twist components).
fn parse_constraints(
    cx: &Ctx,
    raw: &RawConstraints,
    inputs: &[RawInput],
    noise_names: &HashSet<&str>,
    check: &dyn Fn(&Expr) -> Result<(), SourceError>,
) -> Result<Constraints, SourceError> {
    let mut rows = Vec::new();
    let mut seen = HashSet::new();
    for r in &raw.row {
        let name = r.rate.get_ref();
        match inputs.iter().find(|i| i.name.get_ref() == name) {
            Some(i) if i.kind == InputKind::Cumulative => {}
            Some(_) => return Err(cx.err_span(&r.rate, format!("`{name}` is an absolute input; a constraint row needs a rate (a cumulative input)"))),
            None => return Err(cx.err_span(&r.rate, format!("unknown input `{name}`"))),
        }
        if !seen.insert(name.clone()) {
            return Err(cx.err_span(&r.rate, format!("`{name}` is constrained twice")));
        }
        let co = r.coeffs.get_ref();
        if co.len() != 3 {
            return Err(cx.err_span(
                &r.coeffs,
                format!(
                    "a constraint row has 3 coefficients (of vx, vy, omega), this one has {}",
                    co.len()
                ),
            ));
        }
        let mut es = Vec::new();
        for s in co {
            let e = cx.parse_expr(s)?;
            check(&e)?;
            es.push(e);
        }
        let [a, b, d]: [Expr; 3] = es.try_into().expect("three");
        rows.push((name.clone(), [a, b, d]));
    }
    if rows.len() < 3 {
        let at = raw.row.last().map_or(0, |r| r.rate.span().start);
        return Err(cx.err_at(
            at,
            format!(
                "{} constraint row(s) cannot determine the 3 twist components",
                rows.len()
            ),
        ));
    }
    if let Some(i) = inputs
        .iter()
        .find(|i| i.kind == InputKind::Cumulative && !seen.contains(i.name.get_ref()))
    {
        return Err(cx.err_span(
            &i.name,
            format!(
                "cumulative input `{}` appears in no constraint row",
                i.name.get_ref()
            ),
        ));
    }
    let mut noise = [None, None, None];
    if let Some(n) = &raw.noise {
        if n.get_ref().len() != 3 {
            return Err(cx.err_span(
                n,
                "`noise` names one noise input per twist component [vx, vy, omega]",
            ));
        }
        for (slot, name) in noise.iter_mut().zip(n.get_ref()) {
            if !noise_names.contains(name.as_str()) {
                return Err(cx.err_span(n, format!("`{name}` is not a declared noise input")));
            }
            *slot = Some(name.clone());
        }
    }
    Ok(Constraints { rows, noise })
}

fn declare_free_name(
    cx: &Ctx,
    name: &Spanned<String>,
    declared: &Declared,
) -> Result<(), SourceError> {
    if !is_identifier(name.get_ref()) {
        return Err(cx.err_span(name, "observation name must be an identifier"));
    }
    if declared.contains_key(name.get_ref()) {
        return Err(cx.err_span(name, format!("duplicate name `{}`", name.get_ref())));
    }
    Ok(())
}

/// Depth-first topological order of definitions; a cycle is an error at the first
/// definition found on it.
fn order_definitions(
    cx: &Ctx,
    defs: &[(&RawDefine, Expr)],
    def_names: &HashSet<&str>,
) -> Result<Vec<(String, Expr, String)>, SourceError> {
    let index: HashMap<&str, usize> = defs
        .iter()
        .enumerate()
        .map(|(i, (d, _))| (d.name.get_ref().as_str(), i))
        .collect();
    // 0 = unvisited, 1 = on the stack, 2 = done
    let mut mark = vec![0u8; defs.len()];
    let mut order = Vec::new();
    fn visit(
        i: usize,
        defs: &[(&RawDefine, Expr)],
        index: &HashMap<&str, usize>,
        def_names: &HashSet<&str>,
        mark: &mut [u8],
        order: &mut Vec<usize>,
        chain: &mut Vec<String>,
    ) -> Result<(), usize> {
        if mark[i] == 2 {
            return Ok(());
        }
        if mark[i] == 1 {
            return Err(i);
        }
        mark[i] = 1;
        chain.push(defs[i].0.name.get_ref().clone());
        for (v, _) in defs[i].1.variables() {
            if def_names.contains(v) {
                visit(index[v], defs, index, def_names, mark, order, chain)?;
            }
        }
        chain.pop();
        mark[i] = 2;
        order.push(i);
        Ok(())
    }
    for i in 0..defs.len() {
        let mut chain = Vec::new();
        if let Err(at) = visit(
            i, defs, &index, def_names, &mut mark, &mut order, &mut chain,
        ) {
            let start = chain
                .iter()
                .position(|n| n == defs[at].0.name.get_ref())
                .unwrap_or(0);
            let mut cycle = chain[start..].to_vec();
            cycle.push(defs[at].0.name.get_ref().clone());
            return Err(cx.err_span(
                &defs[at].0.name,
                format!("cyclic definition: {}", cycle.join(" -> ")),
            ));
        }
    }
    Ok(order
        .into_iter()
        .map(|i| {
            (
                defs[i].0.name.get_ref().clone(),
                defs[i].1.clone(),
                defs[i].0.doc.clone(),
            )
        })
        .collect())
}

/// A parameter's `tolerance` in its own unit: a number as it is, `"2%"` of
/// `nominal`; above 0 and finite.
fn tolerance(cx: &Ctx, t: &Spanned<RawTolerance>, nominal: f64) -> Result<f64, SourceError> {
    let value = match t.get_ref() {
        RawTolerance::Absolute(v) => *v,
        RawTolerance::Relative(text) => {
            let Some(pct) = text
                .trim()
                .strip_suffix('%')
                .and_then(|n| n.trim().parse::<f64>().ok())
            else {
                return Err(cx.err_span(
                    t,
                    format!("tolerance `{text}`: a number in the parameter's unit (0.002) or a percentage of its nominal value (\"2%\")"),
                ));
            };
            if nominal == 0.0 {
                return Err(cx.err_span(
                    t,
                    "a relative tolerance of a parameter whose nominal value is 0 is 0: give it in the parameter's unit",
                ));
            }
            pct / 100.0 * nominal.abs()
        }
    };
    if !(value.is_finite() && value > 0.0) {
        return Err(cx.err_span(
            t,
            format!("tolerance {value}: a standard deviation above 0"),
        ));
    }
    // fit weighs the prior by 1/tolerance^2, which must be a number (1e-320
    // made it infinite, and the fit then blamed the log)
    if !(1.0 / (value * value)).is_finite() {
        return Err(cx.err_span(
            t,
            format!("tolerance {value:e}: too small to weigh (its inverse square is not finite); a parameter known that well is `free = false`"),
        ));
    }
    Ok(value)
}
