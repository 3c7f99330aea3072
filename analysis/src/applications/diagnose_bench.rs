//! The recovery benchmark (`kinegen bench-diagnose`): how often diagnosis
//! names what was hidden. Every spec x every applicable catalogue effect x 3
//! magnitudes x 2 noise levels x seeds is simulated (smooth random driving,
//! 91 s a lap at 20 Hz) and diagnosed, plus clean logs (a named effect there
//! is a false alarm) and logs with two effects at once (both must be named).
//! Effects the diagnosis finds redundant with the spec's own parameters on
//! these logs cannot be told apart from them and are counted separately,
//! not as misses.
//!
//! With effects written for the benchmark outside the catalogue
//! ([`Settings::beyond`]), each is hidden too: the diagnosis cannot name
//! it, and its proposal beyond the catalogue (`verdict.proposed`) is scored
//! against the true effect calibrated: recovered when the proposal removes
//! at least half of the held-out error the true effect removes. A proposal
//! on a clean log or on one whose effect is in the catalogue is a false
//! proposal.
//!
//! The cases have a fixed order, so a benchmark can be cut into shards run
//! on different machines ([`Shard`]) and joined back ([`merge`]) into the
//! table the whole run gives; a merge refuses anything but the whole of one
//! benchmark.
//!
//! ```ignore
//! let settings = Settings { seeds: 1, laps: 1, shard: None, effects: vec![] };
//! let table = bench(&specs, &settings, &my_deriver, &|failed| eprintln!("{failed}"))?;
//! for m in &table.models { println!("{}: {:?}", m.model, m.top1); }
//! ```
use crate::applications::hidden::{with_hidden, Hidden, Robots};
use crate::applications::simulate::{simulate, SimOptions, Trajectory};
use crate::diagnosis::diagnose_job::Hooks;
use crate::diagnosis::propose::proposal::ScoredOn;
use crate::diagnosis::request::diagnose_runs;
use crate::model_on_log::derivation::Deriver;
use crate::model_on_log::model::Runner;
use kinegen_model::effects::{catalogue, Applicability, Effect, EffectError};
use kinegen_model::spec::Model;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::fmt;
use std::path::{Path, PathBuf};
use std::str::FromStr;
use std::time::Instant;

/// Hidden magnitudes, as fractions of each effect parameter's largest bound.
pub const MAGNITUDES: [f64; 3] = [0.1, 0.2, 0.4];
/// Noise levels: the simulator's default sensor noise, and 3x.
pub const NOISE: [f64; 2] = [1.0, 3.0];

/// Slice `k` of `n` (k from 1): case number i (in the benchmark's fixed
/// order) belongs to slice i mod n + 1. Written `K/N`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Shard {
    pub k: u64,
    pub n: u64,
}

impl Shard {
    fn holds(&self, index: u64) -> bool {
        index % self.n == self.k - 1
    }
}

impl FromStr for Shard {
    type Err = String;
    /// `K/N` with whole numbers 1 <= K <= N.
    fn from_str(s: &str) -> Result<Shard, String> {
        let bad = || format!("`{s}` is not K/N with whole numbers 1 <= K <= N");
        let (k, n) = s.split_once('/').ok_or_else(bad)?;
        let (k, n): (u64, u64) = (
            k.trim().parse().map_err(|_| bad())?,
            n.trim().parse().map_err(|_| bad())?,
        );
        if k >= 1 && k <= n {
            Ok(Shard { k, n })
        } else {
            Err(bad())
        }
    }
}

impl fmt::Display for Shard {
    fn fmt(&self, f: &mut fmt::Formatter) -> fmt::Result {
        write!(f, "{}/{}", self.k, self.n)
    }
}

/// What to run: seeds per case, laps of the random trajectory per log, the
/// slice, only these effects (empty: every applicable one), and
/// folders of effects written for the benchmark, outside the catalogue,
/// hidden as well (each at each magnitude of its first parameter's bound).
#[derive(Debug, Clone)]
pub struct Settings {
    pub seeds: u64,
    pub laps: u64,
    pub shard: Option<Shard>,
    pub effects: Vec<String>,
    pub beyond: Vec<PathBuf>,
}

