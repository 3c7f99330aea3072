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
/// numbers (the header is line 1 unless comment lines come first), finite
/// numbers, errors naming file, line and column.
pub struct CsvHeader {
    pub path: PathBuf,
    pub names: Vec<String>,
    /// The file's line of the first data row (2 for a file that starts with
    /// its header).
    pub first_data_line: usize,
}

/// A CSV reader positioned at a file's first data row.
pub type CsvReader = csv::Reader<Box<dyn std::io::Read>>;

/// The lines before a CSV file's data: `#` comment lines, which loggers
/// write to describe a file (`# robot 3, firmware 2.1`), and the first line
/// after them, as bytes (the csv reader reads it again and says, at its line,
/// if it is not text).
struct Preamble {
    comments: Vec<String>,
    first: Vec<u8>,
}

impl Preamble {
    /// Read lines up to and including the first that is not a comment.
    fn read(rdr: &mut impl std::io::BufRead) -> std::io::Result<Preamble> {
        let mut comments = Vec::new();
        loop {
            let mut line = Vec::new();
            let n = rdr.read_until(b'\n', &mut line)?;
            let text = String::from_utf8_lossy(&line);
            if n == 0 || !is_comment(&text) {
                return Ok(Preamble {
                    comments,
                    first: line,
                });
            }
            comments.push(text.into_owned());
        }
    }
}

fn is_comment(line: &str) -> bool {
    line.trim_start_matches('\u{feff}')
        .trim_start()
        .starts_with('#')
}

/// The trimmed cells of one CSV line.
fn cells(line: &str) -> Vec<String> {
    let mut rdr = csv::ReaderBuilder::new()
        .has_headers(false)
        .trim(csv::Trim::All)
        .from_reader(line.trim_start_matches('\u{feff}').as_bytes());
    rdr.records()
        .next()
        .and_then(Result::ok)
        .map(|r| r.iter().map(str::to_string).collect())
        .unwrap_or_default()
}

/// Whether a line's cells are all numbers (a data row, not a header).
fn is_data(cells: &[String]) -> bool {
    !cells.is_empty() && cells.iter().all(|c| c.parse::<f64>().is_ok())
}

/// A missing column's message: the header as it is, and the column it has
/// under another case, which the contract's exact names do not match (`T`
/// for `t`; spaces around a name are trimmed on reading).
fn missing_column(c: &str, header: &[String]) -> String {
    let near = header
        .iter()
        .find(|h| h.eq_ignore_ascii_case(c))
        .map(|h| format!("; `{h}` differs only in case: rename it `{c}`"))
        .unwrap_or_default();
    format!(
        "missing column `{c}` (the header has: {}){near}",
        header.join(", ")
    )
}

/// What is wrong with a row the csv crate could not read, in the file's
/// terms (its own message counts lines from where the reader started, after
/// any comment lines, and would contradict the line the error names).
fn malformed(x: &csv::Error) -> String {
    match x.kind() {
        csv::ErrorKind::UnequalLengths {
            expected_len, len, ..
        } => format!(
            "malformed row: {len} cell(s) where the header has {expected_len} (a `#` comment or a line of another format among the data rows?)"
        ),
        csv::ErrorKind::Utf8 { .. } => "malformed row: not UTF-8 text".to_string(),
        _ => format!("malformed row: {x}"),
    }
}

/// Open a CSV file (`what` names it in the error) and read its header.
///
/// Comment lines (`#`) before the header are skipped. A header written as a
/// comment, as numpy's `savetxt(..., header=...)` does (`# t,v,omega`), is
/// the header when data follows it directly. The csv crate's own comment
/// option is not used: it would also skip `#` lines among the data rows
/// silently and make the rows' line numbers wrong in every later error.
pub fn read_csv(path: &Path, what: &str) -> Result<(CsvHeader, CsvReader), LogError> {
    let e = |row: Option<usize>, m: String| LogError::new(path, row, None, m);
    let cannot = |x: std::io::Error| e(None, format!("cannot read {what}: {x}"));
    // bounded: a device or a pipe as a log stops at the machine's limit
    let mut file =
        std::io::BufReader::new(kinegen_model::files::open_bounded(path).map_err(cannot)?);
    let pre = Preamble::read(&mut file).map_err(cannot)?;
    let header_line = pre.comments.len() + 1;
    let first = cells(&String::from_utf8_lossy(&pre.first));
    let from_comment = pre
        .comments
        .last()
        .map(|c| {
            cells(
                c.trim_start_matches('\u{feff}')
                    .trim_start()
                    .trim_start_matches('#'),
            )
        })
        .filter(|h| is_data(&first) && h.len() == first.len() && !is_data(h));
    let builder = |has_headers: bool| {
        use std::io::Read;
        let rest: Box<dyn Read> = Box::new(std::io::Cursor::new(pre.first).chain(file));
        csv::ReaderBuilder::new()
            .trim(csv::Trim::All)
            .has_headers(has_headers)
            .from_reader(rest)
    };
    let (names, rdr, first_data_line) = if let Some(names) = from_comment {
        (names, builder(false), header_line)
    } else {
        let mut rdr = builder(true);
        let names: Vec<String> = rdr
            .headers()
            .map_err(|x| e(Some(header_line), format!("bad header: {x}")))?
            .iter()
            .map(str::to_string)
            .collect();
        (names, rdr, header_line + 1)
    };
    let header = CsvHeader {
        path: path.to_path_buf(),
        names,
        first_data_line,
    };
    header.check(what, header_line)?;
    Ok((header, rdr))
}

