//! A whole diagnosis as a user asks for it, in one call: which catalogue
//! effects apply to the spec and are observable in the logs (the others are
//! skipped with the reason), the ranking and chain of [`crate::diagnosis::diagnose`],
//! the spec change each effect found makes, and the first effect's residual
//! signature for the report.
//!
//! ```ignore
//! let chains = EffectChains { spec: &spec, catalogue: &cat, deriver: &my_deriver, sets: &[] };
//! let job = Job { runner: &runner, runs: &runs, chains: &chains, for_report: false };
//! let out = diagnose_job(&job, &Hooks::none())?;
//! println!("{:?}", out.diagnosis.verdict());
//! ```
use crate::diagnosis::diagnose::{diagnose, DiagnoseError, Diagnosis};
use crate::diagnosis::sensor::range_errors_by_bearing;
use crate::diagnosis::structure::{signature, Signature};
use crate::diagnosis::trial::Catalogue;
use crate::effects::{Applicability, Effect};
use crate::model_on_log::dataset::channel_missing;
use crate::model_on_log::derivation::EffectChains;
use crate::model_on_log::model::Runner;
use crate::model_on_log::run::Run;
use crate::model_on_log::track_rows::{Heading, Recipe};
use kinegen_model::spec::Model;
use std::collections::BTreeMap;

/// What to diagnose: the spec's runner (with the user's values), the logs,
/// and the spec with its catalogue and deriver.
pub struct Job<'a> {
    pub runner: &'a Runner,
    pub runs: &'a [Run],
    pub chains: &'a EffectChains<'a>,
    /// Also compute what a report draws: the first effect's signature (it
    /// derives the spec with that effect once more) and the sightings'
    /// range errors.
    pub for_report: bool,
}

/// Told what the logs' reading found that the user should know (before the
/// long part starts: [`crate::diagnosis::request::diagnose_files`]), how many effects
/// are tried, then each step's name (from worker threads), for a progress bar.
pub struct Hooks<'a> {
    pub warnings: &'a dyn Fn(&[String]),
    pub candidates: &'a dyn Fn(usize),
    pub progress: &'a (dyn Fn(&str) + Sync),
}

impl Hooks<'_> {
    /// No progress reports.
    pub fn none() -> Hooks<'static> {
        Hooks {
            warnings: &|_| {},
            candidates: &|_| {},
            progress: &|_| {},
        }
    }
}

/// An effect's name and a sentence: its doc, or why it is not tried.
pub type Named = (String, String);

/// The diagnosis and what its report and its advice need.
pub struct Outcome {
    pub diagnosis: Diagnosis,
    /// How many effects were tried.
    pub tried: usize,
    /// Per effect of the chain, the lines of the spec that adding it (at its
    /// estimates, after the ones before it) changes.
    pub spec_changes: Vec<Option<String>>,
    /// For a report ([`Job::for_report`]): the first effect's signature.
    pub signature: Option<FirstSignature>,
    /// For a report, when the chain holds a sensor effect: the sightings'
    /// range errors against their bearing, seen from the ground truth.
    pub sensor_errors: Option<SensorErrors>,
}

/// The sightings' range errors against their bearing
/// ([`range_errors_by_bearing`]): the calibrated spec's, and the model's
/// with the sensor's effects found.
pub struct SensorErrors {
    pub calibrated: Vec<(f64, f64)>,
    pub with_effects: Vec<(f64, f64)>,
}

impl Outcome {
    /// The calibrated spec's track (`base` is the spec's runner), computed
    /// as it is read.
    pub fn calibrated_track<'r>(&self, base: &'r Runner) -> Recipe<'r> {
        model_track(base, &self.diagnosis.base_fit.p)
    }

    /// The track with the chain's effects at their estimates, computed as it
    /// is read; None when the chain is empty.
    pub fn chain_track(&self) -> Option<Recipe<'_>> {
        let d = &self.diagnosis;
        (!d.chain.is_empty()).then(|| model_track(&d.final_runner, &d.final_p))
    }

    /// The chain's effects joined for a legend: `lateral_slip + time_offset`.
    pub fn chain_label(&self) -> String {
        let names: Vec<&str> = self
            .diagnosis
            .chain
            .iter()
            .map(|c| c.effect.as_str())
            .collect();
        names.join(" + ")
    }
}

/// The body's own track at `p` (no sensor offset, the model's heading).
fn model_track<'r>(r: &'r Runner, p: &[f64]) -> Recipe<'r> {
    Recipe {
        r,
        p: p.to_vec(),
        offset: [0.0; 3],
        heading: Heading::Model,
    }
}

