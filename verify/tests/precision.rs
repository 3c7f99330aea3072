//! The exact step near its removable singularity, against a 50-digit reference
//! (`verify/precision/reference.py`, mpmath): diff_drive's `step_exact` and
//! `step_exact_jac_p` for omega*dt from 0 through the series switch to 1. Every
//! entry must be within 4e-15 of its output row's scale (today 9e-16): the
//! series has to be long enough (generated with an order-4 series the kernels
//! are off by 5e-12) and the switch far enough out that the closed form has
//! not lost digits to cancellation (with the switch at 1e-3: 4e-13).
use kinegen_generated::diff_drive as dd;
use serde::Deserialize;

#[derive(Deserialize)]
struct Case {
    s: f64,
    x: [f64; 3],
    u: [f64; 2],
    dt: f64,
    pose: [String; 3],
    jac_p: [[String; 5]; 3],
}

#[derive(Deserialize)]
struct Fixture {
    params: [f64; 5],
    cases: Vec<Case>,
}

/// Largest |ours - reference| over a row, relative to the row's largest |reference|.
fn row_error(ours: &[f64], reference: &[String]) -> f64 {
    let r: Vec<f64> = reference.iter().map(|t| t.parse().unwrap()).collect();
    let scale = r.iter().fold(0.0f64, |m, v| m.max(v.abs())).max(1e-300);
    ours.iter()
        .zip(&r)
        .map(|(a, b)| {
            if a.is_finite() {
                (a - b).abs() / scale
            } else {
                f64::INFINITY
            }
        })
        .fold(0.0, f64::max)
}

#[test]
fn exact_step_matches_a_50_digit_reference_across_the_series_switch() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/precision/near_zero.json");
    let fx: Fixture = serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    let mut worst = (0.0f64, 0.0f64);
    for c in &fx.cases {
        let (pose, _, jac_p) = dd::step_exact_with_jac_p(&c.x, &c.u, &[0.0, 0.0], &fx.params, c.dt);
        let alone = (
            dd::step_exact(&c.x, &c.u, &[0.0, 0.0], &fx.params, c.dt),
            dd::step_exact_jac_p(&c.x, &c.u, &[0.0, 0.0], &fx.params, c.dt),
        );
        assert_eq!(
            (pose, jac_p),
            alone,
            "fused and single kernels differ at s = {}",
            c.s
        );
        // the pose as one row (x and y share a scale); theta is exact up to rounding
        let e_pose = row_error(&pose[..2], &c.pose[..2]).max(row_error(&pose[2..], &c.pose[2..]));
        let e_jac = (0..3)
            .map(|i| row_error(&jac_p[i], &c.jac_p[i]))
            .fold(0.0, f64::max);
        assert!(
            e_pose < 4e-15 && e_jac < 4e-15,
            "at omega*dt = {}: pose off by {e_pose:.1e}, jac_p by {e_jac:.1e} of the row's scale",
            c.s
        );
        worst = (worst.0.max(e_pose), worst.1.max(e_jac));
    }
    eprintln!(
        "worst relative error: pose {:.1e}, jac_p {:.1e}",
        worst.0, worst.1
    );
}
