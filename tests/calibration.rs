//! simulate, compare and fit: recovery of parameters, every bundled model, real
//! data, and bad input.
mod common;
use common::*;
// the library's scenarios, in-process (only this test binary links them);
// its `Sim` is the library's writer beside `common`'s, which runs the binary
#[path = "../analysis/tests/scenarios/mod.rs"]
#[allow(clippy::duplicate_mod)]
mod library_scenarios;

/// Run `kinegen ARGS --json DIR/NAME.json` where the command may exit 1 (a fit
/// named unusable): returns the output and the JSON it wrote.
fn run_to_json(
    dir: &std::path::Path,
    name: &str,
    args: &[&str],
) -> (std::process::Output, serde_json::Value) {
    let out = dir.join(format!("{name}.json"));
    let mut a = args.to_vec();
    a.extend(["--json", out.to_str().unwrap()]);
    let o = kinegen(&a);
    assert!(
        matches!(o.status.code(), Some(0 | 1)),
        "{args:?}: {}",
        stderr(&o)
    );
    let doc = serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    (o, doc)
}

/// `kinegen simulate` writes, byte for byte, the log and sightings the
/// library's tests make in-process (`analysis/tests/scenarios`' `Sim`):
/// the same description of a log, written by either side.
#[test]
fn simulate_writes_the_scenarios_logs() {
    let tmp = tempfile::tempdir().unwrap();
    let map = root().join("data/beacons.csv");
    let (sets, effects) = (["b=0.21"], ["lateral_slip=0.1"]);
    let cli = Sim::new("spec/diff_drive.toml")
        .sets(&sets)
        .effects(&effects)
        .drive("figure8", 5, 2)
        .sighting(&map)
        .camera(2.0, 8.0);
    let (cli_log, cli_obs) = cli.write_sighted(tmp.path(), "cli.csv");
    let library = library_scenarios::Sim::new("spec/diff_drive.toml")
        .sets(&sets)
        .effects(&effects)
        .drive("figure8", 5, 2)
        .sighting(&map)
        .camera(2.0, 8.0);
    let (log, obs) = library.write_sighted(tmp.path(), "library.csv");
    let read = |p: &std::path::Path| std::fs::read_to_string(p).unwrap();
    assert!(read(&log) == read(&cli_log), "the logs differ");
    assert!(read(&obs) == read(&cli_obs) && read(&obs).lines().count() > 100);
}

/// `fit --json` as CONTRACT section 4 gives it (the values themselves are
/// analysis/tests/results/calibration.rs's): the model, the metric, before and after,
/// each free parameter's nominal value, estimate and standard deviation
/// (null where the logs do not determine it, never a small number), each
/// run by the path given, fitted and held out, with its start pose, and
/// `--loss` said back.
#[test]
fn fit_json_has_the_contract_shape() {
    let tmp = tempfile::tempdir().unwrap();
    let spec = "spec/diff_drive.toml";
    let sim = |name: &str, traj: &str| {
        Sim::new(spec)
            .sets(&["b=0.21"])
            .drive(traj, 1, 1)
            .write(tmp.path(), name)
    };
    let (square, spin) = (sim("square.csv", "square"), sim("spin.csv", "spin"));
    let (square, spin) = (square.to_str().unwrap(), spin.to_str().unwrap());
    let doc = kinegen_json(&[
        "fit",
        "--spec",
        spec,
        "--data",
        square,
        "--holdout",
        spin,
        "--loss",
        "huber",
    ]);
    assert_eq!(doc["model"], "diff_drive");
    assert!(doc["metric"].is_string());
    assert_eq!(doc["loss"], "huber");
    for k in ["before", "after"] {
        assert!(doc[k]["rmse"].as_f64().unwrap() > 0.0, "{k}: {}", doc[k]);
    }
    for n in ["r_r", "r_l", "b"] {
        let p = &doc["parameters"][n];
        for k in ["nominal", "estimate", "std"] {
            assert!(p[k].as_f64().is_some(), "{n}.{k}: {p}");
        }
    }
    assert_eq!(doc["unusable"], serde_json::json!([]));
    let runs = doc["runs"].as_array().unwrap();
    assert_eq!(runs.len(), 2);
    for (run, (path, held)) in runs.iter().zip([(square, false), (spin, true)]) {
        assert_eq!(run["path"], path);
        assert_eq!(run["holdout"], held);
        assert!(run["rmse"].as_f64().is_some() && run["final_error"].as_f64().is_some());
        assert!(run["before"]["rmse"].as_f64().is_some());
    }
    assert_eq!(runs[0]["start_pose"].as_array().unwrap().len(), 3);
    // turning in place alone: the common scale is undetermined, its std null
    let doc = kinegen_json(&["fit", "--spec", spec, "--data", spin]);
    for n in ["r_r", "r_l", "b"] {
        let p = &doc["parameters"][n];
        assert!(
            p["std"].is_null() && p["estimate"].as_f64().is_some(),
            "{n}: {p}"
        );
    }
}

/// `compare --json` gives the position RMSE and where it fails (the
/// regimes), for every bundled model.
#[test]
fn every_bundled_model_can_be_simulated_and_compared() {
    let tmp = tempfile::tempdir().unwrap();
    for spec in [
        "diff_drive",
        "tricycle",
        "tricycle_fwd",
        "omni3",
        "omni_caster",
        "unicycle_ekf",
    ] {
        let path = format!("spec/{spec}.toml");
        let log = Sim::new(&path)
            .drive("square", 1, 1)
            .write(tmp.path(), &format!("{spec}.csv"));
        let cmp = kinegen_json(&["compare", "--spec", &path, "--data", log.to_str().unwrap()]);
        assert!(
            cmp["rmse"].as_f64().unwrap() >= 0.0,
            "{spec}: {}",
            cmp["rmse"]
        );
        assert!(
            !cmp["regimes"].as_array().unwrap().is_empty(),
            "{spec}: no regime breakdown"
        );
    }
}

/// `fit --method all --truth ... --hidden N --report DIR`: every method in
/// the JSON with its note, parameters and distance to the truth, the one
/// closest named, the network named by its size, and the report saying
/// which method came closest (the comparison's values are
/// analysis/tests/results/calibration.rs's).
#[test]
fn methods_are_compared_in_the_json_and_the_report() {
    let tmp = tempfile::tempdir().unwrap();
    let log = seed_000_log(tmp.path(), "omni.csv", 3);
    let report = tmp.path().join("report");
    let mut args = vec![
        "fit",
        "--spec",
        "spec/omni_caster.toml",
        "--method",
        "all",
        "--hidden",
        "9",
        "--data",
        log.to_str().unwrap(),
        "--report",
        report.to_str().unwrap(),
    ];
    for t in &SEED_000_TRUTH {
        args.extend(["--truth", t]);
    }
    let doc = kinegen_json(&args);
    let methods = doc["methods"].as_object().unwrap();
    for m in ["lm", "gd", "ekf", "neural-9"] {
        let row = &methods[m];
        assert!(
            row["note"].is_string() && row["after"]["rmse"].is_number(),
            "{m}: {row}"
        );
        assert!(
            row["distance_to_truth"].is_number() || m == "neural-9",
            "{m}: {row}"
        );
    }
    assert!(methods["lm"]["parameters"]["r1"]["estimate"].is_number());
    let closest = doc["closest_to_truth"].as_str().unwrap();
    assert_eq!(doc["truth"]["r1"], 0.101);
    let html = std::fs::read_to_string(report.join("index.html")).unwrap();
    assert!(html.contains(&format!("Closest to the true parameters: <b>{closest}</b>")));
    assert!(html.contains("neural-9"));
}

