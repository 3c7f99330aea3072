//! `kinegen diagnose`.
use crate::analysis_cmd::{bad, prepare, quiet, Common};
use crate::effects_cmd::materialise;
use crate::ir_source;
use crate::output::Out;
use kinegen_analysis::dataset::channel_missing;
use kinegen_analysis::diagnose::diagnose;
use kinegen_analysis::effects::{default_dir, load_catalogue, Applicability};
use kinegen_analysis::model::{parse_sets, Runner};
use serde_json::json;
use std::collections::BTreeMap;
use std::process::ExitCode;
use std::time::Instant;

pub fn run(c: Common) -> ExitCode {
    let out = Out::new(c.json.as_deref());
    let t0 = Instant::now();
    let prep = match prepare(&c) {
        Ok(p) => p,
        Err(e) => return bad(e),
    };
    let text = match std::fs::read_to_string(&c.spec) {
        Ok(t) => t,
        Err(e) => return bad(format!("{}: {e}", c.spec.display())),
    };
    let catalogue = match load_catalogue(&default_dir()) {
        Ok(x) => x,
        Err(e) => return bad(e),
    };
    let sets = parse_sets(&c.set).unwrap_or_default();
    let mut augmented = Vec::new();
    let mut skipped = Vec::new();
    for eff in &catalogue {
        match eff.applicability(&text) {
            Applicability::Applies => {}
            Applicability::Redundant(why) => {
                skipped.push((eff.name.clone(), format!("redundant: {why}")));
                continue;
            }
            Applicability::AlreadyIn => {
                skipped.push((eff.name.clone(), "already in the spec".into()));
                continue;
            }
            Applicability::NotForThisModel => continue,
        }
        if let Some(channels) = eff.observation_only_channels() {
            let missing: Vec<String> = channels.iter().filter_map(|ch| channel_missing(&prep.runs, ch).map(|need| format!("the `{ch}` observation, and the logs have no {need}"))).collect();
            if missing.len() == channels.len() {
                skipped.push((eff.name.clone(), format!("not observable: it changes only {}", missing.join(" and "))));
                continue;
            }
        }
        let aug = eff.apply(&text, &BTreeMap::new()).and_then(|t| materialise(&t, &prep.runner.ir.name)).and_then(|p| ir_source::load(&p));
        match aug.and_then(|ir| Runner::new(ir, &sets).map_err(|e| e.to_string())) {
            Ok(r) => augmented.push((eff.name.clone(), eff.doc.clone(), r)),
            Err(e) => skipped.push((eff.name.clone(), format!("could not be derived: {e}"))),
        }
    }
    let t_prep = t0.elapsed();
    let t1 = Instant::now();
    let bar = crate::progress::Progress::bar(augmented.len() as u64 + 1, "diagnose", quiet(&c));
    let d = match diagnose(&prep.runner, &prep.runs, &augmented, skipped, &|step| {
        bar.message(step);
        bar.inc();
    }) {
        Ok(d) => d,
        Err(e) => return bad(e),
    };
    drop(bar);
    let t_diag = t1.elapsed();
    let r = &prep.runner;
    let samples: usize = prep.runs.iter().map(|x| x.t.len()).sum();
    out.say(&format!("{}: diagnosis on {} run(s), {samples} samples, {} candidate effect(s)", r.ir.name, prep.runs.len(), augmented.len()));
    out.say(&format!("  error with nominal parameters: {:.4}", d.baseline_rmse));
    out.say(&format!("  error after calibrating the spec as it is: {:.4} (held-out {:.4})", d.calibrated_rmse, d.base_holdout_rmse));
    out.say("  (error = RMS of residuals in units of their sigma: pose 0.01 m / 0.01 rad, gyro 0.01 rad/s)");
    out.say("candidates, most likely first:");
    for (i, cand) in d.candidates.iter().enumerate() {
        let params: Vec<String> = cand.parameters.iter().map(|(k, v)| format!("{k} = {:.5} ± {}", v["estimate"].as_f64().unwrap_or(f64::NAN), crate::output::fmt_std(v["std"].as_f64()))).collect();
        out.say(&format!(
            "  {}. {:<24} error {:.4} ({:+.0}%), {}  [{}]",
            i + 1,
            cand.effect,
            cand.rmse,
            -100.0 * cand.improvement,
            if cand.significant { "SIGNIFICANT" } else { "not significant" },
            params.join(", ")
        ));
        out.say(&format!("     {}", cand.evidence));
    }
    for (n, why) in &d.skipped {
        out.say(&format!("  (not tested: {n}: {why})"));
    }
    match &d.verdict {
        Some(v) => {
            let cand = d.candidates.iter().find(|x| &x.effect == v).unwrap();
            out.say(&format!("verdict: `{v}` is missing from the model. {}", cand.doc));
            out.say(&format!("  adding it takes the error from {:.4} to {:.4} ({:.1}x smaller)", d.calibrated_rmse, cand.rmse, d.calibrated_rmse / cand.rmse));
            let eff = catalogue.iter().find(|e| &e.name == v).unwrap();
            let vals: BTreeMap<String, f64> = cand.parameters.iter().map(|(k, v)| (k.clone(), v["estimate"].as_f64().unwrap_or(0.0))).collect();
            if let Ok(change) = eff.spec_change(&text, &vals) {
                out.say(&format!("spec change that adds it:\n{change}"));
                let args: Vec<String> = vals.iter().map(|(k, v)| format!("--value {k}={v:.6}")).collect();
                out.say(&format!("apply it with: kinegen add-effect --spec {} --effect {v} {} --out {}_{v}.toml", c.spec.display(), args.join(" "), r.ir.name));
            }
        }
        None => out.say("verdict: no catalogue effect is significant"),
    }
    if d.structure.structured {
        out.say("unexplained structure remains in the residuals:");
        for f in &d.structure.findings {
            out.say(&format!("  {f}"));
        }
    } else {
        out.say("the residuals left are noise (no structure explained by the motion)");
    }
    let per_candidate = if augmented.is_empty() { 0.0 } else { t_diag.as_secs_f64() / augmented.len() as f64 };
    out.say(&format!("time: {:.2} s preparing (derivations), {:.2} s diagnosing ({:.3} s per candidate)", t_prep.as_secs_f64(), t_diag.as_secs_f64(), per_candidate));
    let doc = json!({
        "model": r.ir.name,
        "metric": "weighted_residual_rms (pose residuals / 0.01 m and 0.01 rad, gyro / 0.01 rad/s)",
        "baseline": {"rmse": d.baseline_rmse},
        "calibrated": {"rmse": d.calibrated_rmse, "holdout_rmse": d.base_holdout_rmse,
            "parameters": d.base_fit.free.iter().map(|&i| (r.names[i].clone(), json!(d.base_fit.p[i]))).collect::<serde_json::Map<_, _>>()},
        "candidates": d.candidates,
        "verdict": {"effect": d.verdict, "unexplained_structure": d.structure.structured, "structure": d.structure.findings},
        "skipped": d.skipped.iter().map(|(n, w)| json!({"effect": n, "reason": w})).collect::<Vec<_>>(),
        "timing": {"prepare_s": t_prep.as_secs_f64(), "diagnose_s": t_diag.as_secs_f64(), "per_candidate_s": per_candidate},
    });
    if let Some(dir) = &c.report {
        if let Err(e) = crate::report::diagnose_report(dir, &prep.runner, &prep.runs, &d, &augmented, &doc) {
            return bad(e);
        }
        out.say(&format!("report: {}", dir.join("index.html").display()));
    }
    match out.json(c.json.as_deref(), &doc) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => bad(e),
    }
}
