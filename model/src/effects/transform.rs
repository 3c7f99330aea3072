//! An effect applied to a typed [`Model`]: what it needs of the model
//! ([`Effect::applicability`]), the parameters it adds
//! ([`Effect::parameters_for`]) and the model with it
//! ([`Effect::with_values`]): expressions substituted as trees, parameters
//! added as [`Param`]s, observations patched by role. The spec text of the
//! result is rendered from it ([`super::render`]), never edited by hand.
use super::capability::{has, inputs_of, Capability, InputClass};
use super::definition::{role_key, Bounds, Effect, ParamTemplate};
use super::{Applicability, ApplyError};
use crate::decl::{ObservationDecl, Param};
use crate::expr::{Expr, ExprKind};
use crate::spec::{Kinematics, Model, Observation, ObservationRole, DEFAULT_POSE_COLUMNS};
use std::collections::BTreeMap;

impl Effect {
    pub fn applicability(&self, m: &Model) -> Applicability {
        if m.effects.iter().any(|e| e == &self.name) {
            return Applicability::AlreadyIn;
        }
        let mut needs = self.requires.clone();
        if !self.motion.is_empty() {
            needs.push(Capability::Twist);
        }
        if let Some(why) = needs.into_iter().find_map(|c| has(m, c).err()) {
            return Applicability::NotApplicable(why.into());
        }
        if let Some(why) = self.timing_conflict(m) {
            return Applicability::NotApplicable(why);
        }
        let patches = self.substitutions(m).len()
            + self.motion.len()
            + self
                .observation
                .iter()
                .filter(|p| p.create || has_role(m, p.role))
                .count();
        if patches == 0 && self.timing().is_none() {
            return Applicability::NotApplicable(format!(
                "nothing to patch: {}",
                self.what_it_patches()
            ));
        }
        Applicability::Applies
    }