/// One case's outcome.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Case {
    /// Its number in the benchmark's fixed order (what a shard slices).
    pub index: u64,
    pub model: String,
    pub spec: String,
    pub hidden: Vec<String>,
    pub noise: f64,
    pub seed: u64,
    pub found: Vec<String>,
    /// Hidden effects the diagnosis set aside as redundant on this log.
    pub redundant: Vec<String>,
    pub seconds: f64,
    /// The hidden effect is outside the catalogue ([`Settings::beyond`]).
    #[serde(default)]
    pub beyond: bool,
    /// What the diagnosis proposed beyond the catalogue, if anything.
    #[serde(default)]
    pub proposed: Option<ProposedScore>,
    /// For an effect beyond the catalogue: the held-out error of the spec
    /// calibrated as it is, and with the true effect calibrated.
    #[serde(default)]
    pub truth: Option<TruthScore>,
}

/// A proposal's name and the held-out error it leaves.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ProposedScore {
    pub name: String,
    pub held_out_after: f64,
}

/// The held-out errors a proposal is scored against.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
pub struct TruthScore {
    /// The spec calibrated as it is.
    pub held_out_before: f64,
    /// The spec with the true effect, calibrated.
    pub held_out_true: f64,
}

impl Case {
    /// A proposal that removes at least half of the held-out error the true
    /// effect removes.
    pub fn recovered(&self) -> bool {
        match (&self.proposed, self.truth) {
            (Some(p), Some(t)) => {
                t.held_out_before - p.held_out_after >= 0.5 * (t.held_out_before - t.held_out_true)
            }
            _ => false,
        }
    }
}

/// k of n cases.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct Rate {
    pub found: usize,
    pub of: usize,
}

impl Rate {
    fn count(&mut self, hit: bool) {
        self.of += 1;
        self.found += usize::from(hit);
    }
}

/// One model's rates over its cases.
#[derive(Debug, Clone, Serialize)]
pub struct ModelRates {
    pub model: String,
    pub spec: String,
    /// Cases with one hidden effect whose verdict named it first.
    pub top1: Rate,
    /// Cases whose chain named exactly what was hidden.
    pub full_chain: Rate,
    /// Clean cases with a verdict.
    pub false_alarms: Rate,
    /// Cases whose hidden effect was found redundant with the spec.
    pub redundant_cases: usize,
    /// Cases hiding an effect beyond the catalogue whose proposal recovered
    /// it ([`Case::recovered`]).
    pub beyond_recovered: Rate,
    /// Clean cases and cases hiding a catalogue effect that got a proposal.
    pub false_proposals: Rate,
    pub median_seconds: f64,
    pub slowest_seconds: f64,
}

/// The specs (by name and path) and effects a benchmark was run on.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Selection {
    pub specs: Vec<String>,
    pub effects: Vec<String>,
    /// The effects written for the benchmark, outside the catalogue.
    #[serde(default)]
    pub beyond: Vec<String>,
}

/// The benchmark's table, as `--json` writes it: a shard's (with the
/// whole's size, the failed cases of this shard and the selection, which a
/// merge checks), a whole run's, or a merge's.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Table {
    pub command: String,
    pub seeds: u64,
    pub laps: u64,
    /// `K/N` for a shard.
    pub shard: Option<String>,
    /// How many shards a merge joined.
    pub merged_shards: Option<usize>,
    pub magnitudes_of_bound: Vec<f64>,
    pub noise_levels: Vec<f64>,
    #[serde(skip_deserializing)]
    pub models: Vec<ModelRates>,
    pub cases: Vec<Case>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cases_total: Option<u64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub failed_cases: Option<Vec<u64>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub selection: Option<Selection>,
}

/// Why a benchmark cannot be run or merged.
#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    #[error(transparent)]
    Catalogue(#[from] EffectError),
    #[error("--effect {effect}: no such effect in the catalogue (it has: {known})")]
    UnknownEffect { effect: String, known: String },
    #[error("{spec}: {why}")]
    Spec { spec: String, why: String },
    #[error("{}: {why}", .file.display())]
    Shard { file: PathBuf, why: String },
    #[error("--merge: {0}")]
    Merge(String),
}

/// A hidden effect of a case: the effect, its parameter and its value.
#[derive(Debug, Clone)]
struct HiddenEffect {
    effect: String,
    parameter: String,
    value: f64,
    /// Outside the catalogue the diagnosis searches.
    beyond: bool,
}

