//! A run: one log as model steps (per-step inputs, step lengths) with its
//! measurements, and what follows from the run alone (where it rests, where a
//! time falls among its rows, its pieces). Reading logs into runs is
//! [`crate::model_on_log::dataset`]; everything that runs a model over a run sits above both.
use crate::logs::column::Column;
use crate::logs::rows::Inputs;

#[derive(Debug, Clone)]
pub struct Run {
    pub name: String,
    /// The log file as the user named it (runs are reported by path: two runs
    /// called `run1.csv` in different directories are different runs).
    pub path: String,
    pub t: Column<f64>,
    /// Step k goes from row k to row k+1.
    pub dt: Column<f64>,
    pub u: Inputs,
    /// Ground-truth pose per row, heading unwrapped.
    pub gt: Option<Column<[f64; 3]>>,
    /// Gyro yaw rate per row; row k+1 is compared with the model rate of step k.
    pub gyro: Option<Column<f64>>,
    /// Range-bearing observations of mapped landmarks during the run (may be empty).
    pub landmarks: Vec<LandmarkObs>,
    /// Which inputs are rates of cumulative columns (the others are absolute
    /// values, like a steering angle, which say nothing about standing still).
    pub rate_inputs: Vec<bool>,
    /// Per step, how much each absolute input (a steering angle) changes over it
    /// (0 for rates); `u` holds their mid-step values. Dead reckoning reads it
    /// to sub-step where a fast-changing input bends the twist within a step
    /// (see `deadreckon::substeps`). None: the model has no absolute input.
    pub swing: Option<Inputs>,
    /// The log file's line of row 0 (2, the row after the header; a piece's
    /// where it starts in its log): messages name rows by their line.
    pub first_line: usize,
}

/// One range-bearing observation, with the mapped landmark it refers to.
#[derive(Debug, Clone)]
pub struct LandmarkObs {
    pub t: f64,
    /// Shared, not owned: a run is copied whole when its commands are
    /// shifted by a delay or lag (`timeline::executed`), once per
    /// evaluation of a fit, and an owned id made each copy allocate once per
    /// sighting (7% of a real robot's diagnose in `perf`, with the frees).
    pub id: std::sync::Arc<str>,
    pub xl: f64,
    pub yl: f64,
    pub range: f64,
    pub bearing: f64,
}

/// The default `--max-gap`, s: a log is split into runs only at steps longer
/// than this. A few seconds: irregular loggers (velocity commands sent when
/// they change, 0.01-1.4 s apart) stay one run, while a logger that stopped
/// for longer is not bridged by holding its last command.
pub const DEFAULT_MAX_GAP_S: f64 = 3.0;

impl Run {
    pub fn steps(&self) -> usize {
        self.dt.len()
    }

    /// Where dead reckoning starts: the mean ground-truth pose over the rows before
    /// the inputs first change (the robot at rest), which averages out the motion
    /// capture noise that would otherwise rotate the whole track; row 0 if the robot
    /// moves at once. Origin when there is no ground truth.
    ///
    /// Without ground truth, the pose that places the landmarks seen during that
    /// rest (or the first 0.1 s) on the map, if at least two are seen.
    pub fn start_pose(&self) -> [f64; 3] {
        let rest_rows = self.rest_steps();
        let Some(g) = self.gt.as_ref().filter(|_| self.start_measured()) else {
            return pose_from_landmarks(&self.landmarks, self.start_window_end())
                .unwrap_or([0.0; 3]);
        };
        let rest = rest_rows.max(1).min(g.len());
        let mut m = [0.0; 3];
        for p in &g[..rest] {
            for i in 0..3 {
                m[i] += p[i] / rest as f64;
            }
        }
        m
    }

    /// How well the start heading is measured when the run starts at rest for
    /// half a second or more: the spread of the measured heading over the rest
    /// rows over sqrt(rows), its mean's standard error. None otherwise (one
    /// sample, or no ground truth).
    pub fn start_heading_std(&self) -> Option<f64> {
        let rest = self.rest_steps();
        let g = self.gt.as_ref().filter(|_| self.start_measured())?;
        if rest < 2 || self.t[rest] - self.t[0] < 0.5 {
            return None;
        }
        let n = rest.min(g.len()) as f64;
        let mean = g[..rest].iter().map(|p| p[2]).sum::<f64>() / n;
        let var = g[..rest].iter().map(|p| (p[2] - mean).powi(2)).sum::<f64>() / (n - 1.0);
        // a noiseless (simulated, quantised) heading still gets a finite weight
        Some((var.sqrt() / n.sqrt()).max(1e-6))
    }

