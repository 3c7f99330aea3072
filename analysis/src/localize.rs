//! EKF localisation with mapped landmarks (seed 001 eq. 1-9) on the model's own
//! kernels: predict with the exact step and its Jacobians with respect to the
//! state (F, eq. 4) and the process noise (G, eq. 5), Q from the spec's
//! `[[noise]]` sigmas; update with the range-bearing observation and its
//! Jacobian (H, eq. 6-7), R from its sigmas. Innovations beyond a chi-square
//! gate are rejected and counted. Consistency: NIS (always) and NEES (against
//! ground truth, when the log has it and the model measures the body pose
//! directly) against their chi-square bounds.
use crate::log::wrap;
use crate::model::Runner;
use crate::run::Run;
use kinegen_model::decl::ObservationRole::{Pose, RangeBearing};
use kinegen_model::ir::StepForm;
use nalgebra::{DMatrix, DVector, Matrix3, Vector3};

#[derive(Debug, Clone)]
pub struct EkfOptions {
    /// NIS above which an observation is rejected (chi-square, 2 dof: 9.21 is
    /// the 99% point).
    pub gate: f64,
    /// Start-pose standard deviations (x, y m; theta rad).
    pub start_sigma: [f64; 3],
    /// Process-noise sigmas by `[[noise]]` name, replacing the spec's.
    pub noise_sigma: Vec<(String, f64)>,
}

impl Default for EkfOptions {
    fn default() -> Self {
        EkfOptions {
            gate: 9.21,
            start_sigma: [0.05, 0.05, 0.02],
            noise_sigma: Vec::new(),
        }
    }
}

/// One run's filter output.
#[derive(Debug, Clone)]
pub struct Localization {
    /// Estimated pose at every row, and its covariance.
    pub track: Vec<[f64; 3]>,
    pub cov: Vec<Matrix3<f64>>,
    /// Normalised innovation squared of each accepted observation.
    pub nis: Vec<f64>,
    /// Normalised estimation error squared at each row with ground truth.
    pub nees: Vec<f64>,
    pub accepted: usize,
    pub rejected: usize,
}

/// Chi-square quantile (Wilson-Hilferty; within 1% for k >= 3): the p-quantile
/// of a chi-square variable with k degrees of freedom, for the z-score of p.
fn chi2_quantile(k: f64, z: f64) -> f64 {
    let a = 2.0 / (9.0 * k);
    k * (1.0 - a + z * a.sqrt()).powi(3)
}

/// 95% bounds of the mean of n chi-square values with `dof` degrees of freedom.
pub fn mean_bounds(n: usize, dof: f64) -> (f64, f64) {
    let k = n as f64 * dof;
    (
        chi2_quantile(k, -1.959964) / n as f64,
        chi2_quantile(k, 1.959964) / n as f64,
    )
}

