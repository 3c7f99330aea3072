//! The Levenberg-Marquardt stage: bounded, scaled, with a start-heading
//! nuisance per run, no step along directions the data do not determine, and
//! the estimate's covariance and identifiability at its end.
//!
//! [`levenberg_marquardt`] fixes the dead-reckoning sub-step counts for a
//! stage; [`levenberg_marquardt_planned`] runs one: a [`Stage`] (the problem:
//! its [`Unknowns`] and how to evaluate them) iterates an [`Iterate`] and
//! reports a [`FitResult`].
use super::options::BelowRoundOff;
use super::{
    arrow, correlation, correlation_warnings, cosine, normal_equations, orthonormal, psd_inverse,
    residual_sums, sizes, start_columns, FitError, FitOptions, FitResult, Start, Sums,
    MAX_DOUBLINGS, PERSISTENT, ROUND_OFF, STEP_TOLERANCE, UNDETERMINED_INFORMATION,
};
use crate::model_on_log::deadreckon;
use crate::model_on_log::linalg;
use crate::model_on_log::model::Runner;
use crate::model_on_log::run::Run;
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;
use std::sync::Arc;

/// A step may run with up to this many sub-steps fewer than its inputs need at
/// the current parameters (see [`levenberg_marquardt`]): one fewer than
/// `deadreckon::substep_plan` asks for leaves its error within a factor
/// (n/(n-1))^2 of the per-step tolerance, still far below any sensor's noise.
const PLAN_SLACK: u8 = 1;

/// [`super::fit_stage`]'s solver. The directions of `o.hold` get no step at all.
///
/// A model whose absolute inputs swing within a step (steering angles) is
/// dead-reckoned with sub-steps, as many as the swing needs at the parameters
/// of the moment (`deadreckon::substep_plan`: three twist evaluations a step,
/// a fifth of a pass). The stage fixes the counts at its starting parameters
/// for all its passes, which also makes its cost one smooth function of the
/// parameters (counts that change between trial points are small jumps in
/// it); where the optimum needs more than [`PLAN_SLACK`] more sub-steps in
/// some step, the stage goes on from there with the counts raised.
pub(super) fn levenberg_marquardt(
    r: &Runner,
    runs: &[Run],
    o: &FitOptions,
    start: Start,
) -> Result<FitResult, FitError> {
    if o.substeps.is_some() {
        return levenberg_marquardt_planned(r, runs, o, start);
    }
    let plans = |p: &[f64]| -> Vec<Option<Vec<u8>>> {
        runs.par_iter()
            .map(|run| deadreckon::substep_plan(r, p, run))
            .collect()
    };
    let mut plan = plans(&r.p);
    if plan.iter().all(Option::is_none) {
        return levenberg_marquardt_planned(r, runs, o, start);
    }
    let (mut at, mut kind) = (r.clone(), start);
    let mut warm = o.start_offsets.clone();
    let mut first: Option<FitResult> = None;
    // the counts only grow (up to deadreckon's cap): a few rounds at most
    for round in 0.. {
        let planned = FitOptions {
            substeps: Some(Arc::new(plan.clone())),
            start_offsets: warm.clone(),
            ..o.clone()
        };
        let res = levenberg_marquardt_planned(&at, runs, &planned, kind)?;
        let res = match &first {
            None => res,
            Some(f) => FitResult {
                cost_before: f.cost_before,
                iterations: f.iterations + res.iterations,
                ..res
            },
        };
        let needed = plans(&res.p);
        let short = plan
            .iter()
            .zip(&needed)
            .any(|(have, need)| match (have, need) {
                (Some(h), Some(n)) => h.iter().zip(n).any(|(h, n)| *n > h + PLAN_SLACK),
                _ => false,
            });
        if !short || round == 2 {
            return Ok(res);
        }
        for (have, need) in plan.iter_mut().zip(needed) {
            if let (Some(h), Some(n)) = (have.as_mut(), need) {
                h.iter_mut().zip(n).for_each(|(h, n)| *h = (*h).max(n));
            }
        }
        at.p = res.p.clone();
        kind = Start::NearOptimum;
        warm = Some(Arc::new(res.starts.clone()));
        first = Some(res);
    }
    unreachable!("the loop returns by its third round")
}

