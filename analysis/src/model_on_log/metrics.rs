//! How wrong is the model, and where: absolute trajectory error, relative pose
//! error over distance and time windows, gyro residuals, and which motion regimes
//! and segments carry the error.
use crate::model_on_log::model::Runner;
use crate::model_on_log::run::Run;
use crate::model_on_log::track_rows::{row_error, Cursor, Heading, Recipe, TrackRows};
use serde::Serialize;

#[derive(Debug, Clone, Serialize)]
pub struct RegimeShare {
    pub regime: String,
    pub time_s: f64,
    pub distance_m: f64,
    /// Position error accumulated while in this regime (m), and its share.
    pub position_error_growth_m: f64,
    pub position_share: f64,
    /// Heading error accumulated while in this regime (rad), and its share.
    pub heading_error_growth_rad: f64,
    pub heading_share: f64,
}

#[derive(Debug, Clone, Serialize)]
pub struct Segment {
    pub run: String,
    pub t_start: f64,
    pub t_end: f64,
    pub regime: String,
    /// Growth of the position error over the segment (m).
    pub position_error_growth_m: f64,
    pub heading_error_growth_rad: f64,
}

#[derive(Debug, Clone, Serialize, Default)]
pub struct Errors {
    /// Position RMSE over all rows (absolute trajectory error), m.
    pub rmse: f64,
    pub heading_rmse_rad: f64,
    /// Position error at the end of the run; over several runs, the root mean
    /// square of the runs' final errors (see `worst_final_position_error_m`).
    pub final_position_error_m: f64,
    /// Heading error at the end of the run (signed); over several runs, the root
    /// mean square of the runs' final heading errors.
    pub final_heading_error_rad: f64,
    /// The largest final position error over the runs.
    pub worst_final_position_error_m: f64,
    pub max_position_error_m: f64,
    pub max_error_at_s: f64,
    /// Relative pose error: translation drift per metre travelled, over 1 m windows.
    pub rpe_per_m: Option<f64>,
    /// Translation drift over 5 s windows, m.
    pub rpe_5s_m: Option<f64>,
    pub gyro_rmse_rad_s: Option<f64>,
    pub samples: usize,
}

/// Motion regime of a step from its body twist.
pub fn regime(tw: &[f64; 3], fast: f64) -> &'static str {
    let v = (tw[0] * tw[0] + tw[1] * tw[1]).sqrt();
    if v < 0.02 && tw[2].abs() < 0.05 {
        "standing"
    } else if v < 0.02 {
        "turn in place"
    } else if tw[1].abs() > 0.5 * v {
        "sideways"
    } else if tw[2].abs() < 0.1 {
        if v > fast {
            "straight fast"
        } else {
            "straight slow"
        }
    } else if tw[2] > 0.0 {
        "turn left"
    } else {
        "turn right"
    }
}

fn rel(a: &[f64; 3], b: &[f64; 3]) -> [f64; 2] {
    // b expressed in a's frame (translation only)
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let (c, s) = (a[2].cos(), a[2].sin());
    [c * dx + s * dy, -s * dx + c * dy]
}

/// What [`errors`] adds up over one run: summed, then divided once over all
/// the runs (or over each run alone, [`errors_each`]).
#[derive(Default)]
struct Sums {
    position_sq: f64,
    heading_sq: f64,
    rows: usize,
    gyro_sq: f64,
    gyro_rows: usize,
    rpe_distance: f64,
    rpe_distance_windows: usize,
    rpe_time: f64,
    rpe_time_windows: usize,
    /// The largest position error and when (s from the run's start).
    max: (f64, f64),
    /// The last row's (position, heading) error, for runs with ground truth.
    last: Option<(f64, f64)>,
}

/// Error summary over several runs (each with its own track).
pub fn errors(runs: &[(&Run, &dyn TrackRows)]) -> Errors {
    let sums: Vec<Sums> = runs.iter().map(|&(run, tr)| sums(run, tr)).collect();
    summary(&sums)
}

/// The errors of `run` dead-reckoned with parameters `p` from its measured
/// start (how a held-out run is scored), a figure that stops being a number
/// read as infinite: the worst.
pub fn from_measured_start(r: &Runner, p: &[f64], run: &Run) -> Errors {
    from_measured_starts(r, p, std::slice::from_ref(run))
}

