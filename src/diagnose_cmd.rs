//! `kinegen diagnose`.
use crate::analysis_cmd::{bad, prepare, quiet, Common, Prepared};
use crate::effects_cmd::materialise;
use crate::ir_source;
use crate::output::Out;
use kinegen_analysis::dataset::channel_missing;
use kinegen_analysis::diagnose::{diagnose, Catalogue, Diagnosis};
use kinegen_analysis::effects::{catalogue, Applicability, Effect};
use kinegen_analysis::model::{parse_sets, Runner};
use kinegen_model::spec::Model;
use serde_json::json;
use std::collections::BTreeMap;
use std::process::ExitCode;
use std::time::Instant;

/// The spec with `effects` added in order (each at its nominal values).
fn with_chain(spec: &Model, cat: &[Effect], effects: &[String]) -> Result<Model, String> {
    effects.iter().try_fold(spec.clone(), |m, name| {
        let eff = cat
            .iter()
            .find(|e| &e.name == name)
            .ok_or_else(|| format!("unknown effect `{name}`"))?;
        eff.added_to(&m)
            .map_err(|why| format!("{why} (on the model with the effects found before it)"))
    })
}

/// The runner of `spec` with a chain of catalogue effects added. Derivations
/// run in `kinegen derive` children, one at a time (symbolica's one-thread
/// licence), and are cached by spec fingerprint.
fn deriver<'a>(
    spec: &'a Model,
    cat: &'a [Effect],
    name: &'a str,
    sets: &'a [(String, f64)],
) -> impl Fn(&[String]) -> Result<Runner, String> + Sync + 'a {
    move |effects: &[String]| {
        let m = with_chain(spec, cat, effects)?;
        let combined = materialise(&m.source, name)?;
        // the combined spec lives in kinegen's cache: name it by what it is
        // (`add-effect` writes the same text where the user can read it)
        let ir = ir_source::load(&combined).map_err(|e| {
            let e = e.replace(
                &combined.display().to_string(),
                &format!("{} with {} added", spec.path.display(), effects.join(", ")),
            );
            format!("could not be derived: {e} (`kinegen add-effect` writes that spec to read)")
        })?;
        Runner::new(ir, sets).map_err(|e| e.to_string())
    }
}

/// Diagnose `runs` against every applicable effect of the bundled catalogue and
/// `dirs`: the effects that apply to `spec` and are observable in these logs
/// are ranked and chained (kinegen_analysis::diagnose); the others are listed as
/// skipped with the reason. `candidates(n)` is told how many effects are tried,
/// `progress` each step. Returns the diagnosis and the number of candidates.
/// The share of the noise floor above which the model's own discretisation
/// error is no longer "far below the noise" (issue 12 item 3).
const DISCRETISATION_WARN: f64 = 0.3;

