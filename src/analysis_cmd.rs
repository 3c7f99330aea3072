//! `kinegen compare` and `kinegen fit`.
use crate::ir_source;
use crate::output::Out;
use clap::Args;
use kinegen_analysis::bag::{is_bag, Detection, TopicMap};
use kinegen_analysis::fit::{FitOptions, FitResult};
use kinegen_analysis::innovations::{self, Innovation, InnovationStats};
use kinegen_analysis::input_range;
use kinegen_analysis::landmarks;
use kinegen_analysis::methods::{by_name, Method, Settings, METHODS};
use kinegen_analysis::metrics::{errors, errors_each, where_it_fails, Errors};
use kinegen_analysis::model::{parse_sets, Runner};
use kinegen_analysis::run::Run;
use kinegen_analysis::track_rows::{first_non_finite, Heading, Recipe, TrackRows};
use kinegen_model::decl::ObservationRole::RangeBearing;
use serde_json::{json, Value};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

#[derive(Args, Debug, Clone)]
pub struct Common {
    /// The model spec.
    #[arg(long)]
    pub spec: PathBuf,
    /// Measurement log (CSV, CONTRACT section 2); repeat for several runs.
    #[arg(long, required = true)]
    pub data: Vec<PathBuf>,
    /// Topic mapping for ROS 2 bags given as --data (TOML: `stamps`, `[inputs]`,
    /// `[pose]`, `[gyro]`; see the README). Without it: the bag's only
    /// JointState, PoseStamped/Odometry and Imu topics, joints named as the
    /// spec's input columns.
    #[arg(long, value_name = "FILE.toml")]
    pub topics: Option<PathBuf>,
    /// Runs scored but not fitted; repeatable.
    #[arg(long)]
    pub holdout: Vec<PathBuf>,
    /// Override a parameter's nominal value: NAME=VALUE; repeatable.
    #[arg(long = "set")]
    pub set: Vec<String>,
    /// Range-bearing observations `t,id,range,bearing` (needs --landmarks); the
    /// k-th file belongs to the k-th --data log. Repeatable.
    #[arg(long)]
    pub observations: Vec<PathBuf>,
    /// Landmark map `id,x,y` for --observations.
    #[arg(long)]
    pub landmarks: Option<PathBuf>,
    /// Write a self-contained HTML report to DIR/index.html.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Write one JSON document to PATH (`-`: stdout).
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Split a log into runs only at gaps longer than this (seconds); shorter
    /// gaps are bridged: a command holds its value, a counter's difference
    /// spreads over the interval.
    #[arg(long, value_name = "SECONDS", default_value_t = kinegen_analysis::run::DEFAULT_MAX_GAP_S, value_parser = positive)]
    pub max_gap: f64,
    #[command(flatten)]
    pub catalogue: EffectDirs,
}

/// `--effects DIR`: the user's own effect catalogues (commands that use effects).
#[derive(Args, Debug, Clone, Default)]
pub struct EffectDirs {
    /// A directory of your own effect files (same format as the bundled
    /// catalogue, which is built in); repeatable. A file with a bundled effect's
    /// name replaces it.
    #[arg(long = "effects", value_name = "DIR")]
    pub effects: Vec<PathBuf>,
}

/// Progress bars stay quiet when stdout carries the JSON document.
pub fn quiet(c: &Common) -> bool {
    c.json.as_deref() == Some(std::path::Path::new("-"))
}

/// Exit 2 with a message naming the problem.
/// Say each of the warnings `prepare` found.
pub fn say_warnings(out: &Out, warnings: &[String]) {
    for w in warnings {
        out.say(&format!("warning: {w}"));
    }
}

pub fn bad(msg: impl std::fmt::Display) -> ExitCode {
    eprintln!("error: {msg}");
    ExitCode::from(2)
}

pub struct Prepared {
    pub runner: Runner,
    pub runs: Vec<Run>,
    pub holdout: Vec<Run>,
    /// Things the user should know before reading any result (inputs outside
    /// their declared range), said by every command and kept in its JSON.
    pub warnings: Vec<String>,
}

pub fn prepare(c: &Common) -> Result<Prepared, String> {
    crate::output::check_outputs(c.json.as_deref(), c.report.as_deref())?;
    // --effects is read whatever the command: a broken catalogue is said now,
    // not on the day diagnose reads it
    if !c.catalogue.effects.is_empty() {
        kinegen_analysis::effects::catalogue(&c.catalogue.effects).map_err(|e| e.to_string())?;
    }
    let ir = ir_source::load(&c.spec)?;
    let sets = parse_sets(&c.set).map_err(|e| e.to_string())?;
    let runner = Runner::new(ir, &sets).map_err(|e| e.to_string())?;
    let topics = match &c.topics {
        Some(p) => {
            let t = TopicMap::read(p).map_err(|e| e.to_string())?;
            // an [inputs] entry for a column the spec does not read would be
            // ignored: most likely a misspelt column
            let columns: Vec<&str> = runner.ir.inputs.iter().map(|i| i.column.as_str()).collect();
            if let Some(c) = t.inputs.keys().find(|k| !columns.contains(&k.as_str())) {
                return Err(format!(
                    "{}: [inputs] maps `{c}`, which is no input column of the spec (it reads: {})",
                    p.display(),
                    columns.join(", ")
                ));
            }
            t
        }
        None => TopicMap::default(),
    };
    let read = |paths: &[PathBuf]| {
        paths
            .iter()
            .map(|p| {
                let bar = is_bag(p).then(|| {
                    crate::progress::Progress::spinner(
                        &format!("reading {}", p.display()),
                        quiet(c),
                    )
                });
                let progress = |done: usize, total: usize| {
                    if let Some(b) = &bar {
                        b.message(&format!("{done}/{total} messages"));
                    }
                };
                Run::read_with(p, &runner, &topics, &progress).map_err(|e| e.to_string())
            })
            .collect::<Result<Vec<_>, _>>()
    };
    let mut warnings: Vec<String> = Vec::new();
    let (mut runs, found): (Vec<Run>, Vec<_>) = read(&c.data)?.into_iter().unzip();
    let (mut holdout, found_holdout): (Vec<Run>, Vec<_>) = read(&c.holdout)?.into_iter().unzip();
    attach_landmarks(c, &runner, &mut runs, &found, &mut holdout, &found_holdout)?;
    // a log with gaps becomes one run per piece between them
    let mut split = |set: Vec<Run>| -> Vec<Run> {
        set.into_iter()
            .flat_map(|run| {
                let (pieces, warning) = run.split_at_gaps(c.max_gap);
                warnings.extend(warning);
                pieces
            })
            .collect()
    };
    let (runs, holdout) = (split(runs), split(holdout));
    if runs.is_empty() {
        return Err("no run of 3 rows or more between the gaps of the logs (--data)".into());
    }
    // results that would be NaN or infinite are refused here, with the row
    for set in [&runs, &holdout] {
        check_finite(set, &tracks(&runner, &runner.p, set, &[]), &c.set)?;
    }
    warnings.extend(
        runs.iter()
            .chain(&holdout)
            .flat_map(|run| input_range::excursions(run, &runner.ir.inputs))
            .map(|e| e.to_string()),
    );
    Ok(Prepared {
        runner,
        runs,
        holdout,
        warnings,
    })
}

