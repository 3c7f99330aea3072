//! `kinegen compare --report`: the model's track against the measured one,
//! its position error with the worst stretches shaded, the turn-rate
//! residual against speed, turn rate and heading, the landmark innovations,
//! and where the error grows.
use super::{chart, drawn, error_chart, esc, gt_xy, page, traj, trajectory_chart, write, Series};
use kinegen_analysis::model_on_log::comparison::Comparison;
use kinegen_analysis::model_on_log::innovations::Innovation;
use kinegen_analysis::model_on_log::metrics::{RegimeShare, Segment};
use kinegen_analysis::model_on_log::model::Runner;
use kinegen_analysis::model_on_log::run::Run;
use plotters::prelude::*;
use serde_json::Value;
use std::path::Path;

fn worst_marks(segments: &[Segment], run: &str) -> Vec<(f64, f64)> {
    segments
        .iter()
        .filter(|s| s.run == run)
        .map(|s| (s.t_start, s.t_end))
        .collect()
}

/// The compare report's table of where the error grows, by regime.
fn regime_table(regimes: &[RegimeShare]) -> String {
    let mut t = String::from("<h2>Where the error grows</h2><table><tr><th>regime</th><th>time (s)</th><th>distance (m)</th><th>position error share</th><th>heading error share</th></tr>");
    for g in regimes {
        t += &format!(
            "<tr><td>{}</td><td>{:.1}</td><td>{:.2}</td><td>{:.1}%</td><td>{:.1}%</td></tr>",
            esc(&g.regime),
            g.time_s,
            g.distance_m,
            100.0 * g.position_share,
            100.0 * g.heading_share
        );
    }
    t + "</table>"
}

/// The landmark range and bearing innovations of each run that has sightings.
fn innovation_charts(runs: &[Run], innov: &[Vec<Innovation>]) -> Result<Vec<String>, String> {
    let mut figs = Vec::new();
    for (run, inn) in runs.iter().zip(innov).filter(|(_, i)| !i.is_empty()) {
        let t0 = run.t[0];
        let range: Vec<(f64, f64)> = inn.iter().map(|i| (i.t - t0, i.range_m)).collect();
        let bearing: Vec<(f64, f64)> = inn.iter().map(|i| (i.t - t0, i.bearing_rad)).collect();
        figs.push(chart(
            &format!("{}: landmark range innovation", run.name),
            "t (s)",
            "measured - predicted (m)",
            &[("range", RGBColor(0, 90, 200), range)],
            true,
            false,
            &[],
        )?);
        figs.push(chart(
            &format!("{}: landmark bearing innovation", run.name),
            "t (s)",
            "measured - predicted (rad)",
            &[("bearing", RGBColor(200, 120, 0), bearing)],
            true,
            false,
            &[],
        )?);
    }
    Ok(figs)
}

/// The compare page, from the comparison itself; `doc` is its JSON, shown
/// on the page as it is.
pub fn compare_report(
    dir: &Path,
    r: &Runner,
    cmp: &Comparison<'_>,
    answer: &[String],
    warnings: &[String],
    doc: &Value,
) -> Result<(), String> {
    let runs = &cmp.runs;
    let mut figs = innovation_charts(runs, &cmp.innovations)?;
    for ((run, tr), g) in runs.iter().zip(&cmp.tracks).zip(&cmp.gyro_tracks) {
        let d = drawn(run, tr);
        let mut series: Vec<Series> = vec![
            ("measured", BLACK, gt_xy(run)),
            ("model (nominal)", RED, d.traj),
        ];
        if let Some(g) = g {
            series.push(("gyrodometry", RGBColor(0, 90, 200), traj(run, g)));
        }
        figs.push(trajectory_chart(run, &series)?);
        figs.push(error_chart(
            &format!("{}: position error, worst 1 s segments shaded", run.name),
            &[("model (nominal)", RED, d.pos_err)],
            &worst_marks(&cmp.segments, &run.name),
        )?);
        let [a, b, c] = d.scatter;
        figs.push(chart(
            "turn-rate residual vs speed",
            "speed (m/s)",
            "model - measured yaw rate (rad/s)",
            &[("residual", BLUE, a)],
            true,
            false,
            &[],
        )?);
        figs.push(chart(
            "turn-rate residual vs turn rate",
            "yaw rate (rad/s)",
            "residual (rad/s)",
            &[("residual", BLUE, b)],
            true,
            false,
            &[],
        )?);
        figs.push(chart(
            "turn-rate residual vs heading",
            "heading (rad)",
            "residual (rad/s)",
            &[("residual", BLUE, c)],
            true,
            false,
            &[],
        )?);
    }
    let t = regime_table(&cmp.regimes);
    let e = &cmp.errors;
    let intro = format!(
        "<p>Model <b>{}</b> with nominal parameters against {} run(s): position RMSE <b>{:.4} m</b>, heading RMSE {:.4} rad, final error {:.4} m.</p>",
        esc(&r.ir.name),
        runs.len(),
        e.rmse,
        e.heading_rmse_rad,
        e.final_position_error_m
    );
    write(
        dir,
        &page(
            &format!("kinegen compare: {}", r.ir.name),
            answer,
            &intro,
            &figs,
            &t,
            warnings,
            doc,
        ),
    )
}