/// The sightings' range errors, when the chain holds a sensor effect.
fn sensor_errors(base: &Runner, runs: &[Run], d: &Diagnosis) -> Option<SensorErrors> {
    d.chain
        .iter()
        .any(|c| c.sightings.is_some())
        .then(|| SensorErrors {
            calibrated: range_errors_by_bearing(base, &d.base_fit.p, runs),
            with_effects: range_errors_by_bearing(&d.final_runner, &d.final_p, runs),
        })
}

/// The first effect's residual signature (see [`signature`]) on each run.
pub struct FirstSignature {
    pub effect: String,
    pub parameter: String,
    pub estimate: f64,
    /// Per run: the channel and the (change per unit, residual) points.
    pub per_run: Vec<Option<Signature>>,
}

/// Diagnose `job` against every applicable and observable effect of its
/// catalogue.
pub fn diagnose_job(job: &Job, hooks: &Hooks) -> Result<Outcome, DiagnoseError> {
    let chains = job.chains;
    let (applicable, skipped) = applicable(chains.spec, chains.catalogue, job.runner, job.runs);
    let tried = applicable.len();
    (hooks.candidates)(tried);
    let diagnosis = diagnose(
        job.runner,
        job.runs,
        &Catalogue {
            effects: applicable,
            chains,
        },
        skipped,
        hooks.progress,
    )?;
    Ok(Outcome {
        spec_changes: spec_changes(chains.spec, chains.catalogue, &diagnosis),
        signature: if job.for_report {
            first_signature(job, &diagnosis)
        } else {
            None
        },
        sensor_errors: if job.for_report {
            sensor_errors(job.runner, job.runs, &diagnosis)
        } else {
            None
        },
        diagnosis,
        tried,
    })
}

/// The effects of `cat` that apply to `spec` and that the logs can show,
/// as (name, doc); and the others as (name, why not).
pub fn applicable(
    spec: &Model,
    cat: &[Effect],
    runner: &Runner,
    runs: &[Run],
) -> (Vec<Named>, Vec<Named>) {
    let mut applicable = Vec::new();
    let mut skipped = Vec::new();
    for eff in cat {
        match eff.applicability(spec) {
            Applicability::Applies => {}
            Applicability::AlreadyIn => {
                skipped.push((eff.name.clone(), "already in the spec".into()));
                continue;
            }
            Applicability::NotApplicable(why) => {
                skipped.push((eff.name.clone(), format!("does not apply: {why}")));
                continue;
            }
        }
        if let Some(roles) = eff.observation_only_roles() {
            let missing: Vec<String> = roles
                .iter()
                .filter_map(|role| {
                    channel_missing(runs, runner, *role).map(|need| {
                        format!("the {role:?} observation, and the logs have no {need}")
                    })
                })
                .collect();
            if missing.len() == roles.len() {
                skipped.push((
                    eff.name.clone(),
                    format!("not observable: it changes only {}", missing.join(" and ")),
                ));
                continue;
            }
        }
        applicable.push((eff.name.clone(), eff.doc.clone()));
    }
    (applicable, skipped)
}

/// What adding each effect of the chain at its estimates changes in the
/// spec, on the spec with the effects before it.
fn spec_changes(spec: &Model, cat: &[Effect], d: &Diagnosis) -> Vec<Option<String>> {
    let mut model = spec.clone();
    d.chain
        .iter()
        .map(|step| {
            let eff = cat.iter().find(|e| e.name == step.effect)?;
            let values: BTreeMap<String, f64> = step
                .parameters
                .iter()
                .map(|(k, v)| (k.clone(), v.estimate))
                .collect();
            let after = eff.with_values(&model, &values).ok()?;
            let change = crate::effects::spec_change(&model, &after);
            model = after;
            Some(change)
        })
        .collect()
}

/// The verdict's signature on each run (None without a verdict).
fn first_signature(job: &Job, d: &Diagnosis) -> Option<FirstSignature> {
    let effect = d.verdict()?;
    let aug = job.chains.runner(&[effect.to_string()]).ok()?;
    let cand = d.candidates.iter().find(|c| c.effect == effect)?;
    let (parameter, est) = cand.parameters.iter().next()?;
    let per_run = job
        .runs
        .iter()
        .map(|run| {
            signature(
                job.runner,
                &d.base_fit.p,
                &aug,
                std::slice::from_ref(run),
                parameter,
                est.estimate,
            )
        })
        .collect();
    Some(FirstSignature {
        effect: effect.to_string(),
        parameter: parameter.clone(),
        estimate: est.estimate,
        per_run,
    })
}
