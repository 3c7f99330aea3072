//! Standard deviations of a fit on whole dead-reckoned runs, whose pose
//! residuals are not independent: the track carries its start pose's
//! measurement error along and accumulates the odometry's own noise as a
//! random walk, so the usual s^2 (J^T J)^-1 counts every row as new
//! information and reports standard deviations many times too small (8x on
//! a clean simulated 364 s log).
//!
//! The sandwich H^-1 M H^-1 with H = J^T J and M = J^T Cov(residuals) J,
//! where the residual covariance comes from a model fitted to the residuals
//! themselves: per pose component, white noise on a random walk ("local
//! level", [`local_level`]), and the anchoring start pose's noise, whose
//! heading error turns the whole track about it. The walk's contribution
//! sum_j A_j Q_j A_j^T, with A_j the Jacobian summed over the rows after
//! step j, takes reverse cumulative sums: O(rows x parameters). Gyro and
//! landmark residuals are taken as white at their own variance.
//!
//! Generalised least squares with the same noise model (whitening the
//! residuals by its Kalman filter) was tried as the estimator itself: its
//! standard deviations came out 1.7-3.3x smaller than the spread of the
//! estimates over 30 simulated seeds, because the residuals' structure (a
//! track's deterministic discretisation error, heading errors integrated into
//! positions) is not a random walk; the sandwich only needs the model for the
//! size of the uncertainty, and came within 30% of that spread.
use super::{correlation, priors, psd_inverse, run_offsets, run_residuals, start_columns};
use super::{rounding, FitOptions, FitResult};
use crate::logs::rows::Rows;
use crate::model_on_log::model::Runner;
use crate::model_on_log::run::Run;
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;

/// White noise on a random walk, in weighted units (residual / sigma).
#[derive(Debug, Clone, Copy, Default)]
struct Level {
    /// Variance of the white part.
    white: f64,
    /// Variance the walk gains per second.
    walk: f64,
}

/// A residual series: the time step before each row, the values, and the
/// variance of the start it is anchored on, in units of the white variance.
type Series = (Vec<f64>, Vec<f64>, f64);

/// The local-level model of residual series fitted by maximum likelihood: a
/// scalar Kalman filter gives the likelihood for a ratio walk / white, with
/// the white variance concentrated out in closed form; the ratio is chosen on
/// a grid of quarter decades (and 0: white only). Window moments were tried
/// first: with 70 windows in a 364 s log their sampling noise alone read as a
/// walk that inflated the standard deviations 30-fold.
fn local_level(series: &[Series]) -> Level {
    let sums = |lambda: f64| {
        let (mut ss, mut logf, mut n) = (0.0, 0.0, 0.0);
        for (dt, y, anchor) in series {
            let (mut w, mut p) = (0.0, *anchor);
            for (dt, y) in dt.iter().zip(y) {
                let pred = p + lambda * dt;
                let f = pred + 1.0;
                let v = y - w;
                ss += v * v / f;
                logf += f.ln();
                n += 1.0;
                let gain = pred / f;
                w += gain * v;
                p = pred * (1.0 - gain);
            }
        }
        (ss, logf, n)
    };
    let mut best: Option<(f64, Level)> = None;
    let grid = std::iter::once(0.0).chain((0..=48).map(|i| 10f64.powf(-9.0 + 0.25 * i as f64)));
    for lambda in grid {
        let (ss, logf, n) = sums(lambda);
        if n < 2.0 || ss <= 0.0 {
            return Level::default();
        }
        let white = ss / n;
        let loglik = -0.5 * n * white.ln() - 0.5 * logf;
        if best.as_ref().is_none_or(|b| loglik > b.0) {
            let walk = lambda * white;
            best = Some((loglik, Level { white, walk }));
        }
    }
    best.map(|b| b.1).unwrap_or_default()
}