/// An applicable effect, its first parameter and that parameter's largest
/// bound (0.5 when it has none).
struct Candidate {
    effect: String,
    parameter: String,
    bound: f64,
    beyond: bool,
}

/// The applicable effects of `effects` on a spec (`beyond`: outside the
/// catalogue).
fn effects_of(spec: &Model, effects: &[Effect], beyond: bool) -> Vec<Candidate> {
    let mut out = Vec::new();
    for eff in effects {
        if eff.applicability(spec) != Applicability::Applies {
            continue;
        }
        let Some(p) = eff.parameters_for(spec).into_iter().next() else {
            continue;
        };
        let bound = [p.min, p.max]
            .into_iter()
            .flatten()
            .map(f64::abs)
            .fold(0.0, f64::max);
        out.push(Candidate {
            effect: eff.name.clone(),
            parameter: p.name,
            bound: if bound > 0.0 { bound } else { 0.5 },
            beyond,
        });
    }
    out
}

/// The hidden effects of a spec's cases: each catalogue effect at each
/// magnitude, consecutive pairs of the catalogue at the middle magnitude,
/// two clean logs, then each effect beyond the catalogue at each magnitude.
fn hidden_sets(effects: &[Candidate], beyond: &[Candidate]) -> Vec<Vec<HiddenEffect>> {
    let at = |c: &Candidate, m: f64| HiddenEffect {
        effect: c.effect.clone(),
        parameter: c.parameter.clone(),
        value: m * c.bound,
        beyond: c.beyond,
    };
    let mut sets: Vec<Vec<HiddenEffect>> = Vec::new();
    for c in effects {
        for m in MAGNITUDES {
            sets.push(vec![at(c, m)]);
        }
    }
    for w in effects.windows(2) {
        sets.push(w.iter().map(|c| at(c, MAGNITUDES[1])).collect());
    }
    sets.push(Vec::new()); // clean
    sets.push(Vec::new());
    for c in beyond {
        for m in MAGNITUDES {
            sets.push(vec![at(c, m)]);
        }
    }
    sets
}

/// A case to run.
struct Planned<'s> {
    index: u64,
    spec: &'s Model,
    hidden: Vec<HiddenEffect>,
    noise: f64,
    seed: u64,
    /// Every case its own trajectory.
    trajectory: u64,
    /// Simulate landmark sightings ([`BENCH_MAP`]) beside the ground truth.
    sightings: bool,
}

/// Every case of the benchmark (those of `settings.shard`), in its order,
/// and how many the whole benchmark has. A spec that does not derive, or
/// whose IR is unusable, stops the benchmark before its first case.
fn plan<'s>(
    specs: &'s [Model],
    (cat, beyond): (&[Effect], &[Effect]),
    settings: &Settings,
    deriver: &dyn Deriver,
) -> Result<(Vec<Planned<'s>>, u64), BenchError> {
    let all = || cat.iter().chain(beyond);
    if let Some(e) = (settings.effects.iter()).find(|e| !all().any(|c| &c.name == *e)) {
        let known: Vec<&str> = all().map(|c| c.name.as_str()).collect();
        return Err(BenchError::UnknownEffect {
            effect: e.clone(),
            known: known.join(", "),
        });
    }
    let mut todo = Vec::new();
    let mut index = 0u64;
    for spec in specs {
        let label = spec.path.display().to_string();
        let usable = (deriver.derive(spec, &label).map_err(|e| e.to_string()))
            .and_then(|ir| Runner::new(ir, &[]).map_err(|e| e.to_string()));
        if let Err(why) = usable {
            return Err(BenchError::Spec { spec: label, why });
        }
        let mut effects = effects_of(spec, cat, false);
        if !settings.effects.is_empty() {
            effects.retain(|c| settings.effects.contains(&c.effect));
        }
        let mut beyond = effects_of(spec, beyond, true);
        if !settings.effects.is_empty() {
            beyond.retain(|c| settings.effects.contains(&c.effect));
        }
        // sightings for every case of a spec with a landmark observation
        // when an effect hidden on it acts on the sensor: its clean logs
        // must be as a hidden sensor effect's are, but for the effect
        let on_sensor = |c: &Candidate| {
            (all()).any(|e| e.name == c.effect && scored_on(e) == ScoredOn::Sightings)
        };
        let sightings = has_landmarks(spec) && effects.iter().chain(&beyond).any(on_sensor);
        for (j, hidden) in hidden_sets(&effects, &beyond).into_iter().enumerate() {
            for &noise in &NOISE {
                for seed in 1..=settings.seeds {
                    let i = index;
                    index += 1;
                    if settings.shard.is_some_and(|s| !s.holds(i)) {
                        continue;
                    }
                    todo.push(Planned {
                        index: i,
                        spec,
                        hidden: hidden.clone(),
                        noise,
                        seed,
                        trajectory: 1000 * j as u64 + seed,
                        sightings,
                    });
                }
            }
        }
    }
    Ok((todo, index))
}

