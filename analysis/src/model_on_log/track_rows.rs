//! A model's track over a run, read a row at a time. The error metrics, the
//! report and the coverage check read whole logs' tracks in order; a
//! [`Recipe`] computes its rows as they are read instead of holding them, so
//! what a command keeps of a log beyond the log itself does not grow with it
//! (a 1,000,000-row log's before and after tracks were 96 bytes a row, issue
//! 11 item 5). A reader that needs the rows again reads the track again: dead
//! reckoning without sensitivities is cheap next to a calibration. A computed
//! [`Track`] (a calibration's segments) reads the same way.
use crate::logs::log::wrap;
use crate::model_on_log::deadreckon::{
    gyro_at, gyro_step, reckoning_start, sensed_at, Stepper, Track,
};
use crate::model_on_log::interp::lerp3;
use crate::model_on_log::model::Runner;
use crate::model_on_log::run::Run;
use kinegen_model::decl::ObservationRole::{Pose, YawRate};
use kinegen_model::ir::Function;
use std::collections::VecDeque;
use std::sync::Arc;

/// One row of a track.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Row {
    /// The model's body pose.
    pub pose: [f64; 3],
    /// What the pose sensor should read (see [`Track::measured`]).
    pub measured: [f64; 3],
    /// The body twist of the step from this row to the next (None at the last row).
    pub twist: Option<[f64; 3]>,
    /// What the gyro should read over that step (see [`Track::gyro`]; None at
    /// the last row, and where the track predicts no gyro).
    pub gyro: Option<f64>,
}

/// A track over a run that can be read in order, as often as needed.
pub trait TrackRows: Sync {
    fn rows<'s>(&'s self, run: &'s Run) -> Box<dyn Iterator<Item = Row> + 's>;
}

/// (position error, heading error) of a measured pose against the logged one.
pub fn row_error(measured: &[f64; 3], gt: &[f64; 3]) -> (f64, f64) {
    (
        ((measured[0] - gt[0]).powi(2) + (measured[1] - gt[1]).powi(2)).sqrt(),
        wrap(measured[2] - gt[2]),
    )
}

/// A row of a track against the run's ground truth, as the reports draw it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RowAgainstTruth {
    /// Seconds from the run's start.
    pub t: f64,
    /// Where the pose sensor should read the model (see [`Row::measured`]).
    pub measured: [f64; 2],
    /// Distance from the measured position, m (None without ground truth).
    pub position_error: Option<f64>,
    /// The step to the next row's turn rate against the measured one (None
    /// at the last row and without ground truth).
    pub turn_rate: Option<TurnRateResidual>,
}

/// A step's model minus measured yaw rate (rad/s), beside what it may
/// depend on: the model's speed and turn rate and the measured heading.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TurnRateResidual {
    pub speed: f64,
    pub turn_rate: f64,
    pub heading: f64,
    pub residual: f64,
}

/// `tr`'s rows on `run` against its ground truth, read as they are computed.
pub fn against_truth<'s>(
    tr: &'s dyn TrackRows,
    run: &'s Run,
) -> impl Iterator<Item = RowAgainstTruth> + 's {
    let gt = run.gt.as_ref();
    tr.rows(run).enumerate().map(move |(k, row)| {
        let m = row.measured;
        let g = gt.map(|g| (g[k], g.get(k + 1)));
        RowAgainstTruth {
            t: run.t[k] - run.t[0],
            measured: [m[0], m[1]],
            position_error: g.map(|(g, _)| row_error(&m, &g).0),
            turn_rate: match (row.twist, g) {
                (Some(tw), Some((g, Some(next)))) => Some(TurnRateResidual {
                    speed: tw[0].hypot(tw[1]),
                    turn_rate: tw[2],
                    heading: wrap(g[2]),
                    residual: tw[2] - wrap(next[2] - g[2]) / run.dt[k],
                }),
                _ => None,
            },
        }
    })
}

impl TrackRows for Track {
    fn rows<'s>(&'s self, _run: &'s Run) -> Box<dyn Iterator<Item = Row> + 's> {
        let m = self.measured();
        Box::new((0..self.pose.len()).map(move |k| Row {
            pose: self.pose[k],
            measured: m[k],
            twist: self.twist.get(k).copied(),
            gyro: self.gyro.get(k).copied(),
        }))
    }
}

/// A yaw rate learned as a function of a step's inputs (seed 000 sec. 3.2's
/// virtual gyro, `crate::estimation::neural`).
pub type LearnedYawRate = Arc<dyn Fn(&[f64]) -> f64 + Send + Sync>;