/// One run's pose residual rows: (x, y, heading) triples for ground-truth
/// rows 1.., with their Jacobian rows.
struct PoseRows<'a> {
    res: &'a [f64],
    jac: &'a Rows,
    run: &'a Run,
    /// lever-arm factor in weighted units: heading sigma / position sigma
    lever: f64,
    /// Per step, the pose change its inputs' rounding errors make, one
    /// standard deviation each, in weighted units (see [`rounding`]), and
    /// whether the step starts a run of rows logging the same value; empty
    /// where the inputs are not rounded.
    rounding: Vec<Vec<([f64; 3], bool)>>,
}

impl PoseRows<'_> {
    fn rows(&self) -> usize {
        self.run
            .gt
            .as_ref()
            .map_or(0, |g| g.len().saturating_sub(1))
    }

    /// Position (x, y) of residual row k (ground-truth row k + 1).
    fn at(&self, k: usize) -> [f64; 2] {
        let g = &self.run.gt.as_ref().unwrap()[k + 1];
        [g[0], g[1]]
    }

    /// The time step that ends at residual row k.
    fn dt(&self, k: usize) -> f64 {
        self.run.t[k + 1] - self.run.t[k]
    }

    /// The series of component c (x, y, heading).
    fn series(&self, c: usize) -> Series {
        let n = self.rows();
        let anchor = 1.0 / self.run.rest_steps().max(1) as f64;
        let values = (0..n).map(|k| self.res[3 * k + c]).collect();
        ((0..n).map(|k| self.dt(k)).collect(), values, anchor)
    }

    /// M for this run's pose rows: white noise on every row, each
    /// component's walk, and the anchoring start pose's noise. `turned`: the
    /// fit refines the run's start heading.
    fn meat(&self, noise: &[Level; 2], width: usize, turned: bool) -> DMatrix<f64> {
        let n = self.rows();
        let mut meat = DMatrix::zeros(width, width);
        let row = |k: usize, c: usize| DVector::from_column_slice(&self.jac[3 * k + c][..width]);
        let level = |c: usize| noise[usize::from(c == 2)];
        for k in 0..n {
            for c in 0..3 {
                let v = row(k, c);
                meat.ger(level(c).white, &v, &v, 1.0);
            }
        }
        // reverse cumulative sums over rows k >= j of J_x, J_y, J_th: each
        // component's walk, injected during the step that ends at row j,
        // moves that component of every later row. (Each component's walk is
        // fitted to its own series, so a heading walk's effect on the
        // positions is already in theirs and is not carried over again.)
        let zero = || DVector::<f64>::zeros(width);
        let (mut sx, mut sy, mut sth, mut sxy, mut syx) = (zero(), zero(), zero(), zero(), zero());
        let mut shared: Vec<DVector<f64>> = Vec::new();
        for k in (0..n).rev() {
            let p = self.at(k);
            let (jx, jy, jth) = (row(k, 0), row(k, 1), row(k, 2));
            sxy += &jx * p[1];
            syx += &jy * p[0];
            sx += jx;
            sy += jy;
            sth += jth;
            let dt = self.dt(k);
            meat.ger(level(0).walk * dt, &sx, &sx, 1.0);
            meat.ger(level(1).walk * dt, &sy, &sy, 1.0);
            meat.ger(level(2).walk * dt, &sth, &sth, 1.0);
            // an input's rounding in this step moves every later row: its
            // position, and its heading with the lever arm from here. Rows
            // that share one error (see rounding::held) add their moves up
            // before they count, once per run of equal values.
            if let Some(errors) = self.rounding.get(k).filter(|e| !e.is_empty()) {
                let from = self.run.gt.as_ref().unwrap()[k];
                let turn = &sth - (&sxy - &sx * from[1]) * self.lever
                    + (&syx - &sy * from[0]) * self.lever;
                shared.resize(errors.len(), zero());
                for ((e, starts), sum) in errors.iter().zip(shared.iter_mut()) {
                    *sum += &sx * e[0] + &sy * e[1] + &turn * e[2];
                    if *starts {
                        meat.ger(1.0, sum, sum, 1.0);
                        sum.fill(0.0);
                    }
                }
            }
        }
        // The start pose the track is anchored on: the mean of the rows it
        // rests on first (Run::start_pose), each with the white noise. Its
        // heading error turns the whole track about it (the lever arm of
        // every later row), unless the fit refines the start heading: the
        // offset then cancels it, and it is left only in the start heading's
        // prior row, which carries it already.
        let g = self.run.start_pose();
        let rested = self.run.rest_steps().max(1) as f64;
        meat.ger(level(0).white / rested, &sx, &sx, 1.0);
        meat.ger(level(1).white / rested, &sy, &sy, 1.0);
        if !turned {
            let turn = sth - (sxy - &sx * g[1]) * self.lever + (syx - &sy * g[0]) * self.lever;
            meat.ger(level(2).white / rested, &turn, &turn, 1.0);
        }
        meat
    }
}

