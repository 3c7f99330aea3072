//! `kinegen diagnose --report`: the calibrated spec's and the chain's tracks,
//! the first effect's residual signature, the sightings' range errors, the
//! candidates, the spec changes and a proposal beyond the catalogue.
use super::{chart, drawn, error_chart, esc, gt_xy, page, trajectory_chart, write, Series};
use kinegen_analysis::diagnosis::clock::ClockVerdict;
use kinegen_analysis::diagnosis::diagnose::{ChainStep, Diagnosis};
use kinegen_analysis::diagnosis::diagnose_job::Outcome;
use kinegen_analysis::diagnosis::propose::proposal::Proposal;
use kinegen_analysis::model_on_log::model::Runner;
use kinegen_analysis::model_on_log::run::Run;
use plotters::prelude::*;
use serde_json::Value;
use std::path::Path;

/// Diagnosis page: before/after trajectories of the calibrated base model and of
/// the winning effect, the residual signature, and the candidate table.
pub fn diagnose_report(
    dir: &Path,
    base: &Runner,
    runs: &[Run],
    outcome: &Outcome,
    answer: &[String],
    warnings: &[String],
    doc: &Value,
) -> Result<(), String> {
    let d = &outcome.diagnosis;
    let mut figs = Vec::new();
    let chain_label = format!("with {}", outcome.chain_label());
    let (calibrated, with_chain) = (outcome.calibrated_track(base), outcome.chain_track());
    for (k, run) in runs.iter().enumerate() {
        let b = drawn(run, &calibrated);
        let mut series: Vec<Series> = vec![
            ("measured", BLACK, gt_xy(run)),
            ("calibrated spec", RED, b.traj),
        ];
        let mut errs: Vec<Series> = vec![("calibrated spec", RED, b.pos_err)];
        if let Some(with_chain) = &with_chain {
            let a = drawn(run, with_chain);
            series.push((chain_label.as_str(), GREEN, a.traj));
            errs.push((chain_label.as_str(), GREEN, a.pos_err));
        }
        let signature = outcome
            .signature
            .as_ref()
            .and_then(|sig| Some((sig, sig.per_run.get(k)?.as_ref()?)));
        if let Some((sig, (chan, pts))) = signature {
            let (name, param, est, pts) = (&sig.effect, &sig.parameter, sig.estimate, pts.clone());
            let (lo, hi) = pts.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |m, p| {
                (m.0.min(p.0), m.1.max(p.0))
            });
            let line = vec![(lo, lo), (hi, hi)];
            figs.push(chart(
                &format!("signature of {name}: {chan} one-step residual of the calibrated spec"),
                &format!("change of the prediction by {param} = {est:.4}"),
                "residual",
                &[
                    ("calibrated spec, per step", RED, pts),
                    ("residual = change (the effect explains it)", GREEN, line),
                ],
                true,
                false,
                &[],
            )?);
        }
        figs.insert(0, trajectory_chart(run, &series)?);
        let title = format!("{}: position error", run.name);
        figs.insert(1, error_chart(&title, &errs, &[])?);
    }
    let t = candidates_html(d, base);
    let intro = format!(
        "<p>Model <b>{}</b>: error {:.4} with nominal parameters, {:.4} after calibrating the spec as it is (error: RMS of the residuals in units of their sigma). Verdict: <b>{}</b>.</p>",
        esc(&base.ir.name),
        d.baseline_rmse,
        d.calibrated_rmse,
        esc(&if d.chain.is_empty() { "no catalogue effect is significant".to_string() } else { d.chain.iter().map(step_said).collect::<Vec<_>>().join(", then ") })
    );
    if let Some(fig) = sensor_chart(outcome)? {
        figs.push(fig);
    }
    // each effect's change to the spec, as add-effect writes it (the
    // commands that apply them are in the answer box)
    let mut t = t;
    for (step, change) in d.chain.iter().zip(&outcome.spec_changes) {
        if let Some(c) = change {
            t += &format!(
                "<h2>Spec change: <code>{}</code></h2><pre>{}</pre>",
                esc(&step.effect),
                esc(c)
            );
        }
    }
    for p in &d.proposed {
        t += &proposal_html(p);
    }
    write(
        dir,
        &page(
            &format!("kinegen diagnose: {}", base.ir.name),
            answer,
            &intro,
            &figs,
            &t,
            warnings,
            doc,
        ),
    )
}

