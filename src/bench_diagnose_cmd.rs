//! `kinegen bench-diagnose`: how often diagnosis names what was hidden. Every
//! spec x every applicable catalogue effect x 3 magnitudes x 2 noise levels x
//! seeds is simulated (smooth random driving, 91 s at 20 Hz) and diagnosed, plus
//! clean logs (a named effect there is a false alarm) and logs with two effects
//! at once (both must be named). Effects the diagnosis finds redundant with the
//! spec's own parameters on these logs cannot be told apart from them and are
//! counted separately, not as misses.
use crate::analysis_cmd::bad;
use crate::output::Out;
use clap::Args;
use kinegen_analysis::applications::hidden::{with_hidden, Hidden, Robots};
use kinegen_analysis::applications::simulate::{simulate, SimOptions, Trajectory};
use kinegen_analysis::diagnosis::diagnose_job::Hooks;
use kinegen_analysis::effects::{catalogue, Applicability};
use kinegen_analysis::model_on_log::model::Runner;
use kinegen_model::spec::Model;
use rayon::prelude::*;
use serde_json::json;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

#[derive(Args, Debug)]
pub struct BenchDiagnoseArgs {
    /// Specs to benchmark (repeatable). Default: spec/*.toml and
    /// tests/user_specs/*.toml under the working directory, or the bundled
    /// specs (built in) elsewhere.
    #[arg(long)]
    pub spec: Vec<PathBuf>,
    /// Only these catalogue effects (repeatable; default: every applicable one).
    #[arg(long)]
    pub effect: Vec<String>,
    /// Seeds per case (the full benchmark: 5).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..=50))]
    pub seeds: u64,
    /// Laps of the random trajectory per log: 1 is 91 s (1,820 rows at 20 Hz);
    /// 6 is 546 s (10,921 rows), the size of diagnosis' speed target.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..=100))]
    pub laps: u64,
    /// Run only slice K of N (K from 1): case number i (in the benchmark's
    /// fixed order) belongs to slice i mod N + 1. Shards run on different
    /// machines; `--merge` joins their JSON documents into the whole table.
    #[arg(long, value_name = "K/N", value_parser = parse_shard)]
    pub shard: Option<(u64, u64)>,
    /// Join the JSON documents of shards (`--shard K/N --json FILE`) into the
    /// table the unsharded run gives; nothing is diagnosed.
    #[arg(long, value_name = "FILE", num_args = 1.., conflicts_with = "shard")]
    pub merge: Vec<PathBuf>,
    /// Write one JSON document to PATH (`-`: stdout).
    #[arg(long)]
    pub json: Option<PathBuf>,
}

/// `K/N` with 1 <= K <= N.
fn parse_shard(s: &str) -> Result<(u64, u64), String> {
    let bad = || format!("`{s}` is not K/N with whole numbers 1 <= K <= N");
    let (k, n) = s.split_once('/').ok_or_else(bad)?;
    let (k, n): (u64, u64) = (
        k.trim().parse().map_err(|_| bad())?,
        n.trim().parse().map_err(|_| bad())?,
    );
    if k >= 1 && k <= n {
        Ok((k, n))
    } else {
        Err(bad())
    }
}

/// Hidden magnitudes, as fractions of each effect parameter's largest bound.
const MAGNITUDES: [f64; 3] = [0.1, 0.2, 0.4];
/// Noise levels: the simulator's default sensor noise, and 3x.
const NOISE: [f64; 2] = [1.0, 3.0];

#[derive(Debug, Clone)]
struct Case {
    /// Its number in the benchmark's fixed order (what `--shard` slices).
    index: u64,
    model: String,
    spec: String,
    hidden: Vec<String>,
    noise: f64,
    seed: u64,
    found: Vec<String>,
    /// Hidden effects the diagnosis set aside as redundant on this log.
    redundant: Vec<String>,
    seconds: f64,
}

#[derive(Default)]
struct Rates {
    top1: (usize, usize),
    chains: (usize, usize),
    false_alarms: (usize, usize),
    redundant: usize,
    seconds: Vec<f64>,
}

