//! Calibration that knows what one session cannot tell (issue 70, item 5).
//!
//! A log that barely excites a parameter still gives it a least-squares
//! estimate. A straight back-and-forth run says almost nothing about a
//! wheelbase. Its drift-aware standard deviation is then large, yet the
//! estimate was used as if it were known. Calibrated on single straight runs
//! of a real differential drive (../shared/real/optiodom-dev, the Ivanjko
//! sessions' first runs), the wheelbase came out at 0.29-0.33 m from 0.2
//! (±13-78% by its own standard deviation). It made the robot's other
//! sessions dead-reckon 6-48x worse than the nominal values, without a
//! warning.
//!
//! A nominal value from a drawing or a datasheet is itself a measurement, and
//! this module treats it as one. Where the spec declares no `tolerance`, it
//! has a relative standard deviation of [`DEFAULT_TOLERANCE`]; a declared one
//! already enters the fit's cost as its prior (`residuals::priors`). The
//! fit's deviation from the nominal values is then updated along the
//! eigen-directions of its drift-aware covariance, measured in those
//! tolerances ([`Update`]):
//!
//! - directions the data pin down far better than the nominal is known keep
//!   the fitted value;
//! - directions the data know worse stay at the nominal value;
//! - parameters correlated with those follow through the covariance;
//! - a nominal value the data contradict is not held to ([`kept_share`]),
//!   and an update the covariance cannot be trusted for (a misspecified
//!   model's) is not made.
//!
//! The fit's own search stays maximum likelihood: diagnosis compares its
//! costs by BIC and calls [`super::fit`], not this. This step is applied
//! where a calibration is handed to the user: the `lm` method (`fit`, the
//! Python API) and `bench-real`.
pub use super::options::{HeldNearNominal, Motion};
use super::{correlation, starts_for, FitOptions, FitResult};
use crate::model_on_log::model::Runner;
use crate::model_on_log::run::Run;
use nalgebra::{DMatrix, DVector};

/// The relative standard deviation of a nominal value where the spec
/// declares no `tolerance`: 10%. Wheel radii and tracks from a drawing are
/// usually within a few percent of the effective values a calibration finds
/// (the OptiOdom robots' published calibrations: 0.1-3%). The exceptions
/// (a skid-steer's effective track, a tyre's loaded radius) are determined
/// well by any log that turns or drives, and a prior this wide costs them
/// almost nothing: a parameter the data know to 3% keeps 99% of its fitted
/// deviation ([`Update`]).
pub const DEFAULT_TOLERANCE: f64 = 0.10;

/// The parameters of `res.free` that get the default prior: declared without
/// a `tolerance`, a nominal value other than 0 (a relative tolerance needs a
/// scale; effect terms start at 0), not a delay or a lag, and with a finite
/// standard deviation (an undetermined one is already held at its start).
fn with_default_prior(r: &Runner, res: &FitResult) -> Vec<usize> {
    let params = r.ir.runtime_params();
    (0..res.free.len())
        .filter(|&k| {
            let i = res.free[k];
            let q = params[i];
            q.tolerance.is_none()
                && r.p[i] != 0.0
                && !(q.measurement_delay || q.input_delay || q.input_lag)
                && res.std.get(k).is_some_and(|s| s.is_finite() && *s > 0.0)
        })
        .collect()
}

