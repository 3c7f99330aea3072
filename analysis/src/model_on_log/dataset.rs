//! A log turned into model steps: per-step inputs (rates of cumulative columns,
//! held values of absolute ones), step lengths, and the measurements.
use crate::logs::bag::{Detection, TopicMap};
use crate::logs::column::Column;
use crate::logs::log::{typical, unwrap, Log, LogError};
use crate::logs::merged::{self, Fill, InputColumn, Measurement};
use crate::logs::rows::Inputs;
use crate::model_on_log::model::Runner;
use crate::model_on_log::run::Run;
use kinegen_model::decl::{InputKind, ObservationRole};

/// How a log column becomes a step's input value.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Between {
    /// A cumulative column: its difference over the step, as a rate.
    Spread,
    /// An absolute column held from its row (a command).
    Hold,
    /// An absolute column sampled from a continuous signal (a steering angle).
    Linear,
}

impl Between {
    fn of(i: &kinegen_model::decl::Input) -> Between {
        match (i.kind, i.between()) {
            (InputKind::Cumulative, _) => Between::Spread,
            (InputKind::Absolute, kinegen_model::decl::Between::Hold) => Between::Hold,
            (InputKind::Absolute, kinegen_model::decl::Between::Linear) => Between::Linear,
        }
    }
}