/// [`from_measured_start`] over several runs together.
pub fn from_measured_starts(r: &Runner, p: &[f64], runs: &[Run]) -> Errors {
    let track = Recipe {
        r,
        p: p.to_vec(),
        offset: [0.0; 3],
        heading: Heading::Model,
    };
    let pairs: Vec<(&Run, &dyn TrackRows)> = runs
        .iter()
        .map(|run| (run, &track as &dyn TrackRows))
        .collect();
    let mut e = errors(&pairs);
    for v in [&mut e.rmse, &mut e.final_position_error_m] {
        if !v.is_finite() {
            *v = f64::INFINITY;
        }
    }
    e
}

/// [`errors`] over all the runs, and each run's own, from one reading of
/// each track.
pub fn errors_each(runs: &[(&Run, &dyn TrackRows)]) -> (Errors, Vec<Errors>) {
    let sums: Vec<Sums> = runs.iter().map(|&(run, tr)| sums(run, tr)).collect();
    let each = sums
        .iter()
        .map(|x| summary(std::slice::from_ref(x)))
        .collect();
    (summary(&sums), each)
}

/// One run's [`Sums`], in one pass over its track (and two cursors for the
/// far ends of the relative pose windows): a long log's track is not held.
fn sums(run: &Run, tr: &dyn TrackRows) -> Sums {
    let mut s = Sums::default();
    let gyro = run.gyro.as_ref();
    let Some(gt) = &run.gt else {
        if let Some(g) = gyro {
            for (k, row) in tr.rows(run).enumerate() {
                if let Some(w) = row.gyro {
                    s.gyro_sq += (w - g[k + 1]).powi(2);
                    s.gyro_rows += 1;
                }
            }
        }
        return s;
    };
    // RPE: windows of 1 m travelled (the distance between rows i and j
    // kept as a running sum) and of 5 s, each far end read by its cursor
    let step = |k: usize| (gt[k][0] - gt[k - 1][0]).hypot(gt[k][1] - gt[k - 1][1]);
    let (mut far_d, mut far_t) = (Cursor::new(tr, run), Cursor::new(tr, run));
    let (mut j, mut travelled, mut jt) = (0, 0.0, 0);
    let (mut by_distance, mut by_time) = (true, true);
    for (i, row) in tr.rows(run).enumerate() {
        let (pos, head) = row_error(&row.measured, &gt[i]);
        s.position_sq += pos * pos;
        s.heading_sq += head * head;
        s.rows += 1;
        if pos > s.max.0 {
            s.max = (pos, run.t[i] - run.t[0]);
        }
        s.last = Some((pos, head));
        if let (Some(g), Some(w)) = (gyro, row.gyro) {
            s.gyro_sq += (w - g[i + 1]).powi(2);
            s.gyro_rows += 1;
        }
        if by_distance {
            if i > 0 {
                travelled -= step(i);
            }
            if j < i {
                (j, travelled) = (i, 0.0);
            }
            while j < gt.len() && travelled < 1.0 {
                j += 1;
                if j < gt.len() {
                    travelled += step(j);
                }
            }
            match far_d.get(j).filter(|_| j < gt.len()) {
                Some(far) => {
                    let (a, b) = (rel(&gt[i], &gt[j]), rel(&row.measured, &far.measured));
                    s.rpe_distance +=
                        ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt() / travelled;
                    s.rpe_distance_windows += 1;
                }
                None => by_distance = false,
            }
        }
        if by_time {
            while jt < gt.len() && run.t[jt] - run.t[i] < 5.0 {
                jt += 1;
            }
            match far_t.get(jt).filter(|_| jt < gt.len()) {
                Some(far) => {
                    let (a, b) = (rel(&gt[i], &gt[jt]), rel(&row.measured, &far.measured));
                    s.rpe_time += ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt();
                    s.rpe_time_windows += 1;
                }
                None => by_time = false,
            }
        }
    }
    s.last = s.last.or(Some((0.0, 0.0)));
    s
}