pub fn run_diagnosis(
    spec: &Model,
    runner: &Runner,
    runs: &[kinegen_analysis::run::Run],
    dirs: &[std::path::PathBuf],
    sets: &[(String, f64)],
    candidates: &dyn Fn(usize),
    progress: &(dyn Fn(&str) + Sync),
) -> Result<(kinegen_analysis::diagnose::Diagnosis, usize), String> {
    let cat = catalogue(dirs).map_err(|e| e.to_string())?;
    let mut applicable = Vec::new();
    let mut skipped = Vec::new();
    for eff in &cat {
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
    let derive = deriver(spec, &cat, &runner.ir.name, sets);
    let n = applicable.len();
    candidates(n);
    let d = diagnose(
        runner,
        runs,
        &Catalogue {
            effects: applicable,
            derive: &derive,
        },
        skipped,
        progress,
    )?;
    Ok((d, n))
}

pub fn run(c: Common) -> ExitCode {
    let out = Out::new(c.json.as_deref());
    let t0 = Instant::now();
    let mut prep = match prepare(&c) {
        Ok(p) => p,
        Err(e) => return bad(e),
    };
    pool_pieces(&mut prep);
    crate::analysis_cmd::say_warnings(&out, &prep.warnings);
    if let Err(e) = check_moves(&prep) {
        return bad(e);
    }
    let spec = match Model::load(&c.spec) {
        Ok(m) => m,
        Err(e) => return bad(e),
    };
    let sets = parse_sets(&c.set).unwrap_or_default();
    let t_prep = t0.elapsed();
    let t1 = Instant::now();
    let bar = crate::progress::Progress::bar(1, "diagnose", quiet(&c));
    let (d, n_candidates) = match run_diagnosis(
        &spec,
        &prep.runner,
        &prep.runs,
        &c.catalogue.effects,
        &sets,
        &|n| bar.set_length(n as u64 + 1),
        &|step| {
            bar.message(step);
            bar.inc();
        },
    ) {
        Ok(d) => d,
        Err(e) => return bad(e),
    };
    drop(bar);
    // the catalogue and derivation again, for the spec changes and the report
    let cat = match catalogue(&c.catalogue.effects) {
        Ok(x) => x,
        Err(e) => return bad(e),
    };
    let derive = deriver(&spec, &cat, &prep.runner.ir.name, &sets);
    let t_diag = t1.elapsed();
    let r = &prep.runner;
    let samples: usize = prep.runs.iter().map(|x| x.t.len()).sum();
    out.say(&format!(
        "{}: diagnosis on {} run(s), {samples} samples, {n_candidates} candidate effect(s)",
        r.ir.name,
        prep.runs.len()
    ));
    out.say(&format!(
        "  error with nominal parameters: {:.4}",
        d.baseline_rmse
    ));
    out.say(&format!(
        "  error after calibrating the spec as it is: {:.4} (held-out {:.4})",
        d.calibrated_rmse, d.base_holdout_rmse
    ));
    out.say("  (error = RMS of residuals in units of their sigma: pose 0.01 m / 0.01 rad, gyro 0.01 rad/s)");
    say_candidates(&out, &d);
    let apply_cmds = say_chain(&out, &c, r, &spec, &cat, &d);
    say_structure(&out, &d);
    let disc_ratio = say_discretisation(&out, &d);
    let per_candidate = if n_candidates == 0 {
        0.0
    } else {
        t_diag.as_secs_f64() / n_candidates as f64
    };
    out.say(&format!(
        "time: {:.2} s preparing, {:.2} s diagnosing",
        t_prep.as_secs_f64(),
        t_diag.as_secs_f64()
    ));
    let disc = &d.discretisation;
    let doc = json!({
        "model": r.ir.name,
        "metric": "weighted_residual_rms (pose residuals / 0.01 m and 0.01 rad, gyro / 0.01 rad/s)",
        "baseline": {"rmse": d.baseline_rmse},
        "calibrated": {"rmse": d.calibrated_rmse, "holdout_rmse": d.base_holdout_rmse,
            "parameters": d.base_fit.free.iter().map(|&i| (r.names[i].clone(), json!(d.base_fit.p[i]))).collect::<serde_json::Map<_, _>>()},
        "candidates": d.candidates,
        "verdict": {"effect": d.verdict(), "effects": d.chain, "unexplained_structure": d.structure.structured, "structure": d.structure.findings, "apply": apply_cmds},
        "discretisation": {"rate_hz": disc.rate_hz, "error": disc.error, "noise_floor": d.noise_floor, "ratio": disc_ratio, "far_below_noise": disc_ratio <= DISCRETISATION_WARN},
        "warnings": prep.warnings,
        "skipped": d.skipped.iter().map(|(n, w)| json!({"effect": n, "reason": w})).collect::<Vec<_>>(),
        "timing": {"prepare_s": t_prep.as_secs_f64(), "diagnose_s": t_diag.as_secs_f64(), "per_candidate_s": per_candidate},
    });
    if let Some(dir) = &c.report {
        if let Err(e) =
            crate::report::diagnose_report(dir, &prep.runner, &prep.runs, &d, &derive, &doc)
        {
            return bad(e);
        }
        out.say(&format!("report: {}", dir.join("index.html").display()));
    }
    match out.json(c.json.as_deref(), &doc) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => bad(e),
    }
}

/// Pieces of a log cut at its gaps that are too short to diagnose are left
/// out (with a warning), as long as the log leaves enough: diagnosis pools
/// the rest.
fn pool_pieces(prep: &mut Prepared) {
    let min = kinegen_analysis::diagnose::MIN_ROWS;
    if prep.runs.iter().any(|r| r.t.len() >= min) {
        let (keep, short): (Vec<_>, Vec<_>) = prep.runs.drain(..).partition(|r| r.t.len() >= min);
        if !short.is_empty() {
            prep.warnings.push(format!(
                "{} piece(s) under {min} rows left out of the diagnosis ({}); it pools the other {}",
                short.len(),
                short.iter().take(3).map(|r| r.path.as_str()).collect::<Vec<_>>().join(", "),
                keep.len()
            ));
        }
        prep.runs = keep;
    }
}

/// A robot that never moves shows no effect (every ratio would be 0/0): refused.
fn check_moves(prep: &Prepared) -> Result<(), String> {
    if prep.runs.iter().all(|r| r.rest_steps() == r.steps()) {
        let cols: Vec<&str> = prep
            .runner
            .ir
            .inputs
            .iter()
            .map(|i| i.column.as_str())
            .collect();
        return Err(format!(
            "{}: the inputs ({}) never change: the model robot never moves, so there is nothing to diagnose",
            prep.runs.iter().map(|r| r.path.as_str()).collect::<Vec<_>>().join(", "),
            cols.join(", ")
        ));
    }
    Ok(())
}

/// The candidates on the spec as it is, most likely first, and those not tested.
fn say_candidates(out: &Out, d: &Diagnosis) {
    out.say("candidates on the spec as it is, most likely first:");
    for (i, cand) in d.candidates.iter().enumerate() {
        let params: Vec<String> = cand
            .parameters
            .iter()
            .map(|(k, v)| {
                format!(
                    "{k} = {:.5} ± {}",
                    v["estimate"].as_f64().unwrap_or(f64::NAN),
                    crate::output::fmt_std(v["std"].as_f64())
                )
            })
            .collect();
        out.say(&format!(
            "  {}. {:<24} error {:.4} ({:+.0}%), {}  [{}]",
            i + 1,
            cand.effect,
            cand.rmse,
            -100.0 * cand.improvement,
            if cand.significant {
                "SIGNIFICANT"
            } else {
                "not significant"
            },
            params.join(", ")
        ));
        out.say(&format!("     {}", cand.evidence));
    }
    for (n, why) in &d.skipped {
        out.say(&format!("  (not tested: {n}: {why})"));
    }
}

