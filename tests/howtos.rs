//! The guide's how-to pages run as written (docs/src/howto/*.md).
//!
//! A page is run top to bottom in one temporary home, with `kinegen` on the
//! PATH and `/path/to/kinegen` standing for this checkout:
//! - each ```sh block runs as a bash script (`-euo pipefail`): every command
//!   must succeed;
//! - a ```text block right after it shows part of what it printed: each of
//!   its lines must be printed, in order (`...` skips lines);
//! - a ```toml or ```yaml block whose first line is a comment naming a file
//!   (`# my_effects/turn_rate_loss.toml`) is that file, written as shown;
//! - a hidden `<!-- test: ... -->` comment runs its shell at that point: it
//!   makes what the page takes as given (your logs, your URDF) or checks
//!   what the commands made;
//! - `<!-- test: not run: WHY -->` right before a block leaves it out (a
//!   command for a cluster this machine does not have), saying why;
//! - `<!-- test: exits N -->` right before a block: its last command ends
//!   with exit status N (inverse's 1 for a path a robot cannot drive);
//! - `<!-- test: needs python MODULE -->` skips the page where Python lacks
//!   MODULE (CI installs it: there, it fails instead).
//!
//! Every page with a shell block is run by a test here
//! (`every_page_with_commands_is_run`). The Python page is run by the
//! Python package's tests (python/tests/test_howto.py), the firmware page's
//! Rust by the verify crate's doctests.
use std::path::PathBuf;
use std::process::Command;

mod common;
use common::{path_with_kinegen, root, shows};

/// What a page asks the runner to do, in page order.
#[derive(Debug, PartialEq)]
enum Step {
    /// A shell block (shown or hidden), where it starts, and the exit
    /// status it must end with.
    Run {
        script: String,
        line: usize,
        exit: i32,
    },
    /// Lines the previous run must print.
    Shows { text: String, line: usize },
    /// A file shown on the page, written as shown.
    Write { path: String, text: String },
    /// A Python module the page needs.
    NeedsPython(String),
}

const PAGES: &str = "docs/src/howto";

/// The steps of a page's text (see the module's doc for the markup);
/// `page` names it in panics.
fn steps_of(page: &str, text: &str) -> Vec<Step> {
    let mut out = Vec::new();
    let mut lines = text.lines().enumerate().peekable();
    let mut skip_next_block = false;
    let mut next_exit = 0;
    while let Some((i, line)) = lines.next() {
        if let Some(rest) = line.trim_start().strip_prefix("<!-- test:") {
            let mut body = rest.to_string();
            while !body.trim_end().ends_with("-->") {
                let (_, l) = lines
                    .next()
                    .unwrap_or_else(|| panic!("{page}:{}: <!-- test: unclosed", i + 1));
                body = body + "\n" + l;
            }
            let body = body.trim_end().trim_end_matches("-->").trim().to_string();
            if let Some(why) = body.strip_prefix("not run:") {
                assert!(
                    !why.trim().is_empty(),
                    "{page}:{}: say why it is not run",
                    i + 1
                );
                skip_next_block = true;
            } else if let Some(code) = body.strip_prefix("exits ") {
                next_exit = code.trim().parse().expect("`exits N`: N an exit status");
            } else if let Some(m) = body.strip_prefix("needs python") {
                out.push(Step::NeedsPython(m.trim().to_string()));
            } else {
                out.push(Step::Run {
                    script: body,
                    line: i + 1,
                    exit: 0,
                });
            }
            continue;
        }
        let Some(lang) = line.trim_start().strip_prefix("```") else {
            continue;
        };
        let indent = line.len() - line.trim_start().len();
        let body: Vec<&str> = lines
            .by_ref()
            .map(|(_, l)| l)
            .take_while(|l| !l.trim_start().starts_with("```"))
            .map(|l| l.get(indent..).unwrap_or(l.trim_start()))
            .collect();
        let body = body.join("\n") + "\n";
        if std::mem::take(&mut skip_next_block) {
            continue;
        }
        match lang {
            "sh" => out.push(Step::Run {
                script: body,
                line: i + 1,
                exit: std::mem::take(&mut next_exit),
            }),
            "text" if matches!(out.last(), Some(Step::Run { .. })) => out.push(Step::Shows {
                text: body,
                line: i + 1,
            }),
            "toml" | "yaml" => {
                let first = body.lines().next().unwrap_or("");
                let named = first
                    .strip_prefix("# ")
                    .filter(|p| !p.contains(' ') && (p.ends_with(".toml") || p.ends_with(".yaml")));
                if let Some(path) = named {
                    out.push(Step::Write {
                        path: path.to_string(),
                        text: body.clone(),
                    });
                }
            }
            _ => {}
        }
    }
    out
}

fn python_has(module: &str) -> bool {
    Command::new("python3")
        .args(["-c", &format!("import {module}")])
        .output()
        .is_ok_and(|o| o.status.success())
}

