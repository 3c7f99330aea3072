//! Whose clock is late: the motion capture's, or the robot's commands'.
//!
//! A command the robot executes late (`input_delay`, `command_lag`) and a
//! motion capture that reports late (`time_offset`) move a pose-only log
//! alike: the model's track and the measured one are shifted against each
//! other either way, and the fits tell them apart by a hair (on five real
//! velocity-commanded robots, 0.1-2% of the error). Landmark sightings beside
//! the ground truth decide it without the motion model. The sightings are
//! stamped on the robot's clock, as its commands are: the model predicts
//! each from the track at its own time (see fit's landmark residuals). So if
//! the ground truth lags by tau, the pose the camera saw at t is the one the
//! ground truth reports at t + tau; if the commands are late instead, the
//! ground truth and the camera agree at the same instant. The shift that best
//! aligns the sightings with the ground truth measures the ground truth's
//! delay directly.
//!
//! It is measured on the whole log and its standard error taken by the
//! jackknife over the log's minutes (sighting errors persist for seconds, a
//! robot turns for tens of them: the sightings are not independent, the
//! minutes nearly are).
use crate::estimation::fit::SEGMENT_S;
use crate::logs::log::wrap;
use crate::model_on_log::interp::lerp3;
use crate::model_on_log::model::Runner;
use crate::model_on_log::robust::{median, robust_sd};
use crate::model_on_log::run::Run;
use kinegen_model::decl::ObservationRole::RangeBearing;
use rayon::prelude::*;
use serde::Serialize;

/// The shifts tried, s: up to this far either way (the catalogue's
/// `time_offset` is bounded at half a second).
const REACH_S: f64 = 1.0;

/// Spacing of the shifts tried, s; the minimum is refined between them.
const STEP_S: f64 = 0.01;

/// Fewest pieces of the log with sightings for a standard error to mean
/// anything (a log of about three minutes).
const MIN_PIECES: usize = 3;

/// Two-sided level at which a delay is contradicted: strict, as the folds'
/// one-sided level (see `folds::LEVEL`), for the same reason.
const LEVEL: f64 = 1e-3;

/// Residuals beyond this many robust standard deviations count linearly
/// (Huber): a sighting of the wrong landmark must not pull the shift.
const HUBER_K: f64 = 1.5;

/// How far the ground truth lags the landmark sightings, measured on a log.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SightingClock {
    /// The ground truth's delay behind the sightings, s (negative: ahead).
    pub lag: f64,
    /// Its standard error, s (jackknife over the pieces).
    pub std: f64,
    /// Pieces of the log ([`SEGMENT_S`] each) with sightings.
    pub pieces: usize,
    pub sightings: usize,
    /// The smallest difference it resolves, s: the critical multiple of
    /// `std` (Student's t at [`LEVEL`], `pieces - 1` degrees of freedom), and
    /// at least the log's median row interval (the ground truth is
    /// interpolated between rows).
    pub resolution: f64,
}

impl SightingClock {
    /// Whether a model whose ground truth lags the inputs by `delay` seconds
    /// contradicts the sightings.
    pub fn contradicts(&self, delay: f64) -> bool {
        (delay - self.lag).abs() > self.resolution
    }

    /// What the sightings say of a model that moves the ground truth's delay
    /// from `before` to `after` seconds: nothing when they agree with both.
    pub fn judge(&self, before: f64, after: f64) -> Option<ClockVerdict> {
        match (self.contradicts(before), self.contradicts(after)) {
            (_, true) => Some(ClockVerdict::Contradicted { delay: after }),
            (true, false) => Some(ClockVerdict::Confirmed { delay: after }),
            (false, false) => None,
        }
    }
}

/// What the sightings' clock says of a candidate that changes the ground
/// truth's delay.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(rename_all = "snake_case", tag = "verdict")]
pub enum ClockVerdict {
    /// The delay (s) the candidate needs is outside what the sightings allow.
    Contradicted { delay: f64 },
    /// The sightings put the ground truth late, and the candidate's delay
    /// (s) is what they measure: a late motion capture, not a late robot.
    Confirmed { delay: f64 },
}

