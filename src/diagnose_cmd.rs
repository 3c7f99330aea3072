//! `kinegen diagnose`.
use crate::analysis_cmd::{bad, quiet, Common};
use crate::output::Out;
use kinegen_analysis::diagnosis::clock::ClockVerdict;
use kinegen_analysis::diagnosis::diagnose::Diagnosis;
use kinegen_analysis::diagnosis::diagnose_job::{Hooks, Outcome};
use kinegen_analysis::diagnosis::document::{
    diagnose_document, discretisation_ratio, DISCRETISATION_WARN,
};
use kinegen_analysis::diagnosis::next_steps::{Invocation, NextSteps};
use kinegen_analysis::diagnosis::request::{diagnose_files, Request};
use kinegen_analysis::model_on_log::files::Files;
use kinegen_analysis::model_on_log::model::Runner;
use std::collections::BTreeMap;
use std::process::ExitCode;

/// What diagnose's errors are measured in.
pub const ERROR_UNIT: &str =
    "  (error = RMS of residuals in units of their sigma: pose 0.01 m / 0.01 rad, gyro 0.01 rad/s)";

pub fn run(c: Common) -> ExitCode {
    let out = Out::new(c.json.as_deref());
    if let Err(e) = crate::output::check_outputs(c.json.as_deref(), c.report.as_deref()) {
        return bad(e);
    }
    if let Err(e) = c.check_repeated_logs() {
        return bad(e);
    }
    let bar = crate::progress::Progress::bar(1, "diagnose", quiet(&c));
    let sources = c.sources();
    let request = Request {
        files: Files {
            sources: &sources,
            effect_dirs: &c.catalogue.effects,
        },
        for_report: c.report.is_some(),
    };
    let warned = std::cell::Cell::new(0);
    let done = diagnose_files(
        &request,
        crate::ir_source::analysis_deriver(),
        &crate::analysis_cmd::read_progress(quiet(&c)),
        &Hooks {
            // said before the diagnosis starts, as the logs are read
            warnings: &|w| {
                let said = crate::analysis_cmd::say_read_warnings(&out, w, c.verbose);
                warned.set(warned.get() + said);
            },
            candidates: &|n| bar.set_length(n as u64 + 1),
            progress: &|step| {
                bar.message(step);
                bar.inc();
            },
        },
    );
    drop(bar);
    let done = match done {
        Ok(d) => d,
        Err(e) => return bad(e.to_string()),
    };
    let (prep, outcome) = (&done.loaded, &done.outcome);
    let (d, n_candidates) = (&outcome.diagnosis, outcome.tried);
    let r = &prep.runner;
    let steps = NextSteps::of(
        d,
        &r.ir.name,
        &Invocation::of(&sources, &c.catalogue.effects),
    );
    let doc = diagnose_document(&done, &steps);
    let samples: usize = prep.runs.iter().map(|x| x.t.len()).sum();
    // the answer: said by default, and the report's first box
    let kept = Out::keeping();
    let reserved = warned.get() + usize::from(c.report.is_some());
    crate::diagnose_text::say_summary(&kept, &prep.runs, r, outcome, &steps, reserved);
    let answer = kept.lines();
    if c.verbose {
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
        out.say(ERROR_UNIT);
        say_timing(&out, d, r);
        say_candidates(&out, d);
        say_chain(&out, outcome, &steps);
        say_structure(&out, d);
        say_proposals(&out, d);
        say_discretisation(&out, d);
        out.say(&format!(
            "time: {:.2} s preparing, {:.2} s diagnosing",
            done.preparing.as_secs_f64(),
            done.diagnosing.as_secs_f64()
        ));
    } else {
        answer.iter().for_each(|l| out.say(l));
    }
    if let Some(dir) = &c.report {
        if let Err(e) = crate::report::diagnose::diagnose_report(
            dir,
            &prep.runner,
            &prep.runs,
            outcome,
            &answer,
            &prep.warnings,
            &doc,
        ) {
            return bad(e);
        }
        // the proposal as an effect file `add-effect --effects DIR/proposed` reads
        for p in &d.proposed {
            let file = dir.join("proposed").join(format!("{}.toml", p.name));
            if let Err(e) = kinegen_model::files::write_atomic(&file, &p.toml) {
                return bad(e);
            }
        }
        out.say(&format!("report: {}", dir.join("index.html").display()));
    }
    out.finish(c.json.as_deref(), &doc)
}

