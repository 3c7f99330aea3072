//! Issue #34: real robots as they come, through the command line. Velocity
//! commands logged at irregular times hold between rows; a log is split
//! only at gaps over --max-gap; a spec a user writes without `[inverse]`
//! runs every analysis. On the five real robots of
//! `../shared/real/mrclam-dataset6/` every command runs on the logs as they
//! are, with default options, and prints a text read at a glance. The
//! simulated commanded robot's timing effects and filter are asserted on
//! the library's values in analysis/tests/results/commanded.rs.
mod common;
use common::*;
use serde_json::Value;
use std::path::{Path, PathBuf};

/// `kinegen args --json -` in `dir`: its document, its default text checked
/// to read at a glance (the real robots' runs are output_shape's MRCLAM
/// cases too: each long run is made once).
fn run_in(dir: &Path, args: &[&str]) -> serde_json::Value {
    kinegen_json_glanceable(dir, args)
}

/// A model that stops being numbers in the second piece of a log split at a
/// gap is refused at the line of the file where it happens, not at the
/// line counted from the piece's start (line 5 of the piece was line 11).
#[test]
fn a_refusal_in_a_later_piece_names_the_files_line() {
    let tmp = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(commanded_spec(tmp.path(), "")).unwrap();
    let spec = tmp.path().join("divides.toml");
    std::fs::write(
        &spec,
        text.replace(
            "vx = \"k_v*v_cmd + dv\"",
            "vx = \"k_v*v_cmd/(w_cmd - 0.5) + dv\"",
        ),
    )
    .unwrap();
    // rows 0-5 at 10 Hz, a 10 s gap, rows 6-11; row 8 (line 10) commands the
    // turn rate the model divides by zero at
    let mut log = String::from("t,v,omega\n");
    for k in 0..12 {
        let t = 0.1 * k as f64 + if k >= 6 { 10.0 } else { 0.0 };
        let w = if k == 8 { 0.5 } else { 0.1 };
        log += &format!("{t:.1},0.2,{w}\n");
    }
    let path = tmp.path().join("log.csv");
    std::fs::write(&path, log).unwrap();
    let o = kinegen(&[
        "compare",
        "--spec",
        spec.to_str().unwrap(),
        "--data",
        path.to_str().unwrap(),
    ]);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(
        err.contains("log.csv (10.60-11.10 s):11: the model's predicted pose is not finite"),
        "{err}"
    );
}

