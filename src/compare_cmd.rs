//! `kinegen compare`: the model with its current parameters against the
//! logs (one call to kinegen_analysis::model_on_log::comparison::compare_files), rendered as
//! text, JSON and a report.
use crate::analysis_cmd::{
    bad, fmt_errors, fmt_landmarks, fmt_landmarks_from_truth, quiet, read_progress, say_warnings,
    Common,
};
use crate::output::Out;
use kinegen_analysis::model_on_log::comparison::{self, Compared};
use kinegen_analysis::model_on_log::files::Files;

use std::process::ExitCode;

pub fn compare(c: Common) -> ExitCode {
    let out = Out::new(c.json.as_deref());
    if let Err(e) = crate::output::check_outputs(c.json.as_deref(), c.report.as_deref()) {
        return bad(e);
    }
    if let Err(e) = c.check_repeated_logs() {
        return bad(e);
    }
    let files = Files {
        sources: &c.sources(),
        effect_dirs: &c.catalogue.effects,
    };
    let progress = read_progress(quiet(&c));
    match comparison::compare_files(
        &files,
        crate::ir_source::analysis_deriver(),
        &progress,
        |done| render(&c, &out, done),
    ) {
        Ok(code) => code,
        Err(e) => bad(e.to_string()),
    }
}

/// The comparison said as text, written as JSON and as a report.
fn render(c: &Common, out: &Out, done: Compared) -> ExitCode {
    // the document the library builds (the Python package writes the same)
    let doc = serde_json::to_value(done.document()).expect("the comparison serialises");
    let Compared {
        runner: r,
        warnings,
        comparison: cmp,
    } = done;
    let secs: f64 = cmp.runs.iter().map(|r| r.t.last().unwrap() - r.t[0]).sum();
    let which = if c.set.is_empty() {
        "nominal parameters".to_string()
    } else {
        format!("nominal parameters with --set {}", c.set.join(" --set "))
    };
    let header = format!(
        "{} against {} run(s), {:.1} s of data, {which}",
        r.ir.name,
        cmp.runs.len(),
        secs
    );
    // the answer: said by default, and the report's first box
    let kept = Out::keeping();
    crate::compare_text::say_summary(&kept, &header, &cmp, warnings);
    let answer = kept.lines();
    if !c.verbose {
        answer.iter().for_each(|l| out.say(l));
    }
    // the detail: said with -v, in the JSON either way
    let detail = &out.detail(c.verbose);
    let out_all = out;
    let out = detail;
    out.say(&header);
    say_warnings(out, warnings);
    if cmp.has_ground_truth() {
        out.say(&format!("  {}", fmt_errors(&cmp.errors)));
    } else {
        out.say(&format!(
            "  no ground truth ({}) in the logs: no trajectory error",
            r.ir.pose_columns().join(", ")
        ));
    }
    if let Some(s) = &cmp.landmarks {
        out.say(&format!("  {}", fmt_landmarks(s)));
    }
    if let Some(s) = &cmp.landmarks_from_truth {
        out.say(&format!("  {}", fmt_landmarks_from_truth(s)));
    }
    say_where_it_fails(out, &cmp.regimes, &cmp.segments);
    if let Some((n, g)) = &cmp.gyrodometry {
        out.say(&format!(
            "gyrodometry (heading from the gyro), {} run(s):\n  position RMSE {:.4} m, heading RMSE {:.4} rad; final error {:.4} m / {:.4} rad",
            n,
            g.rmse,
            g.heading_rmse_rad,
            g.final_position_error_m,
            g.final_heading_error_rad
        ));
    }
    if let Some(dir) = &c.report {
        if let Err(e) =
            crate::report::compare::compare_report(dir, r, &cmp, &answer, warnings, &doc)
        {
            return bad(e);
        }
        out_all.say(&format!("report: {}", dir.join("index.html").display()));
    }
    out_all.finish(c.json.as_deref(), &doc)
}

/// Where the error grows: each driving regime's share of the error growth,
/// and the worst 1 s segments.
fn say_where_it_fails(
    out: &Out,
    regimes: &[kinegen_analysis::model_on_log::metrics::RegimeShare],
    segments: &[kinegen_analysis::model_on_log::metrics::Segment],
) {
    if !regimes.is_empty() {
        out.say("where the error grows (share of position / heading error growth):");
        for g in regimes {
            out.say(&format!(
                "  {:<14} {:>7.1} s {:>7.2} m   {:>5.1}% / {:>5.1}%",
                g.regime,
                g.time_s,
                g.distance_m,
                100.0 * g.position_share,
                100.0 * g.heading_share
            ));
        }
        out.say("worst 1 s segments:");
        for s in segments {
            out.say(&format!(
                "  {} {:.1}-{:.1} s ({}): position error +{:.4} m, heading error {:+.4} rad",
                s.run,
                s.t_start,
                s.t_end,
                s.regime,
                s.position_error_growth_m,
                s.heading_error_growth_rad
            ));
        }
    }
}
