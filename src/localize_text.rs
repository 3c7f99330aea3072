//! localize's default text: the answer first (how far the filter's track
//! is off, against dead reckoning), a table of the runs with their
//! consistency, and the one action the estimate suggests (a range reading
//! to put in the spec), within 25 lines of 100 columns. `-v` says the noise
//! estimate and every consistency figure (localize_cmd.rs); the JSON and
//! the report keep them all.
use crate::output::{command_lines, cut, table, table_lines, Out};
use kinegen_analysis::applications::localize::summary::{side, Side, Summary};
use kinegen_analysis::applications::localize::{Localization, Localized};
use kinegen_analysis::model_on_log::run::Run;

/// Runs listed by default (the rest behind -v).
const RUNS: usize = 12;

/// "1.63 low" / "3.26 ok" / "5.61 high": a mean against its 95% bounds.
fn judged(m: Option<f64>, b: Option<kinegen_analysis::applications::localize::Bounds>) -> String {
    match (m, side(m, b)) {
        (Some(m), Some(Side::Below)) => format!("{m:.2} low"),
        (Some(m), Some(Side::Within)) => format!("{m:.2} ok"),
        (Some(m), Some(Side::Above)) => format!("{m:.2} high"),
        (Some(m), None) => format!("{m:.2}"),
        _ => "-".into(),
    }
}

pub fn say_summary(
    out: &Out,
    model: &str,
    runs: &[&Run],
    done: &Localized,
    advice: Option<(String, String)>,
) {
    let secs: f64 = runs.iter().map(|r| r.t.last().unwrap() - r.t[0]).sum();
    let used: usize = done.runs.iter().map(|(l, _)| l.accepted).sum();
    let s = if runs.len() == 1 { "" } else { "s" };
    out.say(&format!(
        "{model}: EKF on {} run{s}, {secs:.1} s, {used} sightings used",
        runs.len()
    ));
    // the library's note on where the noise came from, its first clause
    let note = done.note.split(" by the ").next().unwrap_or(&done.note);
    let note = note.split(" (").next().unwrap_or(note);
    out.say(&cut(&format!("{note} (-v: the estimate)")));
    let with_truth: Vec<&(Localization, Summary)> =
        done.runs.iter().filter(|(_, s)| s.rmse.is_some()).collect();
    if let [(_, only)] = with_truth.as_slice() {
        let (e, d) = (only.rmse.unwrap(), only.dead_reckoning.unwrap_or(f64::NAN));
        out.say(&format!(
            "answer: position RMSE {e:.4} m against the ground truth (dead reckoning: {d:.4} m)"
        ));
    } else if !with_truth.is_empty() {
        let (lo, hi) = with_truth
            .iter()
            .fold((f64::INFINITY, 0.0f64), |(lo, hi), (_, s)| {
                let e = s.rmse.unwrap();
                (lo.min(e), hi.max(e))
            });
        out.say(&format!(
            "answer: position RMSE {lo:.4}-{hi:.4} m over {} runs with a ground truth",
            with_truth.len()
        ));
    } else {
        out.say("answer: no ground truth in the logs: the track is not scored (--track writes it)");
    }
    out.say("");
    let mut t = table(&[
        "run",
        "RMSE m",
        "dead reckoning m",
        "used",
        "rejected",
        "NIS",
        "NEES",
    ]);
    for (run, (loc, sum)) in runs.iter().zip(&done.runs).take(RUNS) {
        let total = (loc.accepted + loc.rejected).max(1);
        t.add_row(vec![
            crate::report::localize::short(&run.path),
            sum.rmse.map_or("-".into(), |e| format!("{e:.4}")),
            sum.dead_reckoning.map_or("-".into(), |e| format!("{e:.4}")),
            loc.accepted.to_string(),
            format!("{:.1}%", 100.0 * loc.rejected as f64 / total as f64),
            judged(sum.nis, sum.nis_bounds),
            judged(sum.nees, sum.nees_bounds),
        ]);
    }
    for l in table_lines(&t) {
        out.say(&l);
    }
    if runs.len() > RUNS {
        out.say(&format!("  ... {} more runs (-v)", runs.len() - RUNS));
    }
    out.say("NIS, NEES: mean against the 95% bounds (low: the filter is pessimistic; high: overconfident)");
    if let Some((why, cmd)) = advice {
        out.say(&cut(&why));
        for l in command_lines(&cmd, 2) {
            out.say(&l);
        }
    }
}
