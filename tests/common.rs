//! Helpers shared by the end-to-end tests: run the kinegen binary.
#![allow(dead_code)]
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

pub fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

pub fn kinegen(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_kinegen"))
        .args(args)
        .current_dir(root())
        .output()
        .expect("run kinegen")
}

pub fn kinegen_in(dir: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_kinegen"))
        .args(args)
        .current_dir(dir)
        .output()
        .expect("run kinegen")
}

pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).to_string()
}

pub fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).to_string()
}

/// Copy a directory's files (not recursive).
pub fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap().flatten() {
        if e.path().is_file() {
            std::fs::copy(e.path(), to.join(e.file_name())).unwrap();
        }
    }
}

/// Run kinegen with `--json -` appended and parse stdout.
pub fn kinegen_json(args: &[&str]) -> serde_json::Value {
    let mut a = args.to_vec();
    a.extend(["--json", "-"]);
    let o = kinegen(&a);
    assert!(
        o.status.success(),
        "kinegen {:?} failed: {}",
        args,
        stderr(&o)
    );
    serde_json::from_slice(&o.stdout).unwrap_or_else(|e| {
        panic!(
            "stdout of {args:?} is not one JSON document ({e}): {}",
            stdout(&o)
        )
    })
}

/// Simulate a log into `dir`; returns its path.
pub fn simulate(dir: &Path, name: &str, args: &[&str]) -> PathBuf {
    let out = dir.join(name);
    let mut a = vec!["simulate"];
    a.extend_from_slice(args);
    a.extend(["--out", out.to_str().unwrap()]);
    let o = kinegen(&a);
    assert!(o.status.success(), "simulate {args:?}: {}", stderr(&o));
    out
}

pub fn real_runs() -> Vec<PathBuf> {
    let dir = root().join("../shared/real/optiodom-diff-square");
    assert!(
        dir.exists(),
        "the real logs are expected at {} (shared/ beside the checkout)",
        dir.display()
    );
    (1..=6).map(|i| dir.join(format!("run-0{i}.csv"))).collect()
}