    /// The range-bearing observations that see the start pose (see
    /// [`Run::start_window_end`]), if they fix it: two distinct landmarks.
    pub fn start_observations(&self) -> Option<Vec<&LandmarkObs>> {
        observations_until(&self.landmarks, self.start_window_end())
    }

    /// Until when observations still see the start pose: the end of the rest
    /// at the start, or the first 0.1 s when the robot moves at once.
    pub fn start_window_end(&self) -> f64 {
        let rest_rows = self.rest_steps();
        if rest_rows > 0 {
            self.t[rest_rows]
        } else {
            self.t[0] + 0.1
        }
    }

    /// Leading steps in which the robot stands still: every rate input is zero
    /// (a steering angle may read anything while the robot stands).
    /// A model without rate inputs (speeds given directly) stands when all are zero.
    pub fn rest_steps(&self) -> usize {
        let any_rate = self.rate_inputs.iter().any(|r| *r);
        self.u
            .iter()
            .take_while(|u| {
                u.iter().enumerate().all(|(i, v)| {
                    *v == 0.0 || (any_rate && !self.rate_inputs.get(i).copied().unwrap_or(true))
                })
            })
            .count()
    }

    /// Where time `s` falls among the rows: (j, a) with t_j <= s < t_{j+1} and
    /// a = (s - t_j)/(t_{j+1} - t_j), j clamped to the first and last interval (so
    /// a may fall outside [0, 1] before the start or after the end: linear
    /// extrapolation).
    pub fn locate(&self, s: f64) -> (usize, f64) {
        let n = self.t.len();
        let j = self.t.partition_point(|t| *t <= s).clamp(1, n - 1) - 1;
        (j, (s - self.t[j]) / (self.t[j + 1] - self.t[j]))
    }

    /// Rows `a..b` (inclusive of b-1) as a run of their own, sharing this run's
    /// columns.
    pub fn slice(&self, a: usize, b: usize) -> Run {
        Run {
            name: format!("{}[{a}..{b}]", self.name),
            path: self.path.clone(),
            t: self.t.slice(a, b),
            dt: self.dt.slice(a, b - 1),
            u: self.u.slice(a, b - 1),
            gt: self.gt.as_ref().map(|g| g.slice(a, b)),
            gyro: self.gyro.as_ref().map(|g| g.slice(a, b)),
            landmarks: self
                .landmarks
                .iter()
                .filter(|o| o.t >= self.t[a] && o.t <= self.t[b - 1])
                .cloned()
                .collect(),
            rate_inputs: self.rate_inputs.clone(),
            swing: self.swing.as_ref().map(|s| s.slice(a, b - 1)),
            first_line: self.first_line + a,
        }
    }

    /// The run as a log at half its rate would give it: every other row, each
    /// step spanning two of this run's (rates averaged over both, absolute
    /// inputs from the samples that bound the pair). The measurements of the
    /// rows kept stay; the gyro, whose reading spans a step, is dropped.
    pub fn halved(&self) -> Run {
        let rows: Vec<usize> = (0..self.t.len()).step_by(2).collect();
        let width = self.u.width();
        let (mut u, mut swing) = (Vec::new(), Vec::new());
        let mut dt = Vec::with_capacity(rows.len());
        for w in rows.windows(2) {
            let k = w[0];
            let d = self.dt[k] + self.dt[k + 1];
            dt.push(d);
            for i in 0..width {
                if self.rate_inputs.get(i).copied().unwrap_or(true) {
                    u.push((self.u[k][i] * self.dt[k] + self.u[k + 1][i] * self.dt[k + 1]) / d);
                    swing.push(0.0);
                } else {
                    let s = |j: usize| self.swing.as_ref().map_or(0.0, |s| s[j][i]);
                    let (a, b) = (self.u[k][i] - s(k) / 2.0, self.u[k + 1][i] + s(k + 1) / 2.0);
                    u.push(0.5 * (a + b));
                    swing.push(b - a);
                }
            }
        }
        let steps = dt.len();
        Run {
            name: format!("{} at half rate", self.name),
            path: self.path.clone(),
            t: rows.iter().map(|&k| self.t[k]).collect(),
            dt: dt.into(),
            u: Inputs::from_flat(steps, width, u),
            gt: self
                .gt
                .as_ref()
                .map(|g| rows.iter().map(|&k| g[k]).collect()),
            gyro: None,
            landmarks: self.landmarks.clone(),
            rate_inputs: self.rate_inputs.clone(),
            swing: self
                .swing
                .as_ref()
                .map(|_| Inputs::from_flat(steps, width, swing)),
            // internal (the discretisation check): its rows are every other line
            first_line: self.first_line,
        }
    }

