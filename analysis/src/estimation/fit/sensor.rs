//! Calibrating a range-bearing sensor on its own: the parameters that only
//! its readings feel (a camera reading depth, a range scale, a turned
//! mount), fitted to the landmark sightings seen from the ground-truth pose.
//!
//! Seen from the ground truth, the sightings do not depend on the motion
//! model, so these parameters are a separate problem from the motion's, and
//! are solved apart: with Huber's loss (a misread barcode does not decide
//! them), and with standard deviations from a jackknife over stretches of the
//! sightings (a camera's errors persist for seconds, so the sightings are not
//! independent). In the motion's least squares they were judged against the
//! residual variance of the whole fit, which the dead-reckoned poses set: on
//! a simulated robot slipping 9 cm off its model, a camera's depth share (1)
//! was called unidentified and left at 0.01, its scale at -0.04 (true 0.03).
//! [`super::fit`] and `crate::diagnosis::sensor` both use this.
use super::sightings_from_truth;
use crate::logs::rows::Rows;
use crate::model_on_log::model::Runner;
use crate::model_on_log::robust::robust_sd;
use crate::model_on_log::run::Run;
use kinegen_model::decl::ObservationRole::RangeBearing;
use nalgebra::{DMatrix, DVector};
use serde::Serialize;

/// Stretches of the sightings the test holds out in turn. More than the
/// motion's 8 (`crate::diagnosis::folds`): a stretch's calibration here costs a few
/// evaluations of the observation per sighting, not a dead-reckoned log, and
/// the t-test's power grows with the stretches (its critical value at 1e-3
/// falls from 4.8 to 3.7). On a 15-minute log a stretch is about a minute,
/// as long as a camera's errors persist (localize estimates 78 s on MRCLAM).
pub const FOLDS: usize = 16;

/// Fewest sightings per stretch for the test to run.
pub const MIN_PER_FOLD: usize = 20;

/// Huber's threshold, in units of each channel's robust scale: a residual
/// beyond it counts linearly (a misread barcode, a landmark half hidden).
const HUBER: f64 = 3.0;

/// Fewest stretches worth calibrating apart and testing on (as the
/// motion's folds: below them a t-test has too little power).
pub const MIN_STRETCHES: usize = 5;

/// Gauss-Newton passes of a calibration (the sensor's parameters enter the
/// sightings nearly linearly: 3-6 passes converge).
const PASSES: usize = 30;

/// Whether an effect's parameters change only what the range-bearing sensor
/// reads: neither the motion (twist, step), nor a timing, nor another
/// observation.
pub fn sensor_only(aug: &Runner, effect_params: &[usize]) -> bool {
    aug.only_observed_by(effect_params, RangeBearing)
}

/// Why the sensor's effects were not tested.
#[derive(Debug, Clone, PartialEq, Serialize, thiserror::Error)]
pub enum SensorUnmeasured {
    #[error("the logs have no ground-truth pose beside their landmark sightings to see them from")]
    NoTruth,
    #[error("{0} landmark sightings beside the ground truth; testing the sensor stretch by stretch needs {need}", need = MIN_STRETCHES * MIN_PER_FOLD)]
    TooFew(usize),
}

/// The sightings of every run with a ground truth, as one problem: the
/// runs, each channel's robust scale at the current model, and the stretch
/// each sighting belongs to.
pub struct Sightings<'a> {
    runs: Vec<&'a Run>,
    /// Robust scale (1.4826 MAD) of the range and the bearing residual, in
    /// units of the spec's sigma, at the current model.
    scale: [f64; 2],
    /// Stretch of each sighting, in run and time order.
    pub fold: Vec<usize>,
    pub folds: usize,
}

impl<'a> Sightings<'a> {
    pub fn of(r: &Runner, p: &[f64], runs: &'a [Run]) -> Result<Self, SensorUnmeasured> {
        let runs: Vec<&Run> = runs
            .iter()
            .filter(|x| x.gt.is_some() && !x.landmarks.is_empty())
            .collect();
        if runs.is_empty() {
            return Err(SensorUnmeasured::NoTruth);
        }
        let mut s = Sightings {
            runs,
            scale: [1.0, 1.0],
            fold: Vec::new(),
            folds: 0,
        };
        // counted by their residuals: a sighting the truth cannot place
        // (innovations::truth_at) has none
        let (res, _) = s.residuals(r, p, &[], false);
        let n = res.len() / 2;
        if n < MIN_STRETCHES * MIN_PER_FOLD {
            return Err(SensorUnmeasured::TooFew(n));
        }
        s.folds = FOLDS.min(n / MIN_PER_FOLD);
        s.fold = (0..n).map(|k| k * s.folds / n).collect();
        s.scale = [0, 1].map(|c| robust_scale(res.iter().skip(c).step_by(2).copied()));
        Ok(s)
    }

    pub fn count(&self) -> usize {
        self.fold.len()
    }

    /// Residuals in units of the spec's sigmas (range, bearing per
    /// sighting), and their Jacobian in `free`.
    pub fn residuals(&self, r: &Runner, p: &[f64], free: &[usize], jac: bool) -> (Vec<f64>, Rows) {
        let (mut res, mut rows) = (Vec::new(), Rows::new(free.len()));
        for run in &self.runs {
            let (e, j) = sightings_from_truth(r, p, free, run, jac);
            res.extend(e);
            for row in j.iter() {
                rows.push(row.iter().copied());
            }
        }
        (res, rows)
    }

