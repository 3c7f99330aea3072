//! Measurement logs (CONTRACT.md section 2): CSV with a header, SI units, `t`
//! strictly increasing. Every problem is reported with file, row and column.
use std::collections::HashMap;
use std::path::{Path, PathBuf};

#[derive(Debug, thiserror::Error)]
#[error("{file}{}: {message}", location(.row, .column))]
pub struct LogError {
    pub file: PathBuf,
    /// 1-based line number in the file (the header is line 1).
    pub row: Option<usize>,
    pub column: Option<String>,
    pub message: String,
}

impl LogError {
    pub fn new(
        file: &Path,
        row: Option<usize>,
        column: Option<&str>,
        message: impl Into<String>,
    ) -> LogError {
        LogError {
            file: file.to_path_buf(),
            row,
            column: column.map(str::to_string),
            message: message.into(),
        }
    }
}

fn location(row: &Option<usize>, column: &Option<String>) -> String {
    match (row, column) {
        (Some(r), Some(c)) => format!(":{r}: column `{c}`"),
        (Some(r), None) => format!(":{r}"),
        (None, Some(c)) => format!(": column `{c}`"),
        (None, None) => String::new(),
    }
}

/// The header of a CSV file being read, and the rules every CSV input follows
/// (logs, landmark maps, landmark observations): trimmed cells, 1-based line
/// numbers (the header is line 1), finite numbers, errors naming file, line and
/// column.
pub struct CsvHeader {
    pub path: PathBuf,
    pub names: Vec<String>,
}

/// Open a CSV file (`what` names it in the error) and read its header.
pub fn read_csv(
    path: &Path,
    what: &str,
) -> Result<(CsvHeader, csv::Reader<std::fs::File>), LogError> {
    let e = |row: Option<usize>, m: String| LogError::new(path, row, None, m);
    let mut rdr = csv::ReaderBuilder::new()
        .trim(csv::Trim::All)
        .from_path(path)
        .map_err(|x| e(None, format!("cannot read {what}: {x}")))?;
    let names: Vec<String> = rdr
        .headers()
        .map_err(|x| e(Some(1), format!("bad header: {x}")))?
        .iter()
        .map(str::to_string)
        .collect();
    if names.iter().all(String::is_empty) {
        return Err(e(
            Some(1),
            format!(
                "the file is empty: a {what} file starts with a header line naming its columns"
            ),
        ));
    }
    if names.len() == 1 {
        if let Some(sep) = [';', '\t', '|'].into_iter().find(|c| names[0].contains(*c)) {
            return Err(e(Some(1), format!("the header is one column `{}`: {what} files are comma-separated, this one looks {sep:?}-separated", names[0])));
        }
    }
    // a repeated name would make every reader pick one of them silently
    for (i, n) in names.iter().enumerate() {
        if let Some(first) = names[..i].iter().position(|x| x == n) {
            return Err(LogError::new(
                path,
                Some(1),
                Some(n),
                format!(
                    "column `{n}` appears twice in the header (columns {} and {})",
                    first + 1,
                    i + 1
                ),
            ));
        }
    }
    Ok((
        CsvHeader {
            path: path.to_path_buf(),
            names,
        },
        rdr,
    ))
}

impl CsvHeader {
    pub fn err(
        &self,
        row: Option<usize>,
        column: Option<&str>,
        message: impl Into<String>,
    ) -> LogError {
        LogError::new(&self.path, row, column, message)
    }

    pub fn position(&self, column: &str) -> Option<usize> {
        self.names.iter().position(|n| n == column)
    }

    /// Positions of `columns`, all of which must be present.
    pub fn require(&self, columns: &[&str]) -> Result<Vec<usize>, LogError> {
        columns
            .iter()
            .map(|c| {
                self.position(c).ok_or_else(|| {
                    self.err(
                        Some(1),
                        Some(c),
                        format!(
                            "missing column `{c}` (the header has: {})",
                            self.names.join(", ")
                        ),
                    )
                })
            })
            .collect()
    }