/// `res` (a fit of `r` on `runs` from `r.p`) with the directions the data
/// know worse than the nominal values held near them (see the module doc):
/// its parameters, standard deviations, correlations and start offsets
/// updated, its cost taken again, and a warning for each parameter the data
/// alone knew worse than its nominal value.
pub fn toward_nominal(r: &Runner, runs: &[Run], o: &FitOptions, mut res: FitResult) -> FitResult {
    let prior = with_default_prior(r, &res);
    if prior.is_empty() {
        return res;
    }
    let m = res.free.len();
    // only the parameters with a finite standard deviation take part
    let known: Vec<usize> = (0..m).filter(|&k| res.std[k].is_finite()).collect();
    let cov = DMatrix::from_fn(known.len(), known.len(), |a, b| {
        let (ka, kb) = (known[a], known[b]);
        res.corr[(ka, kb)] * res.std[ka] * res.std[kb]
    });
    let at: Vec<usize> = prior
        .iter()
        .map(|k| {
            known
                .iter()
                .position(|j| j == k)
                .expect("a prior's std is finite")
        })
        .collect();
    let tolerance: Vec<f64> = prior
        .iter()
        .map(|&k| DEFAULT_TOLERANCE * r.p[res.free[k]].abs())
        .collect();
    let from_nominal = DVector::from_fn(known.len(), |a, _| {
        let i = res.free[known[a]];
        res.p[i] - r.p[i]
    });
    let deviation = DVector::from_fn(at.len(), |b, _| from_nominal[at[b]]);
    let Some(update) = Update::new(&cov, &at, &tolerance, &deviation) else {
        return res;
    };
    let moved = &update.map * from_nominal;
    let posterior = update.covariance(&cov);
    let data: Vec<(f64, f64)> = prior
        .iter()
        .map(|&k| (res.p[res.free[k]], res.std[k]))
        .collect();
    // what the update moves: nothing worth a new start (a hundredth of a
    // standard deviation) where the data determine every direction well
    let moves = known.iter().enumerate().any(|(a, &k)| {
        let i = res.free[k];
        (r.p[i] + moved[a] - res.p[i]).abs() > 0.01 * res.std[k]
    });
    let params = r.ir.runtime_params();
    // Each parameter ends between its nominal and fitted values, give or
    // take two of its standard deviations, and inside its bounds; else the
    // covariance is no guide (a misspecified model: a tricycle with a
    // hidden steering offset knew its axle, wheel and steering gain to
    // 100-360% and r = 0.99 correlations, and the update took the axle
    // through 0), and the fit stands as the data made it.
    let plausible = known.iter().enumerate().all(|(a, &k)| {
        let (i, sd) = (res.free[k], 2.0 * res.std[k]);
        let v = r.p[i] + moved[a];
        let (q, fit) = (params[i], res.p[i]);
        v >= r.p[i].min(fit) - sd
            && v <= r.p[i].max(fit) + sd
            && q.min.is_none_or(|lo| v > lo)
            && q.max.is_none_or(|hi| v < hi)
    });
    if moves && plausible {
        for (a, &k) in known.iter().enumerate() {
            let i = res.free[k];
            res.p[i] = r.p[i] + moved[a];
            res.std[k] = posterior[(a, a)].max(0.0).sqrt();
        }
        let corr = correlation(&posterior);
        for (a, &ka) in known.iter().enumerate() {
            for (b, &kb) in known.iter().enumerate() {
                res.corr[(ka, kb)] = corr[(a, b)];
            }
        }
        // the start headings refined for the new values, and the cost there
        (res.starts, res.cost_after) = starts_for(r, &res.p, runs, o);
    }
    let corners = input_corners(runs);
    let held: Vec<HeldNearNominal> = prior
        .iter()
        .zip(&tolerance)
        .zip(&data)
        .map(
            |((&k, &tolerance), &(data_estimate, data_std))| HeldNearNominal {
                param: res.free[k],
                tolerance,
                nominal: r.p[res.free[k]],
                estimate: res.p[res.free[k]],
                data_estimate,
                data_std,
                excited_by: excited_by(r, &res.p, &corners, res.free[k]),
            },
        )
        .collect();
    for h in held.iter().filter(|h| h.barely_determined()) {
        res.warnings.push(warning(r, h));
    }
    res.near_nominal = held;
    res
}

/// How far the data may contradict a nominal value before it is no longer
/// trusted: 3 standard deviations (of the data's and the nominal value's
/// together) along a direction.
const CONFLICT: f64 = 3.0;