/// The landmarks of a case with sightings: a 5 x 5 grid 3 m apart around
/// the random driving's start, so that some are always in range.
const BENCH_MAP: (usize, f64) = (5, 3.0);

fn bench_map() -> Vec<(String, [f64; 2])> {
    let (n, step) = BENCH_MAP;
    let half = (n - 1) as f64 / 2.0;
    (0..n * n)
        .map(|k| {
            let (i, j) = ((k / n) as f64 - half, (k % n) as f64 - half);
            (format!("L{k}"), [i * step, j * step])
        })
        .collect()
}

/// The spec has a range-bearing observation of mapped landmarks.
fn has_landmarks(spec: &Model) -> bool {
    spec.observations.iter().any(|o| o.landmark)
}

/// The residuals an effect's proposal is scored on: the sightings' for an
/// effect on the sensor, the track's for one on the motion.
fn scored_on(e: &Effect) -> ScoredOn {
    if e.observation.is_empty() {
        ScoredOn::Track
    } else {
        ScoredOn::Sightings
    }
}

/// The held-out errors a proposal for the hidden effect `e` is scored
/// against: the spec calibrated as it is (from `d`, its diagnosis), and
/// with `e` itself as the only catalogue effect, calibrated, on the
/// residuals `e` acts on.
fn truth_score(
    spec: &Model,
    (base, run): (&Runner, &crate::model_on_log::run::Run),
    e: &Effect,
    deriver: &dyn Deriver,
    d: &crate::diagnosis::diagnose::Diagnosis,
) -> Result<TruthScore, String> {
    let with_truth = diagnose_runs(
        spec,
        (base, std::slice::from_ref(run)),
        (std::slice::from_ref(e), deriver),
        &[],
        false,
        &Hooks::none(),
    )
    .map_err(|e| e.to_string())?
    .diagnosis;
    Ok(match scored_on(e) {
        ScoredOn::Track => TruthScore {
            held_out_before: d.base_holdout_rmse,
            held_out_true: (with_truth.candidates.iter())
                .find(|c| c.effect == e.name)
                .map_or(d.base_holdout_rmse, |c| c.holdout_rmse),
        },
        // both on the sightings at the motion's model, at one scale
        ScoredOn::Sightings => {
            let fit = (with_truth.sensor_candidates.iter())
                .find(|c| c.effect == e.name)
                .map(|c| &c.fit)
                .ok_or("the true sensor effect was not tested on the sightings")?;
            TruthScore {
                held_out_before: fit.held_out_before,
                held_out_true: fit.held_out_after,
            }
        }
    })
}

