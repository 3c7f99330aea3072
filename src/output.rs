//! Where human text and JSON go: with `--json -` stdout carries exactly one JSON
//! document and everything for people goes to stderr.
use std::io::Write;
use std::path::Path;

pub struct Out {
    json_to_stdout: bool,
    /// Says nothing: the detail a command's `-v` text gives, while the
    /// default text says its summary (the JSON is built either way).
    mute: bool,
    /// Keeps what is said instead of printing it: the answer a command
    /// prints is also the box its report opens with.
    kept: Option<std::cell::RefCell<Vec<String>>>,
}

impl Out {
    pub fn new(json: Option<&Path>) -> Out {
        Out {
            json_to_stdout: json.is_some_and(|p| p == Path::new("-")),
            mute: false,
            kept: None,
        }
    }

    /// An output that keeps its lines (`lines`) instead of printing them.
    pub fn keeping() -> Out {
        Out {
            json_to_stdout: false,
            mute: false,
            kept: Some(Default::default()),
        }
    }

    /// The lines kept so far (an output made by `keeping`).
    pub fn lines(&self) -> Vec<String> {
        self.kept
            .as_ref()
            .map(|k| {
                k.borrow()
                    .iter()
                    .flat_map(|l| l.split('\n').map(String::from))
                    .collect()
            })
            .unwrap_or_default()
    }

    /// This output when `verbose`, else one that says nothing.
    pub fn detail(&self, verbose: bool) -> Out {
        Out {
            json_to_stdout: self.json_to_stdout,
            mute: !verbose,
            kept: None,
        }
    }