/// [`levenberg_marquardt`] with the sub-step counts of `o` as they are.
fn levenberg_marquardt_planned(
    r: &Runner,
    runs: &[Run],
    o: &FitOptions,
    start: Start,
) -> Result<FitResult, FitError> {
    let stage = Stage {
        r,
        runs,
        o,
        u: Unknowns::new(r, runs, o),
    };
    let p = r.p.clone();
    let x = stage.u.initial(runs, o);
    let (res, jtj_raw, jtr_raw) = stage.normal(&p, &x);
    if res.n == 0 {
        return Err(FitError::NoResiduals {
            pose: r.ir.pose_columns().join(", "),
            gyro: r.ir.gyro_column(),
        });
    }
    let cost_before = res.cost;
    if !cost_before.is_finite() {
        return Err(FitError::Diverged(
            "the residuals at the starting point are not finite".into(),
        ));
    }
    let mut it = Iterate {
        p,
        x,
        c: cost_before,
        res,
        jtj_raw,
        jtr_raw,
        lambda: match start {
            Start::Rough => 1e-3,
            Start::NearOptimum => 1e-7,
        },
        last_gain: None,
        last_step: None,
    };
    let mut iterations = 0;
    for k in 0..o.max_iter {
        if stage.u.dims == 0 {
            break;
        }
        iterations = k + 1;
        if !stage.iteration(&mut it, start) {
            break;
        }
    }
    if !it.c.is_finite() {
        return Err(FitError::Diverged("cost became non-finite".into()));
    }
    // the covariance's decompositions do not return on a NaN
    if !it
        .jtj_raw
        .iter()
        .chain(it.jtr_raw.iter())
        .all(|v| v.is_finite())
    {
        return Err(FitError::Diverged("the Jacobian became non-finite".into()));
    }
    Ok(stage.report(it, cost_before, iterations))
}

/// The unknowns of a stage: the free parameters, then a start-heading offset
/// per run that has one. The solver works in scaled variables
/// ([`Runner::param_scale`]; start headings scale with 10 mrad).
struct Unknowns {
    free: Vec<usize>,
    /// how many free parameters (the first unknowns)
    m: usize,
    /// how many unknowns
    dims: usize,
    bounds: Vec<(f64, f64)>,
    scale: Vec<f64>,
    /// each run's start-heading unknown, if it has one
    start_cols: Vec<Option<usize>>,
    /// the held directions (`FitOptions::hold`) in the scaled variables
    locked: Vec<DVector<f64>>,
}

impl Unknowns {
    fn new(r: &Runner, runs: &[Run], o: &FitOptions) -> Unknowns {
        let free = r.free.clone();
        let m = free.len();
        let rp = r.ir.runtime_params();
        let start_cols = start_columns(runs, o, m);
        let n_start = start_cols.iter().flatten().count();
        let mut bounds: Vec<(f64, f64)> = free
            .iter()
            .map(|&i| {
                let p = rp[i];
                // strict lower bounds such as r > 0: stay a hair inside
                let lo = p
                    .min
                    .map_or(f64::NEG_INFINITY, |m| m + 1e-9 * p.nominal.abs().max(1e-9));
                (lo, p.max.unwrap_or(f64::INFINITY))
            })
            .collect();
        let mut scale: Vec<f64> = free.iter().map(|&i| r.param_scale(i, r.p[i])).collect();
        for _ in 0..n_start {
            scale.push(0.01);
            bounds.push((-0.5, 0.5));
        }
        let locked = o
            .hold
            .iter()
            .filter(|u| u.len() == m)
            .map(|u| u.component_div(&DVector::from_row_slice(&scale[..m])))
            .collect();
        Unknowns {
            free,
            m,
            dims: m + n_start,
            bounds,
            scale,
            start_cols,
            locked,
        }
    }