/// Simulate one case's log and diagnose it.
fn run_case(
    c: &Planned,
    (laps, beyond_dirs): (u64, &[PathBuf]),
    (cat, beyond): (&[Effect], &[Effect]),
    deriver: &dyn Deriver,
) -> Result<Case, String> {
    let effects: Vec<Hidden> = (c.hidden.iter())
        .map(|h| Hidden::new(&h.effect, &h.parameter, h.value))
        .collect();
    let Robots {
        spec: base,
        robot: truth,
    } = with_hidden(c.spec, &effects, &[], beyond_dirs, deriver).map_err(|e| e.to_string())?;
    let o = SimOptions {
        trajectory: Trajectory::Random,
        seed: c.trajectory,
        laps: laps as usize,
        pos_noise: 0.001 * c.noise,
        heading_noise: 0.002 * c.noise,
        gyro_noise: 0.005 * c.noise,
        landmarks: if c.sightings { bench_map() } else { vec![] },
        ..SimOptions::default()
    };
    let sim = simulate(&base, &truth, &o);
    let mut run = sim.to_run(&base, "bench").map_err(|e| e.to_string())?;
    run.landmarks = sim.sightings(&o.landmarks);
    let t0 = Instant::now();
    let outcome = diagnose_runs(
        c.spec,
        (&base, std::slice::from_ref(&run)),
        (cat, deriver),
        &[],
        false,
        &Hooks::none(),
    )
    .map_err(|e| e.to_string())?;
    let d = outcome.diagnosis;
    let names: Vec<String> = c.hidden.iter().map(|h| h.effect.clone()).collect();
    let is_beyond = c.hidden.iter().any(|h| h.beyond);
    let hidden_beyond = (c.hidden.iter().find(|h| h.beyond))
        .and_then(|h| beyond.iter().find(|e| e.name == h.effect));
    let truth = match hidden_beyond {
        Some(e) => Some(truth_score(c.spec, (&base, &run), e, deriver, &d)?),
        None => None,
    };
    // a case beyond the catalogue is scored by the proposal on the
    // residuals its effect acts on; any other case's first proposal is a
    // false one
    let proposal = match hidden_beyond {
        Some(e) => (d.proposed.iter()).find(|p| p.scored_on == scored_on(e)),
        None => d.proposed.first(),
    };
    Ok(Case {
        beyond: is_beyond,
        proposed: proposal.map(|p| ProposedScore {
            name: p.name.clone(),
            held_out_after: p.held_out_after,
        }),
        truth,
        index: c.index,
        model: c.spec.name.clone(),
        spec: c.spec.path.display().to_string(),
        redundant: (d.skipped.iter())
            .filter(|(e, why)| names.contains(e) && why.starts_with("redundant"))
            .map(|(e, _)| e.clone())
            .collect(),
        noise: c.noise,
        seed: c.seed,
        // a step that names a group these logs cannot tell apart counts as
        // naming the hidden effect when the group holds it
        found: (d.chain.iter())
            .map(|step| {
                (names.iter().find(|h| step.equivalent.contains(h)).cloned())
                    .unwrap_or_else(|| step.effect.clone())
            })
            .collect(),
        hidden: names,
        seconds: t0.elapsed().as_secs_f64(),
    })
}

/// Run the benchmark of `specs` (the cases on every core: derivation takes
/// no lock, and each diagnosis shares the threads it does not use).
/// `failed` hears each case that could not run, in a sentence; the table
/// counts it in `failed_cases`.
pub fn bench(
    specs: &[Model],
    settings: &Settings,
    deriver: &dyn Deriver,
    failed: &dyn Fn(&str),
) -> Result<Table, BenchError> {
    let cat = catalogue(&[])?;
    // the effects written for the benchmark: those the folders add to the
    // catalogue (the diagnosis never searches them)
    let beyond: Vec<Effect> = (catalogue(&settings.beyond)?.into_iter())
        .filter(|e| !cat.iter().any(|c| c.name == e.name))
        .collect();
    let (todo, total) = plan(specs, (&cat, &beyond), settings, deriver)?;
    let done: Vec<Result<Case, String>> = todo
        .par_iter()
        .map(|c| {
            run_case(
                c,
                (settings.laps, &settings.beyond),
                (&cat, &beyond),
                deriver,
            )
        })
        .collect();
    let mut cases = Vec::new();
    let mut failed_cases = Vec::new();
    for (c, result) in todo.iter().zip(done) {
        match result {
            Ok(case) => cases.push(case),
            Err(e) => {
                let hidden: Vec<&str> = c.hidden.iter().map(|h| h.effect.as_str()).collect();
                failed(&format!(
                    "{}: {hidden:?} noise x{} seed {}: {e}",
                    c.spec.name, c.noise, c.seed
                ));
                failed_cases.push(c.index);
            }
        }
    }
    let specs: Vec<String> = (specs.iter())
        .map(|s| format!("{} ({})", s.name, s.path.display()))
        .collect();
    let mut table = table(settings.seeds, settings.laps, cases);
    table.shard = settings.shard.map(|s| s.to_string());
    table.cases_total = Some(total);
    table.failed_cases = Some(failed_cases);
    table.selection = Some(Selection {
        specs,
        effects: settings.effects.clone(),
        beyond: beyond.iter().map(|e| e.name.clone()).collect(),
    });
    Ok(table)
}