    /// The run cut at its gaps: steps longer than `max_gap` seconds (a logger
    /// that stopped, a dropped connection). Shorter gaps are bridged (commands
    /// hold, counter differences spread over the interval: a log at irregular
    /// times stays one run). Each piece of 3 rows or more becomes a run of its
    /// own, started from its own measured pose, with the warning that says
    /// where and what the split costs.
    ///
    /// Rows without a measurement (motion capture or gyro cells left empty:
    /// the tracker lost the robot) are cut out first, the same way: each
    /// stretch of complete rows is a run of its own.
    pub fn split_at_gaps(self, max_gap: f64) -> (Vec<Run>, Vec<String>) {
        let (pieces, mut warnings) = match self.split_at_missing() {
            (pieces, Some(w)) => (pieces, vec![w]),
            (pieces, None) => (pieces, Vec::new()),
        };
        let mut runs = Vec::new();
        for piece in pieces {
            let (split, warning) = piece.split_at_time_gaps(max_gap);
            runs.extend(split);
            warnings.extend(warning);
        }
        (runs, warnings)
    }

    /// Rows `a..b` as a run of their own, named by their time span (a piece
    /// of a log split at a gap).
    fn piece(&self, a: usize, b: usize) -> Run {
        let mut piece = self.slice(a, b);
        let span = format!("{:.2}-{:.2} s", self.t[a], self.t[b - 1]);
        piece.name = format!("{} ({span})", self.name);
        piece.path = format!("{} ({span})", self.path);
        piece
    }

    /// Whether row `k` lacks a measurement the run has (a NaN pose or gyro:
    /// an empty cell, see [`Run::split_at_gaps`]).
    pub fn missing(&self, k: usize) -> bool {
        self.gt.as_ref().is_some_and(|g| g[k][0].is_nan())
            || self.gyro.as_ref().is_some_and(|g| g[k].is_nan())
    }

    /// The stretches of rows with every measurement (see [`Run::split_at_gaps`]).
    fn split_at_missing(self) -> (Vec<Run>, Option<String>) {
        let n = self.t.len();
        let missing: Vec<usize> = (0..n).filter(|&k| self.missing(k)).collect();
        if missing.is_empty() {
            return (vec![self], None);
        }
        let mut pieces = Vec::new();
        let mut a = 0;
        for k in (0..=n).filter(|&k| k == n || self.missing(k)) {
            if k >= a + 3 {
                pieces.push(self.piece(a, k));
            }
            a = k + 1;
        }
        let warning = format!(
            "{}: {} row(s) without a measurement (empty or nan in the pose or gyro columns: {}): the rows between are used as {} run(s), each started from its own measured pose (stretches under 3 rows dropped); nothing is compared where nothing was measured",
            self.path,
            missing.len(),
            line_ranges(self.first_line, &missing),
            pieces.len()
        );
        (pieces, Some(warning))
    }

    /// [`Run::split_at_gaps`] for a job that ground truth only scores
    /// (localisation): the run is cut at its time gaps only, and rows without
    /// ground truth stay in it, said.
    pub fn split_at_time_gaps_only(self, max_gap: f64) -> (Vec<Run>, Vec<String>) {
        let missing: Vec<usize> = (0..self.t.len())
            .filter(|&k| self.gt.as_ref().is_some_and(|g| g[k][0].is_nan()))
            .collect();
        let mut warnings = Vec::new();
        if !missing.is_empty() {
            warnings.push(format!(
                "{}: {} row(s) without ground truth (empty or nan in the pose columns: {}): the filter runs through them, and only rows with ground truth are scored",
                self.path,
                missing.len(),
                line_ranges(self.first_line, &missing)
            ));
        }
        let (runs, warning) = self.split_at_time_gaps(max_gap);
        warnings.extend(warning);
        (runs, warnings)
    }