/// A steering log that leaves the spec's declared range (seed 001's tricycle,
/// `range = [-1.2, 1.2]`) is flagged by compare and fit with the lines, so a poor
/// fit there is not blamed on identifiability; the same log inside it is not.
#[test]
fn inputs_outside_their_declared_range_are_reported_with_their_lines() {
    let tmp = tempfile::tempdir().unwrap();
    let spec = "spec/tricycle.toml";
    let log = Sim::new(spec)
        .drive("random", 2, 1)
        .write(tmp.path(), "inside.csv");
    let inside = kinegen_json(&["compare", "--spec", spec, "--data", log.to_str().unwrap()]);
    assert_eq!(inside["warnings"], serde_json::json!([]));
    // data rows 99..=119 (CSV lines 101-121) steer to 1.5 rad
    let text = std::fs::read_to_string(&log).unwrap();
    let mut lines: Vec<String> = text.lines().map(String::from).collect();
    let col = lines[0].split(',').position(|c| c == "alpha").unwrap();
    for line in &mut lines[100..=120] {
        let mut cells: Vec<&str> = line.split(',').collect();
        cells[col] = "1.5";
        *line = cells.join(",");
    }
    let wide = tmp.path().join("wide.csv");
    std::fs::write(&wide, lines.join("\n") + "\n").unwrap();
    for cmd in ["compare", "fit"] {
        // the fit exits 1: one second of 1.5 rad steering drags the wheel
        // radius 32% short and the drift over 5 s windows grows 5x (unusable)
        let (_, doc) = run_to_json(
            tmp.path(),
            cmd,
            &[cmd, "--spec", spec, "--data", wide.to_str().unwrap()],
        );
        let w = doc["warnings"].as_array().unwrap();
        let hit: Vec<&str> = w
            .iter()
            .filter_map(|x| x.as_str())
            .filter(|x| x.contains("declared range"))
            .collect();
        assert_eq!(hit.len(), 1, "{cmd}: {w:?}");
        assert!(
            hit[0].contains("input `alpha` (column `alpha`)")
                && hit[0].contains("[-1.2, 1.2] rad")
                && hit[0].contains("lines 101-121")
                && hit[0].contains("up to 1.5000 rad"),
            "{cmd}: {}",
            hit[0]
        );
    }
}

#[test]
fn real_optiodom_runs_compare_and_fit_with_holdout() {
    let Some(runs) = real_runs() else { return };
    let p = |i: usize| runs[i].to_str().unwrap().to_string();
    let cmp = kinegen_json(&["compare", "--spec", "spec/diff_drive.toml", "--data", &p(0)]);
    assert!(cmp["rmse"].as_f64().unwrap() > 0.0);
    // fit on runs 1, 2 (one direction) and 4, 5 (the other); score on 3 and 6
    let fit = kinegen_json(&[
        "fit",
        "--spec",
        "spec/diff_drive.toml",
        "--data",
        &p(0),
        "--data",
        &p(1),
        "--data",
        &p(3),
        "--data",
        &p(4),
        "--holdout",
        &p(2),
        "--holdout",
        &p(5),
    ]);
    let hb = fit["holdout"]["before"]["rmse"].as_f64().unwrap();
    let ha = fit["holdout"]["after"]["rmse"].as_f64().unwrap();
    assert!(
        ha < hb,
        "calibration did not help on held-out runs: {hb} -> {ha}"
    );
    let b = fit["parameters"]["b"]["estimate"].as_f64().unwrap();
    assert!(
        (b - 0.2).abs() < 0.01,
        "wheelbase estimate {b} is not physically plausible"
    );
}

/// (file content, expected "file:row: column `c`" fragment, expected message)
fn bad_logs() -> Vec<(&'static str, String, &'static str)> {
    [bad_cells_and_times(), bad_headers_and_comments()].concat()
}

/// Bad cells, times, lengths and column names.
fn bad_cells_and_times() -> Vec<(&'static str, String, &'static str)> {
    let ok_header = "t,enc_r,enc_l,gt_x,gt_y,gt_theta";
    vec![
        ("", ":1".into(), "the file is empty"),
        (
            Box::leak(
                format!("{ok_header}\n0,0,0,0,0,0\n0.05,1,1,,,\n0.05,,,0.1,0,0\n0.1,2,2,0.2,0,0\n")
                    .into_boxed_str(),
            ),
            ":4: column `t`".into(),
            "each with cells the other leaves empty (two sources logged at the same time): merge them into one row",
        ),
        (
            Box::leak(
                format!("{ok_header}\n0,0,0,0,0,0\n10,1,1,0,0,0\n20,2,2,0,0,0\n30,3,3,0,0,0\n")
                    .into_boxed_str(),
            ),
            ": column `t`".into(),
            "as milliseconds, the rows would be 0.010 s apart: divide `t` by 1000",
        ),
        (
            Box::leak(
                format!("{ok_header}\n0,0,0,0,0,178\n0.05,1,1,0,0,179.5\n0.1,2,2,0,0,-179\n0.15,3,3,0,0,-178\n")
                    .into_boxed_str(),
            ),
            ":4: column `gt_theta`".into(),
            "as an angle in degrees does where it wraps",
        ),
        (
            "t,enc_r,gt_x,gt_y,gt_theta\n0,0,0,0,0\n0.05,1,0,0,0\n0.1,2,0,0,0\n",
            ":1: column `enc_l`".into(),
            "missing column",
        ),
        // a column named in another case: the header listed as it is, and the name to use
        (
            "T,enc_l,enc_r,gt_x,gt_y,gt_theta\n0,0,0,0,0,0\n0.05,1,1,0,0,0\n0.1,2,2,0,0,0\n",
            ":1: column `t`".into(),
            "(the header has: T, enc_l, enc_r, gt_x, gt_y, gt_theta); `T` differs only in case: rename it `t`",
        ),
        (
            Box::leak(
                format!("{ok_header}\n0,0,0,0,0,0\n0.05,1,x1,0,0,0\n0.1,2,2,0,0,0\n")
                    .into_boxed_str(),
            ),
            ":3: column `enc_l`".into(),
            "not a number",
        ),
        (
            Box::leak(
                format!("{ok_header}\n0,0,0,0,0,0\n0.05,1,inf,0,0,0\n0.1,2,2,0,0,0\n")
                    .into_boxed_str(),
            ),
            ":3: column `enc_l`".into(),
            "not finite",
        ),
        (
            Box::leak(
                format!("{ok_header}\n0,0,0,0,0,0\n0.05,1,1,inf,0,0\n0.1,2,2,0,0,0\n")
                    .into_boxed_str(),
            ),
            ":3: column `gt_x`".into(),
            "not finite",
        ),
        (
            Box::leak(
                format!("{ok_header}\n0,0,0,0,0,0\n0.05,1,1,0,0,0\n0.05,2,2,0,0,0\n")
                    .into_boxed_str(),
            ),
            ":4: column `t`".into(),
            "increase strictly",
        ),
        (
            Box::leak(
                format!("{ok_header}\n0,0,0,0,0,0\n1e-300,1,1,0,0,0\n2e-300,2,2,0,0,0\n3e-300,3,3,0,0,0\n")
                    .into_boxed_str(),
            ),
            ":3: column `t`".into(),
            "t must be in seconds",
        ),
        (
            Box::leak(
                format!("{ok_header}\n0,0,0,0,0,0\n0.05,1,1,0,0,0\n0.1,2,2,1e308,0,0\n0.15,3,3,0,0,0\n")
                    .into_boxed_str(),
            ),
            ":4".into(),
            "out of any physical range",
        ),
        (
            Box::leak(format!("{ok_header}\n0,0,0,0,0,0\n0.05,1,1,0,0,0\n").into_boxed_str()),
            "short.csv".into(),
            "at least 3",
        ),
    ]
}

