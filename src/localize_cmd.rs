//! `kinegen localize`: the EKF of seed 001 over logs with landmark observations
//! (one call to kinegen_analysis::applications::localize_request::localize_files), rendered
//! with its consistency checks as text, JSON, a report and a track.
use crate::analysis_cmd::{bad, Common};
use crate::output::Out;
use clap::Args;
use kinegen_analysis::applications::localize::reading::RangeReading;
use kinegen_analysis::applications::localize::timing::TimingEstimate;
use kinegen_analysis::applications::localize::{
    side, Bounds, EkfOptions, Localization, NeesParts, NoiseSource, Side, Spread, Summary,
};
use kinegen_analysis::applications::localize_document::localize_document;
use kinegen_analysis::applications::localize_request::{
    localize_files, LocalizeRequest, LocalizedFiles,
};
use kinegen_analysis::diagnosis::next_steps::add_effect_command;
use kinegen_analysis::model_on_log::files::Files;
use kinegen_analysis::model_on_log::load::Loaded;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Args, Debug)]
pub struct LocalizeArgs {
    /// Reject an observation whose normalised innovation squared exceeds this
    /// (chi-square with 2 degrees of freedom: 13.82 is its 99.9% point, which
    /// a consistent filter exceeds once in a thousand sightings; real
    /// cameras' errors have heavier tails than a Gaussian, and a tighter gate
    /// throws away good sightings with the bad: 9.21 is the 99% point).
    #[arg(long, default_value_t = kinegen_analysis::applications::localize::DEFAULT_GATE, value_parser = crate::analysis_cmd::positive)]
    pub gate: f64,
    /// Write the estimated track with its covariance (t, x, y, theta, var_x,
    /// cov_xy, var_y, var_theta) to this CSV (several runs: one after another,
    /// with a `run` column).
    #[arg(long)]
    pub track: Option<PathBuf>,
    /// Process-noise standard deviation NAME=SIGMA (repeatable), in the spec's
    /// form for that `[[noise]]` (a density where its unit says `/sqrt(Hz)`,
    /// per row otherwise). With every `[[noise]]` given the filter runs as
    /// given, with the spec's observation sigmas; otherwise what is not given
    /// is estimated from the log.
    #[arg(long)]
    pub noise: Vec<String>,
    /// Use the spec's `[[noise]]` sigmas and observation sigmas as written
    /// instead of estimating the noise from the log.
    #[arg(long)]
    pub spec_noise: bool,
    /// Also run the fixed-interval RTS smoother (offline: every estimate uses
    /// the sightings after it too); its track goes to --track and the report.
    #[arg(long)]
    pub smooth: bool,
    /// Noise sweep: drive the first log's robot again with
    /// each [[noise]] sigma in turn raised from 0.001 to 0.1, re-observe its
    /// landmarks, and report the EKF's position error for each.
    #[arg(long)]
    pub sweep: bool,
}

pub fn run(c: Common, a: &LocalizeArgs) -> ExitCode {
    let out = Out::new(c.json.as_deref());
    if let Some(t) = &a.track {
        if let Err(e) = crate::output::check_writable("--track", t) {
            return bad(e);
        }
    }
    if let Err(e) = crate::output::check_outputs(c.json.as_deref(), c.report.as_deref()) {
        return bad(e);
    }
    if let Err(e) = c.check_repeated_logs() {
        return bad(e);
    }
    let options = match ekf_options(a) {
        Ok(o) => o,
        Err(e) => return bad(e),
    };
    let request = LocalizeRequest {
        files: Files {
            sources: &c.sources(),
            effect_dirs: &c.catalogue.effects,
        },
        options,
        sweep: a.sweep,
        for_report: c.report.is_some(),
    };
    let progress = crate::analysis_cmd::read_progress(crate::analysis_cmd::quiet(&c));
    let said = |prep: &Loaded| {
        crate::analysis_cmd::say_read_warnings(&out, &prep.warnings, c.verbose);
    };
    match localize_files(
        &request,
        crate::ir_source::analysis_deriver(),
        &progress,
        &said,
    ) {
        Ok(done) => render(&c, a, &out, &done),
        Err(e) => bad(e.to_string()),
    }
}

