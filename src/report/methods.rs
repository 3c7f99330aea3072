//! `kinegen fit --method all` (or one seed method) `--report`: each method's
//! track and error against the nominal model, and their estimates compared.
use super::{drawn, error_chart, esc, gt_xy, page, trajectory_chart, write, Series};
use kinegen_analysis::estimation::fit_job::MethodsOutcome;
use kinegen_analysis::model_on_log::model::Runner;
use kinegen_analysis::model_on_log::run::Run;
use plotters::prelude::*;
use serde_json::Value;
use std::path::Path;

/// Colours for the calibration methods, in the order they are listed.
const METHOD_COLORS: [RGBColor; 4] = [
    RGBColor(0, 150, 0),
    RGBColor(0, 90, 200),
    RGBColor(200, 120, 0),
    RGBColor(150, 0, 150),
];

/// `fit --method all` (or one seed method): every method's trajectory and error
/// against the nominal model, and a table comparing their errors, their distance
/// to known true values and their estimates side by side.
pub fn methods_report(
    dir: &Path,
    r: &Runner,
    runs: &[Run],
    compared: &MethodsOutcome<'_>,
    truth: &[(String, f64)],
    warnings: &[String],
    doc: &Value,
) -> Result<(), String> {
    let mut figs = Vec::new();
    for (k, run) in runs.iter().enumerate() {
        let nominal_drawn = drawn(run, &compared.before.tracks[k]);
        let mut traj_series: Vec<Series> = vec![
            ("measured", BLACK, gt_xy(run)),
            ("nominal", RED, nominal_drawn.traj),
        ];
        let mut err_series: Vec<Series> = vec![("nominal", RED, nominal_drawn.pos_err)];
        for (m, row) in compared.rows.iter().enumerate() {
            let color = METHOD_COLORS[m % METHOD_COLORS.len()];
            let d = drawn(run, &row.after.tracks[k]);
            traj_series.push((row.name.as_str(), color, d.traj));
            err_series.push((row.name.as_str(), color, d.pos_err));
        }
        figs.push(trajectory_chart(run, &traj_series)?);
        figs.push(error_chart(
            &format!("{}: position error", run.name),
            &err_series,
            &[],
        )?);
    }
    let t = methods_table(r, compared, truth);
    let intro = format!(
        "<p>Model <b>{}</b>, {} run(s): {} calibration method(s) from the same nominal parameters (position RMSE {:.4} m).</p>",
        esc(&r.ir.name),
        runs.len(),
        compared.rows.len(),
        compared.before.errors.rmse
    );
    write(
        dir,
        &page(
            &format!("kinegen fit: methods compared on {}", r.ir.name),
            &[],
            &intro,
            &figs,
            &t,
            warnings,
            doc,
        ),
    )
}

/// The methods' errors, distances to the truth and notes, then their
/// estimates side by side (with the truth where it is known).
fn methods_table(r: &Runner, compared: &MethodsOutcome<'_>, truth: &[(String, f64)]) -> String {
    let num = |v: Option<f64>, digits: usize| {
        v.filter(|x| x.is_finite())
            .map(|x| format!("{x:.digits$}"))
            .unwrap_or_else(|| "-".into())
    };
    let mut t = String::from("<h2>Methods</h2><table><tr><th>method</th><th>position RMSE (m)</th><th>held-out RMSE (m)</th><th>distance to truth left</th><th>notes</th></tr>");
    for m in &compared.rows {
        t += &format!(
            "<tr><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td style=\"text-align:left;white-space:pre-wrap\">{}</td></tr>",
            esc(&m.name),
            num(Some(m.after.errors.rmse), 4),
            num(m.holdout.as_ref().map(|h| h.rmse), 4),
            m.distance_to_truth.map(|d| format!("{:.1}%", 100.0 * d)).unwrap_or_else(|| "-".into()),
            esc(&m.note)
        );
    }
    t += "</table>";
    if let Some((_, best)) = &compared.closest {
        t += &format!(
            "<p>Closest to the true parameters: <b>{}</b>.</p>",
            esc(best)
        );
    }
    t += "<h2>Estimates</h2><table><tr><th>parameter</th><th>nominal</th>";
    if !truth.is_empty() {
        t += "<th>truth</th>";
    }
    for m in &compared.rows {
        t += &format!("<th>{}</th>", esc(&m.name));
    }
    t += "</tr>";
    for (k, &i) in r.free.iter().enumerate() {
        let pname = &r.names[i];
        t += &format!("<tr><td>{}</td><td>{:.6}</td>", esc(pname), r.p[i]);
        if !truth.is_empty() {
            let v = truth.iter().find(|(n, _)| n == pname).map(|(_, v)| *v);
            t += &format!("<td>{}</td>", num(v, 6));
        }
        for m in &compared.rows {
            let c = &m.calibration;
            t += &format!(
                "<td>{} &plusmn; {}</td>",
                num(c.p.get(i).copied(), 6),
                crate::output::fmt_std(c.std.get(k).copied())
            );
        }
        t += "</tr>";
    }
    t + "</table>"
}
