//! A log turned into model steps: per-step inputs (rates of cumulative columns,
//! held values of absolute ones), step lengths, and the measurements.
use crate::bag::{Detection, TopicMap};
use crate::landmarks::{pose_from_landmarks, LandmarkObs};
use crate::log::{unwrap, Log, LogError};
use crate::model::Runner;
use crate::rows::Inputs;
use kinegen_model::spec::{InputKind, ObservationRole};

#[derive(Debug, Clone)]
pub struct Run {
    pub name: String,
    /// The log file as the user named it (runs are reported by path: two runs
    /// called `run1.csv` in different directories are different runs).
    pub path: String,
    pub t: Vec<f64>,
    /// Step k goes from row k to row k+1.
    pub dt: Vec<f64>,
    pub u: Inputs,
    /// Ground-truth pose per row, heading unwrapped.
    pub gt: Option<Vec<[f64; 3]>>,
    /// Gyro yaw rate per row; row k+1 is compared with the model rate of step k.
    pub gyro: Option<Vec<f64>>,
    /// Range-bearing observations of mapped landmarks during the run (may be empty).
    pub landmarks: Vec<LandmarkObs>,
    /// Which inputs are rates of cumulative columns (the others are absolute
    /// values, like a steering angle, which say nothing about standing still).
    pub rate_inputs: Vec<bool>,
}

/// Shortest time step a log may have, s.
pub const MIN_STEP_S: f64 = 1e-6;

/// A wrapping counter (`wrap` bits) made continuous: each step's difference is
/// taken modulo 2^bits into [-2^(bits-1), 2^(bits-1)), then accumulated.
fn unwrap_counter(c: Vec<f64>, bits: Option<u32>) -> Vec<f64> {
    let Some(bits) = bits else { return c };
    let m = 2f64.powi(bits as i32);
    let mut out = Vec::with_capacity(c.len());
    let mut acc = c.first().copied().unwrap_or(0.0);
    for (k, v) in c.iter().enumerate() {
        if k > 0 {
            let d = v - c[k - 1];
            acc += d - m * (d / m).round();
        }
        out.push(acc);
    }
    out
}