/// The localisation said as text, written as JSON, a report and the
/// `--track` CSV.
fn render(c: &Common, a: &LocalizeArgs, out: &Out, files: &LocalizedFiles) -> ExitCode {
    let LocalizedFiles {
        loaded: prep,
        localized: done,
        sweep,
        unseen_landmarks,
        figures,
        ..
    } = files;
    if let Some(w) = unseen_landmarks {
        if c.verbose {
            eprintln!("warning: {w}");
        } else {
            for l in crate::output::warning_lines(w, 2) {
                eprintln!("{l}");
            }
        }
    }
    let r = &prep.runner;
    let (noise, note) = (&done.noise, &done.note);
    // the answer: said by default, and the report's first box
    let runs: Vec<&kinegen_analysis::model_on_log::run::Run> =
        prep.runs.iter().chain(&prep.holdout).collect();
    let kept = Out::keeping();
    crate::localize_text::say_summary(
        &kept,
        &r.ir.name,
        &runs,
        done,
        reading_step(c, noise, &r.ir),
    );
    let answer = kept.lines();
    if !c.verbose {
        answer.iter().for_each(|l| out.say(l));
    }
    // the detail: said with -v, in the JSON either way
    let out_all = out;
    let out = &out.detail(c.verbose);
    out.say(note);
    let base = kinegen_analysis::model_on_log::landmarks::sigma(r);
    let whose = if kinegen_analysis::model_on_log::landmarks::declares_sigma(r) {
        "the spec's"
    } else {
        "the defaults'"
    };
    for line in noise.describe(base, whose) {
        out.say(&format!("  {line}"));
    }
    if let Some(advice) = reading_advice(c, noise, &r.ir) {
        out.say(&format!("  {advice}"));
    }
    // the report's noise table: the noise, and the delay it was estimated with
    let mut described = noise.describe(base, whose);
    for d in &done.timing {
        out.say(&say_timing(d));
        described.push(say_timing(d));
    }
    let mut locs = Vec::new();
    let mut csv = String::from("run,t,x,y,theta,var_x,cov_xy,var_y,var_theta\n");
    for (run, (loc, summary)) in prep.runs.iter().chain(&prep.holdout).zip(&done.runs) {
        say_run(out, run, loc, summary, a.gate);
        csv += &track_rows(run, loc);
        locs.push((run, loc, summary));
    }
    let doc = localize_document(files);
    if !sweep.is_empty() {
        say_sweep(out, &locs[0].0.path, sweep);
    }
    if let Some(dir) = &c.report {
        let pages: Vec<crate::report::localize::RunPage> = (locs.iter().zip(figures))
            .map(
                |(&(run, loc, summary), figures)| crate::report::localize::RunPage {
                    run,
                    loc,
                    summary,
                    figures,
                },
            )
            .collect();
        if let Err(e) = crate::report::localize::localize_report(
            dir,
            &pages,
            &described,
            sweep,
            &answer,
            &prep.warnings,
            &doc,
        ) {
            return bad(e);
        }
        out_all.say(&format!("report: {}", dir.join("index.html").display()));
    }
    if let Some(t) = &a.track {
        if let Err(e) = kinegen_model::files::write_atomic(t, &csv) {
            return bad(e);
        }
        out_all.say(&format!("track: {}", t.display()));
    }
    out_all.finish(c.json.as_deref(), &doc)
}

/// The `--track` CSV rows of a run: the estimate (smoothed with --smooth)
/// and its covariance at every row.
fn track_rows(run: &kinegen_analysis::model_on_log::run::Run, loc: &Localization) -> String {
    let (track, cov) = loc
        .smoothed
        .clone()
        .unwrap_or((loc.track.clone(), loc.cov.clone()));
    let mut csv = String::new();
    for (k, (x, p)) in track.iter().zip(&cov).enumerate() {
        csv += &format!(
            "{},{},{},{},{},{},{},{},{}\n",
            run.path,
            run.t[k],
            x[0],
            x[1],
            x[2],
            p[(0, 0)],
            p[(0, 1)],
            p[(1, 1)],
            p[(2, 2)]
        );
    }
    csv
}