/// The bundled specs, built in so that the benchmark runs from any directory.
const BUNDLED: [(&str, &str); 6] = [
    ("diff_drive", include_str!("../spec/diff_drive.toml")),
    ("tricycle", include_str!("../spec/tricycle.toml")),
    ("tricycle_fwd", include_str!("../spec/tricycle_fwd.toml")),
    ("omni3", include_str!("../spec/omni3.toml")),
    ("omni_caster", include_str!("../spec/omni_caster.toml")),
    ("unicycle_ekf", include_str!("../spec/unicycle_ekf.toml")),
];

/// spec/*.toml and tests/user_specs/*.toml under the working directory (a
/// checkout), else the built-in bundled specs (named `NAME.toml (built into
/// kinegen)`: they have no file, and none is written).
fn default_specs() -> Result<Vec<Model>, String> {
    let local = local_specs();
    if !local.is_empty() {
        return local
            .iter()
            .map(|p| Model::load(p).map_err(|e| e.to_string()))
            .collect();
    }
    BUNDLED
        .iter()
        .map(|(name, text)| {
            let label = PathBuf::from(format!("{name}.toml (built into kinegen)"));
            Model::parse(&label, text).map_err(|e| e.to_string())
        })
        .collect()
}

fn local_specs() -> Vec<PathBuf> {
    let mut v = Vec::new();
    for dir in ["spec", "tests/user_specs"] {
        if let Ok(rd) = std::fs::read_dir(dir) {
            let mut files: Vec<PathBuf> = rd
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.extension().is_some_and(|e| e == "toml"))
                .collect();
            files.sort();
            v.extend(files);
        }
    }
    v
}

/// The applicable effects of a spec, each with its first parameter and that
/// parameter's largest bound.
fn effects_of(spec: &Model) -> Result<Vec<(String, String, f64)>, String> {
    let cat = catalogue(&[]).map_err(|e| e.to_string())?;
    let mut out = Vec::new();
    for eff in &cat {
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
        let bound = if bound > 0.0 { bound } else { 0.5 };
        out.push((eff.name.clone(), p.name, bound));
    }
    Ok(out)
}

fn run_case(
    spec: &Model,
    hidden: &[(String, String, f64)],
    noise: f64,
    seed: u64,
    laps: u64,
) -> Result<Case, String> {
    let effects: Vec<Hidden> = hidden
        .iter()
        .map(|(e, p, v)| Hidden::new(e, p, *v))
        .collect();
    let Robots {
        spec: base,
        robot: truth,
    } = with_hidden(
        spec,
        &effects,
        &[],
        &[],
        crate::ir_source::analysis_deriver(),
    )
    .map_err(|e| e.to_string())?;
    let o = SimOptions {
        trajectory: Trajectory::Random,
        seed,
        laps: laps as usize,
        pos_noise: 0.001 * noise,
        heading_noise: 0.002 * noise,
        gyro_noise: 0.005 * noise,
        ..SimOptions::default()
    };
    let run = simulate(&base, &truth, &o)
        .to_run(&base, "bench")
        .map_err(|e| e.to_string())?;
    let cat = catalogue(&[]).map_err(|e| e.to_string())?;
    let t0 = Instant::now();
    let outcome = kinegen_analysis::diagnosis::request::diagnose_runs(
        spec,
        (&base, std::slice::from_ref(&run)),
        (&cat, crate::ir_source::analysis_deriver()),
        &[],
        false,
        &Hooks::none(),
    )
    .map_err(|e| e.to_string())?;
    let d = outcome.diagnosis;
    let names: Vec<String> = hidden.iter().map(|h| h.0.clone()).collect();
    Ok(Case {
        index: 0,
        model: spec.name.clone(),
        spec: spec.path.display().to_string(),
        redundant: d
            .skipped
            .iter()
            .filter(|(e, why)| names.contains(e) && why.starts_with("redundant"))
            .map(|(e, _)| e.clone())
            .collect(),
        hidden: names,
        noise,
        seed,
        // a step that names a group these logs cannot tell apart counts as
        // naming the hidden effect when the group holds it
        found: d
            .chain
            .iter()
            .map(|c| {
                hidden
                    .iter()
                    .map(|h| &h.0)
                    .find(|h| c.equivalent.contains(h))
                    .cloned()
                    .unwrap_or_else(|| c.effect.clone())
            })
            .collect(),
        seconds: t0.elapsed().as_secs_f64(),
    })
}

