//! Diagnosis beyond the catalogue (`verdict.proposed`) on the command line:
//! bench-diagnose's `--beyond` and its JSON, and a proposal's way through
//! `diagnose --report`, `add-effect --effects` and `fit`. How often the
//! proposals recover the effects written for the tests, and how rarely they
//! are made on logs that need none, is the library's to show
//! (analysis/tests/results/proposals.rs).
mod common;
use common::*;

/// Issue 70 item 6: bench-diagnose hides effects written outside the
/// catalogue (`--beyond`) and scores the proposals: each such case carries
/// the held-out error of the spec as it is and with the true effect
/// calibrated, the table counts the proposals that recover at least half
/// of what the truth removes, and the clean cases' proposals as false.
#[test]
fn bench_diagnose_scores_proposals_beyond_the_catalogue() {
    let tmp = tempfile::tempdir().unwrap();
    let fx = root().join("tests/proposal_effects");
    let spec = root().join("spec/diff_drive.toml");
    let o = kinegen_in(
        tmp.path(),
        &[
            "bench-diagnose",
            "--spec",
            spec.to_str().unwrap(),
            "--beyond",
            fx.to_str().unwrap(),
            "--effect",
            "turn_saturation",
            "--json",
            "bench.json",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stdout(&o).contains("beyond the catalogue: recovered"),
        "{}",
        stdout(&o)
    );
    let text = std::fs::read_to_string(tmp.path().join("bench.json")).unwrap();
    let d: serde_json::Value = serde_json::from_str(&text).unwrap();
    let beyond_effects = d["selection"]["beyond"].as_array().unwrap();
    assert!(
        beyond_effects.iter().any(|e| e == "turn_saturation"),
        "{}",
        d["selection"]
    );
    let cases = d["cases"].as_array().unwrap();
    let beyond: Vec<&serde_json::Value> = cases.iter().filter(|c| c["beyond"] == true).collect();
    // 3 magnitudes x 2 noise levels, each scored against the truth
    assert_eq!(beyond.len(), 6);
    for c in &beyond {
        let (before, truth) = (
            c["truth"]["held_out_before"].as_f64().unwrap(),
            c["truth"]["held_out_true"].as_f64().unwrap(),
        );
        assert!(
            truth < 0.5 * before,
            "the true effect explains the log: {c}"
        );
    }
    let m = &d["models"][0];
    assert_eq!(m["beyond_recovered"]["of"], 6, "{m}");
    assert!(m["beyond_recovered"]["found"].as_u64().unwrap() >= 5, "{m}");
    assert_eq!(m["false_proposals"]["of"], 4, "{m}");
    assert_eq!(m["false_proposals"]["found"], 0, "{m}");
}

/// A correction of the range-bearing sensor (issue 70, item 2's observation
/// kind) goes the way of every effect: diagnose proposes it on the
/// sightings (`scored_on: sightings`) and writes its effect file beside the
/// report, `add-effect --effects DIR` applies it, and `fit` calibrates its
/// gain to what the diagnosis estimated (a focal length 10% long: the gain
/// of `sin(2*bearing)` is about 0.05). Its recovery rates over seeds are
/// analysis/tests/sensor_proposals.rs's.
#[test]
fn a_sensor_proposal_is_applied_by_add_effect_and_calibrated_by_fit() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let mut map = String::from("id,x,y\n");
    for k in 0..25 {
        map += &format!("L{k},{},{}\n", 3 * (k / 5 - 2), 3 * (k % 5 - 2));
    }
    std::fs::write(d.join("map.csv"), map).unwrap();
    std::fs::copy(root().join("spec/diff_drive.toml"), d.join("robot.toml")).unwrap();
    let fx = root().join("tests/proposal_effects");
    let sightings = ["--observations", "obs.csv", "--landmarks", "map.csv"];
    let run = |args: &[&str]| {
        let o = kinegen_in(d, args);
        assert!(o.status.success(), "{args:?}: {}", stderr(&o));
        o
    };
    run(&[
        &[
            "simulate",
            "--spec",
            "robot.toml",
            "--effects",
            fx.to_str().unwrap(),
        ][..],
        &[
            "--effect",
            "camera_focal_error.k_focal=0.1",
            "--trajectory",
            "random",
        ],
        &["--seed", "3", "--out", "log.csv"],
        &sightings,
    ]
    .concat());
    let base = ["--spec", "robot.toml", "--data", "log.csv"];
    let o = run(&[
        &["diagnose"][..],
        &base,
        &sightings,
        &["--report", "rep", "--json", "-"],
    ]
    .concat());
    let doc: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let proposed = doc["verdict"]["proposed"].as_array().unwrap();
    let p = (proposed.iter())
        .find(|p| p["scored_on"] == "sightings")
        .unwrap_or_else(|| panic!("no sensor proposal: {}", doc["verdict"]));
    assert_eq!(p["name"], "proposed_bearing_correction", "{p}");
    assert_eq!(p["terms"][0], "sin(2*bearing)", "{p}");
    let proposed_gain = p["parameters"]["k_bearing_focal"]["estimate"]
        .as_f64()
        .unwrap();
    assert!(d
        .join("rep/proposed/proposed_bearing_correction.toml")
        .is_file());
    run(&[
        "add-effect",
        "--spec",
        "robot.toml",
        "--effects",
        "rep/proposed",
        "--effect",
        "proposed_bearing_correction",
        "--out",
        "robot2.toml",
    ]);
    let o = run(&[
        &["fit", "--spec", "robot2.toml", "--data", "log.csv"][..],
        &sightings,
        &["--json", "-"],
    ]
    .concat());
    let fit: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let e = &fit["parameters"]["k_bearing_focal"];
    let (gain, sd) = (e["estimate"].as_f64().unwrap(), e["std"].as_f64().unwrap());
    assert!(
        (gain - proposed_gain).abs() <= 2.0 * sd.max(1e-4),
        "{e} against {p}"
    );
    assert!((gain - 0.05).abs() < 0.005, "{e}");
}
