//! What a user runs after a diagnosis: the `kinegen add-effect` commands
//! that add the effects found, in order, the `kinegen fit` that calibrates
//! the result, and the commands for the rivals the logs cannot tell apart
//! from the first effect. Written here, once, so the command line, its
//! report, its JSON and the Python package's `to_json()` give the same text.
use crate::diagnosis::diagnose::Diagnosis;
use crate::model_on_log::load::Sources;
use std::collections::BTreeMap;
use std::path::PathBuf;

/// The inputs a diagnosis ran on, as the user named them: the commands
/// repeat them so they run as printed.
#[derive(Clone, Debug, Default)]
pub struct Invocation {
    /// The spec file diagnosed.
    pub spec: String,
    pub data: Vec<String>,
    pub topics: Option<String>,
    pub observations: Vec<String>,
    pub landmarks: Option<String>,
    /// The user's effect directories (`--effects DIR`): an effect of theirs
    /// is added only by an add-effect that reads them too.
    pub effects: Vec<String>,
}

impl Invocation {
    /// The inputs as `sources` and `effect_dirs` name them.
    pub fn of(sources: &Sources, effect_dirs: &[PathBuf]) -> Invocation {
        let shown = |p: &PathBuf| p.display().to_string();
        Invocation {
            spec: shown(&sources.spec),
            data: sources.data.iter().map(shown).collect(),
            topics: sources.topics.as_ref().map(shown),
            observations: sources.observations.iter().map(shown).collect(),
            landmarks: sources.landmarks.as_ref().map(shown),
            effects: effect_dirs.iter().map(shown).collect(),
        }
    }
}

/// The commands that act on a diagnosis (empty when it names no effect).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct NextSteps {
    /// One add-effect per effect of the chain: the first reads the spec,
    /// each later one the file the one before writes.
    pub apply: Vec<String>,
    /// The fit that calibrates the last file and writes it back
    /// (`--export spec`).
    pub calibrate: Option<String>,
    /// In place of the first effect, each rival these logs fit as well, at
    /// its own calibrated values.
    pub alternatives: Vec<String>,
}

impl NextSteps {
    /// The commands for `d`, on model `model`, run as `inv` names its inputs.
    pub fn of(d: &Diagnosis, model: &str, inv: &Invocation) -> NextSteps {
        let mut steps = NextSteps::default();
        for (k, step) in d.chain.iter().enumerate() {
            let from = match k {
                0 => inv.spec.clone(),
                _ => written(model, &d.chain[k - 1].effect),
            };
            let values = step.parameters.iter().map(|(n, v)| (n.clone(), v.estimate));
            let values: BTreeMap<String, f64> = values.collect();
            let cmd = add_effect_command(&from, &step.effect, &values, model, &inv.effects);
            steps.apply.push(cmd);
        }
        let Some(last) = d.chain.last() else {
            return steps;
        };
        steps.calibrate = Some(calibrate_command(inv, &written(model, &last.effect), model));
        let first = &d.chain[0];
        steps.alternatives = (first.equivalent.iter())
            .filter_map(|e| d.candidates.iter().find(|c| &c.effect == e))
            .map(|c| {
                let values = c.parameters.iter().map(|(k, v)| (k.clone(), v.estimate));
                add_effect_command(&inv.spec, &c.effect, &values.collect(), model, &inv.effects)
            })
            .collect();
        steps
    }
}

/// The file `add-effect` writes for `effect` on `model`.
fn written(model: &str, effect: &str) -> String {
    format!("{model}_{effect}.toml")
}

/// The `kinegen add-effect` command that adds `effect` at `values` to the
/// spec `spec`, written as `{model}_{effect}.toml`, reading the user's
/// effect directories `effect_dirs` as the diagnosis did.
pub fn add_effect_command(
    spec: &str,
    effect: &str,
    values: &BTreeMap<String, f64>,
    model: &str,
    effect_dirs: &[String],
) -> String {
    let mut a = vec![format!("kinegen add-effect --spec {spec}")];
    a.extend(effect_dirs.iter().map(|d| format!("--effects {d}")));
    a.push(format!("--effect {effect}"));
    a.extend(values.iter().map(|(k, v)| format!("--value {k}={v:.6}")));
    a.push(format!("--out {}", written(model, effect)));
    a.join(" ")
}

/// The `fit` that calibrates `spec` on the diagnosed logs and writes it back
/// with the calibrated values (`--export spec`).
pub fn calibrate_command(inv: &Invocation, spec: &str, model: &str) -> String {
    let mut a = vec![format!("kinegen fit --spec {spec}")];
    a.extend(inv.data.iter().map(|d| format!("--data {d}")));
    a.extend(inv.topics.iter().map(|t| format!("--topics {t}")));
    let observations = inv.observations.iter();
    a.extend(observations.map(|o| format!("--observations {o}")));
    a.extend(inv.landmarks.iter().map(|l| format!("--landmarks {l}")));
    a.push(format!("--export spec {model}_fitted.toml"));
    a.join(" ")
}
