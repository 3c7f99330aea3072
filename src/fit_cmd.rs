//! `kinegen fit`: one call to kinegen_analysis::estimation::fit_request::fit_files (the
//! Levenberg-Marquardt calibration judged, the default, or several methods
//! compared), rendered as text, JSON, a report and an export.
use crate::analysis_cmd::{
    bad, fmt_errors, fmt_landmarks, fmt_landmarks_from_truth, non_negative, positive, quiet,
    read_progress, say_warnings, Common,
};
use crate::output::Out;
use crate::progress::Progress;
use clap::Args;
use kinegen_analysis::estimation::fit::{FitOptions, FitResult};
use kinegen_analysis::estimation::fit_document::calibration_document;
use kinegen_analysis::estimation::fit_job::{
    self, Calibrated, Growth, MethodRow, MethodsJob, MethodsOutcome,
};
use kinegen_analysis::estimation::fit_request::{fit_files, FitHooks, FitRequest, Fitted};
use kinegen_analysis::estimation::methods::{MethodChoice, Settings};
use kinegen_analysis::model_on_log::evaluation::metric_name;
use kinegen_analysis::model_on_log::files::Files;
use kinegen_analysis::model_on_log::load::Loaded;
use kinegen_analysis::model_on_log::metrics::Errors;
use kinegen_analysis::model_on_log::model::Runner;
use kinegen_analysis::model_on_log::run::Run;
use serde_json::{json, Value};
use std::cell::{Cell, RefCell};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

/// The options of `fit` besides the common ones.
#[derive(Args, Debug)]
pub struct FitArgs {
    /// Calibration method (the registry in kinegen_analysis::estimation::methods), or all
    /// (every applicable method, compared).
    #[arg(long, default_value = "lm", value_parser = method_names())]
    pub method: String,
    /// Square side (m) of the UMBMark runs.
    #[arg(long, default_value_t = Settings::SIDE, value_parser = positive)]
    pub side: f64,
    /// EKF measurement-noise inflation mu of the parameter EKF, rad/s.
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
    #[arg(long, default_value = "track", value_parser = kinegen_analysis::estimation::fit::Likelihood::NAMES)]
    pub likelihood: String,
    /// Write the calibrated values for the robot's configuration: `--export
    /// ros2-yaml PATH` (ROS 2 diff_drive_controller parameters for a differential
    /// drive, every calibrated parameter with its standard deviation otherwise),
    /// or `--export spec PATH` (a copy of the spec with the calibrated values as
    /// its nominals, comments and layout kept: for localize, compare, simulate).
    #[arg(long, num_args = 2, value_names = ["FORMAT", "PATH"])]
    pub export: Vec<String>,
    /// Hidden tanh units of the neural gyrodometry network (--method neural or
    /// all); repeatable: one network per size (e.g. 9 and 50).
    #[arg(long, default_values_t = [50], value_parser = clap::value_parser!(u32).range(1..=1000))]
    pub hidden: Vec<u32>,
}

/// `--method` values with their one-line descriptions, from the method registry.
fn method_names() -> clap::builder::PossibleValuesParser {
    use clap::builder::PossibleValue;
    use kinegen_analysis::estimation::methods::METHODS;
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
    // parsed once, here: the registry's method (or all), then by type
    let Some(method) = MethodChoice::parse(&a.method) else {
        return bad(format!("--method {}: no such method", a.method));
    };
    if export.is_some() && !method.is_full_fit() {
        return bad("--export writes the Levenberg-Marquardt calibration: use it with --method lm");
    }
    let out = Out::new(c.json.as_deref());
    if let Err(e) = crate::output::check_outputs(c.json.as_deref(), c.report.as_deref()) {
        return bad(e);
    }
    if let Err(e) = c.check_repeated_logs() {
        return bad(e);
    }
    let fo = fit_options(a);
    let truth = match kinegen_analysis::model_on_log::model::parse_pairs("--truth", &a.truth) {
        Ok(t) => t,
        Err(e) => return bad(e.to_string()),
    };
    let request = if method.is_full_fit() {
        FitRequest::Calibrate {
            options: &fo,
            truth: &truth,
        }
    } else {
        FitRequest::Methods(MethodsJob {
            method,
            settings: Settings {
                side: a.side,
                mu: a.mu,
                fit: &fo,
                hidden: 0,
            },
            hidden: &a.hidden,
            truth: &truth,
        })
    };
    let files = Files {
        sources: &c.sources(),
        effect_dirs: &c.catalogue.effects,
    };
    // the calibration's spinner (or the methods' bar) starts once the logs
    // are read, and stops before the result is said
    let busy: RefCell<Option<Progress>> = RefCell::new(None);
    let started = Cell::new(false);
    let hooks = FitHooks {
        loaded: &|prep| *busy.borrow_mut() = Some(progress_for(&c, &out, &request, prep)),
        method: &|name| {
            if let Some(bar) = busy.borrow().as_ref() {
                if started.replace(true) {
                    bar.inc();
                }
                bar.message(name);
            }
        },
    };
    let progress = read_progress(quiet(&c));
    let done = fit_files(
        &files,
        &request,
        crate::ir_source::analysis_deriver(),
        &progress,
        &hooks,
        |prep, fitted| {
            busy.take();
            match fitted {
                Fitted::Calibrated(cal) => render_lm(&c, &out, prep, &fo, &cal, export.as_ref()),
                Fitted::Methods(m) => render_methods(&c, &out, prep, &truth, &m),
            }
        },
    );
    match done {
        Ok(code) => code,
        Err(e) => bad(e.to_string()),
    }
}