/// The [`Errors`] of runs' [`Sums`] together.
fn summary(runs: &[Sums]) -> Errors {
    let mut e = Errors::default();
    let total = |f: fn(&Sums) -> f64| runs.iter().map(f).sum::<f64>();
    let count = |f: fn(&Sums) -> usize| runs.iter().map(f).sum::<usize>();
    for s in runs {
        if s.max.0 > e.max_position_error_m {
            (e.max_position_error_m, e.max_error_at_s) = s.max;
        }
    }
    let finals: Vec<(f64, f64)> = runs.iter().filter_map(|s| s.last).collect();
    match finals[..] {
        [] => {}
        [(pos, head)] => (e.final_position_error_m, e.final_heading_error_rad) = (pos, head),
        _ => {
            let rms = |f: fn(&(f64, f64)) -> f64| {
                (finals.iter().map(|x| f(x).powi(2)).sum::<f64>() / finals.len() as f64).sqrt()
            };
            e.final_position_error_m = rms(|x| x.0);
            e.final_heading_error_rad = rms(|x| x.1);
        }
    }
    e.worst_final_position_error_m = finals.iter().map(|x| x.0).fold(0.0, f64::max);
    let (n, gn) = (count(|s| s.rows), count(|s| s.gyro_rows));
    if n > 0 {
        e.rmse = (total(|s| s.position_sq) / n as f64).sqrt();
        e.heading_rmse_rad = (total(|s| s.heading_sq) / n as f64).sqrt();
    }
    e.samples = n.max(gn);
    let (dn, tn) = (
        count(|s| s.rpe_distance_windows),
        count(|s| s.rpe_time_windows),
    );
    e.rpe_per_m = (dn > 0).then(|| total(|s| s.rpe_distance) / dn as f64);
    e.rpe_5s_m = (tn > 0).then(|| total(|s| s.rpe_time) / tn as f64);
    e.gyro_rmse_rad_s = (gn > 0).then(|| (total(|s| s.gyro_sq) / gn as f64).sqrt());
    e
}

/// Most values a robust statistic of a whole log is taken from (the median
/// moving speed, a twist quantile): every k-th step of a longer log, so that
/// what it keeps does not grow with the log.
pub const SAMPLE: usize = 100_000;

/// Steps between the values kept of `steps` steps (see [`SAMPLE`]).
pub fn sample_every(steps: usize) -> usize {
    steps.div_ceil(SAMPLE).max(1)
}

/// The body twists of every step of the tracks, or of every k-th step of
/// long ones (see [`sample_every`]).
pub fn sampled_twists(runs: &[(&Run, &dyn TrackRows)]) -> Vec<[f64; 3]> {
    let every = sample_every(runs.iter().map(|(run, _)| run.steps()).sum());
    runs.iter()
        .flat_map(|&(run, tr)| tr.rows(run).filter_map(|row| row.twist))
        .step_by(every)
        .collect()
}

/// Worst segments [`where_it_fails`] reports.
const WORST_SEGMENTS: usize = 5;

/// Which regimes carry the error growth, and the worst 1 s segments. Two
/// passes over each track (the median moving speed that splits fast from
/// slow, then the regimes); only the worst segments so far are kept.
pub fn where_it_fails(runs: &[(&Run, &dyn TrackRows)]) -> (Vec<RegimeShare>, Vec<Segment>) {
    let mut speeds: Vec<f64> = sampled_twists(runs)
        .iter()
        .map(|w| (w[0] * w[0] + w[1] * w[1]).sqrt())
        .filter(|v| *v > 0.02)
        .collect();
    speeds.sort_by(f64::total_cmp);
    let fast = speeds.get(speeds.len() / 2).copied().unwrap_or(0.0);
    let mut shares: Vec<RegimeShare> = Vec::new();
    let mut worst: Vec<Segment> = Vec::new();
    for &(run, tr) in runs {
        let Some(gt) = &run.gt else { continue };
        let mut rows = tr.rows(run);
        let Some(mut prev) = rows.next() else {
            continue;
        };
        let mut prev_err = row_error(&prev.measured, &gt[0]);
        let (mut seg_start, mut start_err) = (0, prev_err);
        // the regimes of the current segment's steps (its middle one names it)
        let mut seg_regimes: Vec<&'static str> = Vec::new();
        for (k, row) in rows.enumerate() {
            let err = row_error(&row.measured, &gt[k + 1]);
            let tw = prev.twist.unwrap_or([0.0; 3]);
            let reg = regime(&tw, fast);
            seg_regimes.push(reg);
            let s = match shares.iter_mut().position(|s| s.regime == reg) {
                Some(i) => &mut shares[i],
                None => {
                    shares.push(RegimeShare {
                        regime: reg.into(),
                        time_s: 0.0,
                        distance_m: 0.0,
                        position_error_growth_m: 0.0,
                        position_share: 0.0,
                        heading_error_growth_rad: 0.0,
                        heading_share: 0.0,
                    });
                    shares.last_mut().unwrap()
                }
            };
            s.time_s += run.dt[k];
            s.distance_m += (tw[0].powi(2) + tw[1].powi(2)).sqrt() * run.dt[k];
            s.position_error_growth_m += (err.0 - prev_err.0).max(0.0);
            s.heading_error_growth_rad += (err.1.abs() - prev_err.1.abs()).max(0.0);
            if run.t[k + 1] - run.t[seg_start] >= 1.0 || k + 1 == run.steps() {
                keep_worst(
                    &mut worst,
                    Segment {
                        run: run.name.clone(),
                        t_start: run.t[seg_start] - run.t[0],
                        t_end: run.t[k + 1] - run.t[0],
                        // dominant regime of the segment: the one of its middle step
                        regime: seg_regimes[(k - seg_start) / 2].into(),
                        position_error_growth_m: err.0 - start_err.0,
                        heading_error_growth_rad: err.1.abs() - start_err.1.abs(),
                    },
                );
                (seg_start, start_err) = (k + 1, err);
                seg_regimes.clear();
            }
            (prev, prev_err) = (row, err);
        }
    }
    let (tp, th): (f64, f64) = shares.iter().fold((0.0, 0.0), |a, s| {
        (
            a.0 + s.position_error_growth_m,
            a.1 + s.heading_error_growth_rad,
        )
    });
    for s in &mut shares {
        s.position_share = if tp > 0.0 {
            s.position_error_growth_m / tp
        } else {
            0.0
        };
        s.heading_share = if th > 0.0 {
            s.heading_error_growth_rad / th
        } else {
            0.0
        };
    }
    shares.sort_by(|a, b| b.position_share.total_cmp(&a.position_share));
    (shares, worst)
}

