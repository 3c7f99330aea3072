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
use std::time::Instant;

mod mutation;
use mutation::{deadline, edit, hostile, mutate, toml_texts};

fn specs() -> &'static [(PathBuf, String)] {
    static SPECS: OnceLock<Vec<(PathBuf, String)>> = OnceLock::new();
    SPECS.get_or_init(|| {
        let v = toml_texts("spec");
        assert!(v.len() >= 5, "bundled specs not found");
        v
    })
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
    #![proptest_config(mutation::config())]

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
