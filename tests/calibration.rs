//! simulate, compare and fit: recovery of parameters, every bundled model, real
//! data, and bad input.
mod common;
use common::*;

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

#[test]
fn fit_recovers_wheel_radii_and_wheelbase_within_0_2_percent_and_error_falls_tenfold() {
    let tmp = tempfile::tempdir().unwrap();
    let truth = [("r_r", 0.0425), ("r_l", 0.0418), ("b", 0.2050)];
    let sets: Vec<String> = truth.iter().map(|(n, v)| format!("{n}={v}")).collect();
    let mut args = vec![
        "--spec",
        "spec/diff_drive.toml",
        "--trajectory",
        "square",
        "--seed",
        "3",
    ];
    for s in &sets {
        args.extend(["--set", s.as_str()]);
    }
    let log = simulate(tmp.path(), "params.csv", &args);
    let doc = kinegen_json(&[
        "fit",
        "--spec",
        "spec/diff_drive.toml",
        "--data",
        log.to_str().unwrap(),
    ]);
    for (name, value) in truth {
        let est = doc["parameters"][name]["estimate"].as_f64().unwrap();
        assert!(
            ((est - value) / value).abs() < 0.002,
            "{name}: {est} vs true {value}"
        );
        assert!(doc["parameters"][name]["std"].as_f64().unwrap() > 0.0);
    }
    let (before, after) = (
        doc["before"]["rmse"].as_f64().unwrap(),
        doc["after"]["rmse"].as_f64().unwrap(),
    );
    assert!(
        after * 10.0 < before,
        "error fell only from {before} to {after}"
    );
    assert_eq!(doc["model"], "diff_drive");
}

#[test]
fn every_bundled_model_can_be_simulated_compared_and_fitted() {
    let tmp = tempfile::tempdir().unwrap();
    for (spec, set) in [
        ("diff_drive", "b=0.21"),
        ("tricycle", "L=1.03"),
        ("tricycle_fwd", "L=1.03"),
        ("omni3", "L=1.04"),
        ("omni_caster", "r2=0.103"),
        ("unicycle_ekf", "v_scale=1.05"),
    ] {
        let path = format!("spec/{spec}.toml");
        let log = simulate(
            tmp.path(),
            &format!("{spec}.csv"),
            &[
                "--spec",
                &path,
                "--set",
                set,
                "--trajectory",
                "random",
                "--seed",
                "2",
            ],
        );
        let cmp = kinegen_json(&["compare", "--spec", &path, "--data", log.to_str().unwrap()]);
        assert!(cmp["rmse"].as_f64().unwrap() > 0.0);
        assert!(
            !cmp["regimes"].as_array().unwrap().is_empty(),
            "{spec}: no regime breakdown"
        );
        let fit = kinegen_json(&["fit", "--spec", &path, "--data", log.to_str().unwrap()]);
        let (b, a) = (
            fit["before"]["rmse"].as_f64().unwrap(),
            fit["after"]["rmse"].as_f64().unwrap(),
        );
        assert!(
            a < 0.5 * b,
            "{spec}: fit did not reduce the error ({b} -> {a})"
        );
    }
}

/// A steering log that leaves the spec's declared range (seed 001's tricycle,
/// `range = [-1.2, 1.2]`) is flagged by compare and fit with the lines, so a poor
/// fit there is not blamed on identifiability; the same log inside it is not.
#[test]
fn inputs_outside_their_declared_range_are_reported_with_their_lines() {
    let tmp = tempfile::tempdir().unwrap();
    let spec = "spec/tricycle.toml";
    let log = simulate(
        tmp.path(),
        "inside.csv",
        &["--spec", spec, "--trajectory", "random", "--seed", "2"],
    );
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
    let log = simulate(
        tmp.path(),
        "log.csv",
        &["--spec", "spec/diff_drive.toml", "--seed", "4"],
    );
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
    let log = simulate(
        tmp.path(),
        "log.csv",
        &[
            "--spec",
            "spec/diff_drive.toml",
            "--trajectory",
            "random",
            "--seed",
            "2",
        ],
    );
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
    let log = simulate(
        tmp.path(),
        "log.csv",
        &["--spec", "spec/diff_drive.toml", "--trajectory", "random"],
    );
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
    let log = simulate(
        tmp.path(),
        "delay.csv",
        &[
            "--spec",
            "spec/diff_drive.toml",
            "--effect",
            "time_offset=0.08",
            "--trajectory",
            "random",
            "--seed",
            "7",
        ],
    );
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
    let log = simulate(
        tmp.path(),
        "lagged.csv",
        &[
            "--spec",
            spec,
            "--set",
            "mocap_lag=0.06",
            "--trajectory",
            "random",
            "--seed",
            "7",
        ],
    );
    let fit = kinegen_json(&["fit", "--spec", spec, "--data", log.to_str().unwrap()]);
    let tau = fit["parameters"]["mocap_lag"]["estimate"].as_f64().unwrap();
    assert!((tau - 0.06).abs() < 0.004, "mocap_lag {tau}");
}

#[test]
fn seed_methods_run_and_are_compared_on_umbmark_squares() {
    let tmp = tempfile::tempdir().unwrap();
    let truth = ["r_r=0.0423", "r_l=0.0417", "b=0.206"];
    let mut data = Vec::new();
    for dir in ["cw", "ccw"] {
        let traj = format!("square-{dir}");
        let log = simulate(
            tmp.path(),
            &format!("{dir}.csv"),
            &[
                "--spec",
                "spec/diff_drive.toml",
                "--set",
                truth[0],
                "--set",
                truth[1],
                "--set",
                truth[2],
                "--trajectory",
                &traj,
                "--seed",
                "1",
            ],
        );
        data.push(log.to_str().unwrap().to_string());
    }
    let mut args = vec![
        "fit",
        "--spec",
        "spec/diff_drive.toml",
        "--method",
        "all",
        "--data",
        &data[0],
        "--data",
        &data[1],
    ];
    for t in &truth {
        args.extend(["--truth", t]);
    }
    let doc = kinegen_json(&args);
    let methods = doc["methods"].as_object().unwrap();
    for m in ["lm", "gd", "ekf", "umbmark"] {
        assert!(methods.contains_key(m), "{m} did not run");
    }
    assert_eq!(doc["closest_to_truth"], "lm");
    // UMBMark moves every parameter toward the truth
    let nominal = [0.042, 0.042, 0.2];
    for ((name, t), n) in ["r_r", "r_l", "b"]
        .iter()
        .zip([0.0423, 0.0417, 0.206])
        .zip(nominal)
    {
        let est = methods["umbmark"]["parameters"][*name]["estimate"]
            .as_f64()
            .unwrap();
        assert!(
            (est - t).abs() < (n - t).abs(),
            "umbmark {name}: {est}, truth {t}, nominal {n}"
        );
    }
    // the yaw-rate EKF (seed 000) improves the ratio it can see: omega = (r_r w_r - r_l w_l)/b
    let e = &methods["ekf"]["parameters"];
    let ratio = |r: f64, b: f64| r / b;
    let (er, eb) = (
        e["r_r"]["estimate"].as_f64().unwrap(),
        e["b"]["estimate"].as_f64().unwrap(),
    );
    assert!(
        (ratio(er, eb) - ratio(0.0423, 0.206)).abs()
            < (ratio(0.042, 0.2) - ratio(0.0423, 0.206)).abs()
    );
}