/// The share of its fitted deviation a direction keeps (see [`Update`]):
/// 1 / (1 + l^2) for a direction the data know to a variance `l` in units of
/// the tolerance's, while the deviation is `z` combined standard deviations
/// at most [`CONFLICT`]. Beyond, the data contradict the nominal value (a
/// drawing 10x off: a real tricycle's axle started at 0.015 m, fitted to
/// 0.157 m, 55 combined standard deviations), and its weight falls as
/// (CONFLICT / z)^4.
fn kept_share(l: f64, z: f64) -> f64 {
    let trust = if z > CONFLICT {
        (CONFLICT / z).powi(4)
    } else {
        1.0
    };
    1.0 / (1.0 + l * l * trust)
}

/// The linear update of a fit's deviation from the nominal values, over the
/// parameters with a finite standard deviation.
///
/// In the prior's parameters, scaled by their tolerances (the prior is then
/// the identity), the data's covariance has eigen-directions v_i with
/// variances l_i. Along each, the fitted deviation is kept by the factor
/// f_i = 1 / (1 + l_i^2): 1 where the data know the direction far better
/// than the nominal value (l_i << 1), 0 where far worse, one half where
/// equally well; and 1 again where the data contradict the nominal value
/// ([`kept_share`]). (The Gaussian posterior's factor, 1 / (1 + l_i), keeps a
/// direction the data know to four times the tolerance at 6% of its fitted
/// deviation, which on the real straight runs was still a 3.7% wheelbase
/// and 3.7x the nominal values' error elsewhere; and it pulls a
/// well-determined direction toward the nominal value by l_i of its
/// deviation, a bias of a standard deviation for a skid-steer's effective
/// track 50% from its drawing. This factor does neither.) The other
/// parameters follow through their regression on the prior's.
struct Update {
    /// deviation from nominal after = map * deviation before
    map: DMatrix<f64>,
    /// the nominal values' covariance along the directions held to them
    held: DMatrix<f64>,
}

impl Update {
    fn new(
        cov: &DMatrix<f64>,
        at: &[usize],
        tolerance: &[f64],
        deviation: &DVector<f64>,
    ) -> Option<Update> {
        let n = cov.nrows();
        let scaled = DMatrix::from_fn(at.len(), at.len(), |a, b| {
            cov[(at[a], at[b])] / (tolerance[a] * tolerance[b])
        });
        let eig = scaled.symmetric_eigen();
        let l = &eig.eigenvalues;
        if l.iter().any(|x| !x.is_finite() || *x <= 0.0) {
            return None;
        }
        let v = &eig.eigenvectors;
        let s = DMatrix::from_diagonal(&DVector::from_row_slice(tolerance));
        let s_inv = DMatrix::from_diagonal(&DVector::from_fn(at.len(), |a, _| 1.0 / tolerance[a]));
        // the fitted deviation along each direction, in its combined
        // standard deviations (the data's and the nominal value's)
        let along = v.transpose() * &s_inv * deviation;
        let f = DMatrix::from_fn(at.len(), at.len(), |a, b| {
            if a == b {
                kept_share(l[a], along[a].abs() / (l[a] + 1.0).sqrt())
            } else {
                0.0
            }
        });
        let keep = &s * v * &f * v.transpose() * &s_inv;
        // the prior's parameters' covariance inverted through its eigen-directions
        let l_inv = DMatrix::from_diagonal(&l.map(|x| 1.0 / x));
        let c_pp_inv = &s_inv * v * l_inv * v.transpose() * &s_inv;
        let c_op = DMatrix::from_fn(n, at.len(), |a, b| cov[(a, at[b])]);
        let change = &keep - DMatrix::identity(at.len(), at.len());
        let follow = &c_op * c_pp_inv * &change;
        let mut map = DMatrix::identity(n, n);
        for (b, &j) in at.iter().enumerate() {
            for a in 0..n {
                map[(a, j)] += follow[(a, b)];
            }
        }
        // the prior's own rows: exactly `keep` (the regression reproduces
        // it only up to round-off)
        for (a, &i) in at.iter().enumerate() {
            for (b, &j) in at.iter().enumerate() {
                map[(i, j)] = keep[(a, b)];
            }
        }
        let one_minus_f = DMatrix::from_diagonal(&f.diagonal().map(|x| 1.0 - x));
        let held_pp = &s * v * one_minus_f * v.transpose() * &s;
        let mut held = DMatrix::zeros(n, n);
        for (a, &i) in at.iter().enumerate() {
            for (b, &j) in at.iter().enumerate() {
                held[(i, j)] = held_pp[(a, b)];
            }
        }
        Some(Update { map, held })
    }

