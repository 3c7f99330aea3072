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

fn location(row: &Option<usize>, column: &Option<String>) -> String {
    match (row, column) {
        (Some(r), Some(c)) => format!(":{r}: column `{c}`"),
        (Some(r), None) => format!(":{r}"),
        (None, Some(c)) => format!(": column `{c}`"),
        (None, None) => String::new(),
    }
}

/// A log: named numeric columns of equal length.
#[derive(Debug, Clone)]
pub struct Log {
    pub path: PathBuf,
    pub columns: HashMap<String, Vec<f64>>,
    pub len: usize,
}

impl Log {
    pub fn err(&self, row: Option<usize>, column: Option<&str>, message: impl Into<String>) -> LogError {
        LogError { file: self.path.clone(), row, column: column.map(str::to_string), message: message.into() }
    }

    pub fn has(&self, c: &str) -> bool {
        self.columns.contains_key(c)
    }

    pub fn col(&self, c: &str) -> Result<&[f64], LogError> {
        self.columns
            .get(c)
            .map(|v| &v[..])
            .ok_or_else(|| self.err(Some(1), Some(c), format!("missing column `{c}` (the header has: {})", self.header())))
    }

    fn header(&self) -> String {
        let mut h: Vec<&str> = self.columns.keys().map(String::as_str).collect();
        h.sort();
        h.join(", ")
    }

    /// Read a log, keeping only `wanted` columns (others are ignored, as the contract says).
    pub fn read(path: &Path, wanted: &[&str]) -> Result<Log, LogError> {
        let e = |row: Option<usize>, col: Option<&str>, m: String| LogError { file: path.to_path_buf(), row, column: col.map(str::to_string), message: m };
        let mut rdr = csv::ReaderBuilder::new()
            .trim(csv::Trim::All)
            .from_path(path)
            .map_err(|x| e(None, None, format!("cannot read log: {x}")))?;
        let headers = rdr.headers().map_err(|x| e(Some(1), None, format!("bad header: {x}")))?.clone();
        let idx: Vec<(usize, String)> = headers.iter().enumerate().filter(|(_, h)| wanted.contains(h)).map(|(i, h)| (i, h.to_string())).collect();
        let mut columns: HashMap<String, Vec<f64>> = idx.iter().map(|(_, h)| (h.clone(), Vec::new())).collect();
        let mut len = 0;
        for (n, rec) in rdr.records().enumerate() {
            let line = n + 2;
            let rec = rec.map_err(|x| e(Some(line), None, format!("malformed row: {x}")))?;
            for (i, h) in &idx {
                let cell = rec.get(*i).ok_or_else(|| e(Some(line), Some(h), "row is shorter than the header".into()))?;
                let v: f64 = cell.parse().map_err(|_| e(Some(line), Some(h), format!("`{cell}` is not a number")))?;
                if !v.is_finite() {
                    return Err(e(Some(line), Some(h), format!("`{cell}` is not finite")));
                }
                columns.get_mut(h).unwrap().push(v);
            }
            len += 1;
        }
        let log = Log { path: path.to_path_buf(), columns, len };
        let t = log.col("t")?;
        for k in 1..t.len() {
            if t[k] <= t[k - 1] {
                return Err(log.err(Some(k + 2), Some("t"), format!("time must increase strictly: {} follows {}", t[k], t[k - 1])));
            }
        }
        Ok(log)
    }
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
    let r = (a + std::f64::consts::PI).rem_euclid(2.0 * std::f64::consts::PI) - std::f64::consts::PI;
    if r <= -std::f64::consts::PI {
        r + 2.0 * std::f64::consts::PI
    } else {
        r
    }
}