/// Read --landmarks and attach range-bearing observations to the runs: the
/// k-th --observations file to the k-th run, or the detections of a bag's
/// landmark topic (--topics `[landmarks]`) to its run.
fn attach_landmarks(
    c: &Common,
    r: &Runner,
    runs: &mut [Run],
    found: &[Vec<Detection>],
    holdout: &mut [Run],
    found_holdout: &[Vec<Detection>],
) -> Result<(), String> {
    use landmarks::{from_detections, read_map, read_observations};
    let from_bags = found.iter().chain(found_holdout).any(|d| !d.is_empty());
    match (&c.landmarks, c.observations.is_empty(), from_bags) {
        (None, true, false) => return Ok(()),
        (None, _, true) => {
            return Err("the bag's landmark topic (--topics [landmarks]) needs --landmarks MAP.csv (the landmark positions)".into())
        }
        (None, false, false) => {
            return Err("--observations needs --landmarks MAP.csv (the landmark positions)".into())
        }
        (Some(m), true, false) => {
            return Err(format!(
                "--landmarks {} given without --observations (or a bag with a [landmarks] topic in --topics)",
                m.display()
            ))
        }
        _ => {}
    }
    let map_path = c.landmarks.as_ref().unwrap();
    if r.ir
        .observation_kernels(RangeBearing)
        .map(|o| o.value)
        .is_none()
    {
        return Err(format!(
            "{}: the model has no `landmark` observation to predict range-bearing data with",
            c.spec.display()
        ));
    }
    if c.observations.len() > runs.len() {
        return Err(format!(
            "{} --observations files for {} --data logs (one per log, in order)",
            c.observations.len(),
            runs.len()
        ));
    }
    let map = read_map(map_path).map_err(|e| e.to_string())?;
    let files = c
        .observations
        .iter()
        .map(Some)
        .chain(std::iter::repeat(None));
    let all = runs.iter_mut().zip(found).zip(files).chain(
        holdout
            .iter_mut()
            .zip(found_holdout)
            .zip(std::iter::repeat(None)),
    );
    for ((run, found), file) in all {
        let (obs, source) = match (file, found.is_empty()) {
            (Some(path), false) => {
                return Err(format!(
                    "{}: the run has landmark observations from its bag's topic `{}` and from --observations {}: give one",
                    run.path,
                    found[0].topic,
                    path.display()
                ))
            }
            (Some(path), true) => (
                read_observations(path, &map, map_path),
                path.display().to_string(),
            ),
            (None, false) => (
                from_detections(Path::new(&run.path), found, &map, map_path),
                format!("{} (topic `{}`)", run.path, found[0].topic),
            ),
            (None, true) => continue,
        };
        let obs = obs.map_err(|e| e.to_string())?;
        let (t0, t1) = (run.t[0], *run.t.last().unwrap());
        let inside: Vec<_> = obs.into_iter().filter(|o| o.t >= t0 && o.t <= t1).collect();
        if inside.is_empty() {
            return Err(format!(
                "{source}: no observation falls inside the log's time span {t0:.3}-{t1:.3} s"
            ));
        }
        run.landmarks = inside;
    }
    Ok(())
}

/// Dead-reckoned tracks of every run with parameters `p`, each from its
/// measured start plus its offset in `offsets` (none: the measured start):
/// described, and computed each time they are read (a long log's tracks are
/// never held, see `kinegen_analysis::track_rows`).
fn tracks<'r>(r: &'r Runner, p: &[f64], runs: &[Run], offsets: &[[f64; 3]]) -> Vec<Recipe<'r>> {
    (0..runs.len())
        .map(|i| Recipe {
            r,
            p: p.to_vec(),
            offset: offsets.get(i).copied().unwrap_or([0.0; 3]),
            heading: Heading::Model,
        })
        .collect()
}

/// Each run with its track, as the metrics read them.
fn pairs<'a>(runs: &'a [Run], tracks: &'a [Recipe<'_>]) -> Vec<(&'a Run, &'a dyn TrackRows)> {
    runs.iter()
        .zip(tracks)
        .map(|(run, t)| (run, t as &dyn TrackRows))
        .collect()
}

/// Parameters `p` on `runs`: the dead-reckoned tracks, the errors they make and
/// the landmark innovations.
pub struct Evaluation<'r> {
    pub tracks: Vec<Recipe<'r>>,
    /// Error summary; on logs without ground truth but with landmarks, `rmse` is
    /// the landmark range innovation RMSE.
    pub errors: Errors,
    /// Each run's own error summary.
    pub per_run: Vec<Errors>,
    pub landmarks: Option<InnovationStats>,
}

pub fn evaluation<'r>(r: &'r Runner, p: &[f64], runs: &[Run]) -> Evaluation<'r> {
    evaluation_from(r, p, runs, &[])
}

/// [`evaluation`] with each run started at its measured start plus its offset
/// in `offsets` (the start headings a fit refined).
pub fn evaluation_from<'r>(
    r: &'r Runner,
    p: &[f64],
    runs: &[Run],
    offsets: &[[f64; 3]],
) -> Evaluation<'r> {
    let tracks = tracks(r, p, runs, offsets);
    let (mut errors, per_run) = errors_each(&pairs(runs, &tracks));
    let all: Vec<Innovation> = runs
        .iter()
        .zip(&tracks)
        .flat_map(|(run, t)| innovations::innovations(r, p, run, t))
        .collect();
    let landmarks = innovations::stats(&all);
    if !runs.iter().any(|x| x.gt.is_some()) {
        if let Some(s) = &landmarks {
            errors.rmse = s.range_rmse_m;
        }
    }
    Evaluation {
        tracks,
        errors,
        per_run,
        landmarks,
    }
}

