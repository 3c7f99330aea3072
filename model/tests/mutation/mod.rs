//! Token-level mutation of text files (specs, effect files) for the parser
//! fuzz tests: the vocabulary of tokens that broke kinegen before, the edits
//! proptest draws, and the time bound that keeps CI short.
#![allow(dead_code)] // each fuzz test binary uses its own part of this module
use proptest::prelude::*;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;
use std::time::{Duration, Instant};

/// Cases stop being checked after `KINEGEN_FUZZ_SECONDS` (default 20)
/// seconds of this test binary.
pub fn deadline() -> Instant {
    static START: OnceLock<Instant> = OnceLock::new();
    let secs = std::env::var("KINEGEN_FUZZ_SECONDS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(20);
    *START.get_or_init(Instant::now) + Duration::from_secs(secs)
}

/// The `*.toml` files of the repository folder `folder` (`spec`,
/// `spec/effects`) with their text: what the fuzzers mutate.
pub fn toml_texts(folder: &str) -> Vec<(PathBuf, String)> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .join(folder);
    let files = kinegen_model::files::spec_files(&dir).unwrap();
    let texts = files.into_iter().map(|p| {
        let text = std::fs::read_to_string(&p).unwrap();
        (p, text)
    });
    texts.collect()
}

/// The fuzz tests' proptest settings: 400 cases (`PROPTEST_CASES` for a
/// longer local run), no regression files written.
pub fn config() -> ProptestConfig {
    ProptestConfig {
        cases: std::env::var("PROPTEST_CASES")
            .ok()
            .and_then(|s| s.parse().ok())
            .unwrap_or(400),
        failure_persistence: None,
        ..ProptestConfig::default()
    }
}

/// Tokens of a spec: runs of identifier characters, runs of digits and dots,
/// runs of spaces, and single other characters.
pub fn tokens(text: &str) -> Vec<String> {
    let class = |c: char| {
        if c.is_alphanumeric() || c == '_' || c == '.' {
            0
        } else if c == ' ' {
            1
        } else {
            2
        }
    };
    let mut out: Vec<String> = Vec::new();
    let mut prev = None;
    for c in text.chars() {
        let k = class(c);
        match out.last_mut() {
            Some(t) if prev == Some(k) && k != 2 => t.push(c),
            _ => out.push(c.to_string()),
        }
        prev = Some(k);
    }
    out
}

/// What an effect file may be given on top of [`hostile`]: its holes, its
/// tables and the keys that steer how a patch is applied.
pub fn hostile_in_effects() -> Vec<String> {
    let mut v = hostile();
    v.extend(
        [
            "{vx}",
            "{vy}",
            "{omega}",
            "{input}",
            "{inverse}",
            "{input_unit}",
            "{0}",
            "{",
            "deadband_{input}",
            "[[parameter]]",
            "[[each_input]]",
            "[observation.pose]",
            "[observation.range_bearing]",
            "[observation.gyro]",
            "create = true",
            "substitute",
            "class = \"command\"",
            "class = \"wheel\"",
            "bounds = \"robot_size\"",
            "bounds = \"input_range\"",
            "requires",
            "input_delay",
            "nominal = -1e308",
        ]
        .iter()
        .map(|s| s.to_string()),
    );
    v
}

/// What a mutation may put into a spec.
pub fn hostile() -> Vec<String> {
    let mut v: Vec<String> = [
        "(",
        ")",
        "-",
        "+",
        "*",
        "/",
        "^",
        ",",
        "=",
        "[",
        "]",
        "{",
        "}",
        "\"",
        "'",
        "\n",
        "#",
        "0",
        "0.0",
        "-1",
        "1e400",
        "-1e400",
        "1e-300",
        "nan",
        "inf",
        "0/0",
        "sqrt(-1)",
        "ln(0)",
        "atan2(",
        "atan2(0,0)",
        "2^2^2^2^2^2",
        "n_r^1000000000",
        "10^400",
        "fn",
        "lib",
        "self",
        "mod",
        "true",
        "false",
        "ω",
        "θ",
        "é",
        "\u{0}",
        "\t",
        "[motion]",
        "[[observation]]",
        "[[param]]",
        "[[input]]",
        "[inverse]",
        "name",
        "min",
        "max",
        "sigma",
        "range",
        "wrap = 32",
        "measurement_delay = true",
        "x",
        "y",
        "theta",
        "pose",
        "gyro",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    v.push("(".repeat(5000) + "x" + &")".repeat(5000));
    v.push("-".repeat(5000) + "x");
    v.push(vec!["x"; 20000].join("+"));
    v
}

#[derive(Debug, Clone)]
pub enum Edit {
    Replace(usize, usize),
    Delete(usize),
    Insert(usize, usize),
    Duplicate(usize),
}

pub fn edit() -> impl Strategy<Value = Edit> {
    prop_oneof![
        (any::<usize>(), any::<usize>()).prop_map(|(a, b)| Edit::Replace(a, b)),
        any::<usize>().prop_map(Edit::Delete),
        (any::<usize>(), any::<usize>()).prop_map(|(a, b)| Edit::Insert(a, b)),
        any::<usize>().prop_map(Edit::Duplicate),
    ]
}

/// `text` with `edits` applied to its tokens, drawing from [`hostile`].
pub fn mutate(text: &str, edits: &[Edit]) -> String {
    mutate_with(text, edits, &hostile())
}

/// `text` with `edits` applied to its tokens, drawing from `vocab`.
pub fn mutate_with(text: &str, edits: &[Edit], vocab: &[String]) -> String {
    let mut t = tokens(text);
    for e in edits {
        let n = t.len().max(1);
        match *e {
            Edit::Replace(i, w) if !t.is_empty() => t[i % n] = vocab[w % vocab.len()].clone(),
            Edit::Delete(i) if !t.is_empty() => {
                t.remove(i % n);
            }
            Edit::Insert(i, w) => t.insert(i % (t.len() + 1), vocab[w % vocab.len()].clone()),
            Edit::Duplicate(i) if !t.is_empty() => {
                let x = t[i % n].clone();
                t.insert(i % n, x);
            }
            _ => {}
        }
    }
    t.concat()
}
