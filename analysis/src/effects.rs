//! The effect catalogue (`spec/effects/*.toml`): physically meaningful changes to a
//! model, kept as data. Applying an effect to a spec yields a new spec text, which
//! is derived like any other spec (so kernels, Jacobians and verification follow).
//!
//! An effect file has: `name`, `doc`, `applies_to` (model names or "*"),
//! `redundant_if_free` (parameters which, when all free, already express it;
//! `a|b` means either), `[[parameter]]` blocks as in specs, and patches:
//! `[motion]` (templates over the original `{vx}`, `{vy}`, `{omega}`),
//! `[substitute]` (replace a symbol in definitions and motion), and
//! `[observation.NAME]` (templates `{0}`, `{1}`... over an observation's
//! expressions, or a whole new observation when it has `columns`).
use kinegen_model::expr;
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use toml::{Table, Value};

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Effect {
    pub name: String,
    pub doc: String,
    pub applies_to: Vec<String>,
    #[serde(default)]
    pub redundant_if_free: Vec<String>,
    #[serde(default)]
    pub parameter: Vec<Table>,
    #[serde(default)]
    pub motion: BTreeMap<String, String>,
    #[serde(default)]
    pub substitute: BTreeMap<String, String>,
    #[serde(default)]
    pub observation: BTreeMap<String, Table>,
}

#[derive(Debug, thiserror::Error)]
#[error("{file}: {message}")]
pub struct EffectError {
    pub file: PathBuf,
    pub message: String,
}

#[derive(Debug, Clone, PartialEq)]
pub enum Applicability {
    Applies,
    NotForThisModel,
    /// The spec can already express it (named parameters are free).
    Redundant(String),
    AlreadyIn,
}

/// The default catalogue directory next to the bundled specs.
pub fn default_dir() -> PathBuf {
    PathBuf::from("spec/effects")
}

