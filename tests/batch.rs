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

/// How many child processes `pid` has now (Linux /proc; 0 elsewhere).
fn children(pid: u32) -> usize {
    let Ok(tasks) = std::fs::read_dir(format!("/proc/{pid}/task")) else {
        return 0;
    };
    tasks
        .filter_map(|t| t.ok())
        .filter_map(|t| std::fs::read_to_string(t.path().join("children")).ok())
        .map(|c| c.split_whitespace().count())
        .sum()
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
    let log = Sim::new("spec/diff_drive.toml")
        .sets(&["b=0.205"])
        .drive("square", 1, 1)
        .write(dir, "r1.csv");
    let spec = root().join("spec/diff_drive.toml");
    let s = spec.to_str().unwrap();
    // 200 jobs: fits, two diagnoses, a compare, and one that fails
    let mut jobs = String::new();
    for k in 0..199 {
        let cmd = match k {
            0 | 100 => "diagnose",
            1 => "compare",
            _ => "fit",
        };
        jobs += &serde_json::json!({"id": format!("job{k}"), "args": [cmd, "--spec", s, "--data", "r1.csv"]}).to_string();
        jobs.push('\n');
    }
    jobs +=
        &serde_json::json!({"id": "broken", "args": ["fit", "--spec", s, "--data", "missing.csv"]})
            .to_string();
    jobs.push('\n');
    std::fs::write(dir.join("jobs.jsonl"), &jobs).unwrap();
    // never more than --jobs children at once
    let mut child = Command::new(env!("CARGO_BIN_EXE_kinegen"))
        .args(["batch", "jobs.jsonl", "--out", "res.jsonl", "--jobs", "2"])
        .current_dir(dir)
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let mut most = 0;
    let status = loop {
        if let Some(st) = child.try_wait().unwrap() {
            break st;
        }
        most = most.max(children(child.id()));
        std::thread::sleep(std::time::Duration::from_millis(5));
    };
    assert_eq!(status.code(), Some(1));
    assert!(
        (1..=2).contains(&most),
        "{most} jobs ran at once with --jobs 2"
    );
    let res = results(&dir.join("res.jsonl"));
    assert_eq!(res.len(), 200);
    let by_id: HashMap<&str, &serde_json::Value> =
        res.iter().map(|r| (r["id"].as_str().unwrap(), r)).collect();
    assert_eq!(by_id.len(), 200, "every job once");
    assert!(
        by_id["job0"]["result"]["verdict"].is_object(),
        "{}",
        by_id["job0"]
    );
    let fit = by_id["job10"];
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
    let mut want: Vec<String> = (0..199).map(|k| format!("job{k}")).collect();
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
    for k in 1..=4 {
        let name = format!("shard{k}.json");
        let d = run(&["--shard", &format!("{k}/4")], &name);
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

/// Issue #38.3: the distributed driver (`scripts/dask_batch.py`, Dask) on a
/// local cluster of 2 workers gives the results `kinegen batch` gives: every
/// job once, the same exit codes, estimates and errors.
#[test]
fn the_dask_driver_gives_the_local_batch_results() {
    let has_dask = Command::new("python3")
        .args(["-c", "import dask.distributed"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !has_dask {
        assert!(
            std::env::var_os("CI").is_none(),
            "CI must have dask (scripts/test.sh installs verify/batch/requirements.txt)"
        );
        use std::io::Write;
        let _ = writeln!(
            std::io::stderr(),
            "SKIPPED the_dask_driver_gives_the_local_batch_results: no dask (pip install -r verify/batch/requirements.txt)"
        );
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    Sim::new("spec/diff_drive.toml")
        .sets(&["b=0.205"])
        .drive("square", 1, 1)
        .write(dir, "a.csv");
    Sim::new("spec/diff_drive.toml")
        .sets(&["r_l=0.0418"])
        .drive("figure8", 1, 1)
        .write(dir, "b.csv");
    let spec = root().join("spec/diff_drive.toml");
    let s = spec.to_str().unwrap();
    let mut jobs = String::new();
    for (id, cmd, data) in [
        ("a-fit", "fit", "a.csv"),
        ("b-fit", "fit", "b.csv"),
        ("a-compare", "compare", "a.csv"),
        ("broken", "fit", "nowhere.csv"),
    ] {
        jobs +=
            &serde_json::json!({"id": id, "args": [cmd, "--spec", s, "--data", data]}).to_string();
        jobs.push('\n');
    }
    std::fs::write(dir.join("jobs.jsonl"), jobs).unwrap();
    let o = batch(dir, &["jobs.jsonl", "--out", "local.jsonl", "--jobs", "2"]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    let o = Command::new("python3")
        .arg(root().join("scripts/dask_batch.py"))
        .args([
            "jobs.jsonl",
            "--out",
            "dask.jsonl",
            "--local",
            "2",
            "--kinegen",
            env!("CARGO_BIN_EXE_kinegen"),
        ])
        .current_dir(dir)
        .output()
        .unwrap();
    assert_eq!(
        o.status.code(),
        Some(1),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let by_id = |f: &str| -> HashMap<String, serde_json::Value> {
        results(&dir.join(f))
            .into_iter()
            .map(|r| (r["id"].as_str().unwrap().to_string(), r))
            .collect()
    };
    let (local, dask) = (by_id("local.jsonl"), by_id("dask.jsonl"));
    assert_eq!(local.len(), 4);
    assert_eq!(dask.len(), 4);
    let close = |a: &serde_json::Value, b: &serde_json::Value| {
        let (a, b) = (a.as_f64().unwrap(), b.as_f64().unwrap());
        (a - b).abs() <= 1e-9 * (1.0 + a.abs())
    };
    for (id, l) in &local {
        let d = &dask[id];
        assert_eq!(l["exit"], d["exit"], "{id}");
        assert_eq!(l["error"], d["error"], "{id}");
        if id.ends_with("fit") && l["exit"] == 0 {
            for p in ["r_r", "r_l", "b"] {
                let (x, y) = (
                    &l["result"]["parameters"][p]["estimate"],
                    &d["result"]["parameters"][p]["estimate"],
                );
                assert!(close(x, y), "{id} {p}: {x} vs {y}");
            }
        }
        if id.ends_with("compare") {
            assert!(close(&l["result"]["rmse"], &d["result"]["rmse"]), "{id}");
        }
    }
}

/// Issue #38.4: `batch --plan` writes a job for every log of a directory
/// (CSV files with the spec's input columns, to one level down; not a map or
/// an observations file), so a nightly run is two commands.
#[test]
fn a_plan_writes_a_job_for_every_log_of_a_directory() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let logs = dir.join("logs");
    std::fs::create_dir_all(logs.join("robot2")).unwrap();
    Sim::new("spec/diff_drive.toml")
        .drive("square", 1, 1)
        .write(&logs, "run-01.csv");
    Sim::new("spec/diff_drive.toml")
        .drive("figure8", 1, 1)
        .write(&logs.join("robot2"), "run-01.csv");
    std::fs::write(logs.join("map.csv"), "id,x,y\nA,1,2\n").unwrap();
    // a log with a comment line above its header is a log, as every command
    // reads it
    let square = std::fs::read_to_string(logs.join("run-01.csv")).unwrap();
    std::fs::write(
        logs.join("noted.csv"),
        format!("# robot 3, firmware 2.1\n{square}"),
    )
    .unwrap();
    let spec = root().join("spec/diff_drive.toml");
    let o = batch(
        dir,
        &[
            "logs",
            "--plan",
            "fit",
            "--spec",
            spec.to_str().unwrap(),
            "--out",
            "jobs.jsonl",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let jobs = results(&dir.join("jobs.jsonl"));
    let ids: Vec<&str> = jobs.iter().map(|j| j["id"].as_str().unwrap()).collect();
    assert_eq!(
        ids,
        ["noted-fit", "robot2-run-01-fit", "run-01-fit"],
        "{jobs:?}"
    );
    // a CSV file left out is said, with the columns it lacks
    assert!(
        stderr(&o).contains("1 CSV file(s) left out")
            && stderr(&o).contains("map.csv (no column enc_r, enc_l)"),
        "{}",
        stderr(&o)
    );
    let o = batch(dir, &["jobs.jsonl", "--out", "res.jsonl"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(results(&dir.join("res.jsonl")).len(), 3);
}
