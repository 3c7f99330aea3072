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
use super::residuals::run_residuals_into;
use super::sink::{Kept, Sink};
use super::square_root::SquareRoot;
use super::{priors, run_offsets, set_covariance, start_columns};
use super::{rounding, FitOptions, FitResult};
use crate::model_on_log::model::Runner;
use crate::model_on_log::run::Run;
use nalgebra::DVector;
use rayon::prelude::*;

/// White noise on a random walk, in weighted units (residual / sigma).
#[derive(Debug, Clone, Copy, Default)]
struct Level {
    /// Variance of the white part.
    white: f64,
    /// Variance the walk gains per second.
    walk: f64,
}

/// A residual series: one pose component of a run's pose residuals, read in
/// place (a million-row log's three series were 48 MB as copies).
struct Series<'a> {
    /// the run's row times: the step before row k + 1 is `t[k + 1] - t[k]`
    t: &'a [f64],
    /// the run's pose residuals, (x, y, heading) triples for rows 1..
    values: &'a [f64],
    component: usize,
    /// the variance of the start the series is anchored on, in units of
    /// the white variance
    anchor: f64,
}

impl Series<'_> {
    /// Each row's time step and value.
    fn rows(&self) -> impl Iterator<Item = (f64, f64)> + '_ {
        let n = self.values.len() / 3;
        (0..n).map(|k| {
            (
                self.t[k + 1] - self.t[k],
                self.values[3 * k + self.component],
            )
        })
    }
}

/// The local-level model of residual series fitted by maximum likelihood: a
/// scalar Kalman filter gives the likelihood for a ratio walk / white, with
/// the white variance concentrated out in closed form; the ratio is chosen on
/// a grid of quarter decades (and 0: white only). Window moments were tried
/// first: with 70 windows in a 364 s log their sampling noise alone read as a
/// walk that inflated the standard deviations 30-fold.
fn local_level(series: &[Series]) -> Level {
    let sums = |lambda: f64| {
        let (mut ss, mut logf, mut n) = (0.0, 0.0, 0.0);
        // sum ln f as the ln of running products (f >= 1, so they only
        // grow): one logarithm per few hundred rows instead of one a row,
        // which on a million-row log was a tenth of the whole fit's time
        let mut product = 1.0;
        for one in series {
            let (mut w, mut p) = (0.0, one.anchor);
            for (dt, y) in one.rows() {
                let pred = p + lambda * dt;
                let f = pred + 1.0;
                let v = y - w;
                ss += v * v / f;
                let grown = product * f;
                if grown < 1e250 {
                    product = grown;
                } else {
                    // before it could overflow (and a NaN goes on as one)
                    logf += product.ln() + f.ln();
                    product = 1.0;
                }
                n += 1.0;
                let gain = pred / f;
                w += gain * v;
                p = pred * (1.0 - gain);
            }
        }
        (ss, logf + product.ln(), n)
    };
    // the log-likelihood and level at the ratio `q` quarter decades above
    // 1e-9 (None: 0, white only); None when the series are too short
    let at = |q: Option<i32>| -> Option<(f64, Level)> {
        let lambda = q.map_or(0.0, |q| 10f64.powf(-9.0 + 0.25 * f64::from(q)));
        let (ss, logf, n) = sums(lambda);
        if n < 2.0 || ss <= 0.0 {
            return None;
        }
        let white = ss / n;
        let loglik = -0.5 * n * white.ln() - 0.5 * logf;
        Some((
            loglik,
            Level {
                white,
                walk: lambda * white,
            },
        ))
    };
    let mut best: Option<(f64, Level, Option<i32>)> = None;
    // the grid's whole decades first, then its quarter decades within a
    // decade of the best: the likelihood has one maximum in the ratio, so
    // this is the whole grid's choice with 20 passes over the residuals
    // instead of 50 (a tenth of a million-row fit's time)
    let decades = std::iter::once(None).chain((0..=12).map(|d| Some(4 * d)));
    for q in decades {
        let Some((loglik, level)) = at(q) else {
            return Level::default();
        };
        if best.as_ref().is_none_or(|b| loglik > b.0) {
            best = Some((loglik, level, q));
        }
    }
    if let Some((_, _, Some(centre))) = best {
        let quarters = (centre - 3..=centre + 3).filter(|q| q % 4 != 0 && (0..=48).contains(q));
        for q in quarters {
            if let Some((loglik, level)) = at(Some(q)) {
                if best.as_ref().is_none_or(|b| loglik > b.0) {
                    best = Some((loglik, level, Some(q)));
                }
            }
        }
    }
    best.map(|b| b.1).unwrap_or_default()
}