    /// Each run's start-pose offset for the unknowns `x`.
    fn starts_of(&self, x: &[f64]) -> Vec<[f64; 3]> {
        self.start_cols
            .iter()
            .map(|c| c.map_or([0.0; 3], |c| [0.0, 0.0, x[c]]))
            .collect()
    }

    /// The unknowns to begin from: the start headings of `o` (a warm start)
    /// within their bounds, else zero. (`x` holds the start headings in
    /// `x[m..]`; the parameters themselves live in the runner's vector.)
    fn initial(&self, runs: &[Run], o: &FitOptions) -> Vec<f64> {
        let mut x = vec![0.0; self.dims];
        if let Some(warm) = o.start_offsets.as_ref().filter(|w| w.len() == runs.len()) {
            for (c, w) in self.start_cols.iter().zip(warm.iter()) {
                if let Some(c) = *c {
                    x[c] = w[2].clamp(self.bounds[c].0, self.bounds[c].1);
                }
            }
        }
        x
    }

    /// The parameters and start offsets a scaled step `s` leads to, within bounds.
    fn moved(&self, p: &[f64], x: &[f64], s: &DVector<f64>) -> (Vec<f64>, Vec<f64>) {
        let (scale, bounds) = (&self.scale, &self.bounds);
        let mut t = p.to_vec();
        for (k, &i) in self.free.iter().enumerate() {
            t[i] = (p[i] + s[k] * scale[k]).clamp(bounds[k].0, bounds[k].1);
        }
        let mut xt = x.to_vec();
        for k in self.m..self.dims {
            xt[k] = (x[k] + s[k] * scale[k]).clamp(bounds[k].0, bounds[k].1);
        }
        (t, xt)
    }

    /// The normal equations in scaled variables: J D, so J^T J -> D J^T J D
    /// and J^T r -> D J^T r.
    fn scaled(
        &self,
        jtj_raw: &DMatrix<f64>,
        jtr_raw: &DVector<f64>,
    ) -> (DMatrix<f64>, DVector<f64>) {
        let dsc = DVector::from_vec(self.scale.clone());
        let jtj = DMatrix::from_fn(self.dims, self.dims, |a, b| {
            jtj_raw[(a, b)] * dsc[a] * dsc[b]
        });
        (jtj, jtr_raw.component_mul(&dsc))
    }
}

/// Where an iteration stands: the point, its cost and normal equations, the
/// damping, and the last accepted step.
struct Iterate {
    p: Vec<f64>,
    x: Vec<f64>,
    c: f64,
    res: Sums,
    jtj_raw: DMatrix<f64>,
    jtr_raw: DVector<f64>,
    lambda: f64,
    /// the last accepted step's decrease, for the extrapolation of `cost_tolerance`
    last_gain: Option<f64>,
    /// the last accepted step (scaled), to recognise a persistent direction
    last_step: Option<DVector<f64>>,
}

/// A trial point: its unknowns, its residual sums and, when computed with
/// them, its normal equations.
struct Trial {
    p: Vec<f64>,
    x: Vec<f64>,
    res: Sums,
    normal: Option<(DMatrix<f64>, DVector<f64>)>,
}

/// One stage's problem: the logs, the options and the unknowns.
struct Stage<'a> {
    r: &'a Runner,
    runs: &'a [Run],
    o: &'a FitOptions,
    u: Unknowns,
}