    /// Mean Huber loss of the sightings whose stretch `keep` accepts.
    pub fn loss(&self, res: &[f64], keep: impl Fn(usize) -> bool) -> f64 {
        let (mut sum, mut n) = (0.0, 0usize);
        for (i, &e) in res.iter().enumerate() {
            if keep(self.fold[i / 2]) {
                sum += huber(e / self.scale[i % 2]);
                n += 1;
            }
        }
        sum / n.max(1) as f64
    }

    /// Calibrate `free` of `r` from `p` on the stretches `keep` accepts:
    /// Gauss-Newton on the Huber loss (iteratively reweighted), within the
    /// parameters' bounds.
    pub fn calibrate(
        &self,
        r: &Runner,
        p: &[f64],
        free: &[usize],
        keep: impl Fn(usize) -> bool,
    ) -> Vec<f64> {
        let bounds = r.ir.runtime_params();
        let mut p = p.to_vec();
        let (mut res, mut jac) = self.residuals(r, &p, free, true);
        let mut loss = self.loss(&res, &keep);
        for _ in 0..PASSES {
            let m = free.len();
            let (mut a, mut b) = (DMatrix::zeros(m, m), DVector::zeros(m));
            for (i, &e) in res.iter().enumerate() {
                if !keep(self.fold[i / 2]) {
                    continue;
                }
                let s = self.scale[i % 2];
                let z = e / s;
                let w = if z.abs() <= HUBER {
                    1.0
                } else {
                    HUBER / z.abs()
                };
                let g = DVector::from_iterator(m, jac[i].iter().map(|x| x / s));
                a += w * &g * g.transpose();
                b += w * z * &g;
            }
            let Some(step) = (a + DMatrix::identity(m, m) * 1e-9).lu().solve(&(-b)) else {
                break;
            };
            let mut trial = p.clone();
            for (k, &i) in free.iter().enumerate() {
                let (lo, hi) = (
                    bounds[i].min.unwrap_or(f64::MIN),
                    bounds[i].max.unwrap_or(f64::MAX),
                );
                trial[i] = (p[i] + step[k]).clamp(lo, hi);
            }
            let (res_t, jac_t) = self.residuals(r, &trial, free, true);
            let loss_t = self.loss(&res_t, &keep);
            // a NaN loss is no improvement either
            if loss_t.partial_cmp(&loss) != Some(std::cmp::Ordering::Less) {
                break;
            }
            let done = loss - loss_t < 1e-9 * loss;
            (p, res, jac, loss) = (trial, res_t, jac_t, loss_t);
            if done {
                break;
            }
        }
        p
    }
}

/// Huber's loss of a residual in units of its scale.
fn huber(z: f64) -> f64 {
    if z.abs() <= HUBER {
        0.5 * z * z
    } else {
        HUBER * (z.abs() - 0.5 * HUBER)
    }
}

/// [`robust_sd`], or 1 where there is no spread (a scale to divide by).
fn robust_scale(v: impl Iterator<Item = f64>) -> f64 {
    let s = robust_sd(v);
    if s > 0.0 {
        s
    } else {
        1.0
    }
}

/// A sensor calibration: the parameters, and each stretch's held out.
pub struct SensorFit {
    /// The whole parameter vector, `free` calibrated on every stretch.
    pub p: Vec<f64>,
    /// The jackknife standard deviation of each of `free`.
    pub std: Vec<f64>,
    /// Per stretch: the loss of its sightings calibrated without them, and
    /// that calibration.
    pub held_out: Vec<(f64, Vec<f64>)>,
}

/// Calibrate `free` of `r` from `start` on all of `s`'s sightings, and once
/// without each stretch in turn.
pub fn calibrate_with_folds(s: &Sightings, r: &Runner, start: &[f64], free: &[usize]) -> SensorFit {
    let p = s.calibrate(r, start, free, |_| true);
    let held_out: Vec<(f64, Vec<f64>)> = (0..s.folds)
        .map(|k| {
            let pk = s.calibrate(r, &p, free, |f| f != k);
            let (rk, _) = s.residuals(r, &pk, &[], false);
            (s.loss(&rk, |f| f == k), pk)
        })
        .collect();
    let std = free
        .iter()
        .map(|&i| {
            let est: Vec<f64> = held_out.iter().map(|(_, pk)| pk[i]).collect();
            let k = est.len() as f64;
            let mean = est.iter().sum::<f64>() / k;
            ((k - 1.0) / k * est.iter().map(|e| (e - mean).powi(2)).sum::<f64>()).sqrt()
        })
        .collect();
    SensorFit { p, std, held_out }
}

/// The free parameters of `r` that only its range-bearing observation reads.
pub fn sensor_params(r: &Runner) -> Vec<usize> {
    r.free
        .iter()
        .copied()
        .filter(|&i| sensor_only(r, &[i]))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn huber_is_quadratic_inside_and_linear_outside() {
        assert_eq!(huber(2.0), 2.0);
        assert_eq!(huber(-5.0), HUBER * (5.0 - 0.5 * HUBER));
        // continuous at the threshold
        assert!((huber(HUBER) - HUBER * (HUBER - 0.5 * HUBER)).abs() < 1e-12);
    }

    #[test]
    fn robust_scale_ignores_an_outlier() {
        let v = [-1.0, -0.5, 0.0, 0.5, 1.0, 1000.0];
        let s = robust_scale(v.into_iter());
        assert!(s < 1.5, "{s}");
    }
}
