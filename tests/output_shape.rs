//! Every command's default text is read at a glance: the answer first, at
//! most 25 lines of at most 100 characters, on the bundled log and on the
//! real logs (OptiOdom here; MRCLAM's compare, fit, localize and diagnose
//! with a user's spec are checked by tests/velocity_commands.rs on the runs
//! it makes for their figures); `-v` says more.
mod common;
use common::*;
use std::path::Path;

/// Run kinegen (in `dir`), check the shape of what it prints by default,
/// and that `-v` prints more; returns the default text.
fn shaped(dir: &Path, args: &[&str]) -> String {
    let o = kinegen_in(dir, args);
    assert!(o.status.success(), "kinegen {args:?}: {}", stderr(&o));
    let text = stdout(&o) + &stderr(&o);
    assert_glanceable(args, &text);
    if matches!(
        args[0],
        "compare" | "fit" | "diagnose" | "localize" | "bench-real"
    ) {
        let lines = text.lines().count();
        let mut v = args.to_vec();
        v.push("-v");
        let o = kinegen_in(dir, &v);
        let more = stdout(&o) + &stderr(&o);
        assert!(
            more.lines().count() > lines || more.len() > text.len(),
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
    let (epuck, arena, tour) = (
        root().join("data/seed004/epuck.toml"),
        root().join("data/seed004/arena.txt"),
        root().join("data/beacon_tour.csv"),
    );
    let text = shaped(
        d,
        &[
            "navigate",
            "--spec",
            epuck.to_str().unwrap(),
            "--grid",
            arena.to_str().unwrap(),
            "--set",
            "b=0.056",
            "--calibrate",
            "umbmark",
        ],
    );
    assert!(
        text.lines()
            .nth(1)
            .is_some_and(|l| l.starts_with("answer: ")),
        "{text}"
    );
    let omni = root().join("spec/omni3.toml");
    let omni = omni.to_str().unwrap();
    shaped(
        d,
        &[
            "inverse",
            "--spec",
            spec,
            "--spec",
            omni,
            "--path",
            tour.to_str().unwrap(),
        ],
    );
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
