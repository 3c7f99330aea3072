//! `kinegen inverse` (issue 14, seed 001 eq. 12-18, Figs 8-10): wheel-rate
//! profiles of several robots along the bundled beacon tour, from the generated
//! integrated inverse, checked against the inputs' `max_rate` and `range`.
mod common;
use common::*;

fn inverse(args: &[&str]) -> (Option<i32>, serde_json::Value, String) {
    let mut a = vec!["inverse"];
    a.extend_from_slice(args);
    a.extend(["--json", "-"]);
    let o = kinegen(&a);
    let doc = serde_json::from_slice(&o.stdout).unwrap_or(serde_json::Value::Null);
    (o.status.code(), doc, stderr(&o))
}

/// A planned path file `name` under `dir` with the rows `t,x,y,theta`.
fn path_file(dir: &std::path::Path, name: &str, rows: &[String]) -> std::path::PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, format!("t,x,y,theta\n{}\n", rows.join("\n"))).unwrap();
    path
}

/// The omni drives `path`; the differential drive cannot (motion sideways).
fn only_the_omni_drives(path: &std::path::Path) {
    let (code, doc, err) = inverse(&[
        "--spec",
        "spec/omni3.toml",
        "--spec",
        "spec/diff_drive.toml",
        "--path",
        path.to_str().unwrap(),
    ]);
    assert_eq!(code, Some(1), "{err}");
    assert_eq!(model(&doc, "omni3")["feasible"], true);
    let dd = model(&doc, "diff_drive")["infeasible"].as_array().unwrap();
    assert!(
        dd.iter()
            .any(|s| s["input"] == "path" && s["why"].as_str().unwrap().contains("sideways")),
        "{dd:?}"
    );
}

fn model<'a>(doc: &'a serde_json::Value, name: &str) -> &'a serde_json::Value {
    doc["specs"]
        .as_array()
        .unwrap()
        .iter()
        .find(|s| s["model"] == name)
        .unwrap()
}

#[test]
fn three_robots_on_the_beacon_tour() {
    let tmp = tempfile::tempdir().unwrap();
    let report = tmp.path().join("report");
    let (code, doc, err) = inverse(&[
        "--spec",
        "spec/diff_drive.toml",
        "--spec",
        "spec/tricycle.toml",
        "--spec",
        "spec/omni3.toml",
        "--path",
        "data/beacon_tour.csv",
        "--report",
        report.to_str().unwrap(),
    ]);
    // the tricycle's steering servo (max_rate 0.5 rad/s) cannot follow the
    // sharpest turn: exit 1, the stretch named
    assert_eq!(code, Some(1), "{err}");
    assert_eq!(doc["feasible"], false);
    let tri = model(&doc, "tricycle");
    let stretches = tri["infeasible"].as_array().unwrap();
    assert!(
        !stretches.is_empty() && stretches.iter().all(|s| s["input"] == "alpha"),
        "{stretches:?}"
    );
    assert!(stretches[0]["why"]
        .as_str()
        .unwrap()
        .contains("above max_rate 0.5"));
    for m in ["diff_drive", "omni3"] {
        assert_eq!(model(&doc, m)["feasible"], true, "{m}");
    }
    // the inputs drive the model along the path: the model's step with them
    // lands on the next planned pose (exactly for the holonomic omni; the
    // differential drive follows a path planned along its heading closely)
    assert!(model(&doc, "omni3")["max_step_miss_m"].as_f64().unwrap() < 1e-9);
    assert!(
        model(&doc, "diff_drive")["max_step_miss_m"]
            .as_f64()
            .unwrap()
            < 2e-3
    );
    // Figs 8-10: the differential drive's wheels turn forward all along the
    // tour; only the omni's wheels turn backwards
    let rates = |m: &str, i: &str| -> Vec<f64> {
        model(&doc, m)["profile"]["inputs"][i]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect()
    };
    assert!(rates("diff_drive", "n_r")
        .iter()
        .chain(&rates("diff_drive", "n_l"))
        .all(|v| *v > 0.0));
    assert!(["w1", "w2", "w3"]
        .iter()
        .any(|w| rates("omni3", w).iter().any(|v| *v < -0.1)));
    let html = std::fs::read_to_string(report.join("index.html")).unwrap();
    assert!(
        html.contains("tricycle: inputs in rad") && html.contains("<svg"),
        "report"
    );
}

