//! Calibration: bounded Levenberg-Marquardt on the generated parameter Jacobians.
//!
//! Residuals, each divided by its sigma: dead-reckoned pose minus ground truth at
//! every row (through the model's `pose` observation when it has one, e.g. an
//! off-centre marker), and model minus measured gyro yaw rate at every step
//! (through `obs_gyro`, so gyro effects enter naturally). The Jacobian comes from
//! the forward sensitivities of the exact step, so it is exact, not numerical.
//!
//! Why not a solver crate (`levenberg-marquardt`, a MINPACK port, or argmin):
//! both take the Jacobian as one matrix, and a million-sample log cut into 833
//! segments with a start-heading nuisance each has a 4e6 x 836 Jacobian (27 GB);
//! here J^T J is summed block by block without forming J ([`normal_equations`])
//! and solved through its arrow shape ([`arrow`]). The loop also does what
//! those crates do not: directions the data do not determine take no step
//! (they stay at their nominal values instead of wandering along a null space),
//! bounds clamp the step, and it stops when a step is below a hundredth of a
//! standard deviation of the estimate.
mod arrow;
mod drift;
pub mod leave_one_out;

use crate::deadreckon;
use crate::interp::{chain, lerp3};
use crate::log::wrap;
use crate::model::Runner;
use crate::rows::Rows;
use crate::run::Run;
use kinegen_model::decl::ObservationRole::{Pose, RangeBearing, YawRate};
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;
use serde::Serialize;
use std::sync::Arc;

/// Length of the re-anchored segments of long runs (see [`fit`]).
pub const SEGMENT_S: f64 = 60.0;

/// Window of the increments likelihood ([`FitOptions::increments`]): long enough
/// that the random walk of the inputs, not the shared endpoint measurement,
/// dominates each window's residual (over 30 simulated seeds, 5 s windows gave
/// standard deviations within 15% of the estimates' spread for a differential
/// drive, 1-3 s windows overstated them 1.5-2x).
pub const WINDOW_S: f64 = 5.0;

/// The runs as calibration and scoring see them: runs longer than 2 min split
/// into re-anchored segments of about a minute.
pub fn segmented(runs: &[Run]) -> Vec<Run> {
    runs.iter().flat_map(|x| x.segments(SEGMENT_S)).collect()
}

/// The fitted start offsets `starts` of [`segmented`]`(runs)` carried to the
/// segments of `part`, whose runs begin where `runs`' do (a training part cut
/// from each run's start): a segment of both starts at the same row. None if
/// some segment of `part` has no such twin.
pub fn part_starts(runs: &[Run], part: &[Run], starts: &[[f64; 3]]) -> Option<Vec<[f64; 3]>> {
    if runs.len() != part.len() {
        return None;
    }
    let mut out = Vec::new();
    let mut first = 0;
    for (run, cut) in runs.iter().zip(part) {
        let whole = run.segments(SEGMENT_S);
        for seg in cut.segments(SEGMENT_S) {
            let k = whole.iter().position(|w| w.t[0] == seg.t[0])?;
            out.push(*starts.get(first + k)?);
        }
        first += whole.len();
    }
    Some(out)
}

/// The calibration `at`, an optimum on `runs` whose segments started at
/// `starts` ([`FitResult::starts`]), refined locally on `part` (runs cut from
/// the same starts, such as a training part): from the start headings of the
/// segments the two share, or from the measured ones when they share none.
pub fn refine_on_part(
    at: &Runner,
    runs: &[Run],
    part: &[Run],
    starts: &[[f64; 3]],
    o: &FitOptions,
) -> Result<FitResult, FitError> {
    match part_starts(runs, part, starts) {
        Some(warm) => refine_from(at, part, o, &warm),
        None => refine(at, part, o),
    }
}

#[derive(Debug, Clone)]
pub struct FitOptions {
    pub pos_sigma: f64,
    pub heading_sigma: f64,
    pub gyro_sigma: f64,
    pub use_pose: bool,
    pub use_gyro: bool,
    pub use_landmarks: bool,
    pub max_iter: usize,
    /// Robust loss: residuals beyond this many sigmas count linearly instead of
    /// quadratically (Huber), so outliers (a motion-capture glitch, a wrong
    /// landmark association) do not drag the estimate. None: least squares.
    pub huber: Option<f64>,
    /// Refine each run's (segment's) start heading as a nuisance parameter: the
    /// measured start is one noisy sample, or a rest's mean, whose heading error
    /// rotates the whole track (a position error does not grow, so the position
    /// stays measured; freeing it would also let a wrong model re-centre its
    /// drift). A rest's mean is refined within its uncertainty (see
    /// `has_start_nuisance`). Estimated with the parameters, never reported as one.
    pub estimate_start: bool,
    /// Fit pose increments over windows of this many seconds instead of the
    /// absolute track: each window is dead-reckoned from its measured start and
    /// compared at its end only, so its residual depends on that window's inputs
    /// alone. Window increments are close to independent whatever drift the
    /// model leaves, and their sandwich covariance does not rely on the track's
    /// residuals being white (with every start heading refined, the absolute
    /// track's least-squares deviations matched the estimates' spread over 50
    /// simulated logs too; see tests/calibration.rs). None: absolute track.
    pub increments: Option<f64>,
    /// Pose residuals at the last row of each run only (see `increments`).
    pub endpoints_only: bool,
    /// Directions in parameter space (unscaled, one entry per free parameter)
    /// along which the parameters stay at their starting values: ones an
    /// earlier fit of the same data found undetermined (see [`fit_stage`]).
    pub hold: Vec<DVector<f64>>,
    /// Sub-steps per step of each run in the `runs` a fit is given (see
    /// [`deadreckon::substep_plan`]), fixed by a Levenberg-Marquardt stage for
    /// all its passes (see [`levenberg_marquardt`]). None: each pass chooses.
    pub substeps: Option<Arc<Vec<Option<Vec<u8>>>>>,
    /// Start-pose offsets a Levenberg-Marquardt stage begins from: an earlier
    /// fit's [`FitResult::starts`] on the same runs (see [`refine_from`]).
    /// None, or a count that does not match the runs: the measured starts.
    pub start_offsets: Option<Arc<Vec<[f64; 3]>>>,
    /// A stage also ends when the decrease still to come, extrapolated from
    /// its last two steps (Gauss-Newton on a misspecified model converges
    /// linearly: each step gains a fixed fraction of the one before), is below
    /// this fraction of the cost. 0: only the statistical test (steps below a
    /// hundredth of a standard deviation) and round-off end it. For fits
    /// whose optimum is only a starting point ([`BASIN_TOLERANCE`]) or only
    /// compared ([`crate::diagnose`]'s ranking).
    pub cost_tolerance: f64,
    /// End [`fit`] on the whole runs: the search works on re-anchored
    /// [`SEGMENT_S`] segments (a long track from rough values is outside any
    /// basin), then refines from there on each run dead-reckoned from its
    /// start, as the user's odometry runs, and reports standard deviations
    /// that account for the track's drift ([`drift`]). Segments minimise
    /// something else: on a clean simulated 364 s log their optimum doubled
    /// the whole-run error (0.0015 m -> 0.0030 m) with estimates 8 reported
    /// standard deviations from the truth. What `kinegen fit` reports;
    /// diagnosis ranks candidate effects on the segments alone.
    pub whole_runs: bool,
    /// Also start the search from each positive free parameter scaled by
    /// 0.1, 0.3, 3 and 10 ([`START_FACTORS`]), and say when one of those
    /// starts found a better optimum than the starting values did. What
    /// `kinegen fit` does; diagnosis refines from a calibration already made.
    pub multi_start: bool,
}

/// What a calibration compares with the ground truth (`--likelihood`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Likelihood {
    /// Each whole run dead-reckoned from its start, found through re-anchored
    /// segments ([`FitOptions::whole_runs`]).
    Track,
    /// The re-anchored [`SEGMENT_S`] segments only (what diagnosis ranks on).
    Segments,
    /// Pose increments over [`WINDOW_S`] windows ([`FitOptions::increments`]).
    Increments,
}