/// The table of `cases` (in their benchmark order).
fn table(seeds: u64, laps: u64, cases: Vec<Case>) -> Table {
    let mut specs: Vec<(&str, &str)> = Vec::new();
    for c in &cases {
        if !specs.iter().any(|s| s.1 == c.spec) {
            specs.push((&c.model, &c.spec));
        }
    }
    let models = (specs.into_iter())
        .map(|(model, spec)| rates_of(model, spec, cases.iter().filter(|c| c.spec == spec)))
        .collect();
    Table {
        command: "bench-diagnose".into(),
        seeds,
        laps,
        shard: None,
        merged_shards: None,
        magnitudes_of_bound: MAGNITUDES.to_vec(),
        noise_levels: NOISE.to_vec(),
        models,
        cases,
        cases_total: None,
        failed_cases: None,
        selection: None,
    }
}

/// The rates of one model's cases.
fn rates_of<'a>(model: &str, spec: &str, cases: impl Iterator<Item = &'a Case>) -> ModelRates {
    let (mut top1, mut chains, mut false_alarms) =
        (Rate::default(), Rate::default(), Rate::default());
    let (mut recovered, mut false_proposals) = (Rate::default(), Rate::default());
    let mut redundant = 0;
    let mut seconds = Vec::new();
    for c in cases {
        seconds.push(c.seconds);
        if c.beyond {
            recovered.count(c.recovered());
            continue;
        }
        false_proposals.count(c.proposed.is_some());
        match c.hidden.len() {
            0 => false_alarms.count(!c.found.is_empty()),
            _ if !c.redundant.is_empty() => redundant += 1,
            1 => {
                top1.count(c.found.first() == c.hidden.first());
                chains.count(c.found == c.hidden);
            }
            _ => {
                let (mut f, mut h) = (c.found.clone(), c.hidden.clone());
                f.sort();
                h.sort();
                chains.count(f == h);
            }
        }
    }
    seconds.sort_by(f64::total_cmp);
    ModelRates {
        model: model.to_string(),
        spec: spec.to_string(),
        top1,
        full_chain: chains,
        false_alarms,
        redundant_cases: redundant,
        beyond_recovered: recovered,
        false_proposals,
        median_seconds: seconds.get(seconds.len() / 2).copied().unwrap_or(0.0),
        slowest_seconds: seconds.last().copied().unwrap_or(0.0),
    }
}

/// One shard's document, read for a merge.
fn read_shard(file: &Path) -> Result<(Shard, Table), BenchError> {
    let err = |why: String| BenchError::Shard {
        file: file.to_path_buf(),
        why,
    };
    // bounded, and a byte that is not UTF-8 named at its line
    let text = kinegen_model::files::read_text(file)
        .map_err(|e| err(kinegen_model::files::unreadable(e)))?;
    let doc: Table = serde_json::from_str(&text)
        .map_err(|e| err(format!("not a bench-diagnose JSON document: {e}")))?;
    let shard = (doc.shard.as_deref())
        .and_then(|s| s.parse::<Shard>().ok())
        .ok_or_else(|| err("not a shard (write shards with --shard K/N --json)".into()))?;
    if doc.cases_total.is_none() {
        return Err(err(
            "no `cases_total` (a shard of an older kinegen: run it again)".into(),
        ));
    }
    Ok((shard, doc))
}

