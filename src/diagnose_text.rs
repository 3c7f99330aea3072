//! diagnose's default text: the answer first (which effect, how large, the
//! commands that add it and calibrate it), then one aligned table of the
//! effects tested, within 25 lines of 100 columns. `-v` prints the
//! evidence behind each line (diagnose_cmd.rs); the JSON and the report
//! keep every figure.
use crate::output::{command_lines, cut, table as new_table, table_lines, with_std, Out};
use kinegen_analysis::diagnosis::diagnose::Diagnosis;
use kinegen_analysis::diagnosis::diagnose_job::Outcome;
use kinegen_analysis::diagnosis::document::{discretisation_ratio, DISCRETISATION_WARN};
use kinegen_analysis::diagnosis::estimate::Estimates;
use kinegen_analysis::diagnosis::next_steps::NextSteps;
use kinegen_analysis::diagnosis::propose::proposal::{Proposal, ScoredOn};
use kinegen_analysis::model_on_log::model::Runner;
use kinegen_analysis::model_on_log::run::Run;

/// Say the summary, with the commands `steps` holds, in 25 lines less
/// `reserved` (the lines the command says after it: the report's path).
pub fn say_summary(
    out: &Out,
    runs: &[Run],
    r: &Runner,
    outcome: &Outcome,
    steps: &NextSteps,
    reserved: usize,
) {
    let d = &outcome.diagnosis;
    let mut head = vec![header(r, runs, outcome.tried)];
    say_answer(&mut head, d, steps);
    let mut tail = Vec::new();
    say_leftovers(&mut tail, d);
    let disc = &d.discretisation;
    let ratio = discretisation_ratio(d);
    if disc.measured && ratio > DISCRETISATION_WARN {
        tail.push(format!(
            "warning: the model's own step at {:.0} Hz errs {ratio:.1}x the noise floor (-v: why)",
            disc.rate_hz
        ));
    }
    // the weights are fit's fixed ones (docs/src/explanation/calibration.md
    // says why): a user whose spec gives other sigmas reads it here
    tail.push(
        "errors: RMS residuals in units of 0.01 m, rad and rad/s (fixed weights, not the spec's sigmas)"
            .into(),
    );
    // the table gets what the answer and the notes leave of 25 lines
    let room = LINES.saturating_sub(head.len() + tail.len() + reserved);
    for l in head.iter().chain(&table(d, room)).chain(&tail) {
        out.say(l);
    }
}

/// The most lines diagnose says by default.
const LINES: usize = 25;

/// "error 1.189 -> 0.370 (3.2x smaller)", or "(-2%)" for a small fall.
fn fall(before: f64, after: f64) -> String {
    let x = before / after.max(1e-300);
    if x >= 1.5 {
        format!("error {before:.3} -> {after:.3} ({x:.1}x smaller)")
    } else {
        format!(
            "error {before:.3} -> {after:.3} ({:+.0}%)",
            100.0 * (after / before.max(1e-300) - 1.0)
        )
    }
}

/// "skid4: 1 run, 1821 rows (91.0 s), 9 effects tested"
fn header(r: &Runner, runs: &[Run], tried: usize) -> String {
    let rows: usize = runs.iter().map(|x| x.t.len()).sum();
    let seconds: f64 = runs
        .iter()
        .map(|x| x.t.last().copied().unwrap_or(0.0) - x.t.first().copied().unwrap_or(0.0))
        .sum();
    let s = |n: usize| if n == 1 { "" } else { "s" };
    format!(
        "{}: {} run{}, {rows} rows ({seconds:.1} s); {tried} effect{} tested",
        r.ir.name,
        runs.len(),
        s(runs.len()),
        s(tried)
    )
}

/// "k_slip = 0.10060 ± 0.00039, ..."
fn values(p: &Estimates) -> String {
    p.iter()
        .map(|(k, v)| format!("{k} = {}", with_std(v.estimate, v.std)))
        .collect::<Vec<_>>()
        .join(", ")
}

/// The parameters' cell of the table: at most `PARAMS_WIDTH` characters,
/// cut with `…` (each value in full with -v and in the JSON).
fn values_cell(p: &Estimates) -> String {
    let s = values(p);
    if s.chars().count() <= PARAMS_WIDTH {
        s
    } else {
        s.chars().take(PARAMS_WIDTH - 1).collect::<String>() + "…"
    }
}

/// Room left for the parameters beside the other columns within 100.
const PARAMS_WIDTH: usize = 46;