/// Refuse tracks that stop being numbers (see `track_rows::first_non_finite`),
/// naming the log and its line; `sets` are the --set values, named as suspects.
pub fn check_finite(runs: &[Run], tracks: &[Recipe<'_>], sets: &[String]) -> Result<(), String> {
    for (run, t) in runs.iter().zip(tracks) {
        if let Some((k, what)) = first_non_finite(t, run) {
            let suspects = if sets.is_empty() {
                String::new()
            } else {
                format!(" (with --set {})", sets.join(" --set "))
            };
            return Err(format!("{}:{}: {what}{suspects}", run.path, k + 2));
        }
    }
    Ok(())
}

/// A method's evaluation: dead reckoning with its parameters, or, for a method
/// that learned the yaw rate (neural gyrodometry), gyrodometry with its virtual
/// gyro.
fn method_evaluation<'r>(
    r: &'r Runner,
    m: &kinegen_analysis::methods::Calibration,
    runs: &[Run],
) -> Evaluation<'r> {
    let Some(f) = &m.yaw_rate else {
        return evaluation(r, &m.p, runs);
    };
    let tracks: Vec<Recipe> = runs
        .iter()
        .map(|_| Recipe {
            r,
            p: m.p.clone(),
            offset: [0.0; 3],
            heading: Heading::Learned(f.clone()),
        })
        .collect();
    let (errors, per_run) = errors_each(&pairs(runs, &tracks));
    Evaluation {
        errors,
        per_run,
        tracks,
        landmarks: None,
    }
}