pub fn run(a: &BenchDiagnoseArgs) -> ExitCode {
    let out = Out::new(a.json.as_deref());
    if !a.merge.is_empty() {
        return match merged(&a.merge) {
            Ok((seeds, laps, cases)) => {
                finish(&out, a, seeds, laps, &cases, Some(a.merge.len()), None)
            }
            Err(e) => bad(e),
        };
    }
    let specs = if a.spec.is_empty() {
        default_specs()
    } else {
        a.spec
            .iter()
            .map(|p| Model::load(p).map_err(|e| e.to_string()))
            .collect()
    };
    let specs = match specs {
        Ok(s) => s,
        Err(e) => return bad(e),
    };
    let known: Vec<String> = match catalogue(&[]) {
        Ok(c) => c.iter().map(|e| e.name.clone()).collect(),
        Err(e) => return bad(e),
    };
    if let Some(e) = a.effect.iter().find(|e| !known.contains(e)) {
        return bad(format!(
            "--effect {e}: no such effect in the catalogue (it has: {})",
            known.join(", ")
        ));
    }
    // every case of this shard, in benchmark order
    let mut todo = Vec::new();
    let mut index = 0u64;
    for spec in &specs {
        // a spec that does not derive, or whose IR is unusable, stops the
        // benchmark before its first case
        if let Err(e) = crate::ir_source::analysis_deriver()
            .derive(spec, &spec.path.display().to_string())
            .map_err(|e| e.to_string())
            .and_then(|ir| Runner::new(ir, &[]).map_err(|e| e.to_string()))
        {
            return bad(e);
        }
        let mut effects = match effects_of(spec) {
            Ok(e) => e,
            Err(e) => return bad(e),
        };
        if !a.effect.is_empty() {
            effects.retain(|(e, _, _)| a.effect.contains(e));
        }
        for (j, hidden) in hidden_sets(&effects).into_iter().enumerate() {
            for &noise in &NOISE {
                for seed in 1..=a.seeds {
                    let i = index;
                    index += 1;
                    if a.shard.is_some_and(|(k, n)| i % n != k - 1) {
                        continue;
                    }
                    // every case its own trajectory
                    todo.push((i, spec, hidden.clone(), noise, seed, 1000 * j as u64 + seed));
                }
            }
        }
    }
    // the cases on every core: derivation takes no lock, and each
    // diagnosis shares the threads it does not use
    let done: Vec<_> = todo
        .par_iter()
        .map(|(_, spec, hidden, noise, _, trajectory)| {
            run_case(spec, hidden, *noise, *trajectory, a.laps)
        })
        .collect();
    let mut cases = Vec::new();
    let mut failed: Vec<u64> = Vec::new();
    for ((i, spec, hidden, noise, seed, _), result) in todo.iter().zip(done) {
        match result {
            Ok(c) => cases.push(Case { index: *i, ..c }),
            Err(e) => {
                out.say(&format!(
                    "  {}: {hidden:?} noise x{noise} seed {seed}: {e}",
                    spec.name
                ));
                failed.push(*i);
            }
        }
    }
    // what a merge checks the shards against: the whole benchmark's size,
    // which cases of this slice failed, and what was selected
    let whole = Whole {
        total: index,
        failed,
        selection: selection(a, &specs),
    };
    finish(&out, a, a.seeds, a.laps, &cases, None, Some(&whole))
}

/// The benchmark a shard belongs to: how many cases the whole has, the
/// cases of this shard that failed, and the specs and effects selected. A
/// merge joins only shards of one whole, and only a whole one.
struct Whole {
    total: u64,
    failed: Vec<u64>,
    selection: serde_json::Value,
}

/// The specs (by name and path) and effects the benchmark was run on.
fn selection(a: &BenchDiagnoseArgs, specs: &[Model]) -> serde_json::Value {
    let specs: Vec<String> = specs
        .iter()
        .map(|s| format!("{} ({})", s.name, s.path.display()))
        .collect();
    json!({"specs": specs, "effects": a.effect})
}

