//! `kinegen navigate` (issue 15, seed 004): cellular-automaton navigation on
//! the bundled arena, driven on odometry by an e-puck whose left wheel is 2%
//! small and whose axle is 5.7% longer than the odometry believes.
mod common;
use common::*;

const SPEC: &str = "data/seed004/epuck.toml";
const GRID: &str = "data/seed004/arena.txt";

fn navigate(extra: &[&str]) -> serde_json::Value {
    let mut a = vec![
        "navigate",
        "--spec",
        SPEC,
        "--grid",
        GRID,
        "--set",
        "r_l=0.0201",
        "--set",
        "b=0.056",
        "--calibrate",
        "umbmark",
    ];
    a.extend_from_slice(extra);
    kinegen_json(&a)
}

#[test]
fn umbmark_calibration_removes_the_collisions_and_recalculation_shrinks_the_error() {
    let tmp = tempfile::tempdir().unwrap();
    let report = tmp.path().join("report");
    let once = navigate(&["--report", report.to_str().unwrap()]);
    let recalc = navigate(&["--recalc", "1"]);
    let f = |d: &serde_json::Value, which: &str, k: &str| d[which][k].as_f64().unwrap();
    println!(
        "planned once: uncalibrated {} collisions, {:.1} cm; calibrated {} collisions, {:.1} cm; recalculated every move: calibrated {} collisions, {:.1} cm",
        f(&once, "uncalibrated", "collisions"),
        100.0 * f(&once, "uncalibrated", "final_error_m"),
        f(&once, "calibrated", "collisions"),
        100.0 * f(&once, "calibrated", "final_error_m"),
        f(&recalc, "calibrated", "collisions"),
        100.0 * f(&recalc, "calibrated", "final_error_m"),
    );
    // uncalibrated, the robot hits obstacles and ends far from the goal
    assert!(f(&once, "uncalibrated", "collisions") >= 1.0);
    assert!(f(&once, "uncalibrated", "final_error_m") > 0.15);
    // UMBMark finds the geometry errors: no collision, a few cm from the goal
    assert_eq!(f(&once, "calibrated", "collisions"), 0.0);
    assert!(f(&once, "calibrated", "final_error_m") < 0.07);
    let p = &once["calibration"]["parameters"];
    assert!(
        (p["b"]["estimate"].as_f64().unwrap() - 0.056).abs() < 0.001,
        "{p}"
    );
    // recalculating from the odometry pose corrects the motors' errors too
    assert_eq!(f(&recalc, "calibrated", "collisions"), 0.0);
    assert!(f(&recalc, "calibrated", "final_error_m") < f(&once, "calibrated", "final_error_m"));
    let html = std::fs::read_to_string(report.join("index.html")).unwrap();
    assert!(html.contains("calibrated odometry") && html.contains("<svg"));
}

#[test]
fn bad_grids_and_robots_are_refused_with_their_place() {
    let tmp = tempfile::tempdir().unwrap();
    let cases = [
        ("S...\n..\n...G\n", "grid.txt:2", "rectangular"),
        ("S.#..\n###..\n....G\n", "grid.txt:1", "no path"),
        ("S...\n....\n", "grid.txt", "no goal"),
        ("S..x\n...G\n", "grid.txt:1", "column 4"),
    ];
    for (text, place, what) in cases {
        let g = tmp.path().join("grid.txt");
        std::fs::write(&g, text).unwrap();
        let o = kinegen(&["navigate", "--spec", SPEC, "--grid", g.to_str().unwrap()]);
        assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
        assert!(
            stderr(&o).contains(place) && stderr(&o).contains(what),
            "{place} {what}: {}",
            stderr(&o)
        );
    }
    // a robot that cannot turn in place cannot make the seed's moves
    let o = kinegen(&["navigate", "--spec", "spec/tricycle.toml", "--grid", GRID]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("cannot turn in place"),
        "{}",
        stderr(&o)
    );
}

/// Issue #37.2: a cell of 1e300 m is refused, naming the option (it allocated
/// until the process aborted), and a 1000 x 1000 grid is driven (0.1 s here;
/// the distance diffusion swept the grid once per cell of path, and every
/// integration step checked every obstacle: over two minutes, then 50 s).
/// The time per cell is measured by `cargo bench -p kinegen-analysis --bench
/// speed -- grid`.
#[test]
fn absurd_cells_are_refused_and_large_grids_are_driven() {
    let e = refused(&[
        "navigate",
        "--spec",
        "data/seed004/epuck.toml",
        "--grid",
        "data/seed004/arena.txt",
        "--cell",
        "1e300",
    ]);
    assert!(e.contains("--cell 1e300"), "{}", e);
    // a model that cannot turn in place is refused naming its spec
    let e = refused(&[
        "navigate",
        "--spec",
        "spec/tricycle.toml",
        "--grid",
        "data/seed004/arena.txt",
    ]);
    assert!(
        e.contains("spec/tricycle.toml: model `tricycle` cannot turn in place"),
        "{}",
        e
    );
    let tmp = tempfile::tempdir().unwrap();
    let n = 1000;
    let mut text = String::new();
    for r in 0..n {
        for c in 0..n {
            text.push(match (r, c) {
                (1, 1) => 'S',
                _ if r == n - 2 && c == n - 2 => 'G',
                _ if r % 50 == 25 && (c < 2 * n / 3) == (r % 100 == 25) => '#',
                _ => '.',
            });
        }
        text.push('\n');
    }
    let grid = tmp.path().join("big.txt");
    std::fs::write(&grid, text).unwrap();
    let o = kinegen(&[
        "navigate",
        "--spec",
        "data/seed004/epuck.toml",
        "--grid",
        grid.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
}