    /// The run with its measurements (ground truth, gyro) left out: the
    /// model on the inputs alone.
    pub fn inputs_only(&self) -> Run {
        Run {
            gt: None,
            gyro: None,
            ..self.clone()
        }
    }

    /// Whether the run's start is measured: ground truth over its first rows
    /// (the rest it starts with, or its first row). A run whose motion
    /// capture starts late is placed by its landmarks instead.
    pub fn start_measured(&self) -> bool {
        self.gt.as_ref().is_some_and(|g| {
            let rest = self.rest_steps().max(1).min(g.len());
            g[..rest].iter().all(|p| p.iter().all(|v| v.is_finite()))
        })
    }

    /// [`Run::split_at_gaps`] for the time between rows only.
    fn split_at_time_gaps(self, max_gap: f64) -> (Vec<Run>, Option<String>) {
        let gaps: Vec<usize> = (0..self.dt.len())
            .filter(|&k| self.dt[k] > max_gap)
            .collect();
        if gaps.is_empty() {
            return (vec![self], None);
        }
        let mut bounds = vec![0];
        bounds.extend(gaps.iter().map(|&k| k + 1));
        bounds.push(self.t.len());
        let pieces: Vec<Run> = bounds
            .windows(2)
            .filter(|w| w[1] - w[0] >= 3)
            .map(|w| self.piece(w[0], w[1]))
            .collect();
        let at: Vec<String> = gaps
            .iter()
            .take(5)
            .map(|&k| format!("{:.3} s after t = {:.3} s", self.dt[k], self.t[k]))
            .collect();
        let lost: f64 = gaps.iter().map(|&k| self.dt[k]).sum();
        // sightings in a gap (or in a dropped piece) belong to no run
        let unused = self.landmarks.len() - pieces.iter().map(|p| p.landmarks.len()).sum::<usize>();
        let warning = format!(
            "{}: {} gap(s) longer than --max-gap {max_gap} s ({}{}): used as {} run(s), each started from its own measured pose{}; the {lost:.1} s in the gaps are not dead-reckoned, so drift across them is not counted{} (a larger --max-gap bridges them)",
            self.path,
            gaps.len(),
            at.join(", "),
            if gaps.len() > 5 { ", ..." } else { "" },
            pieces.len(),
            if pieces.len() < gaps.len() + 1 { " (pieces under 3 rows dropped)" } else { "" },
            match unused {
                0 => String::new(),
                n => format!(", and the {n} landmark sighting(s) in them are not used"),
            }
        );
        (pieces, Some(warning))
    }

    /// Split a long run into pieces of about `seconds`, each dead-reckoned from its
    /// own measured start pose (a run shorter than twice that stays whole).
    pub fn segments(&self, seconds: f64) -> Vec<Run> {
        let dur = self.t.last().unwrap() - self.t[0];
        if dur < 2.0 * seconds || self.gt.is_none() {
            return vec![self.clone()];
        }
        let mut out = Vec::new();
        let mut a = 0;
        while a + 2 < self.t.len() {
            let mut b = a + 1;
            while b < self.t.len() && self.t[b] - self.t[a] < seconds {
                b += 1;
            }
            let b = if self.t.len() - b < 10 {
                self.t.len()
            } else {
                (b + 1).min(self.t.len())
            };
            out.push(self.slice(a, b));
            a = b - 1;
        }
        out
    }
}

/// The robot pose from landmarks seen while it stands still at the start (at
/// least two distinct landmarks before `t_until`): each observation places a
/// landmark in the robot frame, and the rigid transform that maps those points
/// onto the map is the pose (2-D Kabsch / Procrustes, closed form). Used when a
/// log has no ground truth.
pub fn pose_from_landmarks(obs: &[LandmarkObs], t_until: f64) -> Option<[f64; 3]> {
    let seen = observations_until(obs, t_until)?;
    pose_from_sightings(&seen, |_| [0.0; 3])
}