/// Join the documents of shards (`--shard K/N --json FILE`) into the table
/// the unsharded run gives: only the whole of one benchmark (the same
/// seeds, laps, N, size and selection; every slice once; every case once).
pub fn merge(files: &[PathBuf]) -> Result<Table, BenchError> {
    let mut cases: Vec<Case> = Vec::new();
    let mut first: Option<(Shard, Table)> = None;
    let mut slices: Vec<u64> = Vec::new();
    let mut failed = 0u64;
    for f in files {
        let err = |why: String| BenchError::Shard {
            file: f.clone(),
            why,
        };
        let (shard, doc) = read_shard(f)?;
        if let Some((s, w)) = &first {
            if (doc.seeds, doc.laps) != (w.seeds, w.laps) {
                return Err(err(
                    "its --seeds or --laps differ from the other shards'".into()
                ));
            }
            if shard.n != s.n {
                return Err(err(format!(
                    "a shard of {}, the others are of {}",
                    shard.n, s.n
                )));
            }
            if (doc.cases_total, &doc.selection) != (w.cases_total, &w.selection) {
                return Err(err(
                    "a shard of another benchmark (other specs, effects or size than the others')"
                        .into(),
                ));
            }
        }
        if slices.contains(&shard.k) {
            return Err(err(format!("shard {shard} is given twice")));
        }
        slices.push(shard.k);
        failed += doc.failed_cases.as_ref().map_or(0, |v| v.len() as u64);
        for c in &doc.cases {
            if cases.iter().any(|d| d.index == c.index) {
                return Err(err(format!("case {} is in two shards", c.index)));
            }
            cases.push(c.clone());
        }
        first.get_or_insert((shard, doc));
    }
    let Some((shard, whole)) = first else {
        return Err(BenchError::Merge("no shard given".into()));
    };
    let missing: Vec<String> = (1..=shard.n)
        .filter(|k| !slices.contains(k))
        .map(|k| format!("{k}/{}", shard.n))
        .collect();
    if !missing.is_empty() {
        return Err(BenchError::Merge(format!(
            "shard(s) {} missing: the table would not be the whole benchmark",
            missing.join(", ")
        )));
    }
    let total = whole.cases_total.unwrap_or_default();
    if cases.len() as u64 + failed != total {
        return Err(BenchError::Merge(format!(
            "{} cases and {failed} failed, where the benchmark has {total}",
            cases.len()
        )));
    }
    cases.sort_by_key(|c| c.index);
    let mut table = table(whole.seeds, whole.laps, cases);
    table.merged_shards = Some(files.len());
    Ok(table)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `K/N` reads only with 1 <= K <= N, and a shard holds every N-th case.
    #[test]
    fn shards_read_and_slice() {
        let s: Shard = "2/3".parse().unwrap();
        assert_eq!(s, Shard { k: 2, n: 3 });
        assert_eq!(s.to_string(), "2/3");
        assert!((0..9).filter(|&i| s.holds(i)).eq([1, 4, 7]));
        for bad in ["0/3", "4/3", "2", "a/b", "-1/2"] {
            assert!(bad.parse::<Shard>().is_err(), "{bad}");
        }
    }

    /// The rates count each kind of case where it belongs: a clean case
    /// with a verdict is a false alarm, a redundant one is set aside, a
    /// pair is found in any order.
    #[test]
    fn rates_count_each_kind_of_case() {
        let case = |hidden: &[&str], found: &[&str], redundant: &[&str]| Case {
            index: 0,
            model: "m".into(),
            spec: "m.toml".into(),
            hidden: hidden.iter().map(|s| s.to_string()).collect(),
            noise: 1.0,
            seed: 1,
            found: found.iter().map(|s| s.to_string()).collect(),
            redundant: redundant.iter().map(|s| s.to_string()).collect(),
            seconds: 1.0,
            beyond: false,
            proposed: None,
            truth: None,
        };
        let cases = [
            case(&["a"], &["a"], &[]),
            case(&["a"], &["b", "a"], &[]),
            case(&["a", "b"], &["b", "a"], &[]),
            case(&[], &["a"], &[]),
            case(&[], &[], &[]),
            case(&["c"], &[], &["c"]),
        ];
        let beyond = |after: Option<f64>| Case {
            beyond: true,
            proposed: after.map(|held_out_after| ProposedScore {
                name: "proposed_x".into(),
                held_out_after,
            }),
            truth: Some(TruthScore {
                held_out_before: 1.0,
                held_out_true: 0.2,
            }),
            ..case(&["x"], &[], &[])
        };
        let mut proposed_on_clean = case(&[], &[], &[]);
        proposed_on_clean.proposed = beyond(Some(0.5)).proposed;
        let mut cases = cases.to_vec();
        // half of the 0.8 the truth removes is 0.4: an error of 0.55 is
        // recovered, 0.61 and no proposal are not
        cases.extend([beyond(Some(0.55)), beyond(Some(0.61)), beyond(None)]);
        cases.push(proposed_on_clean);
        let r = rates_of("m", "m.toml", cases.iter());
        assert_eq!(r.top1, Rate { found: 1, of: 2 });
        assert_eq!(r.full_chain, Rate { found: 2, of: 3 });
        assert_eq!(r.false_alarms, Rate { found: 1, of: 3 });
        assert_eq!(r.redundant_cases, 1);
        assert_eq!(r.beyond_recovered, Rate { found: 1, of: 3 });
        assert_eq!(r.false_proposals, Rate { found: 1, of: 7 });
    }
}