/// The hidden effects of a spec's cases: each effect at each magnitude,
/// consecutive pairs of the catalogue at the middle magnitude, and two
/// clean logs.
fn hidden_sets(effects: &[(String, String, f64)]) -> Vec<Vec<(String, String, f64)>> {
    let mut jobs: Vec<Vec<(String, String, f64)>> = Vec::new();
    for (e, p, bound) in effects {
        for m in MAGNITUDES {
            jobs.push(vec![(e.clone(), p.clone(), m * bound)]);
        }
    }
    for w in effects.windows(2) {
        jobs.push(
            w.iter()
                .map(|(e, p, b)| (e.clone(), p.clone(), MAGNITUDES[1] * b))
                .collect(),
        );
    }
    jobs.push(Vec::new()); // clean
    jobs.push(Vec::new());
    jobs
}

/// The rates of one model's cases.
fn rates_of<'a>(cases: impl Iterator<Item = &'a Case>) -> Rates {
    let mut rates = Rates::default();
    for c in cases {
        rates.seconds.push(c.seconds);
        match c.hidden.len() {
            0 => {
                rates.false_alarms.1 += 1;
                rates.false_alarms.0 += usize::from(!c.found.is_empty());
            }
            _ if !c.redundant.is_empty() => rates.redundant += 1,
            1 => {
                rates.top1.1 += 1;
                rates.top1.0 += usize::from(c.found.first() == c.hidden.first());
                rates.chains.1 += 1;
                rates.chains.0 += usize::from(c.found == c.hidden);
            }
            _ => {
                let (mut f, mut h) = (c.found.clone(), c.hidden.clone());
                f.sort();
                h.sort();
                rates.chains.1 += 1;
                rates.chains.0 += usize::from(f == h);
            }
        }
    }
    rates
}

/// The table of `cases` (in their benchmark order), said and written as JSON.
fn finish(
    out: &Out,
    a: &BenchDiagnoseArgs,
    seeds: u64,
    laps: u64,
    cases: &[Case],
    shards: Option<usize>,
    whole: Option<&Whole>,
) -> ExitCode {
    let mut specs: Vec<(&str, &str)> = Vec::new();
    for c in cases {
        if !specs.iter().any(|s| s.1 == c.spec) {
            specs.push((&c.model, &c.spec));
        }
    }
    let pct = |(k, n): (usize, usize)| {
        if n == 0 {
            "-".to_string()
        } else {
            format!("{:.0}% ({k}/{n})", 100.0 * k as f64 / n as f64)
        }
    };
    let mut table = Vec::new();
    for (model, spec) in specs {
        let rates = rates_of(cases.iter().filter(|c| c.spec == spec));
        let mut secs = rates.seconds.clone();
        secs.sort_by(f64::total_cmp);
        let median = secs.get(secs.len() / 2).copied().unwrap_or(0.0);
        let slowest = secs.last().copied().unwrap_or(0.0);
        out.say(&format!(
            "{:<14} top-1 {:<14} full chain {:<14} false alarms {:<12} redundant {:<3} median {:.1} s, slowest {:.1} s per diagnosis",
            model,
            pct(rates.top1),
            pct(rates.chains),
            pct(rates.false_alarms),
            rates.redundant,
            median,
            slowest
        ));
        let rate = |(k, n): (usize, usize)| json!({"found": k, "of": n});
        table.push(json!({
            "model": model, "spec": spec,
            "top1": rate(rates.top1), "full_chain": rate(rates.chains), "false_alarms": rate(rates.false_alarms),
            "redundant_cases": rates.redundant, "median_seconds": median, "slowest_seconds": slowest,
        }));
    }
    let cases_json: Vec<_> = cases
        .iter()
        .map(|c| {
            json!({
                "index": c.index, "model": c.model, "spec": c.spec, "hidden": c.hidden, "noise": c.noise,
                "seed": c.seed, "found": c.found, "redundant": c.redundant, "seconds": c.seconds,
            })
        })
        .collect();
    let shard = a.shard.map(|(k, n)| format!("{k}/{n}"));
    let mut doc = json!({"command": "bench-diagnose", "seeds": seeds, "laps": laps, "shard": shard, "merged_shards": shards,
        "magnitudes_of_bound": MAGNITUDES, "noise_levels": NOISE, "models": table, "cases": cases_json});
    if let Some(w) = whole {
        doc["cases_total"] = json!(w.total);
        doc["failed_cases"] = json!(w.failed);
        doc["selection"] = w.selection.clone();
    }
    match out.json(a.json.as_deref(), &doc) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => bad(e),
    }
}

