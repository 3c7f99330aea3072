//! Where human text and JSON go: with `--json -` stdout carries exactly one JSON
//! document and everything for people goes to stderr.
use std::io::Write;
use std::path::Path;

pub struct Out {
    json_to_stdout: bool,
}

impl Out {
    pub fn new(json: Option<&Path>) -> Out {
        Out {
            json_to_stdout: json.is_some_and(|p| p == Path::new("-")),
        }
    }

    pub fn say(&self, text: &str) {
        if self.json_to_stdout {
            eprintln!("{text}");
        } else {
            println!("{text}");
        }
    }

    /// Write the JSON document (atomically when it is a file).
    pub fn json(&self, json: Option<&Path>, value: &serde_json::Value) -> Result<(), String> {
        let Some(path) = json else { return Ok(()) };
        let text = serde_json::to_string_pretty(value).map_err(|e| e.to_string())? + "\n";
        if path == Path::new("-") {
            std::io::stdout()
                .write_all(text.as_bytes())
                .map_err(|e| e.to_string())
        } else {
            kinegen_model::files::write_atomic(path, &text).map_err(|e| e.to_string())
        }
    }

    /// A command's last step: its JSON document written where `--json` says,
    /// success, or exit 2 with the reason it could not be written.
    pub fn finish(&self, json: Option<&Path>, value: &serde_json::Value) -> std::process::ExitCode {
        match self.json(json, value) {
            Ok(()) => std::process::ExitCode::SUCCESS,
            Err(e) => bad(e),
        }
    }
}

/// Exit 2 with a message naming the problem (bad input or usage).
pub fn bad(msg: impl std::fmt::Display) -> std::process::ExitCode {
    eprintln!("error: {msg}");
    std::process::ExitCode::from(2)
}

/// Whether `path` can be written later (its directory, or the nearest existing
/// ancestor that would hold it, is a writable directory; `path` itself is not a
/// directory), checked without creating anything, so a long computation does
/// not end in a write error and a refused run leaves nothing behind.
/// Check a command's `--json PATH` (not `-`) and `--report DIR` before any
/// work starts, so an unwritable output is not found after it.
pub fn check_outputs(json: Option<&Path>, report: Option<&Path>) -> Result<(), String> {
    if let Some(j) = json.filter(|j| *j != Path::new("-")) {
        check_writable("--json", j)?;
    }
    if let Some(r) = report {
        check_writable("--report", &r.join("index.html"))?;
    }
    Ok(())
}

pub fn check_writable(option: &str, path: &Path) -> Result<(), String> {
    let fail = |why: String| Err(format!("{option} {}: {why}", path.display()));
    if path.is_dir() {
        return fail("is a directory".into());
    }
    match std::fs::metadata(path) {
        // a device or a pipe (/dev/null, /dev/stdout) is written in place
        Ok(m) if !m.is_file() => return Ok(()),
        Ok(m) if m.permissions().readonly() => return fail(
            "is read-only: kinegen does not replace it (make it writable, or choose another path)"
                .into(),
        ),
        _ => {}
    }
    let mut dir = path.parent().unwrap_or(Path::new("."));
    if dir.as_os_str().is_empty() {
        dir = Path::new(".");
    }
    while !dir.exists() {
        match dir.parent() {
            Some(p) if !p.as_os_str().is_empty() => dir = p,
            _ => {
                dir = Path::new(".");
                break;
            }
        }
    }
    match std::fs::metadata(dir) {
        Ok(m) if !m.is_dir() => fail(format!("{} is not a directory", dir.display())),
        Ok(m) if m.permissions().readonly() => fail(format!("{} is read-only", dir.display())),
        Ok(_) => probe(dir).or_else(|e| fail(format!("cannot write in {}: {e}", dir.display()))),
        Err(e) => fail(e.to_string()),
    }
}

/// Create and remove a hidden file in `dir` (permission bits do not tell the
/// whole story: read-only mounts, /proc, ACLs).
fn probe(dir: &Path) -> std::io::Result<()> {
    let p = dir.join(format!(".kinegen-probe-{}", std::process::id()));
    std::fs::write(&p, b"")?;
    std::fs::remove_file(&p)
}

/// A standard deviation for people: "unidentified" when the data do not
/// determine the parameter (infinite or missing std, null in JSON).
pub fn fmt_std(std: Option<f64>) -> String {
    match std {
        Some(s) if s.is_finite() => format!("{s:.1e}"),
        _ => "unidentified".into(),
    }
}