/// Run the filter over one run.
pub fn localize(r: &Runner, run: &Run, o: &EkfOptions) -> Result<Localization, String> {
    let h =
        r.ir.observation_kernels(RangeBearing)
            .map(|o| o.value)
            .ok_or("the model has no range-bearing (`landmark = true`) observation")?;
    let hx =
        r.ir.observation_kernels(RangeBearing)
            .map(|o| o.jac_x)
            .ok_or("the model has no range-bearing observation Jacobian")?;
    let exact = r.ir.step(StepForm::Exact);
    let (step, fx, fw) = (exact.value, exact.jac_x, exact.jac_w);
    let nw = r.ir.noise.len();
    let q = DMatrix::from_diagonal(&DVector::from_iterator(
        nw,
        r.ir.noise.iter().map(|n| {
            let s = o
                .noise_sigma
                .iter()
                .find(|(name, _)| *name == n.name)
                .map_or(n.sigma, |(_, s)| *s);
            s * s
        }),
    ));
    let sig = crate::landmarks::sigma(r);
    let rm = nalgebra::Matrix2::new(sig[0] * sig[0], 0.0, 0.0, sig[1] * sig[1]);
    let p = &r.p;
    let zeros = vec![0.0; nw.max(1)];
    let mut x = Vector3::from(crate::deadreckon::model_start(r, p, run));
    let mut cov = Matrix3::from_diagonal(&Vector3::from(o.start_sigma.map(|s| s * s)));
    let mut out = Localization {
        track: vec![x.into()],
        cov: vec![cov],
        nis: Vec::new(),
        nees: Vec::new(),
        accepted: 0,
        rejected: 0,
    };
    // NEES needs the body pose measured directly
    let gt = run.gt.as_ref().filter(|_| r.ir.observation(Pose).is_none());
    let mut obs = run.landmarks.iter().peekable();
    for k in 0..run.steps() {
        // predict (eq. 2-5)
        let (xs, dt) = ([x[0], x[1], x[2]], [run.dt[k]]);
        let args = Runner::step_args(step, &xs, &run.u[k], p, &dt, &zeros);
        let next = step.eval(&args);
        let f = Matrix3::from_row_slice(
            &fx.eval(&Runner::step_args(fx, &xs, &run.u[k], p, &dt, &zeros)),
        );
        cov = f * cov * f.transpose();
        if let (Some(fw), true) = (fw, nw > 0) {
            let g = DMatrix::from_row_slice(
                3,
                nw,
                &fw.eval(&Runner::step_args(fw, &xs, &run.u[k], p, &dt, &zeros)),
            );
            let gq = &g * &q * g.transpose();
            cov += Matrix3::from_fn(|a, b| gq[(a, b)]);
        }
        x = Vector3::new(next[0], next[1], next[2]);
        // update with the observations up to the end of the step (eq. 6-9)
        while let Some(z) = obs.next_if(|z| z.t <= run.t[k + 1]) {
            let xs = [x[0], x[1], x[2]];
            let lm = [z.xl, z.yl];
            let pred = h.eval(&Runner::obs_args(h, &xs, &run.u[k], p, &lm));
            let hm = nalgebra::Matrix2x3::from_row_slice(
                &hx.eval(&Runner::obs_args(hx, &xs, &run.u[k], p, &lm)),
            );
            let y = nalgebra::Vector2::new(z.range - pred[0], wrap(z.bearing - pred[1]));
            let s = hm * cov * hm.transpose() + rm;
            let Some(si) = s.try_inverse() else {
                out.rejected += 1;
                continue;
            };
            let nis = (y.transpose() * si * y)[(0, 0)];
            if !nis.is_finite() || nis > o.gate {
                out.rejected += 1;
                continue;
            }
            let gain = cov * hm.transpose() * si;
            x += gain * y;
            // Joseph form: stays symmetric positive semi-definite
            let ikh = Matrix3::identity() - gain * hm;
            cov = ikh * cov * ikh.transpose() + gain * rm * gain.transpose();
            out.nis.push(nis);
            out.accepted += 1;
        }
        if !x.iter().all(|v| v.is_finite()) {
            return Err(format!(
                "{}: the filter diverged at t = {}",
                run.path,
                run.t[k + 1]
            ));
        }
        out.track.push(x.into());
        out.cov.push(cov);
        if let Some(g) = gt {
            let e = Vector3::new(
                x[0] - g[k + 1][0],
                x[1] - g[k + 1][1],
                wrap(x[2] - g[k + 1][2]),
            );
            if let Some(ci) = cov.try_inverse() {
                out.nees.push((e.transpose() * ci * e)[(0, 0)]);
            }
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn chi_square_bounds_bracket_the_degrees_of_freedom() {
        let (lo, hi) = mean_bounds(100, 2.0);
        assert!(lo < 2.0 && hi > 2.0 && (hi - lo) < 1.2, "{lo} {hi}");
        // 95% of chi2(30): 16.79 .. 46.98
        assert!((chi2_quantile(30.0, -1.959964) - 16.79).abs() < 0.3);
        assert!((chi2_quantile(30.0, 1.959964) - 46.98).abs() < 0.3);
    }
}