/// [`pose_from_landmarks`] for a robot that moved between its sightings:
/// `moved(o)` is its pose at sighting `o` in the frame of the pose sought
/// (odometry from it), so each sighting still places its landmark in that
/// frame.
pub fn pose_from_sightings(
    seen: &[&LandmarkObs],
    moved: impl Fn(&LandmarkObs) -> [f64; 3],
) -> Option<[f64; 3]> {
    if seen.is_empty() {
        return None;
    }
    let body: Vec<[f64; 2]> = seen
        .iter()
        .map(|o| {
            let [mx, my, mth] = moved(o);
            let (s, c) = (mth + o.bearing).sin_cos();
            [mx + o.range * c, my + o.range * s]
        })
        .collect();
    let world: Vec<[f64; 2]> = seen.iter().map(|o| [o.xl, o.yl]).collect();
    let n = seen.len() as f64;
    let mean = |v: &[[f64; 2]]| {
        [
            v.iter().map(|p| p[0]).sum::<f64>() / n,
            v.iter().map(|p| p[1]).sum::<f64>() / n,
        ]
    };
    let (mb, mw) = (mean(&body), mean(&world));
    let (mut sdot, mut scross) = (0.0, 0.0);
    for (b, w) in body.iter().zip(&world) {
        let (bx, by, wx, wy) = (b[0] - mb[0], b[1] - mb[1], w[0] - mw[0], w[1] - mw[1]);
        sdot += bx * wx + by * wy;
        scross += bx * wy - by * wx;
    }
    let th = scross.atan2(sdot);
    let (s, c) = th.sin_cos();
    Some([
        mw[0] - (c * mb[0] - s * mb[1]),
        mw[1] - (s * mb[0] + c * mb[1]),
        th,
    ])
}

/// The observations up to `t_until`, if they see at least two distinct
/// landmarks (what fixes a pose).
pub fn observations_until(obs: &[LandmarkObs], t_until: f64) -> Option<Vec<&LandmarkObs>> {
    let seen: Vec<&LandmarkObs> = obs.iter().filter(|o| o.t <= t_until).collect();
    let distinct: std::collections::HashSet<&str> = seen.iter().map(|o| &*o.id).collect();
    (distinct.len() >= 2).then_some(seen)
}

/// Rows (0-based, after the header) as the file's line ranges, the first
/// five: `lines 2000-2099, line 2300, ...`.
fn line_ranges(first_line: usize, rows: &[usize]) -> String {
    let mut stretches: Vec<(usize, usize)> = Vec::new();
    for &k in rows {
        match stretches.last_mut() {
            Some((_, b)) if *b + 1 == k => *b = k,
            _ => stretches.push((k, k)),
        }
    }
    let lines: Vec<String> = stretches
        .iter()
        .take(5)
        .map(|&(a, b)| {
            if a == b {
                format!("line {}", first_line + a)
            } else {
                format!("lines {}-{}", first_line + a, first_line + b)
            }
        })
        .collect();
    let more = if stretches.len() > 5 { ", ..." } else { "" };
    format!("{}{more}", lines.join(", "))
}

/// What unit tests build on: rows at times `t` with one row of inputs per
/// step (absolute inputs), and no measurements; a test sets the fields it
/// needs on the result.
#[cfg(test)]
impl Run {
    pub fn bare<R: AsRef<[f64]>>(t: Vec<f64>, u: impl IntoIterator<Item = R>) -> Run {
        let u: Inputs = u.into_iter().collect();
        Run {
            name: "r".into(),
            path: "r".into(),
            dt: t.windows(2).map(|w| w[1] - w[0]).collect(),
            rate_inputs: vec![false; u.width()],
            t: t.into(),
            u,
            gt: None,
            gyro: None,
            landmarks: Vec::new(),
            swing: None,
            first_line: 2,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pose_from_two_landmarks_is_exact() {
        let pose = [1.0, -2.0, 0.7];
        let marks = [("a", 4.0, 1.0), ("b", -1.0, 3.0), ("c", 0.0, -5.0)];
        let obs: Vec<LandmarkObs> = marks
            .iter()
            .map(|(id, x, y)| {
                let (dx, dy) = (x - pose[0], y - pose[1]);
                LandmarkObs {
                    t: 0.0,
                    id: (*id).into(),
                    xl: *x,
                    yl: *y,
                    range: dx.hypot(dy),
                    bearing: dy.atan2(dx) - pose[2],
                }
            })
            .collect();
        let got = pose_from_landmarks(&obs, 0.5).unwrap();
        for i in 0..3 {
            assert!((got[i] - pose[i]).abs() < 1e-12, "{got:?}");
        }
        assert!(pose_from_landmarks(&obs[..1], 0.5).is_none());
    }
}
