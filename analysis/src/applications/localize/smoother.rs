//! The fixed-interval Rauch-Tung-Striebel smoother over a filter pass: every
//! estimate also uses the sightings after it (offline use: mapping,
//! calibration targets, judging a log afterwards).
use super::filter::Pass;
use crate::logs::log::wrap;
use nalgebra::{Matrix3, Vector3};

/// The smoothed pose and covariance at every row of a pass kept with its nodes.
pub fn smooth(pass: &Pass) -> (Vec<[f64; 3]>, Vec<Matrix3<f64>>) {
    let nodes = &pass.nodes;
    let n = nodes.len();
    let mut xs: Vec<Vector3<f64>> = vec![Vector3::zeros(); n];
    let mut ps: Vec<Matrix3<f64>> = vec![Matrix3::zeros(); n];
    xs[n - 1] = nodes[n - 1].x;
    ps[n - 1] = nodes[n - 1].p;
    for i in (0..n - 1).rev() {
        let (now, next) = (&nodes[i], &nodes[i + 1]);
        // C = P_i F^T (P_pred_{i+1})^-1; a singular prediction (nothing
        // moved, no noise) passes the later estimate through unchanged
        let c = match next.p_pred.try_inverse() {
            Some(inv) => now.p * next.f.transpose() * inv,
            None => Matrix3::identity(),
        };
        let mut dx = xs[i + 1] - next.x_pred;
        dx[2] = wrap(dx[2]);
        xs[i] = now.x + c * dx;
        let p = now.p + c * (ps[i + 1] - next.p_pred) * c.transpose();
        // keep it symmetric against rounding
        ps[i] = (p + p.transpose()) * 0.5;
    }
    pass.row_node
        .iter()
        .map(|&i| ([xs[i][0], xs[i][1], xs[i][2]], ps[i]))
        .unzip()
}
