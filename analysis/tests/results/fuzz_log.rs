//! Fuzzing the log reader (issue 16): random mutations of a real-format log
//! (cells replaced by hostile values, rows deleted, duplicated, swapped, cut
//! or widened, the header's names duplicated or renamed, another separator, a
//! byte-order mark). Whatever the file, reading it for a model either fails
//! with an error that names the file and a line or column inside it, or gives
//! a run whose dead reckoning is refused at a located row
//! (`track_rows::first_non_finite`) or yields finite error figures: never a
//! panic, never a NaN that looks like a result. The track computed at once
//! and the one computed as it is read (`track_rows::Recipe`) agree.
//!
//! Bounded in time for CI: cases stop being checked after
//! `KINEGEN_FUZZ_SECONDS` (default 20) seconds; `PROPTEST_CASES` raises the
//! number of cases for a longer local run.
use kinegen_analysis::model_on_log::run::Run;
use kinegen_analysis::model_on_log::track_rows::{first_non_finite, Heading, Recipe, TrackRows};
use kinegen_analysis::model_on_log::{deadreckon, metrics, model::Runner};
use kinegen_model::ir::ModelIr;
use proptest::prelude::*;
use std::path::Path;
use std::sync::OnceLock;
use std::time::{Duration, Instant};

fn runner() -> &'static Runner {
    static R: OnceLock<Runner> = OnceLock::new();
    R.get_or_init(|| {
        let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../generated/ir/diff_drive.json");
        let ir = ModelIr::from_json(&std::fs::read_to_string(p).unwrap()).unwrap();
        Runner::new(ir, &[]).unwrap()
    })
}