/// What shows the calibration running: a spinner for Levenberg-Marquardt,
/// a bar over the methods otherwise (whose run the logs' warnings precede:
/// Levenberg-Marquardt says them with its own).
fn progress_for(c: &Common, out: &Out, request: &FitRequest, prep: &Loaded) -> Progress {
    match request {
        FitRequest::Calibrate { .. } => {
            Progress::spinner("calibrating (Levenberg-Marquardt)", quiet(c))
        }
        FitRequest::Methods(job) => {
            say_warnings(out, &prep.warnings);
            let count = fit_job::method_runs(job).map_or(0, |j| j.len());
            Progress::bar(count as u64, "calibration methods", quiet(c))
        }
    }
}

/// What `--export` writes, and where.
#[derive(Debug, Clone)]
enum Export {
    Ros2Yaml(PathBuf),
    Spec(PathBuf),
}

/// `--export FORMAT PATH`: what to write where (checked writable), if any.
fn export_path(export: &[String]) -> Result<Option<Export>, String> {
    match export {
        [] => Ok(None),
        [f, p] if f == "ros2-yaml" || f == "spec" => {
            let path = PathBuf::from(p);
            crate::output::check_writable(&format!("--export {f}"), &path)?;
            Ok(Some(if f == "spec" {
                Export::Spec(path)
            } else {
                Export::Ros2Yaml(path)
            }))
        }
        [f, _] => Err(format!(
            "--export {f}: unknown format (known: ros2-yaml, spec)"
        )),
        _ => Err(
            "--export takes a format and a path: --export ros2-yaml PATH, --export spec PATH"
                .into(),
        ),
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
    // (with no option given: FitOptions::command_default, the Python package's)
    let fo = FitOptions {
        huber: (a.loss == "huber").then_some(3.0),
        use_pose: uses_residuals(a, "pose"),
        use_gyro: uses_residuals(a, "gyro"),
        use_landmarks: uses_residuals(a, "landmarks"),
        sightings_from_truth: uses_residuals(a, "pose"),
        multi_start: true,
        ..FitOptions::default()
    };
    kinegen_analysis::estimation::fit::Likelihood::parse(&a.likelihood)
        .expect("clap checked the name")
        .apply(fo)
}

/// `fit --method M` (or all): each method's calibration, compared.
fn render_methods(
    c: &Common,
    out: &Out,
    prep: &Loaded,
    truth: &[(String, f64)],
    compared: &MethodsOutcome,
) -> ExitCode {
    let r = &prep.runner;
    for (name, e) in &compared.not_applicable {
        out.say(&format!("{name}: not applicable here: {e}"));
    }
    out.say(&format!(
        "{}: {} calibration method(s) on {} run(s); position RMSE with nominal parameters {:.4} m",
        r.ir.name,
        compared.rows.len(),
        prep.runs.len(),
        compared.before.errors.rmse
    ));
    let mut methods_json = serde_json::Map::new();
    for m in &compared.rows {
        say_method(out, r, m);
        methods_json.insert(m.name.clone(), method_json(r, m));
    }
    if let Some((d, name)) = &compared.closest {
        out.say(&format!("closest to the true parameters: {name} ({:.1}% of the nominal parameters' distance to the truth left)", 100.0 * d));
    }
    // the top-level result is the first method's
    let first = compared
        .rows
        .first()
        .map(|m| &methods_json[m.name.as_str()]);
    let doc = json!({
        "model": r.ir.name, "metric": metric_name(&prep.runs),
        "before": {"rmse": compared.before.errors.rmse},
        "holdout_before": compared.holdout_before.map(|h| json!({"rmse": h})),
        "after": {"rmse": first.map(|m| m["after"]["rmse"].clone())},
        "parameters": first.map(|m| m["parameters"].clone()),
        "methods": methods_json,
        "closest_to_truth": compared.closest.as_ref().map(|b| b.1.clone()),
        "truth": truth.iter().map(|(n, v)| (n.clone(), json!(v))).collect::<serde_json::Map<String, Value>>(),
        "warnings": prep.warnings,
    });
    if let Some(dir) = &c.report {
        if let Err(e) = crate::report::methods::methods_report(
            dir,
            r,
            &prep.runs,
            compared,
            truth,
            &prep.warnings,
            &doc,
        ) {
            return bad(e);
        }
        out.say(&format!("report: {}", dir.join("index.html").display()));
    }
    out.finish(c.json.as_deref(), &doc)
}

/// One method's lines: its error (held-out too), its distance to the truth,
/// its note and its parameters.
fn say_method(out: &Out, r: &Runner, m: &MethodRow) {
    out.say(&format!(
        "  {:<8} position RMSE {:.4} m{}{}  ({})",
        m.name,
        m.after.errors.rmse,
        m.holdout
            .as_ref()
            .map(|h| format!(", held-out {:.4} m", h.rmse))
            .unwrap_or_default(),
        m.distance_to_truth
            .map(|d| format!(
                ", {:.1}% of the nominal's distance to truth left",
                100.0 * d
            ))
            .unwrap_or_default(),
        m.note
    ));
    for &i in &r.free {
        out.say(&format!(
            "      {:<14} {:.6}",
            r.names[i], m.calibration.p[i]
        ));
    }
}

/// One method's JSON entry.
fn method_json(r: &Runner, m: &MethodRow) -> Value {
    let c = &m.calibration;
    let params: serde_json::Map<String, Value> = r.free.iter().enumerate().map(|(k, &i)| (r.names[i].clone(), json!({"nominal": r.p[i], "estimate": c.p[i], "std": c.std.get(k).copied().filter(|v| v.is_finite())}))).collect();
    json!({"after": {"rmse": m.after.errors.rmse}, "holdout": m.holdout.as_ref().map(|h| json!({"rmse": h.rmse})), "parameters": params, "note": m.note, "distance_to_truth": m.distance_to_truth})
}

/// `fit` (Levenberg-Marquardt, the default): the calibration, judged, with
/// its per-run table, held-out runs, leave-one-out, report and export.
fn render_lm(
    c: &Common,
    out: &Out,
    prep: &Loaded,
    fo: &FitOptions,
    cal: &Calibrated,
    export: Option<&Export>,
) -> ExitCode {
    let r = &prep.runner;
    let res = &cal.fit;
    // the answer: said by default, and the report's first box
    let kept = Out::keeping();
    crate::fit_text::say_summary(&kept, prep, cal);
    let answer = kept.lines();
    if !c.verbose {
        answer.iter().for_each(|l| out.say(l));
    }
    // the detail: said with -v, in the JSON either way
    let detail = &out.detail(c.verbose);
    say_calibration(detail, prep, res, &cal.before.errors, &cal.after.errors);
    say_judgement(detail, cal);
    let doc = calibration_document(prep, cal, fo);
    if let (Some(lb), Some(la)) = (&cal.before.landmarks, &cal.after.landmarks) {
        detail.say(&format!(
            "  before: {}\n  after:  {}",
            fmt_landmarks(lb),
            fmt_landmarks(la)
        ));
    }
    if let (Some(lb), Some(la)) = (
        &cal.before.landmarks_from_truth,
        &cal.after.landmarks_from_truth,
    ) {
        detail.say(&format!(
            "  before: {}\n  after:  {}",
            fmt_landmarks_from_truth(lb),
            fmt_landmarks_from_truth(la)
        ));
    }
    say_runs(detail, prep, cal);
    if let Some(w) = &cal.leave_one_out_warning {
        detail.say(&format!("warning: {w}"));
    }
    let warnings = cal.warnings();
    if let Some(dir) = &c.report {
        if let Err(e) =
            crate::report::fit::fit_report(dir, r, &prep.runs, cal, &answer, &warnings, &doc)
        {
            return bad(e);
        }
        out.say(&format!("report: {}", dir.join("index.html").display()));
    }
    if let Some(path) = export {
        if let Err(e) = export_fit(out, &c.spec, r, res, path, &cal.unusable) {
            return bad(e);
        }
    }
    match out.json(c.json.as_deref(), &doc) {
        Ok(()) if cal.unusable.is_empty() => ExitCode::SUCCESS,
        Ok(()) => ExitCode::from(1),
        Err(e) => bad(e),
    }
}

/// The calibration's headline: what was fitted, the error before and after,
/// and each parameter's estimate.
fn say_calibration(out: &Out, prep: &Loaded, res: &FitResult, before: &Errors, after: &Errors) {
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
        // compare scores from the measured start, so its figure differs
        out.say("  (each dead-reckoned from the runs' start headings as refined for its parameters, as the fit scores them; `compare` starts from the measured ones)");
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

/// The judgement of the calibration: its warnings, what the whole-run
/// error's growth means, and why it cannot be used, if it cannot (said
/// plainly, never shown as a success).
fn say_judgement(out: &Out, cal: &Calibrated) {
    for w in &cal.fit.warnings[..cal.warnings_before_growth] {
        out.say(&format!("warning: {w}"));
    }
    match &cal.growth {
        Some(Growth::Note(n)) => out.say(&format!("note: {n}")),
        Some(Growth::Warning(w)) => out.say(&format!("warning: {w}")),
        None => {}
    }
    for u in &cal.unusable {
        out.say(&format!("FIT UNUSABLE: {u}"));
    }
    if !cal.unusable.is_empty() {
        out.say("  no parameter values make this model follow these logs: it is likely missing a physical effect (`kinegen diagnose` with the same --spec and --data names it)");
    }
}

/// Each run's errors before and after (the fitted ones, then the held-out
/// ones, with a warning where the calibration does worse on them), said as
/// a table when there are several.
fn say_runs(out: &Out, prep: &Loaded, cal: &Calibrated) {
    if let Some(h) = &cal.holdout {
        let (hb, ha) = (&h.before, &h.after);
        out.say(&format!(
            "  holdout before: {}\n  holdout after:  {}",
            fmt_errors(&hb.errors),
            fmt_errors(&ha.errors)
        ));
        if let Some(w) = &h.worse {
            out.say(&format!("warning: {w}"));
        }
    }
    if prep.runs.len() + prep.holdout.len() > 1 {
        // the first column as wide as the longest path, so the figures line up
        let width = (prep.runs.iter())
            .chain(&prep.holdout)
            .map(|r| r.path.chars().count())
            .max()
            .unwrap_or(0)
            .max(40);
        out.say(&format!(
            "  {:<width$} {:>8} {:>10} {:>10} {:>12}",
            "run", "role", "RMSE m", "final m", "before m"
        ));
        // the fitted runs, then the held-out ones: each run's errors after, and before
        let say = |runs: &[Run], before: &[Errors], after: &[Errors], role: &str| {
            for (run, (b, a)) in runs.iter().zip(before.iter().zip(after)) {
                out.say(&format!(
                    "  {:<width$} {:>8} {:>10.4} {:>10.4} {:>12.4}",
                    run.path, role, a.rmse, a.final_position_error_m, b.rmse,
                ));
            }
        };
        say(
            &prep.runs,
            &cal.before.per_run,
            &cal.after.per_run,
            "fitted",
        );
        if let Some(h) = &cal.holdout {
            say(
                &prep.holdout,
                &h.before.per_run,
                &h.after.per_run,
                "held out",
            );
        }
    }
}

/// `--export FORMAT PATH`: the calibration written for the robot, unless
/// it is unusable (then said, not written).
fn export_fit(
    out: &Out,
    spec: &Path,
    r: &Runner,
    res: &FitResult,
    export: &Export,
    unusable: &[String],
) -> Result<(), String> {
    let (text, path) = match export {
        Export::Ros2Yaml(p) => (crate::export::ros2_yaml(spec, r, res), p),
        Export::Spec(p) => (crate::export::fitted_spec(spec, r, res), p),
    };
    if !unusable.is_empty() {
        out.say(&format!(
            "not exported to {}: the fit is unusable",
            path.display()
        ));
        return Ok(());
    }
    text.and_then(|y| kinegen_model::files::write_atomic(path, &y).map_err(|e| e.to_string()))?;
    out.say(&format!("exported: {}", path.display()));
    Ok(())
}