pub fn load_catalogue(dir: &Path) -> Result<Vec<Effect>, EffectError> {
    let e = |m: String| EffectError { file: dir.to_path_buf(), message: m };
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(|x| e(format!("cannot read the effect catalogue: {x}")))?
        .filter_map(|d| d.ok().map(|d| d.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    files.sort();
    files
        .iter()
        .map(|f| {
            let text = std::fs::read_to_string(f).map_err(|x| EffectError { file: f.clone(), message: x.to_string() })?;
            toml::from_str(&text).map_err(|x| EffectError { file: f.clone(), message: x.to_string() })
        })
        .collect()
}

fn spec_table(spec_text: &str) -> Result<Table, String> {
    spec_text.parse::<Table>().map_err(|e| e.to_string())
}

fn free_params(t: &Table) -> Vec<String> {
    t.get("parameter")
        .and_then(Value::as_array)
        .map(|a| {
            a.iter()
                .filter(|p| p.get("free").and_then(Value::as_bool).unwrap_or(true) && !p.get("const").and_then(Value::as_bool).unwrap_or(false))
                .filter_map(|p| p.get("name").and_then(Value::as_str).map(str::to_string))
                .collect()
        })
        .unwrap_or_default()
}

/// Names of the spec's inputs and parameters.
fn declared_names(t: &Table) -> Vec<String> {
    ["input", "parameter"]
        .iter()
        .flat_map(|s| t.get(*s).and_then(Value::as_array).cloned().unwrap_or_default())
        .filter_map(|v| v.get("name").and_then(Value::as_str).map(str::to_string))
        .collect()
}

/// Substitute whole identifiers in an expression string.
fn subst(src: &str, map: &BTreeMap<String, String>) -> Result<String, String> {
    let e = expr::parse(src).map_err(|e| format!("`{src}`: {}", e.message))?;
    if !e.variables().iter().any(|(v, _)| map.contains_key(*v)) {
        return Ok(src.to_string());
    }
    let parsed: BTreeMap<&str, expr::Expr> = map.iter().map(|(k, v)| Ok((k.as_str(), expr::parse(v).map_err(|e| format!("`{v}`: {}", e.message))?))).collect::<Result<_, String>>()?;
    Ok(e.substitute(&|v| parsed.get(v).cloned()).to_source())
}

impl Effect {
    pub fn applicability(&self, spec_text: &str) -> Applicability {
        let Ok(t) = spec_table(spec_text) else { return Applicability::NotForThisModel };
        let name = t.get("name").and_then(Value::as_str).unwrap_or("");
        if t.get("effects").and_then(Value::as_array).is_some_and(|a| a.iter().any(|v| v.as_str() == Some(&self.name))) {
            return Applicability::AlreadyIn;
        }
        if !self.applies_to.iter().any(|a| a == "*" || a == name) {
            return Applicability::NotForThisModel;
        }
        // gyro effects need a gyro; substitutions need their symbol
        for o in self.observation.keys() {
            let exists = t.get("observation").and_then(Value::as_array).is_some_and(|a| a.iter().any(|x| x.get("name").and_then(Value::as_str) == Some(o)));
            if !exists && !self.observation[o].contains_key("columns") {
                return Applicability::NotForThisModel;
            }
        }
        let declared = declared_names(&t);
        if !self.substitute.is_empty() && !self.substitute.keys().any(|s| declared.contains(s)) {
            return Applicability::NotForThisModel;
        }
        // a twist template needs an explicit twist ([motion], not [constraints])
        if !self.motion.is_empty() && !t.contains_key("motion") {
            return Applicability::NotForThisModel;
        }
        let free = free_params(&t);
        if !self.redundant_if_free.is_empty() && self.redundant_if_free.iter().all(|alt| alt.split('|').any(|p| free.iter().any(|f| f == p))) {
            return Applicability::Redundant(format!("the spec already calibrates {}", self.redundant_if_free.join(", ")));
        }
        Applicability::Applies
    }

    /// The spec with this effect added; `values` set the effect parameters' nominal values.
    pub fn apply(&self, spec_text: &str, values: &BTreeMap<String, f64>) -> Result<String, String> {
        let mut t = spec_table(spec_text)?;
        let sub = self.applicable_substitutions(&t);
        // parameters: those the applied patches use (an effect may carry one per
        // steered wheel, of which a model uses the ones its symbols need)
        let params = t.entry("parameter").or_insert(Value::Array(vec![])).as_array_mut().ok_or("`parameter` is not an array")?;
        for p in self.used_parameter_tables(&sub) {
            let mut p = p.clone();
            let n = p.get("name").and_then(Value::as_str).unwrap_or("").to_string();
            if let Some(v) = values.get(&n) {
                p.insert("nominal".into(), Value::Float(*v));
            }
            params.push(Value::Table(p));
        }
        // substitutions in definitions and motion
        if !sub.is_empty() {
            if let Some(defs) = t.get_mut("define").and_then(Value::as_array_mut) {
                for d in defs {
                    if let Some(e) = d.get("expr").and_then(Value::as_str) {
                        let new = subst(e, &sub)?;
                        d.as_table_mut().unwrap().insert("expr".into(), Value::String(new));
                    }
                }
            }
        }
        if let Some(rows) = t.get_mut("constraints").and_then(|c| c.get_mut("row")).and_then(Value::as_array_mut) {
            // a constraint model: substitutions go into the rows of S
            if !self.motion.is_empty() {
                return Err("a twist template cannot be applied to a [constraints] model".into());
            }
            for row in rows {
                if let Some(co) = row.get_mut("coeffs").and_then(Value::as_array_mut) {
                    for c in co.iter_mut() {
                        if let Some(e) = c.as_str() {
                            *c = Value::String(if sub.is_empty() { e.to_string() } else { subst(e, &sub)? });
                        }
                    }
                }
            }
        } else {
            let motion = t.get_mut("motion").and_then(Value::as_table_mut).ok_or("spec has neither [motion] nor [constraints]")?;
            let mut orig: BTreeMap<String, String> = BTreeMap::new();
            for k in ["vx", "vy", "omega"] {
                let e = motion.get(k).and_then(Value::as_str).ok_or(format!("motion.{k} missing"))?;
                orig.insert(k.into(), if sub.is_empty() { e.to_string() } else { subst(e, &sub)? });
            }
            for k in ["vx", "vy", "omega"] {
                let new = match self.motion.get(k) {
                    Some(tpl) => orig.iter().fold(tpl.clone(), |acc, (n, e)| acc.replace(&format!("{{{n}}}"), e)),
                    None => orig[k].clone(),
                };
                motion.insert(k.into(), Value::String(new));
            }
        }
        // observations
        for (oname, patch) in &self.observation {
            let obs = t.entry("observation").or_insert(Value::Array(vec![])).as_array_mut().ok_or("`observation` is not an array")?;
            match obs.iter_mut().find(|o| o.get("name").and_then(Value::as_str) == Some(oname)) {
                Some(o) if !patch.contains_key("columns") => {
                    let old: Vec<String> = o.get("expr").and_then(Value::as_array).map(|a| a.iter().filter_map(|v| v.as_str().map(str::to_string)).collect()).unwrap_or_default();
                    let tpl: Vec<&str> = patch.get("expr").and_then(Value::as_array).map(|a| a.iter().filter_map(Value::as_str).collect()).unwrap_or_default();
                    let new: Vec<Value> = tpl
                        .iter()
                        .map(|t| Value::String(old.iter().enumerate().fold(t.to_string(), |acc, (i, e)| acc.replace(&format!("{{{i}}}"), e))))
                        .collect();
                    o.as_table_mut().unwrap().insert("expr".into(), Value::Array(new));
                }
                Some(_) => return Err(format!("the spec already has an observation `{oname}`")),
                None => {
                    let mut o = patch.clone();
                    o.insert("name".into(), Value::String(oname.clone()));
                    obs.push(Value::Table(o));
                }
            }
        }
        let eff = t.entry("effects").or_insert(Value::Array(vec![])).as_array_mut().ok_or("`effects` is not an array")?;
        eff.push(Value::String(self.name.clone()));
        let header = format!("# Spec with the `{}` effect added by kinegen: {}\n", self.name, self.doc);
        Ok(header + &toml::to_string(&t).map_err(|e| e.to_string())?)
    }

    /// The observation channels this effect changes when it changes nothing
    /// else (no motion, substitution or timing): a gyro bias is visible in gyro
    /// readings only, so a log without a gyro cannot test it. None for effects
    /// that change the motion or the timing (seen by every measurement).
    pub fn observation_only_channels(&self) -> Option<Vec<&str>> {
        let times = self.parameter.iter().any(|p| p.get("name").and_then(Value::as_str) == Some("time_offset"));
        (self.motion.is_empty() && self.substitute.is_empty() && !times && !self.observation.is_empty()).then(|| self.observation.keys().map(String::as_str).collect())
    }

    /// Names of the parameters this effect adds to `spec_text`, in catalogue
    /// order: a per-wheel effect adds only those of the wheels the spec has.
    pub fn parameters_for(&self, spec_text: &str) -> Result<Vec<String>, String> {
        let t = spec_table(spec_text)?;
        Ok(self.used_parameter_tables(&self.applicable_substitutions(&t)).iter().filter_map(|p| p.get("name").and_then(Value::as_str).map(str::to_string)).collect())
    }

    /// The substitutions whose symbol the spec declares.
    fn applicable_substitutions(&self, t: &Table) -> BTreeMap<String, String> {
        let names = declared_names(t);
        self.substitute.iter().filter(|(k, _)| names.contains(k)).map(|(k, v)| (k.clone(), v.clone())).collect()
    }

    /// The `[[parameter]]` tables of the parameters the applied patches use.
    fn used_parameter_tables(&self, sub: &BTreeMap<String, String>) -> Vec<&Table> {
        let used = self.used_parameters(sub);
        self.parameter.iter().filter(|p| p.get("name").and_then(Value::as_str).is_some_and(|n| used.iter().any(|u| u == n))).collect()
    }

    /// Names of this effect's parameters that its patches use, given the
    /// substitutions that apply to the spec.
    fn used_parameters(&self, sub: &BTreeMap<String, String>) -> Vec<String> {
        let mut texts: Vec<String> = sub.values().cloned().collect();
        texts.extend(self.motion.values().cloned());
        for patch in self.observation.values() {
            if let Some(a) = patch.get("expr").and_then(Value::as_array) {
                texts.extend(a.iter().filter_map(|v| v.as_str().map(str::to_string)));
            }
        }
        let mut used = Vec::new();
        for text in texts {
            // templates hold {vx}, {0}...: blank them out before parsing
            let clean: String = text.split('{').enumerate().map(|(i, part)| if i == 0 { part.to_string() } else { format!("0{}", part.split_once('}').map_or("", |x| x.1)) }).collect();
            if let Ok(e) = expr::parse(&clean) {
                used.extend(e.variables().into_iter().map(|(v, _)| v.to_string()));
            }
        }
        // an effect with no patch that names its parameters (e.g. time_offset,
        // read by the analysis itself) keeps them all
        if !self.parameter.iter().any(|p| p.get("name").and_then(Value::as_str).is_some_and(|n| used.iter().any(|u| u == n))) {
            return self.parameter.iter().filter_map(|p| p.get("name").and_then(Value::as_str).map(str::to_string)).collect();
        }
        used
    }

    /// What adding the effect changes, for people (the lines to add to the spec).
    pub fn spec_change(&self, spec_text: &str, values: &BTreeMap<String, f64>) -> Result<String, String> {
        let before = spec_table(spec_text)?;
        let after = spec_table(&self.apply(spec_text, values)?)?;
        let mut s = String::new();
        for p in self.used_parameter_tables(&self.applicable_substitutions(&before)) {
            let mut p = p.clone();
            let n = p.get("name").and_then(Value::as_str).unwrap_or("").to_string();
            if let Some(v) = values.get(&n) {
                p.insert("nominal".into(), Value::Float(*v));
            }
            s += "[[parameter]]\n";
            s += &toml::to_string(&p).map_err(|e| e.to_string())?;
            s += "\n";
        }
        if let (Some(bm), Some(am)) = (before.get("motion"), after.get("motion")) {
            for k in ["vx", "vy", "omega"] {
                let (a, b) = (&bm[k], &am[k]);
                if a != b {
                    s += &format!("[motion] {k}: {a} -> {b}\n");
                }
            }
        }
        if let (Some(br), Some(ar)) = (before.get("constraints").and_then(|c| c.get("row")).and_then(Value::as_array), after.get("constraints").and_then(|c| c.get("row")).and_then(Value::as_array)) {
            for (a, b) in br.iter().zip(ar) {
                if a.get("coeffs") != b.get("coeffs") {
                    s += &format!("[[constraints.row]] rate = {}: coeffs {} -> {}\n", b["rate"], a["coeffs"], b["coeffs"]);
                }
            }
        }
        if let Some(defs) = after.get("define").and_then(Value::as_array) {
            for (i, d) in defs.iter().enumerate() {
                if before["define"][i]["expr"] != d["expr"] {
                    s += &format!("[[define]] {}: {} -> {}\n", d["name"], before["define"][i]["expr"], d["expr"]);
                }
            }
        }
        for oname in self.observation.keys() {
            let find = |t: &Table| t.get("observation").and_then(Value::as_array).and_then(|a| a.iter().find(|o| o.get("name").and_then(Value::as_str) == Some(oname)).cloned());
            match (find(&before), find(&after)) {
                (Some(a), Some(b)) => s += &format!("[[observation]] {oname}: expr {} -> {}\n", a["expr"], b["expr"]),
                (None, Some(b)) => s += &format!("[[observation]]\n{}", toml::to_string(&b).map_err(|e| e.to_string())?),
                _ => {}
            }
        }
        s += &format!("effects = [..., \"{}\"]\n", self.name);
        Ok(s)
    }
}
