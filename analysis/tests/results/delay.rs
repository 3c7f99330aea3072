//! The first estimate of a measurement delay (`lag::delay_estimate`),
//! which diagnosis starts the `time_offset` effect from: a model calibrated
//! without a delay absorbs part of it, and a refinement from no delay stays
//! near zero (issue 12's speed target).
use kinegen_analysis::applications::simulate::{simulate, SimOptions, Trajectory};
use kinegen_analysis::estimation::lag::delay_estimate;
use kinegen_analysis::model_on_log::model::Runner;
use kinegen_analysis::model_on_log::run::Run;
use kinegen_model::ir::ModelIr;
use std::path::Path;

fn runner(model: &str) -> Runner {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("../generated/ir/{model}.json"));
    let ir = ModelIr::from_json(&std::fs::read_to_string(p).unwrap()).unwrap();
    Runner::new(ir, &[]).unwrap()
}

/// A diff_drive log whose logged poses are shifted by `rows` rows against
/// its inputs: lagging them when positive (the pose logged at row k is the
/// robot's at row k - rows), leading when negative.
fn shifted_log(r: &Runner, rows: isize) -> Run {
    let o = SimOptions {
        trajectory: Trajectory::Random,
        seed: 3,
        ..SimOptions::default()
    };
    let mut run = simulate(r, r, &o).to_run(r, "r").unwrap();
    let gt = run.gt.as_ref().unwrap();
    let n = gt.len() as isize;
    let shifted: Vec<[f64; 3]> = (0..n)
        .map(|k| gt[(k - rows).clamp(0, n - 1) as usize])
        .collect();
    run.gt = Some(shifted.into());
    run
}

/// Lags and leads of 1-4 rows (20 Hz) come back within a quarter of a row
/// (the start a refinement needs; the parabola through the best three lags
/// is not the correlation peak's exact shape),
/// with the model's wheel radii 10% off (correlation does not see scale).
/// With the sign of the lag flipped, or the correlation taken at the wrong
/// rows, every assertion fails.
#[test]
fn a_logged_pose_shifted_against_the_inputs_gives_its_delay() {
    let r = runner("diff_drive");
    let mut p = r.p.clone();
    p[0] *= 1.1;
    p[1] *= 1.1;
    for rows in [1isize, 2, 4, -3] {
        let run = shifted_log(&r, rows);
        let dt = (run.t[run.t.len() - 1] - run.t[0]) / run.steps() as f64;
        let est = delay_estimate(&r, &p, &[run], (-0.5, 0.5)).unwrap();
        let want = rows as f64 * dt;
        eprintln!("{rows} rows: want {want:.4} s, got {est:.4} s");
        assert!(
            (est - want).abs() < 0.25 * dt,
            "{rows} rows: {est} s against {want} s"
        );
    }
}

/// An unshifted log gives no delay (None: nothing to start from but zero),
/// and the estimate stays inside the bounds it is given.
#[test]
fn an_aligned_log_gives_no_delay_and_bounds_hold() {
    let r = runner("diff_drive");
    let run = shifted_log(&r, 0);
    let est = delay_estimate(&r, &r.p, &[run], (-0.5, 0.5));
    assert!(est.is_none(), "{est:?}");
    let lagging = shifted_log(&r, 4);
    let est = delay_estimate(&r, &r.p, &[lagging], (-0.1, 0.1)).unwrap();
    assert!((0.05..=0.1).contains(&est), "{est}");
}