/// The error summary of [`evaluation`].
/// When a calibration made the held-out runs worse (`nominal` -> `now` m), the
/// warning that says so and why: the motions and inputs of the held-out runs
/// the fitted runs do not cover (dead-reckoned with the nominal values in
/// `fitted` and `held`), or else that the fitted runs do not determine what
/// the held-out runs need.
fn held_out_worse(
    r: &Runner,
    fitted: (&[Run], &[Recipe<'_>]),
    held: (&[Run], &[Recipe<'_>]),
    nominal: f64,
    now: f64,
) -> Option<String> {
    // (a NaN is not "worse": the fit's own checks name non-finite results)
    if now.partial_cmp(&(1.001 * nominal)) != Some(std::cmp::Ordering::Greater) {
        return None;
    }
    let gaps = kinegen_analysis::coverage::uncovered(
        r,
        &pairs(fitted.0, fitted.1),
        &pairs(held.0, held.1),
    );
    let why = if gaps.is_empty() {
        "the fitted runs do not determine what the held-out runs need (see the standard deviations): fit on runs that drive like the held-out ones".to_string()
    } else {
        format!(
            "the fitted runs do not cover them ({}): add runs that do to --data",
            gaps.join("; ")
        )
    };
    Some(format!(
        "worse than the nominal parameters on the held-out runs ({nominal:.4} m -> {now:.4} m): {why}"
    ))
}

/// Leave-one-run-out ([`kinegen_analysis::fit::leave_one_out`]): the runs
/// the others' calibration dead-reckons worse than the starting values are
/// named in a warning; every left-out run's figures go to the JSON.
fn say_leave_one_out(
    out: &Out,
    r: &Runner,
    p: &[f64],
    runs: &[Run],
    fo: &FitOptions,
    doc: &mut Value,
) {
    let checked = kinegen_analysis::fit::leave_one_out::leave_one_out(r, p, runs, fo);
    if checked.is_empty() {
        return;
    }
    let unsupported: Vec<String> = checked
        .iter()
        .filter(|x| x.unsupported())
        .map(|x| {
            format!(
                "{} ({:.4} m -> {:.4} m)",
                x.path, x.nominal_rmse_m, x.calibrated_rmse_m
            )
        })
        .collect();
    if !unsupported.is_empty() {
        let w = format!(
            "leave-one-run-out: calibrated on the other runs, {} of {} runs are dead-reckoned worse than with the starting values: {}. These runs do not support the estimate (too short, or driven differently from the rest): look at them, add runs like them, or give the parameters a `tolerance` in the spec",
            unsupported.len(),
            checked.len(),
            unsupported.join(", ")
        );
        out.say(&format!("warning: {w}"));
        if let Some(list) = doc["warnings"].as_array_mut() {
            list.push(json!(w));
        }
    }
    doc["leave_one_out"] = json!(checked);
}

/// The logs of `runs` by path, each once, for a message about all of them
/// (a few named, then how many more).
fn logs_named(runs: &[Run]) -> String {
    let mut paths: Vec<&str> = Vec::new();
    for r in runs {
        if !paths.contains(&r.path.as_str()) {
            paths.push(&r.path);
        }
    }
    match paths.len() {
        0..=3 => paths.join(", "),
        n => format!("{} and {} more", paths[..3].join(", "), n - 3),
    }
}

pub fn evaluate(r: &Runner, p: &[f64], runs: &[Run]) -> Errors {
    evaluation(r, p, runs).errors
}

/// The metric `rmse` reports (CONTRACT section 4 leaves its name to us).
pub fn metric_name(runs: &[Run]) -> &'static str {
    if runs.iter().any(|x| x.gt.is_some()) || !runs.iter().any(|x| !x.landmarks.is_empty()) {
        "position_rmse_m"
    } else {
        "landmark_range_rmse_m"
    }
}

fn fmt_landmarks(s: &InnovationStats) -> String {
    format!(
        "landmark innovations: {} observations of {} landmarks; range RMSE {:.4} m (bias {:+.4}), bearing RMSE {:.4} rad (bias {:+.4}){}",
        s.observations,
        s.landmarks,
        s.range_rmse_m,
        s.range_bias_m,
        s.bearing_rmse_rad,
        s.bearing_bias_rad,
        s.worst_landmark.as_ref().map(|(id, v)| format!("; worst landmark `{id}` ({v:.4} m)")).unwrap_or_default()
    )
}

fn fmt_errors(e: &Errors) -> String {
    let mut s = format!(
        "position RMSE {:.4} m, heading RMSE {:.4} rad; final error {:.4} m / {:.4} rad; worst {:.4} m at {:.1} s",
        e.rmse, e.heading_rmse_rad, e.final_position_error_m, e.final_heading_error_rad, e.max_position_error_m, e.max_error_at_s
    );
    if let Some(d) = e.rpe_per_m {
        s += &format!(
            "\n  drift {:.2}% of distance (relative pose error over 1 m)",
            100.0 * d
        );
    }
    if let Some(d) = e.rpe_5s_m {
        s += &format!(", {:.4} m per 5 s", d);
    }
    if let Some(g) = e.gyro_rmse_rad_s {
        s += &format!("\n  gyro yaw-rate residual RMSE {:.5} rad/s", g);
    }
    s
}

pub fn compare(c: Common) -> ExitCode {
    let out = Out::new(c.json.as_deref());
    let mut prep = match prepare(&c) {
        Ok(p) => p,
        Err(e) => return bad(e),
    };
    // moved, not cloned: a long log's runs are most of the memory
    let mut all: Vec<Run> = std::mem::take(&mut prep.runs);
    all.append(&mut prep.holdout);
    let r = &prep.runner;
    let tracks = tracks(r, &r.p, &all, &[]);
    let read = pairs(&all, &tracks);
    let (e, each) = errors_each(&read);
    let (regimes, segments) = where_it_fails(&read);
    let secs: f64 = all.iter().map(|r| r.t.last().unwrap() - r.t[0]).sum();
    let which = if c.set.is_empty() {
        "nominal parameters".to_string()
    } else {
        format!("nominal parameters with --set {}", c.set.join(" --set "))
    };
    out.say(&format!(
        "{} against {} run(s), {:.1} s of data, {which}",
        r.ir.name,
        all.len(),
        secs
    ));
    say_warnings(&out, &prep.warnings);
    if all.iter().any(|x| x.gt.is_some()) {
        out.say(&format!("  {}", fmt_errors(&e)));
    } else {
        out.say(&format!(
            "  no ground truth ({}) in the logs: no trajectory error",
            r.ir.pose_columns().join(", ")
        ));
    }
    let innov: Vec<Vec<Innovation>> = all
        .iter()
        .zip(&tracks)
        .map(|(run, t)| innovations::innovations(r, &r.p, run, t))
        .collect();
    let lm_stats = innovations::stats(&innov.concat());
    if let Some(s) = &lm_stats {
        out.say(&format!("  {}", fmt_landmarks(s)));
    }
    say_where_it_fails(&out, &regimes, &segments);
    // Gyrodometry (seed 000 eq. 13-18) on the runs that log a gyro.
    let gyro_tracks: Vec<Option<Recipe>> = all
        .iter()
        .map(|run| {
            run.gyro.is_some().then(|| Recipe {
                r,
                p: r.p.clone(),
                offset: [0.0; 3],
                heading: Heading::Gyro,
            })
        })
        .collect();
    let gyro_pairs: Vec<(&Run, &dyn TrackRows)> = all
        .iter()
        .zip(&gyro_tracks)
        .filter_map(|(run, t)| t.as_ref().map(|t| (run, t as &dyn TrackRows)))
        // errors need the ground truth to compare with
        .filter(|(run, _)| run.gt.is_some())
        .collect();
    let gyro_errors = (!gyro_pairs.is_empty()).then(|| errors(&gyro_pairs));
    if let Some(g) = &gyro_errors {
        out.say(&format!(
            "gyrodometry (heading from the gyro, seed 000 eq. 13-18), {} run(s):\n  position RMSE {:.4} m, heading RMSE {:.4} rad; final error {:.4} m / {:.4} rad",
            gyro_pairs.len(),
            g.rmse,
            g.heading_rmse_rad,
            g.final_position_error_m,
            g.final_heading_error_rad
        ));
    }
    let per_run: Vec<Value> = all
        .iter()
        .zip(&each)
        .map(|(run, e)| json!({"run": run.name, "errors": e}))
        .collect();
    let doc = json!({
        "model": r.ir.name, "metric": metric_name(&all),
        "errors": e, "rmse": if all.iter().any(|x| x.gt.is_some()) { e.rmse } else { lm_stats.as_ref().map_or(e.rmse, |s| s.range_rmse_m) },
        "landmarks": lm_stats, "regimes": regimes, "worst_segments": segments, "runs": per_run,
        "gyrodometry": gyro_errors.as_ref().map(|g| json!({"rmse": g.rmse, "errors": g})),
        "parameters": r.names.iter().zip(&r.p).map(|(n, v)| (n.clone(), json!(v))).collect::<serde_json::Map<_, _>>(),
        "warnings": prep.warnings,
    });
    if let Some(dir) = &c.report {
        if let Err(e) =
            crate::report::compare_report(dir, r, &all, &tracks, &gyro_tracks, &innov, &doc)
        {
            return bad(e);
        }
        out.say(&format!("report: {}", dir.join("index.html").display()));
    }
    match out.json(c.json.as_deref(), &doc) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => bad(e),
    }
}

/// Where the error grows: each driving regime's share of the error growth,
/// and the worst 1 s segments.
fn say_where_it_fails(
    out: &Out,
    regimes: &[kinegen_analysis::metrics::RegimeShare],
    segments: &[kinegen_analysis::metrics::Segment],
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

/// JSON for a finished fit (CONTRACT section 4).
pub fn fit_json(
    r: &Runner,
    res: &FitResult,
    before: &Errors,
    after: &Errors,
    metric: &str,
) -> Value {
    let params: serde_json::Map<String, Value> = res
        .free
        .iter()
        .enumerate()
        .map(|(k, &i)| {
            (
                r.names[i].clone(),
                json!({"nominal": r.p[i], "estimate": res.p[i], "std": res.std[k],
                       "tolerance": r.ir.runtime_params()[i].tolerance}),
            )
        })
        .collect();
    let names: Vec<&str> = res.free.iter().map(|&i| r.names[i].as_str()).collect();
    let corr: Vec<Vec<f64>> = (0..names.len())
        .map(|a| (0..names.len()).map(|b| res.corr[(a, b)]).collect())
        .collect();
    json!({
        "model": r.ir.name, "metric": metric,
        "before": {"rmse": before.rmse, "errors": before}, "after": {"rmse": after.rmse, "errors": after},
        "parameters": params, "correlation": {"parameters": names, "matrix": corr},
        "warnings": res.warnings, "iterations": res.iterations, "residuals": res.n_residuals,
    })
}

/// Every run's own figures, named by the path the user gave (CONTRACT section 4
/// `runs`): after calibration at the top, before it under `before`, and for
/// fitted runs the start pose the fit used (measured start plus its refinement).
/// Each run's JSON: its errors before and after, whether it was held out,
/// and the start pose its dead reckoning used (a fitted run's with its
/// refined start heading, a held-out run's as measured).
fn per_run(
    runs: &[Run],
    before: &[Errors],
    after: &[Errors],
    starts: &[[f64; 3]],
    holdout: bool,
) -> Vec<Value> {
    runs.iter()
        .enumerate()
        .map(|(i, run)| {
            let (b, a) = (&before[i], &after[i]);
            json!({
                "path": run.path, "holdout": holdout,
                "rmse": a.rmse, "final_error": a.final_position_error_m,
                "final_heading_error": a.final_heading_error_rad, "errors": a,
                "before": {"rmse": b.rmse, "final_error": b.final_position_error_m},
                "start_pose": starts.get(i),
            })
        })
        .collect()
}

/// The options of `fit` besides the common ones.
#[derive(Args, Debug)]
pub struct FitArgs {
    /// Calibration method (the registry in kinegen_analysis::methods), or all
    /// (every applicable method, compared).
    #[arg(long, default_value = "lm", value_parser = method_names())]
    pub method: String,
    /// Square side (m) of the UMBMark runs.
    #[arg(long, default_value_t = Settings::SIDE, value_parser = positive)]
    pub side: f64,
    /// EKF measurement-noise inflation mu (seed 000 eq. 26), rad/s.
    #[arg(long, default_value_t = Settings::MU, value_parser = non_negative)]
    pub mu: f64,
    /// Known true values NAME=VALUE (simulated logs): the report says which method got closest.
    #[arg(long)]
    pub truth: Vec<String>,
    /// Loss of the Levenberg-Marquardt fit: l2 (least squares) or huber
    /// (residuals beyond 3 sigma count linearly: robust to outliers).
    #[arg(long, default_value = "l2", value_parser = ["l2", "huber"])]
    pub loss: String,
    /// Residuals the Levenberg-Marquardt fit uses (repeatable): pose (ground
    /// truth), gyro, landmarks. Default: every kind the logs have.
    #[arg(long, value_parser = ["pose", "gyro", "landmarks"])]
    pub residuals: Vec<String>,
    /// What the Levenberg-Marquardt fit compares: track (each whole run
    /// dead-reckoned from its start, as the odometry will run; found through
    /// 60 s re-anchored segments, kept where it does not trade their
    /// short-term accuracy; standard deviations that account for the track's
    /// drift), segments (the re-anchored 60 s segments only, each start
    /// heading refined) or increments (pose increments over 5 s windows,
    /// each dead-reckoned from its measured start, with a sandwich
    /// covariance; needs ground truth in every run). Over 50 simulated logs
    /// each reports standard deviations within 30% of the estimates' spread.
    #[arg(long, default_value = "track", value_parser = kinegen_analysis::fit::Likelihood::NAMES)]
    pub likelihood: String,
    /// Write the calibrated values for the robot's configuration: `--export
    /// ros2-yaml PATH` (ROS 2 diff_drive_controller parameters for a differential
    /// drive, every calibrated parameter with its standard deviation otherwise).
    #[arg(long, num_args = 2, value_names = ["FORMAT", "PATH"])]
    pub export: Vec<String>,
    /// Hidden tanh units of the neural gyrodometry network (--method neural or
    /// all); repeatable: one network per size (seed 000 compares 9 and 50).
    #[arg(long, default_values_t = [50], value_parser = clap::value_parser!(u32).range(1..=1000))]
    pub hidden: Vec<u32>,
}

/// A finite number above zero (clap reports the option on error).
pub fn positive(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && v > 0.0 => Ok(v),
        _ => Err(format!("`{s}` is not a finite number above 0")),
    }
}

/// A finite number, zero or above.
pub fn non_negative(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && v >= 0.0 => Ok(v),
        _ => Err(format!("`{s}` is not a finite number of 0 or more")),
    }
}

/// `--method` values with their one-line descriptions, from the method registry.
fn method_names() -> clap::builder::PossibleValuesParser {
    use clap::builder::PossibleValue;
    use kinegen_analysis::methods::METHODS;
    clap::builder::PossibleValuesParser::new(
        METHODS
            .iter()
            .map(|m| PossibleValue::new(m.name()).help(m.about()))
            .chain([PossibleValue::new("all").help("every applicable method, compared")]),
    )
}

pub fn run_fit(c: Common, a: &FitArgs) -> ExitCode {
    let export = match export_path(&a.export) {
        Ok(e) => e,
        Err(e) => return bad(e),
    };
    if export.is_some() && a.method != "lm" {
        return bad("--export writes the Levenberg-Marquardt calibration: use it with --method lm");
    }
    let out = Out::new(c.json.as_deref());
    let fo = fit_options(a);
    let prep = match prepare(&c) {
        Ok(p) => p,
        Err(e) => return bad(e),
    };
    let truth = match truth_values(&prep.runner, &a.truth) {
        Ok(t) => t,
        Err(e) => return bad(e),
    };
    if a.method != "lm" {
        say_warnings(&out, &prep.warnings);
        return run_methods(&c, &out, &prep, a, &fo, &truth);
    }
    run_lm(&c, &out, &prep, a, &fo, export.as_deref())
}

/// `--export FORMAT PATH`: the path to write (checked writable), if any.
fn export_path(export: &[String]) -> Result<Option<PathBuf>, String> {
    match export {
        [] => Ok(None),
        [f, p] if f == "ros2-yaml" => {
            let p = PathBuf::from(p);
            crate::output::check_writable("--export ros2-yaml", &p)?;
            Ok(Some(p))
        }
        [f, _] => Err(format!("--export {f}: unknown format (known: ros2-yaml)")),
        _ => Err("--export takes a format and a path: --export ros2-yaml PATH".into()),
    }
}

/// Whether `fit` uses residuals of `kind` (pose, gyro, landmarks): every kind
/// when `--residuals` names none.
fn uses_residuals(a: &FitArgs, kind: &str) -> bool {
    a.residuals.is_empty() || a.residuals.iter().any(|r| r == kind)
}

/// The calibration options `fit`'s arguments ask for.
fn fit_options(a: &FitArgs) -> FitOptions {
    // Huber threshold in sigmas: 3 leaves Gaussian noise (99.7% inside) untouched
    let fo = FitOptions {
        huber: (a.loss == "huber").then_some(3.0),
        use_pose: uses_residuals(a, "pose"),
        use_gyro: uses_residuals(a, "gyro"),
        use_landmarks: uses_residuals(a, "landmarks"),
        multi_start: true,
        ..FitOptions::default()
    };
    kinegen_analysis::fit::Likelihood::parse(&a.likelihood)
        .expect("clap checked the name")
        .apply(fo)
}

/// `--truth NAME=VALUE` pairs, each naming a parameter of the spec.
fn truth_values(r: &Runner, truth: &[String]) -> Result<Vec<(String, f64)>, String> {
    let truth =
        kinegen_analysis::model::parse_pairs("--truth", truth).map_err(|e| e.to_string())?;
    if let Some((n, _)) = truth.iter().find(|(n, _)| r.param_index(n).is_none()) {
        return Err(format!(
            "--truth {n}: the spec has no parameter `{n}` (it has: {})",
            r.names.join(", ")
        ));
    }
    Ok(truth)
}

/// The methods `--method` names (all of them for `all`), each with a run per
/// `--hidden` size where the method has one (neural gyrodometry).
fn method_jobs(a: &FitArgs) -> Result<Vec<(String, &'static dyn Method, usize)>, String> {
    let methods: Vec<&dyn Method> = if a.method == "all" {
        METHODS.to_vec()
    } else {
        match by_name(&a.method) {
            Some(m) => vec![m],
            None => return Err(format!("--method: unknown method `{}`", a.method)),
        }
    };
    Ok(methods
        .iter()
        .flat_map(|m| {
            if m.per_hidden_size() {
                a.hidden
                    .iter()
                    .map(|&h| (format!("{}-{h}", m.name()), *m, h as usize))
                    .collect::<Vec<_>>()
            } else {
                vec![(m.name().to_string(), *m, 0)]
            }
        })
        .collect())
}

/// `fit --method M` (or all): each method's calibration, compared.
fn run_methods(
    c: &Common,
    out: &Out,
    prep: &Prepared,
    a: &FitArgs,
    fo: &FitOptions,
    truth: &[(String, f64)],
) -> ExitCode {
    let r = &prep.runner;
    let jobs = match method_jobs(a) {
        Ok(j) => j,
        Err(e) => return bad(e),
    };
    let mut rows = Vec::new();
    let bar = crate::progress::Progress::bar(jobs.len() as u64, "calibration methods", quiet(c));
    for (name, m, h) in jobs {
        bar.message(&name);
        let settings = Settings {
            side: a.side,
            mu: a.mu,
            fit: fo,
            hidden: h,
        };
        let result = m.calibrate(r, &prep.runs, &settings);
        bar.inc();
        match result {
            Ok(res) => rows.push((name, res)),
            Err(e) if a.method == "all" => out.say(&format!("{name}: not applicable here: {e}")),
            Err(e) => return bad(format!("{}: {e}", logs_named(&prep.runs))),
        }
    }
    let before = evaluation(r, &r.p, &prep.runs);
    out.say(&format!(
        "{}: {} calibration method(s) on {} run(s); position RMSE with nominal parameters {:.4} m",
        r.ir.name,
        rows.len(),
        prep.runs.len(),
        before.errors.rmse
    ));
    let compared = MethodComparison::new(r, prep, truth);
    let mut methods_json = serde_json::Map::new();
    let mut per_method: Vec<(String, Vec<Recipe>)> = Vec::new();
    let mut best: Option<(f64, &str)> = None;
    for (name, m) in &rows {
        let (entry, tracks, dist) = compared.method(out, name, m, &before);
        if let Some(d) = dist {
            if best.is_none_or(|b| d < b.0) {
                best = Some((d, name.as_str()));
            }
        }
        methods_json.insert(name.to_string(), entry);
        per_method.push((name.to_string(), tracks));
    }
    if let Some((d, name)) = best {
        out.say(&format!("closest to the true parameters: {name} ({:.1}% of the nominal parameters' distance to the truth left)", 100.0 * d));
    }
    // the top-level result is the first method's
    let first = rows.first().map(|(name, _)| &methods_json[name.as_str()]);
    let doc = json!({
        "model": r.ir.name, "metric": metric_name(&prep.runs),
        "before": {"rmse": before.errors.rmse},
        "holdout_before": compared.hold_nominal().map(|h| json!({"rmse": h})),
        "after": {"rmse": first.map(|m| m["after"]["rmse"].clone())},
        "parameters": first.map(|m| m["parameters"].clone()),
        "methods": methods_json,
        "closest_to_truth": best.map(|b| b.1),
        "truth": truth.iter().map(|(n, v)| (n.clone(), json!(v))).collect::<serde_json::Map<String, Value>>(),
        "warnings": prep.warnings,
    });
    if let Some(dir) = &c.report {
        if let Err(e) =
            crate::report::methods_report(dir, r, &prep.runs, &before.tracks, &per_method, &doc)
        {
            return bad(e);
        }
        out.say(&format!("report: {}", dir.join("index.html").display()));
    }
    match out.json(c.json.as_deref(), &doc) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => bad(e),
    }
}

