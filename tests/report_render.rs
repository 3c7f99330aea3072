//! The HTML reports render in headless Chromium (Debian's chromium package, which
//! .ci/run installs): the page loads, its figures are inline SVG, and a
//! screenshot is produced.
mod common;
use common::*;
use std::process::Command;

fn chromium() -> Option<&'static str> {
    ["chromium", "chromium-browser"].into_iter().find(|c| {
        Command::new(c)
            .arg("--version")
            .output()
            .is_ok_and(|o| o.status.success())
    })
}

#[test]
fn reports_render_in_headless_chromium() {
    let Some(browser) = chromium() else {
        assert!(
            std::env::var("CI").is_err(),
            "CI must have chromium (see .ci/run)"
        );
        eprintln!("chromium not installed: report rendering not checked here (CI checks it)");
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    // any two runs of one robot: the bundled log and a simulated one
    let second = Sim::new("spec/diff_drive.toml")
        .drive("random", 7, 1)
        .write(tmp.path(), "second.csv");
    let dir = tmp.path().join("report");
    let o = kinegen(&[
        "fit",
        "--spec",
        "spec/diff_drive.toml",
        "--data",
        "data/mystery_robot.csv",
        "--data",
        second.to_str().unwrap(),
        "--report",
        dir.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let page = format!("file://{}", dir.join("index.html").display());
    let profile = tmp.path().join("profile");
    let common = [
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-quic",
        "--no-first-run",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
    ];
    let shot = tmp.path().join("shot.png");
    let o = Command::new(browser)
        .args(common)
        .arg(format!("--user-data-dir={}", profile.display()))
        .args([
            "--window-size=1250,1400",
            &format!("--screenshot={}", shot.display()),
            &page,
        ])
        .output()
        .unwrap();
    assert!(
        shot.exists(),
        "no screenshot: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(
        std::fs::metadata(&shot).unwrap().len() > 20_000,
        "the screenshot is suspiciously small"
    );
    let o = Command::new(browser)
        .args(common)
        .arg(format!("--user-data-dir={}", profile.display()))
        .args(["--dump-dom", &page])
        .output()
        .unwrap();
    let dom = String::from_utf8_lossy(&o.stdout);
    assert!(
        dom.matches("<svg").count() >= 6,
        "figures missing from the rendered page"
    );
    assert!(dom.contains("kinegen fit: diff_drive") && dom.contains("after calibration"));
}