    /// The `n`-th record (0-based, as `csv::Reader::records` counts) with its line number.
    pub fn record(
        &self,
        n: usize,
        rec: csv::Result<csv::StringRecord>,
    ) -> Result<(usize, csv::StringRecord), LogError> {
        let line = n + 2;
        rec.map(|r| (line, r))
            .map_err(|x| self.err(Some(line), None, format!("malformed row: {x}")))
    }

    /// Cell `i` of a record as text.
    pub fn text<'a>(
        &self,
        line: usize,
        rec: &'a csv::StringRecord,
        i: usize,
    ) -> Result<&'a str, LogError> {
        rec.get(i).ok_or_else(|| {
            self.err(
                Some(line),
                Some(&self.names[i]),
                "row is shorter than the header",
            )
        })
    }

    /// Cell `i` of a record as a finite number, or NaN where the cell is
    /// empty or `nan` and `missing_ok` (a measurement not taken in that row:
    /// motion capture that lost the robot).
    pub fn number_or_missing(
        &self,
        line: usize,
        rec: &csv::StringRecord,
        i: usize,
        missing_ok: bool,
    ) -> Result<f64, LogError> {
        if missing_ok {
            let cell = self.text(line, rec, i)?.trim();
            if cell.is_empty() || cell.eq_ignore_ascii_case("nan") {
                return Ok(f64::NAN);
            }
        }
        self.number(line, rec, i)
    }

    /// Cell `i` of a record as a finite number.
    pub fn number(&self, line: usize, rec: &csv::StringRecord, i: usize) -> Result<f64, LogError> {
        let cell = self.text(line, rec, i)?;
        let v: f64 = cell.parse().map_err(|_| {
            self.err(
                Some(line),
                Some(&self.names[i]),
                format!("`{cell}` is not a number"),
            )
        })?;
        if !v.is_finite() {
            return Err(self.err(
                Some(line),
                Some(&self.names[i]),
                format!("`{cell}` is not finite"),
            ));
        }
        // no measured quantity comes near this; its square (a squared error,
        // a variance) would overflow to infinity and poison every result
        if v.abs() > MAX_MAGNITUDE {
            return Err(self.err(
                Some(line),
                Some(&self.names[i]),
                format!(
                    "`{cell}` is out of any physical range (magnitude above {MAX_MAGNITUDE:e})"
                ),
            ));
        }
        Ok(v)
    }
}

/// The largest magnitude a number read from a log may have.
pub const MAX_MAGNITUDE: f64 = 1e150;

/// Whether a value read from a log (CSV cell, bag field) is a finite number
/// within [`MAX_MAGNITUDE`].
pub fn physical(x: f64) -> bool {
    x.is_finite() && x.abs() <= MAX_MAGNITUDE
}

/// A log: named numeric columns of equal length.
#[derive(Debug, Clone)]
pub struct Log {
    pub path: PathBuf,
    pub columns: HashMap<String, Vec<f64>>,
    pub len: usize,
}

impl Log {
    pub fn err(
        &self,
        row: Option<usize>,
        column: Option<&str>,
        message: impl Into<String>,
    ) -> LogError {
        LogError::new(&self.path, row, column, message)
    }

    pub fn has(&self, c: &str) -> bool {
        self.columns.contains_key(c)
    }

    pub fn col(&self, c: &str) -> Result<&[f64], LogError> {
        self.columns.get(c).map(|v| &v[..]).ok_or_else(|| {
            self.err(
                Some(1),
                Some(c),
                format!("missing column `{c}` (the header has: {})", self.header()),
            )
        })
    }

    fn header(&self) -> String {
        let mut h: Vec<&str> = self.columns.keys().map(String::as_str).collect();
        h.sort();
        h.join(", ")
    }

