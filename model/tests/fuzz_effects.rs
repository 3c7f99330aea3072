//! Fuzzing the effect files (issue 67): random token-level mutations of every
//! bundled effect (`spec/effects/*.toml`), with the tokens that broke the spec
//! parser and the effect files' own holes, tables and keys. Whatever the
//! text, reading it returns an effect or an error that names the file and a
//! line and column inside the text; an effect that reads is then added to
//! every bundled spec, which gives a model or an error, never a panic.
//!
//! Bounded in time for CI like fuzz_spec.rs (`KINEGEN_FUZZ_SECONDS`,
//! `PROPTEST_CASES`).
use kinegen_model::effects::Effect;
use kinegen_model::spec::Model;
use proptest::prelude::*;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;
use std::time::Instant;

mod mutation;
use mutation::{deadline, edit, hostile_in_effects, mutate_with, toml_texts};

fn effects() -> &'static [(PathBuf, String)] {
    static EFFECTS: OnceLock<Vec<(PathBuf, String)>> = OnceLock::new();
    EFFECTS.get_or_init(|| {
        let v = toml_texts("spec/effects");
        assert!(v.len() >= 10, "bundled effects not found");
        v
    })
}

fn models() -> &'static [Model] {
    static MODELS: OnceLock<Vec<Model>> = OnceLock::new();
    MODELS.get_or_init(|| {
        toml_texts("spec")
            .iter()
            .map(|(p, t)| Model::parse(p, t).unwrap())
            .collect()
    })
}

fn vocab() -> &'static [String] {
    static V: OnceLock<Vec<String>> = OnceLock::new();
    V.get_or_init(hostile_in_effects)
}

/// Read and apply on a thread with the main thread's stack size (8 MB), as
/// the CLI does; fail on a panic, or a read error that does not say where.
fn check(path: &Path, text: &str) -> Result<(), TestCaseError> {
    let (p, t) = (path.to_path_buf(), text.to_string());
    let outcome = std::thread::Builder::new()
        .stack_size(8 << 20)
        .spawn(move || {
            Effect::parse(&p, &t).map(|e| {
                for m in models() {
                    // a model or an error: both are fine, a panic is not
                    let _ = e.added_to(m);
                }
            })
        })
        .unwrap()
        .join();
    let lines = text.split('\n').count();
    match outcome {
        Err(_) => Err(TestCaseError::fail("reading or applying panicked")),
        Ok(Ok(())) => Ok(()),
        Ok(Err(e)) => {
            prop_assert!(e.file == path, "error names {}", e.file.display());
            let at = e
                .message
                .strip_prefix("line ")
                .and_then(|r| r.split_once(", column "))
                .and_then(|(l, r)| Some((l.parse::<usize>().ok()?, r)))
                .and_then(|(l, r)| {
                    let c = r.split_once(':')?.0.parse::<usize>().ok()?;
                    Some((l, c))
                });
            let Some((line, column)) = at else {
                return Err(TestCaseError::fail(format!(
                    "error without line and column: {e}"
                )));
            };
            prop_assert!(
                (1..=lines).contains(&line) && column >= 1,
                "position {line}:{column} outside the text ({lines} lines): {e}"
            );
            Ok(())
        }
    }
}

proptest! {
    #![proptest_config(mutation::config())]

    #[test]
    fn mutated_effects_read_or_fail_with_a_location_and_apply_without_panics(
        which in any::<usize>(),
        edits in prop::collection::vec(edit(), 1..4),
    ) {
        if Instant::now() > deadline() {
            return Ok(());
        }
        let (path, text) = &effects()[which % effects().len()];
        check(path, &mutate_with(text, &edits, vocab()))?;
    }
}

/// The unmutated catalogue reads and applies (the check above is not
/// vacuous: every bundled effect reaches `added_to`).
#[test]
fn the_bundled_effects_read_and_apply_to_a_bundled_spec() {
    for (path, text) in effects() {
        let e = Effect::parse(path, text).unwrap_or_else(|e| panic!("{e}"));
        assert!(
            models().iter().any(|m| e.added_to(m).is_ok()),
            "{} applies to no bundled spec",
            e.name
        );
    }
}