    /// Why a timing effect cannot go on this model: it declares that timing
    /// already, or (for a command's delay or lag) has no commands.
    fn timing_conflict(&self, m: &Model) -> Option<String> {
        if self.measurement_delay().is_some() {
            if let Some(d) = m.params.iter().find(|p| p.measurement_delay) {
                return Some(format!(
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
                return Some(format!("the model already declares {what} (`{}`)", d.name));
            }
            if inputs_of(m, InputClass::Command).is_empty() {
                return Some(format!(
                    "the model has no commands (absolute inputs that hold between rows): {measured}"
                ));
            }
        }
        None
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
                .iter()
                .map(|p| format!("the {} observation", role_key(p.role))),
        );
        if v.is_empty() {
            v.push("the twist".into());
        }
        format!("it changes {} and the model has none", v.join(" and "))
    }

    /// The parameter the analysis reads as a measurement delay (the timeline
    /// shifts measurements by it); None for effects that patch expressions.
    pub fn measurement_delay(&self) -> Option<&str> {
        self.flagged(|p| p.measurement_delay)
    }

    /// The parameter the analysis reads as the delay with which the robot
    /// executes its commands (see [`crate::decl::Param::input_delay`]).
    pub fn input_delay(&self) -> Option<&str> {
        self.flagged(|p| p.input_delay)
    }

    /// The parameter the analysis reads as the time constant of the robot's
    /// response to its commands (see [`crate::decl::Param::input_lag`]).
    pub fn input_lag(&self) -> Option<&str> {
        self.flagged(|p| p.input_lag)
    }

    /// The parameter with `flag`, for an effect that patches no expression
    /// (a timing effect); None otherwise.
    fn flagged(&self, flag: impl Fn(&ParamTemplate) -> bool) -> Option<&str> {
        let patches =
            !self.motion.is_empty() || !self.each_input.is_empty() || !self.observation.is_empty();
        if patches {
            return None;
        }
        self.parameters
            .iter()
            .find(|p| flag(p))
            .map(|p| p.name.as_str())
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
        .then(|| self.observation.iter().map(|p| p.role).collect())
    }

    /// Each input this effect substitutes, with its new expression.
    fn substitutions(&self, m: &Model) -> BTreeMap<String, Expr> {
        let mut out = BTreeMap::new();
        for patch in &self.each_input {
            for input in inputs_of(m, patch.class) {
                let e = patch.expr.fill(Some(&input), &|_| None);
                out.insert(input, e);
            }
        }
        out
    }

    /// The parameter names the patches that go into `m` use.
    fn names_used(&self, m: &Model) -> Vec<String> {
        let mut used: Vec<String> = Vec::new();
        for patch in &self.each_input {
            for input in inputs_of(m, patch.class) {
                used.extend(patch.expr.names(Some(&input)));
            }
        }
        for (_, t) in &self.motion {
            used.extend(t.names(None));
        }
        for p in self
            .observation
            .iter()
            .filter(|p| p.create || has_role(m, p.role))
        {
            used.extend(p.expr.iter().flat_map(|t| t.names(None)));
            used.extend(p.substitute.iter().flat_map(|(_, t)| t.names(None)));
        }
        used
    }

    /// The parameters this effect adds to `m`, in catalogue order: those its
    /// applied patches use (a per-input effect adds one per input the model
    /// has), and a timing effect's own.
    pub fn parameters_for(&self, m: &Model) -> Vec<Param> {
        let used = self.names_used(m);
        let mut out = Vec::new();
        for t in &self.parameters {
            // one parameter per input when its name is a template
            let each: Vec<(String, Option<&crate::spec::Input>)> = if t.name.contains("{input}") {
                m.inputs
                    .iter()
                    .map(|i| (t.name.replace("{input}", &i.name), Some(i)))
                    .collect()
            } else {
                vec![(t.name.clone(), None)]
            };
            for (name, input) in each {
                if used.contains(&name) || t.is_timing() {
                    out.push(instantiate(t, name, input, m));
                }
            }
        }
        out
    }

    /// The model with this effect added at its nominal values (unchanged when
    /// it is already in); Err says why it does not apply or what went wrong.
    pub fn added_to(&self, m: &Model) -> Result<Model, ApplyError> {
        match self.applicability(m) {
            Applicability::AlreadyIn => Ok(m.clone()),
            Applicability::NotApplicable(why) => Err(ApplyError::NotApplicable(why)),
            Applicability::Applies => self.with_values(m, &BTreeMap::new()),
        }
    }

    /// The model with this effect added; `values` set its parameters'
    /// nominal values (an unknown name is an error). The result's `source`
    /// is its spec text: `m`'s, with the effect's changes written in.
    pub fn with_values(
        &self,
        m: &Model,
        values: &BTreeMap<String, f64>,
    ) -> Result<Model, ApplyError> {
        let mut params = self.parameters_for(m);
        for (k, v) in values {
            let Some(p) = params.iter_mut().find(|p| &p.name == k) else {
                return Err(ApplyError::NoSuchParameter {
                    effect: self.name.clone(),
                    parameter: k.clone(),
                    adds: params
                        .iter()
                        .map(|p| p.name.as_str())
                        .collect::<Vec<_>>()
                        .join(", "),
                });
            };
            p.nominal = *v;
        }
        let mut out = m.clone();
        let sub = self.substitutions(m);
        let put = |e: &Expr| e.substitute(&|v| sub.get(v).cloned());
        for d in &mut out.defines {
            d.1 = put(&d.1);
        }
        out.kinematics = match &m.kinematics {
            Kinematics::Twist(t) => Kinematics::Twist(t.each_ref().map(put)),
            Kinematics::Constraints(c) => {
                let mut c = c.clone();
                for (_, row) in &mut c.rows {
                    *row = row.each_ref().map(put);
                }
                Kinematics::Constraints(c)
            }
        };
        self.patch_inverse(m, &mut out);
        self.patch_motion(&mut out)?;
        self.patch_observations(&mut out, &sub)?;
        out.params.extend(params);
        out.effects.push(self.name.clone());
        if let Err(e) = out.check_names() {
            let message = e.to_string();
            return Err(ApplyError::InvalidResult {
                from: self.locate(&message),
                message,
            });
        }
        out.source = super::render::spec_text(m, &out)?;
        Ok(out)
    }

    /// A declared `[inverse]` after the input substitutions: each substituted
    /// input's expression rewritten by its patch's `inverse` template, or the
    /// whole inverse dropped when a substituted input's patch has none.
    fn patch_inverse(&self, m: &Model, out: &mut Model) {
        let Some((exprs, _)) = &mut out.inverse else {
            return;
        };
        for patch in &self.each_input {
            for name in inputs_of(m, patch.class) {
                let Some(k) = m.inputs.iter().position(|i| i.name == name) else {
                    continue;
                };
                let Some(tpl) = &patch.inverse else {
                    out.inverse = None;
                    return;
                };
                let old = exprs[k].clone();
                exprs[k] = tpl.fill(Some(&name), &|h| (h == "inverse").then(|| old.clone()));
            }
        }
    }

    /// The twist templates over the (substituted) twist.
    fn patch_motion(&self, out: &mut Model) -> Result<(), ApplyError> {
        if self.motion.is_empty() {
            return Ok(());
        }
        let Kinematics::Twist(twist) = &mut out.kinematics else {
            return Err(ApplyError::Shape("the spec has no [motion] twist to patch"));
        };
        let old = twist.clone();
        let component = |h: &str| {
            ["vx", "vy", "omega"]
                .iter()
                .position(|c| *c == h)
                .map(|i| old[i].clone())
        };
        for (k, tpl) in &self.motion {
            twist[*k] = tpl.fill(None, &component).without_identities();
        }
        Ok(())
    }

    /// The observation patches, by role (creating an observation where the
    /// patch says so), then the input substitutions `sub` in them.
    fn patch_observations(
        &self,
        out: &mut Model,
        sub: &BTreeMap<String, Expr>,
    ) -> Result<(), ApplyError> {
        for patch in &self.observation {
            let k = match out.observations.iter().position(|o| o.role == patch.role) {
                Some(k) => k,
                None if patch.create => {
                    let created = created_observation(out, patch.role)?;
                    out.observations.push(created);
                    out.observations.len() - 1
                }
                None => continue,
            };
            let obs = &mut out.observations[k];
            if !patch.expr.is_empty() {
                let old = obs.exprs.clone();
                let missing = std::cell::Cell::new(false);
                obs.exprs = patch
                    .expr
                    .iter()
                    .map(|t| {
                        t.fill(None, &|h| {
                            let e = h.parse::<usize>().ok().and_then(|i| old.get(i).cloned());
                            missing.set(missing.get() || e.is_none());
                            e
                        })
                    })
                    .collect();
                if missing.get() {
                    return Err(ApplyError::Shape(
                        "the patch names an expression the observation does not have",
                    ));
                }
            }
            let state: BTreeMap<&str, Expr> = patch
                .substitute
                .iter()
                .map(|(k, t)| (k.as_str(), t.fill(None, &|_| None)))
                .collect();
            for e in &mut obs.exprs {
                *e = e
                    .substitute(&|v| state.get(v).cloned())
                    .substitute(&|v| sub.get(v).cloned());
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
}

fn has_role(m: &Model, role: ObservationRole) -> bool {
    m.observations.iter().any(|o| o.role == role)
}

/// A parameter template on a model: its name, its input's unit, its
/// bounds scaled to the robot or the input.
fn instantiate(
    t: &ParamTemplate,
    name: String,
    input: Option<&crate::spec::Input>,
    m: &Model,
) -> Param {
    // `unit = "{input_unit}"`: the parameter is in its input's units (a
    // steering encoder in ticks gets an offset in ticks)
    let unit = match input {
        Some(i) if t.unit == "{input_unit}" => i.unit.clone(),
        _ => t.unit.clone(),
    };
    let half = match t.bounds {
        Some(Bounds::RobotSize) => Some(robot_size(m)),
        Some(Bounds::InputRange) => input
            .and_then(|i| i.range)
            .map(|[lo, hi]| (hi - lo).abs() / 8.0),
        None => None,
    };
    let (min, max) = match half.filter(|r| r.is_finite() && *r > 0.0) {
        Some(r) => (Some(-r), Some(r)),
        None => (t.min, t.max),
    };
    Param {
        name,
        nominal: t.nominal,
        unit,
        doc: t.doc.clone(),
        min: crate::spec::declared_min(t.input_lag, min),
        max,
        free: t.free && !t.constant,
        constant: t.constant,
        measurement_delay: t.measurement_delay,
        input_delay: t.input_delay,
        input_lag: t.input_lag,
        tolerance: t.tolerance,
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
fn created_observation(m: &Model, role: ObservationRole) -> Result<Observation, ApplyError> {
    if role != ObservationRole::Pose {
        return Err(ApplyError::CannotCreate(role));
    }
    let name = if m.observations.iter().any(|o| o.name == "pose") {
        "pose_tracker"
    } else {
        "pose"
    };
    let var = |v: &str| Expr {
        kind: ExprKind::Var(v.to_string()),
        span: (0, 0),
    };
    Ok(Observation {
        decl: ObservationDecl {
            name: name.to_string(),
            doc: "Pose of the tracked point (added by an effect).".to_string(),
            columns: DEFAULT_POSE_COLUMNS.iter().map(|c| c.to_string()).collect(),
            angle: vec![false, false, true],
            sigma: vec![0.0; 3],
            landmark: false,
            role,
        },
        exprs: vec![var("x"), var("y"), var("theta")],
    })
}
