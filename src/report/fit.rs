//! `kinegen fit --report`: the tracks and position errors before and after
//! calibration, the turn-rate residual against speed, and the parameters.
use super::{chart, drawn, error_chart, esc, gt_xy, page, trajectory_chart, write};
use kinegen_analysis::estimation::fit::FitResult;
use kinegen_analysis::estimation::fit_job::Calibrated;
use kinegen_analysis::model_on_log::model::Runner;
use kinegen_analysis::model_on_log::run::Run;
use plotters::prelude::*;
use serde_json::Value;
use std::path::Path;

/// The calibrated parameters: nominal, estimate and standard deviation.
pub fn param_table(r: &Runner, fit: &FitResult) -> String {
    let mut t = String::from("<h2>Parameters</h2><table><tr><th>parameter</th><th>nominal</th><th>estimate</th><th>std</th></tr>");
    for (k, &i) in fit.free.iter().enumerate() {
        t += &format!(
            "<tr><td>{}</td><td>{:.6}</td><td>{:.6}</td><td>{}</td></tr>",
            esc(&r.names[i]),
            r.p[i],
            fit.p[i],
            crate::output::fmt_std(fit.std.get(k).copied())
        );
    }
    t += "</table>";
    t
}

/// The fit page, from the calibration itself; `doc` is its JSON, shown on
/// the page as it is.
pub fn fit_report(
    dir: &Path,
    r: &Runner,
    runs: &[Run],
    cal: &Calibrated<'_>,
    answer: &[String],
    warnings: &[String],
    doc: &Value,
) -> Result<(), String> {
    let mut figs = Vec::new();
    for ((run, b), a) in runs.iter().zip(&cal.before.tracks).zip(&cal.after.tracks) {
        let (b, a) = (drawn(run, b), drawn(run, a));
        figs.push(trajectory_chart(
            run,
            &[
                ("measured", BLACK, gt_xy(run)),
                ("before calibration", RED, b.traj),
                ("after calibration", GREEN, a.traj),
            ],
        )?);
        figs.push(error_chart(
            &format!("{}: position error", run.name),
            &[("before", RED, b.pos_err), ("after", GREEN, a.pos_err)],
            &[],
        )?);
        let [sb, _, _] = b.scatter;
        let [sa, _, _] = a.scatter;
        figs.push(chart(
            "turn-rate residual vs speed",
            "speed (m/s)",
            "residual (rad/s)",
            &[("before", RED, sb), ("after", GREEN, sa)],
            true,
            false,
            &[],
        )?);
    }
    let intro = format!(
        "<p>Model <b>{}</b> calibrated on {} run(s): position RMSE <b>{:.4} m</b> before, <b>{:.4} m</b> after.</p>",
        esc(&r.ir.name),
        runs.len(),
        cal.before.errors.rmse,
        cal.after.errors.rmse
    );
    write(
        dir,
        &page(
            &format!("kinegen fit: {}", r.ir.name),
            answer,
            &intro,
            &figs,
            &param_table(r, &cal.fit),
            warnings,
            doc,
        ),
    )
}