impl Stage<'_> {
    fn eval(&self, p: &[f64], x: &[f64]) -> Sums {
        residual_sums(
            self.r,
            p,
            &self.u.free,
            self.runs,
            self.o,
            &self.u.starts_of(x),
        )
    }

    fn normal(&self, p: &[f64], x: &[f64]) -> (Sums, DMatrix<f64>, DVector<f64>) {
        normal_equations(
            self.r,
            p,
            &self.u.free,
            self.runs,
            self.o,
            &self.u.starts_of(x),
        )
    }

    /// The residual variance at cost `c` of `n` residuals.
    fn variance(&self, c: f64, n: usize) -> f64 {
        2.0 * c / (n.saturating_sub(self.u.dims).max(1)) as f64
    }

    /// Directions the data do not determine (information below 1 in scaled
    /// units: a standard deviation above the parameter's own size at the
    /// nominal noise), with the held ones: they get no step, so they stay at
    /// their nominal values instead of wandering along a null space (a
    /// turn-in-place log moves r_r, r_l and b together to 9x their size
    /// otherwise). From the parameters' information with the start headings
    /// marginalised out.
    fn undetermined(&self, jtj: &DMatrix<f64>) -> Vec<DVector<f64>> {
        if self.u.m == 0 {
            return Vec::new(); // only start headings are refined
        }
        let Some(eig) = linalg::symmetric_eigen(arrow::marginal(jtj, self.u.m)) else {
            // not finite: no direction is determined
            return unit_vectors(self.u.m);
        };
        let emax = eig.eigenvalues.max();
        let seen = (0..self.u.m)
            .filter(|&k| eig.eigenvalues[k] < UNDETERMINED_INFORMATION.max(ROUND_OFF * emax))
            .map(|k| eig.eigenvectors.column(k).into_owned());
        orthonormal(self.u.locked.iter().cloned().chain(seen))
    }

    /// Near the optimum: converged when even the undamped Gauss-Newton step
    /// would lower the cost by a negligible amount (a hundredth of a standard
    /// deviation, see [`Stage::accept`]); see [`Start`].
    fn at_optimum(
        &self,
        it: &Iterate,
        jtj: &DMatrix<f64>,
        g: &DVector<f64>,
        undetermined: &[DVector<f64>],
    ) -> bool {
        let s2 = self.variance(it.c, it.res.n);
        arrow::damped_step(jtj, g, self.u.m, 1e-12, undetermined).is_some_and(|gn| {
            let predicted = -(g.dot(&gn) + 0.5 * gn.dot(&(jtj * &gn)));
            2.0 * predicted < STEP_TOLERANCE * STEP_TOLERANCE * s2
        })
    }

    /// One iteration: damped steps tried until one lowers the cost. False
    /// when the stage is done (no step helps, or the accepted one changed
    /// nothing a user could see).
    fn iteration(&self, it: &mut Iterate, start: Start) -> bool {
        let (jtj, g) = self.u.scaled(&it.jtj_raw, &it.jtr_raw);
        let undetermined = self.undetermined(&jtj);
        if start == Start::NearOptimum && self.at_optimum(it, &jtj, &g, &undetermined) {
            return false;
        }
        let mut first_trial = true;
        for _ in 0..30 {
            let Some(step) = arrow::damped_step(&jtj, &g, self.u.m, it.lambda, &undetermined)
            else {
                it.lambda *= 10.0;
                continue;
            };
            let (p, x) = self.u.moved(&it.p, &it.x, &step);
            // The first trial of an iteration is usually accepted (lambda
            // shrinks as the fit converges), so it is evaluated with its
            // normal equations at once: the accepted point needs them next,
            // and one pass with sensitivities replaces a pass without them
            // followed by one with. Retries after a rejection evaluate only.
            let trial = if first_trial {
                let (res, a, b) = self.normal(&p, &x);
                Trial {
                    p,
                    x,
                    res,
                    normal: Some((a, b)),
                }
            } else {
                let res = self.eval(&p, &x);
                Trial {
                    p,
                    x,
                    res,
                    normal: None,
                }
            };
            first_trial = false;
            if trial.res.cost.is_finite() && trial.res.cost < it.c {
                return self.accept(it, step, trial);
            }
            it.lambda *= 4.0;
            if it.lambda > 1e16 {
                break;
            }
        }
        false
    }

    /// `step`, scaled by `f` from the current point, evaluated.
    fn along(&self, it: &Iterate, step: &DVector<f64>, f: f64) -> (DVector<f64>, Trial) {
        let s = step * f;
        let (p, x) = self.u.moved(&it.p, &it.x, &s);
        let res = self.eval(&p, &x);
        (
            s,
            Trial {
                p,
                x,
                res,
                normal: None,
            },
        )
    }

    /// Move to `trial`, which lowers the cost, or to a point further along
    /// or back along `step` that lowers it more. False when the move changed
    /// nothing a user could see (the stage is done).
    fn accept(&self, it: &mut Iterate, step: DVector<f64>, trial: Trial) -> bool {
        let c = it.c;
        let mut tc = trial.res.cost;
        // Along a direction the fit keeps taking (a misspecified model's
        // long straight valley, where the quadratic model overshoots
        // and the damping holds every step short: a tricycle missing a
        // 0.1 rad steering offset took 100 such steps, each first
        // tried too long), the step is doubled while the cost falls.
        // Only while the gains shrink slowly: near an optimum the steps
        // shrink fast and a doubled one would only overshoot.
        let creeping = it.last_gain.is_some_and(|g| c - tc > 0.5 * g);
        let turn = it
            .last_step
            .as_ref()
            .map_or(0.0, |last: &DVector<f64>| cosine(last, &step));
        let persistent = creeping && turn > PERSISTENT;
        let (mut taken, mut trial) = (step.clone(), trial);
        // Back along the step before it: Gauss-Newton overshoots
        // across a valley and zig-zags; its floor is about half-way.
        if creeping && turn < -PERSISTENT {
            let (s2, t2) = self.along(it, &step, 0.5);
            if t2.res.cost.is_finite() && t2.res.cost < tc {
                tc = t2.res.cost;
                (taken, trial) = (s2, t2);
            }
        }
        if persistent {
            let mut longer = None;
            for k in 1..=MAX_DOUBLINGS {
                let (s2, t2) = self.along(it, &step, f64::from(1u32 << k));
                if !(t2.res.cost.is_finite() && t2.res.cost < tc) {
                    break;
                }
                tc = t2.res.cost;
                longer = Some((s2, t2));
            }
            if let Some((s2, t2)) = longer {
                (taken, trial) = (s2, t2);
            }
        }
        it.last_step = Some(taken);
        let rel = (c - tc) / c.max(1e-300);
        // The step's length in standard deviations of the estimate:
        // near the optimum a Gauss-Newton step of d (in the metric of
        // J^T J) lowers the cost by d^2 / 2, and one standard
        // deviation is s^2 = 2 cost / (n - dims) of it. Steps below a
        // hundredth of a standard deviation change nothing a user
        // could see; on a million residuals LM would otherwise go on
        // for a dozen passes over the log. Exact (noise-free) data
        // have s^2 near zero and still converge to round-off.
        let s2 = self.variance(tc, it.res.n);
        let gain = c - tc;
        let negligible = 2.0 * gain < STEP_TOLERANCE * STEP_TOLERANCE * s2;
        // a geometric series: the gains still to come sum to gain q / (1 - q)
        let to_come = it
            .last_gain
            .map(|g| gain / g)
            .filter(|q| *q < 1.0)
            .map(|q| gain * q / (1.0 - q));
        let converged = to_come.is_some_and(|d| d < self.o.cost_tolerance * tc);
        it.last_gain = Some(gain);
        it.p = trial.p;
        it.x = trial.x;
        it.c = tc;
        it.lambda = (it.lambda / 3.0).max(1e-12);
        (it.res, it.jtj_raw, it.jtr_raw) = match trial.normal {
            Some((a, b)) => (trial.res, a, b),
            None => self.normal(&it.p, &it.x),
        };
        !(rel < 1e-12 || negligible || converged)
    }

    /// The stage's result at `it`: the estimate, its standard deviations and
    /// correlations, and warnings about what the data do not determine.
    ///
    /// Uncertainty: s^2 (J^T J)^-1 with s^2 from the residuals (assumes
    /// independent residuals; dead-reckoning residuals are correlated, so
    /// these are optimistic; `fit::drift` replaces them where it applies).
    /// Identifiability and covariance in the scaled variables (then scaled
    /// back), so that parameters of different units are compared fairly.
    fn report(&self, it: Iterate, cost_before: f64, iterations: usize) -> FitResult {
        let (m, dims, scale) = (self.u.m, self.u.dims, &self.u.scale);
        let n = it.res.n;
        let s2 = self.variance(it.c, n);
        let full = DMatrix::from_fn(dims, dims, |a, b| it.jtj_raw[(a, b)] * scale[a] * scale[b]);
        // information about the parameters with the start offsets marginalised out
        // (Schur complement), so the nuisance never shows up as a parameter
        let mut jtj = arrow::marginal(&full, m);
        if !self.u.locked.is_empty() {
            // held directions carry no information: the data were not let to
            // move them, so they are reported undetermined, with the rest
            // estimated on the complement
            let mut proj = DMatrix::identity(m, m);
            for v in orthonormal(self.u.locked.iter().cloned()) {
                proj -= &v * v.transpose();
            }
            jtj = &proj * jtj * &proj;
        }
        let bare = FitResult {
            starts: self.u.starts_of(&it.x),
            p: it.p,
            free: self.u.free.clone(),
            std: vec![],
            corr: DMatrix::zeros(0, 0),
            cost_before,
            cost_after: it.c,
            iterations,
            n_residuals: n,
            warnings: vec![],
            undetermined: vec![],
            search_notes: vec![],
            near_nominal: vec![],
            below_round_off: vec![],
            correlated: vec![],
        };
        if m == 0 {
            // only start poses were refined: no parameter to report on
            return bare;
        }
        let names: Vec<&str> = self
            .u
            .free
            .iter()
            .map(|&i| self.r.names[i].as_str())
            .collect();
        let seen = self.identifiability(&jtj, s2, &names);
        let mut warnings = seen.warnings;
        // The covariance is the inverse of the (marginal) information on its
        // determined subspace.
        let d = DMatrix::from_diagonal(&DVector::from_vec(scale[..m].to_vec()));
        let info_inv = psd_inverse(&jtj, |l, _| l > seen.cutoff);
        let cov = &d * info_inv * &d * s2;
        // The pseudo-inverse gives an undetermined direction zero variance, which would
        // read as "known exactly": such parameters get an infinite standard deviation
        // (reported as unidentified, null in JSON).
        let std: Vec<f64> = (0..m)
            .map(|k| {
                if seen.undetermined[k] {
                    f64::INFINITY
                } else {
                    cov[(k, k)].max(0.0).sqrt()
                }
            })
            .collect();
        let corr = correlation(&cov);
        let scale = sizes(self.r, &self.u.free, &bare.p);
        let correlated = correlation_warnings(&names, &scale, &corr, &std);
        warnings.extend(correlated.iter().cloned());
        for (k, &i) in self.u.free.iter().enumerate() {
            let (lo, hi) = self.u.bounds[k];
            let p = bare.p[i];
            if (p - lo).abs() < 1e-6 * scale[k] || (p - hi).abs() < 1e-6 * scale[k] {
                warnings.push(format!(
                    "{} ended on its physical bound ({}): the estimate is not meaningful",
                    names[k], p
                ));
            }
        }
        FitResult {
            std,
            corr,
            warnings,
            undetermined: seen.null,
            below_round_off: seen.below_round_off,
            correlated,
            ..bare
        }
    }

    /// Which parameter directions the data pin down at the optimum.
    ///
    /// A direction is identifiable when the data pin it to better than the
    /// parameters' own scale: standard deviation sqrt(s2 / sigma_i) < 1 in
    /// scaled units (and numerically above round-off). Conditioning alone is
    /// no criterion: long dead-reckoning tracks give condition numbers of
    /// 1e11 that noise-level data still resolve.
    fn identifiability(&self, jtj: &DMatrix<f64>, s2: f64, names: &[&str]) -> Identifiability {
        let (m, scale) = (self.u.m, &self.u.scale);
        let Some(svd) = linalg::svd(jtj.clone()) else {
            return Identifiability::none_finite(m, names);
        };
        let smax = svd.singular_values.max();
        let cutoff = (s2 / 1.0).max(ROUND_OFF * smax);
        let rank = svd.singular_values.iter().filter(|&&s| s > cutoff).count();
        let mut seen = Identifiability {
            cutoff,
            undetermined: vec![false; m],
            null: Vec::new(),
            warnings: Vec::new(),
            below_round_off: Vec::new(),
        };
        if rank == m {
            return seen;
        }
        let v_t = svd.v_t.as_ref().unwrap();
        for (k, &s) in svd.singular_values.iter().enumerate() {
            if s > cutoff {
                continue;
            }
            let row = v_t.row(k);
            // back to unscaled parameter space
            let u = row
                .transpose()
                .component_mul(&DVector::from_row_slice(&scale[..m]));
            let direction = u.normalize();
            seen.null.push(direction.clone());
            // the parameters taking part in it, the largest share first
            let mut params: Vec<usize> = (0..m).filter(|&j| row[j].abs() > 0.2).collect();
            params.sort_by(|&a, &b| row[b].abs().total_cmp(&row[a].abs()));
            for &j in &params {
                seen.undetermined[j] = true;
            }
            let names: Vec<&str> = params.iter().map(|&j| names[j]).collect();
            let warning = match names.as_slice() {
                [one] => format!("not identifiable from these logs: {one} (kept at its starting value)"),
                _ => format!(
                    "not identifiable from these logs: the combination of {} cannot be separated (rank {rank} of {m}; kept at the starting values along it)",
                    names.join(" and ")
                ),
            };
            if s > s2 {
                seen.below_round_off.push(BelowRoundOff {
                    direction,
                    params,
                    warning: warning.clone(),
                });
            }
            seen.warnings.push(warning);
        }
        seen
    }
}

/// What [`Stage::identifiability`] finds.
struct Identifiability {
    /// information below which a direction is undetermined
    cutoff: f64,
    /// parameters taking part in a direction the data do not determine
    undetermined: Vec<bool>,
    /// those directions, in unscaled parameter space
    null: Vec<DVector<f64>>,
    warnings: Vec<String>,
    /// those of `null` only round-off hides
    below_round_off: Vec<BelowRoundOff>,
}

/// The `m` unit vectors: every direction, when none is determined.
fn unit_vectors(m: usize) -> Vec<DVector<f64>> {
    (0..m)
        .map(|k| DVector::from_fn(m, |i, _| f64::from(i == k)))
        .collect()
}

impl Identifiability {
    /// When the normal equations are not finite (a parameter so large the
    /// tracks overflow): no direction is determined, and the warning says
    /// why.
    fn none_finite(m: usize, names: &[&str]) -> Identifiability {
        Identifiability {
            cutoff: f64::INFINITY,
            undetermined: vec![true; m],
            null: unit_vectors(m),
            below_round_off: Vec::new(),
            warnings: vec![format!(
                "not identifiable from these logs: {} (the fit's normal equations are not finite: a value so far out that the tracks overflow?)",
                names.join(", ")
            )],
        }
    }
}