/// The cases of shard documents, in benchmark order; each case once.
fn merged(files: &[PathBuf]) -> Result<(u64, u64, Vec<Case>), String> {
    let mut cases: Vec<Case> = Vec::new();
    let mut settings = None;
    let mut whole = None;
    let mut slices: Vec<u64> = Vec::new();
    let mut failed = 0u64;
    for f in files {
        let text = std::fs::read_to_string(f).map_err(|e| format!("{}: {e}", f.display()))?;
        let doc: serde_json::Value = serde_json::from_str(&text)
            .map_err(|e| format!("{}: not a bench-diagnose JSON document: {e}", f.display()))?;
        let here = (doc["seeds"].as_u64(), doc["laps"].as_u64());
        if *settings.get_or_insert(here) != here {
            return Err(format!(
                "{}: its --seeds or --laps differ from the other shards'",
                f.display()
            ));
        }
        // one benchmark's shards: the same N, the same whole, the same
        // selection of specs and effects
        let (k, n) = doc["shard"]
            .as_str()
            .and_then(|s| parse_shard(s).ok())
            .ok_or_else(|| {
                format!(
                    "{}: not a shard (write shards with --shard K/N --json)",
                    f.display()
                )
            })?;
        let this = (n, doc["cases_total"].as_u64(), doc["selection"].clone());
        if this.1.is_none() {
            return Err(format!(
                "{}: no `cases_total` (a shard of an older kinegen: run it again)",
                f.display()
            ));
        }
        match &whole {
            None => whole = Some(this),
            Some(w) if w.0 != n => {
                return Err(format!(
                    "{}: a shard of {n}, the others are of {}",
                    f.display(),
                    w.0
                ))
            }
            Some(w) if *w != this => {
                return Err(format!(
                "{}: a shard of another benchmark (other specs, effects or size than the others')",
                f.display()
            ))
            }
            Some(_) => {}
        }
        if slices.contains(&k) {
            return Err(format!("{}: shard {k}/{n} is given twice", f.display()));
        }
        slices.push(k);
        failed += doc["failed_cases"].as_array().map_or(0, |v| v.len() as u64);
        let list = doc["cases"]
            .as_array()
            .ok_or_else(|| format!("{}: no `cases` (write shards with --json)", f.display()))?;
        let strings = |v: &serde_json::Value| -> Vec<String> {
            v.as_array()
                .into_iter()
                .flatten()
                .filter_map(|s| s.as_str().map(str::to_string))
                .collect()
        };
        for c in list {
            let index = c["index"]
                .as_u64()
                .ok_or_else(|| format!("{}: a case without `index` (not a shard)", f.display()))?;
            if cases.iter().any(|d| d.index == index) {
                return Err(format!("{}: case {index} is in two shards", f.display()));
            }
            cases.push(Case {
                index,
                model: c["model"].as_str().unwrap_or_default().to_string(),
                spec: c["spec"].as_str().unwrap_or_default().to_string(),
                hidden: strings(&c["hidden"]),
                noise: c["noise"].as_f64().unwrap_or(0.0),
                seed: c["seed"].as_u64().unwrap_or(0),
                found: strings(&c["found"]),
                redundant: strings(&c["redundant"]),
                seconds: c["seconds"].as_f64().unwrap_or(0.0),
            });
        }
    }
    if let Some((n, Some(total), _)) = &whole {
        let missing: Vec<String> = (1..=*n)
            .filter(|k| !slices.contains(k))
            .map(|k| format!("{k}/{n}"))
            .collect();
        if !missing.is_empty() {
            return Err(format!(
                "--merge: shard(s) {} missing: the table would not be the whole benchmark",
                missing.join(", ")
            ));
        }
        if cases.len() as u64 + failed != *total {
            return Err(format!(
                "--merge: {} cases and {failed} failed, where the benchmark has {total}",
                cases.len()
            ));
        }
    }
    cases.sort_by_key(|c| c.index);
    let (seeds, laps) = settings.unwrap_or((Some(1), Some(1)));
    Ok((seeds.unwrap_or(1), laps.unwrap_or(1), cases))
}