/// A missing, numeric or mis-separated header; comment lines before it and
/// among the rows.
fn bad_headers_and_comments() -> Vec<(&'static str, String, &'static str)> {
    let ok_header = "t,enc_r,enc_l,gt_x,gt_y,gt_theta";
    vec![
        // a log without its header
        (
            "0,0,0,0,0,0\n0.05,1,1,0,0,0\n0.1,2,2,0,0,0\n",
            ":1".into(),
            "the first line is numbers (0,0,0,0,0,0), not a header",
        ),
        // comment lines before the header count in the lines errors name
        (
            Box::leak(
                format!("# robot 3\n# firmware 2.1\n{ok_header}\n0,0,0,0,0,0\n0.05,1,x1,0,0,0\n0.1,2,2,0,0,0\n")
                    .into_boxed_str(),
            ),
            ":5: column `enc_l`".into(),
            "not a number",
        ),
        (
            Box::leak(
                format!("# robot 3\n{ok_header}\n0,0,0,0,0,0\n0.05,1,1,0,0,0\n0.05,2,2,0,0,0\n")
                    .into_boxed_str(),
            ),
            ":5: column `t`".into(),
            "increase strictly",
        ),
        // a comment among the data rows is no row
        (
            Box::leak(
                format!("{ok_header}\n0,0,0,0,0,0\n# paused\n0.05,1,1,0,0,0\n0.1,2,2,0,0,0\n")
                    .into_boxed_str(),
            ),
            ":3".into(),
            "1 cell(s) where the header has 6 (a `#` comment",
        ),
        ("# robot 3\n", ":2".into(), "the file ends after 1 comment line(s)"),
        (
            "t enc_r enc_l gt_x gt_y gt_theta\n0 0 0 0 0 0\n0.05 1 1 0 0 0\n0.1 2 2 0 0 0\n",
            ":1".into(),
            "this one looks space-separated",
        ),
    ]
}

/// Loggers describe a file in `#` lines before its header, and numpy's
/// `savetxt` writes the header itself as one (`# t,enc_r,...`): both read as
/// the plain log does.
#[test]
fn comment_lines_before_the_header_are_read_past() {
    let tmp = tempfile::tempdir().unwrap();
    let log = Sim::new("spec/diff_drive.toml")
        .drive("square", 4, 1)
        .write(tmp.path(), "log.csv");
    let text = std::fs::read_to_string(&log).unwrap();
    let (header, rows) = text.split_once('\n').unwrap();
    let variants = [
        (
            "described.csv",
            format!("# robot 3, firmware 2.1\n#\n{text}"),
        ),
        ("savetxt.csv", format!("# {header}\n{rows}")),
        ("bom.csv", format!("\u{feff}# robot 3\n{text}")),
    ];
    let rmse = |path: &std::path::Path| {
        kinegen_json(&[
            "compare",
            "--spec",
            "spec/diff_drive.toml",
            "--data",
            path.to_str().unwrap(),
        ])["errors"]["rmse"]
            .as_f64()
            .unwrap()
    };
    let plain = rmse(&log);
    for (name, content) in variants {
        let path = tmp.path().join(name);
        std::fs::write(&path, content).unwrap();
        assert_eq!(rmse(&path), plain, "{name}");
    }
}

/// Real logs have holes: a connection that dropped for seconds. A gap cuts
/// the log into runs, each started from its own measured pose (dead reckoning
/// cannot bridge it), and says so in the text and the JSON warnings. A row
/// logged twice breaks the contract's strictly increasing time: an error that
/// names both lines and says whether they are the same row.
#[test]
fn gaps_split_a_log_and_repeated_rows_are_named() {
    let tmp = tempfile::tempdir().unwrap();
    let log = Sim::new("spec/diff_drive.toml")
        .drive("random", 2, 1)
        .write(tmp.path(), "log.csv");
    let text = std::fs::read_to_string(&log).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    // lines 501-600 lost: a 5 s gap at 20 Hz
    let mut holed: Vec<&str> = lines[..500].to_vec();
    holed.extend(&lines[600..]);
    let holed_path = tmp.path().join("holed.csv");
    std::fs::write(&holed_path, holed.join("\n") + "\n").unwrap();
    let doc = kinegen_json(&[
        "fit",
        "--spec",
        "spec/diff_drive.toml",
        "--data",
        holed_path.to_str().unwrap(),
    ]);
    let warnings = doc["warnings"].to_string();
    assert!(
        warnings.contains("1 gap(s)") && warnings.contains("used as 2 run(s)"),
        "{warnings}"
    );
    assert_eq!(doc["runs"].as_array().unwrap().len(), 2, "{}", doc["runs"]);
    assert!(doc["after"]["rmse"].as_f64().unwrap() < doc["before"]["rmse"].as_f64().unwrap());
    let fit = |name: &str, rows: Vec<String>| {
        let p = tmp.path().join(name);
        std::fs::write(&p, rows.join("\n") + "\n").unwrap();
        let o = kinegen(&[
            "fit",
            "--spec",
            "spec/diff_drive.toml",
            "--data",
            p.to_str().unwrap(),
        ]);
        assert_eq!(o.status.code(), Some(2), "{name}");
        stderr(&o)
    };
    // line 51 written twice
    let mut twice: Vec<String> = lines[..51].iter().map(|s| s.to_string()).collect();
    twice.extend(lines[50..].iter().map(|s| s.to_string()));
    let err = fit("twice.csv", twice);
    assert!(
        err.contains("twice.csv:52: column `t`") && err.contains("line 52 repeats line 51 exactly"),
        "{err}"
    );
    // the same time with other values
    let mut clash: Vec<String> = lines[..51].iter().map(|s| s.to_string()).collect();
    let mut other: Vec<String> = lines[50].split(',').map(str::to_string).collect();
    other[1] = format!("{}1", other[1]);
    clash.push(other.join(","));
    clash.extend(lines[51..].iter().map(|s| s.to_string()));
    let err = fit("clash.csv", clash);
    assert!(
        err.contains("clash.csv:52: column `t`") && err.contains("lines 51 and 52 are both at t ="),
        "{err}"
    );
}