    /// The updated deviation's covariance: the data's, carried through the
    /// map, plus the nominal values' along what is held to them.
    fn covariance(&self, cov: &DMatrix<f64>) -> DMatrix<f64> {
        &self.map * cov * self.map.transpose() + &self.held
    }
}

/// The warning for a parameter the data alone knew worse than its nominal
/// value: what the data said, what is reported instead, and what would
/// determine it.
fn warning(r: &Runner, h: &HeldNearNominal) -> String {
    let i = h.param;
    let nominal = r.p[i];
    let relative = |x: f64| 100.0 * x / nominal.abs();
    let runs = h
        .excited_by
        .map(|m| format!(": {} determine it", m.runs_that_determine()))
        .unwrap_or_default();
    format!(
        "{name} barely determined by these logs (alone: {est:.4} ± {sd:.0}%), so kept near its nominal {nominal}{runs}; a spec `tolerance` sets how far a nominal value is trusted (default ±{tol:.0}%)",
        name = r.names[i],
        est = h.data_estimate,
        sd = relative(h.data_std),
        tol = relative(h.tolerance),
    )
}

/// The corners of the box of inputs `runs` reach: every input at plus or
/// minus its largest magnitude (2^8 corners at most; beyond that, each input
/// alone). Made once for all the parameters [`excited_by`] is asked about.
pub(super) fn input_corners(runs: &[Run]) -> Vec<Vec<f64>> {
    let Some(width) = runs.first().map(|r| r.u.width()) else {
        return Vec::new();
    };
    let mut reach = vec![0.0f64; width];
    for run in runs {
        for k in 0..run.steps() {
            for (c, v) in run.u[k].iter().enumerate() {
                reach[c] = reach[c].max(v.abs());
            }
        }
    }
    if width <= 8 {
        (0..1usize << width)
            .map(|bits| {
                (0..width)
                    .map(|c| {
                        if bits >> c & 1 == 1 {
                            reach[c]
                        } else {
                            -reach[c]
                        }
                    })
                    .collect()
            })
            .collect()
    } else {
        (0..width)
            .flat_map(|c| {
                [1.0, -1.0].map(|s| {
                    (0..width)
                        .map(|d| if d == c { s * reach[c] } else { 0.0 })
                        .collect()
                })
            })
            .collect()
    }
}

/// Which body motion parameter `i` acts on most, relative to that motion's
/// own size, over the `corners` of the logs' input box ([`input_corners`]):
/// a wheelbase scales the turn rate and leaves the forward speed alone,
/// which a log that never turns cannot show.
pub(super) fn excited_by(r: &Runner, p: &[f64], corners: &[Vec<f64>], i: usize) -> Option<Motion> {
    if corners.is_empty() {
        return None;
    }
    let tw = r.ir.twist();
    let h = 1e-4 * p[i].abs().max(1e-9);
    let mut moved = p.to_vec();
    moved[i] += h;
    let (mut change, mut size) = ([0.0f64; 3], [0.0f64; 3]);
    for u in corners {
        let (a, b) = (r.eval(tw, &[u, p]), r.eval(tw, &[u, &moved]));
        if a.len() < 3 || b.len() < 3 {
            return None;
        }
        for j in 0..3 {
            change[j] += (b[j] - a[j]).abs();
            size[j] += a[j].abs();
        }
    }
    let relative: Vec<f64> = (0..3)
        .map(|j| {
            if size[j] > 0.0 {
                change[j] / size[j]
            } else {
                0.0
            }
        })
        .collect();
    let (j, &most) = relative
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.total_cmp(b.1))?;
    (most > 0.0 && most.is_finite()).then(|| Motion::of_twist_component(j))
}