/// The measured pose of every row: NaN in all three where any of them is
/// missing (see [`Log::read`]), the heading unwrapped across the rows that
/// have one; None when no row has one (a log whose pose columns are empty).
fn measured_pose(x: &[f64], y: &[f64], th: &[f64]) -> Option<Vec<[f64; 3]>> {
    let complete = |k: usize| !(x[k].is_nan() || y[k].is_nan() || th[k].is_nan());
    let rows: Vec<usize> = (0..x.len()).filter(|&k| complete(k)).collect();
    if rows.is_empty() {
        return None;
    }
    let heading = unwrap(&rows.iter().map(|&k| th[k]).collect::<Vec<_>>());
    let mut pose = vec![[f64::NAN; 3]; x.len()];
    for (&k, h) in rows.iter().zip(heading) {
        pose[k] = [x[k], y[k], h];
    }
    Some(pose)
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

/// A counter that wraps without its spec declaring `wrap`: the first step
/// (index k: rows k to k + 1) whose jump is within 5% of 2^16 or 2^32 in
/// size while the counter's typical step is under 5% of it (20x smaller). Such
/// a jump read as motion gave a yaw rate of 1e6 rad/s, and compare exited 0.
fn undeclared_wrap(c: &[f64]) -> Option<(usize, f64, u32)> {
    let jumps: Vec<f64> = c.windows(2).map(|w| (w[1] - w[0]).abs()).collect();
    let typical = typical(jumps.clone())?;
    for bits in [16u32, 32] {
        let m = 2f64.powi(bits as i32);
        if typical >= 0.05 * m {
            continue;
        }
        if let Some(k) = jumps.iter().position(|d| (d - m).abs() <= 0.05 * m) {
            return Some((k, c[k + 1] - c[k], bits));
        }
    }
    None
}

/// A counter that starts again from 0 mid-log (the robot's controller
/// rebooted): the first step (index k: rows k to k + 1) that lands within a
/// few typical steps of 0 from a value over 100 typical steps away, a jump
/// of over 100 typical steps. Read as motion, the reset is one step of a
/// huge speed backwards (compare 13.97 m, fit "missing a physical effect",
/// and exit 0).
fn counter_reset(c: &[f64]) -> Option<(usize, f64, f64)> {
    let jumps: Vec<f64> = c.windows(2).map(|w| (w[1] - w[0]).abs()).collect();
    // the typical step while moving: a robot that mostly stands has a
    // median step of 0, against which any step would look huge
    let moving: Vec<f64> = jumps.iter().copied().filter(|d| *d > 0.0).collect();
    let typical = typical(moving)?;
    jumps
        .iter()
        .enumerate()
        .position(|(k, d)| {
            *d > 100.0 * typical && c[k].abs() > 100.0 * typical && c[k + 1].abs() <= 3.0 * typical
        })
        .map(|k| (k, c[k], c[k + 1]))
}

/// An angle column logged in degrees: the first step (index k: rows k to
/// k + 1) where it jumps by 300-420, as a heading in degrees does where it
/// wraps at +-180 (in radians the wrap is a jump of 2 pi, and an unwrapped
/// heading does not jump). Read as radians, such a log dead-reckoned
/// against a heading 57 times too large, and compare exited 0.
fn degrees_wrap(c: &[f64]) -> Option<(usize, f64)> {
    c.windows(2)
        .position(|w| (300.0..=420.0).contains(&(w[1] - w[0]).abs()))
        .map(|k| (k, c[k + 1] - c[k]))
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

/// A log's times and the steps between them: at least 3 rows, and no step
/// under [`MIN_STEP_S`].
fn steps_of(log: &Log) -> Result<(Vec<f64>, Vec<f64>), LogError> {
    if log.len < 3 {
        // located at the log's last line, where more rows were expected
        return Err(log.err(
            Some(log.line(log.len) - 1),
            None,
            format!(
                "the log ends after {} data row(s); the model needs at least 3",
                log.len
            ),
        ));
    }
    let t = log.col("t")?.to_vec();
    let dt: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
    // (gaps are cut out later, by Run::split_at_gaps, with a warning)
    // a step under a microsecond is no sampling interval of a robot: t is in
    // the wrong unit, or rows are duplicated with rounding noise
    if let Some(k) = dt.iter().position(|&d| d < MIN_STEP_S) {
        return Err(log.err(
            Some(log.line(k + 1)),
            Some("t"),
            format!(
                "time step of {:.3e} s (under {MIN_STEP_S} s): t must be in seconds",
                dt[k]
            ),
        ));
    }
    Ok((t, dt))
}

/// Each input's column as the steps read it (angles in `angle_cols`
/// unwrapped, counters unwrapped at their declared width), with how it
/// becomes a step's value; a counter that wraps without a declared width is
/// an error at the line where it jumps.
fn step_columns(
    log: &Log,
    r: &Runner,
    angle_cols: &[&str],
) -> Result<Vec<(Vec<f64>, Between)>, LogError> {
    let mut cols = Vec::new();
    for i in &r.ir.inputs {
        if i.kind == InputKind::Cumulative && i.wrap.is_none() {
            if let Some((k, d, bits)) = undeclared_wrap(log.col(&i.column)?) {
                return Err(log.err(
                    Some(log.line(k + 1)),
                    Some(&i.column),
                    format!(
                        "the counter jumps by {d} from the line before, about 2^{bits}: it wraps like a {bits}-bit register; declare `wrap = {bits}` on input `{}` in the spec",
                        i.name
                    ),
                ));
            }
        }
        if i.kind == InputKind::Cumulative && i.wrap.is_none() {
            if let Some((k, from, to)) = counter_reset(log.col(&i.column)?) {
                return Err(log.err(
                    Some(log.line(k + 1)),
                    Some(&i.column),
                    format!(
                        "the counter drops from {from} to {to} from the line before: it starts again from 0 (a reboot?), which no motion does; split the log at this line and give each part as its own --data"
                    ),
                ));
            }
        }
        let c = log.col(&i.column)?;
        let c = if angle_cols.contains(&i.column.as_str()) {
            unwrap(c)
        } else {
            c.to_vec()
        };
        cols.push((unwrap_counter(c, i.wrap), Between::of(i)));
    }
    Ok(cols)
}

/// Each step's input values from the columns, and, where an input is
/// sampled linearly (a steering angle), how much each changes over the step.
fn step_inputs(cols: &[(Vec<f64>, Between)], dt: &[f64]) -> (Inputs, Option<Inputs>) {
    let mut u = Vec::with_capacity(dt.len() * cols.len());
    for k in 0..dt.len() {
        u.extend(cols.iter().map(|(c, between)| match between {
            // a counter's difference spreads evenly over the interval, however long
            Between::Spread => (c[k + 1] - c[k]) / dt[k],
            // a command holds from its row until the next (CONTRACT.md, --max-gap)
            Between::Hold => c[k],
            // a sampled continuous angle: its mean over the step is best
            // estimated by the mean of the two samples that bound it
            Between::Linear => 0.5 * (c[k] + c[k + 1]),
        }));
    }
    let u = Inputs::from_flat(dt.len(), cols.len(), u);
    let swing = cols.iter().any(|(_, b)| *b == Between::Linear).then(|| {
        let mut s = Vec::with_capacity(dt.len() * cols.len());
        for k in 0..dt.len() {
            s.extend(cols.iter().map(|(c, b)| match b {
                Between::Linear => c[k + 1] - c[k],
                Between::Hold | Between::Spread => 0.0,
            }));
        }
        Inputs::from_flat(dt.len(), cols.len(), s)
    });
    (u, swing)
}

impl Run {
    /// Columns a model needs from a log.
    pub fn wanted(r: &Runner) -> Vec<String> {
        let mut w: Vec<String> = vec!["t".into()];
        w.extend(r.ir.pose_columns());
        w.push(r.ir.gyro_column());
        w.extend(r.ir.inputs.iter().map(|i| i.column.clone()));
        w
    }

    pub fn from_log(log: &Log, r: &Runner) -> Result<Run, LogError> {
        let (t, dt) = steps_of(log)?;
        // Absolute angles (steering encoders) may be logged wrapped to (-pi, pi]:
        // unwrap them so held values and rates (a column may feed both, as the
        // steering angle and its rate of a caster wheel) do not jump by 2 pi.
        let angle_cols: Vec<&str> =
            r.ir.inputs
                .iter()
                .filter(|i| absolute_angle(i))
                .map(|i| i.column.as_str())
                .collect();
        let cols = step_columns(log, r, &angle_cols)?;
        let (u, swing) = step_inputs(&cols, &dt);
        let [cx, cy, cth] = r.ir.pose_columns();
        for c in angle_cols.iter().copied().chain([cth.as_str()]) {
            let Some(col) = log.columns.get(c) else {
                continue;
            };
            if let Some((k, d)) = degrees_wrap(col) {
                return Err(log.err(
                    Some(log.line(k + 1)),
                    Some(c),
                    format!("the angle jumps by {d:.1} from the line before, as an angle in degrees does where it wraps at +-180: angles are logged in radians"),
                ));
            }
        }
        let gt = if log.has(&cx) && log.has(&cy) && log.has(&cth) {
            measured_pose(log.col(&cx)?, log.col(&cy)?, log.col(&cth)?)
        } else {
            None
        };
        // a gyro column with no reading at all is no gyro
        let gyro = log
            .columns
            .get(&r.ir.gyro_column())
            .filter(|g| g.iter().any(|v| !v.is_nan()))
            .cloned();
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
            t: t.into(),
            dt: dt.into(),
            u,
            gt: gt.map(Column::from),
            gyro: gyro.map(Column::from),
            landmarks: Vec::new(),
            rate_inputs,
            swing,
            first_line: log.first_line,
        })
    }

    /// Read a log for a model: a CSV file, or a ROS 2 bag (MCAP) with the
    /// default topic mapping.
    pub fn read(path: &std::path::Path, r: &Runner) -> Result<Run, LogError> {
        Run::read_with(path, r, &TopicMap::default(), &|_, _| {}).map(|read| read.run)
    }

    /// Read a log for a model; a bag through `topics`, reporting
    /// `progress(messages read, thousandths of the file read)`, with the range-bearing detections of
    /// its landmark topic (none for a CSV log, whose observations are a file
    /// of their own). A CSV log's empty cells are filled as a log merged
    /// from sources at their own times is ([`crate::logs::merged`]), said in the
    /// note.
    pub fn read_with(
        path: &std::path::Path,
        r: &Runner,
        topics: &TopicMap,
        progress: &dyn Fn(usize, usize),
    ) -> Result<ReadLog, LogError> {
        let (log, detections, note) = if crate::logs::bag::is_bag(path) {
            let wanted = crate::logs::bag::Wanted {
                inputs: r.ir.inputs.iter().map(|i| i.column.clone()).collect(),
                pose: r.ir.pose_columns(),
                gyro: r.ir.gyro_column(),
            };
            let (log, detections) = crate::logs::bag::read(path, &wanted, topics, progress)?;
            (log, detections, None)
        } else {
            let wanted = Run::wanted(r);
            let w: Vec<&str> = wanted.iter().map(String::as_str).collect();
            // every column but time may have empty cells: filled below
            let m: Vec<&str> = w.iter().copied().filter(|c| *c != "t").collect();
            let mut log = Log::read(path, &w, &m)?;
            let note = merged::fill(&mut log, &input_columns(r), &measurements(r))?;
            (log, Vec::new(), note)
        };
        Ok(ReadLog {
            run: Run::from_log(&log, r)?,
            detections,
            note,
        })
    }
}

