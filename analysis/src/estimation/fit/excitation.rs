//! What the logs' motion cannot tell, however well they are fitted (issue
//! 70, item 5).
//!
//! A log that turns one way only cannot separate a scale of the turn rate (a
//! track, a wheelbase, an axle length) from an offset of it (unequal wheel
//! radii, a steering offset): turning left, both add to the same drift.
//! Borenstein and Feng's UMBmark drives its square both ways for this
//! reason. On the real OptiOdom robots (../shared/real/optiodom-dev):
//!
//! - a calibration on one clockwise circle of the tricycle gave an axle of
//!   0.173 m and a steering offset of -0.038 rad (both circles: 0.157 m,
//!   -0.019 rad), and dead-reckoned the counter-clockwise circle worse than
//!   the nominal values (0.91 m against 0.76 m);
//! - single circle runs of the differential drive were fitted to a few
//!   millimetres, the wheelbase "determined" to 2-3%, and made the robot's
//!   other sessions dead-reckon up to 2.6x worse than its nominal values.
//!
//! The standard deviations cannot show it: the confusion is a bias of the
//! model, not noise. The turning is the model's own (its twist's yaw rate),
//! so a log without ground truth is judged too.
use super::nominal_prior::{excited_by, input_corners, Motion};
use crate::model_on_log::model::Runner;
use crate::model_on_log::run::Run;

/// Below this share of their turning the other way, logs turn one way only:
/// a tenth. The OptiOdom circles hold 95-99% one way, its squares and
/// figure-of-eight paths 50-85%.
const OTHER_WAY_SHARE: f64 = 0.1;

/// Logs that turn less than this in all (rad) barely turn at all, which the
/// turn-rate parameters' own standard deviations show: half a turn. (A full
/// circle, as the check had it before, let single runs of the OptiOdom omni3
/// square through: 0.8 turns, 95% of them one way, the calibration 1.7x worse
/// than the nominal values on the other sessions, and no warning.)
const SOME_TURNING_RAD: f64 = std::f64::consts::PI;

/// The window the turning is summed over before its sign is taken, s.
const WINDOW_S: f64 = 1.0;

/// How the logs turn: the heading the model's twist turns through, each way.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Turning {
    /// To the left (counter-clockwise), rad.
    pub left: f64,
    /// To the right (clockwise), rad.
    pub right: f64,
}

impl Turning {
    /// The turning of `runs` by the model's twist at `p` (its yaw rate over
    /// each step), taken over windows of [`WINDOW_S`]: an encoder's count
    /// more on one side than the other, step after step of a straight line,
    /// is noise that turns both ways and cancels within a window.
    pub fn of(r: &Runner, p: &[f64], runs: &[Run]) -> Turning {
        let tw = r.ir.twist();
        let mut t = Turning {
            left: 0.0,
            right: 0.0,
        };
        for run in runs {
            let (mut turned, mut elapsed) = (0.0, 0.0);
            for k in 0..run.steps() {
                let omega = r.eval(tw, &[&run.u[k], p]).get(2).copied().unwrap_or(0.0);
                if (omega * run.dt[k]).is_finite() {
                    turned += omega * run.dt[k];
                    elapsed += run.dt[k];
                }
                if elapsed >= WINDOW_S || k + 1 == run.steps() {
                    t.add(turned);
                    (turned, elapsed) = (0.0, 0.0);
                }
            }
        }
        t
    }

    fn add(&mut self, turned: f64) {
        if turned > 0.0 {
            self.left += turned;
        } else {
            self.right -= turned;
        }
    }

    /// Whether the logs turn, but one way only.
    pub fn one_way(&self) -> bool {
        let total = self.left + self.right;
        total >= SOME_TURNING_RAD && self.left.min(self.right) < OTHER_WAY_SHARE * total
    }
}

/// The warning for a calibration at `p` of `r`'s free parameters on `runs`
/// that turn one way only, where a scale and an offset could trade off: two
/// free parameters at least, one of them acting on the turn rate.
pub fn one_way_warning(r: &Runner, p: &[f64], runs: &[Run]) -> Option<String> {
    if r.free.len() < 2 {
        return None;
    }
    let turning = Turning::of(r, p, runs);
    if !turning.one_way() {
        return None;
    }
    let corners = input_corners(runs);
    let turn_rate: Vec<&str> = r
        .free
        .iter()
        .filter(|&&i| excited_by(r, p, &corners, i) == Some(Motion::Turning))
        .map(|&i| r.names[i].as_str())
        .collect();
    if turn_rate.is_empty() {
        return None;
    }
    let total = turning.left + turning.right;
    let (share, way, other) = if turning.left > turning.right {
        (turning.left / total, "counter-clockwise", "clockwise")
    } else {
        (turning.right / total, "clockwise", "counter-clockwise")
    };
    Some(format!(
        "the fitted runs turn one way: {:.0}% of their {total:.1} rad of turning is {way}. A scale and an offset of the turn rate (of {}) trade off in such runs, so the calibration may not hold for turns the other way: add a run that turns {other} (UMBmark drives both ways)",
        100.0 * share,
        turn_rate.join(", "),
    ))
}