impl Likelihood {
    pub const NAMES: [&'static str; 3] = ["track", "segments", "increments"];

    pub fn parse(name: &str) -> Option<Likelihood> {
        match name {
            "track" => Some(Likelihood::Track),
            "segments" => Some(Likelihood::Segments),
            "increments" => Some(Likelihood::Increments),
            _ => None,
        }
    }

    /// `o` comparing this.
    pub fn apply(self, o: FitOptions) -> FitOptions {
        FitOptions {
            whole_runs: self == Likelihood::Track,
            increments: (self == Likelihood::Increments).then_some(WINDOW_S),
            ..o
        }
    }
}

/// [`FitOptions::cost_tolerance`] of a stage that only has to reach the
/// optimum's basin for the next one (the measured-start stage of a calibration
/// with start headings): 1e-5 of the cost, where that stage spent 25 of its 59
/// passes over a diagnosis log gaining 1e-4 of it.
pub const BASIN_TOLERANCE: f64 = 1e-5;

impl FitOptions {
    /// The fixed sub-step counts of run `i`, if any.
    fn plan(&self, i: usize) -> Option<&[u8]> {
        self.substeps.as_ref()?.get(i)?.as_deref()
    }
}

impl Default for FitOptions {
    fn default() -> Self {
        FitOptions {
            pos_sigma: 0.01,
            heading_sigma: 0.01,
            gyro_sigma: 0.01,
            use_pose: true,
            use_gyro: true,
            use_landmarks: true,
            max_iter: 100,
            huber: None,
            estimate_start: true,
            increments: None,
            endpoints_only: false,
            hold: Vec::new(),
            substeps: None,
            start_offsets: None,
            cost_tolerance: 0.0,
            whole_runs: false,
            multi_start: false,
        }
    }
}

#[derive(Debug, Clone, Serialize)]
pub struct ParamEstimate {
    pub nominal: f64,
    pub estimate: f64,
    pub std: f64,
}

#[derive(Debug, Clone)]
pub struct FitResult {
    pub p: Vec<f64>,
    pub free: Vec<usize>,
    pub std: Vec<f64>,
    pub corr: DMatrix<f64>,
    pub cost_before: f64,
    pub cost_after: f64,
    pub iterations: usize,
    pub n_residuals: usize,
    pub warnings: Vec<String>,
    /// Fitted start-pose offsets of the (segmented) runs, see [`FitOptions::estimate_start`].
    pub starts: Vec<[f64; 3]>,
    /// Unit directions in parameter space (unscaled, indexed like `free`) that
    /// the data do not determine.
    pub undetermined: Vec<DVector<f64>>,
    /// What the search found on its way (a local minimum avoided): carried
    /// through later stages, and said with the warnings at the end of [`fit`].
    pub search_notes: Vec<String>,
}

impl FitResult {
    /// This fit as the continuation of `earlier` (a fit of the same data
    /// from the same starting values): the starting cost is the earlier one's,
    /// the iterations are both fits'.
    fn continuing(self, earlier: &FitResult) -> FitResult {
        let mut notes = earlier.search_notes.clone();
        notes.extend(
            self.search_notes
                .iter()
                .filter(|n| !notes.contains(n))
                .cloned()
                .collect::<Vec<_>>(),
        );
        FitResult {
            cost_before: earlier.cost_before,
            iterations: earlier.iterations + self.iterations,
            search_notes: notes,
            ..self
        }
    }
}

#[derive(Debug, thiserror::Error)]
pub enum FitError {
    #[error("nothing to fit: the logs have no ground truth ({pose}), no gyro ({gyro}) and no landmark observations the model can predict")]
    NoResiduals { pose: String, gyro: String },
    #[error("the fit diverged: {0}")]
    Diverged(String),
}

/// Whether a run's start heading is refined: it has measurements of the absolute
/// pose. A run that starts moving, or a segment cut from a long run, has only
/// one noisy sample of it. A rest of half a second or more averages the noise
/// down but not away: with a heading noise of 0.002 rad over 20 rows, 4e-4 rad
/// is left, 1.2 cm across 30 m of driving, which a spec's own clean simulated
/// log then showed as structure to explain (issue 12). Such a start is refined
/// within its measured uncertainty (a prior, see [`start_prior`]), so a wrong
/// model cannot rotate its track further than the measurement allows to hide
/// part of a missing effect such as a toe angle.
///
/// Without ground truth the start is placed from the landmarks seen during the
/// rest, and a rested start stays where they place it.
fn has_start_nuisance(run: &Run, o: &FitOptions) -> bool {
    let rested = run.rest_steps() > 0 && run.t[run.rest_steps()] - run.t[0] >= 0.5;
    o.estimate_start
        && ((o.use_pose && run.gt.is_some())
            || (!rested && o.use_landmarks && !run.landmarks.is_empty()))
}

/// The standard deviation of a run's measured start heading when the rest it
/// starts with measures it (None: refined freely).
fn start_prior(run: &Run, o: &FitOptions) -> Option<f64> {
    o.use_pose.then(|| run.start_heading_std()).flatten()
}

/// Column of each run's start-heading offset in the Jacobian (after the parameters).
fn start_columns(runs: &[Run], o: &FitOptions, m: usize) -> Vec<Option<usize>> {
    let mut next = m;
    runs.iter()
        .map(|run| {
            has_start_nuisance(run, o).then(|| {
                next += 1;
                next - 1
            })
        })
        .collect()
}

/// The Gaussian priors of the free parameters whose spec declares a
/// `tolerance`: per prior, its column, its residual (p - nominal) / tolerance
/// and that residual's derivative. The nominal value is the runner's (the
/// spec's, or `--set`'s). They enter every cost the fit minimises, after the
/// data's residuals (which are in units of their sigma too), but not the
/// residual count its error figures divide by.
fn priors(r: &Runner, p: &[f64], free: &[usize]) -> Vec<(usize, f64, f64)> {
    let params = r.ir.runtime_params();
    free.iter()
        .enumerate()
        .filter_map(|(c, &i)| {
            params[i]
                .tolerance
                .map(|tol| (c, (p[i] - r.p[i]) / tol, 1.0 / tol))
        })
        .collect()
}

/// Weighted residuals (and their Jacobian w.r.t. the free parameters, then the
/// start-heading offsets of the runs that have them) over all runs; `starts`
/// holds one start-pose offset per run (empty: none). The parameters' priors
/// ([`priors`]) come last.
pub fn residuals(
    r: &Runner,
    p: &[f64],
    free: &[usize],
    runs: &[Run],
    o: &FitOptions,
    with_jac: bool,
    starts: &[[f64; 3]],
) -> (Vec<f64>, Option<DMatrix<f64>>) {
    let cols = start_columns(runs, o, free.len());
    let ncols = free.len() + cols.iter().flatten().count();
    let parts: Vec<(Vec<f64>, Rows)> = runs
        .par_iter()
        .enumerate()
        .map(|(i, run)| {
            run_residuals(
                r,
                p,
                free,
                run,
                o,
                with_jac,
                starts.get(i).copied().unwrap_or([0.0; 3]),
                cols[i].is_some(),
                o.plan(i),
            )
        })
        .collect();
    let prior = priors(r, p, free);
    let n: usize = parts.iter().map(|x| x.0.len()).sum();
    let mut res = Vec::with_capacity(n + prior.len());
    let mut jac = with_jac.then(|| DMatrix::zeros(n + prior.len(), ncols));
    let mut row = 0;
    for (i, (rv, jv)) in parts.into_iter().enumerate() {
        if let Some(j) = jac.as_mut() {
            for (k, jr) in jv.iter().enumerate() {
                for (c, v) in jr.iter().enumerate() {
                    let col = if c < free.len() {
                        c
                    } else {
                        cols[i].unwrap() + c - free.len()
                    };
                    j[(row + k, col)] = *v;
                }
            }
        }
        row += rv.len();
        res.extend(rv);
    }
    if let Some(k) = o.huber {
        huber_weights(&mut res, jac.as_mut(), k);
    }
    for (c, value, slope) in prior {
        if let Some(j) = jac.as_mut() {
            j[(res.len(), c)] = slope;
        }
        res.push(value);
    }
    (res, jac)
}

/// The Gauss-Newton normal equations J^T J and J^T r over all runs, without
/// forming J: each run's start-heading column touches only its own rows, so J is
/// block-sparse and can be huge (a 1,000,000-sample log cut into 833 segments
/// would need a 3e6 x 836 dense matrix), while J^T J is small. Columns as in
/// [`residuals`]. Returns the weighted residuals' [`Sums`], J^T J and J^T r:
/// the residuals themselves are not kept (on a million rows they would be
/// the largest thing the fit holds besides the log).
pub fn normal_equations(
    r: &Runner,
    p: &[f64],
    free: &[usize],
    runs: &[Run],
    o: &FitOptions,
    starts: &[[f64; 3]],
) -> (Sums, DMatrix<f64>, DVector<f64>) {
    let m = free.len();
    let cols = start_columns(runs, o, m);
    let n = m + cols.iter().flatten().count();
    // per run: residuals, A^T A, A^T b, b^T b, A^T r, b^T r (A: parameter columns, b: start heading)
    type Part = (Sums, DMatrix<f64>, DVector<f64>, f64, DVector<f64>, f64);
    let parts: Vec<Part> = runs
        .par_iter()
        .enumerate()
        .map(|(i, run)| {
            let nuis = cols[i].is_some();
            let (mut rv, jv) = run_residuals(
                r,
                p,
                free,
                run,
                o,
                true,
                starts.get(i).copied().unwrap_or([0.0; 3]),
                nuis,
                o.plan(i),
            );
            let (mut ata, mut atb, mut btb, mut atr, mut btr) = (
                DMatrix::zeros(m, m),
                DVector::zeros(m),
                0.0,
                DVector::zeros(m),
                0.0,
            );
            // Rows are gathered in blocks and each block enters A^T A as one
            // matrix product (blocked and vectorised by nalgebra), not as one
            // rank-1 update and one allocation per residual.
            const BLOCK: usize = 256;
            let (mut a, mut b, mut rb) = (
                DMatrix::zeros(BLOCK, m),
                DVector::zeros(BLOCK),
                DVector::zeros(BLOCK),
            );
            for (block, chunk_res) in rv.chunks_mut(BLOCK).enumerate() {
                let n = chunk_res.len();
                for (i, res) in chunk_res.iter_mut().enumerate() {
                    let row = &jv[block * BLOCK + i];
                    let w = o.huber.map_or(1.0, |k| huber_weight(*res, k));
                    *res *= w;
                    for (c, v) in row[..m].iter().enumerate() {
                        a[(i, c)] = v * w;
                    }
                    b[i] = if nuis { row[m] * w } else { 0.0 };
                    rb[i] = *res;
                }
                let (a, b, rb) = (a.rows(0, n), b.rows(0, n), rb.rows(0, n));
                ata.gemm_tr(1.0, &a, &a, 1.0);
                atb.gemv_tr(1.0, &a, &b, 1.0);
                btb += b.dot(&b);
                atr.gemv_tr(1.0, &a, &rb, 1.0);
                btr += b.dot(&rb);
            }
            (Sums::of(&rv), ata, atb, btb, atr, btr)
        })
        .collect();
    let mut sums = Sums::default();
    let mut jtj = DMatrix::zeros(n, n);
    let mut jtr = DVector::zeros(n);
    for (i, (rv, ata, atb, btb, atr, btr)) in parts.into_iter().enumerate() {
        sums.add(rv);
        let mut top = jtj.view_mut((0, 0), (m, m));
        top += &ata;
        let mut g = jtr.rows_mut(0, m);
        g += &atr;
        if let Some(c) = cols[i] {
            for k in 0..m {
                jtj[(k, c)] += atb[k];
                jtj[(c, k)] += atb[k];
            }
            jtj[(c, c)] += btb;
            jtr[c] += btr;
        }
    }
    for (c, value, slope) in priors(r, p, free) {
        jtj[(c, c)] += slope * slope;
        jtr[c] += slope * value;
        sums.cost += 0.5 * value * value;
    }
    (sums, jtj, jtr)
}

/// The cost (half the sum of squares) of weighted residuals and their count.
#[derive(Debug, Clone, Copy, Default)]
pub struct Sums {
    pub cost: f64,
    pub n: usize,
}

impl Sums {
    fn of(res: &[f64]) -> Sums {
        Sums {
            cost: cost(res),
            n: res.len(),
        }
    }