/// What each method of `fit --method` is compared with: the nominal values
/// (on the fitted and the held-out runs) and the known truth.
struct MethodComparison<'a> {
    r: &'a Runner,
    prep: &'a Prepared,
    truth: &'a [(String, f64)],
    /// the nominal values' distance to the truth
    d0: f64,
    /// the nominal values on the fitted and the held-out runs, with held-out runs
    nominal: Option<(Evaluation<'a>, Evaluation<'a>)>,
}

impl<'a> MethodComparison<'a> {
    fn new(r: &'a Runner, prep: &'a Prepared, truth: &'a [(String, f64)]) -> Self {
        let mut me = MethodComparison {
            r,
            prep,
            truth,
            d0: 0.0,
            nominal: (!prep.holdout.is_empty()).then(|| {
                (
                    evaluation(r, &r.p, &prep.runs),
                    evaluation(r, &r.p, &prep.holdout),
                )
            }),
        };
        me.d0 = me.scaled(&r.p);
        me
    }

    /// Distance to the truth, each parameter scaled by its size (so a 2 mm
    /// offset of a 0.3 m axis and of a 0 m axis weigh the same).
    fn scaled(&self, p: &[f64]) -> f64 {
        let r = self.r;
        self.truth
            .iter()
            .filter_map(|(n, v)| {
                r.param_index(n)
                    .map(|i| ((p[i] - v) / r.p[i].abs().max(v.abs()).max(1e-12)).powi(2))
            })
            .sum::<f64>()
            .sqrt()
    }

