//! Logs merged from sources that log at their own times, as a table exported
//! from several topics is: each row carries the cells of the sources that
//! logged at its time and leaves the others empty (a command row, an encoder
//! row, a motion-capture row). Each empty cell gets the value its source had
//! at the row's time, by what its column is:
//! - a command holds its last value (CONTRACT: it applies until the next);
//! - a counter or a sampled angle is interpolated in time (a counter's
//!   difference spreads over the interval, as between any two rows);
//! - a measurement (the pose, the gyro) is interpolated between samples no
//!   further apart than twice its typical interval. Longer stretches are a
//!   tracker that lost the robot: those rows stay empty, to be cut out (or
//!   run through by a localisation) as before.
//!
//! Rows before an input's first value hold that first value, rows after a
//! counter's last value its last one: a log's first and last rows, said.
use crate::logs::log::{typical, wrap, Log, LogError};

/// How an input column's empty cells are filled.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Fill {
    /// The last value holds (a command).
    Hold,
    /// Interpolated in time (a counter, a sampled angle).
    Interpolate,
}

/// An input column of a log and how its empty cells are filled.
#[derive(Debug, Clone)]
pub struct InputColumn {
    pub name: String,
    pub fill: Fill,
    /// An angle in radians, interpolated along the shorter arc.
    pub angle: bool,
}

/// A measurement read from a log: its columns, filled together (a row has a
/// pose when it has all three cells), and which of them is an angle.
#[derive(Debug, Clone)]
pub struct Measurement {
    pub columns: Vec<String>,
    pub angle: Vec<bool>,
}

/// What filling did, counted for the warning.
#[derive(Debug, Default)]
struct Filled {
    input_rows: usize,
    input_columns: Vec<String>,
    ends: usize,
    measured_rows: usize,
}

/// Fill the empty cells of `log`'s `inputs` and short gaps of its
/// `measured` columns (see the module). Returns what the user should be
/// told, None when nothing was empty. An input column without any value is
/// an error naming it.
pub fn fill(
    log: &mut Log,
    inputs: &[InputColumn],
    measured: &[Measurement],
) -> Result<Option<String>, LogError> {
    let mut done = Filled::default();
    // grown to the log's length by the first column with an empty cell
    let mut empty_rows: Vec<bool> = Vec::new();
    for input in inputs {
        // a complete column (the usual log) is left as it is, nothing allocated
        let Some(c) = (log.columns.get(&input.name)).filter(|c| c.iter().any(|v| v.is_nan()))
        else {
            continue;
        };
        let known: Vec<usize> = (0..c.len()).filter(|&k| !c[k].is_nan()).collect();
        if known.is_empty() {
            return Err(log.err(
                None,
                Some(&input.name),
                "no row has a value in this input column",
            ));
        }
        empty_rows.resize(c.len(), false);
        for k in (0..c.len()).filter(|&k| c[k].is_nan()) {
            empty_rows[k] = true;
        }
        done.input_columns.push(input.name.clone());
        // taken out while filled, so that time can be read beside it
        let mut c = log.columns.remove(&input.name).unwrap();
        done.ends += fill_input(&mut c, log.col("t")?, &known, input);
        log.columns.insert(input.name.clone(), c);
    }
    done.input_rows = empty_rows.iter().filter(|&&e| e).count();
    for m in measured {
        done.measured_rows += fill_measurement(log, m)?;
    }
    Ok((done.input_rows + done.measured_rows > 0).then(|| said(log, &done)))
}

/// Fill one input column from its `known` rows; returns how many rows lie
/// before its first value or (interpolated) after its last one.
fn fill_input(c: &mut [f64], t: &[f64], known: &[usize], input: &InputColumn) -> usize {
    let (first, last) = (known[0], *known.last().unwrap());
    let mut ends = first;
    for k in 0..first {
        c[k] = c[first];
    }
    match input.fill {
        Fill::Hold => {
            for k in first + 1..c.len() {
                if c[k].is_nan() {
                    c[k] = c[k - 1];
                }
            }
        }
        Fill::Interpolate => {
            for w in known.windows(2) {
                interpolate(c, t, w[0], w[1], input.angle);
            }
            ends += c.len() - 1 - last;
            for k in last + 1..c.len() {
                c[k] = c[last];
            }
        }
    }
    ends
}

/// Cells strictly between rows `a` and `b` of `c`, linear in time (along
/// the shorter arc for an angle).
fn interpolate(c: &mut [f64], t: &[f64], a: usize, b: usize, angle: bool) {
    let d = if angle {
        wrap(c[b] - c[a])
    } else {
        c[b] - c[a]
    };
    for k in a + 1..b {
        c[k] = c[a] + d * (t[k] - t[a]) / (t[b] - t[a]);
    }
}

/// Fill the short gaps of one measurement (see the module); returns the rows
/// filled.
fn fill_measurement(log: &mut Log, m: &Measurement) -> Result<usize, LogError> {
    let columns: Option<Vec<&Vec<f64>>> = m.columns.iter().map(|c| log.columns.get(c)).collect();
    let Some(columns) = columns else {
        return Ok(0);
    };
    let has = |k: usize| columns.iter().all(|c| !c[k].is_nan());
    // a measurement in every row (the usual log) is left as it is, nothing allocated
    if (0..log.len).all(has) {
        return Ok(0);
    }
    let known: Vec<usize> = (0..log.len).filter(|&k| has(k)).collect();
    let t = log.col("t")?;
    let Some(typical) = typical(known.windows(2).map(|w| t[w[1]] - t[w[0]]).collect()) else {
        return Ok(0);
    };
    let short: Vec<[usize; 2]> = (known.windows(2))
        .filter(|w| w[1] > w[0] + 1 && t[w[1]] - t[w[0]] <= 2.0 * typical)
        .map(|w| [w[0], w[1]])
        .collect();
    for (name, &angle) in m.columns.iter().zip(&m.angle) {
        // taken out while filled, so that time can be read beside it
        let mut c = log.columns.remove(name).unwrap();
        for &[a, b] in &short {
            interpolate(&mut c, log.col("t")?, a, b, angle);
        }
        log.columns.insert(name.clone(), c);
    }
    Ok(short.iter().map(|[a, b]| b - a - 1).sum())
}

fn said(log: &Log, f: &Filled) -> String {
    let mut parts = Vec::new();
    if f.input_rows > 0 {
        let columns: Vec<String> = f.input_columns.iter().map(|c| format!("`{c}`")).collect();
        parts.push(format!(
            "{} row(s) leave input column(s) {} empty, read as a log merged from sources at their own times: a command holds its last value, a counter or sampled angle is interpolated in time",
            f.input_rows,
            columns.join(", ")
        ));
    }
    if f.ends > 0 {
        parts.push(format!(
            "{} cell(s) before an input's first value or after a counter's last one hold that value",
            f.ends
        ));
    }
    if f.measured_rows > 0 {
        parts.push(format!(
            "{} row(s) without a measurement between samples no further apart than twice their typical interval are interpolated",
            f.measured_rows
        ));
    }
    format!("{}: {}", log.path.display(), parts.join("; "))
}