impl ClockVerdict {
    /// What this verdict says of a spec's own measurement delay, the
    /// parameter `name`, calibrated to the verdict's delay (the CLI's and
    /// the report's sentence).
    pub fn of_spec_delay(&self, name: &str) -> String {
        match self {
            ClockVerdict::Contradicted { delay } => format!(
                "the spec's measurement delay `{name}` calibrates to {delay:.3} s, which the sightings contradict: the ground truth is not that late; a late command (input_delay) or a lag (command_lag) may be what it stands in for"
            ),
            ClockVerdict::Confirmed { delay } => format!(
                "the spec's measurement delay `{name}` calibrates to {delay:.3} s, as the sightings measure"
            ),
        }
    }
}

impl std::fmt::Display for SightingClock {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        // (a lag under half a millisecond reads as none: "-0.000 s before")
        let when = match self.lag {
            l if l.abs() < 5e-4 => "at".to_string(),
            l if l < 0.0 => format!("{:.3} s before", -l),
            l => format!("{l:.3} s after"),
        };
        write!(
            f,
            "the {} landmark sightings match the ground truth's pose {when} their own stamps (std {:.3} s over {} pieces of the log; resolves {:.3} s)",
            self.sightings, self.std, self.pieces, self.resolution
        )
    }
}

/// Why sightings beside a ground truth did not measure its lag.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(rename_all = "snake_case", tag = "reason")]
pub enum Unmeasured {
    /// Fewer than [`MIN_PIECES`] pieces of the log hold sightings: too few
    /// for a standard error.
    TooShort { pieces: usize },
    /// The best shift, on the whole log or without one of its pieces, lies at
    /// the end of the range tried: the sightings do not line up with the
    /// ground truth (another frame, another robot's sightings).
    NoMinimum { sightings: usize },
}

impl std::fmt::Display for Unmeasured {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Unmeasured::TooShort { pieces } => write!(
                f,
                "the landmark sightings fill {pieces} minute(s) of the log; timing the ground truth by them needs {MIN_PIECES}"
            ),
            Unmeasured::NoMinimum { sightings } => write!(
                f,
                "the {sightings} landmark sightings line up best with the ground truth {REACH_S} s or more away from their stamps: not the same frame or not the same robot? They do not time the ground truth"
            ),
        }
    }
}

/// Measure the ground truth's lag behind the sightings of `runs`, predicted
/// through `r`'s landmark observation with parameters `p`. None: no run has
/// both, or the spec has no landmark observation.
pub fn measure(r: &Runner, p: &[f64], runs: &[Run]) -> Option<Result<SightingClock, Unmeasured>> {
    r.ir.observation_kernels(RangeBearing)?;
    let shifts: Vec<f64> = {
        let n = (REACH_S / STEP_S).round() as i64;
        (-n..=n).map(|k| k as f64 * STEP_S).collect()
    };
    let (usable, pieces) = usable_sightings(runs);
    let piece_of: Vec<usize> = usable.iter().map(|u| u.2).collect();
    let occupied: Vec<usize> = {
        let set: std::collections::BTreeSet<usize> = piece_of.iter().copied().collect();
        set.into_iter().collect()
    };
    if usable.is_empty() {
        return None;
    }
    if occupied.len() < MIN_PIECES {
        return Some(Err(Unmeasured::TooShort {
            pieces: occupied.len(),
        }));
    }
    // (the costly part, a prediction per sighting and shift, only once the
    // log is known to be long enough)
    let residuals = shifted_residuals(r, p, runs, &usable, &shifts);
    let no_minimum = Unmeasured::NoMinimum {
        sightings: usable.len(),
    };
    // Each channel in units of its robust spread: first at no shift, then
    // again at the shift found (a ground truth 0.3 s late spreads the
    // bearings at no shift eight times wider than the camera's noise).
    let mut lag = 0.0;
    let mut cost = Vec::new();
    for _ in 0..2 {
        let at = nearest(&shifts, lag);
        let scale = [0, 1].map(|c| robust_sd(residuals[at].iter().map(|e| e[c])));
        if scale.iter().any(|s| s.is_nan() || *s <= 0.0) {
            return Some(Err(no_minimum));
        }
        cost = piece_costs(&residuals, &piece_of, pieces, scale);
        let Some(found) = minimum_without(&shifts, &cost, None) else {
            return Some(Err(no_minimum));
        };
        lag = found;
    }
    // jackknife over the pieces
    let Some(drop_one) = occupied
        .iter()
        .map(|&k| minimum_without(&shifts, &cost, Some(k)))
        .collect::<Option<Vec<f64>>>()
    else {
        return Some(Err(no_minimum));
    };
    let m = drop_one.len() as f64;
    let mean = drop_one.iter().sum::<f64>() / m;
    let std = ((m - 1.0) / m * drop_one.iter().map(|x| (x - mean).powi(2)).sum::<f64>()).sqrt();
    let row_interval = median(
        &mut runs
            .iter()
            .flat_map(|r| r.dt.iter().copied())
            .collect::<Vec<_>>(),
    );
    Some(Ok(SightingClock {
        lag,
        std,
        pieces: occupied.len(),
        sightings: usable.len(),
        resolution: (two_sided_critical(occupied.len() - 1) * std).max(row_interval),
    }))
}

