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
            kinegen_codegen::generate::write_atomic(path, &text).map_err(|e| e.to_string())
        }
    }
}

/// A standard deviation for people: "unidentified" when the data do not
/// determine the parameter (infinite or missing std, null in JSON).
pub fn fmt_std(std: Option<f64>) -> String {
    match std {
        Some(s) if s.is_finite() => format!("{s:.1e}"),
        _ => "unidentified".into(),
    }
}