/// `seg` into `worst`, which holds the [`WORST_SEGMENTS`] largest position
/// error growths so far, largest first (earlier segments first among equals,
/// as a stable sort of them all would put them).
fn keep_worst(worst: &mut Vec<Segment>, seg: Segment) {
    let at = worst
        .iter()
        .position(|w| {
            w.position_error_growth_m
                .total_cmp(&seg.position_error_growth_m)
                .is_lt()
        })
        .unwrap_or(worst.len());
    if at < WORST_SEGMENTS {
        worst.insert(at, seg);
        worst.truncate(WORST_SEGMENTS);
    }
}

/// Path length of a planar track, sampled every `every` rows (so measurement
/// noise does not add length).
pub fn path_length(xy: impl Iterator<Item = (f64, f64)>, every: usize) -> f64 {
    let mut pts = xy.step_by(every.max(1));
    let Some(mut last) = pts.next() else {
        return 0.0;
    };
    pts.map(|p| {
        let d = (p.0 - last.0).hypot(p.1 - last.1);
        last = p;
        d
    })
    .sum()
}

/// Window over which [`turning`] adds heading changes, s: long enough that
/// the measurement noise of a heading adds little (about 1.5 rad over 9 min
/// of a 5 mrad tracker), short enough not to alias a robot turning in place
/// below pi/2 rad/s.
const TURN_WINDOW_S: f64 = 2.0;

/// Measured turning (rad) below which [`degenerate`] does not compare it: a
/// log that hardly turns measures mostly its noise.
const MIN_TURNING: f64 = 4.0 * std::f64::consts::PI;

/// Rows of `run` in about `seconds` (at least 1).
fn rows_per(run: &Run, seconds: f64) -> usize {
    let span = run.t.last().copied().unwrap_or(0.0) - run.t.first().copied().unwrap_or(0.0);
    let rate = (run.t.len().saturating_sub(1)) as f64 / span;
    if rate.is_finite() && rate > 0.0 {
        ((seconds * rate).round() as usize).max(1)
    } else {
        1
    }
}

/// Total turning of a heading series, rad: the absolute heading changes
/// between every `every`-th row, each wrapped to (-pi, pi].
pub fn turning(heading: impl Iterator<Item = f64>, every: usize) -> f64 {
    let mut h = heading.step_by(every.max(1));
    let Some(mut last) = h.next() else { return 0.0 };
    h.map(|x| {
        let d = crate::logs::log::wrap(x - last).abs();
        last = x;
        d
    })
    .sum()
}

/// A calibration that cannot be used: on some run the model's track barely
/// moves or turns (or runs away) while the measured one does (a tricycle
/// whose steering encoder reads 0.1 rad high calibrates to a 2 km
/// wheelbase: it travels as far as the robot but never turns). Returns what
/// happened, per run.
pub fn degenerate(runs: &[(&Run, &dyn TrackRows)]) -> Vec<String> {
    let mut out = Vec::new();
    for &(run, tr) in runs {
        let Some(g) = &run.gt else { continue };
        let every = (run.t.len() / 200).max(1);
        let measured = path_length(g.iter().map(|p| (p[0], p[1])), every);
        let model = path_length(tr.rows(run).map(|r| (r.measured[0], r.measured[1])), every);
        if measured > 0.5 && !(model > 0.2 * measured && model < 5.0 * measured) {
            out.push(format!("on {} the calibrated model travels {model:.2} m while the measurements travel {measured:.2} m", run.name));
        }
        let every = rows_per(run, TURN_WINDOW_S);
        let measured = turning(g.iter().map(|p| p[2]), every);
        let model = turning(tr.rows(run).map(|r| r.measured[2]), every);
        if measured > MIN_TURNING && !(model > 0.2 * measured && model < 5.0 * measured) {
            out.push(format!("on {} the calibrated model turns {model:.1} rad in all while the measurements turn {measured:.1} rad", run.name));
        }
    }
    out
}