/// The series of pose component `c` (x, y, heading) of a run's pose
/// residuals (`values`: (x, y, heading) triples for ground-truth rows 1..).
fn series<'a>(run: &'a Run, values: &'a [f64], component: usize) -> Series<'a> {
    Series {
        t: &run.t,
        values: &values[..3 * pose_rows(run)],
        component,
        anchor: 1.0 / run.rest_steps().max(1) as f64,
    }
}

/// The number of pose residual triples of a run: one per ground-truth row
/// after the first.
fn pose_rows(run: &Run) -> usize {
    run.gt.as_ref().map_or(0, |g| g.len().saturating_sub(1))
}

/// Per pose component, a sum of Jacobian rows over a run's triples: x, y and
/// heading, and the x rows times the measured y and the y rows times the
/// measured x (a heading error's lever arm).
#[derive(Clone)]
struct RowSums {
    x: DVector<f64>,
    y: DVector<f64>,
    th: DVector<f64>,
    xy: DVector<f64>,
    yx: DVector<f64>,
}

impl RowSums {
    fn zeros(width: usize) -> RowSums {
        let z = DVector::zeros(width);
        RowSums {
            x: z.clone(),
            y: z.clone(),
            th: z.clone(),
            xy: z.clone(),
            yx: z,
        }
    }

    /// Add triple k's rows, measured at position `at`.
    fn add(&mut self, rows: &[DVector<f64>; 3], at: [f64; 2]) {
        self.xy.axpy(at[1], &rows[0], 1.0);
        self.yx.axpy(at[0], &rows[1], 1.0);
        self.x += &rows[0];
        self.y += &rows[1];
        self.th += &rows[2];
    }

    /// `self` - `before`: the sums over the rows from here on.
    fn minus(&self, before: &RowSums) -> RowSums {
        RowSums {
            x: &self.x - &before.x,
            y: &self.y - &before.y,
            th: &self.th - &before.th,
            xy: &self.xy - &before.xy,
            yx: &self.yx - &before.yx,
        }
    }

    /// How the rows summed move with a heading error at `from`: the heading
    /// rows, and the positions turned about `from` (in weighted units).
    fn turn(&self, from: [f64; 3], lever: f64) -> DVector<f64> {
        &self.th - (&self.xy - &self.x * from[1]) * lever + (&self.yx - &self.y * from[0]) * lever
    }
}

/// The first pass over a run's pose rows with their Jacobian: J^T J of every
/// row (the start heading's prior row too), and the sums of the triples' rows
/// ([`RowSums`]), from which the second pass takes the sums over the rows
/// after each step.
struct Totals<'a> {
    run: &'a Run,
    triples: usize,
    seen: usize,
    /// J^T J, as square roots, of the x, the y and the heading rows apart
    /// (M weighs each by its own white variance), and of the other rows
    /// (the start heading's prior)
    parts: [SquareRoot; 4],
    sums: RowSums,
    triple: [DVector<f64>; 3],
}