    /// Read a log, keeping only `wanted` columns (others are ignored, as the
    /// contract says). Cells of the `measured` columns may be empty or `nan`
    /// (read as NaN: [`crate::run::Run::split_at_gaps`] cuts those rows out).
    pub fn read(path: &Path, wanted: &[&str], measured: &[&str]) -> Result<Log, LogError> {
        let (header, mut rdr) = read_csv(path, "log")?;
        let idx: Vec<(usize, String)> = header
            .names
            .iter()
            .enumerate()
            .filter(|(_, h)| wanted.contains(&h.as_str()))
            .map(|(i, h)| (i, h.clone()))
            .collect();
        let mut columns: HashMap<String, Vec<f64>> =
            idx.iter().map(|(_, h)| (h.clone(), Vec::new())).collect();
        let mut len = 0;
        for (n, rec) in rdr.records().enumerate() {
            let (line, rec) = header.record(n, rec)?;
            for (i, h) in &idx {
                let v = header.number_or_missing(line, &rec, *i, measured.contains(&h.as_str()))?;
                columns.get_mut(h).unwrap().push(v);
            }
            len += 1;
        }
        // growth by doubling leaves up to half of each column unused: give it
        // back (a long log is most of the memory a command uses)
        columns.values_mut().for_each(Vec::shrink_to_fit);
        let log = Log {
            path: path.to_path_buf(),
            columns,
            len,
        };
        let t = log.col("t")?;
        for k in 1..t.len() {
            if t[k] <= t[k - 1] {
                // an empty cell is NaN: two empty cells are the same cell
                let same = |c: &Vec<f64>| c[k] == c[k - 1] || (c[k].is_nan() && c[k - 1].is_nan());
                let fits = |c: &Vec<f64>| same(c) || c[k].is_nan() || c[k - 1].is_nan();
                let same_row = t[k] == t[k - 1] && log.columns.values().all(same);
                let complementary = t[k] == t[k - 1] && log.columns.values().all(fits);
                let why = if same_row {
                    format!("time must increase strictly: line {} repeats line {} exactly (a sample logged twice?): remove one", k + 2, k + 1)
                } else if complementary {
                    format!("time must increase strictly: lines {} and {} are both at t = {}, each with cells the other leaves empty (two sources logged at the same time): merge them into one row", k + 1, k + 2, t[k])
                } else if t[k] == t[k - 1] {
                    format!("time must increase strictly: lines {} and {} are both at t = {} with different values (which one holds?)", k + 1, k + 2, t[k])
                } else {
                    format!("time must increase strictly: {} follows {}", t[k], t[k - 1])
                };
                return Err(log.err(Some(k + 2), Some("t"), why));
            }
        }
        Ok(log)
    }
}

/// The typical value of `values`: their middle one (the upper of the two
/// for an even count; no mean, so it is one of the values); None when empty.
/// What a log's steps, a counter's increments or a sensor's sample interval
/// usually are, whatever their outliers.
pub fn typical(mut values: Vec<f64>) -> Option<f64> {
    let mid = values.len() / 2;
    (!values.is_empty()).then(|| *values.select_nth_unstable_by(mid, f64::total_cmp).1)
}

/// Unwrap a wrapped angle series (contract: angles are logged in (-pi, pi]).
pub fn unwrap(a: &[f64]) -> Vec<f64> {
    let mut out = Vec::with_capacity(a.len());
    let mut offset = 0.0;
    for (k, &v) in a.iter().enumerate() {
        if k > 0 {
            let d = v - a[k - 1];
            if d > std::f64::consts::PI {
                offset -= 2.0 * std::f64::consts::PI;
            } else if d < -std::f64::consts::PI {
                offset += 2.0 * std::f64::consts::PI;
            }
        }
        out.push(v + offset);
    }
    out
}

/// Wrap an angle to (-pi, pi].
pub fn wrap(a: f64) -> f64 {
    let r =
        (a + std::f64::consts::PI).rem_euclid(2.0 * std::f64::consts::PI) - std::f64::consts::PI;
    if r <= -std::f64::consts::PI {
        r + 2.0 * std::f64::consts::PI
    } else {
        r
    }
}