    /// The nominal values' RMSE on the held-out runs, if any.
    fn hold_nominal(&self) -> Option<f64> {
        self.nominal.as_ref().map(|x| x.1.errors.rmse)
    }

    /// One method's lines, its JSON entry, its tracks and its distance to the
    /// truth as a fraction of where the nominal values started (< 1: moved
    /// toward the truth).
    fn method(
        &self,
        out: &Out,
        name: &str,
        m: &kinegen_analysis::methods::Calibration,
        before: &Evaluation,
    ) -> (Value, Vec<Recipe<'a>>, Option<f64>) {
        let (r, prep) = (self.r, self.prep);
        let Evaluation {
            tracks: after_tracks,
            errors: after,
            ..
        } = method_evaluation(r, m, &prep.runs);
        let hold =
            (!prep.holdout.is_empty()).then(|| method_evaluation(r, m, &prep.holdout).errors);
        // a method that ends worse than the nominal values says so (on the
        // held-out runs when there are some)
        let (what, now, nominal) = match (&hold, self.hold_nominal()) {
            (Some(h), Some(b)) => ("held-out runs", h.rmse, b),
            _ => ("fitted runs", after.rmse, before.errors.rmse),
        };
        let mut note = m.note.clone();
        let held_worse = self.nominal.as_ref().and_then(|(f, h)| {
            held_out_worse(
                r,
                (&prep.runs, &f.tracks),
                (&prep.holdout, &h.tracks),
                nominal,
                now,
            )
        });
        if let Some(w) = held_worse {
            note += &format!("\n      WARNING: {w}: do not use these values");
        } else if now > 1.001 * nominal {
            note += &format!("\n      WARNING: worse than the nominal parameters on the {what} ({nominal:.4} m -> {now:.4} m): do not use these values");
        }
        let params: serde_json::Map<String, Value> = r.free.iter().enumerate().map(|(k, &i)| (r.names[i].clone(), json!({"nominal": r.p[i], "estimate": m.p[i], "std": m.std.get(k).copied().filter(|v| v.is_finite())}))).collect();
        let dist = (!self.truth.is_empty()).then(|| {
            if self.d0 > 0.0 {
                self.scaled(&m.p) / self.d0
            } else {
                self.scaled(&m.p)
            }
        });
        out.say(&format!(
            "  {:<8} position RMSE {:.4} m{}{}  ({})",
            name,
            after.rmse,
            hold.as_ref()
                .map(|h| format!(", held-out {:.4} m", h.rmse))
                .unwrap_or_default(),
            dist.map(|d| format!(
                ", {:.1}% of the nominal's distance to truth left",
                100.0 * d
            ))
            .unwrap_or_default(),
            note
        ));
        for &i in &r.free {
            out.say(&format!("      {:<14} {:.6}", r.names[i], m.p[i]));
        }
        let entry = json!({"after": {"rmse": after.rmse}, "holdout": hold.map(|h| json!({"rmse": h.rmse})), "parameters": params, "note": note, "distance_to_truth": dist});
        (entry, after_tracks, dist)
    }
}