#[test]
fn a_low_max_rate_and_sideways_motion_are_marked() {
    let tmp = tempfile::tempdir().unwrap();
    // a user's omni with weaker motors
    let spec = std::fs::read_to_string(root().join("spec/omni3.toml"))
        .unwrap()
        .replace("max_rate = 10.0", "max_rate = 5.0");
    let weak = tmp.path().join("weak_omni.toml");
    std::fs::write(&weak, spec).unwrap();
    let (code, doc, err) = inverse(&[
        "--spec",
        weak.to_str().unwrap(),
        "--path",
        "data/beacon_tour.csv",
    ]);
    assert_eq!(code, Some(1), "{err}");
    let s = doc["specs"][0]["infeasible"].as_array().unwrap();
    assert!(
        s.iter()
            .any(|s| s["input"] == "w2" && s["why"].as_str().unwrap().contains("above max_rate 5")),
        "{s:?}"
    );
    // a path that strafes: the omni drives it, the differential drive cannot
    let rows: Vec<String> = (0..50)
        .map(|k| format!("{},0,{},0", k as f64 * 0.1, k as f64 * 0.05))
        .collect();
    only_the_omni_drives(&path_file(tmp.path(), "strafe.csv", &rows));
}

/// A path that drifts sideways a little in every step (0.2 m/s beside 0.5 m/s
/// ahead, 20 Hz: 1 cm a step, within what one step may miss) is still
/// sideways motion a differential drive cannot follow; the same circle with
/// millimetre tracker noise is not (noise does not add up over a second).
#[test]
fn slow_sideways_drift_is_marked_and_tracker_noise_is_not() {
    let tmp = tempfile::tempdir().unwrap();
    let rows: Vec<String> = (0..200)
        .map(|k| {
            let t = k as f64 * 0.05;
            format!("{t},{},{},0", 0.5 * t, 0.2 * t)
        })
        .collect();
    only_the_omni_drives(&path_file(tmp.path(), "drift.csv", &rows));
    // a circle of 2 m radius at 0.6 m/s, recorded with 1 mm / 1 mrad noise
    let mut state = 12345u64;
    let mut noise = |s: f64| {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        s * (((state >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0) * 1.7
    };
    let rows: Vec<String> = (0..400)
        .map(|k| {
            let t = k as f64 * 0.05;
            let a = 0.3 * t;
            format!(
                "{t},{},{},{}",
                2.0 * a.sin() + noise(1e-3),
                2.0 * (1.0 - a.cos()) + noise(1e-3),
                a + noise(1e-3)
            )
        })
        .collect();
    let noisy = path_file(tmp.path(), "noisy.csv", &rows);
    let (code, doc, err) = inverse(&[
        "--spec",
        "spec/diff_drive.toml",
        "--path",
        noisy.to_str().unwrap(),
    ]);
    assert_eq!(code, Some(0), "{err}");
    assert_eq!(model(&doc, "diff_drive")["feasible"], true, "{doc}");
}

#[test]
fn bad_paths_are_located() {
    let tmp = tempfile::tempdir().unwrap();
    let cases = [
        (
            "t,x,y,theta\n0,0,0,0\n0.1,0.1,0,0\n0.1,0.2,0,0\n",
            ":4: column `t`",
            "a time step of zero",
        ),
        (
            "t,x,y\n0,0,0\n0.1,0.1,0\n",
            ":1: column `theta`",
            "missing column",
        ),
        (
            "t,x,y,theta\n0,0,0,0\n0.1,abc,0,0\n",
            ":3: column `x`",
            "not a number",
        ),
        ("t,x,y,theta\n0,0,0,0\n", "path.csv", "at least 2"),
    ];
    for (text, place, what) in cases {
        let p = tmp.path().join("path.csv");
        std::fs::write(&p, text).unwrap();
        let (code, _, err) = inverse(&[
            "--spec",
            "spec/diff_drive.toml",
            "--path",
            p.to_str().unwrap(),
        ]);
        assert_eq!(code, Some(2), "{err}");
        assert!(
            err.contains("path.csv") && err.contains(place) && err.contains(what),
            "{place} {what}: {err}"
        );
    }
    // a spec error is located in the spec
    let bad = tmp.path().join("bad.toml");
    std::fs::write(
        &bad,
        std::fs::read_to_string(root().join("spec/omni3.toml"))
            .unwrap()
            .replacen("max_rate = 10.0", "max_rate = -1.0", 1),
    )
    .unwrap();
    let (code, _, err) = inverse(&[
        "--spec",
        bad.to_str().unwrap(),
        "--path",
        "data/beacon_tour.csv",
    ]);
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("bad.toml:") && err.contains("max_rate"),
        "{err}"
    );
}

/// A car-like rover whose steering angle is a configuration input (no
/// `[inverse]` section): its inverse imposes vx only, since the steering sets
/// omega, so the integrated inverse is checked on increments its own inputs
/// reach (the rates come back). Before, verify asked it for random heading
/// changes and reported a failure of 3e3. A sign flipped in the inverse is
/// still caught.
#[test]
fn a_steered_robot_without_a_declared_inverse_verifies_and_a_broken_one_does_not() {
    use kinegen_model::ir::{Kernel, ModelIr};
    use kinegen_verify::checks::inverse_round_trips;
    use kinegen_verify::{Corrupted, IrKernel};
    let tmp = tempfile::tempdir().unwrap();
    let spec = root().join("tests/user_specs/rover.toml");
    let o = kinegen(&["verify", "--spec", spec.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(0), "{}{}", stdout(&o), stderr(&o));
    let ir_path = tmp.path().join("rover.json");
    let o = kinegen(&[
        "derive",
        "--spec",
        spec.to_str().unwrap(),
        "--ir-out",
        ir_path.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let ir = ModelIr::from_json(&std::fs::read_to_string(&ir_path).unwrap()).unwrap();
    let increment = |f: &kinegen_verify::Finding| f.kernel == Kernel::InverseIncrement;
    let good = inverse_round_trips(&ir, &IrKernel, 50, 7);
    assert!(good.iter().filter(|f| increment(f)).all(|f| f.passed()));
    let bad = Corrupted::flip_term(&ir, Kernel::InverseIncrement, 0);
    let found = inverse_round_trips(&ir, &bad, 50, 7);
    let f = found.iter().find(|f| increment(f)).unwrap();
    assert!(!f.passed(), "a corrupted integrated inverse passed");
}

/// The rover's inverse gives only the drive rate; `inverse` solves the
/// steering angle of every step and checks it against the spec's range and
/// max_rate like any other input.
#[test]
fn a_car_like_robots_steering_profile_is_solved_and_checked() {
    let tmp = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(root().join("tests/user_specs/rover.toml"))
        .unwrap()
        .replace("range = [-0.6, 0.6]", "range = [-0.6, 0.6]\nmax_rate = 0.3");
    let spec = tmp.path().join("rover.toml");
    std::fs::write(&spec, text).unwrap();
    let tour = root().join("data/beacon_tour.csv");
    let (code, doc, err) = inverse(&[
        "--spec",
        spec.to_str().unwrap(),
        "--path",
        tour.to_str().unwrap(),
    ]);
    assert_eq!(code, Some(1), "{err}");
    let m = model(&doc, "rover");
    let inputs = m["inputs"].as_array().unwrap();
    let delta = inputs
        .iter()
        .find(|i| i["name"] == "delta")
        .expect("steering reported");
    let peak = delta["peak_rate"].as_f64().unwrap();
    assert!(peak > 0.3 && peak < 1.0, "steering rate {peak}");
    let values: Vec<f64> = m["profile"]["inputs"]["delta"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    assert!(
        values.iter().any(|v| v.abs() > 0.05),
        "the rover never steers"
    );
    assert!(
        m["infeasible"]
            .as_array()
            .unwrap()
            .iter()
            .any(|s| s["input"] == "delta"),
        "{}",
        m["infeasible"]
    );
}
