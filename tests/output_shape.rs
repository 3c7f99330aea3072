//! Every command's default text is read at a glance: the answer first, at
//! most 25 lines of at most 100 characters, on the bundled log and on the
//! real logs (MRCLAM, OptiOdom) with specs a user writes; `-v` says more.
mod common;
use common::*;
use std::path::Path;

const LINES: usize = 25;
const WIDTH: usize = 100;

/// Run kinegen (in `dir`), check the shape of what it prints by default,
/// and that `-v` prints more; returns the default text.
fn shaped(dir: &Path, args: &[&str]) -> String {
    let o = kinegen_in(dir, args);
    assert!(o.status.success(), "kinegen {args:?}: {}", stderr(&o));
    let text = stdout(&o) + &stderr(&o);
    let lines: Vec<&str> = text.lines().collect();
    assert!(
        lines.len() <= LINES,
        "kinegen {args:?}: {} lines:\n{text}",
        lines.len()
    );
    let wide: Vec<&&str> = lines.iter().filter(|l| l.chars().count() > WIDTH).collect();
    assert!(
        wide.is_empty(),
        "kinegen {args:?}: lines over {WIDTH}: {wide:#?}"
    );
    if matches!(
        args[0],
        "compare" | "fit" | "diagnose" | "localize" | "bench-real"
    ) {
        assert!(
            lines.iter().any(|l| l.starts_with("answer: ")),
            "kinegen {args:?}: no answer line:\n{text}"
        );
        let mut v = args.to_vec();
        v.push("-v");
        let o = kinegen_in(dir, &v);
        let more = stdout(&o) + &stderr(&o);
        assert!(
            more.lines().count() > lines.len() || more.len() > text.len(),
            "kinegen {args:?} -v says no more than without it"
        );
    }
    text
}

#[test]
fn the_bundled_story_reads_at_a_glance() {
    let tmp = tempfile::tempdir().unwrap();
    let log = root().join("data/mystery_robot.csv");
    let spec = root().join("spec/diff_drive.toml");
    let (log, spec) = (log.to_str().unwrap(), spec.to_str().unwrap());
    let d = tmp.path();
    shaped(d, &["compare", "--spec", spec, "--data", log]);
    let text = shaped(d, &["diagnose", "--spec", spec, "--data", log]);
    assert!(text.contains("kinegen add-effect"), "{text}");
    shaped(
        d,
        &[
            "add-effect",
            "--spec",
            spec,
            "--effect",
            "lateral_slip",
            "--out",
            "slip.toml",
        ],
    );
    shaped(d, &["fit", "--spec", "slip.toml", "--data", log]);
    shaped(
        d,
        &[
            "simulate",
            "--spec",
            "slip.toml",
            "--trajectory",
            "square",
            "--out",
            "sim.csv",
        ],
    );
}

/// A velocity-commanded robot with a camera, as a user writes it.
const CART: &str = r#"name = "cart"
state = ["x", "y", "theta"]
[[input]]
name = "speed_sp"
column = "v"
kind = "absolute"
unit = "m/s"
[[input]]
name = "yaw_sp"
column = "omega"
kind = "absolute"
unit = "rad/s"
[[parameter]]
name = "gain_speed"
nominal = 1.0
min = 0.0
[[parameter]]
name = "gain_yaw"
nominal = 1.0
min = 0.0
[[noise]]
name = "n_speed"
sigma = 0.03
unit = "m/s/sqrt(Hz)"
[[noise]]
name = "n_yaw"
sigma = 0.03
unit = "rad/s/sqrt(Hz)"
[motion]
vx = "gain_speed*speed_sp + n_speed"
vy = "0"
omega = "gain_yaw*yaw_sp + n_yaw"
[[observation]]
name = "cam"
landmark = true
columns = ["range", "bearing"]
expr = ["sqrt((xl - x)^2 + (yl - y)^2)", "atan2(yl - y, xl - x) - theta"]
angle = [false, true]
sigma = [0.1, 0.03]
"#;