/// The sightings every shift can be tried on, as (run, sighting, piece of
/// the log), and how many pieces the runs make: a run's sightings at least
/// [`REACH_S`] from its ends, in a run with ground truth.
fn usable_sightings(runs: &[Run]) -> (Vec<(usize, usize, usize)>, usize) {
    let mut usable = Vec::new();
    let mut pieces = 0;
    for (i, run) in runs.iter().enumerate() {
        if run.gt.is_none() {
            continue;
        }
        let (t0, t1) = (run.t[0], run.t[run.t.len() - 1]);
        let mut last = None;
        for (k, o) in run.landmarks.iter().enumerate() {
            if o.t - REACH_S >= t0 && o.t + REACH_S <= t1 {
                let piece = ((o.t - t0) / SEGMENT_S) as usize;
                last = last.max(Some(piece));
                usable.push((i, k, pieces + piece));
            }
        }
        pieces += last.map_or(0, |l| l + 1);
    }
    (usable, pieces)
}

/// The range and bearing residuals of the `usable` sightings predicted from
/// the ground truth shifted by each of `shifts`: [shift][sighting]. (The
/// shifts in parallel: the kernels are compiled code, no symbolica.)
fn shifted_residuals(
    r: &Runner,
    p: &[f64],
    runs: &[Run],
    usable: &[(usize, usize, usize)],
    shifts: &[f64],
) -> Vec<Vec<[f64; 2]>> {
    let Some(h) = r.ir.observation_kernels(RangeBearing).map(|o| o.value) else {
        return Vec::new();
    };
    shifts
        .par_iter()
        .map(|s| {
            usable
                .iter()
                .filter_map(|&(i, k, _)| {
                    let (run, o) = (&runs[i], &runs[i].landmarks[k]);
                    let gt = run.gt.as_ref()?;
                    let (j, a) = run.locate(o.t + s);
                    let x = lerp3(&gt[j], &gt[j + 1], a);
                    let u = &run.u[j.min(run.steps() - 1)];
                    let v = r.eval(h, &Runner::obs_args(h, &x, u, p, &[o.xl, o.yl]));
                    Some([o.range - v[0], wrap(o.bearing - v[1])])
                })
                .collect()
        })
        .collect()
}

/// The robust cost of each piece at each shift: [shift][piece].
fn piece_costs(
    residuals: &[Vec<[f64; 2]>],
    piece_of: &[usize],
    pieces: usize,
    scale: [f64; 2],
) -> Vec<Vec<f64>> {
    residuals
        .iter()
        .map(|res| {
            let mut row = vec![0.0; pieces];
            for (e, &k) in res.iter().zip(piece_of) {
                row[k] += huber(e[0] / scale[0]) + huber(e[1] / scale[1]);
            }
            row
        })
        .collect()
}

