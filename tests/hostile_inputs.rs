//! Issue #67's reproductions: each ends in a located exit 2 or a correct
//! result, never in data lost, a hang or a silent choice.
mod common;
use common::*;
use std::path::Path;

fn batch(dir: &Path, args: &[&str]) -> std::process::Output {
    let mut a = vec!["batch"];
    a.extend_from_slice(args);
    kinegen_in(dir, &a)
}

/// One quick job: compare on a simulated log.
fn one_job(dir: &Path) -> String {
    let log = dir.join("r.csv");
    let o = kinegen_in(
        dir,
        &[
            "simulate",
            "--spec",
            root().join("spec/diff_drive.toml").to_str().unwrap(),
            "--out",
            "r.csv",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let spec = root().join("spec/diff_drive.toml");
    let job = serde_json::json!({"id": "a", "args": ["compare", "--spec", spec, "--data", log]});
    let jobs = format!("{job}\n");
    std::fs::write(dir.join("jobs.jsonl"), &jobs).unwrap();
    jobs
}

#[test]
fn batch_refuses_its_jobs_file_as_results_and_keeps_it_whole() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let jobs = one_job(d);
    let e = stderr(&batch(d, &["jobs.jsonl", "--out", "jobs.jsonl"]));
    assert!(e.contains("that is the jobs file"), "{e}");
    std::fs::hard_link(d.join("jobs.jsonl"), d.join("linked.jsonl")).unwrap();
    let o = batch(d, &["jobs.jsonl", "--out", "linked.jsonl"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert_eq!(std::fs::read_to_string(d.join("jobs.jsonl")).unwrap(), jobs);
}

#[test]
fn batch_with_a_huge_jobs_count_ends() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    one_job(d);
    let t0 = std::time::Instant::now();
    let o = batch(
        d,
        &["jobs.jsonl", "--out", "out.jsonl", "--jobs", "100000000"],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(t0.elapsed().as_secs() < 60, "{:?}", t0.elapsed());
    assert!(stderr(&o).contains("1 at once"), "{}", stderr(&o));
}

#[test]
fn batch_refuses_a_read_only_or_foreign_results_file() {
    use std::os::unix::fs::PermissionsExt;
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    one_job(d);
    // read-only: refused, not appended to
    let ro = d.join("ro.jsonl");
    std::fs::write(&ro, "").unwrap();
    std::fs::set_permissions(&ro, std::fs::Permissions::from_mode(0o444)).unwrap();
    let o = batch(d, &["jobs.jsonl", "--out", "ro.jsonl"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert_eq!(std::fs::read_to_string(&ro).unwrap(), "");
    // a line that is no result line is named, and nothing is run
    for (text, says) in [
        ("{\"id\": \"a\"}\n", "has \"id\" and \"exit\""),
        ("not json\n", "not a result line"),
    ] {
        std::fs::write(d.join("x.jsonl"), text).unwrap();
        let e = stderr(&batch(d, &["jobs.jsonl", "--out", "x.jsonl"]));
        assert!(e.contains("x.jsonl:1: ") && e.contains(says), "{e}");
        assert_eq!(std::fs::read_to_string(d.join("x.jsonl")).unwrap(), text);
    }
}

#[test]
fn a_resumed_batch_owes_its_earlier_failures_in_its_exit_status() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    one_job(d);
    std::fs::write(
        d.join("out.jsonl"),
        "{\"id\": \"a\", \"exit\": 2, \"error\": \"bad\", \"seconds\": 0.1}\n",
    )
    .unwrap();
    let o = batch(d, &["jobs.jsonl", "--out", "out.jsonl"]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("1 failed in an earlier run"),
        "{}",
        stderr(&o)
    );
}

#[test]
fn an_option_given_twice_is_refused_naming_both() {
    let log = root().join("data/mystery_robot.csv");
    let l = log.to_str().unwrap();
    let e = refused(&[
        "compare",
        "--spec",
        "spec/diff_drive.toml",
        "--data",
        l,
        "--set",
        "b=0.3",
        "--set",
        "b=0.2",
    ]);
    assert!(
        e.contains("--set b=0.2") && e.contains("--set b=0.3"),
        "{e}"
    );
    let e = refused(&[
        "fit",
        "--spec",
        "spec/diff_drive.toml",
        "--data",
        l,
        "--holdout",
        l,
    ]);
    assert!(e.contains("already given as --data"), "{e}");
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("s.csv");
    let e = refused(&[
        "simulate",
        "--spec",
        "spec/diff_drive.toml",
        "--effect",
        "lateral_slip=0.1",
        "--effect",
        "lateral_slip=0.2",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(e.contains("already given"), "{e}");
    assert!(!out.exists());
    let e = refused(&[
        "add-effect",
        "--spec",
        "spec/diff_drive.toml",
        "--effect",
        "lateral_slip",
        "--value",
        "k_slip=0.1",
        "--value",
        "k_slip=0.2",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(e.contains("given twice"), "{e}");
}

/// A process noise too large for f64 ends in a located exit 2, not a panic
/// (1e100) nor a negative NEES (1e6).
#[test]
fn localize_with_an_absurd_process_noise_says_so() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let spec = root().join("spec/unicycle_ekf.toml");
    let s = spec.to_str().unwrap();
    let map = root().join("data/seed001_beacons.csv");
    let o = kinegen_in(
        d,
        &[
            "simulate",
            "--spec",
            s,
            "--trajectory",
            "random",
            "--landmarks",
            map.to_str().unwrap(),
            "--observations",
            "obs.csv",
            "--out",
            "lm.csv",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let noise = kinegen_model::spec::Model::load(&spec).unwrap();
    let name = noise.noise[0].name.clone();
    for sigma in ["1e100", "1e6"] {
        let set = format!("{name}={sigma}");
        let o = kinegen_in(
            d,
            &[
                "localize",
                "--spec",
                s,
                "--data",
                "lm.csv",
                "--observations",
                "obs.csv",
                "--landmarks",
                map.to_str().unwrap(),
                "--noise",
                &set,
                "--json",
                "out.json",
            ],
        );
        let e = stderr(&o);
        if o.status.code() == Some(0) {
            // a correct result: every NEES a NEES
            let doc: serde_json::Value =
                serde_json::from_str(&std::fs::read_to_string(d.join("out.json")).unwrap())
                    .unwrap();
            let nees = doc["runs"][0]["nees_mean"].as_f64().unwrap_or(0.0);
            assert!(nees >= 0.0, "--noise {set}: NEES {nees}");
        } else {
            assert_eq!(o.status.code(), Some(2), "--noise {set}: {e}");
            assert!(e.contains("lm.csv") && e.contains("--noise"), "{e}");
        }
    }
}

/// A held-out log without a ground truth is refused, not scored 0.
#[test]
fn a_held_out_log_without_ground_truth_is_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let log = root().join("data/mystery_robot.csv");
    let text = std::fs::read_to_string(&log).unwrap();
    // the log without its gt_ columns
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let keep: Vec<usize> = (0..header.len())
        .filter(|&i| !header[i].starts_with("gt_"))
        .collect();
    let pick = |l: &str| {
        let cells: Vec<&str> = l.split(',').collect();
        keep.iter().map(|&i| cells[i]).collect::<Vec<_>>().join(",")
    };
    let mut out = pick(&header.join(",")) + "\n";
    for l in lines {
        out += &(pick(l) + "\n");
    }
    let nogt = tmp.path().join("nogt.csv");
    std::fs::write(&nogt, out).unwrap();
    let e = refused(&[
        "fit",
        "--spec",
        "spec/diff_drive.toml",
        "--data",
        log.to_str().unwrap(),
        "--holdout",
        nogt.to_str().unwrap(),
    ]);
    assert!(
        e.contains("nogt.csv") && e.contains("no ground truth"),
        "{e}"
    );
}

/// A wheel counter that starts again from 0 mid-log (a reboot) is refused at
/// its line, not read as a huge step backwards; the log as logged is not.
#[test]
fn a_counter_reset_mid_log_is_refused_at_its_line() {
    let tmp = tempfile::tempdir().unwrap();
    let log = root().join("data/mystery_robot.csv");
    let text = std::fs::read_to_string(&log).unwrap();
    let mut lines: Vec<String> = text.lines().map(String::from).collect();
    let header: Vec<&str> = lines[0].split(',').collect();
    let col = header.iter().position(|h| *h == "enc_r").unwrap();
    let at = lines.len() / 2;
    let base: f64 = lines[at].split(',').nth(col).unwrap().parse().unwrap();
    for l in lines.iter_mut().skip(at) {
        let mut cells: Vec<String> = l.split(',').map(String::from).collect();
        let v: f64 = cells[col].parse().unwrap();
        cells[col] = format!("{}", v - base);
        *l = cells.join(",");
    }
    let reset = tmp.path().join("reset.csv");
    std::fs::write(&reset, lines.join("\n") + "\n").unwrap();
    let e = refused(&[
        "compare",
        "--spec",
        "spec/diff_drive.toml",
        "--data",
        reset.to_str().unwrap(),
    ]);
    assert!(
        e.contains("reset.csv") && e.contains("enc_r") && e.contains("starts again from 0"),
        "{e}"
    );
    let o = kinegen(&[
        "compare",
        "--spec",
        "spec/diff_drive.toml",
        "--data",
        log.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
}

/// bench-diagnose --merge joins only the whole of one benchmark: one shard
/// of two, or shards of another selection, are refused rather than shown as
/// the whole table.
#[test]
fn a_merge_of_part_of_a_benchmark_is_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let spec = root().join("spec/diff_drive.toml");
    let s = spec.to_str().unwrap();
    let shard = |effect: &str, k: &str, json: &str| {
        let o = kinegen_in(
            d,
            &[
                "bench-diagnose",
                "--spec",
                s,
                "--effect",
                effect,
                "--seeds",
                "1",
                "--shard",
                k,
                "--json",
                json,
            ],
        );
        assert!(o.status.success(), "{}", stderr(&o));
    };
    shard("gyro_bias", "1/2", "a1.json");
    shard("gyro_bias", "2/2", "a2.json");
    shard("gyro_scale", "2/2", "b2.json");
    let merge = |files: &[&str]| {
        let mut a = vec!["bench-diagnose", "--merge"];
        a.extend_from_slice(files);
        kinegen_in(d, &a)
    };
    let o = merge(&["a1.json"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("2/2 missing"), "{}", stderr(&o));
    let o = merge(&["a1.json", "b2.json"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("another benchmark"), "{}", stderr(&o));
    let o = merge(&["a1.json", "a2.json"]);
    assert!(o.status.success(), "{}", stderr(&o));
}

/// batch --plan writes ids batch accepts (no two alike), leaves out what it
/// cannot write or read (a named pipe), and refuses a --topics file that is
/// not there.
#[test]
fn a_plan_never_writes_two_jobs_under_one_id() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let logs = d.join("logs");
    std::fs::create_dir_all(logs.join("x")).unwrap();
    let log = root().join("data/mystery_robot.csv");
    std::fs::copy(&log, logs.join("x/run.csv")).unwrap();
    std::fs::copy(&log, logs.join("x-run.csv")).unwrap();
    // a named pipe that no one writes: reading it would never end
    let fifo = logs.join("pipe.csv");
    let made = std::process::Command::new("mkfifo").arg(&fifo).status();
    let spec = root().join("spec/diff_drive.toml");
    let s = spec.to_str().unwrap();
    let plan = |extra: &[&str]| {
        let mut a = vec![
            "batch",
            "--plan",
            "fit",
            "--spec",
            s,
            "logs",
            "--out",
            "jobs.jsonl",
        ];
        a.extend_from_slice(extra);
        kinegen_in(d, &a)
    };
    let o = plan(&[]);
    assert!(o.status.success(), "{}", stderr(&o));
    if made.is_ok_and(|s| s.success()) {
        assert!(
            stderr(&o).contains("pipe.csv (not a regular file)"),
            "{}",
            stderr(&o)
        );
    }
    let jobs = std::fs::read_to_string(d.join("jobs.jsonl")).unwrap();
    let ids: Vec<String> = jobs
        .lines()
        .map(|l| {
            serde_json::from_str::<serde_json::Value>(l).unwrap()["id"]
                .as_str()
                .unwrap()
                .to_string()
        })
        .collect();
    let unique: std::collections::HashSet<&String> = ids.iter().collect();
    assert_eq!(unique.len(), ids.len(), "{ids:?}");
    assert_eq!(ids.len(), 2, "{ids:?}");
    let e = stderr(&plan(&["--topics", "nowhere.toml"]));
    assert!(e.contains("--topics nowhere.toml: no such file"), "{e}");
}

/// A device that never ends, given as a log, a map or a batch's results,
/// ends in a located exit 2 at the input limit, not in exhausted memory.
#[test]
fn an_endless_device_as_input_stops_at_the_limit() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let run = |args: &[&str]| {
        std::process::Command::new(env!("CARGO_BIN_EXE_kinegen"))
            .args(args)
            .current_dir(root())
            .env("KINEGEN_INPUT_LIMIT_MB", "4")
            .output()
            .unwrap()
    };
    let o = run(&[
        "compare",
        "--spec",
        "spec/diff_drive.toml",
        "--data",
        "/dev/zero",
    ]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("/dev/zero") && stderr(&o).contains("more than 4 MiB"),
        "{}",
        stderr(&o)
    );
    one_job(d);
    let jobs = d.join("jobs.jsonl");
    let o = run(&["batch", jobs.to_str().unwrap(), "--out", "/dev/zero"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("not a regular file"), "{}", stderr(&o));
}

/// A batch killed while its jobs run takes them with it.
#[test]
fn a_killed_batch_leaves_no_job_running() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let spec = root().join("spec/diff_drive.toml");
    // two slow jobs (a recovery benchmark each)
    let mut jobs = String::new();
    for id in ["slow1", "slow2"] {
        let job = serde_json::json!({"id": id, "args": ["bench-diagnose", "--spec", spec, "--seeds", "3"]});
        jobs += &format!("{job}\n");
    }
    std::fs::write(d.join("jobs.jsonl"), jobs).unwrap();
    let mut batch = std::process::Command::new(env!("CARGO_BIN_EXE_kinegen"))
        .args(["batch", "jobs.jsonl", "--out", "out.jsonl", "--jobs", "2"])
        .current_dir(d)
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let children = |pid: u32| -> Vec<u32> {
        std::fs::read_dir(format!("/proc/{pid}/task"))
            .into_iter()
            .flatten()
            .flatten()
            .filter_map(|t| std::fs::read_to_string(t.path().join("children")).ok())
            .flat_map(|c| {
                c.split_whitespace()
                    .filter_map(|p| p.parse().ok())
                    .collect::<Vec<u32>>()
            })
            .collect()
    };
    let mut jobs_seen = Vec::new();
    for _ in 0..100 {
        jobs_seen = children(batch.id());
        if jobs_seen.len() == 2 {
            break;
        }
        std::thread::sleep(std::time::Duration::from_millis(100));
    }
    assert_eq!(jobs_seen.len(), 2, "the jobs did not start");
    batch.kill().unwrap();
    batch.wait().unwrap();
    // each job's process is gone (or a zombie about to be reaped), soon
    let alive = |pid: u32| {
        std::fs::read_to_string(format!("/proc/{pid}/stat"))
            .is_ok_and(|s| s.split_whitespace().nth(2).is_none_or(|st| st != "Z"))
    };
    for _ in 0..50 {
        if !jobs_seen.iter().any(|p| alive(*p)) {
            return;
        }
        std::thread::sleep(std::time::Duration::from_millis(100));
    }
    panic!("jobs still running after the batch was killed: {jobs_seen:?}");
}

/// An output through a link that points nowhere is refused (it created the
/// link target's folders), and so is a navigation cell shorter than one
/// integration step (1e-300 m was accepted).
#[test]
fn a_dangling_link_output_and_a_vanishing_cell_are_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let target = d.join("nowhere/deep");
    std::os::unix::fs::symlink(&target, d.join("rep")).unwrap();
    let log = root().join("data/mystery_robot.csv");
    let rep = d.join("rep");
    let e = refused(&[
        "compare",
        "--spec",
        "spec/diff_drive.toml",
        "--data",
        log.to_str().unwrap(),
        "--report",
        rep.to_str().unwrap(),
    ]);
    assert!(e.contains("which does not exist"), "{e}");
    assert!(!d.join("nowhere").exists());
    let e = refused(&[
        "navigate",
        "--spec",
        "data/seed004/epuck.toml",
        "--grid",
        "data/seed004/arena.txt",
        "--cell",
        "1e-300",
    ]);
    assert!(
        e.contains("--cell 1e-300") && e.contains("one integration step"),
        "{e}"
    );
}

/// Found by scripts/hostile_campaign.py: `simulate --laps 99999999999` asked
/// for 1e15 bytes and aborted (exit 134). It is refused before any memory is
/// taken, naming the option, the rows it would make and the bound, and
/// writes nothing; so are 20,000 laps of the square (36 million rows), just
/// over the bound (the suite simulates up to 550 laps elsewhere).
#[test]
fn a_simulation_too_long_for_memory_is_refused_up_front() {
    let tmp = tempfile::tempdir().unwrap();
    let spec = root().join("spec/diff_drive.toml");
    let spec = spec.to_str().unwrap();
    let o = kinegen_in(
        tmp.path(),
        &[
            "simulate",
            "--spec",
            spec,
            "--out",
            "s.csv",
            "--laps",
            "99999999999",
        ],
    );
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    let said = stderr(&o);
    assert!(
        said.contains("--laps 99999999999:") && said.contains("rows, more than the 2e7"),
        "{said}"
    );
    assert!(!tmp.path().join("s.csv").exists());
    let o = kinegen_in(
        tmp.path(),
        &[
            "simulate", "--spec", spec, "--out", "s.csv", "--laps", "20000",
        ],
    );
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("e7 rows"), "{}", stderr(&o));
}

/// Found by scripts/hostile_campaign.py: `fit --set b=1e308` spun for hours
/// in nalgebra's SVD of a normal matrix that had overflowed (its iteration
/// never converges on an infinity). The decompositions are bounded now
/// (model_on_log/linalg.rs): the fit ends and says the wheelbase is not
/// identifiable, printed in scientific notation, not as 309 digits.
#[test]
fn a_fit_from_an_overflowing_nominal_ends_and_says_so() {
    let tmp = tempfile::tempdir().unwrap();
    let log = std::fs::read_to_string(root().join("data/mystery_robot.csv")).unwrap();
    let short: String = log.lines().take(301).map(|l| format!("{l}\n")).collect();
    std::fs::write(tmp.path().join("short.csv"), short).unwrap();
    let spec = root().join("spec/diff_drive.toml");
    let t0 = std::time::Instant::now();
    let o = kinegen_in(
        tmp.path(),
        &[
            "fit",
            "--spec",
            spec.to_str().unwrap(),
            "--data",
            "short.csv",
            "--set",
            "b=1e308",
        ],
    );
    assert!(t0.elapsed().as_secs() < 60, "{:?}", t0.elapsed());
    let said = stdout(&o) + &stderr(&o);
    assert!(o.status.code() == Some(0), "{said}");
    assert!(
        said.contains("1.0000e308") && said.contains("not identifiable from these logs: b"),
        "{said}"
    );
}