/// Whether any run measures the observation that plays `role`, and if not, the
/// data it would need. Roles kinegen does not read from logs count as measured.
pub fn channel_missing(runs: &[Run], r: &Runner, role: ObservationRole) -> Option<String> {
    let (measured, need) = match role {
        ObservationRole::Pose => (
            runs.iter().any(|x| x.gt.is_some()),
            format!("{} columns", r.ir.pose_columns().join(", ")),
        ),
        ObservationRole::YawRate => (
            runs.iter().any(|x| x.gyro.is_some()),
            format!("{} column", r.ir.gyro_column()),
        ),
        ObservationRole::RangeBearing => (
            runs.iter().any(|x| !x.landmarks.is_empty()),
            "landmark observations (--observations)".into(),
        ),
        ObservationRole::Other => (true, String::new()),
    };
    (!measured).then_some(need)
}

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
        let Some(g) = &self.gt else {
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

    /// Rows `a..b` (inclusive of b-1) as a run of their own.
    pub fn slice(&self, a: usize, b: usize) -> Run {
        Run {
            name: format!("{}[{a}..{b}]", self.name),
            path: self.path.clone(),
            t: self.t[a..b].to_vec(),
            dt: self.dt[a..b - 1].to_vec(),
            u: self.u.slice(a, b - 1),
            gt: self.gt.as_ref().map(|g| g[a..b].to_vec()),
            gyro: self.gyro.as_ref().map(|g| g[a..b].to_vec()),
            landmarks: self
                .landmarks
                .iter()
                .filter(|o| o.t >= self.t[a] && o.t <= self.t[b - 1])
                .cloned()
                .collect(),
            rate_inputs: self.rate_inputs.clone(),
        }
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

    /// Columns a model needs from a log.
    pub fn wanted(r: &Runner) -> Vec<String> {
        let mut w: Vec<String> = vec!["t".into()];
        w.extend(r.ir.pose_columns());
        w.push(r.ir.gyro_column());
        w.extend(r.ir.inputs.iter().map(|i| i.column.clone()));
        w
    }

    pub fn from_log(log: &Log, r: &Runner) -> Result<Run, LogError> {
        if log.len < 3 {
            // located at the log's last line, where more rows were expected
            return Err(log.err(
                Some(log.len + 1),
                None,
                format!(
                    "the log ends after {} data row(s); the model needs at least 3",
                    log.len
                ),
            ));
        }
        let t = log.col("t")?.to_vec();
        let dt: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
        let mut sorted = dt.clone();
        sorted.sort_by(f64::total_cmp);
        let median = sorted[sorted.len() / 2];
        // a step under a microsecond is no sampling interval of a robot: t is in
        // the wrong unit, or rows are duplicated with rounding noise
        if let Some(k) = dt.iter().position(|&d| d < MIN_STEP_S) {
            return Err(log.err(
                Some(k + 3),
                Some("t"),
                format!(
                    "time step of {:.3e} s (under {MIN_STEP_S} s): t must be in seconds",
                    dt[k]
                ),
            ));
        }
        if let Some(k) = dt.iter().position(|&d| d > 20.0 * median) {
            return Err(log.err(
                Some(k + 3),
                Some("t"),
                format!(
                    "gap of {:.3} s in the log (median step {:.4} s)",
                    dt[k], median
                ),
            ));
        }
        // Absolute angles (steering encoders) may be logged wrapped to (-pi, pi]:
        // unwrap them so held values and rates (a column may feed both, as the
        // steering angle and its rate of a caster wheel) do not jump by 2 pi.
        let angle_cols: Vec<&str> =
            r.ir.inputs
                .iter()
                .filter(|i| i.kind == InputKind::Absolute && i.unit == "rad")
                .map(|i| i.column.as_str())
                .collect();
        let mut cols = Vec::new();
        for i in &r.ir.inputs {
            let c = log.col(&i.column)?;
            let c = if angle_cols.contains(&i.column.as_str()) {
                unwrap(c)
            } else {
                c.to_vec()
            };
            cols.push((unwrap_counter(c, i.wrap), i.kind));
        }
        let mut u = Vec::with_capacity(dt.len() * cols.len());
        for k in 0..dt.len() {
            u.extend(cols.iter().map(|(c, kind)| match kind {
                InputKind::Cumulative => (c[k + 1] - c[k]) / dt[k],
                // a sampled continuous angle: its mean over the step is best
                // estimated by the mean of the two samples that bound it
                InputKind::Absolute => 0.5 * (c[k] + c[k + 1]),
            }));
        }
        let u = Inputs::from_flat(dt.len(), cols.len(), u);
        let [cx, cy, cth] = r.ir.pose_columns();
        let gt = if log.has(&cx) && log.has(&cy) && log.has(&cth) {
            let (x, y, th) = (log.col(&cx)?, log.col(&cy)?, unwrap(log.col(&cth)?));
            Some((0..log.len).map(|k| [x[k], y[k], th[k]]).collect())
        } else {
            None
        };
        let gyro = log.columns.get(&r.ir.gyro_column()).cloned();
        let name = log
            .path
            .file_stem()
            .map(|s| s.to_string_lossy().to_string())
            .unwrap_or_default();
        let rate_inputs =
            r.ir.inputs
                .iter()
                .map(|i| i.kind == InputKind::Cumulative)
                .collect();
        Ok(Run {
            name,
            path: log.path.display().to_string(),
            t,
            dt,
            u,
            gt,
            gyro,
            landmarks: Vec::new(),
            rate_inputs,
        })
    }

    /// Read a log for a model: a CSV file, or a ROS 2 bag (MCAP) with the
    /// default topic mapping.
    pub fn read(path: &std::path::Path, r: &Runner) -> Result<Run, LogError> {
        Run::read_with(path, r, &TopicMap::default(), &|_, _| {}).map(|(run, _)| run)
    }

    /// Read a log for a model; a bag through `topics`, reporting
    /// `progress(messages read, total)`, with the range-bearing detections of
    /// its landmark topic (none for a CSV log, whose observations are a file
    /// of their own).
    pub fn read_with(
        path: &std::path::Path,
        r: &Runner,
        topics: &TopicMap,
        progress: &dyn Fn(usize, usize),
    ) -> Result<(Run, Vec<Detection>), LogError> {
        let (log, detections) = if crate::bag::is_bag(path) {
            let wanted = crate::bag::Wanted {
                inputs: r.ir.inputs.iter().map(|i| i.column.clone()).collect(),
                pose: r.ir.pose_columns(),
                gyro: r.ir.gyro_column(),
            };
            crate::bag::read(path, &wanted, topics, progress)?
        } else {
            let wanted = Run::wanted(r);
            let w: Vec<&str> = wanted.iter().map(String::as_str).collect();
            (Log::read(path, &w)?, Vec::new())
        };
        Ok((Run::from_log(&log, r)?, detections))
    }
}