/// A correction beyond the catalogue: its terms, its held-out fall, what it
/// may be, and its effect file (written beside the page, `proposed/`).
fn proposal_html(p: &Proposal) -> String {
    let terms: Vec<String> = p
        .corrections()
        .map(|c| {
            let v = c.value.map_or(String::new(), |e| {
                format!(" = {}", crate::output::with_std(e.estimate, e.std))
            });
            format!(
                "<li><code>{} += {} &times; {}</code>{v}</li>",
                esc(c.output),
                esc(c.gain),
                esc(c.term)
            )
        })
        .collect();
    format!(
        "<h2>Proposed beyond the catalogue: <code>{}</code></h2><p>Not a known physical effect: a correction these logs support{}. Held out ({}): {:.3} &rarr; {:.3}. It may be: {}.</p><ul>{}</ul><p>Its effect file, <code>proposed/{}.toml</code> beside this page (<code>kinegen add-effect --effects DIR/proposed --effect {}</code> adds it to the spec):</p><pre>{}</pre>",
        esc(&p.name),
        if p.instead_of.is_empty() {
            String::new()
        } else {
            format!(
                ", instead of the catalogue's {} (it predicts the held-out part better than they do; its effect file is for the spec without them)",
                esc(&p.instead_of.join(" and "))
            )
        },
        crate::diagnose_text::scored_on(p),
        p.held_out_before,
        p.held_out_after,
        esc(&p.reading),
        terms.join(""),
        esc(&p.name),
        esc(&p.name),
        esc(&p.toml)
    )
}

/// One effect of the verdict's chain, with what proved it.
fn step_said(c: &ChainStep) -> String {
    match &c.sightings {
        Some(f) => format!(
            "{} (the sightings' median range error {:.3} -> {:.3} m, bearing {:.4} -> {:.4} rad; proved stretch by stretch)",
            c.effect, f.range_before, f.range_after, f.bearing_before, f.bearing_after
        ),
        None => format!(
            "{} (error after: {:.4}{})",
            c.effect,
            c.rmse_after,
            if c.folds.is_some() { "; proved fold by fold" } else { "" }
        ),
    }
}

/// The range error of every sighting against its bearing, seen from the
/// ground truth, for the calibrated spec and for the model with the
/// sensor's effects found: what a camera reading depth looks like (short
/// at the edges of its view). None when the diagnosis found none.
fn sensor_chart(outcome: &Outcome) -> Result<Option<String>, String> {
    let Some(errors) = &outcome.sensor_errors else {
        return Ok(None);
    };
    let series: Vec<Series> = vec![
        ("calibrated spec", RED, errors.calibrated.clone()),
        (
            "with the sensor's effects",
            GREEN,
            errors.with_effects.clone(),
        ),
    ];
    chart(
        "landmark sightings seen from the ground truth: range error against bearing",
        "bearing (rad)",
        "range measured - predicted (m)",
        &series,
        true,
        false,
        &[],
    )
    .map(Some)
}