/// The verdict: the effects found, in order, each with its estimates, the
/// error it removes, the spec change and the command that applies it (the
/// commands are returned).
fn say_chain(
    out: &Out,
    c: &Common,
    r: &Runner,
    spec: &Model,
    cat: &[Effect],
    d: &Diagnosis,
) -> Vec<String> {
    let mut model = spec.clone();
    let mut apply_cmds = Vec::new();
    if d.chain.is_empty() {
        out.say("verdict: no catalogue effect is significant");
    } else {
        let names: Vec<&str> = d.chain.iter().map(|s| s.effect.as_str()).collect();
        out.say(&format!(
            "verdict: missing from the model, in the order found: {}",
            names.join(", then ")
        ));
        let mut before = d.calibrated_rmse;
        for (k, step) in d.chain.iter().enumerate() {
            out.say(&format!("  {}. `{}`: {}", k + 1, step.effect, step.doc));
            if !step.equivalent.is_empty() {
                let others: Vec<String> =
                    step.equivalent.iter().map(|e| format!("`{e}`")).collect();
                out.say(&format!(
                    "     these logs cannot tell it apart from {}: it fits them as well (likelihood ratio under {}, 5%); a log with another channel (a gyro, landmarks) or the robot's documentation decides",
                    others.join(" or "),
                    kinegen_analysis::diagnose::EQUIVALENT
                ));
            }
            let vals: BTreeMap<String, f64> = step
                .parameters
                .iter()
                .map(|(k, v)| (k.clone(), v["estimate"].as_f64().unwrap_or(0.0)))
                .collect();
            let pv: Vec<String> = vals.iter().map(|(k, v)| format!("{k} = {v:.5}")).collect();
            out.say(&format!(
                "     {}; error {before:.4} -> {:.4} ({:.1}x smaller)",
                pv.join(", "),
                step.rmse_after,
                before / step.rmse_after.max(1e-300)
            ));
            before = step.rmse_after;
            if let Some(eff) = cat.iter().find(|e| e.name == step.effect) {
                if let Ok(change) = eff.spec_change(&model, &vals) {
                    out.say(&format!(
                        "     spec change:\n{}",
                        change
                            .lines()
                            .map(|l| format!("       {l}"))
                            .collect::<Vec<_>>()
                            .join("\n")
                    ));
                }
                let args: Vec<String> = vals
                    .iter()
                    .map(|(k, v)| format!("--value {k}={v:.6}"))
                    .collect();
                let from = if k == 0 {
                    c.spec.display().to_string()
                } else {
                    format!("{}_{}.toml", r.ir.name, d.chain[k - 1].effect)
                };
                apply_cmds.push(format!(
                    "kinegen add-effect --spec {from} --effect {} {} --out {}_{}.toml",
                    step.effect,
                    args.join(" "),
                    r.ir.name,
                    step.effect
                ));
                if let Some(m) = eff
                    .apply(&model, &vals)
                    .ok()
                    .and_then(|t| Model::parse(&spec.path, &t).ok())
                {
                    model = m;
                }
            }
        }
        out.say(&format!("apply with:\n  {}", apply_cmds.join("\n  ")));
    }
    apply_cmds
}

/// What structure the residuals keep after the last effect.
fn say_structure(out: &Out, d: &Diagnosis) {
    if d.structure.structured {
        out.say(&format!(
            "unexplained structure remains in the residuals{}:",
            if d.chain.is_empty() {
                ""
            } else {
                " after the last effect"
            }
        ));
        for f in &d.structure.findings {
            out.say(&format!("  {f}"));
        }
    } else {
        out.say("the residuals left are noise (no structure explained by the motion)");
    }
}

/// How far the model's own step errs at the log's rate, against the noise
/// floor; returns that ratio.
fn say_discretisation(out: &Out, d: &Diagnosis) -> f64 {
    let disc = &d.discretisation;
    let disc_ratio = disc.error / d.noise_floor.max(1e-300);
    if disc_ratio > DISCRETISATION_WARN {
        out.say(&format!(
            "warning: the model's own step at the log's {:.0} Hz errs by about {:.3}, {disc_ratio:.1}x the noise floor {:.3} (estimated from the log at half its rate): its inputs change too fast between samples for a constant-twist step. Effects are named only beyond that error, and structure of its size may be the step's, not the robot's; a faster log would tell",
            disc.rate_hz, disc.error, d.noise_floor
        ));
    } else {
        out.say(&format!(
            "the model's own step at the log's {:.0} Hz errs by about {:.3}, {disc_ratio:.2}x the noise floor {:.3}: far below it",
            disc.rate_hz, disc.error, d.noise_floor
        ));
    }
    disc_ratio
}