/// Seed 000's setting: the Omni robot with the nominal parameters of eq. 27, the
/// truth taken from the values the paper identified (eq. 28). Every method must
/// move the parameters toward the truth; the report says which got closest.
#[test]
fn seed_000_setting_every_method_moves_toward_the_truth() {
    let tmp = tempfile::tempdir().unwrap();
    let truth = SEED_000_TRUTH;
    let log = seed_000_log(tmp.path(), "omni.csv", "3");
    let report = tmp.path().join("report");
    let mut args = vec![
        "fit",
        "--spec",
        "spec/omni_caster.toml",
        "--method",
        "all",
        "--data",
        log.to_str().unwrap(),
        "--report",
        report.to_str().unwrap(),
    ];
    for t in &truth {
        args.extend(["--truth", t]);
    }
    let doc = kinegen_json(&args);
    let methods = doc["methods"].as_object().unwrap();
    for m in ["lm", "gd", "ekf"] {
        let d = methods[m]["distance_to_truth"].as_f64().unwrap();
        assert!(
            d < 1.0,
            "{m} did not move toward the truth: {:.1}% of the nominal's distance left",
            100.0 * d
        );
    }
    assert_eq!(doc["closest_to_truth"], "lm");
    // pose residuals pin what the yaw rate cannot see: LM leaves < 5% of the initial distance
    assert!(methods["lm"]["distance_to_truth"].as_f64().unwrap() < 0.05);
    // the seed's gyro-only methods are warned about the directions they cannot see
    assert!(methods["ekf"]["note"]
        .as_str()
        .unwrap()
        .contains("undetermined"));
    let html = std::fs::read_to_string(report.join("index.html")).unwrap();
    assert!(html.contains("Closest to the true parameters: <b>lm</b>"));
}

/// Motion-capture glitches (3% of rows thrown 0.8 m off) bias a least-squares
/// fit; the Huber loss (--loss huber) keeps the estimates near the truth.
#[test]
fn huber_loss_resists_ground_truth_outliers() {
    let tmp = tempfile::tempdir().unwrap();
    let log = simulate(
        tmp.path(),
        "sq.csv",
        &[
            "--spec",
            "spec/diff_drive.toml",
            "--set",
            "r_r=0.0425",
            "--set",
            "r_l=0.0418",
            "--set",
            "b=0.205",
            "--trajectory",
            "square",
            "--seed",
            "3",
        ],
    );
    let text = std::fs::read_to_string(&log).unwrap();
    let mut lines: Vec<String> = text.lines().map(String::from).collect();
    let header: Vec<&str> = lines[0].split(',').collect();
    let (ix, iy) = (
        header.iter().position(|h| *h == "gt_x").unwrap(),
        header.iter().position(|h| *h == "gt_y").unwrap(),
    );
    // deterministic glitches: every 33rd row
    for (k, line) in lines.iter_mut().enumerate().skip(1) {
        if k % 33 == 0 {
            let mut cells: Vec<String> = line.split(',').map(String::from).collect();
            let s = if k % 66 == 0 { 0.8 } else { -0.8 };
            cells[ix] = format!("{}", cells[ix].parse::<f64>().unwrap() + s);
            cells[iy] = format!("{}", cells[iy].parse::<f64>().unwrap() - s);
            *line = cells.join(",");
        }
    }
    let bad = tmp.path().join("glitches.csv");
    std::fs::write(&bad, lines.join("\n") + "\n").unwrap();
    let est = |loss: &str| {
        let d = kinegen_json(&[
            "fit",
            "--spec",
            "spec/diff_drive.toml",
            "--data",
            bad.to_str().unwrap(),
            "--loss",
            loss,
        ]);
        assert_eq!(d["loss"], loss);
        [("r_r", 0.0425), ("r_l", 0.0418), ("b", 0.205)]
            .map(|(n, t)| (d["parameters"][n]["estimate"].as_f64().unwrap() - t).abs() / t)
    };
    let (l2, huber) = (est("l2"), est("huber"));
    assert!(huber.iter().all(|e| *e < 0.004), "huber errors {huber:?}");
    let worst = |v: [f64; 3]| v.iter().cloned().fold(0.0, f64::max);
    assert!(
        worst(huber) < worst(l2),
        "huber {huber:?} is not better than l2 {l2:?}"
    );
}