/// The first 200 rows of the bundled diff-drive log.
fn base() -> &'static Vec<String> {
    static B: OnceLock<Vec<String>> = OnceLock::new();
    B.get_or_init(|| {
        let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/mystery_robot.csv");
        let text = std::fs::read_to_string(p).unwrap();
        text.lines().take(201).map(str::to_string).collect()
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

const HOSTILE: &[&str] = &[
    "",
    " ",
    "nan",
    "NaN",
    "inf",
    "-inf",
    "1e308",
    "-1e308",
    "1e-300",
    "1e400",
    "abc",
    "ω",
    "0x10",
    "1,5",
    "\"",
    "\"1\"",
    "1e",
    "--1",
    "0",
    "-0",
    "4294967295",
    "2147483648",
    // a counter that wraps like a 32- or 16-bit register (issue 37.5)
    "-4294967296",
    "65536",
    "t",
    "enc_r",
    "gt_theta",
];

#[derive(Debug, Clone)]
enum Edit {
    Cell(usize, usize, usize),
    DeleteRow(usize),
    DuplicateRow(usize),
    SwapRows(usize, usize),
    CutRow(usize, usize),
    ExtraCell(usize),
    DropCell(usize, usize),
    RenameColumn(usize, usize),
    Semicolons,
    ByteOrderMark,
    KeepRows(usize),
    /// A `#` line inserted before row r (before the header: a logger's
    /// description; among the data: a row that is none).
    Comment(usize),
    /// The header written as a comment, as numpy's savetxt does.
    CommentedHeader,
}

fn edit() -> impl Strategy<Value = Edit> {
    let u = || any::<usize>();
    prop_oneof![
        4 => (u(), u(), u()).prop_map(|(r, c, v)| Edit::Cell(r, c, v)),
        1 => u().prop_map(Edit::DeleteRow),
        1 => u().prop_map(Edit::DuplicateRow),
        1 => (u(), u()).prop_map(|(a, b)| Edit::SwapRows(a, b)),
        1 => (u(), u()).prop_map(|(a, b)| Edit::CutRow(a, b)),
        1 => u().prop_map(Edit::ExtraCell),
        1 => (u(), u()).prop_map(|(a, b)| Edit::DropCell(a, b)),
        1 => (u(), u()).prop_map(|(a, b)| Edit::RenameColumn(a, b)),
        1 => Just(Edit::Semicolons),
        1 => Just(Edit::ByteOrderMark),
        1 => u().prop_map(Edit::KeepRows),
        1 => u().prop_map(Edit::Comment),
        1 => Just(Edit::CommentedHeader),
    ]
}

fn mutate(edits: &[Edit]) -> String {
    let mut rows: Vec<Vec<String>> = base()
        .iter()
        .map(|l| l.split(',').map(str::to_string).collect())
        .collect();
    let (mut sep, mut bom) = (",", "");
    for e in edits {
        let n = rows.len();
        // data rows are 1..n (row 0 is the header)
        let data = |i: usize| if n > 1 { 1 + i % (n - 1) } else { 0 };
        match *e {
            Edit::Cell(r, c, v) => {
                let r = data(r);
                if let Some(row) = rows.get_mut(r) {
                    if !row.is_empty() {
                        let c = c % row.len();
                        row[c] = HOSTILE[v % HOSTILE.len()].to_string();
                    }
                }
            }
            Edit::DeleteRow(r) if n > 1 => {
                rows.remove(data(r));
            }
            Edit::DuplicateRow(r) if n > 1 => {
                let r = data(r);
                rows.insert(r, rows[r].clone());
            }
            Edit::SwapRows(a, b) if n > 1 => rows.swap(data(a), data(b)),
            Edit::CutRow(r, k) if n > 1 => {
                let r = data(r);
                let line = rows[r].join(",");
                let cut = k % (line.len() + 1);
                rows[r] = line[..cut].split(',').map(str::to_string).collect();
            }
            Edit::ExtraCell(r) if n > 1 => rows[data(r)].push("1".into()),
            Edit::DropCell(r, c) if n > 1 => {
                let r = data(r);
                if !rows[r].is_empty() {
                    let c = c % rows[r].len();
                    rows[r].remove(c);
                }
            }
            Edit::RenameColumn(c, v) if n > 0 && !rows[0].is_empty() => {
                let c = c % rows[0].len();
                rows[0][c] = HOSTILE[v % HOSTILE.len()].to_string();
            }
            Edit::Semicolons => sep = ";",
            Edit::ByteOrderMark => bom = "\u{feff}",
            Edit::KeepRows(k) => rows.truncate(k % 8),
            Edit::Comment(r) => {
                let r = r % (n + 1);
                rows.insert(r, vec!["# robot 3".into(), " firmware 2.1".into()]);
            }
            Edit::CommentedHeader if n > 0 && !rows[0].is_empty() => {
                rows[0][0] = format!("# {}", rows[0][0]);
            }
            _ => {}
        }
    }
    let lines: Vec<String> = rows.iter().map(|r| r.join(sep)).collect();
    format!("{bom}{}\n", lines.join("\n"))
}

fn finite(x: f64) -> bool {
    x.is_finite()
}

fn check(text: &str) -> Result<(), TestCaseError> {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("fuzz.csv");
    std::fs::write(&path, text).unwrap();
    let lines = text.lines().count().max(1);
    let r = runner();
    let outcome = std::panic::catch_unwind(|| {
        let run = Run::read(&path, r)?;
        let track = deadreckon::run(r, &r.p, &run, false);
        Ok((run, track))
    });
    let read: Result<_, kinegen_analysis::logs::log::LogError> = match outcome {
        Ok(x) => x,
        Err(_) => return Err(TestCaseError::fail("reading the log panicked")),
    };
    match read {
        Err(e) => {
            let shown = e.to_string();
            prop_assert!(
                shown.starts_with(&path.display().to_string()),
                "error does not name the file: {shown}"
            );
            prop_assert!(
                e.row.is_some() || e.column.is_some(),
                "error without a line or column: {shown}"
            );
            if let Some(row) = e.row {
                prop_assert!(
                    row >= 1 && row <= lines + 1,
                    "line {row} outside the file ({lines} lines): {shown}"
                );
            }
        }
        Ok((run, track)) => {
            let recipe = Recipe {
                r,
                p: r.p.clone(),
                offset: [0.0; 3],
                heading: Heading::Model,
            };
            let refused = first_non_finite(&track, &run);
            prop_assert_eq!(&refused, &first_non_finite(&recipe, &run));
            if let Some((k, _)) = refused {
                prop_assert!(k < run.t.len(), "refused at row {k} of {}", run.t.len());
                return Ok(());
            }
            let e = metrics::errors(&[(&run, &track as &dyn TrackRows)]);
            let streamed = metrics::errors(&[(&run, &recipe as &dyn TrackRows)]);
            prop_assert_eq!(format!("{e:?}"), format!("{streamed:?}"));
            let figures = [
                e.rmse,
                e.heading_rmse_rad,
                e.final_position_error_m,
                e.final_heading_error_rad,
                e.max_position_error_m,
            ];
            prop_assert!(
                figures.into_iter().all(finite)
                    && [e.rpe_per_m, e.rpe_5s_m, e.gyro_rmse_rad_s]
                        .into_iter()
                        .flatten()
                        .all(finite),
                "non-finite results from an accepted log: {e:?}"
            );
        }
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig {
        cases: std::env::var("PROPTEST_CASES").ok().and_then(|s| s.parse().ok()).unwrap_or(300),
        failure_persistence: None,
        ..ProptestConfig::default()
    })]

    #[test]
    fn mutated_logs_are_read_or_refused_with_a_location(edits in prop::collection::vec(edit(), 1..4)) {
        if Instant::now() > deadline() {
            return Ok(());
        }
        check(&mutate(&edits))?;
    }
}

/// Every hostile value in every column of one row: the cases the random
/// search might reach only by luck.
#[test]
fn every_hostile_value_in_every_column() {
    let ncols = base()[0].split(',').count();
    for c in 0..ncols {
        for (v, hostile) in HOSTILE.iter().enumerate() {
            let text = mutate(&[Edit::Cell(57, c, v)]);
            check(&text).unwrap_or_else(|e| panic!("column {c}, {hostile:?}: {e}"));
        }
    }
}