/// The corrections beyond the catalogue in full (-v): their held-out
/// figures, what they may be, and their effect files.
fn say_proposals(out: &Out, d: &Diagnosis) {
    for p in &d.proposed {
        out.say(&format!(
            "proposed beyond the catalogue: {} ({} held out: {:.4} -> {:.4}); may be: {}",
            p.name,
            crate::diagnose_text::scored_on(p),
            p.held_out_before,
            p.held_out_after,
            p.reading
        ));
        if !p.instead_of.is_empty() {
            out.say(&format!(
                "  instead of the catalogue's {}: it predicts the held-out part better than they do (its effect file is for the spec without them)",
                p.instead_of.join(" and ")
            ));
        }
        out.say("  its effect file (--report DIR writes it to DIR/proposed/; add-effect --effects DIR applies it):");
        p.toml.lines().for_each(|l| out.say(&format!("  {l}")));
    }
}

/// What the landmark sightings said of the ground truth's clock, and of the
/// spec's own measurement delay.
fn say_timing(out: &Out, d: &Diagnosis, r: &Runner) {
    if let Some(clock) = &d.clock {
        out.say(&format!(
            "  timing: {clock}; a delay of the ground truth must lie within {:.3} s of {} s",
            clock.resolution,
            signed_ms(clock.lag)
        ));
    }
    if let Some(why) = &d.clock_unmeasured {
        out.say(&format!("  timing: {why}"));
    }
    if let Some(said) = d.spec_clock_said(r) {
        out.say(&format!("  timing: {said}"));
    }
}

/// Each estimate of `p` with its standard deviation ("unidentified" where
/// it has none), as the candidates' lists write them.
pub fn estimates_said(p: &kinegen_analysis::diagnosis::estimate::Estimates) -> Vec<String> {
    p.iter()
        .map(|(k, v)| {
            let std = crate::output::fmt_std(Some(v.std).filter(|s| s.is_finite()));
            format!("{k} = {:.5} ± {std}", v.estimate)
        })
        .collect()
}