/// The noise sweep's table (seed 001 Figs 6-7) and which uncertainty costs most.
fn say_sweep(out: &Out, path: &str, sweep: &[kinegen_analysis::applications::sweep::SweepPoint]) {
    out.say(&format!(
        "noise sweep on {} ({} simulated repetitions per level): EKF position RMSE (m)",
        path,
        kinegen_analysis::applications::sweep::SEEDS
    ));
    let mut names: Vec<&str> = sweep.iter().map(|p| p.noise.as_str()).collect();
    names.dedup();
    out.say(&format!(
        "  {:<10}{}",
        "sigma",
        names.iter().map(|n| format!("{n:>12}")).collect::<String>()
    ));
    for level in kinegen_analysis::applications::sweep::LEVELS {
        let row: String = names
            .iter()
            .map(|n| {
                let p = sweep
                    .iter()
                    .find(|p| p.noise == *n && p.sigma == level)
                    .unwrap();
                format!("{:>12.4}", p.position_rmse_m)
            })
            .collect();
        out.say(&format!("  {level:<10}{row}"));
    }
    let top = |n: &str| {
        sweep
            .iter()
            .filter(|p| p.noise == n)
            .map(|p| p.position_rmse_m)
            .fold(0.0, f64::max)
    };
    let mut ranked: Vec<(&str, f64)> = names.iter().map(|n| (*n, top(n))).collect();
    ranked.sort_by(|a, b| b.1.total_cmp(&a.1));
    if let [(worst, w), .., (least, l)] = ranked.as_slice() {
        out.say(&format!(
            "  at the largest sigma, uncertainty in `{worst}` costs {:.1}x the position error of uncertainty in `{least}`",
            w / l.max(1e-12)
        ));
    }
}

/// The filter's options from the arguments (checked against the spec by
/// the library: `--noise` names and signs, whether the input delay is
/// estimated).
fn ekf_options(a: &LocalizeArgs) -> Result<EkfOptions, String> {
    Ok(EkfOptions {
        gate: a.gate,
        noise_sigma: kinegen_analysis::model_on_log::model::parse_pairs("--noise", &a.noise)
            .map_err(|e| e.to_string())?,
        noise: if a.spec_noise {
            NoiseSource::Spec
        } else {
            NoiseSource::Estimate
        },
        smooth: a.smooth,
        ..EkfOptions::default()
    })
}

/// A statistic's spread, one phrase: its median against chi-square's, and
/// its share beyond the 95% point.
fn fmt_spread(x: &Spread) -> String {
    format!(
        "median {:.2} (chi-square's {:.2}), {:.1}% beyond its 95% point {:.2} (5% expected)",
        x.median,
        x.chi2_median,
        100.0 * x.beyond_95,
        x.point_95
    )
}

/// A mean NIS or NEES against its bounds, and what that says of `who` (the
/// filter, or the smoother whose covariance `--track` writes); the bounds
/// count the `values` (rows, sightings) as the independent ones they are
/// worth.
fn verdict(m: Option<f64>, b: Option<Bounds>, values: &str, who: &str) -> String {
    let (Some(m), Some(b), Some(s)) = (m, b, side(m, b)) else {
        return "n/a".into();
    };
    let (lo, hi) = (b.lo, b.hi);
    let worth = format!("the {values} worth {:.0} independent ones", b.independent);
    match s {
        Side::Below => format!(
            "{m:.2} (below its 95% bounds {lo:.2}..{hi:.2}, {worth}: the {who} is pessimistic)"
        ),
        Side::Above => format!(
            "{m:.2} (above its 95% bounds {lo:.2}..{hi:.2}, {worth}: the {who} is overconfident)"
        ),
        Side::Within => format!("{m:.2} (within its 95% bounds {lo:.2}..{hi:.2}, {worth})"),
    }
}

fn say_run(
    out: &Out,
    run: &kinegen_analysis::model_on_log::run::Run,
    loc: &Localization,
    s: &Summary,
    gate: f64,
) {
    out.say(&format!(
        "{}: EKF over {} steps ({:.1} s); {} landmark observations used, {} rejected by the gate (NIS > {gate}){}",
        run.path,
        run.steps(),
        run.t.last().unwrap() - run.t[0],
        loc.accepted,
        loc.rejected,
        if loc.outside > 0 {
            format!(", {} outside the log's time span", loc.outside)
        } else {
            String::new()
        }
    ));
    if let (Some(e), Some(d)) = (s.rmse, s.dead_reckoning) {
        out.say(&format!(
            "  position RMSE {e:.4} m (dead reckoning with the same model: {d:.4} m)"
        ));
    }
    out.say(&format!(
        "  mean NIS  {}",
        verdict(s.nis, s.nis_bounds, "sightings", "filter")
    ));
    if let Some(line) = crate::report::localize::say_gate_tail(s) {
        out.say(&format!("    {line}"));
    }
    out.say(&format!(
        "  mean NEES {}",
        verdict(s.nees, s.nees_bounds, "rows", "filter")
    ));
    if let Some(n) = s.truth_noise {
        out.say(&format!(
            "    (against the ground truth with its own noise counted: {:.2} mm, {:.2} mrad, from its third differences)",
            1e3 * n[0],
            1e3 * n[2]
        ));
    }
    for (name, spread) in [("NIS ", s.nis_spread), ("NEES", s.nees_spread)] {
        if let Some(x) = spread {
            out.say(&format!("    {name} {}", fmt_spread(&x)));
        }
    }
    if let Some(p) = s.nees_parts {
        out.say(&format!("    {}", say_parts(&p)));
    }
    if let Some(line) = crate::report::localize::say_consistency(s) {
        out.say(&format!("    {line}"));
    }
    if let Some(x) = s.smoothed {
        out.say(&format!(
            "  smoothed (RTS): position RMSE {}, mean NEES {}",
            x.rmse.map_or("n/a".into(), |e| format!("{e:.4} m")),
            verdict(x.nees, x.nees_bounds, "rows", "smoother")
        ));
    }
    let last = loc.cov.last().unwrap();
    out.say(&format!(
        "  final standard deviations: x {:.4} m, y {:.4} m, theta {:.4} rad",
        last[(0, 0)].sqrt(),
        last[(1, 1)].sqrt(),
        last[(2, 2)].sqrt()
    ));
}

