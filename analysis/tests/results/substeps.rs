//! Dead reckoning sub-steps a step whose absolute input (a steering angle)
//! swings across it: the bundled tricycle steering at 2.5 rad/s, logged at 10 Hz,
//! against the same motion logged at 320 Hz (issue 12 item 3).
use kinegen_analysis::logs::rows::Inputs;
use kinegen_analysis::model_on_log::deadreckon;
use kinegen_analysis::model_on_log::model::Runner;
use kinegen_analysis::model_on_log::run::Run;
use kinegen_model::ir::ModelIr;
use std::path::Path;

fn tricycle() -> Runner {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../generated/ir/tricycle.json");
    let ir = ModelIr::from_json(&std::fs::read_to_string(p).unwrap()).unwrap();
    Runner::new(ir, &[]).unwrap()
}

/// The steering angle at time t: sweeps between -1 and 1 rad at 2.5 rad/s,
/// turning back at multiples of the coarse step (a log cannot tell what an
/// input does between its samples; between them, this one moves linearly).
fn alpha(t: f64) -> f64 {
    let phase = (t + 0.4).rem_euclid(1.6);
    if phase < 0.8 {
        -1.0 + 2.5 * phase
    } else {
        1.0 - 2.5 * (phase - 0.8)
    }
}

/// A run of `steps` steps over 4 s, drive wheel at 8 rad/s; with `swing`, the
/// steering angle's change over each step is given (as logs give it).
fn run(steps: usize, swing: bool) -> Run {
    let dt = 4.0 / steps as f64;
    let t: Vec<f64> = (0..=steps).map(|k| k as f64 * dt).collect();
    let mut u = Vec::new();
    let mut s = Vec::new();
    for k in 0..steps {
        let (a, b) = (alpha(t[k]), alpha(t[k + 1]));
        u.extend([8.0, 0.5 * (a + b)]);
        s.extend([0.0, b - a]);
    }
    Run {
        name: "sweep".into(),
        path: "sweep".into(),
        t: t.into(),
        dt: vec![dt; steps].into(),
        u: Inputs::from_flat(steps, 2, u),
        gt: None,
        gyro: None,
        landmarks: Vec::new(),
        rate_inputs: vec![true, false],
        swing: swing.then(|| Inputs::from_flat(steps, 2, s)),
        first_line: 2,
    }
}

#[test]
fn a_swinging_steering_angle_is_sub_stepped() {
    let r = tricycle();
    let end = |run: &Run| *deadreckon::run(&r, &r.p, run, false).pose.last().unwrap();
    let truth = end(&run(1280, false));
    let dist = |a: [f64; 3]| (a[0] - truth[0]).hypot(a[1] - truth[1]);
    let (held, sub) = (dist(end(&run(40, false))), dist(end(&run(40, true))));
    assert!(held > 1e-3, "the test must stress the step: {held}");
    assert!(
        sub < held / 10.0,
        "sub-stepped {sub:.2e} m against {held:.2e} m with the mid-step angle held"
    );
}
