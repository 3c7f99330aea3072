//! CONTRACT section 1 (third round), issue #38: `kinegen batch` runs many
//! jobs, one result line each, a failing job stopping nothing, and resumes
//! after a kill without running a finished job twice or losing one.
mod common;
use common::*;
use std::collections::HashMap;
use std::path::Path;
use std::process::Command;

fn results(path: &Path) -> Vec<serde_json::Value> {
    std::fs::read_to_string(path)
        .unwrap_or_default()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("{e}: {l}")))
        .collect()
}

fn batch(dir: &Path, args: &[&str]) -> std::process::Output {
    let mut a = vec!["batch"];
    a.extend_from_slice(args);
    kinegen_in(dir, &a)
}

/// Fits, compares and a job that fails, two at a time: one line each, the
/// command's own JSON document as `result`, the failure's located message as
/// `error`, exit 1 for the batch. Then a batch killed after its first results
/// is run again: every job appears exactly once.
#[test]
fn a_batch_writes_one_line_a_job_and_resumes_after_a_kill() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let log = simulate(
        dir,
        "r1.csv",
        &[
            "--spec",
            "spec/diff_drive.toml",
            "--set",
            "b=0.205",
            "--trajectory",
            "square",
        ],
    );
    let spec = root().join("spec/diff_drive.toml");
    let s = spec.to_str().unwrap();
    let mut jobs = String::new();
    for k in 0..8 {
        let cmd = if k % 2 == 0 { "fit" } else { "compare" };
        jobs += &serde_json::json!({"id": format!("job{k}"), "args": [cmd, "--spec", s, "--data", "r1.csv"]}).to_string();
        jobs.push('\n');
    }
    jobs +=
        &serde_json::json!({"id": "broken", "args": ["fit", "--spec", s, "--data", "missing.csv"]})
            .to_string();
    jobs.push('\n');
    std::fs::write(dir.join("jobs.jsonl"), &jobs).unwrap();
    let o = batch(dir, &["jobs.jsonl", "--out", "res.jsonl", "--jobs", "2"]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    let res = results(&dir.join("res.jsonl"));
    assert_eq!(res.len(), 9);
    let by_id: HashMap<&str, &serde_json::Value> =
        res.iter().map(|r| (r["id"].as_str().unwrap(), r)).collect();
    assert_eq!(by_id.len(), 9, "every job once");
    let fit = by_id["job0"];
    assert_eq!(fit["exit"], 0);
    assert!(
        fit["result"]["parameters"]["b"]["estimate"]
            .as_f64()
            .is_some(),
        "{fit}"
    );
    assert!(fit["seconds"].as_f64().unwrap() > 0.0);
    assert!(by_id["job1"]["result"]["rmse"].as_f64().is_some());
    let broken = by_id["broken"];
    assert_eq!(broken["exit"], 2);
    assert!(
        broken["error"].as_str().unwrap().contains("missing.csv"),
        "{broken}"
    );
    let _ = log;

    // killed after its first results, then resumed
    std::fs::remove_file(dir.join("res.jsonl")).unwrap();
    let mut child = Command::new(env!("CARGO_BIN_EXE_kinegen"))
        .args(["batch", "jobs.jsonl", "--out", "res.jsonl", "--jobs", "1"])
        .current_dir(dir)
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let t0 = std::time::Instant::now();
    while results(&dir.join("res.jsonl")).len() < 2 && t0.elapsed().as_secs() < 120 {
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    child.kill().unwrap();
    child.wait().unwrap();
    let before = results(&dir.join("res.jsonl"));
    assert!(
        before.len() >= 2 && before.len() < 9,
        "{} results before the kill",
        before.len()
    );
    // a line cut short by the kill is dropped and its job run again
    let mut text = std::fs::read_to_string(dir.join("res.jsonl")).unwrap();
    text += "{\"id\": \"job7\", \"exi";
    std::fs::write(dir.join("res.jsonl"), text).unwrap();
    let o = batch(dir, &["jobs.jsonl", "--out", "res.jsonl", "--jobs", "2"]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    let after = results(&dir.join("res.jsonl"));
    let mut ids: Vec<&str> = after.iter().map(|r| r["id"].as_str().unwrap()).collect();
    ids.sort();
    let mut want: Vec<String> = (0..8).map(|k| format!("job{k}")).collect();
    want.push("broken".into());
    want.sort();
    assert_eq!(ids, want, "each job exactly once after resuming");
    assert_eq!(
        &after[..before.len()],
        &before[..],
        "finished results are kept as they were"
    );
}

/// A jobs file that is not one JSON object a line is refused with its line.
#[test]
fn a_bad_jobs_file_is_refused_with_its_line() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    std::fs::write(
        dir.join("jobs.jsonl"),
        "{\"id\": \"a\", \"args\": [\"compare\"]}\nnot json\n",
    )
    .unwrap();
    let o = batch(dir, &["jobs.jsonl", "--out", "res.jsonl"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("jobs.jsonl:2"), "{}", stderr(&o));
    std::fs::write(
        dir.join("jobs.jsonl"),
        "{\"id\": \"a\", \"args\": [\"compare\"]}\n{\"id\": \"a\", \"args\": [\"fit\"]}\n",
    )
    .unwrap();
    let o = batch(dir, &["jobs.jsonl", "--out", "res.jsonl"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("used twice"), "{}", stderr(&o));
}

/// Issue #38.2: `bench-diagnose --shard K/N` runs a deterministic slice, and
/// `--merge` of the N shards' documents gives the unsharded table (the
/// counts of every model; timings differ run to run) and the same cases.
#[test]
fn bench_diagnose_shards_merge_into_the_whole_table() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let spec = root().join("spec/diff_drive.toml");
    let base = [
        "bench-diagnose",
        "--spec",
        spec.to_str().unwrap(),
        "--effect",
        "gyro_bias",
        "--seeds",
        "1",
    ];
    let run = |extra: &[&str], json: &str| {
        let mut a: Vec<&str> = base.to_vec();
        a.extend_from_slice(extra);
        a.extend(["--json", json]);
        let o = kinegen_in(dir, &a);
        assert!(o.status.success(), "{a:?}: {}", stderr(&o));
        serde_json::from_str::<serde_json::Value>(&std::fs::read_to_string(dir.join(json)).unwrap())
            .unwrap()
    };
    let whole = run(&[], "whole.json");
    let mut shard_files = Vec::new();
    let mut sizes = Vec::new();
    for k in 1..=3 {
        let name = format!("shard{k}.json");
        let d = run(&["--shard", &format!("{k}/3")], &name);
        sizes.push(d["cases"].as_array().unwrap().len());
        shard_files.push(dir.join(name).to_str().unwrap().to_string());
    }
    let n = whole["cases"].as_array().unwrap().len();
    assert_eq!(
        sizes.iter().sum::<usize>(),
        n,
        "the shards split the cases: {sizes:?} of {n}"
    );
    let mut a = vec!["bench-diagnose", "--merge"];
    a.extend(shard_files.iter().map(String::as_str));
    a.extend(["--json", "merged.json"]);
    let o = kinegen_in(dir, &a);
    assert!(o.status.success(), "{}", stderr(&o));
    let merged: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("merged.json")).unwrap()).unwrap();
    let counts = |d: &serde_json::Value| -> Vec<String> {
        d["models"]
            .as_array()
            .unwrap()
            .iter()
            .map(|m| {
                format!(
                    "{} {} {} {} {}",
                    m["model"], m["top1"], m["full_chain"], m["false_alarms"], m["redundant_cases"]
                )
            })
            .collect()
    };
    assert_eq!(counts(&merged), counts(&whole));
    let found = |d: &serde_json::Value| -> Vec<String> {
        d["cases"]
            .as_array()
            .unwrap()
            .iter()
            .map(|c| format!("{} {} {}", c["index"], c["hidden"], c["found"]))
            .collect()
    };
    assert_eq!(
        found(&merged),
        found(&whole),
        "the same cases with the same verdicts"
    );
    // an effect outside the catalogue is refused, not benchmarked as nothing
    let o = kinegen_in(dir, &["bench-diagnose", "--effect", "warp_drive"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("--effect warp_drive"), "{}", stderr(&o));
}