/// `fit` (Levenberg-Marquardt, the default): the calibration, judged, with
/// its per-run table, held-out runs, leave-one-out, report and export.
fn run_lm(
    c: &Common,
    out: &Out,
    prep: &Prepared,
    a: &FitArgs,
    fo: &FitOptions,
    export: Option<&Path>,
) -> ExitCode {
    let r = &prep.runner;
    let spin = crate::progress::Progress::spinner("calibrating (Levenberg-Marquardt)", quiet(c));
    // through the registry like every method; lm's Calibration carries the
    // whole fit, which the rest of this report reads
    let lm = kinegen_analysis::methods::by_name("lm").expect("lm is registered");
    let settings = Settings {
        side: a.side,
        mu: a.mu,
        fit: fo,
        hidden: 0,
    };
    let mut res = match lm.calibrate(r, &prep.runs, &settings) {
        Ok(kinegen_analysis::methods::Calibration { fit: Some(x), .. }) => x,
        Ok(_) => unreachable!("lm's calibration is a fit"),
        Err(e) => return bad(format!("{}: {e}", logs_named(&prep.runs))),
    };
    res.warnings.splice(0..0, prep.warnings.iter().cloned());
    drop(spin);
    // both scored with the start headings refined for their own parameters, as
    // the fit refines them (within what the measured start allows)
    let offsets_before = kinegen_analysis::fit::fitted_offsets(r, &r.p, &prep.runs, fo);
    let (eval_before, eval_after) = (
        evaluation_from(
            r,
            &r.p,
            &prep.runs,
            &kinegen_analysis::fit::run_offsets(&prep.runs, &offsets_before),
        ),
        evaluation_from(
            r,
            &res.p,
            &prep.runs,
            &kinegen_analysis::fit::run_offsets(&prep.runs, &res.starts),
        ),
    );
    say_calibration(out, prep, &res, &eval_before.errors, &eval_after.errors);
    let unusable = judge_fit(
        out,
        prep,
        &mut res,
        (&eval_before, &eval_after),
        &offsets_before,
    );
    let (before, after) = (&eval_before.errors, &eval_after.errors);
    let mut doc = fit_json(r, &res, before, after, metric_name(&prep.runs));
    doc["unusable"] = json!(unusable);
    doc["loss"] = json!(a.loss);
    doc["residual_kinds"] = json!(["pose", "gyro", "landmarks"]
        .iter()
        .filter(|k| uses_residuals(a, k))
        .collect::<Vec<_>>());
    if let (Some(lb), Some(la)) = (&eval_before.landmarks, &eval_after.landmarks) {
        out.say(&format!(
            "  before: {}\n  after:  {}",
            fmt_landmarks(lb),
            fmt_landmarks(la)
        ));
        doc["landmarks"] = json!({"before": lb, "after": la});
    }
    let runs = fit_runs(out, prep, &res, (&eval_before, &eval_after), &mut doc);
    doc["runs"] = json!(runs);
    say_leave_one_out(out, r, &res.p, &prep.runs, fo, &mut doc);
    if let Some(dir) = &c.report {
        if let Err(e) = crate::report::fit_report(
            dir,
            r,
            &prep.runs,
            &eval_before.tracks,
            &eval_after.tracks,
            &doc,
        ) {
            return bad(e);
        }
        out.say(&format!("report: {}", dir.join("index.html").display()));
    }
    if let Some(path) = export {
        if let Err(e) = export_fit(out, &c.spec, r, &res, path, &unusable) {
            return bad(e);
        }
    }
    match out.json(c.json.as_deref(), &doc) {
        Ok(()) if unusable.is_empty() => ExitCode::SUCCESS,
        Ok(()) => ExitCode::from(1),
        Err(e) => bad(e),
    }
}

/// The calibration's headline: what was fitted, the error before and after,
/// and each parameter's estimate.
fn say_calibration(out: &Out, prep: &Prepared, res: &FitResult, before: &Errors, after: &Errors) {
    let r = &prep.runner;
    out.say(&format!(
        "{}: calibrated {} parameter(s) on {} run(s) ({} residuals, {} LM iterations)",
        r.ir.name,
        res.free.len(),
        prep.runs.len(),
        res.n_residuals,
        res.iterations
    ));
    if prep.runs.iter().any(|x| x.gt.is_some()) {
        out.say(&format!("  before: {}", fmt_errors(before)));
        out.say(&format!("  after:  {}", fmt_errors(after)));
    } else {
        out.say("  no ground truth in the logs: calibrated on landmark (and gyro) residuals; the error is the landmark range innovation");
    }
    out.say(&format!(
        "  {:<16} {:>12} {:>12} {:>12}",
        "parameter", "nominal", "estimate", "std"
    ));
    for (k, &i) in res.free.iter().enumerate() {
        out.say(&format!(
            "  {:<16} {:>12.6} {:>12.6} {:>12}",
            r.names[i],
            r.p[i],
            res.p[i],
            crate::output::fmt_std(Some(res.std[k]))
        ));
    }
}