/// The verdict and the commands that act on it.
fn say_answer(out: &mut Vec<String>, d: &Diagnosis, steps: &NextSteps) {
    if d.chain.is_empty() {
        out.push(format!(
            "answer: no catalogue effect is significant; calibrated error {:.3} (nominal {:.3})",
            d.calibrated_rmse, d.baseline_rmse
        ));
        say_proposal(out, d);
        return;
    }
    let mut before = d.calibrated_rmse;
    for (k, step) in d.chain.iter().enumerate() {
        let lead = if k == 0 { "answer: missing" } else { "  then" };
        let named = format!("{lead} `{}`: {}", step.effect, values(&step.parameters));
        if k == 0 {
            out.push(named);
            let change = match &step.sightings {
                Some(f) => format!(
                    "sightings' median range error {:.3} -> {:.3} m; motion error {:.3}",
                    f.range_before, f.range_after, step.rmse_after
                ),
                None => fall(before, step.rmse_after),
            };
            let floor = format!(
                "nominal {:.3}, noise floor {:.3}",
                d.baseline_rmse, d.noise_floor
            );
            let one = format!("    {change}; {floor}");
            if one.chars().count() <= crate::output::WIDTH {
                out.push(one);
            } else {
                out.push(format!("    {change}"));
                out.push(format!("    {floor}"));
            }
        } else {
            // a later step on one line where it fits; a sensor effect is
            // proved on the sightings, which its figures are (the motion's
            // error does not move with it)
            let change = match &step.sightings {
                Some(f) => format!(
                    "sightings' median range error {:.3} -> {:.3} m",
                    f.range_before, f.range_after
                ),
                None => fall(before, step.rmse_after),
            };
            let one = format!("{named}; {change}");
            if one.chars().count() <= crate::output::WIDTH {
                out.push(one);
            } else {
                out.push(named);
                out.push(format!("    {change}"));
            }
        }
        if !step.equivalent.is_empty() {
            let others: Vec<String> = step.equivalent.iter().map(|e| format!("`{e}`")).collect();
            out.push(format!(
                "    these logs cannot tell it from {} (-v: which log would)",
                others.join(" or ")
            ));
        }
        before = step.rmse_after;
    }
    out.push(
        if steps.apply.len() == 1 {
            "add it:"
        } else {
            "add them:"
        }
        .into(),
    );
    for cmd in &steps.apply {
        out.extend(command_lines(cmd, 2));
    }
    say_proposal(out, d);
    if let Some(fit) = &steps.calibrate {
        out.push("then calibrate:".into());
        out.extend(command_lines(fit, 2));
    }
}

/// What a proposal's held-out figures measure, for people.
pub fn scored_on(p: &Proposal) -> &'static str {
    match p.scored_on {
        ScoredOn::Track => "the track's weighted error",
        ScoredOn::Sightings => "the sightings' robust loss",
    }
}

/// The corrections beyond the catalogue diagnose proposes, one line each:
/// where it was found and its held-out fall first, then its terms (what
/// they may be, and its effect file: -v).
fn say_proposal(out: &mut Vec<String>, d: &Diagnosis) {
    for p in &d.proposed {
        let terms: Vec<String> = p
            .corrections()
            .map(|c| {
                let gain = (c.value).map_or(c.gain.to_string(), |e| with_std(e.estimate, e.std));
                // a constant term is its gain alone
                match c.term {
                    "1" => format!("{} += {gain}", c.output),
                    t => format!("{} += {gain} x {t}", c.output),
                }
            })
            .collect();
        let on = match p.scored_on {
            ScoredOn::Track => "",
            ScoredOn::Sightings => " on the sightings",
        };
        let on = if p.instead_of.is_empty() {
            on.to_string()
        } else {
            format!(" instead of {}", p.instead_of.join(" and "))
        };
        out.push(cut(&format!(
            "proposed{on}, {:+.0}% held out (-v): {}",
            100.0 * (p.held_out_after / p.held_out_before - 1.0),
            terms.join(", "),
        )));
    }
}

/// The effects tested, most likely first: the motion's, then the sensor's,
/// in at most `room` lines (a blank and the header before the rows, a
/// "more" line after them when some are left for -v); one line saying
/// where they are when a table does not fit.
fn table(d: &Diagnosis, room: usize) -> Vec<String> {
    let mut t = new_table(&["effect", "error", "change", "significant", "parameters"]);
    let mut rows = 0;
    for cand in &d.candidates {
        t.add_row(vec![
            cand.effect.clone(),
            format!("{:.3}", cand.rmse),
            format!("{:+.0}%", -100.0 * cand.improvement),
            if cand.significant { "yes" } else { "no" }.to_string(),
            values_cell(&cand.parameters),
        ]);
        rows += 1;
    }
    for s in &d.sensor_candidates {
        t.add_row(vec![
            format!("{} (sightings)", s.effect),
            "-".into(),
            "-".into(),
            if s.significant { "yes" } else { "no" }.to_string(),
            values_cell(&s.parameters),
        ]);
        rows += 1;
    }
    if rows == 0 || room == 0 {
        return Vec::new();
    }
    // all rows, or as many as leave a line for "more", one at least
    let shown = if room >= rows + 2 {
        rows
    } else if room >= 4 {
        room - 3
    } else {
        return vec![format!("the {rows} effects tested, with their figures: -v")];
    };
    if let Some(c) = t.column_mut(4) {
        c.set_cell_alignment(comfy_table::CellAlignment::Left);
    }
    let mut out = vec![String::new()];
    out.extend(table_lines(&t).into_iter().take(shown + 1));
    if rows > shown {
        out.push(format!("  ... {} more (-v)", rows - shown));
    }
    out
}

/// The effects not tested (counted by reason), and what the residuals keep.
fn say_leftovers(out: &mut Vec<String>, d: &Diagnosis) {
    let redundant = d
        .skipped
        .iter()
        .filter(|(_, w)| w.starts_with("redundant"))
        .count();
    let other = d.skipped.len() - redundant;
    if !d.skipped.is_empty() {
        out.push(format!(
            "not tested: {other} that do not apply, {redundant} redundant with the calibration (-v)"
        ));
    }
    if let Some(why) = &d.sensor_unmeasured {
        out.push(cut(&format!("sensor effects not tested: {why}")));
    }
    let proposed_on_track = d.proposed.iter().any(|p| p.scored_on == ScoredOn::Track);
    let left = if d.structure.structured && proposed_on_track {
        // the proposal's line says it (its finding is in -v)
        return;
    } else if d.structure.structured {
        let first = d.structure.findings.first().cloned().unwrap_or_default();
        format!("structure remains in the residuals: {first}")
    } else if !d.structure.findings.is_empty() {
        "residual structure not tested (too little ground truth)".to_string()
    } else {
        "residuals left: noise".to_string()
    };
    out.push(cut(&left));
}