/// Commands hold from their row until the next: a command of 1 m/s logged at
/// t = 0 and replaced at t = 1 s moves the robot 1 m (the mean of the two
/// rows would say 0.5 m). A gap of 1 s is bridged; with --max-gap 0.5 the log
/// is split there, and the warning says what the split costs.
#[test]
fn commands_hold_between_rows_and_short_gaps_are_bridged() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let spec = commanded_spec(dir, "m/s/sqrt(Hz)");
    // straight at 1 m/s from t = 0 to 1, then at 0.5 m/s from 1 to 3 with rows
    // 0.02-0.05 s apart, a 1 s gap, and a stop
    let mut s = String::from("t,v,omega,gt_x,gt_y,gt_theta\n");
    s += "0.0,1.0,0,0,0,0\n";
    let mut t = 1.0;
    let mut x = 1.0;
    let mut k = 0;
    while t < 3.0 {
        s += &format!("{t:.3},0.5,0,{x:.6},0,0\n");
        let dt = if k == 20 {
            1.0
        } else {
            [0.02, 0.05, 0.03][k % 3]
        };
        t += dt;
        x += 0.5 * dt;
        k += 1;
    }
    s += &format!("{t:.3},0,0,{x:.6},0,0\n");
    s += &format!("{:.3},0,0,{x:.6},0,0\n", t + 0.5);
    std::fs::write(dir.join("held.csv"), s).unwrap();
    let d = run_in(
        dir,
        &[
            "compare",
            "-v",
            "--spec",
            spec.to_str().unwrap(),
            "--data",
            "held.csv",
        ],
    );
    let rmse = d["rmse"].as_f64().unwrap();
    assert!(rmse < 1e-6, "held commands: position RMSE {rmse}");
    assert_eq!(
        d["runs"].as_array().unwrap().len(),
        1,
        "a 1 s gap is bridged"
    );
    let o = kinegen_in(
        dir,
        &[
            "compare",
            "-v",
            "--spec",
            spec.to_str().unwrap(),
            "--data",
            "held.csv",
            "--max-gap",
            "0.5",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let out = stdout(&o) + &stderr(&o);
    assert!(
        out.contains("longer than --max-gap 0.5 s") && out.contains("not dead-reckoned"),
        "{out}"
    );
    // localize split there (and after the first row, 1 s before the next):
    // the sightings inside the gaps belong to no run, and the warning counts
    // them (they were dropped silently)
    std::fs::write(dir.join("map.csv"), "id,x,y\n7,5,1\n").unwrap();
    let mut obs = String::from("t,id,range,bearing\n");
    // the gaps run from t = 0 to 1 and from 1.67 to 2.67 s
    for ts in [0.5f64, 1.2, 2.0, 2.9] {
        let x = if ts < 1.0 { ts } else { 1.0 + 0.5 * (ts - 1.0) };
        obs += &format!(
            "{ts},7,{},{}\n",
            (5.0 - x).hypot(1.0),
            1.0f64.atan2(5.0 - x)
        );
    }
    std::fs::write(dir.join("obs.csv"), obs).unwrap();
    let o = kinegen_in(
        dir,
        &[
            "localize",
            "--spec",
            spec.to_str().unwrap(),
            "--data",
            "held.csv",
            "--observations",
            "obs.csv",
            "--landmarks",
            "map.csv",
            "--max-gap",
            "0.5",
            // the warning whole (by default its first two lines)
            "-v",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let out = stdout(&o) + &stderr(&o);
    assert!(
        out.contains("and the 2 landmark sighting(s) in them are not used"),
        "{out}"
    );
}

/// A spec whose twist is not linear in any input has no inverse kinematics:
/// generate says so and writes the rest, simulate and compare run, and
/// `inverse` refuses it with the reason (exit 2). A velocity-commanded spec
/// without `[inverse]` gets one derived.
#[test]
fn a_spec_without_inverse_kinematics_runs_everything_that_does_not_need_them() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let specs = dir.join("specs");
    std::fs::create_dir_all(&specs).unwrap();
    let text = std::fs::read_to_string(commanded_spec(dir, "")).unwrap();
    let cubic = text
        .replace("my_create", "cubic_bot")
        .replace("vx = \"k_v*v_cmd + dv\"", "vx = \"k_v*v_cmd^3 + dv\"")
        .replace("omega = \"k_w*w_cmd + dw\"", "omega = \"k_w*w_cmd^3 + dw\"");
    std::fs::write(specs.join("cubic_bot.toml"), &cubic).unwrap();
    let o = kinegen_in(dir, &["generate", "--spec-dir", "specs", "--out", "gen"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("cubic_bot: no inverse kinematics"),
        "{}",
        stderr(&o)
    );
    let src = std::fs::read_to_string(dir.join("gen/src/cubic_bot.rs")).unwrap();
    assert!(src.contains("pub fn step_exact") && !src.contains("pub fn inverse_twist"));
    let spec = specs.join("cubic_bot.toml");
    let s = spec.to_str().unwrap();
    let o = kinegen_in(
        dir,
        &[
            "simulate",
            "--spec",
            s,
            "--trajectory",
            "random",
            "--out",
            "c.csv",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let d = run_in(dir, &["compare", "--spec", s, "--data", "c.csv"]);
    assert!(d["rmse"].as_f64().unwrap() < 0.05, "{}", d["rmse"]);
    std::fs::write(
        dir.join("path.csv"),
        "t,x,y,theta\n0,0,0,0\n1,0.5,0,0\n2,1,0,0\n",
    )
    .unwrap();
    let o = kinegen_in(dir, &["inverse", "--spec", s, "--path", "path.csv"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("has no inverse kinematics") && stderr(&o).contains("not linear"),
        "{}",
        stderr(&o)
    );
    // linear commands: derived, no [inverse] needed
    let linear = commanded_spec(dir, "");
    let o = kinegen_in(
        dir,
        &[
            "inverse",
            "--spec",
            linear.to_str().unwrap(),
            "--path",
            "path.csv",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
}

/// The user's spec for an iRobot Create that logs its commands (the
/// `mrclam-dataset6` format), run from a directory of its own.
fn create_spec(dir: &Path) -> PathBuf {
    commanded_spec(dir, "")
}

/// Issue #34 (done when): on every robot of `mrclam-dataset6`, with a spec a
/// user would write and only the data files as options, compare, fit and
/// diagnose run on the logs as converted (one run each: the gaps of up to
/// 1.4 s are bridged), and localize uses at least 97% of the sightings with
/// a mean NEES between 1 and 6, far below dead reckoning's error, and its
/// smoother lower still; it finds that the camera reads depth.
#[test]
fn real_velocity_commanded_robots_1_to_3_localize_and_calibrate_as_logged() {
    real_robots_localize_and_calibrate(1..=3);
}

#[test]
fn real_velocity_commanded_robots_4_and_5_localize_and_calibrate_as_logged() {
    real_robots_localize_and_calibrate(4..=5);
}

/// localize, compare and fit on MRCLAM's robots: split over tests so that
/// the test runner's threads share them (each robot is a 15-minute log).
fn real_robots_localize_and_calibrate(robots: std::ops::RangeInclusive<usize>) {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let spec = create_spec(dir);
    let s = spec.to_str().unwrap();
    for robot in robots {
        let Some(r) = mrclam_robot(robot) else { return };
        let p = |f: &Path| f.to_str().unwrap().to_string();
        let (log, obs, map) = (p(&r.log), p(&r.observations), p(&r.landmarks));
        let loc = run_in(
            dir,
            &[
                "localize",
                "--spec",
                s,
                "--data",
                &log,
                "--observations",
                &obs,
                "--landmarks",
                &map,
                "--smooth",
            ],
        );
        check_localized(robot, &loc);
        let seen = ["--observations", &obs, "--landmarks", &map];
        let cmp = run_in(
            dir,
            &[&["compare", "--spec", s, "--data", &log], &seen[..]].concat(),
        );
        check_compared(robot, &cmp);
        let fit = run_in(dir, &["fit", "--spec", s, "--data", &log]);
        let k_v = fit["parameters"]["k_v"]["estimate"].as_f64().unwrap();
        // the achieved speed is below the commanded one on this hardware
        assert!(k_v < 1.0 && k_v > 0.8, "robot{robot}: k_v {k_v}");
    }
}

#[test]
fn a_real_velocity_commanded_robot_is_diagnosed_as_logged() {
    let Some(r) = mrclam_robot(1) else { return };
    let tmp = tempfile::tempdir().unwrap();
    let spec = create_spec(tmp.path());
    let diag = diagnose_seen(&spec, &r.log, &r.observations, &r.landmarks);
    check_diagnosed_robot1(&diag);
}

/// localize's figures on one MRCLAM robot: the done-when bounds, the
/// camera's depth reading found, and the consistency verdicts read as a
/// whole.
fn check_localized(robot: usize, loc: &Value) {
    let r = &loc["runs"][0];
    let f = |k: &str| r[k].as_f64().unwrap();
    let (used, rejected) = (f("observations_used"), f("observations_rejected"));
    let share = used / (used + rejected);
    let (rmse, dead, nees) = (
        f("position_rmse_m"),
        f("dead_reckoning_rmse_m"),
        f("nees_mean"),
    );
    let smoothed = r["smoothed"]["position_rmse_m"].as_f64().unwrap();
    eprintln!(
        "robot{robot}: used {:.1}%, RMSE {rmse:.3} m (smoothed {smoothed:.3}, dead reckoning {dead:.2}), NEES {nees:.2}",
        100.0 * share
    );
    assert!(
        share >= 0.97,
        "robot{robot}: {:.1}% of the sightings used",
        100.0 * share
    );
    assert!(
        (1.0..=6.0).contains(&nees),
        "robot{robot}: mean NEES {nees}"
    );
    assert!(
        rmse < 0.2 * dead,
        "robot{robot}: EKF {rmse} m, dead reckoning {dead} m"
    );
    assert!(
        smoothed < rmse,
        "robot{robot}: smoothed {smoothed} m, filter {rmse} m"
    );
    assert!(loc["noise"]["process"]["dv"]["sigma"].as_f64().unwrap() > 0.0);
    // the camera reads depth, not range (fit, from the ground truth: a
    // share of depth of 0.77-0.98, read 1.8-5.1% long): the filter finds
    // it from the sightings alone (where the likelihood leaves out the
    // change of variables, it takes the ranges as 29-50% long)
    let reading = &loc["noise"]["range_reading"];
    let read = |k: &str| reading[k].as_f64().unwrap_or(f64::NAN);
    assert!(
        (0.7..=1.1).contains(&read("range_depth")) && (-0.02..=0.08).contains(&read("depth_scale")),
        "robot{robot}: {reading}"
    );
    // means that contradict each other are read through the medians and
    // tails, never left as two opposite verdicts
    let side = |m: &str, b: &str| {
        let (m, b) = (f(m), &r[b]);
        (m > b[1].as_f64().unwrap()) as i8 - (m < b[0].as_f64().unwrap()) as i8
    };
    if side("nis_mean", "nis_bounds") * side("nees_mean", "nees_bounds") < 0 {
        assert_ne!(r["consistency"], "agree", "robot{robot}: {r}");
    }
    // the gate rejects 1.0-2.3% of these sightings, 10-23 times a
    // consistent filter's 0.1%: the NIS's own tail is overconfident, which
    // its mean over the sightings let through does not count
    let tail = &r["gate_tail"];
    assert_eq!(tail["overconfident"], true, "robot{robot}: {tail}");
    assert!(
        (tail["consistent_share"].as_f64().unwrap() - 0.001).abs() < 1e-4,
        "robot{robot}: {tail}"
    );
    // an overconfident NEES is taken apart: the belief that is wrong is
    // named (on these robots the position; the heading alone is at or
    // below its bounds, as the NIS is)
    if side("nees_mean", "nees_bounds") > 0 {
        let parts = &r["nees_parts"];
        assert!(
            parts["overconfident"].as_str().is_some(),
            "robot{robot}: {parts}"
        );
    }
    assert!(
        r["nees_spread"]["beyond_95"].as_f64().unwrap() < 0.3,
        "robot{robot}: {r}"
    );
}

/// compare on one MRCLAM robot: one run, and the sightings' own error seen
/// from Vicon.
fn check_compared(robot: usize, cmp: &Value) {
    assert_eq!(
        cmp["runs"].as_array().unwrap().len(),
        1,
        "robot{robot}: split"
    );
    // seen from Vicon, the sightings show the camera's own error (its
    // depth reading and misread barcodes left in: 0.12-0.22 m of range,
    // 0.012-0.096 rad of bearing, most bearings within a robust sd of
    // 6-11 mrad), not the dead-reckoned track's 1.3-2.7 m
    let range = |k: &str| cmp[k]["range_rmse_m"].as_f64().unwrap();
    assert!(
        range("landmarks_from_truth") < 0.3
            && range("landmarks") > 5.0 * range("landmarks_from_truth")
            && cmp["landmarks_from_truth"]["bearing_rmse_rad"]
                .as_f64()
                .unwrap()
                < 0.15
            && cmp["landmarks_from_truth"]["bearing_robust_sd_rad"]
                .as_f64()
                .unwrap()
                < 0.02,
        "robot{robot}: {} {}",
        cmp["landmarks"],
        cmp["landmarks_from_truth"]
    );
}

/// diagnose on MRCLAM robot 1: the late commands proved fold by fold, the
/// exact step, the camera's depth reading.
fn check_diagnosed_robot1(diag: &Value) {
    assert!(diag["verdict"].is_object(), "{diag}");
    // the motion follows the commands some tenths of a second late (the
    // dataset's README: the commands lead the motion): random drift
    // dominates the whole log's error, and the lag is proved fold by fold on
    // short increments. The sightings see the ground truth's pose at their
    // own instant (within a few hundredths of a second), so the lag is the
    // robot's: a late motion capture (which outscores it by BIC on the
    // poses alone) is ruled out, and the command-side rival is named beside it
    let (first, delay) = lag_proved_fold_by_fold(diag);
    assert!((0.1..0.4).contains(&delay), "{first}");
    assert_ne!(first["effect"], "time_offset", "{}", diag["clock"]);
    assert!(
        diag["clock"]["lag"].as_f64().unwrap().abs() < 0.1,
        "{}",
        diag["clock"]
    );
    let time_offset = diag["candidates"]
        .as_array()
        .unwrap()
        .iter()
        .find(|c| c["effect"] == "time_offset")
        .unwrap();
    assert_eq!(
        time_offset["clock"]["verdict"], "contradicted",
        "{time_offset}"
    );
    assert!(
        !first["equivalent"].as_array().unwrap().is_empty(),
        "{first}"
    );
    // held commands make the twist constant over each step: the step is
    // exact (halving the log, as for counters, said the model's own step
    // erred by 1.9x the noise floor here: an error it does not have)
    assert_eq!(
        diag["discretisation"]["error"], 0.0,
        "{}",
        diag["discretisation"]
    );
    // the camera reads depth, not range (its range error, seen from Vicon,
    // falls with the bearing): named after the lag, from the sightings
    let camera = diag["verdict"]["effects"]
        .as_array()
        .unwrap()
        .iter()
        .find(|e| e["effect"] == "range_as_depth")
        .unwrap_or_else(|| panic!("{}", diag["verdict"]));
    let share = camera["parameters"]["range_depth"]["estimate"].as_f64();
    assert!((0.7..1.1).contains(&share.unwrap()), "{camera}");
    let range = &camera["sightings"];
    let (before, after) = (
        range["range_before"].as_f64(),
        range["range_after"].as_f64(),
    );
    assert!(after.unwrap() < 0.5 * before.unwrap(), "{range}");
    // a command is no steering encoder: no steering offset is offered for it
    let tested: Vec<&str> = diag["candidates"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c["effect"].as_str().unwrap())
        .collect();
    assert!(!tested.contains(&"steering_offset"), "{tested:?}");
}

/// The random trip the sighting tests drive.
const TRIP: [&str; 6] = ["--trajectory", "random", "--laps", "3", "--seed", "4"];

/// The commanded spec and a map of landmarks along its [`TRIP`].
fn commanded_among_landmarks(dir: &Path) -> (PathBuf, PathBuf) {
    let spec = commanded_spec(dir, "");
    let s = spec.to_str().unwrap();
    let track = simulate(dir, "track.csv", &[&["--spec", s][..], &TRIP].concat());
    let map = dir.join("map.csv");
    landmarks_along(&track, &map);
    (spec, map)
}

/// A landmark map with one landmark every 8 m over the area the run `log`
/// covers (and 8 m beyond), every other column offset by 3 m so that no
/// two lines of sight coincide.
fn landmarks_along(log: &Path, map: &Path) {
    // rows of (t, x, y)
    let truth = ground_truth(&std::fs::read_to_string(log).unwrap());
    let (lo, hi) = truth.iter().fold(
        ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]),
        |(lo, hi), p| {
            (
                [lo[0].min(p[1]), lo[1].min(p[2])],
                [hi[0].max(p[1]), hi[1].max(p[2])],
            )
        },
    );
    let mut text = String::from("id,x,y\n");
    let (mut x, mut k) = (lo[0] - 8.0, 0);
    while x <= hi[0] + 8.0 {
        let mut y = lo[1] - 8.0 + if k % 2 == 1 { 3.0 } else { 0.0 };
        while y <= hi[1] + 8.0 {
            text += &format!("L{k}_{y:.0},{x:.1},{y:.1}\n");
            y += 8.0;
        }
        (x, k) = (x + 8.0, k + 1);
    }
    std::fs::write(map, text).unwrap();
}

/// `diagnose` of `log` with its landmark sightings `obs` of the map `map`.
fn diagnose_seen(spec: &Path, log: &Path, obs: &Path, map: &Path) -> serde_json::Value {
    diagnose_seen_with(spec, log, obs, map, &[])
}

/// [`diagnose_seen`] with more options.
fn diagnose_seen_with(
    spec: &Path,
    log: &Path,
    obs: &Path,
    map: &Path,
    more: &[&str],
) -> serde_json::Value {
    let path = |p: &Path| p.to_str().unwrap().to_string();
    let (spec, log, obs, map) = (path(spec), path(log), path(obs), path(map));
    let mut args = vec![
        "diagnose",
        "--spec",
        &spec,
        "--data",
        &log,
        "--observations",
        &obs,
        "--landmarks",
        &map,
    ];
    args.extend(more);
    kinegen_json_glanceable(&root(), &args)
}

/// `from`, a log written as the MRCLAM logs are (`t,v,omega,gt_*`), without
/// its ground truth: its commands alone, in `to`.
fn commands_only(from: &Path, to: &Path) {
    rewrite_lines(from, to, |_, l| {
        l.split(',').take(3).collect::<Vec<_>>().join(",")
    });
}

/// Write `from`'s lines to `to`, each (its index, 0 the header, and text)
/// through `line`.
fn rewrite_lines(from: &Path, to: &Path, line: impl Fn(usize, &str) -> String) {
    let text = std::fs::read_to_string(from).unwrap();
    let out: String = text
        .lines()
        .enumerate()
        .map(|(i, l)| line(i, l) + "\n")
        .collect();
    std::fs::write(to, out).unwrap();
}

/// Issue #34: which clock is late. A late command and a late motion capture
/// move a pose-only log alike, but landmark sightings, stamped on the
/// robot's clock as its commands are, see the ground truth's pose at their
/// own instant only if the motion capture is on time. A commanded robot
/// simulated 0.3 s late: diagnose with its sightings names a late command
/// and rules `time_offset` out (on a pose-only log it outscores the late
/// command by BIC); simulated with its motion capture 0.3 s late instead:
/// `time_offset` is named, confirmed by the sightings, with no late command
/// offered in its place. A spec that declares the delay itself hears the
/// same of its calibrated value; sightings stamped 3 s off time nothing;
/// without the ground truth, the evidence names the sightings' channels.
#[test]
fn landmark_sightings_tell_a_late_motion_capture_from_a_late_command() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let (spec, map) = commanded_among_landmarks(dir);
    let s = spec.to_str().unwrap();
    let trip = TRIP;
    let m = map.to_str().unwrap();
    let files = |effect: &str| {
        (
            dir.join(format!("{effect}.csv")),
            dir.join(format!("obs_{effect}.csv")),
        )
    };
    for (effect, late_clock) in [("input_delay", false), ("time_offset", true)] {
        let (log, obs) = files(effect);
        let hidden = format!("{effect}=0.3");
        let o = obs.to_str().unwrap();
        let sightings = ["--landmarks", m, "--landmark-hz", "1", "--observations", o];
        let args = [&["--spec", s, "--effect", &hidden][..], &trip, &sightings].concat();
        simulate(dir, log.file_name().unwrap().to_str().unwrap(), &args);
        let d = diagnose_seen(&spec, &log, &obs, &map);
        let lag = d["clock"]["lag"].as_f64().unwrap();
        let expected = if late_clock { 0.3 } else { 0.0 };
        assert!((lag - expected).abs() < 0.02, "{effect}: {}", d["clock"]);
        let first = &d["verdict"]["effects"][0];
        let time_offset = d["candidates"]
            .as_array()
            .unwrap()
            .iter()
            .find(|c| c["effect"] == "time_offset")
            .unwrap();
        let ruling = &time_offset["clock"]["verdict"];
        if late_clock {
            assert_eq!(first["effect"], "time_offset", "{}", d["verdict"]);
            assert_eq!(ruling, "confirmed", "{time_offset}");
            assert_eq!(first["equivalent"], serde_json::json!([]), "{first}");
        } else {
            let named = first["effect"].as_str().unwrap();
            let late_command = ["input_delay", "command_lag"].contains(&named);
            assert!(late_command, "{}", d["verdict"]);
            assert_eq!(ruling, "contradicted", "{time_offset}");
            assert!(!time_offset["significant"].as_bool().unwrap());
        }
    }
    // a spec that already declares a measurement delay hears what the
    // sightings say of its calibrated value
    let with_offset = dir.join("with_offset.toml");
    add_effect(&spec, "time_offset", &[], &with_offset);
    for (effect, verdict) in [
        ("input_delay", "contradicted"),
        ("time_offset", "confirmed"),
    ] {
        let (log, obs) = files(effect);
        let report = dir.join(format!("report_{effect}"));
        let more = ["--report", report.to_str().unwrap()];
        let d = diagnose_seen_with(&with_offset, &log, &obs, &map, &more);
        let said = &d["spec_clock"];
        assert_eq!(said["verdict"], verdict, "{effect}: {said}");
        // and the report says it beside the clock
        let page = std::fs::read_to_string(report.join("index.html")).unwrap();
        let tells = match verdict {
            "contradicted" => "which the sightings contradict",
            _ => "as the sightings measure",
        };
        assert!(
            page.contains("measurement delay `time_offset` calibrates to") && page.contains(tells),
            "{effect}: the report does not say what the sightings say of the spec's delay"
        );
    }
    // sightings stamped by a clock 3 s off line up with no shift tried:
    // they time nothing, and diagnose says so rather than ruling
    let (log, obs) = files("input_delay");
    let off = dir.join("obs_off.csv");
    rewrite_lines(&obs, &off, |i, l| match (i, l.split_once(',')) {
        (0, _) | (_, None) => l.to_string(),
        (_, Some((t, rest))) => format!("{},{rest}", t.parse::<f64>().unwrap() + 3.0),
    });
    let d = diagnose_seen(&spec, &log, &off, &map);
    assert!(d["clock"].is_null(), "{}", d["clock"]);
    assert_eq!(d["clock_unmeasured"]["reason"], "no_minimum", "{d}");
    // without motion capture the sightings are all diagnose has: each
    // candidate's evidence names the sighting channel its signature is in
    let blind = dir.join("commands_only.csv");
    commands_only(&log, &blind);
    let d = diagnose_seen(&spec, &blind, &obs, &map);
    for c in d["candidates"].as_array().unwrap() {
        let evidence = c["evidence"].as_str().unwrap();
        assert!(evidence.contains("mostly in landmark"), "{evidence}");
    }
}

/// (t, x, y) of a simulated or MRCLAM log's ground truth, from its text.
fn ground_truth(log: &str) -> Vec<[f64; 3]> {
    log.lines()
        .skip(1)
        .map(|l| {
            let v: Vec<f64> = l.split(',').map(|x| x.parse().unwrap()).collect();
            [v[0], v[3], v[4]]
        })
        .collect()
}

/// A localize `--track` CSV's rows (t, x, y, theta, var_x, cov_xy, var_y,
/// var_theta) and each row's position error against `truth`, interpolated.
fn track_errors(track: &Path, truth: &[[f64; 3]]) -> (Vec<Vec<f64>>, Vec<f64>) {
    let at = |t: f64| {
        let k = truth
            .partition_point(|r| r[0] <= t)
            .clamp(1, truth.len() - 1);
        let (a, b) = (truth[k - 1], truth[k]);
        let w = (t - a[0]) / (b[0] - a[0]);
        [a[1] + w * (b[1] - a[1]), a[2] + w * (b[2] - a[2])]
    };
    let rows: Vec<Vec<f64>> = std::fs::read_to_string(track)
        .unwrap()
        .lines()
        .skip(1)
        .map(|l| l.split(',').skip(1).map(|x| x.parse().unwrap()).collect())
        .collect();
    let errors = rows
        .iter()
        .map(|v| {
            let g = at(v[0]);
            (v[1] - g[0]).hypot(v[2] - g[1])
        })
        .collect();
    (rows, errors)
}

/// Root mean square of `errors`.
fn rms(errors: &[f64]) -> f64 {
    (errors.iter().map(|e| e * e).sum::<f64>() / errors.len() as f64).sqrt()
}

/// A commanded robot simulated with landmarks, its spec without observation
/// `sigma` (the user left it out: the simulator then adds the defaults'
/// noise, which localize assumes, not exact sightings), the log cut to start
/// in motion at 10 s without its ground truth, one sighting a second, those
/// before `sighted_from` s left out. Returns the spec, the map, the cut log
/// and the sightings; the simulated log with its truth is `dir/full.csv`.
fn moving_start_case(dir: &Path, sighted_from: f64) -> [PathBuf; 4] {
    let spec = commanded_spec(dir, "");
    let text = std::fs::read_to_string(&spec).unwrap();
    std::fs::write(&spec, text.replace("sigma = [0.05, 0.02]\n", "")).unwrap();
    let (map, obs) = (root().join("data/beacons.csv"), dir.join("obs.csv"));
    let log = Sim::new(spec.to_str().unwrap())
        .drive("random", 4, 1)
        .sighting(&map)
        .write_to(&dir.join("full.csv"), &obs);
    let full = std::fs::read_to_string(&log).unwrap();
    let cut = dir.join("cut.csv");
    let mut rows = vec!["t,v,omega".to_string()];
    for l in full.lines().skip(1) {
        let v: Vec<&str> = l.split(',').collect();
        if v[0].parse::<f64>().unwrap() >= 10.0 {
            rows.push(v[..3].join(","));
        }
    }
    std::fs::write(&cut, rows.join("\n") + "\n").unwrap();
    let sightings = std::fs::read_to_string(&obs).unwrap();
    let exact = sightings
        .lines()
        .nth(1)
        .unwrap()
        .split(',')
        .nth(2)
        .unwrap()
        .to_string();
    assert_ne!(
        exact, "4.000000000",
        "the first sighting (B1 at 4 m) is noisy"
    );
    // one sighting a second, turning through those of that second
    let mut by_second: std::collections::BTreeMap<i64, Vec<&str>> = Default::default();
    for l in sightings.lines().skip(1) {
        let t: f64 = l.split(',').next().unwrap().parse().unwrap();
        if t >= sighted_from {
            by_second.entry(t as i64).or_default().push(l);
        }
    }
    let mut thin = vec!["t,id,range,bearing".to_string()];
    for (k, ls) in by_second.values().enumerate() {
        thin.push(ls[k % ls.len()].to_string());
    }
    let thin_obs = dir.join("thin.csv");
    std::fs::write(&thin_obs, thin.join("\n") + "\n").unwrap();
    [spec, map, cut, thin_obs]
}

/// localize of [`moving_start_case`]: what it said, and each row's position
/// error against the simulated truth, with the row's time.
fn localize_moving_start(dir: &Path, sighted_from: f64) -> (String, Vec<(f64, f64)>) {
    let [spec, map, cut, obs] = moving_start_case(dir, sighted_from);
    let truth = ground_truth(&std::fs::read_to_string(dir.join("full.csv")).unwrap());
    let track = dir.join("track.csv");
    let o = kinegen(&[
        "localize",
        "--spec",
        spec.to_str().unwrap(),
        "--data",
        cut.to_str().unwrap(),
        "--observations",
        obs.to_str().unwrap(),
        "--landmarks",
        map.to_str().unwrap(),
        "--track",
        track.to_str().unwrap(),
        // the warnings whole (by default their first two lines)
        "-v",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let (rows, errors) = track_errors(&track, &truth);
    let timed = rows.iter().map(|r| r[0]).zip(errors).collect();
    (String::from_utf8_lossy(&o.stdout).to_string(), timed)
}

/// Issue #34: a robot without motion capture that moves from its first row
/// and sights one landmark at a time (a velocity-commanded robot's log as it
/// comes): localize places its start where its first sightings and its
/// odometry between them put it, instead of at the origin. The filter starts
/// within 0.1 m and tracks to 0.05 m RMS (started at the origin: 0.36 m).
#[test]
fn a_moving_start_without_ground_truth_is_placed_by_the_first_sightings() {
    let tmp = tempfile::tempdir().unwrap();
    let (said, errors) = localize_moving_start(tmp.path(), 0.0);
    assert!(!said.contains("no ground truth at the start"), "{said}");
    assert!(errors[0].1 < 0.1, "start {} m from the truth", errors[0].1);
    let rmse = rms(&errors.iter().map(|e| e.1).collect::<Vec<_>>());
    assert!(rmse < 0.05, "{rmse}");
}

/// The same robot seeing nothing for its first 30 s (the log starts at 10
/// s, the sightings at 40): its start is placed by the sightings it makes
/// next, through the odometry since the start, and the user is told the
/// track before them carries that odometry's drift. From 5 s after the
/// first sighting the filter tracks to under 0.05 m RMS (0.03); left at the
/// map's origin (as before), 0.51 m.
#[test]
fn a_start_seen_only_later_is_placed_by_the_later_sightings() {
    let tmp = tempfile::tempdir().unwrap();
    let (said, errors) = localize_moving_start(tmp.path(), 40.0);
    assert!(
        said.contains("cut.csv: no ground truth at the start (10.0 s) and no two landmarks seen within 20 s of it: the start is placed by the sightings of 40.")
            && said.contains("so the track before 40."),
        "{said}"
    );
    let after: Vec<f64> = (errors.iter())
        .filter(|(t, _)| *t >= 45.0)
        .map(|e| e.1)
        .collect();
    let rmse = rms(&after);
    assert!(rmse < 0.05, "{rmse}");
}

/// Issue #34: the MRCLAM logs as a user without motion capture has them
/// (their ground-truth columns removed). These robots move from their first
/// row and sight one landmark at a time: the start is placed by the first
/// sightings and the odometry between them, with their spread as the
/// start's covariance. On every robot the filter tracks the Vicon truth to
/// under 0.45 m RMS (from the origin: 0.46-1.19 m), and its start lies
/// within 3 standard deviations of the truth (the 5 cm prior it had covers
/// none of their 0.28-0.92 m).
#[test]
fn real_robots_without_motion_capture_are_started_where_their_sightings_put_them() {
    let tmp = tempfile::tempdir().unwrap();
    let spec = create_spec(tmp.path());
    for robot in 1..=5 {
        let Some(d) = mrclam_robot(robot) else { return };
        let full = std::fs::read_to_string(&d.log).unwrap();
        let truth = ground_truth(&full);
        let log = tmp.path().join(format!("robot{robot}.csv"));
        commands_only(&d.log, &log);
        let track = tmp.path().join(format!("track{robot}.csv"));
        let o = kinegen(&[
            "localize",
            "--spec",
            spec.to_str().unwrap(),
            "--data",
            log.to_str().unwrap(),
            "--observations",
            d.observations.to_str().unwrap(),
            "--landmarks",
            d.landmarks.to_str().unwrap(),
            "--track",
            track.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        let (rows, errors) = track_errors(&track, &truth);
        let rmse = rms(&errors);
        // t, x, y, theta, var_x, cov_xy, var_y, var_theta
        let start_sd = (rows[0][4] + rows[0][6]).sqrt();
        eprintln!(
            "robot{robot}: RMSE {rmse:.3} m, start {:.3} m off (sd {start_sd:.3})",
            errors[0]
        );
        assert!(rmse < 0.45, "robot{robot}: {rmse}");
        assert!(
            errors[0] < 3.0 * start_sd,
            "robot{robot}: start {} m off, sd {start_sd}",
            errors[0]
        );
    }
}

/// A velocity-commanded robot as real ones drive: commands at irregular
/// times, executed `delay` s late, the speeds disturbed at random (slip, a
/// controller that does not hold the command: white noise of `slip_v` m/s
/// and `slip_w` rad/s per sqrt(s)), motion capture at 50 Hz with 1 mm and
/// 2 mrad of noise. Written as the MRCLAM logs are (`t,v,omega,gt_*`).
fn drifting_commanded_log(path: &Path, seconds: f64, delay: f64, slip: [f64; 2], seed: u64) {
    use rand::{Rng, SeedableRng};
    use rand_distr::{Distribution, Normal};
    let mut rng = rand::rngs::SmallRng::seed_from_u64(seed);
    let n01 = Normal::new(0.0, 1.0).unwrap();
    let dt = 0.02;
    // the commands: (time issued, v, omega), a new one every 0.3-1.5 s
    let mut cmds = vec![(0.0, 0.1, 0.0)];
    while cmds.last().unwrap().0 < seconds {
        let t = cmds.last().unwrap().0 + rng.gen_range(0.3..1.5);
        let w = if rng.gen_bool(0.4) {
            0.0
        } else {
            rng.gen_range(-0.4..0.4)
        };
        cmds.push((t, rng.gen_range(0.0..0.12), w));
    }
    let at = |t: f64| {
        let k = cmds.partition_point(|c| c.0 <= t).max(1) - 1;
        (cmds[k].1, cmds[k].2)
    };
    let (mut x, mut y, mut th) = (0.0f64, 0.0f64, 0.0f64);
    let mut text = String::from("t,v,omega,gt_x,gt_y,gt_theta\n");
    let steps = (seconds / dt) as usize;
    for k in 0..=steps {
        let t = k as f64 * dt;
        let (v, w) = at(t);
        let noisy = |s: f64, rng: &mut rand::rngs::SmallRng| s * n01.sample(rng);
        let gt = [
            x + noisy(0.001, &mut rng),
            y + noisy(0.001, &mut rng),
            th + noisy(0.002, &mut rng),
        ];
        text += &format!(
            "{t:.3},{v:.3},{w:.3},{:.5},{:.5},{:.5}\n",
            gt[0], gt[1], gt[2]
        );
        // the robot executes the command of `delay` s ago, disturbed
        let (ve, we) = at(t - delay);
        let ve = ve + slip[0] / dt.sqrt() * n01.sample(&mut rng);
        let we = we + slip[1] / dt.sqrt() * n01.sample(&mut rng);
        x += ve * th.cos() * dt;
        y += ve * th.sin() * dt;
        th += we * dt;
    }
    std::fs::write(path, text).unwrap();
}

/// Issue #34, item 5: on a real robot, random drift dominates the whole
/// log's error and a late command explains a few percent of it: never most
/// of the excess over the sensor noise, nor 20%. Diagnosis then proves the
/// effect fold by fold (calibrated without each stretch of the log, it
/// predicts that stretch's motion over a second better, in a paired t-test
/// over the stretches): a 10 min simulated log of such a robot, its
/// commands 0.25 s late, gets a timing effect named, its value near 0.25 s.
/// The same log without the delay gets nothing named.
#[test]
fn a_late_command_under_random_drift_is_proved_fold_by_fold() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let spec = commanded_spec(dir, "");
    let s = spec.to_str().unwrap();
    for (delay, name) in [(0.25, "late.csv"), (0.0, "prompt.csv")] {
        let log = dir.join(name);
        drifting_commanded_log(&log, 600.0, delay, [0.01, 0.03], 7);
        let json = dir.join("diagnosis.json");
        let o = kinegen_in(
            dir,
            &[
                "diagnose",
                "-v",
                "--spec",
                s,
                "--data",
                log.to_str().unwrap(),
                "--json",
                json.to_str().unwrap(),
            ],
        );
        assert!(o.status.success(), "{}", stderr(&o));
        let diag: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
        let effects = diag["verdict"]["effects"].as_array().unwrap();
        eprintln!("delay {delay}: {}", diag["verdict"]["effects"]);
        if delay == 0.0 {
            assert!(effects.is_empty(), "{}", diag["verdict"]);
            continue;
        }
        let (first, value) = lag_proved_fold_by_fold(&diag);
        assert!((0.15..0.35).contains(&value), "{first}");
        // each effect it cannot be told from comes with its own command
        let text = stdout(&o);
        let equivalent = first["equivalent"].as_array().unwrap();
        assert!(!equivalent.is_empty(), "{first}");
        for e in equivalent {
            let e = e.as_str().unwrap();
            assert!(
                text.contains(&format!("add-effect --spec {s} --effect {e} --value")),
                "{text}"
            );
        }
    }
}

/// The first effect of a diagnosis's verdict, which must be a timing effect
/// (a late motion capture, a late or lagging command) that the folds proved
/// (see `diagnosis/folds.rs`), and its value, s.
fn lag_proved_fold_by_fold(diag: &serde_json::Value) -> (serde_json::Value, f64) {
    let timing = ["time_offset", "input_delay", "command_lag"];
    let first = diag["verdict"]["effects"]
        .get(0)
        .unwrap_or_else(|| panic!("nothing named: {}", diag["candidates"]))
        .clone();
    let effect = first["effect"].as_str().unwrap();
    assert!(timing.contains(&effect), "{}", diag["verdict"]);
    // the whole log's error barely moves: the folds proved it
    let folds = &first["folds"];
    assert!(
        folds["t"].as_f64().unwrap() > folds["critical"].as_f64().unwrap(),
        "{first}"
    );
    let value = first["parameters"][effect]["estimate"].as_f64().unwrap();
    (first, value)
}

/// Issue #34: what the camera itself misses. MRCLAM's camera reads a
/// landmark's depth along its axis, not its range (its range error, seen
/// from Vicon, is +4% ahead and -9% at the edges of its view). A commanded
/// robot simulated with landmarks, its sightings kept within a 0.6 rad
/// half-field of view and rewritten as such a camera would read them: 1.03
/// times the depth. Diagnose names `range_as_depth` from the sightings seen
/// from the ground truth, at a share within 0.05 of 1 and a scale within
/// 0.01 of 0.03, and nothing else; the same sightings with their straight
/// ranges name nothing; turned 0.02 rad, `bearing_offset` within 0.006.
#[test]
fn a_camera_that_reads_depth_or_looks_aside_is_named_from_its_sightings() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let (spec, map) = commanded_among_landmarks(dir);
    let s = spec.to_str().unwrap();
    let trip = TRIP;
    let (m, all) = (map.to_str().unwrap(), dir.join("all.csv"));
    let sightings = ["--landmarks", m, "--landmark-hz", "1", "--observations"];
    let args = [
        &["--spec", s][..],
        &trip,
        &sightings,
        &[all.to_str().unwrap()],
    ]
    .concat();
    let log = simulate(dir, "log.csv", &args);
    // the sightings of `from` within the field of view, as `read` reads them
    let camera = |from: &Path, name: &str, read: fn(f64, f64) -> (f64, f64)| {
        camera_view(from, &dir.join(format!("{name}.csv")), read)
    };
    let depth: fn(f64, f64) -> (f64, f64) = |r, b| (1.03 * r * b.cos(), b);
    let seen = |name: &str, read| diagnose_seen(&spec, &log, &camera(&all, name, read), &map);
    let found = |d: &serde_json::Value| -> Vec<String> {
        let effects = d["verdict"]["effects"].as_array().unwrap();
        effects
            .iter()
            .map(|e| e["effect"].as_str().unwrap().to_string())
            .collect()
    };
    let d = seen("depth", depth);
    assert_eq!(found(&d), ["range_as_depth"], "{}", d["verdict"]);
    let step = &d["verdict"]["effects"][0];
    let value = |name: &str| step["parameters"][name]["estimate"].as_f64().unwrap();
    assert!((value("range_depth") - 1.0).abs() < 0.05, "{step}");
    assert!((value("depth_scale") - 0.03).abs() < 0.01, "{step}");
    assert!(
        step["sightings"]["folds"]["t"].as_f64().unwrap() > 0.0,
        "{step}"
    );
    // and `fit` of the spec with it calibrates it from the sightings seen
    // from the ground truth, on a robot that slips sideways as its spec
    // does not say: seen from the dead-reckoned track, the sightings are
    // the track's drift (a real robot's calibrated to 0.36, not the camera)
    let with = dir.join("with_depth.toml");
    add_effect(&spec, "range_as_depth", &[], &with);
    let all_slip = dir.join("all_slip.csv");
    let slip = [
        "--effect",
        "lateral_slip=0.5",
        "--observations",
        all_slip.to_str().unwrap(),
    ];
    let args = [&["--spec", s][..], &trip, &sightings[..4], &slip].concat();
    let slipping = simulate(dir, "slipping.csv", &args);
    let obs = camera(&all_slip, "depth_slip", depth);
    let (w, l) = (with.to_str().unwrap(), slipping.to_str().unwrap());
    let sighted = ["--observations", obs.to_str().unwrap(), "--landmarks", m];
    let f = kinegen_json(&[&["fit", "--spec", w, "--data", l][..], &sighted].concat());
    let fitted = |name: &str| f["parameters"][name]["estimate"].as_f64().unwrap();
    assert!(
        (fitted("range_depth") - 1.0).abs() < 0.05,
        "{}",
        f["parameters"]
    );
    assert!(
        (fitted("depth_scale") - 0.03).abs() < 0.01,
        "{}",
        f["parameters"]
    );
    let d = seen("plain", |r, b| (r, b));
    assert_eq!(found(&d), Vec::<String>::new(), "{}", d["verdict"]);
    // the camera's three effects and sensor_offset's range-bearing mounting
    assert_eq!(d["sensor_candidates"].as_array().unwrap().len(), 4, "{d}");
    let d = seen("turned", |r, b| (r, b + 0.02));
    assert_eq!(found(&d), ["bearing_offset"], "{}", d["verdict"]);
    let offset = d["verdict"]["effects"][0]["parameters"]["bearing_offset"]["estimate"].as_f64();
    assert!((offset.unwrap() - 0.02).abs() < 0.006, "{}", d["verdict"]);
}

/// Calibrated on a real robot's sightings alone (MRCLAM robot 4 with its
/// Vicon columns removed: 15 minutes of velocity commands dead-reckoned
/// whole), the sightings still err by 18 and 37 times the spec's sigmas:
/// fit says the drift dominates and the parameters are biased by it (k_v
/// 0.975 against 0.919 with the ground truth). A simulated robot whose
/// calibrated sightings err at the sensor's noise gets no such warning
/// (`tests/landmarks.rs` checks the estimates there).
#[test]
fn a_calibration_on_drifting_sightings_says_it_is_biased() {
    let Some(d) = mrclam_robot(4) else { return };
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let spec = create_spec(dir);
    let blind = dir.join("no_vicon.csv");
    commands_only(&d.log, &blind);
    // fit on `log`'s sightings `obs` of `map`: its warnings
    let warned = |log: &Path, obs: &Path, map: &Path| {
        let s = |p: &Path| p.to_str().unwrap().to_string();
        let (spec, log, obs, map) = (s(&spec), s(log), s(obs), s(map));
        let args = [
            "fit",
            "--spec",
            &spec,
            "--data",
            &log,
            "--observations",
            &obs,
            "--landmarks",
            &map,
        ];
        run_in(dir, &args)["warnings"].to_string()
    };
    let said = warned(&blind, &d.observations, &d.landmarks);
    assert!(
        said.contains("drifts far beyond the sensor's noise"),
        "{said}"
    );
    // the same robot's sightings dead-reckoned with a simulated robot's
    // precision: no warning
    let (log, obs, map) = (
        dir.join("sim.csv"),
        dir.join("sim_obs.csv"),
        root().join("data/beacons.csv"),
    );
    Sim::new(spec.to_str().unwrap())
        .drive("random", 3, 1)
        .sighting(&map)
        .write_to(&dir.join("sim.csv"), &obs);
    let clean = dir.join("sim_blind.csv");
    commands_only(&log, &clean);
    let said = warned(&clean, &obs, &map);
    assert!(!said.contains("drifts far beyond"), "{said}");
}