/// Why the calibration cannot be used, if it cannot (said plainly, never shown
/// as a success), with its warnings said and added to `res`.
fn judge_fit(
    out: &Out,
    prep: &Prepared,
    res: &mut FitResult,
    (eval_before, eval_after): (&Evaluation, &Evaluation),
    offsets_before: &[[f64; 3]],
) -> Vec<String> {
    let r = &prep.runner;
    let (before, after) = (&eval_before.errors, &eval_after.errors);
    let mut unusable =
        kinegen_analysis::metrics::degenerate(&pairs(&prep.runs, &eval_after.tracks));
    let (worse, worse_warnings) = kinegen_analysis::metrics::short_term_worse(before, after);
    unusable.extend(worse);
    let implausible = kinegen_analysis::metrics::implausible(
        res.free
            .iter()
            .map(|&i| (r.names[i].as_str(), r.p[i], res.p[i])),
    );
    res.warnings
        .extend(worse_warnings.into_iter().chain(implausible));
    for w in &res.warnings {
        out.say(&format!("warning: {w}"));
    }
    if after.rmse.is_finite() && after.rmse > 1.001 * before.rmse {
        if let Some(u) = judge_growth(out, prep, res, (before.rmse, after.rmse), offsets_before) {
            unusable.push(u);
        }
    }
    if !after.rmse.is_finite() || res.p.iter().any(|v| !v.is_finite()) {
        unusable.push("the calibrated model gives non-finite results".into());
    }
    for u in &unusable {
        out.say(&format!("FIT UNUSABLE: {u}"));
    }
    if !unusable.is_empty() {
        out.say("  no parameter values make this model follow these logs: it is likely missing a physical effect (`kinegen diagnose` with the same --spec and --data names it)");
    }
    unusable
}

/// A whole-run position error that grew from `before` to `after`: explained
/// (a note or a warning), or the reason the fit is unusable.
fn judge_growth(
    out: &Out,
    prep: &Prepared,
    res: &mut FitResult,
    (before, after): (f64, f64),
    offsets_before: &[[f64; 3]],
) -> Option<String> {
    let r = &prep.runner;
    // Long runs are fitted as re-anchored segments (fit::SEGMENT_S): judge the
    // fit on what it minimised; over a whole long run the absolute error is a
    // random walk the parameters cannot remove.
    let seg = kinegen_analysis::fit::segmented(&prep.runs);
    let (sb, sa) = (
        evaluation_from(r, &r.p, &seg, offsets_before).errors.rmse,
        evaluation_from(r, &res.p, &seg, &res.starts).errors.rmse,
    );
    if seg.len() > prep.runs.len() && sa <= 1.001 * sb {
        out.say(&format!(
            "note: over whole runs the position error grew ({before:.4} m -> {after:.4} m) while over the {:.0} s segments the fit works on it fell ({sb:.4} m -> {sa:.4} m): the remaining long-run drift is noise the parameters cannot remove",
            kinegen_analysis::fit::SEGMENT_S
        ));
        return None;
    }
    if after <= 1.05 * before {
        // within 5%: the starting values were already as good as these logs
        // can tell; the fit traded a little whole-track error for its cost
        out.say(&format!(
            "note: the position error grew slightly ({before:.4} m -> {after:.4} m): the starting values were already about as good as these logs can tell"
        ));
        return None;
    }
    let with_prior: Vec<&str> = res
        .free
        .iter()
        .filter(|&&i| r.ir.runtime_params()[i].tolerance.is_some())
        .map(|&i| r.names[i].as_str())
        .collect();
    let grew = format!("{before:.4} m -> {after:.4} m");
    if with_prior.is_empty() {
        return Some(format!(
            "calibration made the position error worse ({grew})"
        ));
    }
    // a prior may rightly cost some fit: the spec says what is known
    let w = format!(
        "the position error grew ({grew}) under the spec's tolerances on {}: the log pulls them further than the tolerances allow; loosen a tolerance if the robot can differ from nominal that much",
        with_prior.join(", ")
    );
    out.say(&format!("warning: {w}"));
    res.warnings.push(w);
    None
}

/// Each run's errors before and after (the fitted ones, then the held-out
/// ones, which also go in `doc["holdout"]` with a warning where the
/// calibration does worse on them), said as a table when there are several.
fn fit_runs(
    out: &Out,
    prep: &Prepared,
    res: &FitResult,
    (eval_before, eval_after): (&Evaluation, &Evaluation),
    doc: &mut Value,
) -> Vec<Value> {
    let r = &prep.runner;
    let starts = kinegen_analysis::fit::run_starts(r, &res.p, &prep.runs, &res.starts);
    let mut runs = per_run(
        &prep.runs,
        &eval_before.per_run,
        &eval_after.per_run,
        &starts,
        false,
    );
    if !prep.holdout.is_empty() {
        let (hb, ha) = (
            evaluation(r, &r.p, &prep.holdout),
            evaluation(r, &res.p, &prep.holdout),
        );
        out.say(&format!(
            "  holdout before: {}\n  holdout after:  {}",
            fmt_errors(&hb.errors),
            fmt_errors(&ha.errors)
        ));
        let measured = kinegen_analysis::fit::run_starts(r, &res.p, &prep.holdout, &[]);
        runs.extend(per_run(
            &prep.holdout,
            &hb.per_run,
            &ha.per_run,
            &measured,
            true,
        ));
        if let Some(w) = held_out_worse(
            r,
            (&prep.runs, &eval_before.tracks),
            (&prep.holdout, &hb.tracks),
            hb.errors.rmse,
            ha.errors.rmse,
        ) {
            out.say(&format!("warning: {w}"));
            if let Some(list) = doc["warnings"].as_array_mut() {
                list.push(json!(w));
            }
        }
        doc["holdout"] = json!({"before": {"rmse": hb.errors.rmse, "errors": hb.errors}, "after": {"rmse": ha.errors.rmse, "errors": ha.errors}});
    }
    if runs.len() > 1 {
        out.say(&format!(
            "  {:<40} {:>8} {:>10} {:>10} {:>12}",
            "run", "role", "RMSE m", "final m", "before m"
        ));
        for x in &runs {
            out.say(&format!(
                "  {:<40} {:>8} {:>10.4} {:>10.4} {:>12.4}",
                x["path"].as_str().unwrap_or(""),
                if x["holdout"] == json!(true) {
                    "held out"
                } else {
                    "fitted"
                },
                x["rmse"].as_f64().unwrap_or(f64::NAN),
                x["final_error"].as_f64().unwrap_or(f64::NAN),
                x["before"]["rmse"].as_f64().unwrap_or(f64::NAN),
            ));
        }
    }
    runs
}

/// `--export ros2-yaml PATH`: the calibration written for the robot, unless
/// it is unusable (then said, not written).
fn export_fit(
    out: &Out,
    spec: &Path,
    r: &Runner,
    res: &FitResult,
    path: &Path,
    unusable: &[String],
) -> Result<(), String> {
    if !unusable.is_empty() {
        out.say(&format!(
            "not exported to {}: the fit is unusable",
            path.display()
        ));
        return Ok(());
    }
    crate::export::ros2_yaml(spec, r, res)
        .and_then(|y| kinegen_model::files::write_atomic(path, &y).map_err(|e| e.to_string()))?;
    out.say(&format!("exported: {}", path.display()));
    Ok(())
}