/// Turning in place shows only the ratios r/b: the fit warns by name that the
/// common scale of r_r, r_l and b is not identifiable, reports their standard
/// deviations as null (not as a small number), keeps them near nominal instead
/// of wandering along the null direction, and still fits the ratio it can see.
#[test]
fn turning_in_place_leaves_the_common_scale_unidentified_and_says_so() {
    let tmp = tempfile::tempdir().unwrap();
    let log = simulate(
        tmp.path(),
        "spin.csv",
        &[
            "--spec",
            "spec/diff_drive.toml",
            "--set",
            "b=0.21",
            "--trajectory",
            "spin",
            "--seed",
            "1",
        ],
    );
    let fit = kinegen_json(&[
        "fit",
        "--spec",
        "spec/diff_drive.toml",
        "--data",
        log.to_str().unwrap(),
    ]);
    let warnings: Vec<&str> = fit["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .map(|w| w.as_str().unwrap())
        .collect();
    assert!(
        warnings
            .iter()
            .any(|w| w.contains("not identifiable")
                && ["r_r", "r_l", "b"].iter().all(|n| w.contains(n))),
        "{warnings:?}"
    );
    let est = |n: &str| fit["parameters"][n]["estimate"].as_f64().unwrap();
    for n in ["r_r", "r_l", "b"] {
        assert!(
            fit["parameters"][n]["std"].is_null(),
            "{n}: std {}",
            fit["parameters"][n]["std"]
        );
    }
    assert!(
        (est("b") / 0.2 - 1.0).abs() < 0.1,
        "b wandered to {}",
        est("b")
    );
    let ratio = (est("r_r") + est("r_l")) / est("b");
    assert!(
        (ratio / (0.084 / 0.21) - 1.0).abs() < 0.005,
        "(r_r + r_l)/b = {ratio}, truth {}",
        0.084 / 0.21
    );
}

/// A cart whose only steering is a fixed toe angle: the log shows the curvature
/// tan(toe)/L and nothing else, a curved set of equally good (L, toe) pairs.
/// From toe = 0 the fit must still reach the curvature (before: the
/// undetermined direction found at the optimum, held from the start, was
/// nearly the toe axis there, and the fit ended where it began, 0.77 m RMSE)
/// and say that L and toe cannot be separated.
#[test]
fn a_curved_undetermined_direction_does_not_stop_the_fit_at_its_start() {
    let tmp = tempfile::tempdir().unwrap();
    let spec = tmp.path().join("cart.toml");
    std::fs::write(
        &spec,
        r#"name = "cart"
state = ["x", "y", "theta"]

[[input]]
name = "w"
column = "wheel_rad"
kind = "cumulative"
unit = "rad/s"

[[parameter]]
name = "r"
nominal = 0.11
unit = "m"
min = 0.01

[[parameter]]
name = "L"
nominal = 0.65
unit = "m"
min = 0.1

[[parameter]]
name = "toe"
nominal = 0.0
unit = "rad"
min = -0.2
max = 0.2

[motion]
vx = "r*w"
vy = "0"
omega = "r*w*tan(toe)/L"

[[observation]]
name = "mocap"
columns = ["mx", "my", "myaw"]
expr = ["x", "y", "theta"]
angle = [false, false, true]
sigma = [0.003, 0.003, 0.005]
"#,
    )
    .unwrap();
    let spec = spec.to_str().unwrap();
    let log = simulate(
        tmp.path(),
        "cart.csv",
        &[
            "--spec",
            spec,
            "--set",
            "toe=0.05",
            "--trajectory",
            "figure8",
            "--seed",
            "4",
        ],
    );
    let fit = kinegen_json(&["fit", "--spec", spec, "--data", log.to_str().unwrap()]);
    let after = fit["after"]["rmse"].as_f64().unwrap();
    assert!(
        after < 0.01,
        "position RMSE after the fit {after} m: {}",
        fit["warnings"]
    );
    let est = |n: &str| fit["parameters"][n]["estimate"].as_f64().unwrap();
    let curvature = est("toe").tan() / est("L");
    let truth = 0.05f64.tan() / 0.65;
    assert!(
        (curvature / truth - 1.0).abs() < 0.01,
        "tan(toe)/L = {curvature}, truth {truth}"
    );
    let warnings = fit["warnings"].to_string();
    assert!(
        warnings.contains("combination of L and toe")
            || warnings.contains("combination of toe and L"),
        "{warnings}"
    );
}

/// Issue #11: a front-wheel-drive tricycle (tests/user_specs) whose steering gain
/// is 5x off its nominal value and whose tracker sits 1.8 m ahead of the rear
/// axle. From the nominal values a whole-track fit falls into the "robot that
/// does not move" minimum; the continuation ladder (short re-anchored segments
/// first) must reach the optimum a fit started at the truth reaches, on a short
/// (83 s) and a long (546 s) log. Also checks the per-run JSON (CONTRACT section 4).
#[test]
fn fit_from_rough_nominal_values_reaches_the_optimum_of_a_fit_started_at_the_truth() {
    let tmp = tempfile::tempdir().unwrap();
    let spec = root().join("tests/user_specs/fwd_tricycle.toml");
    let spec = spec.to_str().unwrap();
    let truth = ["steer_gain=0.005", "r=0.23"];
    for (traj, laps, name) in [("square", "1", "square.csv"), ("random", "6", "long.csv")] {
        let mut args = vec![
            "--spec",
            spec,
            "--trajectory",
            traj,
            "--laps",
            laps,
            "--seed",
            "7",
        ];
        for s in truth {
            args.extend(["--set", s]);
        }
        let log = simulate(tmp.path(), name, &args);
        let log = log.to_str().unwrap();
        let from_nominal = kinegen_json(&["fit", "--spec", spec, "--data", log]);
        let mut at_truth = vec!["fit", "--spec", spec, "--data", log];
        for s in truth {
            at_truth.extend(["--set", s]);
        }
        let from_truth = kinegen_json(&at_truth);
        for p in ["r", "L", "steer_gain"] {
            let (a, b) = (&from_nominal["parameters"][p], &from_truth["parameters"][p]);
            let (ea, eb, std) = (
                a["estimate"].as_f64().unwrap(),
                b["estimate"].as_f64().unwrap(),
                b["std"].as_f64().unwrap(),
            );
            assert!(
                (ea - eb).abs() <= 2.0 * std,
                "{traj}: {p} from nominal {ea}, from the truth {eb} (std {std})"
            );
        }
        assert_eq!(from_nominal["unusable"], serde_json::json!([]), "{traj}");
        let runs = from_nominal["runs"].as_array().unwrap();
        assert_eq!(runs.len(), 1);
        assert!(runs[0]["path"].as_str().unwrap().ends_with(name));
        assert!(
            runs[0]["rmse"].as_f64().unwrap() < 0.1 * runs[0]["before"]["rmse"].as_f64().unwrap()
        );
        assert_eq!(runs[0]["start_pose"].as_array().unwrap().len(), 3);
    }
}

/// Issue #70.4: on a spec that lacks the effect the robot has (a misspecified
/// model), fit from rough nominal values (the truth 2-3x off them) reaches
/// the error a fit started at the true values reaches, within 10%, on four
/// models. What is left is for diagnose, and fit says so: where the
/// calibrated model still cannot follow the logs it exits 1 (the JSON
/// written all the same), and the front-drive tricycle that collapses its
/// wheel names what it could not reconcile.
#[test]
fn fit_from_rough_nominal_values_on_a_spec_missing_an_effect_reaches_what_the_truth_reaches() {
    let tmp = tempfile::tempdir().unwrap();
    let cases: [(&str, &[&str], &str); 4] = [
        (
            "spec/diff_drive.toml",
            &["b=0.5", "r_l=0.08", "r_r=0.08"],
            "lateral_slip=0.2",
        ),
        (
            "spec/tricycle.toml",
            &["L=3.0", "r=0.06"],
            "steering_offset=0.05",
        ),
        ("spec/tricycle_fwd.toml", &["L=0.3"], "steering_offset=0.08"),
        ("spec/omni3.toml", &["L=0.3"], "wheel_radius_asymmetry=0.05"),
    ];
    for (k, (spec, truth, effect)) in cases.iter().enumerate() {
        let mut sim = vec!["--spec", spec, "--effect", effect, "--trajectory", "random"];
        sim.extend(["--seed", "11"]);
        for s in *truth {
            sim.extend(["--set", s]);
        }
        let log = simulate(tmp.path(), &format!("log{k}.csv"), &sim);
        let log = log.to_str().unwrap();
        let error = |doc: &serde_json::Value| doc["after"]["errors"]["rmse"].as_f64().unwrap();
        // exit 0, or 1 for a fit the model cannot make usable: both write the JSON
        let fitted = |args: &[&str]| {
            let o = kinegen(&[args, &["--json", "-"]].concat());
            assert!(
                matches!(o.status.code(), Some(0 | 1)),
                "{args:?}: {}",
                stderr(&o)
            );
            serde_json::from_slice::<serde_json::Value>(&o.stdout).unwrap()
        };
        let fit = fitted(&["fit", "--spec", spec, "--data", log]);
        let mut at_truth = vec!["fit", "--spec", spec, "--data", log];
        for s in *truth {
            at_truth.extend(["--set", s]);
        }
        let (from_nominal, from_truth) = (error(&fit), error(&fitted(&at_truth)));
        assert!(
            from_nominal <= 1.1 * from_truth,
            "{spec} with {effect}: {from_nominal} from nominal, {from_truth} from the truth"
        );
        if spec.ends_with("tricycle_fwd.toml") {
            let warnings = fit["warnings"].to_string();
            assert!(warnings.contains("cannot reconcile"), "{warnings}");
        }
    }
}

/// Issue #11.8: UMBMark refuses logs that are not square tests (it would give
/// precise-looking nonsense), naming the file; in `--method all` it is reported
/// as not applicable while the others run.
#[test]
fn umbmark_refuses_logs_that_are_not_square_tests() {
    let tmp = tempfile::tempdir().unwrap();
    let spec = "spec/diff_drive.toml";
    let f8 = simulate(
        tmp.path(),
        "eight.csv",
        &["--spec", spec, "--trajectory", "figure8"],
    );
    let cw = simulate(
        tmp.path(),
        "cw.csv",
        &["--spec", spec, "--trajectory", "square-cw"],
    );
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
    let ccw = simulate(
        tmp.path(),
        "ccw.csv",
        &["--spec", spec, "--trajectory", "square-ccw"],
    );
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

/// Issue #11.8: on the real OptiOdom squares (runs 1, 2, 4, 5 fitted, 3 and 6
/// held out) the yaw-rate methods (seed 000) can end worse than the nominal
/// values on held-out runs; they must say so. And LM beats UMBMark there.
#[test]
fn a_method_worse_than_nominal_on_held_out_runs_says_so() {
    let Some(runs) = real_runs() else { return };
    let p = |i: usize| runs[i].to_str().unwrap().to_string();
    let (a, b, c, d, h1, h2) = (p(0), p(1), p(3), p(4), p(2), p(5));
    let doc = kinegen_json(&[
        "fit",
        "--spec",
        "spec/diff_drive.toml",
        "--method",
        "all",
        "--data",
        &a,
        "--data",
        &b,
        "--data",
        &c,
        "--data",
        &d,
        "--holdout",
        &h1,
        "--holdout",
        &h2,
        "--side",
        "0.75",
    ]);
    let nominal = doc["holdout_before"]["rmse"].as_f64().unwrap();
    let mut warned = 0;
    for (name, m) in doc["methods"].as_object().unwrap() {
        let held = m["holdout"]["rmse"].as_f64().unwrap();
        let says = m["note"]
            .as_str()
            .unwrap()
            .contains("worse than the nominal");
        assert_eq!(
            held > 1.001 * nominal,
            says,
            "{name}: held-out {held} vs nominal {nominal}"
        );
        warned += says as usize;
    }
    assert!(
        warned > 0,
        "expected gd or ekf to end worse than nominal on these runs"
    );
    // a full-trajectory fit beats the four-number end-point method on held-out
    // runs (with the squares' true side, 0.75 m: a wrong --side 1 gives UMBMark
    // a lucky 0.0086 m)
    let held = |m: &str| doc["methods"][m]["holdout"]["rmse"].as_f64().unwrap();
    assert!(
        held("lm") < held("umbmark"),
        "lm {} vs umbmark {}",
        held("lm"),
        held("umbmark")
    );
}

/// Issue #11.2: reported standard deviations are honest. Over 50 simulated seeds
/// of a differential drive (random driving, 91 s, parameter errors), the spread
/// of each estimate matches the mean reported standard deviation within 30%,
/// with the increments likelihood and with the default absolute-track one. The
/// track's standard deviations were 3-9x too small while a start heading
/// averaged over the logs' rest was held fixed: its leftover error rotated the
/// whole track, differently in every log, which the residuals' random walk
/// took the blame for.
#[test]
fn fifty_seeds_spread_matches_the_reported_standard_deviation() {
    let tmp = tempfile::tempdir().unwrap();
    let spec = "spec/diff_drive.toml";
    let names = ["r_r", "r_l", "b"];
    let mut est = vec![vec![]; 3];
    let mut std = vec![vec![]; 3];
    let mut track_std = vec![vec![]; 3];
    let mut track_est = vec![vec![]; 3];
    for seed in 1..=50 {
        let s = seed.to_string();
        let log = simulate(
            tmp.path(),
            &format!("s{seed}.csv"),
            &[
                "--spec",
                spec,
                "--trajectory",
                "random",
                "--seed",
                &s,
                "--set",
                "r_r=0.0425",
                "--set",
                "b=0.205",
            ],
        );
        let log = log.to_str().unwrap();
        let doc = kinegen_json(&[
            "fit",
            "--spec",
            spec,
            "--data",
            log,
            "--likelihood",
            "increments",
        ]);
        let track = kinegen_json(&["fit", "--spec", spec, "--data", log]);
        push_estimates(&doc, &names, &mut est, &mut std);
        push_estimates(&track, &names, &mut track_est, &mut track_std);
    }
    for (k, n) in names.iter().enumerate() {
        let spread = spread_of(&est[k]);
        let ratio = spread / mean(&std[k]);
        assert!(
            (0.7..=1.3).contains(&ratio),
            "{n}: spread {spread:.3e} against reported {:.3e} (ratio {ratio:.2})",
            mean(&std[k])
        );
        let track_ratio = spread_of(&track_est[k]) / mean(&track_std[k]);
        eprintln!("{n}: increments {ratio:.2}, track {track_ratio:.2}");
        assert!(
            (0.7..=1.3).contains(&track_ratio),
            "{n}: track likelihood: spread {:.3e} against reported {:.3e} (ratio {track_ratio:.2})",
            spread_of(&track_est[k]),
            mean(&track_std[k])
        );
    }
}

/// Issue #16: output paths are checked before the work (nothing is created for
/// a refused run), and --truth names must be parameters of the spec.
#[test]
fn unwritable_outputs_and_unknown_truth_names_are_refused_up_front() {
    let tmp = tempfile::tempdir().unwrap();
    let log = simulate(
        tmp.path(),
        "cw.csv",
        &[
            "--spec",
            "spec/diff_drive.toml",
            "--trajectory",
            "square-cw",
        ],
    );
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
    let log = simulate(
        tmp.path(),
        "log.csv",
        &[
            "--spec",
            plain.to_str().unwrap(),
            "--trajectory",
            "random",
            "--set",
            "b=0.21",
        ],
    );
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
    let log = simulate(
        tmp.path(),
        "cw.csv",
        &["--spec", spec, "--trajectory", "random", "--set", "b=0.21"],
    );
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
    let tlog = simulate(
        tmp.path(),
        "trike.csv",
        &["--spec", trike, "--trajectory", "random"],
    );
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
    let log = simulate(
        tmp.path(),
        "run.csv",
        &[
            "--spec",
            spec.to_str().unwrap(),
            "--trajectory",
            "random",
            "--set",
            "b=0.21",
            "--effect",
            "lateral_slip=0.1",
        ],
    );
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
    let log = simulate(
        tmp.path(),
        "cw.csv",
        &["--spec", spec, "--trajectory", "square-cw"],
    );
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

/// Issue 15, seed 000 sec. 3.2 and 4: neural gyrodometry (a tanh MLP trained by
/// LM maps the joint rates to the yaw rate and replaces the gyro) against the
/// calibrated kinematic model, on the omni robot with the nominal parameters
/// of eq. 27 and the truth of eq. 28, scored on a held-out run: the calibrated
/// model beats the 50-unit net, which beats the 9-unit net (the paper's
/// argument for models known a priori over black boxes).
#[test]
fn seed_000_neural_gyrodometry_loses_to_the_calibrated_model() {
    let tmp = tempfile::tempdir().unwrap();
    let log = |seed: &str| seed_000_log(tmp.path(), &format!("omni{seed}.csv"), seed);
    let (a, b, c, held) = (log("3"), log("4"), log("5"), log("11"));
    let report = tmp.path().join("report");
    let doc = kinegen_json(&[
        "fit",
        "--spec",
        "spec/omni_caster.toml",
        "--method",
        "all",
        "--hidden",
        "9",
        "--hidden",
        "50",
        "--data",
        a.to_str().unwrap(),
        "--data",
        b.to_str().unwrap(),
        "--data",
        c.to_str().unwrap(),
        "--holdout",
        held.to_str().unwrap(),
        "--report",
        report.to_str().unwrap(),
    ]);
    let held_out = |m: &str| {
        doc["methods"][m]["holdout"]["rmse"]
            .as_f64()
            .unwrap_or_else(|| panic!("{m}: {}", doc["methods"]))
    };
    let (lm, n50, n9) = (held_out("lm"), held_out("neural-50"), held_out("neural-9"));
    println!("held-out position RMSE: calibrated (lm) {lm:.4} m, neural 50 {n50:.4} m, neural 9 {n9:.4} m, nominal {}", doc["holdout_before"]["rmse"]);
    assert!(
        lm < n50 && n50 < n9,
        "lm {lm}, neural-50 {n50}, neural-9 {n9}"
    );
    let note = doc["methods"]["neural-50"]["note"].as_str().unwrap();
    assert!(
        note.contains("50 hidden units") && note.contains("best on the validation split"),
        "{note}"
    );
    let html = std::fs::read_to_string(report.join("index.html")).unwrap();
    assert!(html.contains("neural-50") && html.contains("neural-9"));
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

/// Issue #11 (done when): across simulated runs of every robot type (squares,
/// figures of eight, free driving, turns in place; one lap and four), a
/// calibration never leaves held-out runs worse than the nominal values
/// without saying why. Each model's free parameters are set 3% off nominal
/// (alternately up and down) in the simulated robot; every fit is scored on a
/// held-out free-driving run. Runs that move like the held-out one must halve
/// its error. A turn in place does not: there, a fit that makes the held-out
/// run worse must say so and name what the fitted runs do not cover (a
/// unicycle's speed scale fitted on a robot that does not drive shrinks to a
/// third: 0.74 m -> 17.6 m held out), and what the runs do not determine
/// stays nominal (before: the speed scale slid to its bound, 0.74 m -> 26 m,
/// with no word about the held-out runs).
#[test]
fn calibration_never_leaves_held_out_runs_worse_than_nominal_without_saying_why() {
    let tmp = tempfile::tempdir().unwrap();
    let specs = [
        "spec/diff_drive.toml",
        "spec/tricycle.toml",
        "spec/tricycle_fwd.toml",
        "spec/omni3.toml",
        "spec/unicycle_ekf.toml",
        "spec/omni_caster.toml",
        "tests/user_specs/fwd_tricycle.toml",
        "tests/user_specs/mecanum4.toml",
        "tests/user_specs/offset_diff.toml",
        "tests/user_specs/skid4.toml",
    ];
    let (mut worse, mut cases) = (Vec::new(), 0);
    for spec in specs {
        let path = root().join(spec);
        let model = kinegen_model::spec::Model::load(&path).unwrap();
        let name = model.name.clone();
        let mut truth = Vec::new();
        for (k, p) in model
            .params
            .iter()
            .filter(|p| p.free && !p.constant && p.nominal != 0.0)
            .enumerate()
        {
            let f = if k % 2 == 0 { 1.03 } else { 0.97 };
            truth.push(format!("{}={}", p.name, p.nominal * f));
        }
        let spec = path.to_str().unwrap();
        let sim = |file: &str, traj: &str, laps: &str, seed: &str| {
            let mut a = vec![
                "--spec",
                spec,
                "--trajectory",
                traj,
                "--laps",
                laps,
                "--seed",
                seed,
            ];
            for s in &truth {
                a.extend(["--set", s.as_str()]);
            }
            simulate(tmp.path(), &format!("{name}-{file}"), &a)
        };
        let hold = sim("held.csv", "random", "2", "99");
        for (traj, laps) in [
            ("square", "1"),
            ("figure8", "4"),
            ("random", "1"),
            ("spin", "1"),
            ("spin", "4"),
        ] {
            let log = sim(&format!("{traj}-{laps}.csv"), traj, laps, "3");
            let doc = kinegen_json(&[
                "fit",
                "--spec",
                spec,
                "--data",
                log.to_str().unwrap(),
                "--holdout",
                hold.to_str().unwrap(),
            ]);
            cases += 1;
            let (before, after) = (
                doc["holdout"]["before"]["rmse"].as_f64().unwrap(),
                doc["holdout"]["after"]["rmse"].as_f64().unwrap(),
            );
            let case = format!("{name} {traj} x{laps}: held out {before:.4} m -> {after:.4} m");
            if traj != "spin" {
                assert!(after < 0.5 * before, "{case}");
            }
            let said = doc["warnings"].as_array().unwrap().iter().any(|w| {
                let w = w.as_str().unwrap();
                w.contains("worse than the nominal parameters on the held-out runs")
                    && (w.contains("do not cover") || w.contains("do not determine"))
            });
            assert_eq!(after > 1.001 * before, said, "{case}: {}", doc["warnings"]);
            if said {
                worse.push(case);
            }
        }
    }
    eprintln!(
        "{} of {cases} calibrations left the held-out run worse, each with its reason: {worse:#?}",
        worse.len()
    );
    // the turns in place are the cases that show the warning works (every
    // other trajectory halves the held-out error, asserted above). The
    // unicycle's logged commands are what it executes (they hold between
    // rows, issue 34), so turning in place its speed command is exactly 0 and
    // its speed scale stays nominal, undetermined; the 12-parameter
    // omni_caster turning in place for four laps is the case left worse, and
    // says why.
    assert!(
        !worse.is_empty() && worse.iter().all(|c| c.contains(" spin x")),
        "{worse:?}"
    );
    let expected = [
        "unicycle_ekf spin x4",
        "omni_caster spin x1",
        "omni_caster spin x4",
    ];
    for c in &worse {
        assert!(expected.iter().any(|e| c.starts_with(e)), "{c}");
    }
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
    let log = simulate(
        tmp.path(),
        "long.csv",
        &[
            "--spec",
            "spec/diff_drive.toml",
            "--trajectory",
            "random",
            "--laps",
            "110",
            "--seed",
            "4",
            "--set",
            "b=0.204",
        ],
    );
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

/// Issue #11 item 3: a fit that needs an implausible model is named unusable.
/// A tricycle (seed 001 eq. 14) whose steering encoder reads 0.1 rad high,
/// fitted with the spec as it is: the best the model can do on 60 s
/// re-anchored segments is a 2 km wheelbase, a robot that travels as far as
/// the measured one but (almost) never turns. Its whole-track error falls (what the
/// report used to show as a success); it must say the model turns 0 rad
/// against the measured tens, that the gyro residual grew, that the wheelbase
/// is thousands of times its drawing, and exit 1.
#[test]
fn a_calibration_that_stops_turning_is_unusable() {
    let tmp = tempfile::tempdir().unwrap();
    let clean = simulate(
        tmp.path(),
        "clean.csv",
        &[
            "--spec",
            "spec/tricycle.toml",
            "--trajectory",
            "random",
            "--seed",
            "4001",
            "--laps",
            "2",
        ],
    );
    let text = std::fs::read_to_string(&clean).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let alpha = header.iter().position(|h| *h == "alpha").unwrap();
    let mut shifted = header.join(",") + "\n";
    for line in lines {
        let mut v: Vec<String> = line.split(',').map(str::to_string).collect();
        v[alpha] = (v[alpha].parse::<f64>().unwrap() + 0.1).to_string();
        shifted += &(v.join(",") + "\n");
    }
    let log = tmp.path().join("steer_high.csv");
    std::fs::write(&log, shifted).unwrap();
    let (o, doc) = run_to_json(
        tmp.path(),
        "fit",
        &[
            "fit",
            "--spec",
            "spec/tricycle.toml",
            "--data",
            log.to_str().unwrap(),
        ],
    );
    assert_eq!(o.status.code(), Some(1), "{}", stdout(&o));
    let unusable = doc["unusable"].to_string();
    // (the segments' optimum turns 0.0 rad; refined on the whole run, 2.1)
    assert!(
        unusable.contains("rad in all while the measurements turn 21.2 rad"),
        "{unusable}"
    );
    assert!(unusable.contains("fits the gyro worse"), "{unusable}");
    let warnings = doc["warnings"].to_string();
    assert!(warnings.contains("times its nominal value"), "{warnings}");
    assert!(stdout(&o).contains("kinegen diagnose"), "{}", stdout(&o));
}

/// Issue #11 item 3, a fit that still turns: a user-written rover
/// (`tests/user_specs/rover.toml`) whose log hides a 0.1 rad steering offset,
/// fitted with the spec as it is. The model keeps moving and turning and its
/// whole-track error falls (26.0 -> 23.2 m), but the wheel radius is fitted
/// 44% short and the drift over 5 s windows triples: unusable, exit 1.
#[test]
fn a_calibration_that_triples_the_short_term_drift_is_unusable() {
    let tmp = tempfile::tempdir().unwrap();
    let log = simulate(
        tmp.path(),
        "rover.csv",
        &[
            "--spec",
            "tests/user_specs/rover.toml",
            "--trajectory",
            "random",
            "--laps",
            "3",
            "--seed",
            "11",
            "--effect",
            "steering_offset=0.1",
        ],
    );
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
}

/// Issue #35.2: a clean long log (364 s at 20 Hz, quantised encoders, white
/// motion-capture noise, simulated with exactly the nominal values) is not
/// made worse by calibration: over 20 seeds the whole-run position RMSE
/// after the fit stays within 5% of the nominal values' (the fit ends on
/// the whole runs), every estimate lies within 2 reported standard
/// deviations of the truth, their mean within half a standard deviation of
/// it, and the reported standard deviations match the spread of the
/// estimates over the seeds within 30% (a sandwich over the track's drift).
/// The re-anchored segments alone (what the fit used to report) fail the
/// first check on seed 2: 0.0015 m -> 0.0030 m, estimates 8 standard
/// deviations off.
///
/// Measured over these seeds: after/before at most 0.997; the largest error
/// of an estimate 1.8 standard deviations, their mean 0.3; spread / mean
/// std 0.91 (r_r, r_l) and 1.02 (b). Dead reckoning that held each step's
/// mean wheel rates (no `deadreckon::swing_offset`) put the mean 1.2-1.3
/// standard deviations short, 17 estimates of 60 beyond 2 and one at 6: the
/// simulated wheels, like real ones, speed up and slow down within a step.
#[test]
fn a_clean_long_log_keeps_its_whole_run_error_and_honest_standard_deviations() {
    let tmp = tempfile::tempdir().unwrap();
    let spec = "spec/diff_drive.toml";
    let names = ["r_r", "r_l", "b"];
    let nominal = [0.042, 0.042, 0.2];
    let (mut est, mut std) = (vec![vec![]; 3], vec![vec![]; 3]);
    for seed in 1..=20 {
        let s = seed.to_string();
        let log = simulate(
            tmp.path(),
            &format!("c{seed}.csv"),
            &[
                "--spec",
                spec,
                "--trajectory",
                "random",
                "--laps",
                "4",
                "--seed",
                &s,
            ],
        );
        let log = log.to_str().unwrap();
        let doc = kinegen_json(&["fit", "--spec", spec, "--data", log]);
        let (before, after) = (
            doc["before"]["rmse"].as_f64().unwrap(),
            doc["after"]["rmse"].as_f64().unwrap(),
        );
        assert!(
            after <= 1.05 * before,
            "seed {seed}: whole-run RMSE {before} -> {after}"
        );
        for (k, n) in names.iter().enumerate() {
            let (e, sd) = (
                doc["parameters"][n]["estimate"].as_f64().unwrap(),
                doc["parameters"][n]["std"].as_f64().unwrap(),
            );
            assert!(
                (e - nominal[k]).abs() <= 2.0 * sd,
                "seed {seed}: {n} {e} ± {sd} (truth {})",
                nominal[k]
            );
            est[k].push(e);
            std[k].push(sd);
        }
        if seed == 2 {
            let seg = kinegen_json(&[
                "fit",
                "--spec",
                spec,
                "--data",
                log,
                "--likelihood",
                "segments",
            ]);
            let grown =
                seg["after"]["rmse"].as_f64().unwrap() / seg["before"]["rmse"].as_f64().unwrap();
            assert!(
                grown > 1.05,
                "the segments alone no longer degrade this log ({grown:.2})"
            );
        }
    }
    for (k, n) in names.iter().enumerate() {
        let spread = spread_of(&est[k]);
        let ratio = spread / mean(&std[k]);
        assert!(
            (0.7..=1.3).contains(&ratio),
            "{n}: spread {spread:.3e}, mean std {:.3e} ({ratio:.2})",
            mean(&std[k])
        );
        let bias = (mean(&est[k]) - nominal[k]) / mean(&std[k]);
        assert!(
            bias.abs() < 0.5,
            "{n}: the estimates' mean is {bias:.2} standard deviations off"
        );
    }
}

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len() as f64
}

/// Sample standard deviation.
fn spread_of(v: &[f64]) -> f64 {
    let m = mean(v);
    (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (v.len() - 1) as f64).sqrt()
}

/// A diff drive with a right wheel of 0.0505 m (nominal 0.042) driving at
/// random (seed 11), simulated into `dir/log.csv`.
fn wide_right_wheel_log(dir: &std::path::Path) -> std::path::PathBuf {
    simulate(
        dir,
        "log.csv",
        &[
            "--spec",
            "spec/diff_drive.toml",
            "--set",
            "r_r=0.0505",
            "--trajectory",
            "random",
            "--seed",
            "11",
        ],
    )
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

/// A robot calibrated on runs that turn one way is warned: a scale and an
/// offset of the turn rate trade off there (UMBmark drives both ways). A
/// circle driven counter-clockwise says so; the same circle with one driven
/// clockwise too does not. On the real tricycle: one clockwise circle is
/// warned, the session's two circles are not.
#[test]
fn runs_that_turn_one_way_are_warned() {
    let tmp = tempfile::tempdir().unwrap();
    let spec = tmp.path().join("wheels.toml");
    std::fs::write(
        &spec,
        r#"name = "wheels"
state = ["x", "y", "theta"]
[[input]]
name = "wr"
column = "phi_r"
kind = "cumulative"
[[input]]
name = "wl"
column = "phi_l"
kind = "cumulative"
[[parameter]]
name = "r_r"
nominal = 0.05
min = 0.0
[[parameter]]
name = "r_l"
nominal = 0.05
min = 0.0
[[parameter]]
name = "b"
nominal = 0.3
min = 0.0
[motion]
vx = "(r_r*wr + r_l*wl)/2"
vy = "0"
omega = "(r_r*wr - r_l*wl)/b"
"#,
    )
    .unwrap();
    // a circle at constant wheel rates, exactly integrated, one way or the other
    let circle = |name: &str, sign: f64| {
        let (wr, wl) = if sign > 0.0 { (10.0, 8.0) } else { (8.0, 10.0) };
        let (v, w) = (0.05 * (wr + wl) / 2.0, 0.05 * (wr - wl) / 0.3);
        let mut s = String::from("t,phi_r,phi_l,gt_x,gt_y,gt_theta\n");
        for k in 0..=600 {
            let t = 0.05 * k as f64;
            let th = w * t;
            let (x, y) = (v / w * th.sin(), v / w * (1.0 - th.cos()));
            let wrapped = (th + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU)
                - std::f64::consts::PI;
            s += &format!("{t:.2},{},{},{x:.6},{y:.6},{wrapped:.6}\n", wr * t, wl * t);
        }
        let path = tmp.path().join(name);
        std::fs::write(&path, s).unwrap();
        path
    };
    let (ccw, cw) = (circle("ccw.csv", 1.0), circle("cw.csv", -1.0));
    let fit = |logs: &[&std::path::Path]| {
        let mut args = vec!["fit", "--spec", spec.to_str().unwrap()];
        for l in logs {
            args.extend(["--data", l.to_str().unwrap()]);
        }
        kinegen_json(&args)["warnings"].to_string()
    };
    let one = fit(&[&ccw]);
    assert!(
        one.contains("turn one way") && one.contains("counter-clockwise"),
        "{one}"
    );
    let both = fit(&[&ccw, &cw]);
    assert!(!both.contains("turn one way"), "{both}");
    let Some(dir) = real_data("optiodom-dev") else {
        return;
    };
    let session = dir.join("tricyc-circular-140120211440");
    let tricycle = root().join("spec/benchmarks/optiodom/tricycle.toml");
    let real = |runs: &[&str]| {
        let mut args = vec![
            "fit".to_string(),
            "--spec".into(),
            tricycle.display().to_string(),
        ];
        for r in runs {
            args.extend(["--data".into(), session.join(r).display().to_string()]);
        }
        let a: Vec<&str> = args.iter().map(String::as_str).collect();
        kinegen_json(&a)["warnings"].to_string()
    };
    assert!(real(&["run-01.csv"]).contains("turn one way"));
    assert!(!real(&["run-01.csv", "run-02.csv"]).contains("turn one way"));
}

/// A simulator written here, not kinegen's, for clean logs as a user's own
/// simulator would make them (issue #35.2 as its reporter made it): wheel
/// speeds and steering that wander smoothly, the pose integrated in exact
/// arcs at 1 kHz, sampled at 50 Hz, motion capture with 1 mm and 2 mrad of
/// white noise.
mod elsewhere {
    use rand::{rngs::SmallRng, Rng, SeedableRng};
    use rand_distr::{Distribution, Normal};
    use std::f64::consts::TAU;

    /// A smooth random signal: a base drawn from `base` (none: 0) plus four
    /// sines of random frequency (drawn from `hz`), phase and amplitude
    /// (drawn from `amplitude`), one draw per run.
    fn wander(
        rng: &mut SmallRng,
        base: Option<(f64, f64)>,
        (amplitude, hz): ((f64, f64), (f64, f64)),
    ) -> impl Fn(f64) -> f64 {
        let base = base.map_or(0.0, |(lo, hi)| rng.gen_range(lo..hi));
        let parts: Vec<[f64; 3]> = (0..4)
            .map(|_| {
                let f = rng.gen_range(hz.0..hz.1);
                [
                    f,
                    rng.gen_range(0.0..TAU),
                    rng.gen_range(amplitude.0..amplitude.1),
                ]
            })
            .collect();
        move |t: f64| {
            base + (parts.iter())
                .map(|[f, ph, a]| a * (TAU * f * t + ph).sin())
                .sum::<f64>()
        }
    }

    /// Drive `seconds` at 50 Hz from the origin: `step(wheels, t, dt)` moves
    /// the wheel angles `wheels` over a millisecond and gives the body's (v,
    /// omega) then; `row(wheels, t)` the logged inputs, as text. Writes
    /// `header` and one row every 20 ms.
    fn drive(
        path: &std::path::Path,
        (rng, header, seconds): (&mut SmallRng, &str, usize),
        mut step: impl FnMut(&mut [f64; 2], f64, f64) -> (f64, f64),
        row: impl Fn(&[f64; 2], f64) -> String,
    ) {
        let (pos, head) = (
            Normal::new(0.0, 0.001).unwrap(),
            Normal::new(0.0, 0.002).unwrap(),
        );
        let (mut x, mut y, mut th, mut t) = (0.0f64, 0.0f64, 0.0f64, 0.0);
        let mut wheels = [0.0; 2];
        let dt = 0.001;
        let mut text = format!("{header},gt_x,gt_y,gt_theta\n");
        for _ in 0..=seconds * 50 {
            text += &format!(
                "{},{:.6},{:.6},{:.6}\n",
                row(&wheels, t),
                x + pos.sample(rng),
                y + pos.sample(rng),
                th + head.sample(rng)
            );
            for _ in 0..20 {
                let (v, w) = step(&mut wheels, t, dt);
                x += v / w * ((th + w * dt).sin() - th.sin());
                y -= v / w * ((th + w * dt).cos() - th.cos());
                (th, t) = (th + w * dt, t + dt);
            }
        }
        std::fs::write(path, text).unwrap();
    }

    /// spec/diff_drive.toml at its nominal values for `seconds`, the
    /// encoders' cumulative counts floored to whole counts.
    pub fn diff_drive(path: &std::path::Path, seed: u64, seconds: usize) {
        let mut rng = SmallRng::seed_from_u64(seed);
        let (r, b, counts_per_rev) = (0.042, 0.2, 64.0 * 43.7);
        let right = wander(&mut rng, Some((3.0, 6.0)), ((1.0, 4.0), (0.02, 0.2)));
        let left = wander(&mut rng, Some((3.0, 6.0)), ((1.0, 4.0), (0.02, 0.2)));
        let count = |a: f64| (a / TAU * counts_per_rev).floor();
        drive(
            path,
            (&mut rng, "t,enc_r,enc_l", seconds),
            |wheels, t, dt| {
                let (wr, wl) = (right(t), left(t));
                (wheels[0], wheels[1]) = (wheels[0] + wr * dt, wheels[1] + wl * dt);
                (r * (wr + wl) / 2.0, r * (wr - wl) / b)
            },
            |wheels, t| format!("{t:.4},{},{}", count(wheels[0]), count(wheels[1])),
        );
    }

    /// spec/benchmarks/optiodom/tricycle.toml at its nominal values for 200 s, the
    /// drive wheel's angle floored to a 2048-count encoder, the steering
    /// rounded to a `steering_steps`-step encoder.
    pub fn tricycle(path: &std::path::Path, seed: u64, steering_steps: f64) {
        let mut rng = SmallRng::seed_from_u64(seed);
        let (r, l) = (0.0325, 0.15);
        let wheel = wander(&mut rng, Some((4.0, 8.0)), ((0.5, 2.0), (0.02, 0.2)));
        // a steering that swings at most 0.1 Hz (see the rounding test)
        let steer = wander(&mut rng, None, ((0.1, 0.3), (0.01, 0.1)));
        let q = TAU / steering_steps;
        drive(
            path,
            (&mut rng, "t,phi,alpha", 200),
            |wheels, t, dt| {
                let (w, a) = (wheel(t), steer(t));
                wheels[0] += w * dt;
                (r * w * a.cos(), r * w * a.sin() / l)
            },
            |wheels, t| {
                let phi = (wheels[0] / TAU * 2048.0).floor() * TAU / 2048.0;
                format!("{t:.4},{phi:.9},{:.9}", (steer(t) / q).round() * q)
            },
        );
    }
}

/// Issue #35.2 on logs kinegen did not simulate: the clean 200 s logs of
/// [`elsewhere::diff_drive`] keep their whole-run RMSE within 5% of the
/// nominal values' and every estimate within 2 reported standard deviations
/// of the truth. Fit used to keep the whole-run refinement only where the
/// re-anchored segments' cost stayed within 10% of theirs at their own
/// optimum; on these information-rich logs the whole-run estimate often
/// cost more there, and the segments' estimate made the whole-run error
/// worse than the nominal values' on 4 seeds of 40 (x1.10-2.01; seeds 15,
/// 16, 19 and 40). It is now also kept where its 5 s drift is no worse:
/// over the 40 seeds the error after the fit is 0.50-0.997 of the nominal
/// values', every estimate within 1.6 standard deviations. The seeds here
/// hold three of the four.
#[test]
fn clean_logs_from_another_simulator_keep_their_whole_run_error() {
    let tmp = tempfile::tempdir().unwrap();
    let truth = [("r_r", 0.042), ("r_l", 0.042), ("b", 0.2)];
    for seed in 13..=20 {
        let log = tmp.path().join(format!("clean{seed}.csv"));
        elsewhere::diff_drive(&log, seed, 200);
        let (doc, before, after) = fit_whole_run("spec/diff_drive.toml", &log);
        assert!(
            after <= 1.05 * before,
            "seed {seed}: whole-run RMSE {before} -> {after}"
        );
        for (name, value) in truth {
            let p = &doc["parameters"][name];
            let (e, sd) = (p["estimate"].as_f64().unwrap(), p["std"].as_f64().unwrap());
            assert!(
                (e - value).abs() <= 2.0 * sd,
                "seed {seed}: {name} {e} ± {sd} (truth {value})"
            );
        }
    }
}

/// Issue #35.2 with an angle read by an encoder: clean tricycle logs from
/// [`elsewhere::tricycle`], the steering rounded to an 11-bit encoder (3.1
/// mrad). Over 30 seeds, each parameter's reported standard deviation
/// matches the spread of its estimates within 30%. The steering's rounding
/// is an error in every row that the track integrates; too small to stand
/// out in the residuals, it is counted from the log's own resolution
/// (`fit/rounding.rs`). Measured: spread / std 0.78 (r), 0.80 (L), 1.02
/// (steer_offset), the worst estimate 2.25 std off; without it the steering
/// offset's spread was 2.21x its reported standard deviation, one estimate
/// 10.4 std off. Left: with a 10-bit encoder r and L come out 0.63-0.69
/// (too cautious); with a 12-bit one, or none, the offset 1.37 (an error
/// the rounding does not explain).
#[test]
fn a_rounded_steering_angle_is_counted_in_the_standard_deviations() {
    let tmp = tempfile::tempdir().unwrap();
    let names = ["r", "L", "steer_offset"];
    let truth = [0.0325, 0.15, 0.0];
    let (mut est, mut std) = (vec![vec![]; 3], vec![vec![]; 3]);
    for seed in 1..=30 {
        let log = tmp.path().join(format!("tricycle{seed}.csv"));
        elsewhere::tricycle(&log, seed, 2048.0);
        let doc = kinegen_json(&[
            "fit",
            "--spec",
            "spec/benchmarks/optiodom/tricycle.toml",
            "--data",
            log.to_str().unwrap(),
        ]);
        push_estimates(&doc, &names, &mut est, &mut std);
    }
    assert_honest_spread(&names, &truth, &est, &std);
}

/// Issue #35.2's standard deviations on long logs from a simulator other
/// than kinegen's: 30 clean 600 s logs at 50 Hz ([`elsewhere::diff_drive`],
/// quantised encoders). Each parameter's reported standard deviation
/// matches the spread of its estimates over the seeds within 30%, their mean
/// lies within half a standard deviation of the truth, and no fit leaves the
/// whole-run error above the nominal values'.
#[test]
fn long_clean_logs_from_another_simulator_get_honest_standard_deviations() {
    let tmp = tempfile::tempdir().unwrap();
    let names = ["r_r", "r_l", "b"];
    let truth = [0.042, 0.042, 0.2];
    let (mut est, mut std) = (vec![vec![]; 3], vec![vec![]; 3]);
    for seed in 101..=130 {
        let log = tmp.path().join(format!("long{seed}.csv"));
        elsewhere::diff_drive(&log, seed, 600);
        let (doc, before, after) = fit_whole_run("spec/diff_drive.toml", &log);
        assert!(
            after <= before,
            "seed {seed}: whole-run RMSE {before} -> {after}"
        );
        push_estimates(&doc, &names, &mut est, &mut std);
    }
    assert_honest_spread(&names, &truth, &est, &std);
}

/// Append each parameter of `names` that the fit document `doc` gives to
/// its list of estimates `est` and of standard deviations `std`.
fn push_estimates(
    doc: &serde_json::Value,
    names: &[&str],
    est: &mut [Vec<f64>],
    std: &mut [Vec<f64>],
) {
    for (k, n) in names.iter().enumerate() {
        est[k].push(doc["parameters"][n]["estimate"].as_f64().unwrap());
        std[k].push(doc["parameters"][n]["std"].as_f64().unwrap());
    }
}

/// Each parameter's reported standard deviations (`std`, per parameter and
/// seed) match the spread of its estimates `est` over the seeds within 30%,
/// and their mean lies within half a standard deviation of `truth`.
fn assert_honest_spread(names: &[&str], truth: &[f64], est: &[Vec<f64>], std: &[Vec<f64>]) {
    for (k, n) in names.iter().enumerate() {
        let ratio = spread_of(&est[k]) / mean(&std[k]);
        let bias = (mean(&est[k]) - truth[k]) / mean(&std[k]);
        let worst = (est[k].iter().zip(&std[k]))
            .map(|(e, s)| ((e - truth[k]) / s).abs())
            .fold(0.0, f64::max);
        eprintln!("{n}: spread / std {ratio:.2}, bias {bias:.2} std, worst {worst:.2} std");
        assert!(
            (0.7..=1.3).contains(&ratio),
            "{n}: spread {:.3e}, mean std {:.3e} ({ratio:.2})",
            spread_of(&est[k]),
            mean(&std[k])
        );
        assert!(
            bias.abs() < 0.5,
            "{n}: the estimates' mean is {bias:.2} std off"
        );
    }
}

/// `fit` of `log` with `spec`: its JSON, and the whole-run position RMSE
/// before and after.
fn fit_whole_run(spec: &str, log: &std::path::Path) -> (serde_json::Value, f64, f64) {
    let doc = kinegen_json(&["fit", "--spec", spec, "--data", log.to_str().unwrap()]);
    let before = doc["before"]["rmse"].as_f64().unwrap();
    let after = doc["after"]["rmse"].as_f64().unwrap();
    (doc, before, after)
}
