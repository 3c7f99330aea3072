//! The README's commands run as written, and print what it shows.
//!
//! - "Your own robot": the block is run as one shell script, in a temporary
//!   home folder, with `kinegen` on the PATH and `/path/to/kinegen` standing
//!   for this checkout; every command must succeed, diagnose must name the
//!   effect the robot was simulated with, and verify must end with its
//!   verdict.
//! - "A five-minute tour": each `kinegen` command is run from the checkout,
//!   and each line of the ```text block after it must be a line of what the
//!   command prints (a line `...` stands for lines left out), so the output
//!   the README shows is the program's.
use std::process::Command;

mod common;
use common::{path_with_kinegen, root, run_in_home, shows};

/// The fenced blocks of a markdown section: (language, text).
fn blocks(readme: &str, heading: &str) -> Vec<(String, String)> {
    let start = readme
        .find(&format!("\n## {heading}\n"))
        .unwrap_or_else(|| panic!("README has no section `## {heading}`"));
    let section = &readme[start + 1..];
    let end = section[3..].find("\n## ").map_or(section.len(), |i| i + 3);
    let mut out = Vec::new();
    let mut lines = section[..end].lines();
    while let Some(line) = lines.next() {
        if let Some(lang) = line.strip_prefix("```") {
            let body: Vec<&str> = lines
                .by_ref()
                .take_while(|l| !l.starts_with("```"))
                .collect();
            out.push((lang.to_string(), body.join("\n") + "\n"));
        }
    }
    out
}

#[test]
fn the_own_robot_block_runs_as_written() {
    let readme = std::fs::read_to_string(root().join("README.md")).unwrap();
    let b = blocks(&readme, "Your own robot");
    let (_, script) = b.iter().find(|(l, _)| l == "sh").expect("an sh block");
    assert!(script.contains("kinegen verify"), "{script}");
    let (home, o) = run_in_home(script);
    let out = String::from_utf8_lossy(&o.stdout);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "the block failed:\n{out}\n{err}");
    assert!(
        out.contains("lateral_slip"),
        "diagnose did not name lateral_slip:\n{out}"
    );
    let last = out
        .lines()
        .rfind(|l| l.starts_with("verify: "))
        .unwrap_or("");
    assert!(last.starts_with("verify: passed"), "{out}\n{err}");
    assert!(home.path().join("my_robot/my_kernels/Cargo.toml").is_file());
}

#[test]
fn the_tour_prints_what_the_readme_shows() {
    let readme = std::fs::read_to_string(root().join("README.md")).unwrap();
    let b = blocks(&readme, "A five-minute tour");
    let tmp = tempfile::tempdir().unwrap();
    let mut checked = 0;
    let mut printed = String::new();
    for (lang, text) in &b {
        match lang.as_str() {
            "sh" => {
                printed.clear();
                for cmd in text.lines().filter(|l| l.starts_with("kinegen ")) {
                    // outputs a command writes go to a scratch folder
                    let cmd = cmd.replace(
                        "my_robot.toml",
                        &tmp.path().join("my_robot.toml").display().to_string(),
                    );
                    let o = Command::new("bash")
                        .args(["-c", &cmd])
                        .env("PATH", path_with_kinegen())
                        .current_dir(root())
                        .output()
                        .unwrap();
                    assert!(
                        o.status.success(),
                        "{cmd}: {}",
                        String::from_utf8_lossy(&o.stderr)
                    );
                    printed += &String::from_utf8_lossy(&o.stdout);
                }
            }
            "text" => {
                shows(text, &printed).unwrap_or_else(|e| panic!("{e}\nprinted:\n{printed}"));
                checked += 1;
            }
            _ => {}
        }
    }
    assert!(checked >= 3, "the tour shows {checked} outputs");
}

/// The comparison is not blind: a line the program does not print fails.
#[test]
fn a_shown_line_that_is_not_printed_fails() {
    assert!(shows("a\n...\nc", "a\nb\nc\n").is_ok());
    assert!(shows("a\nd", "a\nb\nc\n").is_err());
    assert!(shows("c\na", "a\nb\nc\n").is_err());
}

/// The guide's tutorial runs as written: its shell blocks, in order, as one
/// script from a temporary home (the bag step needs Python's rosbags, which
/// scripts/test.sh installs).
#[test]
fn the_tutorial_runs_as_written() {
    let text = std::fs::read_to_string(root().join("docs/src/tutorial/own-robot.md")).unwrap();
    let mut script = String::new();
    let mut lines = text.lines();
    while let Some(line) = lines.next() {
        if line == "```sh" {
            for l in lines.by_ref().take_while(|l| !l.starts_with("```")) {
                script += l;
                script.push('\n');
            }
        }
    }
    assert!(script.contains("csv_to_bag.py") && script.contains("kinegen verify"));
    let have_rosbags = Command::new("python3")
        .args(["-c", "import rosbags"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !have_rosbags {
        assert!(
            std::env::var("CI").is_err(),
            "CI must have rosbags (scripts/test.sh)"
        );
        eprintln!("SKIPPED the_tutorial_runs_as_written: python3 has no rosbags");
        return;
    }
    let (_home, o) = run_in_home(&script);
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "the tutorial failed:\n{out}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(out.contains("lateral_slip"), "{out}");
    assert!(
        out.lines().any(|l| l.starts_with("verify: passed")),
        "{out}"
    );
}
