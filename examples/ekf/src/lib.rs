//! Seed 001's extended Kalman filter (eq. 1-9) for a unicycle with mapped
//! range-bearing beacons, written only against the generated kernels of
//! `spec/unicycle_ekf.toml`: the exact step and its Jacobians with respect to
//! the state (F, eq. 4) and the actuator noise (G, eq. 5), and the landmark
//! observation with its Jacobian (H, eq. 6-7). No allocation, no std: the same
//! code runs on a robot's microcontroller. (`kinegen localize` is the same
//! filter over logs, on the IR evaluator.)
#![no_std]
use kinegen_generated::unicycle_ekf as model;
use nalgebra::{Matrix2, Matrix2x3, Matrix3, Matrix3x2, Vector2, Vector3};

/// Wrap an angle to (-pi, pi] (no libm needed: innovations are small).
fn wrap(mut a: f64) -> f64 {
    use core::f64::consts::PI;
    while a > PI {
        a -= 2.0 * PI;
    }
    while a <= -PI {
        a += 2.0 * PI;
    }
    a
}

pub struct Ekf {
    /// Pose estimate (x, y, theta) and its covariance.
    pub x: Vector3<f64>,
    pub cov: Matrix3<f64>,
    /// Actuator noise covariance (the spec's `[[noise]]`: dv, domega).
    pub q: Matrix2<f64>,
    /// Range-bearing noise covariance.
    pub r: Matrix2<f64>,
    /// Model parameters, in `model::PARAMS` order.
    pub p: [f64; 1],
    /// NIS above which an observation is rejected (chi-square, 2 dof, 99%).
    pub gate: f64,
}

impl Ekf {
    pub fn new(x0: [f64; 3], sigma0: [f64; 3], noise: [f64; 2], sensor: [f64; 2]) -> Ekf {
        Ekf {
            x: Vector3::from(x0),
            cov: Matrix3::from_diagonal(&Vector3::from(sigma0.map(|s| s * s))),
            q: Matrix2::from_diagonal(&Vector2::from(noise.map(|s| s * s))),
            r: Matrix2::from_diagonal(&Vector2::from(sensor.map(|s| s * s))),
            p: model::PARAM_NOMINAL,
            gate: 9.21,
        }
    }

    /// Prediction over one step with inputs `u` (eq. 2-5).
    pub fn predict(&mut self, u: &[f64; 2], dt: f64) {
        let x: [f64; 3] = self.x.into();
        let w = [0.0; 2];
        let f = Matrix3::from_fn(|i, j| model::step_exact_jac_x(&x, u, &w, &self.p, dt)[i][j]);
        let jw = model::step_exact_jac_w(&x, u, &w, &self.p, dt);
        let g = Matrix3x2::from_fn(|i, j| jw[i][j]);
        self.x = Vector3::from(model::step_exact(&x, u, &w, &self.p, dt));
        self.cov = f * self.cov * f.transpose() + g * self.q * g.transpose();
    }

    /// Update with a range-bearing observation `z` of the landmark at `lm`
    /// (eq. 6-9, Joseph form). Returns the NIS, or None when the gate rejects it.
    pub fn update(&mut self, z: [f64; 2], lm: [f64; 2], u: &[f64; 2]) -> Option<f64> {
        let x: [f64; 3] = self.x.into();
        let pred = model::obs_landmark(&x, u, &self.p, &lm);
        let jh = model::obs_landmark_jac_x(&x, u, &self.p, &lm);
        let h = Matrix2x3::from_fn(|i, j| jh[i][j]);
        let y = Vector2::new(z[0] - pred[0], wrap(z[1] - pred[1]));
        let s = h * self.cov * h.transpose() + self.r;
        let si = s.try_inverse()?;
        let nis = (y.transpose() * si * y)[(0, 0)];
        // a NaN innovation is rejected like one beyond the gate
        if nis.is_nan() || nis > self.gate {
            return None;
        }
        let k = self.cov * h.transpose() * si;
        self.x += k * y;
        self.x[2] = wrap(self.x[2]);
        let ikh = Matrix3::identity() - k * h;
        self.cov = ikh * self.cov * ikh.transpose() + k * self.r * k.transpose();
        Some(nis)
    }
}
