//! CONTRACT section 1 (third round): a parameter may declare `tolerance`
//! (absolute, or "2%" of its nominal value), which `fit` uses as a Gaussian
//! prior: where the log says little, the estimate stays near nominal.
mod common;
use common::*;

/// The bundled differential drive with a tolerance on its wheelbase.
fn with_tolerance(tol: &str) -> String {
    let text = std::fs::read_to_string(root().join("spec/diff_drive.toml")).unwrap();
    let at = text.find("name = \"b\"").expect("diff_drive declares b");
    let line_end = at + text[at..].find('\n').unwrap();
    format!(
        "{}\ntolerance = {tol}{}",
        &text[..line_end],
        &text[line_end..]
    )
}

/// A 3 s log of a robot whose wheelbase is 4% off: without a prior the fit
/// moves b most of the way (0.2074 +- 0.0018); with a tolerance of 0.25% it
/// stays near the nominal value, and the JSON says what the prior was.
#[test]
fn a_tolerance_keeps_a_weakly_determined_parameter_near_nominal() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    std::fs::write(dir.join("free.toml"), with_tolerance("1e9")).unwrap();
    std::fs::write(dir.join("tight.toml"), with_tolerance("\"0.25%\"")).unwrap();
    let whole = Sim::new("spec/diff_drive.toml")
        .sets(&["b=0.208"])
        .drive("random", 5, 1)
        .write(dir, "whole.csv");
    // its first 3 s: a few gentle turns, little about the wheelbase
    let text = std::fs::read_to_string(&whole).unwrap();
    let log = dir.join("short.csv");
    std::fs::write(
        &log,
        text.lines().take(60).collect::<Vec<_>>().join("\n") + "\n",
    )
    .unwrap();
    let b = |spec: &str| {
        let d = kinegen_json(&[
            "fit",
            "--spec",
            dir.join(spec).to_str().unwrap(),
            "--data",
            log.to_str().unwrap(),
        ]);
        let p = &d["parameters"]["b"];
        (p["estimate"].as_f64().unwrap(), p["tolerance"].as_f64())
    };
    let nominal = 0.2;
    let (free, _) = b("free.toml");
    let (tight, tol) = b("tight.toml");
    assert!((free - 0.208).abs() < 0.003, "without a prior b = {free}");
    assert!(
        (tight - nominal).abs() < 0.5 * (free - nominal).abs(),
        "a 0.25% tolerance should hold b near {nominal}: {tight} (free: {free})"
    );
    assert_eq!(tol, Some(0.0005), "the JSON gives the prior's width");
}

/// A tolerance that is not a positive number or percentage, or a percentage
/// of a parameter whose nominal value is 0, is a located error (exit 2).
#[test]
fn bad_tolerances_are_located_errors() {
    let tmp = tempfile::tempdir().unwrap();
    for (tol, says) in [
        ("\"abc\"", "percentage"),
        ("-0.1", "above 0"),
        ("0", "above 0"),
    ] {
        let spec = tmp.path().join("bad.toml");
        std::fs::write(&spec, with_tolerance(tol)).unwrap();
        let o = kinegen(&[
            "compare",
            "--spec",
            spec.to_str().unwrap(),
            "--data",
            "data/mystery_robot.csv",
        ]);
        assert_eq!(o.status.code(), Some(2), "{tol}: {}", stderr(&o));
        let e = stderr(&o);
        assert!(e.contains("bad.toml:") && e.contains(says), "{tol}: {e}");
    }
}