/// The NEES's parts: which belief is wrong, and when.
fn say_parts(p: &NeesParts) -> String {
    let (pos, head) = (p.position, p.heading);
    format!(
        "NEES of the position alone {:.2} (bounds {:.2}..{:.2}), of the heading alone {:.2} (bounds {:.2}..{:.2}); of the pose just after the sightings {:.2}, far from them {:.2} (half the rows each)",
        pos.0, pos.1.lo, pos.1.hi, head.0, head.1.lo, head.1.hi, p.near_sightings, p.far_from_sightings
    )
}

/// A command-timing parameter the filter ran with, and where it came from.
fn say_timing(d: &TimingEstimate) -> String {
    let what = d.timing.what();
    if d.estimate_s == d.spec_s {
        format!(
            "{what}: `{}` = {:.3} s as the spec says (no other value makes the sightings more likely)",
            d.name, d.spec_s
        )
    } else {
        format!(
            "{what}: `{}` = {:.3} s, estimated from the sightings with the noise (the spec says {:.3} s; -2 log-likelihood {:.1} lower; --set {}=SECONDS fixes it)",
            d.name, d.estimate_s, d.spec_s, d.gain, d.name
        )
    }
}

/// What to do with the range reading the filter estimated (none where it
/// read the spec's straight-line range): the `add-effect` that puts it into
/// the spec, or, where the spec reads range so already, a new calibration.
fn reading_advice(
    c: &Common,
    n: &kinegen_analysis::applications::localize::NoiseModel,
    ir: &kinegen_model::ir::ModelIr,
) -> Option<String> {
    let r = &n.range_reading;
    if r.is_straight() {
        return None;
    }
    const EFFECT: &str = RangeReading::EFFECT;
    if ir.effects.iter().any(|e| e == EFFECT) {
        return Some(format!(
            "the spec reads range so already ({EFFECT}): the line above is on top of the spec's own reading; `kinegen fit` with the sightings calibrates the spec's against the ground truth"
        ));
    }
    let (_, cmd) = reading_step(c, n, ir)?;
    Some(format!("{READING_WHY}\n    {cmd}"))
}

/// The range reading the filter estimated, as a step to take: why, and the
/// `add-effect` that puts it into the spec (None where the filter read
/// straight-line range, or the spec reads range so already).
fn reading_step(
    c: &Common,
    n: &kinegen_analysis::applications::localize::NoiseModel,
    ir: &kinegen_model::ir::ModelIr,
) -> Option<(String, String)> {
    let r = &n.range_reading;
    const EFFECT: &str = RangeReading::EFFECT;
    if r.is_straight() || ir.effects.iter().any(|e| e == EFFECT) {
        return None;
    }
    let values = r.parameters().map(|(k, v)| (k.to_string(), v)).into();
    let spec = c.spec.display().to_string();
    let cmd = add_effect_command(&spec, EFFECT, &values, &ir.name, &[]);
    let why = format!(
        "the camera reads range as {:.0}% depth along its axis, {:+.1}% long; to put it in the spec:",
        100.0 * r.depth_share,
        100.0 * r.scale
    );
    Some((why, cmd))
}

/// The verbose text's wording of the same step.
const READING_WHY: &str = "to read range so in the spec (then `fit` calibrates it):";