/// One run's residual rows with their Jacobian (the free parameters, then the
/// run's start heading when it has one): the pose rows, then the rest.
struct RunRows {
    pose: (Vec<f64>, Rows),
    rest: (Vec<f64>, Rows),
    /// the run's start-heading column among all runs', if any
    start_col: Option<usize>,
}

impl RunRows {
    fn pose_rows<'a>(&'a self, run: &'a Run, lever: f64) -> PoseRows<'a> {
        PoseRows {
            res: &self.pose.0,
            jac: &self.pose.1,
            run,
            lever,
            rounding: Vec::new(),
        }
    }
}

/// Per step of `run` with ground truth, the pose change of each rounded
/// input's error at one standard deviation (`sd`, per input), in weighted
/// units (position / `o.pos_sigma`, heading / `o.heading_sigma`), turned to
/// the measured heading at the step's start; and whether the input's logged
/// value changes there (a new error starts).
fn rounding_effects(
    r: &Runner,
    run: &Run,
    sd: &[f64],
    o: &FitOptions,
) -> Vec<Vec<([f64; 3], bool)>> {
    let Some(gt) = run.gt.as_ref() else {
        return Vec::new();
    };
    let rounded: Vec<usize> = (0..sd.len()).filter(|&i| sd[i] > 0.0).collect();
    if rounded.is_empty() {
        return Vec::new();
    }
    let steps = gt.len().saturating_sub(1);
    let held: Vec<Vec<bool>> = rounded
        .iter()
        .map(|&i| rounding::held(run.u.iter().take(steps).map(|u| u[i])))
        .collect();
    (0..steps)
        .map(|k| {
            rounded
                .iter()
                .zip(&held)
                .map(|(&i, shared)| {
                    let e = rounding::effect(r, run, k, i, gt[k][2]);
                    let weighted = [
                        sd[i] * e[0] / o.pos_sigma,
                        sd[i] * e[1] / o.pos_sigma,
                        sd[i] * e[2] / o.heading_sigma,
                    ];
                    (
                        weighted,
                        !shared[k] || k == 0 || run.u[k][i] != run.u[k - 1][i],
                    )
                })
                .collect()
        })
        .collect()
}

