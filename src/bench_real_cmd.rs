//! `kinegen bench-real`: calibration judged on real runs it was not fitted
//! on (issue 35), on sessions in the OptiOdom layout. The library reads the
//! sessions and scores every method (`kinegen_analysis::applications::holdout_bench`);
//! this renders the answer and a short table (the whole markdown table, as
//! the guide shows it, with `-v`) and the JSON.
use crate::analysis_cmd::bad;
use crate::output::Out;
use clap::Args;
use kinegen_analysis::applications::holdout_bench::{
    self, optiodom, Measure, SessionResult, HELD_OUT_FINAL, HELD_OUT_RMSE, IN_SAMPLE_FINAL,
    KINEGEN, NOMINAL,
};
use kinegen_analysis::estimation::fit::{FitOptions, Likelihood};
use serde_json::json;
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

#[derive(Args, Debug)]
pub struct BenchRealArgs {
    /// Folder of sessions in the OptiOdom layout (one folder per session with
    /// run-NN.csv and metadata.json; published.json beside them).
    #[arg(default_value = "../shared/real/optiodom-dev")]
    pub dir: PathBuf,
    /// The benchmark file: per robot type, its spec and the mapping of the
    /// study's parameter names. Default: spec/benchmarks/optiodom/benchmark.toml
    /// under the working directory, or the copy built into kinegen elsewhere.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Only the sessions whose folder name starts with this (repeatable); they
    /// are then scored on each other only.
    #[arg(long)]
    pub session: Vec<String>,
    /// Split a log where rows are more than this many seconds apart.
    #[arg(long, value_name = "SECONDS", default_value_t = kinegen_analysis::model_on_log::run::DEFAULT_MAX_GAP_S, value_parser = crate::analysis_cmd::positive)]
    pub max_gap: f64,
    /// Calibrate on each run alone, scored on the robot's other sessions:
    /// what a single run can tell (the published methods, calibrated on
    /// whole sessions, are left out).
    #[arg(long)]
    pub each_run: bool,
    /// What kinegen's calibration compares (as `fit --likelihood`).
    #[arg(long, default_value = "track", value_parser = Likelihood::NAMES)]
    pub likelihood: String,
    /// Write one JSON document to PATH (`-`: stdout).
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// No progress display.
    #[arg(long)]
    pub quiet: bool,
    /// Also print every session's figures (the guide's markdown table).
    #[arg(short, long)]
    pub verbose: bool,
}

pub fn run(a: &BenchRealArgs) -> ExitCode {
    let out = Out::new(a.json.as_deref());
    if let Err(e) = crate::output::check_outputs(a.json.as_deref(), None) {
        return bad(e);
    }
    if a.max_gap.is_nan() || a.max_gap <= 0.0 {
        return bad(format!(
            "--max-gap {}: must be a positive number of seconds",
            a.max_gap
        ));
    }
    let config = match &a.config {
        Some(c) if !c.is_file() => {
            return bad(format!("--config {}: no such file", c.display()));
        }
        Some(c) => c.clone(),
        None => match default_config() {
            Ok(c) => c,
            Err(e) => return bad(e),
        },
    };
    let loaded = match optiodom::load(
        &a.dir,
        &config,
        &a.session,
        a.max_gap,
        crate::ir_source::analysis_deriver(),
    ) {
        Ok(l) => l,
        Err(e) => return bad(e),
    };
    for w in &loaded.warnings {
        out.say(&format!("warning: {w}"));
    }
    let started = Instant::now();
    let spin = crate::progress::Progress::spinner(
        "calibrating",
        a.quiet || a.json.as_deref() == Some(std::path::Path::new("-")),
    );
    let options = Likelihood::parse(&a.likelihood)
        .expect("clap checked the name")
        .apply(FitOptions {
            multi_start: true,
            ..FitOptions::default()
        });
    let sessions = if a.each_run {
        holdout_bench::each_run_alone(loaded.sessions)
    } else {
        loaded.sessions
    };
    let results = holdout_bench::benchmark(&sessions, &options, &|s| spin.message(s));
    drop(spin);
    let seconds = started.elapsed().as_secs_f64();
    for line in answer(&results, seconds, a.each_run) {
        out.say(&line);
    }
    if a.verbose {
        out.say("");
        for line in table(&results) {
            out.say(&line);
        }
    } else {
        for line in losses(&results) {
            out.say(&line);
        }
    }
    let doc = json!({
        "dir": a.dir.display().to_string(),
        "sessions": results,
        "summary": summary(&results),
        "worse_than_nominal": {
            "held_out_final": holdout_bench::worse_than_nominal(&results, HELD_OUT_FINAL),
            "held_out_rmse": holdout_bench::worse_than_nominal(&results, HELD_OUT_RMSE),
        },
        "seconds": started.elapsed().as_secs_f64(),
    });
    match out.json(a.json.as_deref(), &doc) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => bad(e),
    }
}