/// Ratio by which a calibration may worsen the gyro residual before it is
/// named (a warning; twice this makes the fit unusable). A model that can
/// follow the robot fits the gyro as well as the track, or leaves it at the
/// noise (1.00x on simulated logs of every bundled model); one that lacks an
/// effect can still lower its track cost by giving up the turning the gyro
/// sees: a tricycle whose steering encoder read 0.1 rad high calibrated to a
/// wheelbase of 2 km, its gyro residual 4.6x that of the nominal values. (The
/// drift over 5 s windows is a coarser test, see [`DRIFT_WORSE`]: on clean
/// simulated tricycle logs the absolute-track fit's bias alone worsens it by
/// up to 1.5x.)
pub const GYRO_WORSE: f64 = 1.25;

/// Ratio by which a calibration may worsen the drift over 5 s windows before
/// it is unusable: clean simulated logs of every bundled and user spec reach
/// 1.54x from the absolute-track fit's own bias on random tricycle driving;
/// a user-written rover spec missing a 0.1 rad steering offset, 3.2x (its
/// wheel radius fitted 44% short, its whole-track error falling).
pub const DRIFT_WORSE: f64 = 2.0;

/// What a calibration made worse over short windows although its track error
/// may have fallen (see [`GYRO_WORSE`], [`DRIFT_WORSE`]): (unusable, warnings).
pub fn short_term_worse(before: &Errors, after: &Errors) -> (Vec<String>, Vec<String>) {
    let (mut unusable, warnings) = gyro_worse(before, after);
    if let (Some(b), Some(a)) = (before.rpe_5s_m, after.rpe_5s_m) {
        if a > DRIFT_WORSE * b {
            unusable.push(format!(
                "the calibrated model drifts more over 5 s windows ({b:.4} m -> {a:.4} m, x{:.2}): it traded short-term accuracy for the whole track",
                a / b
            ));
        }
    }
    (unusable, warnings)
}

fn gyro_worse(before: &Errors, after: &Errors) -> (Vec<String>, Vec<String>) {
    let (Some(b), Some(a)) = (before.gyro_rmse_rad_s, after.gyro_rmse_rad_s) else {
        return (vec![], vec![]);
    };
    let what = format!(
        "the calibrated model's yaw rate fits the gyro worse ({b:.5} -> {a:.5} rad/s, x{:.2})",
        a / b
    );
    if a > 2.0 * GYRO_WORSE * b {
        (vec![what], vec![])
    } else if a > GYRO_WORSE * b {
        (
            vec![],
            vec![format!(
                "{what}: the wheels and the gyro disagree in a way the model cannot reconcile"
            )],
        )
    } else {
        (vec![], vec![])
    }
}

/// Factor between an estimate and its (nonzero) nominal value beyond which the
/// estimate is named as implausible: a calibration from rough nominal values
/// moves a gain 5x (issue #11's tricycle), a dimension 10x is no longer the
/// robot's but compensation for something the model lacks.
pub const IMPLAUSIBLE_FACTOR: f64 = 10.0;

/// One line per parameter whose estimate is more than [`IMPLAUSIBLE_FACTOR`]
/// times its (nonzero) nominal value, or less than its inverse, from
/// `(name, nominal, estimate)`. A sign change is left alone: an offset may
/// take either sign, and bounds already keep sizes positive.
pub fn implausible<'a>(params: impl IntoIterator<Item = (&'a str, f64, f64)>) -> Vec<String> {
    params
        .into_iter()
        .filter_map(|(name, nominal, estimate)| {
            let ratio = estimate / nominal;
            (nominal != 0.0 && ratio.is_finite() && ratio >= 0.0 && !(1.0 / IMPLAUSIBLE_FACTOR..=IMPLAUSIBLE_FACTOR).contains(&ratio)).then(|| {
                format!(
                    "{name} = {estimate:.6} is {ratio:.3} times its nominal value {nominal}: no robot is that far from its drawing; the parameter is compensating for something the model lacks"
                )
            })
        })
        .collect()
}
