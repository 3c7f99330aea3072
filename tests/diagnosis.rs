//! `kinegen diagnose` as a user runs it: the whole story through the CLI,
//! the JSON as CONTRACT section 4 gives it, the recovery benchmark's
//! document, a user's own effect folder, the text. What the diagnosis finds
//! (verdicts, estimates, structure) is asserted on the library's values in
//! analysis/tests/results/diagnosis.rs.
mod common;
use common::*;

/// compare -> diagnose -> add-effect -> fit -> generate -> verify, through the CLI.
#[test]
fn the_whole_story_through_the_cli() {
    let tmp = tempfile::tempdir().unwrap();
    let t = tmp.path();
    let log = Sim::new("spec/diff_drive.toml")
        .sets(&["b=0.205"])
        .effects(&["lateral_slip=0.2"])
        .drive("random", 11, 1)
        .write(t, "slip.csv");
    let l = log.to_str().unwrap();
    let cmp = kinegen_json(&["compare", "--spec", "spec/diff_drive.toml", "--data", l]);
    assert!(cmp["rmse"].as_f64().unwrap() > 0.05);
    let d = kinegen_json(&["diagnose", "--spec", "spec/diff_drive.toml", "--data", l]);
    assert_eq!(d["verdict"]["effect"], "lateral_slip");
    // CONTRACT section 4
    assert_eq!(d["model"], "diff_drive");
    assert!(d["metric"].is_string());
    assert!(d["baseline"]["rmse"].is_number() && d["calibrated"]["rmse"].is_number());
    let first = &d["candidates"][0];
    for k in ["rmse", "improvement"] {
        assert!(first[k].is_number(), "{k}: {first}");
    }
    assert!(first["significant"].is_boolean() && first["evidence"].is_string());
    assert_eq!(d["verdict"]["effects"][0]["effect"], "lateral_slip");
    assert!(d["verdict"]["effects"][0]["rmse_after"].is_number());
    assert!(d["verdict"]["unexplained_structure"].is_boolean());
    let k = d["candidates"][0]["parameters"]["k_slip"]["estimate"]
        .as_f64()
        .unwrap();
    // the human output prints the spec change
    let o = kinegen(&[
        "diagnose",
        "-v",
        "--spec",
        "spec/diff_drive.toml",
        "--data",
        l,
    ]);
    assert!(
        stdout(&o).contains("spec change:") && stdout(&o).contains("k_slip"),
        "{}",
        stdout(&o)
    );

    let spec_dir = t.join("spec");
    std::fs::create_dir(&spec_dir).unwrap();
    let new_spec = spec_dir.join("diff_drive.toml");
    let o = kinegen(&[
        "add-effect",
        "--spec",
        "spec/diff_drive.toml",
        "--effect",
        "lateral_slip",
        "--value",
        &format!("k_slip={k}"),
        "--out",
        new_spec.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let before = kinegen_json(&["fit", "--spec", "spec/diff_drive.toml", "--data", l]);
    let after = kinegen_json(&["fit", "--spec", new_spec.to_str().unwrap(), "--data", l]);
    let (eb, ea) = (
        before["after"]["rmse"].as_f64().unwrap(),
        after["after"]["rmse"].as_f64().unwrap(),
    );
    assert!(
        ea * 3.0 < eb,
        "adding the effect did not make the error fall: {eb} -> {ea}"
    );
    assert!((after["parameters"]["k_slip"]["estimate"].as_f64().unwrap() - 0.2).abs() < 0.02);

    // regenerate kernels that include the effect, and verify them like any spec
    let out = t.join("generated");
    let o = kinegen(&[
        "generate",
        "--spec-dir",
        spec_dir.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let src = std::fs::read_to_string(out.join("src/diff_drive.rs")).unwrap();
    assert!(src.contains("k_slip"));
    let o = kinegen(&[
        "verify",
        "--spec",
        new_spec.to_str().unwrap(),
        "--samples",
        "30",
    ]);
    assert!(
        o.status.success(),
        "verify failed on the augmented spec: {}{}",
        stdout(&o),
        stderr(&o)
    );
}

/// Issue 12: the recovery benchmark runs and scores. Lateral slip on the
/// differential drive at 3 magnitudes x 2 noise levels is named every time,
/// and clean logs raise no alarm.
#[test]
fn bench_diagnose_scores_recovery_and_false_alarms() {
    let d = kinegen_json(&[
        "bench-diagnose",
        "--spec",
        "spec/diff_drive.toml",
        "--effect",
        "lateral_slip",
    ]);
    let m = &d["models"][0];
    assert_eq!(m["model"], "diff_drive");
    assert_eq!(m["top1"]["of"], 6, "{m}");
    assert_eq!(m["top1"]["found"], 6, "{m}");
    assert_eq!(m["false_alarms"]["of"], 4, "{m}");
    assert_eq!(m["false_alarms"]["found"], 0, "{m}");
    let cases = d["cases"].as_array().unwrap();
    assert!(cases
        .iter()
        .any(|c| c["hidden"][0] == "lateral_slip" && c["found"][0] == "lateral_slip"));
}

/// Issue 12: an effect small next to the sensor noise is named when it explains
/// what the model leaves above the noise floor: a tricycle's gyro reading 5%
/// high under 3x the default noise lowers the error by only 15%, to the floor
/// (the 20% rule alone withheld it), while the clean logs of the same run stay
/// clean.
#[test]
fn an_effect_small_next_to_the_noise_is_named_when_it_explains_the_excess() {
    let d = kinegen_json(&[
        "bench-diagnose",
        "--spec",
        "spec/tricycle.toml",
        "--effect",
        "gyro_scale",
    ]);
    let m = &d["models"][0];
    assert_eq!(m["top1"]["found"], m["top1"]["of"], "{m}");
    assert_eq!(m["false_alarms"]["found"], 0, "{m}");
    let cases = d["cases"].as_array().unwrap();
    assert!(cases.iter().any(|c| c["noise"] == 3.0
        && c["hidden"][0] == "gyro_scale"
        && c["found"][0] == "gyro_scale"));
}

/// A user's own robot (a tracked crawler in ticks, outside the checkout) and
/// a user's own effect (track skid that grows with the speed squared):
/// diagnose names and recovers it, and a candidate chain whose inverse
/// kinematics the effects made singular (the skid with a toe angle, which
/// puts the speed into vx and vy alike) is derived without an inverse
/// instead of failing, and nothing from the derivation's child process (a
/// file in the IR cache, symbolica's log) reaches the user.
#[test]
fn a_users_own_effect_on_a_users_own_robot_is_named_and_quiet() {
    let tmp = tempfile::tempdir().unwrap();
    let fx = tmp.path().join("fx");
    std::fs::create_dir(&fx).unwrap();
    std::fs::write(
        fx.join("skid.toml"),
        "name = \"track_skid\"\ndoc = \"Tracks skid in turns.\"\nrequires = [\"twist\"]\n\n[[parameter]]\nname = \"skid\"\nnominal = 0.0\nunit = \"s^2/m^2\"\nmin = -2.0\nmax = 2.0\n\n[motion]\nomega = \"{omega}*(1 - skid*{vx}^2)\"\n",
    )
    .unwrap();
    let spec = tmp.path().join("crawler.toml");
    // a doc of its own (this run's directory) makes the spec new to the IR
    // cache, so every candidate is derived by a child process here
    std::fs::write(
        &spec,
        format!("doc = \"{}\"\n", tmp.path().display())
            + "name = \"crawler\"\nstate = [\"x\", \"y\", \"theta\"]\n\n[[input]]\nname = \"tl\"\ncolumn = \"left_ticks\"\nkind = \"cumulative\"\nunit = \"tick/s\"\n\n[[input]]\nname = \"tr\"\ncolumn = \"right_ticks\"\nkind = \"cumulative\"\nunit = \"tick/s\"\n\n[[parameter]]\nname = \"m_per_tick\"\nnominal = 0.0005\nunit = \"m\"\nmin = 0.0\n\n[[parameter]]\nname = \"track_width\"\nnominal = 0.45\nunit = \"m\"\nmin = 0.0\n\n[motion]\nvx = \"m_per_tick*(tl + tr)/2\"\nvy = \"0\"\nomega = \"m_per_tick*(tr - tl)/track_width\"\n\n[[observation]]\nname = \"imu\"\ncolumns = [\"gz\"]\nexpr = [\"omega\"]\n",
    )
    .unwrap();
    let (s, f) = (spec.to_str().unwrap(), fx.to_str().unwrap());
    let skidded = tmp.path().join("skidded.toml");
    let o = kinegen(&[
        "add-effect",
        "--spec",
        s,
        "--effect",
        "track_skid",
        "--effects",
        f,
        "--value",
        "skid=0.3",
        "--out",
        skidded.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let written = std::fs::read_to_string(&skidded).unwrap();
    assert!(
        written.contains(
            "omega = \"m_per_tick*(tr - tl)/track_width*(1 - skid*(m_per_tick*(tl + tr)/2)^2)\""
        ),
        "{written}"
    );
    let log = Sim::new(skidded.to_str().unwrap())
        .drive("random", 5, 2)
        .write(tmp.path(), "log.csv");
    // the skid with a toe angle, hidden in a simulated robot: derived by a
    // child process from the cache, whose symbolica log (an infinity met
    // trying the inverse) and errors are not the user's to read
    let o = kinegen(&[
        "simulate",
        "--spec",
        s,
        "--effects",
        f,
        "--effect",
        "track_skid=0.3",
        "--effect",
        "wheel_misalignment=0.01",
        "--trajectory",
        "random",
        "--out",
        tmp.path().join("toed.csv").to_str().unwrap(),
    ]);
    let said = stderr(&o);
    assert!(o.status.success(), "{said}");
    assert!(
        !said.contains("kinegen-ir-cache") && !said.contains("error:") && !said.contains("WARN"),
        "{said}"
    );
    let o = kinegen(&[
        "diagnose",
        "--spec",
        s,
        "--data",
        log.to_str().unwrap(),
        "--effects",
        f,
        "--json",
        "-",
    ]);
    let said = stderr(&o);
    assert!(o.status.success(), "{said}");
    assert!(
        !said.contains("kinegen-ir-cache") && !said.contains("error:") && !said.contains("WARN"),
        "{said}"
    );
    let doc: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(doc["verdict"]["effect"], "track_skid", "{doc}");
}

/// The model's own step, too coarse for the log's rate, is warned about in
/// the text (the check itself is analysis/tests/results/diagnosis.rs's): a clean
/// log of the front-drive tricycle, every fourth row kept (5 Hz), where the
/// steering swings between samples.
#[test]
fn a_step_too_coarse_for_the_log_is_warned_about() {
    let tmp = tempfile::tempdir().unwrap();
    let spec = root().join("tests/user_specs/fwd_tricycle.toml");
    let spec = spec.to_str().unwrap();
    let log = Sim::new(spec)
        .drive("random", 1, 1)
        .write(tmp.path(), "clean1.csv");
    let text = std::fs::read_to_string(&log).unwrap();
    let coarse: Vec<&str> = (text.lines().enumerate())
        .filter(|(i, _)| *i == 0 || (i - 1) % 4 == 0)
        .map(|x| x.1)
        .collect();
    let slow = tmp.path().join("clean1_5hz.csv");
    std::fs::write(&slow, coarse.join("\n") + "\n").unwrap();
    let out = kinegen(&[
        "diagnose",
        "-v",
        "--spec",
        spec,
        "--data",
        slow.to_str().unwrap(),
    ]);
    let text = stdout(&out);
    assert!(
        text.contains("warning: the model's own step at the log's 5 Hz"),
        "{text}"
    );
}