/// The three measures, as the table names them.
const MEASURES: [(&str, Measure); 3] = [
    ("held-out final", HELD_OUT_FINAL),
    ("held-out RMSE", HELD_OUT_RMSE),
    ("in-sample worst final", IN_SAMPLE_FINAL),
];

/// The per-session table in markdown: for each measure kinegen's figure, the
/// best published method's (and which), the nominal values', and whether
/// kinegen is at or below the best published.
fn table(results: &[SessionResult]) -> Vec<String> {
    let mut lines = vec![
        "| session | runs | fit s | held-out final (m): kinegen / best published / nominal | held-out RMSE (m): kinegen / best published / nominal | in-sample worst final (m): kinegen / best published / nominal |".to_string(),
        "|---|---|---|---|---|---|".to_string(),
    ];
    for s in results {
        let mut cells = vec![
            s.session.clone(),
            s.runs.to_string(),
            format!("{:.1}", s.fit_seconds),
        ];
        for (k, (_, m)) in MEASURES.iter().enumerate() {
            cells.push(cell(s, *m, (k < 2).then_some(k)));
        }
        lines.push(format!("| {} |", cells.join(" | ")));
    }
    lines
}

fn cell(s: &SessionResult, m: Measure, k: Option<usize>) -> String {
    let fmt = |v: Option<f64>| v.map_or("-".into(), |v| format!("{v:.3}"));
    let ours = s.score_of(KINEGEN).and_then(m);
    let nominal = s.score_of(NOMINAL).and_then(m);
    let best = s.best_published(m);
    let mark = match s.kinegen_wins(m) {
        Some(true) => "**",
        _ => "",
    };
    let best = best.map_or("-".into(), |(name, v)| format!("{v:.3} ({})", short(name)));
    // run by run against that method: where kinegen is lower, and whether the
    // split is beyond the runs' scatter (sign test at 5%)
    let paired = k.and_then(|k| s.paired(m, k)).map_or(String::new(), |p| {
        let sig = if p.p_value < 0.05 { ", p < 0.05" } else { "" };
        format!(" [{}/{}{sig}]", p.lower, p.differ)
    });
    format!(
        "{mark}{}{mark}{paired} / {best} / {}",
        fmt(ours),
        fmt(nominal)
    )
}

/// A published method's name without its robot prefix (`diff-UMBmark` -> `UMBmark`).
fn short(method: &str) -> &str {
    method.split_once('-').map_or(method, |x| x.1)
}

/// Per robot and measure: sessions where kinegen is at or below the best
/// published method, out of those with one to compare.
fn summary(results: &[SessionResult]) -> serde_json::Value {
    let mut robots: BTreeMap<&str, serde_json::Map<String, serde_json::Value>> = BTreeMap::new();
    for (name, m) in MEASURES {
        for (robot, (wins, of)) in wins(results, m) {
            robots
                .entry(robot)
                .or_default()
                .insert(name.into(), json!({"kinegen_best": wins, "sessions": of}));
        }
    }
    json!(robots)
}

fn wins(results: &[SessionResult], m: Measure) -> BTreeMap<&str, (usize, usize)> {
    let mut out: BTreeMap<&str, (usize, usize)> = BTreeMap::new();
    for s in results {
        if let Some(w) = s.kinegen_wins(m) {
            let e = out.entry(s.robot.as_str()).or_default();
            e.0 += usize::from(w);
            e.1 += 1;
        }
    }
    out
}

