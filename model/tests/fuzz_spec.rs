//! Fuzzing the spec parser (issue 16): random token-level mutations of every
//! bundled spec, with the tokens that broke kinegen before (deep nesting,
//! overflowing literals, towers of powers, keywords as names, non-ASCII text).
//! Whatever the text, `Model::parse` returns: no panic, no stack overflow
//! (which would abort this test binary), and every error names the file and a
//! line and column inside the text.
//!
//! Bounded in time for CI: cases stop being checked after
//! `KINEGEN_FUZZ_SECONDS` (default 20) seconds; `PROPTEST_CASES` raises the
//! number of cases for a longer local run.
use kinegen_model::spec::Model;
use proptest::prelude::*;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;
use std::time::{Duration, Instant};

fn specs() -> &'static [(PathBuf, String)] {
    static SPECS: OnceLock<Vec<(PathBuf, String)>> = OnceLock::new();
    SPECS.get_or_init(|| {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../spec");
        let mut v: Vec<(PathBuf, String)> = std::fs::read_dir(&dir)
            .unwrap()
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|x| x == "toml"))
            .map(|p| (p.clone(), std::fs::read_to_string(&p).unwrap()))
            .collect();
        v.sort();
        assert!(v.len() >= 5, "bundled specs not found in {}", dir.display());
        v
    })
}

fn deadline() -> Instant {
    static START: OnceLock<Instant> = OnceLock::new();
    let secs = std::env::var("KINEGEN_FUZZ_SECONDS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(20);
    *START.get_or_init(Instant::now) + Duration::from_secs(secs)
}

/// Tokens of a spec: runs of identifier characters, runs of digits and dots,
/// runs of spaces, and single other characters.
fn tokens(text: &str) -> Vec<String> {
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

/// What a mutation may put into a spec.
fn hostile() -> Vec<String> {
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
enum Edit {
    Replace(usize, usize),
    Delete(usize),
    Insert(usize, usize),
    Duplicate(usize),
}

fn edit() -> impl Strategy<Value = Edit> {
    prop_oneof![
        (any::<usize>(), any::<usize>()).prop_map(|(a, b)| Edit::Replace(a, b)),
        any::<usize>().prop_map(Edit::Delete),
        (any::<usize>(), any::<usize>()).prop_map(|(a, b)| Edit::Insert(a, b)),
        any::<usize>().prop_map(Edit::Duplicate),
    ]
}

fn mutate(text: &str, edits: &[Edit]) -> String {
    let vocab = hostile();
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

/// Parse on a thread with the main thread's stack size (8 MB), as the CLI
/// does, and fail on a panic or an error that does not say where.
fn check(path: &Path, text: &str) -> Result<(), TestCaseError> {
    let (p, t) = (path.to_path_buf(), text.to_string());
    let outcome = std::thread::Builder::new()
        .stack_size(8 << 20)
        .spawn(move || Model::parse(&p, &t).map(|_| ()))
        .unwrap()
        .join();
    match outcome {
        Err(_) => Err(TestCaseError::fail("the parser panicked")),
        Ok(Ok(())) => Ok(()),
        Ok(Err(e)) => {
            let shown = e.to_string();
            prop_assert!(
                shown.starts_with(&path.display().to_string()),
                "error does not name the file: {shown}"
            );
            let Some(pos) = e.pos else {
                return Err(TestCaseError::fail(format!(
                    "error without line and column: {shown}"
                )));
            };
            let lines = text.split('\n').count();
            prop_assert!(
                pos.line >= 1 && pos.line <= lines && pos.column >= 1,
                "position {}:{} outside the text ({lines} lines): {shown}",
                pos.line,
                pos.column
            );
            Ok(())
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig {
        cases: std::env::var("PROPTEST_CASES").ok().and_then(|s| s.parse().ok()).unwrap_or(400),
        failure_persistence: None,
        ..ProptestConfig::default()
    })]

    #[test]
    fn mutated_specs_parse_or_fail_with_a_location(
        which in any::<usize>(),
        edits in prop::collection::vec(edit(), 1..4),
    ) {
        if Instant::now() > deadline() {
            return Ok(());
        }
        let (path, text) = &specs()[which % specs().len()];
        check(path, &mutate(text, &edits))?;
    }
}

/// The mutations can reach the parser's limits: a hostile token inserted into
/// an expression of every bundled spec is rejected with a location, not a crash.
#[test]
fn every_hostile_token_in_every_expression() {
    for (path, text) in specs() {
        for h in hostile() {
            // the first expression of the spec: `vx = "..."` in [motion]
            let Some(at) = text.find("vx = \"") else {
                continue;
            };
            let at = at + "vx = \"".len();
            let mutated = format!("{}{h}{}", &text[..at], &text[at..]);
            check(path, &mutated).unwrap_or_else(|e| panic!("{}: {h:?}: {e}", path.display()));
        }
    }
}