/// A log as read for a model.
pub struct ReadLog {
    pub run: Run,
    /// The detections of a bag's landmark topic.
    pub detections: Vec<Detection>,
    /// What the user should know of how it was read (empty cells filled).
    pub note: Option<String>,
}

/// Whether input `i` is an absolute angle (a steering encoder), logged
/// wrapped to (-pi, pi].
fn absolute_angle(i: &kinegen_model::decl::Input) -> bool {
    i.kind == InputKind::Absolute && i.unit == "rad"
}

/// The model's input columns and how their empty cells are filled.
fn input_columns(r: &Runner) -> Vec<InputColumn> {
    (r.ir.inputs.iter())
        .map(|i| InputColumn {
            name: i.column.clone(),
            fill: match Between::of(i) {
                Between::Hold => Fill::Hold,
                Between::Spread | Between::Linear => Fill::Interpolate,
            },
            angle: absolute_angle(i),
        })
        .collect()
}

/// The measurements a log may carry for the model: the pose, the gyro.
fn measurements(r: &Runner) -> [Measurement; 2] {
    [
        Measurement {
            columns: r.ir.pose_columns().to_vec(),
            angle: vec![false, false, true],
        },
        Measurement {
            columns: vec![r.ir.gyro_column()],
            angle: vec![false],
        },
    ]
}
