//! compare's default text: the answer first (how far the model is off, and
//! where the error grows most), then the errors, the driving regimes and
//! the worst seconds as aligned tables, within 25 lines of 100 columns.
//! `-v` says every figure (compare_cmd.rs); the JSON and the report keep them.
use crate::fit_text::errors_table;
use crate::output::{say_warnings_short, table, table_lines, Out};
use kinegen_analysis::model_on_log::comparison::Comparison;
use kinegen_analysis::model_on_log::innovations::InnovationStats;
use kinegen_analysis::model_on_log::metrics::Errors;

/// The worst 1 s segments shown by default.
const SEGMENTS: usize = 3;

pub fn say_summary(out: &Out, header: &str, cmp: &Comparison, warnings: &[String]) {
    out.say(header);
    say_warnings_short(out, warnings, 2);
    let e = &cmp.errors;
    if cmp.has_ground_truth() {
        let drift = e
            .rpe_per_m
            .map(|d| format!(", drift {:.2}% of distance", 100.0 * d))
            .unwrap_or_default();
        out.say(&format!(
            "answer: position RMSE {:.4} m, final error {:.4} m{drift}",
            e.rmse, e.final_position_error_m
        ));
        if let Some(worst) = cmp
            .regimes
            .iter()
            .max_by(|a, b| a.position_share.total_cmp(&b.position_share))
        {
            out.say(&format!(
                "  the error grows most in `{}`: {:.0}% of its growth in {:.0}% of the time",
                worst.regime,
                100.0 * worst.position_share,
                100.0 * worst.time_s
                    / cmp
                        .regimes
                        .iter()
                        .map(|g| g.time_s)
                        .sum::<f64>()
                        .max(1e-300)
            ));
        }
        out.say("");
        // gyrodometry's heading is the gyro's: its gyro residual says nothing
        let gyro = cmp.gyrodometry.as_ref().map(|(_, g)| Errors {
            gyro_rmse_rad_s: None,
            ..g.clone()
        });
        let mut rows: Vec<(&str, &Errors)> = vec![("dead reckoning", e)];
        if let Some(g) = &gyro {
            rows.push(("gyrodometry", g));
        }
        for l in errors_table(&rows) {
            out.say(&l);
        }
    } else {
        out.say("answer: no ground truth in the logs: no trajectory error (sightings below)");
    }
    say_sightings(out, cmp);
    say_regimes(out, cmp);
}

/// The landmark innovations along the dead-reckoned track and, with a
/// ground truth, seen from it (the sensor's own error).
fn say_sightings(out: &Out, cmp: &Comparison) {
    let rows: Vec<(&str, &InnovationStats)> = [
        ("along the track", cmp.landmarks.as_ref()),
        ("seen from truth", cmp.landmarks_from_truth.as_ref()),
    ]
    .into_iter()
    .filter_map(|(l, s)| s.map(|s| (l, s)))
    .collect();
    if rows.is_empty() {
        return;
    }
    out.say("");
    let mut t = table(&[
        "sightings",
        "count",
        "range RMSE m",
        "range robust sd m",
        "bearing RMSE rad",
        "bearing robust sd rad",
    ]);
    for (label, s) in rows {
        t.add_row(vec![
            label.to_string(),
            s.observations.to_string(),
            format!("{:.4}", s.range_rmse_m),
            format!("{:.4}", s.range_robust_sd_m),
            format!("{:.4}", s.bearing_rmse_rad),
            format!("{:.4}", s.bearing_robust_sd_rad),
        ]);
    }
    for l in table_lines(&t) {
        out.say(&l);
    }
}

/// Each driving regime's share of the error's growth, and the worst seconds.
fn say_regimes(out: &Out, cmp: &Comparison) {
    if cmp.regimes.is_empty() {
        return;
    }
    out.say("");
    let mut t = table(&[
        "regime",
        "time s",
        "distance m",
        "position growth",
        "heading growth",
    ]);
    for g in cmp.regimes.iter().filter(|g| g.time_s > 0.0) {
        t.add_row(vec![
            g.regime.clone(),
            format!("{:.1}", g.time_s),
            format!("{:.2}", g.distance_m),
            format!("{:.1}%", 100.0 * g.position_share),
            format!("{:.1}%", 100.0 * g.heading_share),
        ]);
    }
    for l in table_lines(&t) {
        out.say(&l);
    }
    if cmp.segments.is_empty() {
        return;
    }
    let worst: Vec<String> = cmp
        .segments
        .iter()
        .take(SEGMENTS)
        .map(|s| {
            format!(
                "{:.1}-{:.1} s (+{:.3} m)",
                s.t_start, s.t_end, s.position_error_growth_m
            )
        })
        .collect();
    let run = &cmp.segments[0].run;
    let line = format!("worst 1 s of {run}: {}", worst.join(", "));
    out.say(&if line.chars().count() > crate::output::WIDTH {
        format!("worst 1 s: {}", worst.join(", "))
    } else {
        line
    });
}