/// The candidates on the spec as it is, most likely first, and those not tested.
fn say_candidates(out: &Out, d: &Diagnosis) {
    out.say("candidates on the spec as it is, most likely first:");
    for (i, cand) in d.candidates.iter().enumerate() {
        let params = estimates_said(&cand.parameters);
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
    say_sensor(out, d);
}

/// The range-bearing sensor's candidates, tested on the sightings seen from
/// the ground truth (or why they were not).
fn say_sensor(out: &Out, d: &Diagnosis) {
    if let Some(why) = &d.sensor_unmeasured {
        out.say(&format!("  (sensor effects not tested: {why})"));
    }
    if d.sensor_candidates.is_empty() {
        return;
    }
    out.say("the range-bearing sensor's candidates, on the sightings seen from the ground truth:");
    for (i, c) in d.sensor_candidates.iter().enumerate() {
        let params = estimates_said(&c.parameters);
        let verdict = if c.significant {
            "SIGNIFICANT"
        } else {
            "not significant"
        };
        out.say(&format!(
            "  {}. {:<24} {verdict}  [{}]",
            i + 1,
            c.effect,
            params.join(", ")
        ));
        out.say(&format!("     {}", sightings_said(&c.fit)));
    }
}

/// How a sensor effect fits the sightings, in words.
fn sightings_said(f: &kinegen_analysis::diagnosis::sensor::SightingFit) -> String {
    let t = &f.folds;
    format!(
        "{} sightings: median range error {:.4} -> {:.4} m, bearing {:.4} -> {:.4} rad; calibrated without each of {} stretches of them in turn, it predicts that stretch {:.0}% better (robust loss; paired t = {:.1}, needs {:.1})",
        f.sightings, f.range_before, f.range_after, f.bearing_before, f.bearing_after,
        t.folds, 100.0 * t.gain, t.t, t.critical
    )
}

/// The verdict: the effects found, in order, each with its estimates, the
/// error it removes, the spec change and the command that applies it.
fn say_chain(out: &Out, outcome: &Outcome, steps: &NextSteps) {
    let d = &outcome.diagnosis;
    if d.chain.is_empty() {
        out.say("verdict: no catalogue effect is significant");
        return;
    }
    let names: Vec<&str> = d.chain.iter().map(|s| s.effect.as_str()).collect();
    out.say(&format!(
        "verdict: missing from the model, in the order found: {}",
        names.join(", then ")
    ));
    let mut before = d.calibrated_rmse;
    for (k, step) in d.chain.iter().enumerate() {
        out.say(&format!("  {}. `{}`: {}", k + 1, step.effect, step.doc));
        if !step.equivalent.is_empty() {
            say_equivalent(out, d, step);
        }
        if k == 0 {
            say_clock_verdicts(out, d, &step.effect);
        }
        let vals: BTreeMap<String, f64> = step
            .parameters
            .iter()
            .map(|(k, v)| (k.clone(), v.estimate))
            .collect();
        let pv: Vec<String> = vals.iter().map(|(k, v)| format!("{k} = {v:.5}")).collect();
        if let Some(f) = &step.sightings {
            out.say(&format!("     {}; {}", pv.join(", "), sightings_said(f)));
        } else {
            out.say(&format!(
                "     {}; error {before:.4} -> {:.4} ({:.1}x smaller)",
                pv.join(", "),
                step.rmse_after,
                before / step.rmse_after.max(1e-300)
            ));
        }
        if let Some(f) = &step.folds {
            // what proved it: the whole log's error barely moves when
            // random drift dominates it
            out.say(&format!(
                "     proved fold by fold: calibrated without each of {} stretches of the log in turn, it predicts that stretch's motion over {} s better (mean square error {:.0}% lower over all; paired t = {:.1}, needs {:.1})",
                f.folds,
                kinegen_analysis::diagnosis::folds::WINDOW_S,
                100.0 * f.gain,
                f.t,
                f.critical
            ));
        }
        before = step.rmse_after;
        if let Some(change) = &outcome.spec_changes[k] {
            out.say(&format!(
                "     spec change:\n{}",
                change
                    .lines()
                    .map(|l| format!("       {l}"))
                    .collect::<Vec<_>>()
                    .join("\n")
            ));
        }
    }
    out.say(&format!("apply with:\n  {}", steps.apply.join("\n  ")));
    if let Some(fit) = &steps.calibrate {
        out.say(&format!(
            "then calibrate it, its values kept as the spec's nominals (what localize, compare and simulate run):\n  {fit}"
        ));
    }
    if !steps.alternatives.is_empty() {
        out.say(&format!(
            "or, in place of `{}` (these logs cannot tell which the robot has):\n  {}",
            d.chain[0].effect,
            steps.alternatives.join("\n  ")
        ));
    }
}

/// The rivals these logs fit as well as `step`, and what would decide.
fn say_equivalent(
    out: &Out,
    d: &Diagnosis,
    step: &kinegen_analysis::diagnosis::diagnose::ChainStep,
) {
    let others: Vec<String> = step.equivalent.iter().map(|e| format!("`{e}`")).collect();
    let per = match step.folds {
        Some(_) => ", each segment counted once",
        None => "",
    };
    let how = format!(
        "it fits them as well (likelihood ratio under {}, 5%{per})",
        kinegen_analysis::diagnosis::ranking::EQUIVALENT
    );
    // with sightings the motion capture's clock is measured already: what
    // is left are rivals on the robot's side
    let decides = match d.clock {
        Some(_) => "the landmark sightings time the ground truth, not the robot: a log of the speeds it executed or its documentation decides",
        None => "a log with another channel (a gyro, landmarks) or the robot's documentation decides",
    };
    out.say(&format!(
        "     these logs cannot tell it apart from {}: {how}; {decides}",
        others.join(" or "),
    ));
}

/// What the landmark sightings said of the first round's candidates that
/// change the ground truth's delay: the winner confirmed, rivals that fit
/// the logs but need a ground truth later than the sightings allow.
fn say_clock_verdicts(out: &Out, d: &Diagnosis, winner: &str) {
    let Some(clock) = &d.clock else { return };
    for c in &d.candidates {
        match c.clock {
            Some(ClockVerdict::Contradicted { delay }) => out.say(&format!(
                "     ruled out by the landmark sightings: `{}` (error {:.4}, BIC gain {:.0}) needs the ground truth {delay:.3} s behind them; they put it at {} s (within {:.3})",
                c.effect, c.rmse, c.bic_gain, signed_ms(clock.lag), clock.resolution
            )),
            Some(ClockVerdict::Confirmed { delay }) if c.effect == winner => out.say(&format!(
                "     confirmed by the landmark sightings: they match the ground truth's pose {} s after their stamps (within {:.3}), as its {delay:.3} s needs: the ground truth is late, not the robot",
                signed_ms(clock.lag), clock.resolution
            )),
            _ => {}
        }
    }
}

/// Seconds to the millisecond with their sign, a rounded -0 as +0.000.
fn signed_ms(s: f64) -> String {
    format!("{:+.3}", (s * 1e3).round() / 1e3 + 0.0)
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
    } else if !d.structure.findings.is_empty() {
        // not tested (no ground truth to take one-step residuals from): not
        // a clean bill
        out.say(&format!(
            "the residuals' structure is not tested: {}",
            d.structure.findings.join("; ")
        ));
    } else {
        out.say("the residuals left are noise (no structure explained by the motion)");
    }
}

/// How far the model's own step errs at the log's rate, against the noise
/// floor.
fn say_discretisation(out: &Out, d: &Diagnosis) {
    let disc = &d.discretisation;
    let disc_ratio = discretisation_ratio(d);
    if !disc.measured {
        out.say(&format!(
            "the model's own step at the log's {:.0} Hz is not measured (it takes a ground truth on every run, and runs of 10 rows or more)",
            disc.rate_hz
        ));
    } else if disc_ratio > DISCRETISATION_WARN {
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
}