/// What turns a [`Recipe`]'s track.
#[derive(Clone)]
pub enum Heading {
    /// The model's own dead reckoning ([`crate::model_on_log::deadreckon::run_from`]).
    Model,
    /// Gyrodometry with the logged gyro (seed 000 eq. 13-18,
    /// [`crate::model_on_log::deadreckon::gyrodometry`]).
    Gyro,
    /// Gyrodometry with a learned yaw rate of the inputs (seed 000 sec. 3.2).
    Learned(LearnedYawRate),
}

/// A track described rather than computed: the model, its parameters, the
/// start offset a calibration refined, and what turns it. Its rows are
/// computed each time they are read, equal to those of the [`Track`] the
/// same description computes at once.
#[derive(Clone)]
pub struct Recipe<'r> {
    pub r: &'r Runner,
    pub p: Vec<f64>,
    pub offset: [f64; 3],
    pub heading: Heading,
}

impl TrackRows for Recipe<'_> {
    fn rows<'s>(&'s self, run: &'s Run) -> Box<dyn Iterator<Item = Row> + 's> {
        Box::new(Streamed::new(self, run))
    }
}

/// The rows of a [`Recipe`] as they are computed. Holds the poses between
/// the instant the next measurement saw (a measurement delay reaches back or
/// ahead of its row) and the next row: a few rows, not the track.
struct Streamed<'s> {
    recipe: &'s Recipe<'s>,
    run: &'s Run,
    stepper: Stepper<'s>,
    twist_gyro: Option<&'s Function>,
    pose_obs: Option<&'s Function>,
    gyro_obs: Option<&'s Function>,
    delay: f64,
    /// Poses of rows `first..`, each with its step's twist once taken.
    window: VecDeque<([f64; 3], Option<[f64; 3]>)>,
    first: usize,
    next: usize,
    scratch: Vec<f64>,
}

impl<'s> Streamed<'s> {
    fn new(recipe: &'s Recipe<'s>, run: &'s Run) -> Self {
        let (r, p) = (recipe.r, recipe.p.as_slice());
        let start = match recipe.heading {
            Heading::Model => reckoning_start(r, p, run, recipe.offset).0,
            // as gyrodometry starts (crate::model_on_log::deadreckon::gyrodometry_with)
            _ => crate::model_on_log::deadreckon::model_start(r, p, run),
        };
        Streamed {
            recipe,
            run,
            stepper: Stepper::new(r, p, run, false, None),
            twist_gyro: (!matches!(recipe.heading, Heading::Model)).then(|| r.ir.twist_gyro()),
            pose_obs: r.ir.observation_kernels(Pose).map(|o| o.value),
            gyro_obs: r.ir.observation_kernels(YawRate).map(|o| o.value),
            delay: crate::model_on_log::timeline::delay(r, p),
            window: VecDeque::from([(start, None)]),
            first: 0,
            next: 0,
            scratch: Vec::new(),
        }
    }

    /// Computes the track up to row `row`.
    fn reach(&mut self, row: usize) {
        while self.first + self.window.len() <= row {
            let k = self.first + self.window.len() - 1;
            let x = self.window.back().expect("never empty").0;
            let (next, twist) = match (&self.recipe.heading, self.twist_gyro) {
                (Heading::Model, _) | (_, None) => self.stepper.step(k, x, |_| {}),
                (heading, Some(_)) => {
                    let w = match heading {
                        Heading::Learned(f) => f(&self.run.u[k]),
                        _ => self.run.gyro.as_ref().map_or(f64::NAN, |g| g[k + 1]),
                    };
                    gyro_step(
                        self.recipe.r,
                        &self.recipe.p,
                        self.run,
                        k,
                        w,
                        x,
                        &mut self.scratch,
                    )
                }
            };
            self.window.back_mut().expect("never empty").1 = Some(twist);
            self.window.push_back((next, None));
        }
    }

    fn pose(&self, row: usize) -> [f64; 3] {
        self.window[row - self.first].0
    }
}