    fn add(&mut self, other: Sums) {
        self.cost += other.cost;
        self.n += other.n;
    }
}

/// The [`Sums`] of [`residuals`] without the residuals: each run's are summed
/// and dropped as its thread finishes it.
pub fn residual_sums(
    r: &Runner,
    p: &[f64],
    free: &[usize],
    runs: &[Run],
    o: &FitOptions,
    starts: &[[f64; 3]],
) -> Sums {
    let cols = start_columns(runs, o, free.len());
    let mut sums = runs
        .par_iter()
        .enumerate()
        .map(|(i, run)| {
            let start = starts.get(i).copied().unwrap_or([0.0; 3]);
            let (mut rv, _) = run_residuals(
                r,
                p,
                free,
                run,
                o,
                false,
                start,
                cols[i].is_some(),
                o.plan(i),
            );
            if let Some(k) = o.huber {
                rv.iter_mut().for_each(|x| *x *= huber_weight(*x, k));
            }
            Sums::of(&rv)
        })
        .reduce(Sums::default, |mut a, b| {
            a.add(b);
            a
        });
    for (_, value, _) in priors(r, p, free) {
        sums.cost += 0.5 * value * value;
    }
    sums
}

/// Huber loss by iteratively reweighted least squares: a residual r beyond k is
/// scaled by sqrt(k/|r|), so its squared contribution is k|r| (linear growth); its
/// Jacobian row gets the same weight (the weight's own derivative is neglected, as
/// IRLS does). Weights are recomputed at every evaluation.
fn huber_weight(r: f64, k: f64) -> f64 {
    if r.abs() > k {
        (k / r.abs()).sqrt()
    } else {
        1.0
    }
}

/// [`huber_weight`] applied to residuals and their Jacobian rows.
fn huber_weights(res: &mut [f64], jac: Option<&mut DMatrix<f64>>, k: f64) {
    let w: Vec<f64> = res.iter().map(|&r| huber_weight(r, k)).collect();
    for (r, wi) in res.iter_mut().zip(&w) {
        *r *= wi;
    }
    if let Some(j) = jac {
        for (i, wi) in w.iter().enumerate() {
            if *wi != 1.0 {
                j.row_mut(i).scale_mut(*wi);
            }
        }
    }
}

/// One run's residuals; Jacobian rows have the free parameters' columns, then
/// (with `nuis`) the start-heading column.
#[allow(clippy::too_many_arguments)]
#[allow(clippy::needless_range_loop)] // k indexes several per-row arrays of the run together
fn run_residuals(
    r: &Runner,
    p: &[f64],
    free: &[usize],
    run: &Run,
    o: &FitOptions,
    with_jac: bool,
    start: [f64; 3],
    nuis: bool,
    plan: Option<&[u8]>,
) -> (Vec<f64>, Rows) {
    let mut res = Vec::new();
    let mut jac = Rows::new(free.len() + usize::from(nuis));
    let track = deadreckon::run_from(r, p, run, with_jac, start, plan);
    // the inputs as executed (an input delay), for the observations' arguments
    let inputs = crate::timeline::executed(r, p, run);
    let np = p.len();
    // sensitivity columns to read: the free parameters, then the start heading
    let cols: Vec<usize> = free
        .iter()
        .copied()
        .chain(if nuis { vec![np + 2] } else { vec![] })
        .collect();
    let free = &cols[..];
    let mut scratch = Vec::new();
    // A measurement delay (crate::timeline): measurement k is compared with the
    // model at t_k - delay, linearly interpolated between rows (exact sensitivities
    // of the interpolation, and d/d delay = minus the interpolated velocity).
    let tau_i = r.delay;
    let tau = crate::timeline::delay(r, p);
    let shifted = |k: usize| crate::timeline::model_instant(run, k, tau);
    if o.use_pose {
        if let Some(gt) = &run.gt {
            let tracker = r.ir.observation_kernels(Pose);
            let first = if o.endpoints_only { gt.len() - 1 } else { 1 };
            for k in first..gt.len() {
                let (j, a) = if tau_i.is_some() {
                    shifted(k)
                } else {
                    (k - 1, 1.0)
                };
                let x = lerp3(&track.pose[j], &track.pose[j + 1], a);
                let vel: [f64; 3] =
                    [0, 1, 2].map(|i| (track.pose[j + 1][i] - track.pose[j][i]) / run.dt[j]);
                let u = &inputs.u[j.min(run.steps() - 1)];
                let (pred, hx, hp) = match tracker {
                    Some(t) => {
                        let h = t.value;
                        let pred = h.eval(&Runner::obs_args(h, &x, u, p, &[]));
                        let (hx, hp) = if with_jac {
                            let fx = t.jac_x;
                            (
                                fx.eval(&Runner::obs_args(fx, &x, u, p, &[])),
                                t.jac_p.map_or(vec![0.0; 3 * np], |fp| {
                                    fp.eval(&Runner::obs_args(fp, &x, u, p, &[]))
                                }),
                            )
                        } else {
                            (vec![], vec![])
                        };
                        (pred, hx, hp)
                    }
                    None => (
                        x.to_vec(),
                        vec![1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
                        vec![0.0; 3 * np],
                    ),
                };
                let sig = [o.pos_sigma, o.pos_sigma, o.heading_sigma];
                for i in 0..3 {
                    let d = pred[i] - gt[k][i];
                    res.push(if i == 2 { wrap(d) } else { d } / sig[i]);
                    if with_jac {
                        let sens = track.sens.as_ref().unwrap();
                        let (s0, s1) = (sens.at(j), sens.at(j + 1));
                        jac.push(free.iter().map(|&c| {
                            let dx = |m: usize| {
                                if Some(c) == tau_i {
                                    -vel[m]
                                } else {
                                    s0[(m, c)] + a * (s1[(m, c)] - s0[(m, c)])
                                }
                            };
                            let direct = if c < np { hp[i * np + c] } else { 0.0 };
                            chain(&hx[i * 3..i * 3 + 3], dx, direct) / sig[i]
                        }));
                    }
                }
            }
        }
    }
    if let Some(sd) = start_prior(run, o).filter(|_| nuis) {
        // the start-heading offset against its measurement's uncertainty
        res.push(start[2] / sd);
        if with_jac {
            let m = free.len() - 1;
            jac.push((0..=m).map(|c| if c == m { 1.0 / sd } else { 0.0 }));
        }
    }
    if o.use_landmarks && !run.landmarks.is_empty() {
        landmark_residuals(r, p, free, run, &track, with_jac, &mut res, &mut jac);
    }
    if o.use_gyro {
        if let (Some(g), Some(gyro)) = (&run.gyro, r.ir.observation_kernels(YawRate)) {
            let (hx, hp) = (gyro.jac_x, gyro.jac_p);
            let mut jp = vec![0.0; np];
            let mut jx = [0.0; 3];
            for k in 0..run.steps() {
                let x = track.pose[k];
                // the track already predicted the reading (Track::gyro)
                res.push((track.gyro[k] - g[k + 1]) / o.gyro_sigma);
                if with_jac {
                    if let Some(hp) = hp {
                        hp.eval_into(
                            &Runner::obs_args(hp, &x, &inputs.u[k], p, &[]),
                            &mut jp,
                            &mut scratch,
                        );
                    }
                    hx.eval_into(
                        &Runner::obs_args(hx, &x, &inputs.u[k], p, &[]),
                        &mut jx,
                        &mut scratch,
                    );
                    let s = track.sens.as_ref().unwrap().at(k);
                    jac.push(free.iter().map(|&c| {
                        let direct = if c < np { jp[c] } else { 0.0 };
                        chain(&jx, |m| s[(m, c)], direct) / o.gyro_sigma
                    }));
                }
            }
        }
    }
    (res, jac)
}

/// Range and bearing residuals of every landmark observation (seed 001 eq. 6),
/// predicted at the track interpolated to the observation time; sigmas from the
/// spec's `landmark` observation. Jacobian: H_x times the interpolated pose
/// sensitivity, plus H_p.
#[allow(clippy::too_many_arguments)]
fn landmark_residuals(
    r: &Runner,
    p: &[f64],
    free: &[usize],
    run: &Run,
    track: &deadreckon::Track,
    with_jac: bool,
    res: &mut Vec<f64>,
    jac: &mut Rows,
) {
    let Some(sensor) = r.ir.observation_kernels(RangeBearing) else {
        return;
    };
    let h = sensor.value;
    let sig = crate::landmarks::sigma(r);
    let np = p.len();
    for o in &run.landmarks {
        let (j, a, x) = crate::innovations::locate_on(run, track, o.t);
        let u = &run.u[j.min(run.steps() - 1)];
        let lm = [o.xl, o.yl];
        let pred = h.eval(&Runner::obs_args(h, &x, u, p, &lm));
        res.push((pred[0] - o.range) / sig[0]);
        res.push(wrap(pred[1] - o.bearing) / sig[1]);
        if with_jac {
            let fx = sensor.jac_x;
            let hx = fx.eval(&Runner::obs_args(fx, &x, u, p, &lm));
            let hp = sensor
                .jac_p
                .map_or(vec![], |fp| fp.eval(&Runner::obs_args(fp, &x, u, p, &lm)));
            let sens = track.sens.as_ref().unwrap();
            let (s0, s1) = (sens.at(j), sens.at(j + 1));
            for i in 0..2 {
                jac.push(free.iter().map(|&c| {
                    let direct = if c < np { hp[i * np + c] } else { 0.0 };
                    let dx = |m: usize| s0[(m, c)] + a * (s1[(m, c)] - s0[(m, c)]);
                    chain(&hx[i * 3..i * 3 + 3], dx, direct) / sig[i]
                }));
            }
        }
    }
}

/// Each run's start-pose offset in the fit: its first segment's (`starts` is per
/// segment of [`segmented`] runs, as in [`FitResult::starts`]).
pub fn run_offsets(runs: &[Run], starts: &[[f64; 3]]) -> Vec<[f64; 3]> {
    let mut seg = 0;
    runs.iter()
        .map(|run| {
            let off = starts.get(seg).copied().unwrap_or([0.0; 3]);
            seg += run.segments(SEGMENT_S).len();
            off
        })
        .collect()
}

/// The start pose each run's dead reckoning used in the fit: its measured start
/// plus the refinement of its first segment (see [`run_offsets`]).
pub fn run_starts(r: &Runner, p: &[f64], runs: &[Run], starts: &[[f64; 3]]) -> Vec<[f64; 3]> {
    runs.iter()
        .zip(run_offsets(runs, starts))
        .map(|(run, off)| deadreckon::placed_start(r, p, run, run.start_pose(), off).0)
        .collect()
}

/// Each segment's (of [`segmented`] runs) start-pose offset refined for
/// parameters `p` held fixed, as a fit at `p` would refine it: a fit's
/// "before" is scored as its "after" is.
pub fn fitted_offsets(r: &Runner, p: &[f64], runs: &[Run], o: &FitOptions) -> Vec<[f64; 3]> {
    at_fitted_starts(r, p, runs, o).2
}

/// `r` with parameters `p` held fixed, the runs as calibration sees them, and
/// each segment's start refined for those parameters: how a model is scored.
fn at_fitted_starts(
    r: &Runner,
    p: &[f64],
    runs: &[Run],
    o: &FitOptions,
) -> (Runner, Vec<Run>, Vec<[f64; 3]>) {
    let seg = segmented(runs);
    let mut fixed = r.clone();
    fixed.p = p.to_vec();
    fixed.free = vec![];
    let starts = fit_stage(&fixed, &seg, o)
        .map(|f| f.starts)
        .unwrap_or_default();
    (fixed, seg, starts)
}

/// Weighted residual RMS of `p` on `runs` (segmented as calibration sees them),
/// after refining only the start poses.
pub fn rms_with_fitted_starts(r: &Runner, p: &[f64], runs: &[Run], o: &FitOptions) -> f64 {
    let (fixed, seg, starts) = at_fitted_starts(r, p, runs, o);
    let (res, _) = residuals(&fixed, p, &[], &seg, o, false, &starts);
    (res.iter().map(|x| x * x).sum::<f64>() / res.len().max(1) as f64).sqrt()
}

/// The white-noise level of the weighted residuals of `r` at `p`: the error a
/// model that explained every structure in the logs would reach. Estimated by
/// successive differences within each channel (von Neumann): a model error
/// varies smoothly along the track and cancels in r_k - r_(k-1), while white
/// sensor noise doubles its variance there. Channels: each pose coordinate,
/// the gyro, the range and the bearing.
pub fn noise_floor(r: &Runner, p: &[f64], runs: &[Run], o: &FitOptions) -> f64 {
    let (fixed, seg, starts) = at_fitted_starts(r, p, runs, o);
    let (mut sum, mut n) = (0.0, 0usize);
    for (stride, pose, gyro, landmarks) in [
        (3, true, false, false),
        (1, false, true, false),
        (2, false, false, true),
    ] {
        let only = FitOptions {
            use_pose: o.use_pose && pose,
            use_gyro: o.use_gyro && gyro,
            use_landmarks: o.use_landmarks && landmarks,
            ..o.clone()
        };
        if !(only.use_pose || only.use_gyro || only.use_landmarks) {
            continue;
        }
        let (res, _) = residuals(&fixed, p, &[], &seg, &only, false, &starts);
        for k in stride..res.len() {
            let d = res[k] - res[k - stride];
            sum += 0.5 * d * d;
            n += 1;
        }
    }
    (sum / n.max(1) as f64).sqrt()
}

fn cost(res: &[f64]) -> f64 {
    0.5 * res.iter().map(|r| r * r).sum::<f64>()
}

/// Continuation ladder (segment lengths in seconds, shortest first): from rough
/// nominal values a long track is far outside the basin of the right optimum (a
/// steering gain 5x off turns a square into a spiral, and the nearest minimum is a
/// robot that does not move at all). Short re-anchored segments keep every
/// residual small and nearly linear in the parameters, so the short-segment fit
/// lands near the optimum; each longer stage refines from there.
const LADDER_S: [f64; 2] = [4.0, 15.0];

/// Rows a continuation stage reads at most (evenly spaced segments beyond this):
/// it only has to find the basin, so a million-row log need not be read in full.
const LADDER_ROWS: usize = 20_000;

/// Rows on which other starting points are screened before a whole long log is
/// fitted from them (see [`fit`]).
const SCREEN_ROWS: usize = 50_000;

/// Weighted residual RMS at which a fit is taken to have reached the noise, so no
/// further starting point is tried.
const AT_NOISE: f64 = 1.5;

/// Calibrate the free parameters of `r` (starting from `r.p`).
///
/// The fit from the nominal values is tried first. Unless it already explains
/// the data down to the noise, it is also restarted from (a) the end of the
/// continuation ladder [`LADDER_S`] and (b) a gyro-only fit (the yaw-rate residual
/// does not accumulate along the track, so it is nearly convex in the
/// parameters); the candidate with the lowest full cost wins.
///
/// A direction the final fit finds undetermined keeps its starting value: when
/// an earlier stage or another starting point moved the parameters along it
/// (where it still looked determined: the first stage of [`fit_from`] has no
/// start-heading nuisance, and a turn-in-place log then slid a speed scale to
/// its bound), the whole fit is redone with that direction held.
pub fn fit(r: &Runner, runs: &[Run], o: &FitOptions) -> Result<FitResult, FitError> {
    let searched = held_where_undetermined(r, runs, o, fit_unheld)?;
    let mut res = if !o.whole_runs || o.increments.is_some() || r.free.is_empty() {
        searched
    } else {
        on_whole_runs(r, runs, o, searched)
    };
    let notes = std::mem::take(&mut res.search_notes);
    res.warnings.extend(notes);
    Ok(res)
}

/// [`FitOptions::whole_runs`]: `searched` (an optimum on the segments)
/// refined on the whole runs, keeping the directions it found undetermined,
/// with the drift-aware standard deviations ([`drift`]). Its `starts` keep
/// the segmented layout of [`FitResult::starts`]: each run's first segment
/// holds the run's start offset, the later segments none.
///
/// The refinement is kept only where it keeps the short-term accuracy the
/// segments had ([`SHORT_TERM_SLACK`]): over a long run whose drift is
/// mostly noise, the whole-run optimum bends the parameters to follow that
/// run's particular drift (a 546 s tricycle log: wheel radius 9 standard
/// deviations off the truth, 8x the drift over 5 s windows). Where it fails
/// or is not kept, `searched`, with its standard deviations made
/// drift-aware on its segments.
fn on_whole_runs(r: &Runner, runs: &[Run], o: &FitOptions, searched: FitResult) -> FitResult {
    let counts: Vec<usize> = runs.iter().map(|x| x.segments(SEGMENT_S).len()).collect();
    let split = segmented(runs);
    let mut at = r.clone();
    at.p = searched.p.clone();
    if counts.iter().all(|&c| c == 1) {
        let mut res = searched;
        drift::sandwich(&at, runs, o, &mut res);
        return res;
    }
    let warm = FitOptions {
        start_offsets: Some(Arc::new(run_offsets(runs, &searched.starts))),
        ..holding(o, &searched)
    };
    let whole = fit_stage_from(&at, runs, &warm, Start::NearOptimum).ok();
    let kept = whole.filter(|w| {
        // the segments' cost at the whole-run estimate (start headings
        // refined for it) against theirs at their own optimum
        let (_, _, starts) = at_fitted_starts(r, &w.p, runs, o);
        let cost = residual_sums(r, &w.p, &[], &split, o, &starts).cost;
        cost <= SHORT_TERM_SLACK * searched.cost_after
    });
    let Some(whole) = kept else {
        let mut res = searched;
        drift::sandwich(&at, &split, o, &mut res);
        return res;
    };
    let mut starts = Vec::with_capacity(counts.iter().sum());
    for (c, s) in counts.iter().zip(&whole.starts) {
        starts.push(*s);
        starts.extend(std::iter::repeat_n([0.0; 3], c - 1));
    }
    let mut res = FitResult {
        starts,
        ..whole.continuing(&searched)
    };
    at.p = res.p.clone();
    drift::sandwich(&at, runs, o, &mut res);
    res
}

/// How much more than at their own optimum the segments may cost at the
/// whole-run estimate for [`on_whole_runs`] to keep it: 10% (RMS up 5%).
const SHORT_TERM_SLACK: f64 = 1.1;

/// The continuation ladder's part of [`fit`]'s search: from the end of the
/// ladder, refined on the whole log (no direct start from `r.p`, no gyro-only
/// start). Diagnosis searches each candidate effect's calibration so, beside a
/// local refinement from the current model's calibration: a candidate's
/// direct and gyro-only starts retrace the current model's own search, which
/// found nothing better than the current calibration (on an omni_caster log
/// with a 0.2 rad steering offset left out, they were 283 of the 318 passes of
/// a wrong candidate's search). Where no run is long enough for the ladder,
/// [`fit`].
pub fn fit_continued(r: &Runner, runs: &[Run], o: &FitOptions) -> Result<FitResult, FitError> {
    held_where_undetermined(r, runs, o, continued_unheld)
}

fn continued_unheld(r: &Runner, runs: &[Run], o: &FitOptions) -> Result<FitResult, FitError> {
    let ladder = o
        .increments
        .is_none()
        .then(|| continuation(r, runs, o))
        .flatten();
    let Some(start) = ladder else {
        return fit_unheld(r, runs, o);
    };
    let split = segmented(runs);
    let mut from = r.clone();
    from.p = start;
    let res = fit_from(&from, &split, o)?;
    Ok(FitResult {
        cost_before: cost_at_start(r, &split, o),
        ..res
    })
}

/// The cost at the starting values `r.p` with the measured start poses, on all
/// of `split`: what a direct fit from them reports as its `cost_before`.
fn cost_at_start(r: &Runner, split: &[Run], o: &FitOptions) -> f64 {
    let starts = vec![[0.0; 3]; split.len()];
    residual_sums(r, &r.p, &r.free, split, o, &starts).cost
}

/// `search`, with its final check of the undetermined directions (see [`fit`]).
fn held_where_undetermined(
    r: &Runner,
    runs: &[Run],
    o: &FitOptions,
    search: fn(&Runner, &[Run], &FitOptions) -> Result<FitResult, FitError>,
) -> Result<FitResult, FitError> {
    let res = search(r, runs, o)?;
    if !moved_along_undetermined(r, &res) {
        return Ok(res);
    }
    let held = search(r, runs, &holding(o, &res))?;
    if !lock_undoes_fit(&held, &res) {
        return Ok(held.continuing(&res));
    }
    // a curved undetermined direction (see `fit_stage_from`): hold it from
    // where the data put the parameters, not from the start, and refine on
    // the residuals the search minimised (its re-anchored segments, from its
    // start headings). On the whole unsegmented run with the measured start
    // headings a misspecified tricycle's track cost 1.6e4 times more at the
    // optimum (3.9e11 against 2.5e7); the refinement wandered to a far worse
    // calibration (wheel radius 0.098 m against 0.144) and reported it.
    let mut at = r.clone();
    at.p = res.p.clone();
    let kept = held_where_fitted(r, refine_from(&at, runs, &holding(o, &res), &res.starts)?);
    Ok(FitResult {
        cost_before: res.cost_before,
        iterations: res.iterations + held.iterations + kept.iterations,
        search_notes: res.search_notes.clone(),
        ..kept
    })
}

/// [`fit`] without its final check of the undetermined directions.
fn fit_unheld(r: &Runner, runs: &[Run], o: &FitOptions) -> Result<FitResult, FitError> {
    // Dead reckoning over hours drifts beyond any basin of attraction: runs longer
    // than 2 min are calibrated as 60 s segments, each re-anchored on its measured
    // start pose (relative rather than absolute error).
    let all_measured = runs.iter().all(|x| x.gt.is_some());
    if let Some(w) = o.increments.filter(|_| all_measured && o.use_pose) {
        // the estimate and its uncertainty from independent window increments,
        // started from the best absolute-track fit (which finds the basin)
        let track = fit_unheld(
            r,
            runs,
            &FitOptions {
                increments: None,
                ..o.clone()
            },
        )?;
        let mut from = r.clone();
        from.p = track.p.clone();
        let windows: Vec<Run> = runs.iter().flat_map(|x| x.segments(w)).collect();
        let mut inc = FitOptions {
            estimate_start: false,
            endpoints_only: true,
            ..o.clone()
        };
        let mut res = fit_stage(&from, &windows, &inc)?;
        // The sigmas are guesses (the spec's or the defaults): re-estimate each
        // residual kind's from its own residuals (variance components), so that
        // a kind whose noise was overstated does not dilute the information of
        // another, and refit with them.
        for _ in 0..3 {
            from.p = res.p.clone();
            inc = variance_components(&from, &windows, &inc);
            res = fit_stage(&from, &windows, &inc)?;
        }
        from.p = res.p.clone();
        sandwich(&from, &windows, &inc, &mut res);
        res.cost_before = track.cost_before;
        res.iterations += track.iterations;
        res.search_notes = track.search_notes;
        return Ok(res);
    }
    let split = segmented(runs);
    let direct = coarse_to_fine(r, &split, o)?;
    let at_noise = (2.0 * direct.cost_after / direct.n_residuals.max(1) as f64).sqrt() < AT_NOISE;
    if r.free.is_empty() || at_noise {
        return Ok(direct);
    }
    // On a long log the other starting points are screened on evenly spaced
    // segments (SCREEN_ROWS rows): a candidate is refined on the whole log only
    // when, refined on those segments, it ends below the direct fit refined on
    // the same segments. A short log is its own screen (nothing changes), and a
    // million-row log is not fitted in full three times over.
    let screen = thinned(split.clone(), SCREEN_ROWS);
    let whole = screen.len() == split.len();
    let direct_cost = direct.cost_after;
    let mut best = direct;
    let mut best_on_screen: Option<f64> = None;
    let mut starts: Vec<LabelledStart> = [continuation(r, runs, o), gyro_start(r, &screen, o)]
        .into_iter()
        .flatten()
        .map(|p| (None, p))
        .collect();
    if o.multi_start {
        starts.extend(screened_starts(r, &screen, o, &best));
    }
    let mut won: Option<String> = None;
    for (label, start) in starts {
        let mut from = r.clone();
        from.p = start;
        if !whole {
            let Ok(c) = fit_from(&from, &screen, o) else {
                continue;
            };
            let reference = *best_on_screen.get_or_insert_with(|| {
                let mut at = r.clone();
                at.p = best.p.clone();
                fit_from(&at, &screen, o).map_or(f64::INFINITY, |b| b.cost_after)
            });
            if c.cost_after >= reference * (1.0 - 1e-9) {
                continue;
            }
            from.p = c.p;
        }
        if let Ok(cand) = fit_from(&from, &split, o) {
            // a scaled start that ends with directions the data do not
            // determine holds them at its own, arbitrary, starting values
            let arbitrary = label.is_some() && !cand.undetermined.is_empty();
            if cand.cost_after < best.cost_after && !arbitrary {
                best_on_screen = None;
                best = cand.continuing(&best);
                won = label;
            }
        }
    }
    if let Some(label) = won.filter(|_| best.cost_after < LOCAL_MINIMUM * direct_cost) {
        best.search_notes.push(format!(
            "the fit from the starting values stopped in a local minimum: starting from {label} it reached a residual RMS {:.2}x smaller, and that result is reported. It depends on where the search starts: check the spec's nominal values",
            (direct_cost / best.cost_after).sqrt()
        ));
    }
    Ok(best)
}

/// Factors on one positive parameter's starting value that [`scaled_starts`]
/// tries: a length or gain within 10x of its nominal value is then within
/// about 1.8x of one of them, inside the basin a local fit finds (from
/// starting values 5-10x off, a real front-drive tricycle's fit stopped with
/// its wheelbase at a tenth of the truth and 2.5x the error).
const START_FACTORS: [f64; 4] = [0.1, 0.3, 3.0, 10.0];

/// A candidate's cost below this fraction of the direct fit's is a local
/// minimum avoided, and said (see [`FitOptions::multi_start`]).
const LOCAL_MINIMUM: f64 = 0.9;

/// The [`scaled_starts`] worth a full fit: each is run through one short
/// stage on `screen` (measured start headings, at most [`SCREEN_ITERATIONS`]
/// passes, stopping once in a basin), and only the one that ends lowest, and
/// below `direct`'s parameters put through the same stage, is returned. A
/// full fit from each of the 24 starts of a six-parameter robot took a
/// minute on a 35,000-row session.
fn screened_starts(
    r: &Runner,
    screen: &[Run],
    o: &FitOptions,
    direct: &FitResult,
) -> Option<LabelledStart> {
    let screen = thinned(screen.to_vec(), START_SCREEN_ROWS);
    let screen = &screen[..];
    let stage = FitOptions {
        estimate_start: false,
        max_iter: SCREEN_ITERATIONS,
        cost_tolerance: o.cost_tolerance.max(BASIN_TOLERANCE),
        ..o.clone()
    };
    let end_cost = |p: Vec<f64>| {
        let mut from = r.clone();
        from.p = p;
        fit_stage(&from, screen, &stage).map_or(f64::INFINITY, |f| f.cost_after)
    };
    let reference = end_cost(direct.p.clone());
    let scored: Vec<(f64, LabelledStart)> = scaled_starts(r)
        .into_par_iter()
        .map(|start| (end_cost(start.1.clone()), start))
        .collect();
    scored
        .into_iter()
        .filter(|(c, _)| c.is_finite() && *c < LOCAL_MINIMUM * reference)
        .min_by(|a, b| a.0.total_cmp(&b.0))
        .map(|x| x.1)
}

/// Passes of the screening stage of [`screened_starts`].
const SCREEN_ITERATIONS: usize = 15;

/// Rows (evenly spaced pieces) the screening stage of [`screened_starts`]
/// reads: a basin shows on a few thousand rows (the 40 starts of a
/// six-parameter robot took 10 s on its 35,000-row session read whole).
const START_SCREEN_ROWS: usize = 8_000;

/// Starting points with one positive free parameter (a length, a radius, a
/// gain: lower bound >= 0, positive nominal value) scaled by each of
/// [`START_FACTORS`], labelled for the user.
///
/// Several parameters can be off at once (a wheel radius 5x too large and a
/// wheelbase 10x too small: no single scaling leaves that tricycle's local
/// minimum), so [`JOINT_STARTS`] more scale all of them together, by factors
/// spread evenly over 0.1-10 in log space (a Halton sequence: deterministic,
/// and even in any number of dimensions).
fn scaled_starts(r: &Runner) -> Vec<LabelledStart> {
    let params = r.ir.runtime_params();
    let positive: Vec<usize> = r
        .free
        .iter()
        .copied()
        .filter(|&i| params[i].min.is_some_and(|m| m >= 0.0) && r.p[i] > 0.0)
        .collect();
    let scaled = |i: usize, f: f64| (r.p[i] * f).min(params[i].max.unwrap_or(f64::INFINITY));
    let mut out = Vec::new();
    for &i in &positive {
        for f in START_FACTORS {
            let mut p = r.p.clone();
            p[i] = scaled(i, f);
            let label = format!("{} = {:.6} ({f}x its starting value)", r.names[i], p[i]);
            out.push((Some(label), p));
        }
    }
    if positive.len() < 2 {
        return out;
    }
    for k in 1..=JOINT_STARTS {
        let mut p = r.p.clone();
        let mut said = Vec::new();
        for (d, &i) in positive.iter().enumerate() {
            let f = 10f64.powf(2.0 * radical_inverse(k, PRIMES[d % PRIMES.len()]) - 1.0);
            p[i] = scaled(i, f);
            said.push(format!("{} = {:.6}", r.names[i], p[i]));
        }
        out.push((Some(said.join(", ")), p));
    }
    out
}

/// A starting point for the search, with what the user is told about it
/// when it wins (None: one of the search's own, not worth a word).
type LabelledStart = (Option<String>, Vec<f64>);

/// Joint scalings tried by [`scaled_starts`].
const JOINT_STARTS: usize = 16;

const PRIMES: [usize; 10] = [2, 3, 5, 7, 11, 13, 17, 19, 23, 29];

/// The k-th element of the van der Corput sequence in `base`, in (0, 1).
fn radical_inverse(mut k: usize, base: usize) -> f64 {
    let (mut x, mut scale) = (0.0, 1.0 / base as f64);
    while k > 0 {
        x += (k % base) as f64 * scale;
        k /= base;
        scale /= base as f64;
    }
    x
}

/// [`fit_from`] on a long log: converged first on evenly spaced segments of
/// about [`SCREEN_ROWS`] rows, then refined on all of them from there, where
/// a few passes over the whole log suffice (each costs a dead reckoning of
/// every row with its sensitivities). A log of up to four times that many rows
/// is fitted whole from the start.
fn coarse_to_fine(r: &Runner, split: &[Run], o: &FitOptions) -> Result<FitResult, FitError> {
    let rows: usize = split.iter().map(|x| x.t.len()).sum();
    if rows <= 4 * SCREEN_ROWS || r.free.is_empty() {
        return fit_from(r, split, o);
    }
    let coarse = fit_from(r, &thinned(split.to_vec(), SCREEN_ROWS), o)?;
    let mut from = r.clone();
    from.p = coarse.p.clone();
    // from the coarse optimum, the start headings are refined with the
    // parameters at once (fit_from's first stage guards against a far start)
    let fine = fit_stage_from(&from, split, o, Start::NearOptimum)?;
    Ok(FitResult {
        cost_before: cost_at_start(r, split, o),
        ..fine.continuing(&coarse)
    })
}

/// Replace a window fit's standard deviations and correlations by the sandwich
/// H^-1 S H^-1, with S summing each window's score J_i^T r_i outer products and
/// the cross terms of neighbouring windows. Consecutive windows share a measured
/// pose (the end of one is the start of the next), so their residuals are
/// negatively correlated (lag 1) and plain least squares overstates the
/// uncertainty (seen: 2-3x over 30 simulated seeds); farther windows share
/// nothing. Directions already found unidentified stay so.
fn sandwich(r: &Runner, windows: &[Run], o: &FitOptions, res: &mut FitResult) {
    let free = &res.free;
    let m = free.len();
    if m == 0 || windows.len() < 4 * m {
        return; // too few windows to estimate S: keep least squares
    }
    // each window's score J_i^T r_i and information J_i^T J_i, from one pass
    let (scores, infos): (Vec<DVector<f64>>, Vec<DMatrix<f64>>) = windows
        .par_iter()
        .map(|w| {
            let (rv, jv) = run_residuals(r, &r.p, free, w, o, true, [0.0; 3], false, None);
            let (mut g, mut info) = (DVector::zeros(m), DMatrix::zeros(m, m));
            for (res, row) in rv.iter().zip(jv.iter()) {
                let row = DVector::from_column_slice(&row[..m]);
                g.axpy(*res, &row, 1.0);
                info.ger(1.0, &row, &row, 1.0);
            }
            (g, info)
        })
        .unzip();
    let h: DMatrix<f64> = infos.iter().fold(DMatrix::zeros(m, m), |a, b| a + b);
    let mut s = DMatrix::zeros(m, m);
    for (i, g) in scores.iter().enumerate() {
        s += g * g.transpose();
        let shares_a_row = windows
            .get(i + 1)
            .is_some_and(|n| n.t[0] == *windows[i].t.last().unwrap());
        if shares_a_row {
            // Bartlett weight 1/2 (Newey-West with a lag of 1): keeps S positive
            // semi-definite, which full weights would not guarantee
            let c = g * scores[i + 1].transpose() * 0.5;
            s += &c + c.transpose();
        }
    }
    // small-sample correction of a cluster-robust S (CR1): G clusters, K parameters
    let g = windows.len() as f64;
    s *= g / (g - m as f64);
    let hinv = psd_inverse(&h, |l, lmax| l > 1e-12 * lmax);
    let cov = &hinv * s * &hinv;
    for k in 0..m {
        if res.std[k].is_finite() {
            res.std[k] = cov[(k, k)].max(0.0).sqrt();
        }
    }
    res.corr = correlation(&cov);
}

/// The inverse of a symmetric positive semi-definite matrix on the subspace of
/// the eigenvalues `keep` accepts (given the largest). A symmetric
/// eigen-decomposition keeps it positive semi-definite: round-off can leave tiny
/// negative eigenvalues (in a Schur complement, say), which an SVD
/// pseudo-inverse would turn into correlations |r| > 1.
fn psd_inverse(a: &DMatrix<f64>, keep: impl Fn(f64, f64) -> bool) -> DMatrix<f64> {
    let n = a.nrows();
    let eig = nalgebra::SymmetricEigen::new((a + a.transpose()) * 0.5);
    let lmax = eig.eigenvalues.max();
    let mut inv = DMatrix::zeros(n, n);
    for (k, &l) in eig.eigenvalues.iter().enumerate() {
        if keep(l, lmax) {
            let v = eig.eigenvectors.column(k);
            inv += v * v.transpose() / l;
        }
    }
    inv
}

/// Correlations of a covariance matrix, within [-1, 1]; a parameter without
/// variance is uncorrelated with the others.
fn correlation(cov: &DMatrix<f64>) -> DMatrix<f64> {
    let m = cov.nrows();
    DMatrix::from_fn(m, m, |a, b| {
        let d = (cov[(a, a)] * cov[(b, b)]).sqrt();
        if a == b {
            1.0
        } else if d > 0.0 {
            (cov[(a, b)] / d).clamp(-1.0, 1.0)
        } else {
            0.0
        }
    })
}

/// `o` with each residual kind's sigma (position, heading, gyro) scaled by the
/// RMS of its weighted residuals at `r.p`, so that each kind's weighted residuals
/// have unit variance. A kind with too few residuals to tell keeps its sigma.
fn variance_components(r: &Runner, runs: &[Run], o: &FitOptions) -> FitOptions {
    let only = |pose: bool, gyro: bool| FitOptions {
        use_pose: pose && o.use_pose,
        use_gyro: gyro && o.use_gyro,
        use_landmarks: false,
        huber: None,
        ..o.clone()
    };
    let rms = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt();
    let scaled = |sigma: f64, v: &[f64]| {
        if v.len() >= 10 && rms(v) > 0.0 && rms(v).is_finite() {
            sigma * rms(v)
        } else {
            sigma
        }
    };
    let pose = residuals(r, &r.p, &[], runs, &only(true, false), false, &[]).0;
    let gyro = residuals(r, &r.p, &[], runs, &only(false, true), false, &[]).0;
    // pose residuals come as (x, y, heading) triples
    let position: Vec<f64> = pose
        .iter()
        .enumerate()
        .filter(|(i, _)| i % 3 != 2)
        .map(|x| *x.1)
        .collect();
    let heading: Vec<f64> = pose.iter().skip(2).step_by(3).copied().collect();
    FitOptions {
        pos_sigma: scaled(o.pos_sigma, &position),
        heading_sigma: scaled(o.heading_sigma, &heading),
        gyro_sigma: scaled(o.gyro_sigma, &gyro),
        ..o.clone()
    }
}

/// The parameters at the end of the continuation ladder, or None when no run is
/// long enough to be cut. Start headings stay measured here: the stages only have
/// to reach the basin; the final fit refines them.
fn continuation(r: &Runner, runs: &[Run], o: &FitOptions) -> Option<Vec<f64>> {
    let stage = FitOptions {
        estimate_start: false,
        ..o.clone()
    };
    let mut at = r.clone();
    let mut moved = false;
    for len in LADDER_S {
        let pieces: Vec<Run> = runs.iter().flat_map(|x| x.segments(len)).collect();
        if pieces.len() <= runs.len() {
            continue;
        }
        if let Ok(f) = fit_stage(&at, &thinned(pieces, LADDER_ROWS), &stage) {
            at.p = f.p;
            moved = true;
        }
    }
    moved.then_some(at.p)
}

/// Evenly spaced pieces holding about `rows` rows in all (all of them when fewer).
fn thinned(pieces: Vec<Run>, rows: usize) -> Vec<Run> {
    let total: usize = pieces.iter().map(|x| x.t.len()).sum();
    let every = total.div_ceil(rows.max(1)).max(1);
    pieces.into_iter().step_by(every).collect()
}

/// The parameters of a gyro-only fit, when the logs have both a gyro the model
/// predicts and ground truth (with only one of them the direct fit is the same).
fn gyro_start(r: &Runner, runs: &[Run], o: &FitOptions) -> Option<Vec<f64>> {
    let has_gyro = runs.iter().any(|x| x.gyro.is_some())
        && r.ir.observation_kernels(YawRate).map(|o| o.value).is_some();
    let has_pose = runs.iter().any(|x| x.gt.is_some());
    if !(o.use_gyro && o.use_pose && has_gyro && has_pose) {
        return None;
    }
    let gyro_only = FitOptions {
        use_pose: false,
        ..o.clone()
    };
    fit_from(r, runs, &gyro_only).ok().map(|f| f.p)
}

/// Refine a calibration locally from `r.p` (no other starting points): for a
/// start already in the optimum's basin, such as the same model's fit on
/// other data.
pub fn refine(r: &Runner, runs: &[Run], o: &FitOptions) -> Result<FitResult, FitError> {
    fit_from(r, &segmented(runs), o)
}

/// Refine from an earlier fit's optimum on the same runs: `r.p` holds its
/// parameters (and those it did not have, such as a candidate effect's, at
/// their starting values), `starts` its fitted start offsets
/// ([`FitResult::starts`]). One joint stage from there: [`refine`]'s first
/// stage with the measured starts would leave the optimum only for the joint
/// stage to creep back to it (a misspecified model's Gauss-Newton steps shrink
/// by a constant factor: 40 passes over a diagnosis log for a candidate that
/// changes nothing). Without matching start offsets this is [`refine`].
pub fn refine_from(
    r: &Runner,
    runs: &[Run],
    o: &FitOptions,
    starts: &[[f64; 3]],
) -> Result<FitResult, FitError> {
    let split = segmented(runs);
    if !o.estimate_start || starts.len() != split.len() {
        return refine(r, runs, o);
    }
    let warm = FitOptions {
        start_offsets: Some(Arc::new(starts.to_vec())),
        ..o.clone()
    };
    fit_stage_from(r, &split, &warm, Start::NearOptimum)
}

/// Calibrate from `r.p`. With start-pose refinement the parameters are fitted
/// first with the measured starts, then jointly with the starts from there: a
/// free start heading from the outset can rotate a badly scaled track into a
/// local minimum (seen with a 5% speed-scale error).
fn fit_from(r: &Runner, runs: &[Run], o: &FitOptions) -> Result<FitResult, FitError> {
    if !o.estimate_start || r.free.is_empty() || !runs.iter().any(|x| has_start_nuisance(x, o)) {
        return fit_stage(r, runs, o);
    }
    let first = fit_stage(
        r,
        runs,
        &FitOptions {
            estimate_start: false,
            cost_tolerance: o.cost_tolerance.max(BASIN_TOLERANCE),
            ..o.clone()
        },
    )?;
    let mut from = r.clone();
    from.p = first.p.clone();
    let joint = fit_stage(&from, runs, o)?;
    Ok(joint.continuing(&first))
}

/// Cosine above which an accepted step continues the one before it (below
/// minus this, it turns back; see [`levenberg_marquardt_planned`]).
const PERSISTENT: f64 = 0.95;

/// At most 2^this times a step along a persistent direction.
const MAX_DOUBLINGS: u32 = 4;

fn cosine(a: &DVector<f64>, b: &DVector<f64>) -> f64 {
    a.dot(b) / (a.norm() * b.norm()).max(1e-300)
}

/// A fit ends when an accepted step moves the estimate by less than this many
/// of its standard deviations: nothing a user could see (see `negligible` in
/// [`levenberg_marquardt`]).
const STEP_TOLERANCE: f64 = 0.01;

/// Information (in scaled units, residuals weighted by their sigmas) below which
/// a parameter direction counts as undetermined by the data during the fit.
const UNDETERMINED_INFORMATION: f64 = 1.0;

/// Scaled displacement (in units of [`Runner::param_scale`]) along an
/// undetermined direction below which a fit counts as not having moved along
/// it: 1% of a parameter's size. A direction computed from the information
/// matrix is a little off the true null space (by 0.02 rad on a turn in
/// place), so a step along the determined directions shows a small component
/// along it (0.0013 for a 0.04 step) that is no drift.
const NOT_MOVED: f64 = 0.01;

/// One Levenberg-Marquardt fit from `r.p`. The iterations judge a direction
/// undetermined with the nominal noise ([`UNDETERMINED_INFORMATION`]) and the
/// Jacobian of the moment; the final check uses the residuals' own variance at
/// the optimum. Where the final check finds a direction the iterations did not
/// (a turn-in-place log: the speed scale's information is tiny but not below
/// 1, so it slid to its bound and the held-out error went 0.74 m -> 26 m), the
/// fit is redone from the start with those directions locked, so that the
/// parameters stay at their starting values along what the data cannot see.
fn fit_stage(r: &Runner, runs: &[Run], o: &FitOptions) -> Result<FitResult, FitError> {
    fit_stage_from(r, runs, o, Start::Rough)
}

/// Where a Levenberg-Marquardt stage starts, which sets its damping.
#[derive(Clone, Copy, PartialEq)]
enum Start {
    /// Anywhere (nominal values, another stage's result): the usual damping
    /// of 1e-3 of the normal equations' diagonal, and the stage ends when an
    /// accepted step changes nothing.
    Rough,
    /// At the optimum of evenly spaced pieces of the same log (see
    /// [`coarse_to_fine`]), where the quadratic model is good. The usual
    /// damping would only slow the first steps along weakly determined
    /// directions (on a million rows: 7 passes with sensitivities instead of
    /// 3), so it starts at 1e-7; and the stage ends as soon as the undamped
    /// Gauss-Newton step predicts a negligible decrease, instead of trying a
    /// round-off-level step and then ever more damped ones (each a pass over
    /// the log). From a rough start that prediction cannot be trusted: a
    /// badly wrong model has a huge residual variance, so a step it calls
    /// negligible can still lead out of a collapse (seen: a tricycle whose
    /// fit then stopped with its wheel radius at zero).
    NearOptimum,
}

/// [`fit_stage`] from a `start` of the given kind.
fn fit_stage_from(
    r: &Runner,
    runs: &[Run],
    o: &FitOptions,
    start: Start,
) -> Result<FitResult, FitError> {
    let first = levenberg_marquardt(r, runs, o, start)?;
    if !moved_along_undetermined(r, &first) {
        return Ok(first);
    }
    let locked = levenberg_marquardt(r, runs, &holding(o, &first), start)?;
    if !lock_undoes_fit(&locked, &first) {
        return Ok(locked.continuing(&first));
    }
    // The undetermined direction is curved (a car-like robot that never
    // steered: only tan(steer_offset)/wheelbase is seen, a hyperbola in the
    // parameters). Its tangent at the optimum, held from the start, blocks
    // what the data do determine (the offset that moves from 0) and the fit
    // ends where it began. Hold it from the optimum instead: the parameters
    // stay where the data put them and do not move further along it.
    let mut at = r.clone();
    at.p = first.p.clone();
    let from_optimum = FitOptions {
        start_offsets: Some(Arc::new(first.starts.clone())),
        ..holding(o, &first)
    };
    let kept = levenberg_marquardt(&at, runs, &from_optimum, Start::NearOptimum)?;
    Ok(held_where_fitted(r, kept.continuing(&first)))
}

/// A fit whose undetermined directions were held from its optimum (see
/// [`fit_stage_from`]) may have moved along them from the start (`r.p`): the
/// warnings of those that moved say so instead of "kept at the starting value".
fn held_where_fitted(r: &Runner, mut res: FitResult) -> FitResult {
    let moved: Vec<&str> = res
        .free
        .iter()
        .filter(|&&i| (res.p[i] - r.p[i]).abs() > NOT_MOVED * r.param_scale(i, r.p[i]))
        .map(|&i| r.names[i].as_str())
        .collect();
    for w in &mut res.warnings {
        let words: Vec<&str> = w.split([' ', '(', ')', ';', ':']).collect();
        if !moved.iter().any(|n| words.contains(n)) {
            continue;
        }
        *w = w
            .replace(
                "(kept at its starting value)",
                "(one of many values that fit equally well: it had to move from its starting value with the parameters the data do determine)",
            )
            .replace(
                "kept at the starting values along it)",
                "the values shown are one of many that fit equally well: they had to move from the starting values with what the data do determine)",
            );
    }
    res
}

/// Whether holding the undetermined directions from the start (`locked`)
/// fits the data visibly worse than the free fit (`first`): its cost more
/// than doubled (RMS up by 41%) and by far more than the noise. Then those
/// directions were not undetermined where the fit started. (Going back along
/// a direction that is undetermined costs little next to the whole misfit:
/// a turn in place whose speed scale slid loses a few percent.)
fn lock_undoes_fit(locked: &FitResult, first: &FitResult) -> bool {
    let lost = locked.cost_after - first.cost_after;
    let dof = first.n_residuals.saturating_sub(first.free.len()).max(1) as f64;
    let s2 = 2.0 * first.cost_after / dof;
    // 25: a 5-sigma change of a one-parameter chi-square
    locked.cost_after > 2.0 * first.cost_after && 2.0 * lost > 25.0 * s2
}

/// Whether `res` moved the parameters away from `r.p` along a direction it
/// found undetermined (by [`NOT_MOVED`] in scaled units).
fn moved_along_undetermined(r: &Runner, res: &FitResult) -> bool {
    let scale: Vec<f64> = res.free.iter().map(|&i| r.param_scale(i, r.p[i])).collect();
    let moved = DVector::from_fn(scale.len(), |k, _| {
        let i = res.free[k];
        (res.p[i] - r.p[i]) / scale[k]
    });
    res.undetermined.iter().any(|u| {
        let v = u.component_div(&DVector::from_row_slice(&scale));
        v.dot(&moved).abs() > NOT_MOVED * v.norm()
    })
}

/// `o` that also holds the directions `res` found undetermined.
fn holding(o: &FitOptions, res: &FitResult) -> FitOptions {
    FitOptions {
        hold: o.hold.iter().chain(&res.undetermined).cloned().collect(),
        ..o.clone()
    }
}

/// Orthonormal basis of the span of `vs` (Gram-Schmidt), so that removing
/// each basis vector's component from a step removes the whole span's.
fn orthonormal(vs: impl IntoIterator<Item = DVector<f64>>) -> Vec<DVector<f64>> {
    let mut basis: Vec<DVector<f64>> = Vec::new();
    for v in vs {
        let Some(mut v) = v.try_normalize(0.0) else {
            continue;
        };
        for b in &basis {
            v -= b * b.dot(&v);
        }
        // a vector within 1% of the span so far is taken to be in it: a
        // direction found again, a little off numerically, would otherwise
        // add its (meaningless) difference as a new direction
        let n = v.norm();
        if n > 1e-2 {
            basis.push(v / n);
        }
    }
    basis
}

/// A step may run with up to this many sub-steps fewer than its inputs need at
/// the current parameters (see [`levenberg_marquardt`]): one fewer than
/// `deadreckon::substep_plan` asks for leaves its error within a factor
/// (n/(n-1))^2 of the per-step tolerance, still far below any sensor's noise.
const PLAN_SLACK: u8 = 1;

/// [`fit_stage`]'s solver. The directions of `o.hold` get no step at all.
///
/// A model whose absolute inputs swing within a step (steering angles) is
/// dead-reckoned with sub-steps, as many as the swing needs at the parameters
/// of the moment (`deadreckon::substep_plan`: three twist evaluations a step,
/// a fifth of a pass). The stage fixes the counts at its starting parameters
/// for all its passes, which also makes its cost one smooth function of the
/// parameters (counts that change between trial points are small jumps in
/// it); where the optimum needs more than [`PLAN_SLACK`] more sub-steps in
/// some step, the stage goes on from there with the counts raised.
fn levenberg_marquardt(
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
    let free = r.free.clone();
    let m = free.len();
    let rp = r.ir.runtime_params();
    // the unknowns: the free parameters, then a start-heading offset per run that has one
    let start_cols = start_columns(runs, o, m);
    let n_start = start_cols.iter().flatten().count();
    let dims = m + n_start;
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
    // Work in scaled variables (Runner::param_scale); start headings scale
    // with 10 mrad.
    let mut scale: Vec<f64> = free.iter().map(|&i| r.param_scale(i, r.p[i])).collect();
    for _ in 0..n_start {
        scale.push(0.01);
        bounds.push((-0.5, 0.5));
    }
    // held directions in the scaled variables
    let locked: Vec<DVector<f64>> = o
        .hold
        .iter()
        .filter(|u| u.len() == m)
        .map(|u| u.component_div(&DVector::from_row_slice(&scale[..m])))
        .collect();
    let starts_of = |x: &[f64]| -> Vec<[f64; 3]> {
        start_cols
            .iter()
            .map(|c| c.map_or([0.0; 3], |c| [0.0, 0.0, x[c]]))
            .collect()
    };
    let mut p = r.p.clone();
    let mut x = vec![0.0; dims]; // the start headings live in x[m..]
    if let Some(warm) = o.start_offsets.as_ref().filter(|w| w.len() == runs.len()) {
        for (c, w) in start_cols.iter().zip(warm.iter()) {
            if let Some(c) = *c {
                x[c] = w[2].clamp(bounds[c].0, bounds[c].1);
            }
        }
    }
    let eval = |p: &[f64], x: &[f64]| residual_sums(r, p, &free, runs, o, &starts_of(x));
    let normal = |p: &[f64], x: &[f64]| normal_equations(r, p, &free, runs, o, &starts_of(x));
    let (mut res, mut jtj_raw, mut jtr_raw) = normal(&p, &x);
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
    let mut c = cost_before;
    let mut lambda = match start {
        Start::Rough => 1e-3,
        Start::NearOptimum => 1e-7,
    };
    let mut iterations = 0;
    // the last accepted step's decrease, for the extrapolation of `cost_tolerance`
    let mut last_gain: Option<f64> = None;
    // the last accepted step (scaled), to recognise a persistent direction
    let mut last_step: Option<DVector<f64>> = None;
    // the parameters and start offsets a scaled step `s` leads to, within bounds
    let moved = |p: &[f64], x: &[f64], s: &DVector<f64>| {
        let mut t = p.to_vec();
        for (k, &i) in free.iter().enumerate() {
            t[i] = (p[i] + s[k] * scale[k]).clamp(bounds[k].0, bounds[k].1);
        }
        let mut xt = x.to_vec();
        for k in m..dims {
            xt[k] = (x[k] + s[k] * scale[k]).clamp(bounds[k].0, bounds[k].1);
        }
        (t, xt)
    };
    for it in 0..o.max_iter {
        if dims == 0 {
            break;
        }
        iterations = it + 1;
        // in scaled variables: J D, so J^T J -> D J^T J D and J^T r -> D J^T r
        let dsc = DVector::from_vec(scale.clone());
        let jtj = DMatrix::from_fn(dims, dims, |a, b| jtj_raw[(a, b)] * dsc[a] * dsc[b]);
        let g = jtr_raw.component_mul(&dsc);
        // Directions the data do not determine (information below 1 in scaled
        // units: a standard deviation above the parameter's own size at the
        // nominal noise) get no step, so they stay at their nominal values
        // instead of wandering along a null space (a turn-in-place log moves
        // r_r, r_l and b together to 9x their size otherwise).
        // the parameters' information with the start headings marginalised out
        let undetermined: Vec<DVector<f64>> = if m == 0 {
            Vec::new() // only start headings are refined
        } else {
            let eig = arrow::marginal(&jtj, m).symmetric_eigen();
            let emax = eig.eigenvalues.max();
            let seen = (0..m)
                .filter(|&k| eig.eigenvalues[k] < UNDETERMINED_INFORMATION.max(1e-14 * emax))
                .map(|k| eig.eigenvectors.column(k).into_owned());
            orthonormal(locked.iter().cloned().chain(seen))
        };
        // Near the optimum: converged when even the undamped Gauss-Newton
        // step would lower the cost by a negligible amount (a hundredth of a
        // standard deviation, see `negligible` below); see [`Start`].
        if start == Start::NearOptimum {
            let s2 = 2.0 * c / (res.n.saturating_sub(dims).max(1)) as f64;
            if let Some(gn) = arrow::damped_step(&jtj, &g, m, 1e-12, &undetermined) {
                let predicted = -(g.dot(&gn) + 0.5 * gn.dot(&(&jtj * &gn)));
                if 2.0 * predicted < STEP_TOLERANCE * STEP_TOLERANCE * s2 {
                    break;
                }
            }
        }
        let mut improved = false;
        let mut first_trial = true;
        for _ in 0..30 {
            let Some(step) = arrow::damped_step(&jtj, &g, m, lambda, &undetermined) else {
                lambda *= 10.0;
                continue;
            };
            let (mut trial, mut xt) = moved(&p, &x, &step);
            // The first trial of an iteration is usually accepted (lambda
            // shrinks as the fit converges), so it is evaluated with its
            // normal equations at once: the accepted point needs them next,
            // and one pass with sensitivities replaces a pass without them
            // followed by one with. Retries after a rejection evaluate only.
            let (tres, tnormal) = if first_trial {
                let (r, a, b) = normal(&trial, &xt);
                (r, Some((a, b)))
            } else {
                (eval(&trial, &xt), None)
            };
            first_trial = false;
            let mut tc = tres.cost;
            if tc.is_finite() && tc < c {
                // Along a direction the fit keeps taking (a misspecified model's
                // long straight valley, where the quadratic model overshoots
                // and the damping holds every step short: a tricycle missing a
                // 0.1 rad steering offset took 100 such steps, each first
                // tried too long), the step is doubled while the cost falls.
                // Only while the gains shrink slowly: near an optimum the steps
                // shrink fast and a doubled one would only overshoot.
                let creeping = last_gain.is_some_and(|g| c - tc > 0.5 * g);
                let turn = last_step
                    .as_ref()
                    .map_or(0.0, |last: &DVector<f64>| cosine(last, &step));
                let persistent = creeping && turn > PERSISTENT;
                let mut taken = step.clone();
                let mut tnormal = tnormal;
                let mut tres = tres;
                // the step times `f`, evaluated
                let scaled = |f: f64| {
                    let s = &step * f;
                    let (p2, x2) = moved(&p, &x, &s);
                    let r2 = eval(&p2, &x2);
                    (s, p2, x2, r2)
                };
                // Back along the step before it: Gauss-Newton overshoots
                // across a valley and zig-zags; its floor is about half-way.
                if creeping && turn < -PERSISTENT {
                    let (s2, p2, x2, r2) = scaled(0.5);
                    if r2.cost.is_finite() && r2.cost < tc {
                        tc = r2.cost;
                        (taken, trial, xt, tres, tnormal) = (s2, p2, x2, r2, None);
                    }
                }
                if persistent {
                    let mut longer = None;
                    for k in 1..=MAX_DOUBLINGS {
                        let (s2, p2, x2, r2) = scaled(f64::from(1u32 << k));
                        if !(r2.cost.is_finite() && r2.cost < tc) {
                            break;
                        }
                        tc = r2.cost;
                        longer = Some((s2, p2, x2, r2));
                    }
                    if let Some((s2, p2, x2, r2)) = longer {
                        (taken, trial, xt, tres, tnormal) = (s2, p2, x2, r2, None);
                    }
                }
                last_step = Some(taken);
                let rel = (c - tc) / c.max(1e-300);
                // The step's length in standard deviations of the estimate:
                // near the optimum a Gauss-Newton step of d (in the metric of
                // J^T J) lowers the cost by d^2 / 2, and one standard
                // deviation is s^2 = 2 cost / (n - dims) of it. Steps below a
                // hundredth of a standard deviation change nothing a user
                // could see; on a million residuals LM would otherwise go on
                // for a dozen passes over the log. Exact (noise-free) data
                // have s^2 near zero and still converge to round-off.
                let s2 = 2.0 * tc / (res.n.saturating_sub(dims).max(1)) as f64;
                let gain = c - tc;
                let negligible = 2.0 * gain < STEP_TOLERANCE * STEP_TOLERANCE * s2;
                // a geometric series: the gains still to come sum to gain q / (1 - q)
                let to_come = last_gain
                    .map(|g| gain / g)
                    .filter(|q| *q < 1.0)
                    .map(|q| gain * q / (1.0 - q));
                let converged = to_come.is_some_and(|d| d < o.cost_tolerance * tc);
                last_gain = Some(gain);
                p = trial;
                x = xt;
                c = tc;
                lambda = (lambda / 3.0).max(1e-12);
                improved = true;
                (res, jtj_raw, jtr_raw) = match tnormal {
                    Some((a, b)) => (tres, a, b),
                    None => normal(&p, &x),
                };
                if rel < 1e-12 || negligible || converged {
                    improved = false;
                }
                break;
            }
            lambda *= 4.0;
            if lambda > 1e16 {
                break;
            }
        }
        if !improved {
            break;
        }
    }
    if !c.is_finite() {
        return Err(FitError::Diverged("cost became non-finite".into()));
    }
    let starts = starts_of(&x);
    // Uncertainty: s^2 (J^T J)^-1 with s^2 from the residuals (assumes independent
    // residuals; dead-reckoning residuals are correlated, so these are optimistic).
    // Identifiability and covariance in the scaled variables (then scaled back), so
    // that parameters of different units are compared fairly.
    let n = res.n;
    let s2 = 2.0 * c / (n.saturating_sub(dims).max(1)) as f64;
    let full = DMatrix::from_fn(dims, dims, |a, b| jtj_raw[(a, b)] * scale[a] * scale[b]);
    // information about the parameters with the start offsets marginalised out
    // (Schur complement), so the nuisance never shows up as a parameter
    let mut jtj = arrow::marginal(&full, m);
    if !locked.is_empty() {
        // held directions carry no information: the data were not let to
        // move them, so they are reported undetermined, with the rest
        // estimated on the complement
        let mut proj = DMatrix::identity(m, m);
        for v in orthonormal(locked.iter().cloned()) {
            proj -= &v * v.transpose();
        }
        jtj = &proj * jtj * &proj;
    }
    if m == 0 {
        // only start poses were refined: no parameter to report on
        return Ok(FitResult {
            p,
            free,
            std: vec![],
            corr: DMatrix::zeros(0, 0),
            cost_before,
            cost_after: c,
            iterations,
            n_residuals: n,
            warnings: vec![],
            starts,
            undetermined: vec![],
            search_notes: vec![],
        });
    }
    let d = DMatrix::from_diagonal(&DVector::from_vec(scale[..m].to_vec()));
    let svd = jtj.clone().svd(true, true);
    let smax = svd.singular_values.max();
    let mut warnings = Vec::new();
    let names: Vec<&str> = free.iter().map(|&i| r.names[i].as_str()).collect();
    // A direction is identifiable when the data pin it to better than the
    // parameters' own scale: standard deviation sqrt(s2 / sigma_i) < 1 in scaled
    // units (and numerically above round-off). Conditioning alone is no criterion:
    // long dead-reckoning tracks give condition numbers of 1e11 that noise-level
    // data still resolve.
    let cutoff = (s2 / 1.0).max(1e-14 * smax);
    let rank = svd.singular_values.iter().filter(|&&s| s > cutoff).count();
    // parameters taking part in a direction the data do not determine
    let mut undetermined = vec![false; m];
    let mut null = Vec::new();
    if rank < m {
        let v_t = svd.v_t.as_ref().unwrap();
        for (k, &s) in svd.singular_values.iter().enumerate() {
            if s <= cutoff {
                let row = v_t.row(k);
                // back to unscaled parameter space
                let u = row
                    .transpose()
                    .component_mul(&DVector::from_row_slice(&scale[..m]));
                null.push(u.normalize());
                for (j, v) in row.iter().enumerate() {
                    undetermined[j] |= v.abs() > 0.2;
                }
                let mut parts: Vec<(f64, &str)> = row
                    .iter()
                    .zip(&names)
                    .map(|(v, n)| (v.abs(), *n))
                    .filter(|(v, _)| *v > 0.2)
                    .collect();
                parts.sort_by(|a, b| b.0.total_cmp(&a.0));
                let names: Vec<&str> = parts.iter().map(|p| p.1).collect();
                warnings.push(match names.as_slice() {
                    [one] => format!("not identifiable from these logs: {one} (kept at its starting value)"),
                    _ => format!(
                        "not identifiable from these logs: the combination of {} cannot be separated (rank {rank} of {m}; kept at the starting values along it)",
                        names.join(" and ")
                    ),
                });
            }
        }
    }
    // The covariance is the inverse of the (marginal) information on its
    // determined subspace.
    let info_inv = psd_inverse(&jtj, |l, _| l > cutoff);
    let cov = &d * info_inv * &d * s2;
    // The pseudo-inverse gives an undetermined direction zero variance, which would
    // read as "known exactly": such parameters get an infinite standard deviation
    // (reported as unidentified, null in JSON).
    let std: Vec<f64> = (0..m)
        .map(|k| {
            if undetermined[k] {
                f64::INFINITY
            } else {
                cov[(k, k)].max(0.0).sqrt()
            }
        })
        .collect();
    let corr = correlation(&cov);
    for a in 0..m {
        for b in a + 1..m {
            // (pairs inside an undetermined direction are already warned about)
            if corr[(a, b)].abs() > 0.98 && !(undetermined[a] && undetermined[b]) {
                warnings.push(format!("{} and {} are strongly correlated (r = {:.3}): this log barely tells them apart", names[a], names[b], corr[(a, b)]));
            }
        }
    }
    for (k, &i) in free.iter().enumerate() {
        let (lo, hi) = bounds[k];
        if (p[i] - lo).abs() < 1e-6 * scale[k] || (p[i] - hi).abs() < 1e-6 * scale[k] {
            warnings.push(format!(
                "{} ended on its physical bound ({}): the estimate is not meaningful",
                names[k], p[i]
            ));
        }
    }
    Ok(FitResult {
        p,
        free,
        std,
        corr,
        cost_before,
        cost_after: c,
        iterations,
        n_residuals: n,
        warnings,
        starts,
        undetermined: null,
        search_notes: vec![],
    })
}