/// The shift that minimises the cost of every piece but `skip` (None: at an
/// end of the range).
fn minimum_without(shifts: &[f64], cost: &[Vec<f64>], skip: Option<usize>) -> Option<f64> {
    let total: Vec<f64> = cost
        .iter()
        .map(|row| row.iter().sum::<f64>() - skip.map_or(0.0, |k| row[k]))
        .collect();
    refined_minimum(shifts, &total)
}

/// The index of the shift nearest `s`.
fn nearest(shifts: &[f64], s: f64) -> usize {
    (0..shifts.len())
        .min_by(|&a, &b| (shifts[a] - s).abs().total_cmp(&(shifts[b] - s).abs()))
        .unwrap_or(0)
}

/// The Huber loss of a standardised residual.
fn huber(z: f64) -> f64 {
    let a = z.abs();
    if a <= HUBER_K {
        0.5 * a * a
    } else {
        HUBER_K * (a - 0.5 * HUBER_K)
    }
}

/// The minimum of `cost` over `shifts`, refined by the parabola through the
/// grid's best point and its neighbours; None when the best point is an end
/// of the grid (the minimum, if any, lies beyond it).
fn refined_minimum(shifts: &[f64], cost: &[f64]) -> Option<f64> {
    let k = (0..cost.len()).min_by(|&a, &b| cost[a].total_cmp(&cost[b]))?;
    if k == 0 || k + 1 == cost.len() {
        return None;
    }
    let (a, b, c) = (cost[k - 1], cost[k], cost[k + 1]);
    let curvature = a - 2.0 * b + c;
    let offset = if curvature > 0.0 {
        0.5 * (a - c) / curvature
    } else {
        0.0
    };
    Some(shifts[k] + offset.clamp(-0.5, 0.5) * (shifts[k + 1] - shifts[k]))
}

/// The two-sided critical value of Student's t at [`LEVEL`] for `dof`
/// degrees of freedom.
fn two_sided_critical(dof: usize) -> f64 {
    super::folds::student_t_quantile(dof, 1.0 - LEVEL / 2.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_minimum_is_refined_between_grid_points() {
        let shifts: Vec<f64> = (0..11).map(|k| k as f64 * 0.1).collect();
        let cost: Vec<f64> = shifts.iter().map(|s| (s - 0.43).powi(2)).collect();
        assert!((refined_minimum(&shifts, &cost).unwrap() - 0.43).abs() < 1e-9);
        // a cost still falling at the end has no minimum in the range
        let falling: Vec<f64> = shifts.iter().map(|s| -s).collect();
        assert_eq!(refined_minimum(&shifts, &falling), None);
    }

    #[test]
    fn a_delay_the_sightings_measure_is_confirmed_and_one_they_do_not_contradicted() {
        let on_time = SightingClock {
            lag: 0.01,
            std: 0.005,
            pieces: 10,
            sightings: 1000,
            resolution: 0.03,
        };
        // a late motion capture the sightings do not see
        assert_eq!(
            on_time.judge(0.0, 0.3),
            Some(ClockVerdict::Contradicted { delay: 0.3 })
        );
        // a small delay within what they resolve says nothing
        assert_eq!(on_time.judge(0.0, 0.02), None);
        let late = SightingClock {
            lag: 0.29,
            ..on_time
        };
        assert_eq!(
            late.judge(0.0, 0.3),
            Some(ClockVerdict::Confirmed { delay: 0.3 })
        );
        assert_eq!(
            late.judge(0.0, 0.1),
            Some(ClockVerdict::Contradicted { delay: 0.1 })
        );
    }

    #[test]
    fn critical_values_are_students_two_sided() {
        // tables: t(0.9995; 10) = 4.587
        assert!((two_sided_critical(10) - 4.587).abs() < 1e-3);
    }
}