/// The range-bearing sensor's candidates, tested on the sightings seen from
/// the ground truth, as an HTML table (empty when none were tested).
fn sensor_html(d: &Diagnosis) -> String {
    let mut t = String::new();
    if let Some(why) = &d.sensor_unmeasured {
        t += &format!(
            "<p>The range-bearing sensor's effects were not tested: {}.</p>",
            esc(&why.to_string())
        );
    }
    if d.sensor_candidates.is_empty() {
        return t;
    }
    t += "<h2>The range-bearing sensor</h2><p>Its effects, calibrated on the landmark sightings seen from the ground truth (Huber's loss) and held out stretch by stretch of the sightings.</p>";
    t += "<table><tr><th>effect</th><th>estimates (± jackknife sd)</th><th>median range error (m)</th><th>median bearing error (rad)</th><th>held out stretch by stretch</th><th>significant</th></tr>";
    for c in &d.sensor_candidates {
        let est: Vec<String> = c
            .parameters
            .iter()
            .map(|(k, v)| format!("{k} = {:.4} ± {:.1e}", v.estimate, v.std))
            .collect();
        let (f, folds) = (&c.fit, &c.fit.folds);
        t += &format!(
            "<tr><td>{}</td><td>{}</td><td>{:.4} -> {:.4}</td><td>{:.4} -> {:.4}</td><td>{:+.0}% in {} stretches (t {:.1}, needs {:.1})</td><td>{}</td></tr>",
            esc(&c.effect),
            esc(&est.join(", ")),
            f.range_before,
            f.range_after,
            f.bearing_before,
            f.bearing_after,
            -100.0 * folds.gain,
            folds.folds,
            folds.t,
            folds.critical,
            match (&c.unphysical, c.significant) {
                (Some(why), _) => format!("no: {}", esc(why)),
                (None, true) => "yes".to_string(),
                (None, false) => "no".to_string(),
            }
        );
    }
    t + "</table>"
}

/// The diagnose report's candidates (table and evidence), the structure the
/// residuals keep, and the effects not tested, as HTML.
fn candidates_html(d: &Diagnosis, base: &Runner) -> String {
    let mut t = format!(
        "<h2>Candidates</h2><table><tr><th>effect</th><th>error</th><th>improvement</th><th>BIC gain</th><th>held-out error</th><th>held out fold by fold ({} s motion)</th><th>significant</th></tr>",
        kinegen_analysis::diagnosis::folds::WINDOW_S
    );
    for c in &d.candidates {
        let folds = c.folds.map_or("not run".to_string(), |f| {
            format!(
                "{:+.0}% (t {:.1}, needs {:.1}{})",
                -100.0 * f.gain,
                f.t,
                f.critical,
                f.too_small()
            )
        });
        t += &format!(
            "<tr><td>{}</td><td>{:.4}</td><td>{:.0}%</td><td>{:.0}</td><td>{:.4}</td><td>{}</td><td>{}</td></tr>",
            esc(&c.effect),
            c.rmse,
            100.0 * c.improvement,
            c.bic_gain,
            c.holdout_rmse,
            folds,
            match (c.significant, c.by_folds(), c.clock) {
                (true, true, _) => "yes (fold by fold)",
                (true, false, _) => "yes",
                (false, _, Some(ClockVerdict::Contradicted { .. })) => {
                    "no (the sightings contradict its delay)"
                }
                _ => "no",
            }
        );
    }
    t += "</table>";
    if let Some(clock) = &d.clock {
        t += &format!("<p>Timing: {}.</p>", esc(&clock.to_string()));
    }
    if let Some(why) = &d.clock_unmeasured {
        t += &format!("<p>Timing: {}.</p>", esc(&why.to_string()));
    }
    if let Some(said) = d.spec_clock_said(base) {
        t += &format!("<p>Timing: {}.</p>", esc(&said));
    }
    t += "<ul>";
    for c in &d.candidates {
        t += &format!("<li><b>{}</b>: {}</li>", esc(&c.effect), esc(&c.evidence));
    }
    t += "</ul>";
    t += &sensor_html(d);
    // findings of a structure test that did not run (no ground truth) say
    // why, not what is left
    let said = if d.structure.structured {
        "structure left"
    } else {
        "structure not tested"
    };
    for f in &d.structure.findings {
        t += &format!("<p class=\"warn\">{said}: {}</p>", esc(f));
    }
    if !d.skipped.is_empty() {
        t += "<h2>Not tested</h2><ul>";
        for (n, why) in &d.skipped {
            t += &format!("<li><b>{}</b>: {}</li>", esc(n), esc(why));
        }
        t += "</ul>";
    }
    t
}