impl CsvHeader {
    /// What makes a header unusable, said at its line: none at all, one
    /// column that is a whole line in another separator, numbers (a file
    /// without a header), a name twice.
    fn check(&self, what: &str, line: usize) -> Result<(), LogError> {
        let e = |m: String| self.err(Some(line), None, m);
        let names = &self.names;
        if names.iter().all(String::is_empty) {
            let what_is = match line - 1 {
                0 => "the file is empty".to_string(),
                n => format!("the file ends after {n} comment line(s)"),
            };
            return Err(e(format!(
                "{what_is}: a {what} file starts with a header line naming its columns"
            )));
        }
        if names.len() == 1 {
            if let Some(sep) = [';', '\t', '|'].into_iter().find(|c| names[0].contains(*c)) {
                return Err(e(format!("the header is one column `{}`: {what} files are comma-separated, this one looks {sep:?}-separated", names[0])));
            }
            // numpy's savetxt and many loggers separate by spaces
            if names[0].split_whitespace().count() > 1 {
                return Err(e(format!("the header is one column `{}`: {what} files are comma-separated, this one looks space-separated", names[0])));
            }
        }
        if is_data(names) {
            return Err(e(format!(
                "the first line is numbers ({}), not a header: a {what} file starts with a header line naming its columns",
                names.join(",")
            )));
        }
        // a repeated name would make every reader pick one of them silently
        for (i, n) in names.iter().enumerate() {
            if let Some(first) = names[..i].iter().position(|x| x == n) {
                return Err(self.err(
                    Some(line),
                    Some(n),
                    format!(
                        "column `{n}` appears twice in the header (columns {} and {})",
                        first + 1,
                        i + 1
                    ),
                ));
            }
        }
        Ok(())
    }

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
                self.position(c)
                    .ok_or_else(|| self.err(Some(1), Some(c), missing_column(c, &self.names)))
            })
            .collect()
    }

    /// The `n`-th record (0-based, as `csv::Reader::records` counts) with its line number.
    pub fn record(
        &self,
        n: usize,
        rec: csv::Result<csv::StringRecord>,
    ) -> Result<(usize, csv::StringRecord), LogError> {
        let line = self.first_data_line + n;
        rec.map(|r| (line, r))
            .map_err(|x| self.err(Some(line), None, malformed(&x)))
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
    /// Every column the source has, kept or not, in its order: what a
    /// missing column's error lists.
    pub header: Vec<String>,
    pub len: usize,
    /// The file's line of row 0 (2 below a header on line 1).
    pub first_line: usize,
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

    /// The file's line of row `k`.
    pub fn line(&self, k: usize) -> usize {
        self.first_line + k
    }

    pub fn has(&self, c: &str) -> bool {
        self.columns.contains_key(c)
    }

    pub fn col(&self, c: &str) -> Result<&[f64], LogError> {
        self.columns
            .get(c)
            .map(|v| &v[..])
            .ok_or_else(|| self.err(Some(1), Some(c), missing_column(c, &self.header)))
    }

    /// Read a log, keeping only `wanted` columns (others are ignored, as the
    /// contract says). Cells of the `measured` columns may be empty or `nan`
    /// (read as NaN: [`crate::model_on_log::run::Run::split_at_gaps`] cuts those rows out).
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
            header: header.names.clone(),
            len,
            first_line: header.first_data_line,
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
                    format!("time must increase strictly: line {} repeats line {} exactly (a sample logged twice?): remove one", log.line(k), log.line(k - 1))
                } else if complementary {
                    format!("time must increase strictly: lines {} and {} are both at t = {}, each with cells the other leaves empty (two sources logged at the same time): merge them into one row", log.line(k - 1), log.line(k), t[k])
                } else if t[k] == t[k - 1] {
                    format!("time must increase strictly: lines {} and {} are both at t = {} with different values (which one holds?)", log.line(k - 1), log.line(k), t[k])
                } else {
                    format!("time must increase strictly: {} follows {}", t[k], t[k - 1])
                };
                return Err(log.err(Some(log.line(k)), Some("t"), why));
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