impl<'a> Totals<'a> {
    fn new(run: &'a Run, width: usize) -> Totals<'a> {
        Totals {
            run,
            triples: 3 * pose_rows(run),
            seen: 0,
            parts: std::array::from_fn(|_| SquareRoot::zeros(width)),
            sums: RowSums::zeros(width),
            triple: std::array::from_fn(|_| DVector::zeros(width)),
        }
    }
}

/// Position (x, y) of residual triple k (ground-truth row k + 1).
fn measured_at(run: &Run, k: usize) -> [f64; 2] {
    let g = &run.gt.as_ref().unwrap()[k + 1];
    [g[0], g[1]]
}

impl Sink for Totals<'_> {
    fn push(&mut self, _: f64, row: Option<impl Iterator<Item = f64>>) {
        let v = DVector::from_iterator(self.parts[0].dim(), row.expect("rows"));
        if self.seen >= self.triples {
            self.parts[3].add(1.0, &v);
        } else {
            let (k, c) = (self.seen / 3, self.seen % 3);
            self.parts[c].add(1.0, &v);
            self.triple[c] = v;
            if c == 2 {
                self.sums.add(&self.triple, measured_at(self.run, k));
            }
        }
        self.seen += 1;
    }
}

/// The rows other than the pose's (gyro, landmarks): their J^T J, which
/// counts in M too, as white noise at their own variance.
struct Rest(SquareRoot);

impl Sink for Rest {
    fn push(&mut self, _: f64, row: Option<impl Iterator<Item = f64>>) {
        let v = DVector::from_iterator(self.0.dim(), row.expect("rows"));
        self.0.add(1.0, &v);
    }
}

/// The second pass over a run's pose rows: M, white noise on every row, each
/// component's walk and the anchoring start pose's noise. A component's walk
/// injected during the step that ends at triple k moves that component of
/// every later row: it weighs the sum of the rows from k on, which is the
/// run's total ([`Totals`]) minus the rows before k, so the rows are read
/// once, forward, as they are made, and never held. (Each component's walk
/// is fitted to its own series, so a heading walk's effect on the positions
/// is already in theirs and is not carried over again.)
struct Meat<'a> {
    run: &'a Run,
    noise: [Level; 2],
    /// lever-arm factor in weighted units: heading sigma / position sigma
    lever: f64,
    /// Per step, the pose change its inputs' rounding errors make, one
    /// standard deviation each, in weighted units (see [`rounding`]), and
    /// whether the step starts a run of rows logging the same value; empty
    /// where the inputs are not rounded.
    rounding: Vec<Vec<([f64; 3], bool)>>,
    totals: RowSums,
    before: RowSums,
    triples: usize,
    seen: usize,
    triple: [DVector<f64>; 3],
    /// Per rounded input, its current error's moves summed over the rows
    /// that share it.
    shared: Vec<DVector<f64>>,
    meat: SquareRoot,
}

impl Meat<'_> {
    fn level(&self, c: usize) -> Level {
        self.noise[usize::from(c == 2)]
    }

    /// The walks triple k injects and its inputs' rounding (its white
    /// noise is [`Totals::parts`]' J^T J, weighed in [`Passes::information`]).
    fn step(&mut self, k: usize) {
        let after = self.totals.minus(&self.before);
        let dt = self.run.t[k + 1] - self.run.t[k];
        for (c, s) in [&after.x, &after.y, &after.th].into_iter().enumerate() {
            self.meat.add(self.level(c).walk * dt, s);
        }
        // an input's rounding in this step moves every later row: its
        // position, and its heading with the lever arm from here. Rows that
        // share one error (see rounding::held) add their moves up before they
        // count, once per run of equal values.
        if let Some(errors) = self.rounding.get(k).filter(|e| !e.is_empty()) {
            let from = self.run.gt.as_ref().unwrap()[k];
            let turn = after.turn(from, self.lever);
            let width = self.meat.dim();
            self.shared.resize(errors.len(), DVector::zeros(width));
            for ((e, starts), sum) in errors.iter().zip(self.shared.iter_mut()) {
                if *starts {
                    self.meat.add(1.0, sum);
                    sum.fill(0.0);
                }
                *sum += &after.x * e[0] + &after.y * e[1] + &turn * e[2];
            }
        }
        self.before.add(&self.triple, measured_at(self.run, k));
    }

    /// M, with the last shared rounding errors and the start pose's noise.
    /// The start pose the track is anchored on is the mean of the rows it
    /// rests on first (Run::start_pose), each with the white noise. Its
    /// heading error turns the whole track about it (the lever arm of every
    /// later row), unless the fit refines the start heading (`turned`): the
    /// offset then cancels it, and it is left only in the start heading's
    /// prior row, which carries it already.
    fn finish(mut self, turned: bool) -> SquareRoot {
        for sum in &self.shared {
            self.meat.add(1.0, sum);
        }
        if self.triples == 0 {
            return self.meat;
        }
        let rested = self.run.rest_steps().max(1) as f64;
        let t = &self.totals;
        self.meat.add(self.level(0).white / rested, &t.x);
        self.meat.add(self.level(1).white / rested, &t.y);
        if !turned {
            let turn = t.turn(self.run.start_pose(), self.lever);
            self.meat.add(self.level(2).white / rested, &turn);
        }
        self.meat
    }
}