/// Run a how-to page.
fn run_page(page: &str) {
    let text = std::fs::read_to_string(root().join(PAGES).join(page)).unwrap();
    run_text(&format!("{PAGES}/{page}"), &text);
}

/// Run a page's steps in a fresh home; panic naming the page and line of
/// the first step that fails.
fn run_text(page: &str, text: &str) {
    let steps = steps_of(page, text);
    assert!(
        steps.iter().any(|s| matches!(s, Step::Run { .. })),
        "{page}: nothing to run"
    );
    for s in &steps {
        if let Step::NeedsPython(m) = s {
            if !python_has(m) {
                assert!(
                    std::env::var("CI").is_err(),
                    "CI must have python {m} (scripts/test.sh)"
                );
                eprintln!("SKIPPED {page}: python3 has no {m}");
                return;
            }
        }
    }
    let home = tempfile::tempdir().unwrap();
    let checkout = root().display().to_string();
    let mut printed = String::new();
    for s in steps {
        match s {
            Step::Run { script, line, exit } => {
                // what a terminal shows: both streams, in the order written
                let script = format!(
                    "exec 2>&1\n{}",
                    script.replace("/path/to/kinegen", &checkout)
                );
                let o = Command::new("bash")
                    .args(["-euo", "pipefail", "-c", &script])
                    .env("HOME", home.path())
                    .env("PATH", path_with_kinegen())
                    .env("NO_COLOR", "1")
                    .current_dir(home.path())
                    .output()
                    .unwrap();
                printed = String::from_utf8_lossy(&o.stdout).into_owned();
                assert!(
                    o.status.code() == Some(exit),
                    "{page}:{line}: the block ended with {} (the page expects {exit}):\n{script}\n\
                     --- printed\n{printed}",
                    o.status
                );
            }
            Step::Shows { text, line } => shows(&text, &printed)
                .unwrap_or_else(|e| panic!("{page}:{line}: {e}\nprinted:\n{printed}")),
            Step::Write { path, text } => {
                let to = home.path().join(&path);
                std::fs::create_dir_all(to.parent().unwrap()).unwrap();
                std::fs::write(to, text).unwrap();
            }
            Step::NeedsPython(_) => {}
        }
    }
}

/// The pages whose commands a test here runs.
const RUN_HERE: [&str; 7] = [
    "calibrate-diff-drive.md",
    "own-effect.md",
    "bags.md",
    "urdf.md",
    "fleet.md",
    "verify-ci.md",
    "inverse-navigate.md",
];

macro_rules! page_test {
    ($name:ident, $page:literal) => {
        #[test]
        fn $name() {
            run_page($page);
        }
    };
}

page_test!(calibrate_a_differential_drive, "calibrate-diff-drive.md");
page_test!(write_your_own_effect, "own-effect.md");
page_test!(read_a_ros2_bag, "bags.md");
page_test!(start_from_a_urdf, "urdf.md");
page_test!(run_a_fleet_with_batch_and_dask, "fleet.md");
page_test!(verify_kernels_in_ci, "verify-ci.md");
page_test!(inverse_kinematics_and_navigation, "inverse-navigate.md");

#[test]
fn every_page_with_commands_is_run() {
    let mut with_commands: Vec<String> = std::fs::read_dir(root().join(PAGES))
        .unwrap()
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| std::fs::read_to_string(p).is_ok_and(|t| t.contains("```sh")))
        .map(|p: PathBuf| p.file_name().unwrap().to_string_lossy().into_owned())
        .filter(|p| p != "python.md") // python/tests/test_howto.py
        .collect();
    with_commands.sort();
    let mut run: Vec<String> = RUN_HERE.iter().map(|s| s.to_string()).collect();
    run.sort();
    assert_eq!(with_commands, run, "a how-to with commands no test runs");
}

/// The runner is not blind: the markup is read as the module's doc says,
/// a failing command and a shown line that is not printed each fail the
/// page, and a block marked "not run" is not run.
#[test]
fn the_markup_is_read_as_the_module_doc_says() {
    let page = "Intro\n<!-- test: echo made > log.csv -->\n```sh\ncat log.csv\n```\n\
                ```text\nmade\n```\n```toml\n# a/b.toml\nx = 1\n```\n\
                <!-- test: not run: a cluster -->\n```sh\nfalse\n```\n";
    assert_eq!(
        steps_of("page", page),
        vec![
            Step::Run {
                script: "echo made > log.csv".into(),
                line: 2,
                exit: 0
            },
            Step::Run {
                script: "cat log.csv\n".into(),
                line: 3,
                exit: 0
            },
            Step::Shows {
                text: "made\n".into(),
                line: 6
            },
            Step::Write {
                path: "a/b.toml".into(),
                text: "# a/b.toml\nx = 1\n".into()
            },
        ]
    );
    run_text("page", page);
    let fails = |text: &str| std::panic::catch_unwind(|| run_text("page", text)).is_err();
    assert!(fails(
        &page.replace("<!-- test: not run: a cluster -->\n", "")
    ));
    assert!(fails(&page.replace("```text\nmade", "```text\nnot made")));
}