/// The answer: how many sessions, and per robot type and measure, where
/// kinegen is at or below the best published method.
fn answer(results: &[SessionResult], seconds: f64, each_run: bool) -> Vec<String> {
    let mut robots: BTreeMap<&str, usize> = BTreeMap::new();
    for s in results {
        *robots.entry(s.robot.as_str()).or_default() += 1;
    }
    let kinds: Vec<String> = robots.iter().map(|(r, n)| format!("{r} {n}")).collect();
    let (mut won, mut of) = (0, 0);
    for (_, m) in MEASURES {
        for (w, n) in wins(results, m).into_values() {
            won += w;
            of += n;
        }
    }
    let mut lines = vec![crate::output::cut(&format!(
        "bench-real ({seconds:.0} s): {} {} ({}) scored on other sessions' runs",
        results.len(),
        if each_run {
            "runs calibrated alone"
        } else {
            "sessions"
        },
        kinds.join(", ")
    ))];
    if of > 0 {
        lines.push(format!("answer: kinegen at or below the best published method in {won} of {of} session x measure pairs"));
    }
    let worse = holdout_bench::worse_than_nominal(results, HELD_OUT_RMSE);
    lines.push(format!(
        "worse than nominal on held-out runs (RMSE, >10%): {} of {}, {} of them unwarned",
        worse.worse, worse.of, worse.unwarned
    ));
    lines.push(String::new());
    if of == 0 {
        return lines;
    }
    let mut t = crate::output::table(&[
        "robot",
        "held-out final",
        "held-out RMSE",
        "in-sample worst final",
    ]);
    for robot in robots.keys() {
        let mut row = vec![robot.to_string()];
        for (_, m) in MEASURES {
            let (w, n) = wins(results, m).get(robot).copied().unwrap_or((0, 0));
            row.push(format!("{w} of {n}"));
        }
        t.add_row(row);
    }
    lines.extend(crate::output::table_lines(&t));
    lines
}

/// Rows shown by default where kinegen is above the best published method.
const LOSSES_SHOWN: usize = 8;

/// Where kinegen is above the best published method: session, measure and
/// both figures, the first [`LOSSES_SHOWN`] of them (all with -v, in the
/// table).
fn losses(results: &[SessionResult]) -> Vec<String> {
    let mut rows = Vec::new();
    for s in results {
        for (name, m) in MEASURES {
            if s.kinegen_wins(m) == Some(false) {
                let ours = s.score_of(KINEGEN).and_then(m);
                let best = s.best_published(m);
                rows.push((s.session.clone(), name, ours, best));
            }
        }
    }
    if rows.is_empty() {
        return vec![];
    }
    let mut lines = vec![
        String::new(),
        "where kinegen is above the best published method (m):".to_string(),
    ];
    let mut t = crate::output::table(&["session", "measure", "kinegen", "best published"]);
    if let Some(c) = t.column_mut(1) {
        c.set_cell_alignment(comfy_table::CellAlignment::Left);
    }
    for (session, measure, ours, best) in rows.iter().take(LOSSES_SHOWN) {
        let best = best.map_or("-".into(), |(name, v)| format!("{v:.3} ({})", short(name)));
        t.add_row(vec![
            session.clone(),
            measure.to_string(),
            ours.map_or("-".into(), |v| format!("{v:.3}")),
            best,
        ]);
    }
    lines.extend(crate::output::table_lines(&t));
    if rows.len() > LOSSES_SHOWN {
        lines.push(format!(
            "  ({} more; every session's figures: -v)",
            rows.len() - LOSSES_SHOWN
        ));
    }
    lines
}

/// The bundled benchmark file and the specs it names, compiled in so that
/// `bench-real` runs from any directory (paths as in the checkout).
const BUNDLED: [(&str, &str); 5] = [
    (
        "spec/benchmarks/optiodom/benchmark.toml",
        include_str!("../spec/benchmarks/optiodom/benchmark.toml"),
    ),
    (
        "spec/benchmarks/optiodom/tricycle.toml",
        include_str!("../spec/benchmarks/optiodom/tricycle.toml"),
    ),
    (
        "spec/benchmarks/optiodom/omni3.toml",
        include_str!("../spec/benchmarks/optiodom/omni3.toml"),
    ),
    (
        "spec/benchmarks/optiodom/omni4.toml",
        include_str!("../spec/benchmarks/optiodom/omni4.toml"),
    ),
    (
        "spec/diff_drive.toml",
        include_str!("../spec/diff_drive.toml"),
    ),
];

/// The benchmark file under the working directory when there is one (a
/// checkout), else the bundled copy written, with its specs, to kinegen's
/// folder in the temporary directory (as the IR cache is).
fn default_config() -> Result<PathBuf, String> {
    let here = PathBuf::from(BUNDLED[0].0);
    if here.is_file() {
        return Ok(here);
    }
    let root = std::env::temp_dir().join("kinegen-bench-real");
    for (path, text) in BUNDLED {
        let to = root.join(path);
        if std::fs::read_to_string(&to).ok().as_deref() != Some(text) {
            kinegen_model::files::write_atomic(&to, text).map_err(|e| e.to_string())?;
        }
    }
    Ok(root.join(BUNDLED[0].0))
}