impl Sink for Meat<'_> {
    fn push(&mut self, _: f64, row: Option<impl Iterator<Item = f64>>) {
        let v = DVector::from_iterator(self.meat.dim(), row.expect("rows"));
        // the rows after the triples (the start heading's prior) are white
        // at their own variance: Totals' fourth part holds them
        if self.seen < self.triples {
            let (k, c) = (self.seen / 3, self.seen % 3);
            self.triple[c] = v;
            if c == 2 {
                self.step(k);
            }
        }
        self.seen += 1;
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
    let offsets = run_offsets(runs, &res.starts);
    let passes = Passes::new(r, o, &res.free);
    // the residuals alone first: the noise model is fitted to them
    let values: Vec<(Vec<f64>, Vec<f64>)> = runs
        .par_iter()
        .zip(&cols)
        .zip(&offsets)
        .map(|((run, col), start)| passes.values(run, *start, col.is_some()))
        .collect();
    let mut position = Vec::new();
    let mut heading = Vec::new();
    for (run, (pose, _)) in runs.iter().zip(&values) {
        if run.gt.is_some() {
            position.extend([series(run, pose, 0), series(run, pose, 1)]);
            heading.push(series(run, pose, 2));
        }
    }
    let noise = [local_level(&position), local_level(&heading)];
    drop((position, heading));
    // the other residuals (gyro, landmarks) as white at their own variance
    let (sq, count) = values.iter().fold((0.0, 0usize), |(s, n), (_, rest)| {
        (s + rest.iter().map(|v| v * v).sum::<f64>(), n + rest.len())
    });
    drop(values);
    let rest_var = if count > 0 { sq / count as f64 } else { 1.0 };
    let rounding_sd: Vec<f64> = rounding::variances(r, runs)
        .into_iter()
        .map(f64::sqrt)
        .collect();
    let noise = RunNoise {
        levels: noise,
        rest_var,
        rounding_sd,
        lever: o.heading_sigma / o.pos_sigma,
    };
    let (mut h, mut meat) = (SquareRoot::zeros(dims), SquareRoot::zeros(dims));
    let locals: Vec<(SquareRoot, SquareRoot)> = runs
        .par_iter()
        .zip(&cols)
        .zip(&offsets)
        .map(|((run, col), start)| passes.information(run, *start, col.is_some(), &noise))
        .collect();
    for ((local_h, local_m), col) in locals.iter().zip(&cols) {
        let place = |c: usize| if c < m { c } else { col.unwrap() };
        h.merge(1.0, local_h, place);
        meat.merge(1.0, local_m, place);
    }
    for (c, _, slope) in priors(r, &r.p, &res.free) {
        let row = DVector::from_fn(dims, |k, _| if k == c { slope } else { 0.0 });
        h.add(1.0, &row);
        meat.add(1.0, &row);
    }
    let hinv = h.inverse(INVERSE_CUTOFF);
    let cov = meat.sandwiched(&hinv).view((0, 0), (m, m)).into_owned();
    set_covariance(r, res, &cov);
}

/// The weakest singular value of the information's square root, in units of
/// each unknown's own information, that [`sandwich`] inverts, relative to the
/// largest: a direction below it is left out. The rotations' round-off is
/// about 1e-16 times the square root of the rows (1e-13 at a million); a
/// 9,100 s log's weakest real direction was 6e-7.
const INVERSE_CUTOFF: f64 = 1e-10;