    pub fn say(&self, text: &str) {
        if self.mute {
            return;
        }
        if let Some(k) = &self.kept {
            k.borrow_mut().push(text.to_string());
            return;
        }
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
    // a link that points nowhere (the path itself, or a folder on the way)
    // would be followed when written, creating its target's folders
    for p in path.ancestors() {
        if p.exists() {
            break;
        }
        if let Ok(target) = std::fs::read_link(p) {
            return fail(format!(
                "{} is a link to {}, which does not exist",
                p.display(),
                target.display()
            ));
        }
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

/// The widest line a command prints by default: a terminal's 100 columns.
pub const WIDTH: usize = 100;

/// A command line for people, wrapped at spaces to at most `WIDTH` columns
/// with shell continuations, indented by `indent`, so it can be pasted as it
/// is printed.
pub fn command_lines(cmd: &str, indent: usize) -> Vec<String> {
    let pad = " ".repeat(indent);
    let mut lines = Vec::new();
    let mut line = pad.clone();
    // an option and its value stay on one line
    let mut words: Vec<String> = Vec::new();
    for w in cmd.split(' ') {
        match words.last_mut() {
            Some(last) if last.starts_with("--") && !last.contains(' ') && !w.starts_with("--") => {
                last.push(' ');
                last.push_str(w);
            }
            _ => words.push(w.to_string()),
        }
    }
    for word in &words {
        let first = line.trim().is_empty();
        // room for " word \"
        if !first && line.chars().count() + 1 + word.chars().count() + 2 > WIDTH {
            lines.push(format!("{line} \\"));
            line = format!("{pad}    {word}");
        } else if first {
            line.push_str(word);
        } else {
            line.push(' ');
            line.push_str(word);
        }
    }
    lines.push(line);
    lines
}

/// A value with its standard deviation, to the digits the deviation leaves
/// meaningful: `0.1006 ± 0.0004`; "unidentified" where there is none.
pub fn with_std(value: f64, std: f64) -> String {
    if !std.is_finite() || std <= 0.0 {
        return match value.abs() >= 1e9 {
            true => format!("{value:.4e} (unidentified)"),
            false => format!("{value:.4} (unidentified)"),
        };
    }
    if value.abs() >= 1e9 {
        return format!("{value:.4e} ± {std:.1e}");
    }
    // two significant digits of the deviation
    let digits = (-(std.log10().floor()) + 1.0).clamp(0.0, 12.0) as usize;
    format!("{value:.digits$} ± {std:.digits$}")
}

/// A number as written in a spec, but in scientific notation when it is
/// too large to read (a value of 1e308 is 309 digits).
pub fn number(v: f64) -> String {
    if v.abs() >= 1e9 {
        format!("{v:.4e}")
    } else if v.abs() < 1e-4 && v != 0.0 {
        format!("{v:e}")
    } else {
        format!("{v}")
    }
}

/// A line cut to `WIDTH` columns, with `…` where it is cut (the whole text
/// is behind -v, in the JSON or in a file).
pub fn cut(s: &str) -> String {
    if s.chars().count() <= WIDTH {
        s.to_string()
    } else {
        s.chars().take(WIDTH - 1).collect::<String>() + "…"
    }
}

/// An aligned table without borders, as wide as its contents: the shape of
/// every command's default table.
pub fn table(header: &[&str]) -> comfy_table::Table {
    let mut t = comfy_table::Table::new();
    t.load_preset(comfy_table::presets::NOTHING)
        .set_content_arrangement(comfy_table::ContentArrangement::Disabled)
        .set_header(header.iter().map(comfy_table::Cell::new));
    // figures line up on their last digit: every column but the first
    for i in 1..header.len() {
        if let Some(c) = t.column_mut(i) {
            c.set_cell_alignment(comfy_table::CellAlignment::Right);
        }
    }
    t
}

/// A table's lines, each cut at `WIDTH` columns (with `…`), without the
/// padding comfy-table leaves at either end.
pub fn table_lines(t: &comfy_table::Table) -> Vec<String> {
    t.lines()
        .map(|l| {
            let l = l.trim_end().to_string();
            let l = l.strip_prefix(' ').unwrap_or(&l).to_string();
            cut(&format!("  {l}"))
        })
        .collect()
}

/// Warnings for people: each said once, wrapped to the width, the first
/// `lines` lines of each (the rest with -v and in the JSON); returns how
/// many lines were said.
pub fn say_warnings_short(out: &Out, warnings: &[String], lines: usize) -> usize {
    let mut seen = std::collections::BTreeSet::new();
    let mut said = 0;
    for w in warnings.iter().filter(|w| seen.insert(w.as_str())) {
        for l in warning_lines(w, lines) {
            out.say(&l);
            said += 1;
        }
    }
    said
}

/// One warning wrapped to the width, cut to its first `lines` lines.
pub fn warning_lines(w: &str, lines: usize) -> Vec<String> {
    let text = format!("warning: {w}");
    let wrapped = textwrap::wrap(&text, textwrap::Options::new(WIDTH).subsequent_indent("  "));
    let mut out = Vec::new();
    for (i, l) in wrapped.iter().enumerate() {
        if i + 1 == lines && wrapped.len() > lines {
            let cut: String = l.chars().take(WIDTH - 8).collect();
            out.push(format!("{cut} … (-v)"));
            break;
        }
        out.push(l.to_string());
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_long_command_wraps_with_continuations_within_the_width() {
        let cmd = format!(
            "kinegen fit --spec {} --data log.csv --export spec x.toml",
            "a/".repeat(40)
        );
        let lines = command_lines(&cmd, 2);
        assert!(lines.len() >= 2, "{lines:?}");
        assert!(
            lines.iter().all(|l| l.chars().count() <= WIDTH),
            "{lines:?}"
        );
        assert!(lines[..lines.len() - 1].iter().all(|l| l.ends_with(" \\")));
        let joined: Vec<&str> = lines
            .iter()
            .map(|l| l.trim().trim_end_matches('\\').trim())
            .collect();
        assert_eq!(joined.join(" "), cmd);
    }

    #[test]
    fn a_value_keeps_the_digits_its_deviation_leaves() {
        assert_eq!(with_std(0.100599, 0.00039), "0.10060 ± 0.00039");
        assert_eq!(with_std(1.5, f64::INFINITY), "1.5000 (unidentified)");
    }
}