/// A user's spec on MRCLAM robot 3 (600 s of velocity commands with
/// sightings) through `commands`, each shaped. Split over tests so that the
/// test runner's threads run diagnose (the longest) beside the others.
fn mrclam_reads_at_a_glance(commands: &[&str]) {
    let Some(mrclam) = real_data("mrclam-dataset6") else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    std::fs::write(d.join("cart.toml"), CART).unwrap();
    let robot = mrclam.join("robot3");
    let files = |f: &str| robot.join(f).to_str().unwrap().to_string();
    let (log, obs, map) = (
        files("log.csv"),
        files("observations.csv"),
        files("landmarks.csv"),
    );
    let with_sightings = ["--observations", &obs, "--landmarks", &map];
    for &cmd in commands {
        let mut a = vec![cmd, "--spec", "cart.toml", "--data", &log];
        a.extend(with_sightings);
        shaped(d, &a);
    }
}

#[test]
fn a_real_robots_diagnosis_reads_at_a_glance() {
    mrclam_reads_at_a_glance(&["diagnose"]);
}

#[test]
fn a_real_robots_comparison_calibration_and_localisation_read_at_a_glance() {
    mrclam_reads_at_a_glance(&["compare", "fit", "localize"]);
}

#[test]
fn a_real_benchmark_reads_at_a_glance() {
    let Some(dev) = real_data("optiodom-dev") else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let dir = dev.to_str().unwrap();
    let args = ["bench-real", dir, "--session", "diff-circular", "--quiet"];
    let text = shaped(tmp.path(), &args);
    assert!(text.contains("answer: kinegen at or below"), "{text}");
}

#[test]
fn real_odometry_runs_read_at_a_glance() {
    let Some(square) = real_data("optiodom-diff-square") else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let runs: Vec<String> = ["run-01.csv", "run-04.csv"]
        .iter()
        .map(|r| square.join(r).to_str().unwrap().to_string())
        .collect();
    let spec = root().join("spec/diff_drive.toml");
    for cmd in ["compare", "fit", "diagnose"] {
        shaped(
            d,
            &[
                cmd,
                "--spec",
                spec.to_str().unwrap(),
                "--data",
                &runs[0],
                "--data",
                &runs[1],
            ],
        );
    }
}

/// The short text changes nothing else: the JSON document is the same with
/// and without -v (times aside), so every figure stays available.
#[test]
fn the_json_is_the_same_with_and_without_verbose() {
    let log = root().join("data/mystery_robot.csv");
    let l = log.to_str().unwrap();
    let strip = |mut v: serde_json::Value| {
        if let Some(o) = v.as_object_mut() {
            o.remove("timing");
        }
        v
    };
    for cmd in ["compare", "fit", "diagnose"] {
        let args = [cmd, "--spec", "spec/diff_drive.toml", "--data", l];
        let short = strip(kinegen_json(&args));
        let mut v = args.to_vec();
        v.push("-v");
        let long = strip(kinegen_json(&v));
        assert_eq!(short, long, "{cmd}: the JSON differs with -v");
    }
}

/// add-effect's diff stays within the width however long the expressions
/// it writes, and says the file has them whole.
#[test]
fn add_effect_cuts_long_lines_of_its_diff_and_says_so() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let fx = d.join("fx");
    std::fs::create_dir_all(&fx).unwrap();
    std::fs::write(
        fx.join("turn_rate_loss.toml"),
        "name = \"turn_rate_loss\"\ndoc = \"Scrub.\"\nrequires = [\"twist\"]\n[[parameter]]\nname = \"k_scrub\"\nnominal = 0.0\nunit = \"s\"\nmin = -1.0\nmax = 1.0\n[motion]\nomega = \"({omega}) - k_scrub*({omega})*abs({omega})\"\n",
    )
    .unwrap();
    let spec = root().join("tests/user_specs/skid4.toml");
    let text = shaped(
        d,
        &[
            "add-effect",
            "--spec",
            spec.to_str().unwrap(),
            "--effects",
            "fx",
            "--effect",
            "turn_rate_loss",
            "--out",
            "s.toml",
        ],
    );
    assert!(text.contains("s.toml has them whole"), "{text}");
    let written = std::fs::read_to_string(d.join("s.toml")).unwrap();
    assert!(written.lines().any(|l| l.chars().count() > 100));
}