/// The residual noise the sandwich's M is made of.
struct RunNoise {
    /// Position's and heading's local levels.
    levels: [Level; 2],
    /// The other residuals' variance (white).
    rest_var: f64,
    /// Per input, its rounding's standard deviation (0: not rounded).
    rounding_sd: Vec<f64>,
    /// heading sigma / position sigma
    lever: f64,
}

/// The passes over each run's residuals at the estimate: pose and the rest
/// apart, each made again by dead reckoning as it is read (a run's rows are
/// never held: on a million-row log they were the fit's largest allocation).
struct Passes<'a> {
    r: &'a Runner,
    free: &'a [usize],
    pose: FitOptions,
    rest: FitOptions,
}

impl<'a> Passes<'a> {
    fn new(r: &'a Runner, o: &FitOptions, free: &'a [usize]) -> Passes<'a> {
        let only = |pose: bool| FitOptions {
            use_pose: pose,
            use_gyro: !pose && o.use_gyro,
            use_landmarks: !pose && o.use_landmarks,
            ..o.clone()
        };
        Passes {
            r,
            free,
            pose: only(true),
            rest: only(false),
        }
    }

    fn pass(&self, run: &Run, (start, nuis): ([f64; 3], bool), pose: bool, sink: &mut impl Sink) {
        let (o, with_jac) = (if pose { &self.pose } else { &self.rest }, true);
        let (r, free) = (self.r, self.free);
        run_residuals_into(r, &r.p, free, run, o, with_jac, (start, None), nuis, sink);
    }

    /// A run's pose residuals and its other residuals.
    fn values(&self, run: &Run, start: [f64; 3], nuis: bool) -> (Vec<f64>, Vec<f64>) {
        let (r, free) = (self.r, self.free);
        let values = |o: &FitOptions, rows: usize| {
            // a million rows' residuals, kept: reserved once, not doubled
            let mut kept = Kept::new(0);
            kept.res.reserve_exact(rows + 1);
            run_residuals_into(r, &r.p, free, run, o, false, (start, None), nuis, &mut kept);
            kept.res
        };
        let rest = run.gyro.as_ref().map_or(0, |_| run.steps()) + 2 * run.landmarks.len();
        (
            values(&self.pose, 3 * pose_rows(run)),
            values(&self.rest, rest),
        )
    }

    /// A run's H and M, in its own columns (the free parameters, then its
    /// start heading when it has one).
    fn information(
        &self,
        run: &Run,
        start: [f64; 3],
        nuis: bool,
        noise: &RunNoise,
    ) -> (SquareRoot, SquareRoot) {
        let width = self.free.len() + usize::from(nuis);
        let mut totals = Totals::new(run, width);
        self.pass(run, (start, nuis), true, &mut totals);
        let mut rest = Rest(SquareRoot::zeros(width));
        self.pass(run, (start, nuis), false, &mut rest);
        let mut meat = Meat {
            run,
            noise: noise.levels,
            lever: noise.lever,
            rounding: rounding_effects(self.r, run, &noise.rounding_sd, &self.pose),
            before: RowSums::zeros(width),
            totals: totals.sums,
            triples: totals.triples,
            seen: 0,
            triple: std::array::from_fn(|_| DVector::zeros(width)),
            shared: Vec::new(),
            meat: SquareRoot::zeros(width),
        };
        self.pass(run, (start, nuis), true, &mut meat);
        let mut meat = meat.finish(nuis);
        let mut info = SquareRoot::zeros(width);
        let white = noise.levels.map(|l| l.white);
        for (part, w) in totals.parts.iter().zip([white[0], white[0], white[1], 1.0]) {
            info.merge(1.0, part, |c| c);
            meat.merge(w, part, |c| c);
        }
        info.merge(1.0, &rest.0, |c| c);
        meat.merge(noise.rest_var, &rest.0, |c| c);
        (info, meat)
    }
}