/// Issue 16: parameter values inside their declared bounds that make the model
/// divide by almost zero, or overflow, give no NaN or infinite result: the
/// first row where the prediction stops being a number is named, with the
/// --set values as suspects. A log whose inputs never change is refused by
/// diagnose (every ratio would be 0/0).
#[test]
fn results_that_would_not_be_finite_are_refused_with_the_row() {
    let tmp = tempfile::tempdir().unwrap();
    let log = Sim::new("spec/diff_drive.toml")
        .drive("random", 1, 1)
        .write(tmp.path(), "log.csv");
    for set in ["b=1e-300", "r_r=1e300"] {
        for cmd in ["compare", "fit", "diagnose"] {
            let o = kinegen(&[
                cmd,
                "--spec",
                "spec/diff_drive.toml",
                "--data",
                log.to_str().unwrap(),
                "--set",
                set,
                "--json",
                "-",
            ]);
            let err = stderr(&o);
            assert_eq!(o.status.code(), Some(2), "{cmd} --set {set}: {err}");
            assert!(
                err.contains("log.csv:") && err.contains("not finite")
                    || err.contains("gyro reading is"),
                "{cmd} {set}: {err}"
            );
            assert!(
                err.contains(set) && o.stdout.is_empty(),
                "{cmd} {set}: {err}"
            );
        }
    }
    let text = std::fs::read_to_string(&log).unwrap();
    let still: Vec<String> = text
        .lines()
        .enumerate()
        .map(|(i, l)| {
            if i == 0 {
                return l.to_string();
            }
            let mut c: Vec<&str> = l.split(',').collect();
            c[1] = "5";
            c[2] = "7";
            c.join(",")
        })
        .collect();
    std::fs::write(&log, still.join("\n")).unwrap();
    let o = kinegen(&[
        "diagnose",
        "--spec",
        "spec/diff_drive.toml",
        "--data",
        log.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("never change"), "{}", stderr(&o));
}

#[test]
fn bad_logs_are_rejected_with_file_row_and_column() {
    let tmp = tempfile::tempdir().unwrap();
    for (i, (content, place, message)) in bad_logs().into_iter().enumerate() {
        let name = if message == "at least 3" {
            "short.csv".to_string()
        } else {
            format!("bad{i}.csv")
        };
        let path = tmp.path().join(&name);
        std::fs::write(&path, content).unwrap();
        for cmd in ["compare", "fit", "diagnose"] {
            let o = kinegen(&[
                cmd,
                "--spec",
                "spec/diff_drive.toml",
                "--data",
                path.to_str().unwrap(),
            ]);
            let err = stderr(&o);
            assert_eq!(o.status.code(), Some(2), "{cmd} {name}: {err}");
            assert!(
                err.contains(&name) && err.contains(&place) && err.contains(message),
                "{cmd} {name}: expected `{place}` and `{message}` in: {err}"
            );
            assert!(!err.contains("panicked"), "{err}");
        }
    }
}

#[test]
fn unknown_set_name_and_bad_value_are_usage_errors() {
    let o = kinegen(&[
        "fit",
        "--spec",
        "spec/diff_drive.toml",
        "--data",
        "data/mystery_robot.csv",
        "--set",
        "wheel=0.1",
    ]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("unknown parameter `wheel`") && stderr(&o).contains("r_r"),
        "{}",
        stderr(&o)
    );
    let o = kinegen(&[
        "fit",
        "--spec",
        "spec/diff_drive.toml",
        "--data",
        "data/mystery_robot.csv",
        "--set",
        "b=abc",
    ]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("--set b=abc"), "{}", stderr(&o));
}

#[test]
fn json_to_a_file_and_a_report_are_written_and_stdout_stays_human() {
    let tmp = tempfile::tempdir().unwrap();
    let json = tmp.path().join("fit.json");
    let report = tmp.path().join("report");
    let o = kinegen(&[
        "fit",
        "--spec",
        "spec/diff_drive.toml",
        "--data",
        "data/mystery_robot.csv",
        "--json",
        json.to_str().unwrap(),
        "--report",
        report.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let doc: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    for k in ["model", "metric", "before", "after", "parameters"] {
        assert!(doc.get(k).is_some(), "fit JSON lacks `{k}`");
    }
    let html = std::fs::read_to_string(report.join("index.html")).unwrap();
    assert!(
        html.contains("<svg")
            && html.contains("after calibration")
            && !html.contains("<script src"),
        "report is not self-contained"
    );
    assert!(stdout(&o).contains("calibrated"));
}

#[test]
fn a_measurement_delay_is_calibrated_once_the_time_offset_effect_is_added() {
    let tmp = tempfile::tempdir().unwrap();
    let log = Sim::new("spec/diff_drive.toml")
        .effects(&["time_offset=0.08"])
        .drive("random", 7, 1)
        .write(tmp.path(), "delay.csv");
    let spec = tmp.path().join("dd_delay.toml");
    let o = kinegen(&[
        "add-effect",
        "--spec",
        "spec/diff_drive.toml",
        "--effect",
        "time_offset",
        "--out",
        spec.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let base = kinegen_json(&[
        "fit",
        "--spec",
        "spec/diff_drive.toml",
        "--data",
        log.to_str().unwrap(),
    ]);
    let with = kinegen_json(&[
        "fit",
        "--spec",
        spec.to_str().unwrap(),
        "--data",
        log.to_str().unwrap(),
    ]);
    let tau = with["parameters"]["time_offset"]["estimate"]
        .as_f64()
        .unwrap();
    assert!((tau - 0.08).abs() < 0.004, "time_offset {tau}");
    assert!(
        with["after"]["rmse"].as_f64().unwrap() * 3.0 < base["after"]["rmse"].as_f64().unwrap()
    );
}

/// A delay the user declares under a name of their own (`measurement_delay =
/// true`): simulated with it, then calibrated by it. Nothing looks for the name
/// `time_offset`.
#[test]
fn a_delay_declared_under_any_name_is_simulated_and_calibrated() {
    let tmp = tempfile::tempdir().unwrap();
    let spec = tmp.path().join("lagged.toml");
    let text = std::fs::read_to_string(root().join("spec/diff_drive.toml")).unwrap();
    let lag = "\n[[parameter]]\nname = \"mocap_lag\"\nnominal = 0.0\nunit = \"s\"\nmin = -0.3\nmax = 0.3\nmeasurement_delay = true\n";
    // the new parameter goes after the last declared one (order = `p` order)
    let at = text
        .find("[[noise]]")
        .or_else(|| text.find("[[define]]"))
        .unwrap();
    std::fs::write(&spec, format!("{}{lag}\n{}", &text[..at], &text[at..])).unwrap();
    let spec = spec.to_str().unwrap();
    let log = Sim::new(spec)
        .sets(&["mocap_lag=0.06"])
        .drive("random", 7, 1)
        .write(tmp.path(), "lagged.csv");
    let fit = kinegen_json(&["fit", "--spec", spec, "--data", log.to_str().unwrap()]);
    let tau = fit["parameters"]["mocap_lag"]["estimate"].as_f64().unwrap();
    assert!((tau - 0.06).abs() < 0.004, "mocap_lag {tau}");
}

/// Issue #11.8: UMBMark refuses logs that are not square tests (it would give
/// precise-looking nonsense), naming the file; in `--method all` it is reported
/// as not applicable while the others run.
#[test]
fn umbmark_refuses_logs_that_are_not_square_tests() {
    let tmp = tempfile::tempdir().unwrap();
    let spec = "spec/diff_drive.toml";
    let f8 = Sim::new(spec)
        .drive("figure8", 1, 1)
        .write(tmp.path(), "eight.csv");
    let cw = Sim::new(spec)
        .drive("square-cw", 1, 1)
        .write(tmp.path(), "cw.csv");
    let (f8, cw) = (f8.to_str().unwrap(), cw.to_str().unwrap());
    let o = kinegen(&[
        "fit", "--spec", spec, "--data", cw, "--data", f8, "--method", "umbmark",
    ]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("eight.csv") && stderr(&o).contains("square"),
        "{}",
        stderr(&o)
    );
    // a wrong --side is caught too
    let ccw = Sim::new(spec)
        .drive("square-ccw", 1, 1)
        .write(tmp.path(), "ccw.csv");
    let ccw = ccw.to_str().unwrap();
    let o = kinegen(&[
        "fit", "--spec", spec, "--data", cw, "--data", ccw, "--method", "umbmark", "--side", "3",
    ]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    let ok = kinegen(&[
        "fit", "--spec", spec, "--data", cw, "--data", ccw, "--method", "umbmark",
    ]);
    assert!(ok.status.success(), "{}", stderr(&ok));
    let doc = kinegen_json(&["fit", "--spec", spec, "--data", f8, "--method", "all"]);
    let methods = doc["methods"].as_object().unwrap();
    assert!(!methods.contains_key("umbmark") && methods.contains_key("lm"));
}

/// Issue #16: output paths are checked before the work (nothing is created for
/// a refused run), and --truth names must be parameters of the spec.
#[test]
fn unwritable_outputs_and_unknown_truth_names_are_refused_up_front() {
    let tmp = tempfile::tempdir().unwrap();
    let log = Sim::new("spec/diff_drive.toml")
        .drive("square-cw", 1, 1)
        .write(tmp.path(), "cw.csv");
    let log = log.to_str().unwrap();
    let dir = tmp.path().to_str().unwrap();
    let file_as_dir = format!("{log}/x.json");
    for (args, needle) in [
        (vec!["--json", dir], "--json"),
        (vec!["--json", file_as_dir.as_str()], "is not a directory"),
        (vec!["--report", "/proc/kinegen"], "--report"),
        (
            vec!["--method", "all", "--truth", "wheel=1"],
            "--truth wheel",
        ),
    ] {
        let mut a = vec!["fit", "--spec", "spec/diff_drive.toml", "--data", log];
        a.extend(args);
        let o = kinegen(&a);
        assert_eq!(o.status.code(), Some(2), "{a:?}: {}", stderr(&o));
        assert!(stderr(&o).contains(needle), "{a:?}: {}", stderr(&o));
    }
    let names: Vec<_> = std::fs::read_dir(tmp.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(names.len(), 1, "stray files: {names:?}");
}

/// Issue #16: a 12-bit encoder counter that wraps (4096 -> 0) is read as the
/// continuous count once the spec says `wrap = 12`; without it, the wrap reads
/// as a huge backwards jump and the fit is far off. A `wrap` on an absolute
/// input is refused at its line.
#[test]
fn wrapping_encoder_counters_are_unwrapped_when_declared() {
    let tmp = tempfile::tempdir().unwrap();
    let spec = std::fs::read_to_string(root().join("spec/diff_drive.toml")).unwrap();
    let wrapped_spec = spec.replace("kind = \"cumulative\"", "kind = \"cumulative\"\nwrap = 12");
    assert_eq!(wrapped_spec.matches("wrap = 12").count(), 2);
    let (plain, wrapped) = (tmp.path().join("dd.toml"), tmp.path().join("dd_wrap.toml"));
    std::fs::write(&plain, &spec).unwrap();
    std::fs::write(&wrapped, &wrapped_spec).unwrap();
    let log = Sim::new(plain.to_str().unwrap())
        .sets(&["b=0.21"])
        .drive("random", 1, 1)
        .write(tmp.path(), "log.csv");
    // the counters as a 12-bit register would hold them
    let text = std::fs::read_to_string(&log).unwrap();
    let mut lines = text.lines();
    let header = lines.next().unwrap();
    let cols: Vec<&str> = header.split(',').collect();
    let enc: Vec<usize> = cols
        .iter()
        .enumerate()
        .filter(|(_, c)| c.starts_with("enc_"))
        .map(|(i, _)| i)
        .collect();
    let mut out = vec![header.to_string()];
    let mut wraps = 0;
    for l in lines {
        let mut f: Vec<String> = l.split(',').map(String::from).collect();
        for &i in &enc {
            let v: f64 = f[i].parse().unwrap();
            wraps += (v >= 4096.0) as usize;
            f[i] = format!("{}", v.rem_euclid(4096.0));
        }
        out.push(f.join(","));
    }
    assert!(wraps > 0, "the simulated counters never pass 4096");
    let wlog = tmp.path().join("wrapped.csv");
    std::fs::write(&wlog, out.join("\n") + "\n").unwrap();
    let fit = |s: &std::path::Path, l: &std::path::Path| {
        kinegen_json(&[
            "fit",
            "--spec",
            s.to_str().unwrap(),
            "--data",
            l.to_str().unwrap(),
        ])["parameters"]["b"]["estimate"]
            .as_f64()
            .unwrap()
    };
    let (reference, unwrapped) = (fit(&plain, &log), fit(&wrapped, &wlog));
    assert!(
        (reference - unwrapped).abs() < 1e-9,
        "{reference} vs {unwrapped}"
    );
    let o = kinegen(&[
        "fit",
        "--spec",
        plain.to_str().unwrap(),
        "--data",
        wlog.to_str().unwrap(),
        "--json",
        "-",
    ]);
    let naive = serde_json::from_slice::<serde_json::Value>(&o.stdout).ok();
    let b = naive
        .as_ref()
        .and_then(|d| d["parameters"]["b"]["estimate"].as_f64());
    assert!(
        b.is_none_or(|b| (b - 0.21).abs() > 1e-3),
        "an undeclared wrap went unnoticed: b = {b:?}"
    );
    // `wrap` on an absolute input is refused where it is written
    let bad = tmp.path().join("bad.toml");
    std::fs::write(
        &bad,
        wrapped_spec.replacen(
            "kind = \"cumulative\"\nwrap = 12",
            "kind = \"absolute\"\nwrap = 12",
            1,
        ),
    )
    .unwrap();
    let o = kinegen(&[
        "fit",
        "--spec",
        bad.to_str().unwrap(),
        "--data",
        log.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("bad.toml:") && stderr(&o).contains("wrap"),
        "{}",
        stderr(&o)
    );
}

/// Issue #17.3: `fit --export ros2-yaml PATH` writes diff_drive_controller
/// parameters for a differential drive (the simulated wheel separation 5% wide
/// shows as a 1.05 multiplier) and every calibrated parameter with its standard
/// deviation for any other model; a bad format or path is refused before the fit.
#[test]
fn calibrated_values_export_as_ros2_yaml() {
    let tmp = tempfile::tempdir().unwrap();
    let spec = "spec/diff_drive.toml";
    let log = Sim::new(spec)
        .sets(&["b=0.21"])
        .drive("random", 1, 1)
        .write(tmp.path(), "cw.csv");
    let log = log.to_str().unwrap();
    let yaml = tmp.path().join("robot/controller.yaml");
    let o = kinegen(&[
        "fit",
        "--spec",
        spec,
        "--data",
        log,
        "--export",
        "ros2-yaml",
        yaml.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = std::fs::read_to_string(&yaml).unwrap();
    let value = |key: &str| -> f64 {
        let line = text
            .lines()
            .find(|l| l.trim_start().starts_with(&format!("{key}:")))
            .unwrap_or_else(|| panic!("no {key} in\n{text}"));
        line.split(':').nth(1).unwrap().trim().parse().unwrap()
    };
    assert!(
        text.contains("diff_drive_controller:\n  ros__parameters:"),
        "{text}"
    );
    assert!((value("wheel_separation") - 0.2).abs() < 1e-9);
    assert!(
        (value("wheel_separation_multiplier") - 1.05).abs() < 0.005,
        "{text}"
    );
    for side in ["left", "right"] {
        assert!(
            (value(&format!("{side}_wheel_radius_multiplier")) - 1.0).abs() < 0.005,
            "{text}"
        );
    }
    // any other model: the generic list
    let trike = root().join("tests/user_specs/fwd_tricycle.toml");
    let trike = trike.to_str().unwrap();
    let tlog = Sim::new(trike)
        .drive("random", 1, 1)
        .write(tmp.path(), "trike.csv");
    let generic = tmp.path().join("trike.yaml");
    let o = kinegen(&[
        "fit",
        "--spec",
        trike,
        "--data",
        tlog.to_str().unwrap(),
        "--export",
        "ros2-yaml",
        generic.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = std::fs::read_to_string(&generic).unwrap();
    assert!(
        text.contains("kinegen_calibration:") && text.contains("    steer_gain:\n      value: "),
        "{text}"
    );
    assert!(
        text.lines()
            .filter(|l| l.trim_start().starts_with("std:"))
            .count()
            == 3,
        "{text}"
    );
    // refused before the work
    for (args, needle) in [
        (vec!["--export", "xml", "x.xml"], "unknown format"),
        (
            vec!["--export", "ros2-yaml", "/proc/kinegen.yaml"],
            "--export",
        ),
    ] {
        let mut a = vec!["fit", "--spec", spec, "--data", log];
        a.extend(args);
        let o = kinegen(&a);
        assert_eq!(o.status.code(), Some(2), "{a:?}");
        assert!(stderr(&o).contains(needle), "{}", stderr(&o));
    }
}

/// `fit --export spec PATH` writes the user's spec with the calibrated values
/// as its nominals, everything else as it was (comments included): its
/// model, as written, is the calibrated one (its error before any fit is the
/// first fit's after).
#[test]
fn calibrated_values_export_as_the_spec() {
    let tmp = tempfile::tempdir().unwrap();
    let spec_text = std::fs::read_to_string(root().join("spec/diff_drive.toml"))
        .unwrap()
        .replacen("\n", "\n# my robot, as I measured it\n", 1);
    let spec = tmp.path().join("my robot.toml");
    std::fs::write(&spec, &spec_text).unwrap();
    let slipping = add_effect(
        &spec,
        "lateral_slip",
        &[],
        &tmp.path().join("slipping.toml"),
    );
    let log = Sim::new(spec.to_str().unwrap())
        .sets(&["b=0.21"])
        .effects(&["lateral_slip=0.1"])
        .drive("random", 1, 1)
        .write(tmp.path(), "run.csv");
    let log = log.to_str().unwrap();
    let fitted = tmp.path().join("fitted.toml");
    let o = kinegen(&[
        "fit",
        "--spec",
        slipping.to_str().unwrap(),
        "--data",
        log,
        "--json",
        "-",
        "--export",
        "spec",
        fitted.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let fit: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let text = std::fs::read_to_string(&fitted).unwrap();
    assert!(text.contains("# my robot, as I measured it"), "{text}");
    assert!(text.starts_with("# calibrated by kinegen fit"), "{text}");
    // fitted again from the exported spec, it starts where the first fit ended
    let o = kinegen(&[
        "fit",
        "--spec",
        fitted.to_str().unwrap(),
        "--data",
        log,
        "--json",
        "-",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let again: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let after = fit["after"]["rmse"].as_f64().unwrap();
    let before = again["before"]["rmse"].as_f64().unwrap();
    eprintln!("fit after {after:.6} m; the exported spec before fitting {before:.6} m");
    assert!(
        (before - after).abs() <= 1e-9 + 1e-6 * after,
        "{before} vs {after}"
    );
    for (name, est) in fit["parameters"].as_object().unwrap() {
        if est["std"].is_null() {
            continue;
        }
        let v = est["estimate"].as_f64().unwrap();
        // the nominal of its [[parameter]] table
        let table = text
            .split("[[parameter]]")
            .find(|t| t.contains(&format!("name = \"{name}\"")))
            .unwrap_or_else(|| panic!("no table for {name} in\n{text}"));
        let nominal: f64 = table
            .lines()
            .find_map(|l| l.strip_prefix("nominal = "))
            .and_then(|n| n.trim().parse().ok())
            .unwrap_or_else(|| panic!("no nominal for {name} in\n{table}"));
        assert!(
            (nominal - v).abs() <= 1e-12 * v.abs().max(1.0),
            "{name}: {nominal} vs {v}"
        );
    }
}

/// Issue #16: numeric options that would give NaN results or empty checks are
/// refused by name (exit 2), and bounds read as numbers, not as `Some(0.0)`.
#[test]
fn nonsensical_numeric_options_are_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let spec = "spec/diff_drive.toml";
    let log = Sim::new(spec)
        .drive("square-cw", 1, 1)
        .write(tmp.path(), "cw.csv");
    let log = log.to_str().unwrap();
    for (args, needle) in [
        (
            vec![
                "fit", "--spec", spec, "--data", log, "--method", "ekf", "--mu", "nan",
            ],
            "--mu",
        ),
        (
            vec![
                "fit", "--spec", spec, "--data", log, "--method", "umbmark", "--side", "0",
            ],
            "--side",
        ),
        (
            vec!["verify", "--spec", spec, "--samples", "0"],
            "--samples",
        ),
        (
            vec!["compare", "--spec", spec, "--data", log, "--set", "b=0"],
            "(above 0)",
        ),
    ] {
        let o = kinegen(&args);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {}", stderr(&o));
        assert!(stderr(&o).contains(needle), "{args:?}: {}", stderr(&o));
        assert!(!stderr(&o).contains("Some("), "{}", stderr(&o));
    }
}

/// Issue 16: a run stopped by SIGTERM or SIGINT while it writes its output
/// leaves no temporary file and no half-written output, and exits 130.
#[test]
fn an_interrupted_write_leaves_nothing_behind() {
    let tmp = tempfile::tempdir().unwrap();
    for signal in [libc_sig::TERM, libc_sig::INT] {
        let out = tmp.path().join(format!("out{signal}"));
        let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_kinegen"))
            .args(["simulate", "--spec", "spec/diff_drive.toml", "--out"])
            .arg(out.join("sim.csv"))
            .current_dir(root())
            .env("KINEGEN_TEST_WRITE_PAUSE_MS", "3000")
            .spawn()
            .unwrap();
        // wait until the temporary file exists (half written), then signal
        let t0 = std::time::Instant::now();
        while std::fs::read_dir(&out).map_or(0, |d| d.count()) == 0 {
            assert!(t0.elapsed().as_secs() < 60, "the write never started");
            std::thread::sleep(std::time::Duration::from_millis(20));
        }
        let names = |d: &std::path::Path| -> Vec<String> {
            std::fs::read_dir(d)
                .unwrap()
                .map(|e| e.unwrap().file_name().to_string_lossy().to_string())
                .collect()
        };
        assert!(
            names(&out).iter().all(|n| n.ends_with(".kinegen-tmp")),
            "{:?}",
            names(&out)
        );
        let kill = std::process::Command::new("kill")
            .args([format!("-{signal}"), child.id().to_string()])
            .status()
            .unwrap();
        assert!(kill.success());
        let status = child.wait().unwrap();
        assert_eq!(status.code(), Some(130), "signal {signal}");
        assert!(
            names(&out).is_empty(),
            "left behind after signal {signal}: {:?}",
            names(&out)
        );
    }
}

/// Issue #37.5: SIGKILL cannot be caught, so a run killed while writing leaves
/// its temporary; the next write of the same output removes it (its writer's
/// process no longer runs) and writes the file.
#[test]
fn a_temporary_left_by_a_killed_run_is_swept_by_the_next() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("sim.csv");
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_kinegen"))
        .args(["simulate", "--spec", "spec/diff_drive.toml", "--out"])
        .arg(&out)
        .current_dir(root())
        .env("KINEGEN_TEST_WRITE_PAUSE_MS", "3000")
        .spawn()
        .unwrap();
    let names = || -> Vec<String> {
        std::fs::read_dir(tmp.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().to_string())
            .collect()
    };
    let t0 = std::time::Instant::now();
    while names().is_empty() {
        assert!(t0.elapsed().as_secs() < 60, "the write never started");
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    child.kill().unwrap();
    child.wait().unwrap();
    let left = names();
    assert!(
        left.len() == 1 && left[0].ends_with(".kinegen-tmp"),
        "{left:?}"
    );
    let o = kinegen(&[
        "simulate",
        "--spec",
        "spec/diff_drive.toml",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(names(), vec!["sim.csv".to_string()]);
}

/// Signal numbers for `kill -N` (POSIX values on Linux).
mod libc_sig {
    pub const INT: i32 = 2;
    pub const TERM: i32 = 15;
}

/// `kinegen compare ... | head -1`: the reader leaves before kinegen has
/// printed; kinegen stops quietly (exit 141, as a Unix filter killed by
/// SIGPIPE), with no panic message.
#[test]
fn a_reader_that_stops_reading_ends_the_run_quietly() {
    use std::process::{Command, Stdio};
    let mut child = Command::new(env!("CARGO_BIN_EXE_kinegen"))
        .args([
            "compare",
            "--spec",
            "spec/diff_drive.toml",
            "--data",
            "data/mystery_robot.csv",
        ])
        .current_dir(root())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    let o = child.wait_with_output().unwrap();
    let err = stderr(&o);
    assert!(!err.contains("panicked"), "{err}");
    assert_eq!(o.status.code(), Some(141), "{err}");
}

/// Issue #11.5: a long log fits through the CLI, and its report stays under
/// 5 MB whatever the log length (plots decimated, extremes kept): before, a
/// million-sample fit wrote a 223 MB report, about 45 MB at this log's
/// 200,000 rows. Also a check that the fit is right at that length: b within
/// 0.1% of the simulated robot's. (The million-row fit's time and memory are
/// scripts/bench_memory.sh's, not a test's.)
#[test]
fn a_long_fit_writes_a_report_under_5_mb() {
    let tmp = tempfile::tempdir().unwrap();
    // 110 laps of 91 s at 20 Hz: 200,201 rows
    let log = Sim::new("spec/diff_drive.toml")
        .sets(&["b=0.204"])
        .drive("random", 4, 110)
        .write(tmp.path(), "long.csv");
    let report = tmp.path().join("report");
    let doc = kinegen_json(&[
        "fit",
        "--spec",
        "spec/diff_drive.toml",
        "--data",
        log.to_str().unwrap(),
        "--report",
        report.to_str().unwrap(),
    ]);
    assert!(doc["residuals"].as_u64().unwrap() > 600_000);
    let b = doc["parameters"]["b"]["estimate"].as_f64().unwrap();
    assert!((b / 0.204 - 1.0).abs() < 1e-3, "b = {b}");
    let size = std::fs::metadata(report.join("index.html")).unwrap().len();
    assert!(size < 5_000_000, "report of {size} bytes");
}

/// Issue #11 item 3, a fit that still turns: a user-written rover
/// (`tests/user_specs/rover.toml`) whose log hides a 0.1 rad steering offset,
/// fitted with the spec as it is. The model keeps moving and turning and its
/// whole-track error falls (26.0 -> 23.2 m), but the wheel radius is fitted
/// 44% short and the drift over 5 s windows triples: unusable, exit 1.
#[test]
fn a_calibration_that_triples_the_short_term_drift_is_unusable() {
    let tmp = tempfile::tempdir().unwrap();
    let log = Sim::new("tests/user_specs/rover.toml")
        .effects(&["steering_offset=0.1"])
        .drive("random", 11, 3)
        .write(tmp.path(), "rover.csv");
    let (o, doc) = run_to_json(
        tmp.path(),
        "fit",
        &[
            "fit",
            "--spec",
            "tests/user_specs/rover.toml",
            "--data",
            log.to_str().unwrap(),
        ],
    );
    assert_eq!(o.status.code(), Some(1), "{}", stdout(&o));
    let unusable = doc["unusable"].to_string();
    assert!(
        unusable.contains("drifts more over 5 s windows"),
        "{unusable}"
    );
    // what to do next: the model lacks something
    assert!(stdout(&o).contains("kinegen diagnose"), "{}", stdout(&o));
}

/// A diff drive with a right wheel of 0.0505 m (nominal 0.042) driving at
/// random (seed 11), simulated into `dir/log.csv`.
fn wide_right_wheel_log(dir: &std::path::Path) -> std::path::PathBuf {
    Sim::new("spec/diff_drive.toml")
        .sets(&["r_r=0.0505"])
        .drive("random", 11, 1)
        .write(dir, "log.csv")
}

/// Motion capture that loses the robot leaves empty (or `nan`) pose cells:
/// those rows are cut out, each stretch between them is a run of its own
/// (said in a warning that names the lines), and the calibration is the one
/// the stretches give as separate logs. An encoder cell left empty is
/// interpolated, and said.
#[test]
fn rows_without_motion_capture_are_cut_out_and_said() {
    let tmp = tempfile::tempdir().unwrap();
    let log = wide_right_wheel_log(tmp.path());
    let text = std::fs::read_to_string(&log).unwrap();
    let mut lines: Vec<String> = text.lines().map(String::from).collect();
    let header: Vec<String> = lines[0].split(',').map(String::from).collect();
    let col = |name: &str| header.iter().position(|h| h == name).unwrap();
    let (gx, gy, gth) = (col("gt_x"), col("gt_y"), col("gt_theta"));
    // data rows 200-259 (file lines 202-261) lost by the tracker; one more as `nan`
    for (k, line) in lines.iter_mut().enumerate().skip(201).take(60) {
        let mut cells: Vec<String> = line.split(',').map(String::from).collect();
        for c in [gx, gy, gth] {
            cells[c] = if k == 230 {
                "nan".into()
            } else {
                String::new()
            };
        }
        *line = cells.join(",");
    }
    let dropped = tmp.path().join("dropped.csv");
    std::fs::write(&dropped, lines.join("\n") + "\n").unwrap();
    let (a, b) = (tmp.path().join("a.csv"), tmp.path().join("b.csv"));
    std::fs::write(&a, lines[..201].join("\n") + "\n").unwrap();
    std::fs::write(&b, [&lines[..1], &lines[261..]].concat().join("\n") + "\n").unwrap();
    let fit = |args: &[&str]| {
        let mut all = vec!["fit", "--spec", "spec/diff_drive.toml"];
        all.extend(args);
        kinegen_json(&all)
    };
    let whole = fit(&["--data", dropped.to_str().unwrap()]);
    let said = whole["warnings"].to_string();
    assert!(
        said.contains("60 row(s) without a measurement") && said.contains("lines 202-261"),
        "{said}"
    );
    let parts = fit(&["--data", a.to_str().unwrap(), "--data", b.to_str().unwrap()]);
    let r_r = |d: &serde_json::Value| d["parameters"]["r_r"]["estimate"].as_f64().unwrap();
    // the same rows, the same calibration (to round-off)
    assert!(
        (r_r(&whole) - r_r(&parts)).abs() < 1e-12,
        "{} vs {}",
        r_r(&whole),
        r_r(&parts)
    );
    assert!((r_r(&whole) - 0.0505).abs() < 1e-4, "{}", r_r(&whole));
    // an encoder cell left empty is no missing measurement: the counter is
    // interpolated over it (its difference spreads over the two steps), said
    let mut broken = lines.clone();
    let enc = col("enc_l");
    let mut cells: Vec<String> = broken[100].split(',').map(String::from).collect();
    cells[enc] = String::new();
    broken[100] = cells.join(",");
    let holed = tmp.path().join("holed.csv");
    std::fs::write(&holed, broken.join("\n") + "\n").unwrap();
    let filled = fit(&["--data", holed.to_str().unwrap()]);
    let said = filled["warnings"].to_string();
    assert!(
        said.contains("holed.csv: 1 row(s) leave input column(s) `enc_l` empty"),
        "{said}"
    );
    assert!(
        (r_r(&filled) - r_r(&whole)).abs() < 1e-5,
        "{}",
        r_r(&filled)
    );
}

/// A log merged from sources that log at their own times, as a table
/// exported from several topics is: encoder rows and motion-capture rows at
/// times of their own, each leaving the other's cells empty, the motion
/// capture at half the encoders' rate. The counters are interpolated to the
/// motion capture's rows and the motion capture to the encoders' rows, so the
/// log calibrates as the complete one does (before, every row lacked a
/// cell: refused, or cut into runs of one row).
#[test]
fn a_log_merged_from_sources_at_their_own_times_is_read_whole() {
    let tmp = tempfile::tempdir().unwrap();
    let log = wide_right_wheel_log(tmp.path());
    let text = std::fs::read_to_string(&log).unwrap();
    let mut lines = text.lines();
    let header = lines.next().unwrap();
    let cols: Vec<&str> = header.split(',').collect();
    let is_gt = |i: usize| cols[i].starts_with("gt_");
    let mut merged = format!("{header}\n");
    for (k, line) in lines.enumerate() {
        let cells: Vec<&str> = line.split(',').collect();
        let t: f64 = cells[0].parse().unwrap();
        let keep = |gt: bool| -> String {
            (0..cells.len())
                .map(|i| {
                    if i == 0 || is_gt(i) == gt {
                        cells[i]
                    } else {
                        ""
                    }
                })
                .collect::<Vec<_>>()
                .join(",")
        };
        merged += &(keep(false) + "\n");
        if k % 2 == 0 {
            // the tracker's sample, taken at the encoders' time, logged 1 ms later
            let mut row: Vec<String> = keep(true).split(',').map(String::from).collect();
            row[0] = format!("{:.4}", t + 0.001);
            merged += &(row.join(",") + "\n");
        }
    }
    let path = tmp.path().join("merged.csv");
    std::fs::write(&path, merged).unwrap();
    let fit = |data: &std::path::Path| {
        kinegen_json(&[
            "fit",
            "--spec",
            "spec/diff_drive.toml",
            "--data",
            data.to_str().unwrap(),
        ])
    };
    let (whole, read) = (fit(&log), fit(&path));
    let said = read["warnings"].to_string();
    assert!(
        said.contains("merged.csv:")
            && said.contains("leave input column(s) `enc_r`, `enc_l` empty"),
        "{said}"
    );
    let r_r = |d: &serde_json::Value| d["parameters"]["r_r"]["estimate"].as_f64().unwrap();
    assert!(
        (r_r(&read) - 0.0505).abs() < 1e-4 && (r_r(&read) - r_r(&whole)).abs() < 2e-5,
        "merged {} vs complete {}",
        r_r(&read),
        r_r(&whole)
    );
    assert_eq!(read["runs"].as_array().unwrap().len(), 1, "{read}");
}
