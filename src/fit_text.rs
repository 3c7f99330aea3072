//! fit's default text: the answer first (how far the calibrated model is
//! off, against the nominal one), then the errors and the parameters as
//! aligned tables, within 25 lines of 100 columns. `-v` says every figure
//! (fit_cmd.rs); the JSON and the report keep them all.
use crate::output::{say_warnings_short, table, table_lines, with_std, Out};
use kinegen_analysis::estimation::fit_job::Calibrated;
use kinegen_analysis::model_on_log::load::Loaded;
use kinegen_analysis::model_on_log::metrics::Errors;

/// Parameters shown by default (the rest behind -v).
const PARAMETERS: usize = 10;

pub fn say_summary(out: &Out, prep: &Loaded, cal: &Calibrated) {
    let r = &prep.runner;
    let res = &cal.fit;
    let rows: usize = prep.runs.iter().map(|x| x.t.len()).sum();
    let s = |n: usize| if n == 1 { "" } else { "s" };
    out.say(&format!(
        "{}: {} parameter{} calibrated on {} run{}, {rows} rows ({} iterations)",
        r.ir.name,
        res.free.len(),
        s(res.free.len()),
        prep.runs.len(),
        s(prep.runs.len()),
        res.iterations
    ));
    let truth = prep.runs.iter().any(|x| x.gt.is_some());
    let (b, a) = (&cal.before, &cal.after);
    if truth {
        let held = cal
            .holdout
            .as_ref()
            .map(|h| {
                format!(
                    "; held out {:.4} -> {:.4} m",
                    h.before.errors.rmse, h.after.errors.rmse
                )
            })
            .unwrap_or_default();
        out.say(&format!(
            "answer: position RMSE {:.4} m -> {:.4} m ({:.1}x smaller){held}",
            b.errors.rmse,
            a.errors.rmse,
            b.errors.rmse / a.errors.rmse.max(1e-300)
        ));
    } else if let (Some(lb), Some(la)) = (&b.landmarks, &a.landmarks) {
        out.say(&format!(
            "answer: landmark range innovations {:.4} m -> {:.4} m (no ground truth: fitted on sightings)",
            lb.range_rmse_m, la.range_rmse_m
        ));
    }
    for u in &cal.unusable {
        out.say(&format!("FIT UNUSABLE: {u}"));
    }
    if !cal.unusable.is_empty() {
        out.say(
            "  the model cannot follow these logs: `kinegen diagnose` names what it is missing",
        );
    }
    if truth {
        out.say("");
        let mut rows: Vec<(&str, &Errors)> = vec![("before", &b.errors), ("after", &a.errors)];
        if let Some(h) = &cal.holdout {
            rows.push(("held out, before", &h.before.errors));
            rows.push(("held out, after", &h.after.errors));
        }
        for l in errors_table(&rows) {
            out.say(&l);
        }
    }
    out.say("");
    let mut t = table(&["parameter", "nominal", "estimate ± std"]);
    for (k, &i) in res.free.iter().take(PARAMETERS).enumerate() {
        t.add_row(vec![
            r.names[i].clone(),
            crate::output::number(r.p[i]),
            with_std(res.p[i], res.std[k]),
        ]);
    }
    for l in table_lines(&t) {
        out.say(&l);
    }
    if res.free.len() > PARAMETERS {
        out.say(&format!("  ... {} more (-v)", res.free.len() - PARAMETERS));
    }
    say_warnings_short(out, &cal.warnings(), 2);
    if truth {
        out.say(
            "errors from start headings the fit refines; `compare` starts from the logged one (-v)",
        );
    }
}

/// Errors before and after, one row each: position and heading RMSE, final
/// error, drift per metre, gyro residual (where measured).
pub fn errors_table(rows: &[(&str, &Errors)]) -> Vec<String> {
    let gyro = rows.iter().any(|(_, e)| e.gyro_rmse_rad_s.is_some());
    let mut header = vec![
        "",
        "position RMSE m",
        "heading RMSE rad",
        "final m",
        "drift %/m",
    ];
    if gyro {
        header.push("gyro rad/s");
    }
    let mut t = table(&header);
    for (label, e) in rows {
        let mut row = vec![
            label.to_string(),
            format!("{:.4}", e.rmse),
            format!("{:.4}", e.heading_rmse_rad),
            format!("{:.4}", e.final_position_error_m),
            e.rpe_per_m
                .map_or("-".into(), |d| format!("{:.2}", 100.0 * d)),
        ];
        if gyro {
            row.push(e.gyro_rmse_rad_s.map_or("-".into(), |g| format!("{g:.4}")));
        }
        t.add_row(row);
    }
    table_lines(&t)
}
