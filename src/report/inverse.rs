//! `kinegen inverse --report`: the planned path and each input's profile
//! along it (seed 001 Figs 8-10).
use super::{chart, esc, page, write, Series};
use kinegen_analysis::applications::inverse::{PlannedPath, Profile};
use plotters::prelude::*;
use serde_json::Value;
use std::path::Path;

/// `kinegen inverse --report`: the planned path, then per spec each input's
/// profile along it (seed 001 Figs 8-10), with the actuator limits as lines and
/// the stretches the robot cannot drive shaded.
pub fn inverse_report(
    dir: &Path,
    path: &PlannedPath,
    profiles: &[(String, Profile)],
    doc: &Value,
) -> Result<(), String> {
    const COLORS: [RGBColor; 6] = [BLUE, RED, GREEN, MAGENTA, CYAN, BLACK];
    let mut figs = vec![chart(
        "planned path",
        "x (m)",
        "y (m)",
        &[(
            "path",
            BLACK,
            path.pose.iter().map(|p| (p[0], p[1])).collect(),
        )],
        false,
        true,
        &[],
    )?];
    for (model, prof) in profiles {
        // one figure per unit, so counts/s and rad do not share an axis
        let mut units: Vec<&str> = prof.inputs.iter().map(|i| i.unit.as_str()).collect();
        units.dedup();
        for unit in units {
            let mut series: Vec<Series> = Vec::new();
            let mut limits: Vec<f64> = Vec::new();
            for (k, inp) in prof.inputs.iter().filter(|i| i.unit == unit).enumerate() {
                let c = COLORS[k % COLORS.len()];
                series.push((
                    inp.name.as_str(),
                    c,
                    prof.t
                        .iter()
                        .copied()
                        .zip(inp.value.iter().copied())
                        .collect(),
                ));
                if let (Some(m), kinegen_model::decl::InputKind::Cumulative) =
                    (inp.max_rate, inp.kind)
                {
                    limits.push(m);
                }
            }
            // each distinct rate limit once, as +-max_rate (one legend entry),
            // in grey: no input's colour
            limits.sort_by(f64::total_cmp);
            limits.dedup();
            let grey = RGBColor(128, 128, 128);
            for m in limits {
                let (a, b) = (prof.t[0], *prof.t.last().unwrap());
                series.push(("±max_rate", grey, vec![(a, m), (b, m)]));
                series.push(("", grey, vec![(a, -m), (b, -m)]));
            }
            let names: Vec<&str> = prof
                .inputs
                .iter()
                .filter(|i| i.unit == unit)
                .map(|i| i.name.as_str())
                .collect();
            let marks: Vec<(f64, f64)> = prof
                .infeasible
                .iter()
                .filter(|s| s.input == "path" || names.contains(&s.input.as_str()))
                .map(|s| (s.t_start, s.t_end))
                .collect();
            figs.push(chart(
                &format!("{model}: inputs in {unit}"),
                "t (s)",
                unit,
                &series,
                false,
                false,
                &marks,
            )?);
        }
    }
    let table = inverse_table(profiles);
    let html = page(
        "Inverse kinematics along a planned path",
        &[],
        &format!(
            "<p>{} (the integrated inverse kinematics). Shaded: stretches the robot cannot drive as planned.</p>",
            esc(&path.file.display().to_string())
        ),
        &figs,
        &table,
        &[],
        doc,
    );
    write(dir, &html)
}

/// The inverse report's table: each robot's inputs (peak rate, limit, the
/// stretches beyond it), and the motion it cannot make at all.
fn inverse_table(profiles: &[(String, Profile)]) -> String {
    let mut table = String::from("<table><tr><th>model</th><th>input</th><th>peak rate</th><th>max_rate</th><th>infeasible stretches</th></tr>");
    for (model, prof) in profiles {
        for inp in &prof.inputs {
            let where_: Vec<String> = prof
                .infeasible
                .iter()
                .filter(|s| s.input == inp.name)
                .map(|s| format!("{:.2}-{:.2} s", s.t_start, s.t_end))
                .collect();
            // an absolute input's rate is its unit per second (a steering
            // angle in rad changes in rad/s); a cumulative input's unit is
            // already a rate
            let rate_unit = match inp.kind {
                kinegen_model::decl::InputKind::Absolute => format!("{}/s", inp.unit),
                _ => inp.unit.clone(),
            };
            table += &format!(
                "<tr><td>{}</td><td>{}</td><td>{:.4} {}</td><td>{}</td><td>{}</td></tr>",
                esc(model),
                esc(&inp.name),
                inp.peak_rate,
                esc(&rate_unit),
                inp.max_rate
                    .map_or("-".into(), |m| format!("{m} {}", esc(&rate_unit))),
                if where_.is_empty() {
                    "none".into()
                } else {
                    where_.join(", ")
                }
            );
        }
        // motion the robot cannot make at all (sideways), shaded on every chart
        let path_stretches: Vec<String> = prof
            .infeasible
            .iter()
            .filter(|s| s.input == "path")
            .map(|s| format!("{:.2}-{:.2} s", s.t_start, s.t_end))
            .collect();
        if !path_stretches.is_empty() {
            table += &format!(
                "<tr><td>{}</td><td>path</td><td>-</td><td>-</td><td>motion it cannot make (sideways): {}</td></tr>",
                esc(model),
                path_stretches.join(", ")
            );
        }
    }
    table += "</table>";
    table
}