impl Iterator for Streamed<'_> {
    type Item = Row;

    fn next(&mut self) -> Option<Row> {
        let (run, k) = (self.run, self.next);
        let steps = run.steps();
        if k > steps || run.t.is_empty() {
            return None;
        }
        self.reach((k + 1).min(steps));
        let (pose, twist) = self.window[k - self.first];
        // where the model was when measurement k was taken
        let (x, oldest) = if self.delay == 0.0 || run.t.len() < 2 {
            (pose, k)
        } else {
            let (j, a) = crate::model_on_log::timeline::model_instant(run, k, self.delay);
            self.reach(j + 1);
            (lerp3(&self.pose(j), &self.pose(j + 1), a), j)
        };
        let p = self.recipe.p.as_slice();
        let measured = sensed_at(self.recipe.r, self.pose_obs, p, run, k, &x);
        let gyro = match (&self.recipe.heading, twist) {
            (_, None) => None,
            (Heading::Model, Some(tw)) => run.gyro.is_some().then(|| {
                gyro_at(
                    self.recipe.r,
                    self.gyro_obs,
                    p,
                    &run.u[k],
                    &pose,
                    &tw,
                    &mut self.scratch,
                )
            }),
            (_, Some(tw)) => Some(tw[2]),
        };
        // rows before both this row's successor and this measurement's
        // instant are not read again (both move forward)
        while self.first < (k + 1).min(oldest) {
            self.window.pop_front();
            self.first += 1;
        }
        self.next += 1;
        Some(Row {
            pose,
            measured,
            twist,
            gyro,
        })
    }
}

/// Rows of a track read forward at chosen rows (a window's far end, an
/// observation's step), each computed once as the cursor passes it.
pub struct Cursor<'s> {
    rows: Box<dyn Iterator<Item = Row> + 's>,
    /// The last two rows passed, with the index of the later one.
    last: [Option<Row>; 2],
    at: Option<usize>,
}

impl<'s> Cursor<'s> {
    pub fn new(track: &'s dyn TrackRows, run: &'s Run) -> Self {
        Cursor {
            rows: track.rows(run),
            last: [None, None],
            at: None,
        }
    }

    /// Row `k`: at or after the row asked for before, or the one just before
    /// that.
    pub fn get(&mut self, k: usize) -> Option<Row> {
        while self.at.is_none_or(|a| a < k) {
            let row = self.rows.next()?;
            self.last = [self.last[1], Some(row)];
            self.at = Some(self.at.map_or(0, |a| a + 1));
        }
        match self.at {
            Some(a) if a == k => self.last[1],
            Some(a) if a == k + 1 => self.last[0],
            _ => None,
        }
    }
}

/// The first row where a track stops being a number, with what did: a
/// predicted pose or gyro reading that is not finite (parameters that divide
/// by almost zero, an input that overflows), or a pose error against the log
/// that overflows (a cell like 1e308). Results past such a row would be NaN or
/// infinite, so commands refuse instead.
pub fn first_non_finite(track: &dyn TrackRows, run: &Run) -> Option<(usize, String)> {
    let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
    // a row without a measurement (an empty cell) is cut out by
    // `Run::split_at_gaps`; a run read without that has no figures there
    if let Some(k) = (0..run.t.len()).find(|&k| run.missing(k)) {
        return Some((
            k,
            "no measurement in this row (an empty or nan pose or gyro cell): cut such rows out first (Run::split_at_gaps)".into(),
        ));
    }
    // a logged pose so large its square overflows is no position at all
    // (and the start pose, estimated from the first rows, inherits it)
    if let Some(g) = &run.gt {
        if let Some(k) = g
            .iter()
            .position(|p| p.iter().any(|v| !(v * v).is_finite()))
        {
            return Some((
                k,
                format!("the measured pose {:?} is out of any physical range", g[k]),
            ));
        }
    }
    let mut gyro_before: Option<f64> = None;
    for (k, row) in track.rows(run).enumerate() {
        let m = row.measured;
        if !finite(&m) {
            return Some((k, format!("the model's predicted pose is not finite ({m:?}): check the parameter values and the inputs up to this row")));
        }
        if let Some(g) = &run.gt {
            let e = [g[k][0] - m[0], g[k][1] - m[1]];
            if !(e[0].hypot(e[1])).is_finite() || !(e[0] * e[0] + e[1] * e[1]).is_finite() {
                return Some((
                    k,
                    format!(
                        "the pose error against the log overflows (measured pose {:?})",
                        g[k]
                    ),
                ));
            }
        }
        if let Some(w) = gyro_before.filter(|w| !w.is_finite() || w.abs() > 1e150) {
            return Some((k, format!("the model's predicted gyro reading is {w:.3e}: check the parameter values and the inputs")));
        }
        gyro_before = row.gyro;
    }
    None
}