/// Replace `res`'s standard deviations and correlations by the drift-aware
/// sandwich (see the module doc). `r.p` holds the estimate; `runs` are the
/// whole runs it was fitted on. A robust (Huber) fit, or one without pose
/// residuals, keeps its own.
pub(super) fn sandwich(r: &Runner, runs: &[Run], o: &FitOptions, res: &mut FitResult) {
    let m = res.free.len();
    if m == 0 || o.huber.is_some() || !o.use_pose || !runs.iter().any(|x| x.gt.is_some()) {
        return;
    }
    let cols = start_columns(runs, o, m);
    let dims = m + cols.iter().flatten().count();
    let parts = run_rows(r, runs, o, res, &cols);
    let lever = o.heading_sigma / o.pos_sigma;
    let mut position = Vec::new();
    let mut heading = Vec::new();
    for (run, part) in runs.iter().zip(&parts) {
        if run.gt.is_some() {
            let rows = part.pose_rows(run, lever);
            position.extend([rows.series(0), rows.series(1)]);
            heading.push(rows.series(2));
        }
    }
    let noise = [local_level(&position), local_level(&heading)];
    // the other residuals (gyro, landmarks) as white at their own variance
    let (sq, count) = parts.iter().fold((0.0, 0usize), |(s, n), p| {
        (
            s + p.rest.0.iter().map(|v| v * v).sum::<f64>(),
            n + p.rest.0.len(),
        )
    });
    let rest_var = if count > 0 { sq / count as f64 } else { 1.0 };
    let rounding_sd: Vec<f64> = rounding::variances(r, runs)
        .into_iter()
        .map(f64::sqrt)
        .collect();
    let (mut h, mut meat) = (DMatrix::zeros(dims, dims), DMatrix::zeros(dims, dims));
    for (run, part) in runs.iter().zip(&parts) {
        let width = part.pose.1.width();
        let place = |c: usize| if c < m { c } else { part.start_col.unwrap() };
        let mut local_h = DMatrix::zeros(width, width);
        let mut local_m = DMatrix::zeros(width, width);
        let pose = PoseRows {
            rounding: rounding_effects(r, run, &rounding_sd, o),
            ..part.pose_rows(run, lever)
        };
        let triples = 3 * pose.rows();
        for (k, row) in part.pose.1.iter().enumerate() {
            let v = DVector::from_column_slice(row);
            local_h.ger(1.0, &v, &v, 1.0);
            if k >= triples {
                local_m.ger(1.0, &v, &v, 1.0); // the start heading's prior
            }
        }
        if triples > 0 {
            local_m += pose.meat(&noise, width, part.start_col.is_some());
        }
        for row in part.rest.1.iter() {
            let v = DVector::from_column_slice(row);
            local_h.ger(1.0, &v, &v, 1.0);
            local_m.ger(rest_var, &v, &v, 1.0);
        }
        for a in 0..width {
            for b in 0..width {
                h[(place(a), place(b))] += local_h[(a, b)];
                meat[(place(a), place(b))] += local_m[(a, b)];
            }
        }
    }
    for (c, _, slope) in priors(r, &r.p, &res.free) {
        h[(c, c)] += slope * slope;
        meat[(c, c)] += slope * slope;
    }
    // inverted in units of each unknown's own information, so that parameters
    // of very different sizes are not cut off as round-off
    let d = DMatrix::from_diagonal(
        &h.diagonal()
            .map(|v: f64| if v > 0.0 { 1.0 / v.sqrt() } else { 0.0 }),
    );
    let hinv = &d * psd_inverse(&(&d * &h * &d), |l, lmax| l > 1e-12 * lmax) * &d;
    let cov = (&hinv * meat * &hinv).view((0, 0), (m, m)).into_owned();
    for k in 0..m {
        if res.std[k].is_finite() {
            res.std[k] = cov[(k, k)].max(0.0).sqrt();
        }
    }
    res.corr = correlation(&cov);
}

/// Each run's residual rows at the estimate, pose and the rest apart.
fn run_rows(
    r: &Runner,
    runs: &[Run],
    o: &FitOptions,
    res: &FitResult,
    cols: &[Option<usize>],
) -> Vec<RunRows> {
    let only = |pose: bool| FitOptions {
        use_pose: pose,
        use_gyro: !pose && o.use_gyro,
        use_landmarks: !pose && o.use_landmarks,
        ..o.clone()
    };
    let (pose_o, rest_o) = (only(true), only(false));
    let offsets = run_offsets(runs, &res.starts);
    runs.par_iter()
        .zip(cols)
        .zip(&offsets)
        .map(|((run, col), start)| {
            let rows = |opts: &FitOptions| {
                run_residuals(
                    r,
                    &r.p,
                    &res.free,
                    run,
                    opts,
                    true,
                    *start,
                    col.is_some(),
                    None,
                )
            };
            RunRows {
                pose: rows(&pose_o),
                rest: rows(&rest_o),
                start_col: *col,
            }
        })
        .collect()
}
