//! `kinegen navigate`: seed 004's cellular-automaton navigation driven on
//! odometry (one call to kinegen_analysis::applications::mission::navigate_files), before and after calibrating the
//! odometry with UMBMark (or LM) squares run in simulation on the same robot.
use crate::analysis_cmd::bad;
use crate::output::Out;
use clap::Args;
use kinegen_analysis::applications::mission::{
    navigate_files, CalibratedDrive, Mission, Navigated,
};
use kinegen_analysis::applications::navigate::{Drive, NavOptions};
use serde_json::json;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Args, Debug)]
pub struct NavigateArgs {
    /// The robot's spec (a differential drive that turns in place; the bundled
    /// e-puck is data/seed004/epuck.toml in the checkout).
    #[arg(long)]
    pub spec: PathBuf,
    /// The grid: rows of `.` free, `#` obstacle, `S` start, `G` goal.
    #[arg(long)]
    pub grid: PathBuf,
    /// Cell side, m (7 cm: the e-puck's diameter).
    #[arg(long, default_value_t = 0.07, value_parser = crate::analysis_cmd::positive)]
    pub cell: f64,
    /// Re-plan from the odometry pose every N moves (default: planned once).
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..))]
    pub recalc: Option<u32>,
    /// The real robot's true parameter NAME=VALUE (hidden geometry errors the
    /// odometry does not know); repeatable.
    #[arg(long = "set")]
    pub set: Vec<String>,
    /// Also drive after calibrating the odometry on simulated square runs of
    /// the real robot with this `fit` method: umbmark (Borenstein's square), lm...
    #[arg(long, value_parser = geometry_methods())]
    pub calibrate: Option<String>,
    /// Motors' relative error per move (what the encoders see and an open-loop
    /// plan does not correct).
    #[arg(long, default_value_t = 0.01, value_parser = crate::analysis_cmd::non_negative)]
    pub actuation: f64,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Write a self-contained HTML report to DIR/index.html.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Write one JSON document to PATH (`-`: stdout).
    #[arg(long)]
    pub json: Option<PathBuf>,
}

/// The calibration methods that calibrate the parameters (not the ones
/// that learn a virtual gyro), from the registry.
fn geometry_methods() -> clap::builder::PossibleValuesParser {
    use kinegen_analysis::estimation::methods::METHODS;
    clap::builder::PossibleValuesParser::new(
        METHODS
            .iter()
            .filter(|m| m.calibrates_parameters())
            .map(|m| clap::builder::PossibleValue::new(m.name()).help(m.about())),
    )
}

/// The drives' table (the shape of every command's default table): per
/// odometry, moves, collisions, safety-zone intrusions, distance to the
/// goal, and whether it believed it reached the goal.
fn drives_table(drives: &[(&str, &Drive)]) -> Vec<String> {
    let mut t = crate::output::table(&[
        "odometry",
        "moves",
        "collisions",
        "safety zone",
        "goal cm",
        "reached",
    ]);
    for (odometry, d) in drives {
        t.add_row(vec![
            odometry.to_string(),
            d.moves.to_string(),
            d.collisions.to_string(),
            d.safety_intrusions.to_string(),
            format!("{:.1}", 100.0 * d.final_error_m),
            if d.reached {
                "yes"
            } else {
                "never believed it"
            }
            .to_string(),
        ]);
    }
    crate::output::table_lines(&t)
}

/// The answer: how the last drive ended, against the nominal one.
fn answer(before: &Drive, calibrated: Option<(&str, &Drive)>) -> String {
    let ended = |d: &Drive| {
        format!(
            "{} collision(s), {:.1} cm from the goal",
            d.collisions,
            100.0 * d.final_error_m
        )
    };
    match calibrated {
        None => format!("answer: with the nominal parameters, {}", ended(before)),
        Some((m, d)) => format!(
            "answer: calibrated by {m}, {} (nominal: {} collisions, {:.1} cm)",
            ended(d),
            before.collisions,
            100.0 * before.final_error_m
        ),
    }
}

pub fn run(a: &NavigateArgs) -> ExitCode {
    if let Err(e) = crate::output::check_outputs(a.json.as_deref(), a.report.as_deref()) {
        return bad(e);
    }
    let out = Out::new(a.json.as_deref());
    let mission = Mission {
        spec: &a.spec,
        grid: &a.grid,
        cell: a.cell,
        sets: &a.set,
        options: NavOptions {
            recalc: a.recalc.map(|n| n as usize),
            actuation: a.actuation,
            seed: a.seed,
            ..NavOptions::default()
        },
        // the registry's method, parsed once here (clap already limits the names)
        calibrate: a
            .calibrate
            .as_deref()
            .and_then(kinegen_analysis::estimation::methods::by_name),
    };
    let done = match navigate_files(&mission, crate::ir_source::symbolic_deriver()) {
        Ok(d) => d,
        Err(e) => return bad(e),
    };
    let Navigated {
        grid,
        belief,
        truth,
        before,
        calibrated,
    } = &done;
    let how = match a.recalc {
        Some(n) => format!("recalculated every {n} move(s) from the odometry pose"),
        None => "planned once".into(),
    };
    let (rows, cols) = grid.size();
    out.say(&format!(
        "{}: {rows} x {cols} cells of {} m, path {how}",
        a.grid.display(),
        if (1e-3..1e3).contains(&a.cell) {
            a.cell.to_string()
        } else {
            format!("{:e}", a.cell)
        }
    ));
    out.say(&answer(
        before,
        calibrated.as_ref().map(|c| (c.method.as_str(), &c.drive)),
    ));
    out.say("");
    let mut drives = vec![("nominal", before)];
    drives.extend(calibrated.iter().map(|c| (c.method.as_str(), &c.drive)));
    for l in drives_table(&drives) {
        out.say(&l);
    }
    let mut calibration = None;
    if let Some(CalibratedDrive {
        method: m,
        note,
        odometry: cal,
        drive: _,
    }) = calibrated
    {
        out.say("");
        out.say(&format!("  {m}: {note}"));
        let mut t = crate::output::table(&["parameter", "calibrated", "true"]);
        let params: serde_json::Map<String, serde_json::Value> = cal
            .free
            .iter()
            .map(|&i| {
                (
                    cal.names[i].clone(),
                    json!({"nominal": belief.p[i], "estimate": cal.p[i], "true": truth.p[i]}),
                )
            })
            .collect();
        // by name, as the JSON lists them
        let mut shown = cal.free.clone();
        shown.sort_by(|a, b| cal.names[*a].cmp(&cal.names[*b]));
        for i in shown {
            t.add_row(vec![
                cal.names[i].clone(),
                format!("{:.6}", cal.p[i]),
                format!("{:.6}", truth.p[i]),
            ]);
        }
        for l in crate::output::table_lines(&t) {
            out.say(&l);
        }
        calibration = Some(json!({"method": m, "note": note, "parameters": params}));
    }
    let after = calibrated.as_ref().map(|c| &c.drive);
    let doc = json!({
        "command": "navigate",
        "grid": a.grid.display().to_string(),
        "recalc": a.recalc,
        "uncalibrated": before,
        "calibrated": after,
        "calibration": calibration,
    });
    if let Some(dir) = &a.report {
        let mut drives = vec![("nominal odometry", before)];
        if let Some(d) = after {
            drives.push(("calibrated odometry", d));
        }
        if let Err(e) = crate::report::navigate::navigate_report(dir, grid, &drives, &doc) {
            return bad(e);
        }
        out.say(&format!("report: {}", dir.join("index.html").display()));
    }
    match out.json(a.json.as_deref(), &doc) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => bad(e),
    }
}
