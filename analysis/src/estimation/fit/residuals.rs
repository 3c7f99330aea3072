//! The weighted residuals a calibration minimises, their Jacobian, and the
//! Gauss-Newton normal equations summed run by run without forming it.
use super::sink::{huber_weight, Folded, Kept, Sink, Summed, Sums};
use super::FitOptions;
use crate::logs::column::Column;
use crate::logs::log::wrap;
use crate::logs::rows::Rows;
use crate::model_on_log::deadreckon;
use crate::model_on_log::interp::{chain, lerp3};
use crate::model_on_log::model::Runner;
use crate::model_on_log::run::Run;
use kinegen_model::decl::ObservationRole::{Pose, RangeBearing, YawRate};
use kinegen_model::ir::ObservationKernels;
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;

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
pub(super) fn has_start_nuisance(run: &Run, o: &FitOptions) -> bool {
    let rested = run.rest_steps() > 0 && run.t[run.rest_steps()] - run.t[0] >= 0.5;
    o.estimate_start
        && ((o.use_pose && run.gt.is_some())
            || (!rested && o.use_landmarks && !run.landmarks.is_empty()))
}

/// The standard deviation of a run's measured start heading when the rest it
/// starts with measures it (None: refined freely).
pub(super) fn start_prior(run: &Run, o: &FitOptions) -> Option<f64> {
    o.use_pose.then(|| run.start_heading_std()).flatten()
}

/// Column of each run's start-heading offset in the Jacobian (after the parameters).
pub(super) fn start_columns(runs: &[Run], o: &FitOptions, m: usize) -> Vec<Option<usize>> {
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
pub(super) fn priors(r: &Runner, p: &[f64], free: &[usize]) -> Vec<(usize, f64, f64)> {
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
    // per run: A^T A, A^T b, b^T b, A^T r, b^T r (A: parameter columns, b:
    // start heading), folded in as the run's residuals are made
    let parts: Vec<Folded> = runs
        .par_iter()
        .enumerate()
        .map(|(i, run)| {
            let nuis = cols[i].is_some();
            let mut folded = Folded::new(m, nuis, o.huber);
            let start = starts.get(i).copied().unwrap_or([0.0; 3]);
            let track = (start, o.plan(i));
            run_residuals_into(r, p, free, run, o, true, track, nuis, &mut folded);
            folded.finish()
        })
        .collect();
    let mut sums = Sums::default();
    let mut jtj = DMatrix::zeros(n, n);
    let mut jtr = DVector::zeros(n);
    for (i, part) in parts.into_iter().enumerate() {
        sums.add(part.squares.sums());
        let mut top = jtj.view_mut((0, 0), (m, m));
        top += &part.ata;
        let mut g = jtr.rows_mut(0, m);
        g += &part.atr;
        if let Some(c) = cols[i] {
            for k in 0..m {
                jtj[(k, c)] += part.atb[k];
                jtj[(c, k)] += part.atb[k];
            }
            jtj[(c, c)] += part.btb;
            jtr[c] += part.btr;
        }
    }
    for (c, value, slope) in priors(r, p, free) {
        jtj[(c, c)] += slope * slope;
        jtr[c] += slope * value;
        sums.cost += 0.5 * value * value;
    }
    (sums, jtj, jtr)
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
            let mut summed = Summed::new(o.huber);
            let track = (start, o.plan(i));
            run_residuals_into(
                r,
                p,
                free,
                run,
                o,
                false,
                track,
                cols[i].is_some(),
                &mut summed,
            );
            summed.squares.sums()
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

/// [`huber_weight`] applied to residuals and their Jacobian rows.
pub(super) fn huber_weights(res: &mut [f64], jac: Option<&mut DMatrix<f64>>, k: f64) {
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

/// One run's residuals, kept; Jacobian rows have the free parameters'
/// columns, then (with `nuis`) the start-heading column.
#[allow(clippy::too_many_arguments)]
pub(super) fn run_residuals(
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
    let mut kept = Kept::new(free.len() + usize::from(nuis));
    let track = (start, plan);
    run_residuals_into(r, p, free, run, o, with_jac, track, nuis, &mut kept);
    (kept.res, kept.jac)
}

/// One run's residuals (and with `with_jac` their Jacobian rows), each given
/// to `sink` as it is made; the track starts at the measured start pose plus
/// `start`, sub-stepped as `plan` says.
///
/// In the order pose, start prior, landmarks, gyro; a sink that does not
/// mind the order ([`Sink::ORDER_FREE`]) may get the pose and gyro
/// residuals interleaved. Where no residual reads the track out of order
/// (a measurement delay interpolates it, landmarks seen from it are
/// sighted between rows), the track is not kept: each step's residuals are
/// made as the dead reckoning makes it ([`deadreckon::reckon`]).
#[allow(clippy::too_many_arguments)]
pub(super) fn run_residuals_into<S: Sink>(
    r: &Runner,
    p: &[f64],
    free: &[usize],
    run: &Run,
    o: &FitOptions,
    with_jac: bool,
    (start, plan): ([f64; 3], Option<&[u8]>),
    nuis: bool,
    sink: &mut S,
) {
    // the inputs as executed (an input delay, a lag): the track's, and the
    // observations' arguments
    let (inputs, timing) = crate::model_on_log::timeline::executed_with_rates(r, p, run, with_jac);
    let np = p.len();
    // sensitivity columns to read: the free parameters, then the start heading
    let cols: Vec<usize> = free
        .iter()
        .copied()
        .chain(if nuis { vec![np + 2] } else { vec![] })
        .collect();
    let cx = RunCx {
        r,
        p,
        free: &cols,
        run,
        o,
        with_jac,
        inputs: &inputs,
        pose_kernels: r.ir.observation_kernels(Pose),
        gyro_kernels: r.ir.observation_kernels(YawRate),
    };
    let pose = o.use_pose && run.gt.is_some();
    let gyro = o.use_gyro && run.gyro.is_some() && cx.gyro_kernels.is_some();
    let landmarks = o.use_landmarks && !run.landmarks.is_empty();
    let from_truth = match &run.gt {
        Some(gt) if o.sightings_from_truth => Some(gt),
        _ => None,
    };
    let streamed = r.delay.is_none()
        && (!landmarks || from_truth.is_some())
        && (S::ORDER_FREE || !(pose && gyro));
    let prior = |sink: &mut S| {
        if let Some(sd) = start_prior(run, o).filter(|_| nuis) {
            // the start-heading offset against its measurement's uncertainty
            let m = cols.len() - 1;
            let row = (0..=m).map(|c| if c == m { 1.0 / sd } else { 0.0 });
            sink.push(start[2] / sd, with_jac.then_some(row));
        }
    };
    if streamed {
        let seen = |sink: &mut S| {
            if let (true, Some(gt)) = (landmarks, from_truth) {
                landmark_residuals(r, p, &cols, run, SeenFrom::Truth(gt), with_jac, sink);
            }
        };
        if !pose {
            // no pose residuals: the gyro's come last, as when the track is kept
            prior(sink);
            seen(sink);
        }
        if !(pose || gyro) {
            // nothing reads the track (a pass of the sightings alone)
            return;
        }
        let mut rows = RowBuffers::new(np, cols.len());
        let first = cx.first_pose_row();
        deadreckon::reckon(
            r,
            p,
            (&inputs, &timing),
            with_jac,
            start,
            plan,
            Some(&cols),
            |s| {
                let sens = s.sens_from.zip(s.sens_to);
                if gyro {
                    cx.gyro_row(&mut rows, s.k, (&s.from, &s.twist), s.sens_from, sink);
                }
                if pose && s.k + 1 >= first {
                    cx.pose_row(&mut rows, s.k + 1, (s.k, 1.0), (&s.from, &s.to), sens, sink);
                }
            },
        );
        if pose {
            prior(sink);
            seen(sink);
        }
        return;
    }
    let track =
        deadreckon::run_executed(r, p, (&inputs, &timing), with_jac, start, plan, Some(&cols));
    if pose {
        cx.pose_residuals(&track, sink);
    }
    prior(sink);
    if landmarks {
        let seen_from = match from_truth {
            Some(gt) => SeenFrom::Truth(gt),
            None => SeenFrom::Track(&track),
        };
        landmark_residuals(r, p, &cols, run, seen_from, with_jac, sink);
    }
    if gyro {
        let mut rows = RowBuffers::new(np, cols.len());
        let sens = track.sens.as_ref();
        for k in 0..run.steps() {
            let at = (&track.pose[k], &track.twist[k]);
            cx.gyro_row(&mut rows, k, at, sens.map(|s| s.at(k)), sink);
        }
    }
}

/// d pose / d pose: the pose residuals' Jacobian where the model has no pose
/// observation of its own.
const IDENTITY: [f64; 9] = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0];

/// One run and what its residuals read besides the track.
struct RunCx<'a> {
    r: &'a Runner,
    p: &'a [f64],
    /// sensitivity columns to read: the free parameters, then the start heading
    free: &'a [usize],
    run: &'a Run,
    o: &'a FitOptions,
    with_jac: bool,
    /// the inputs as executed (an input delay)
    inputs: &'a Run,
    /// the pose and yaw-rate observations' kernels, looked up once a run
    pose_kernels: Option<ObservationKernels<'a>>,
    gyro_kernels: Option<ObservationKernels<'a>>,
}

/// What one row's residuals are made in, allocated once per run (a million
/// rows took three allocations each per pass).
struct RowBuffers {
    pred: [f64; 3],
    hx: [f64; 9],
    hp: Vec<f64>,
    /// the state's sensitivities at the measurement's instant, d x_m / d
    /// column (`ds[m * width + c]`), made once per row for its residuals
    ds: Vec<f64>,
    jp: Vec<f64>,
    jx: [f64; 3],
    scratch: Vec<f64>,
}

impl RowBuffers {
    fn new(np: usize, width: usize) -> RowBuffers {
        RowBuffers {
            pred: [0.0; 3],
            hx: IDENTITY,
            hp: vec![0.0; 3 * np],
            ds: vec![0.0; 3 * width],
            jp: vec![0.0; np],
            jx: [0.0; 3],
            scratch: Vec::new(),
        }
    }
}

impl RunCx<'_> {
    /// The first row with a pose residual.
    fn first_pose_row(&self) -> usize {
        match &self.run.gt {
            Some(gt) if self.o.endpoints_only => gt.len() - 1,
            _ => 1,
        }
    }

    /// The pose residuals against the ground truth (through the model's pose
    /// observation where it has one), read from a kept track.
    fn pose_residuals(&self, track: &deadreckon::Track, sink: &mut impl Sink) {
        let (r, p, run) = (self.r, self.p, self.run);
        let Some(gt) = &run.gt else { return };
        // A measurement delay (crate::model_on_log::timeline): measurement k is compared with the
        // model at t_k - delay, linearly interpolated between rows (exact sensitivities
        // of the interpolation, and d/d delay = minus the interpolated velocity).
        let tau = crate::model_on_log::timeline::delay(r, p);
        let shifted = |k: usize| crate::model_on_log::timeline::model_instant(run, k, tau);
        let mut rows = RowBuffers::new(p.len(), self.free.len());
        for k in self.first_pose_row()..gt.len() {
            let (j, a) = if r.delay.is_some() {
                shifted(k)
            } else {
                (k - 1, 1.0)
            };
            let ends = (&track.pose[j], &track.pose[j + 1]);
            let sens = track.sens.as_ref().map(|s| (s.at(j), s.at(j + 1)));
            self.pose_row(&mut rows, k, (j, a), ends, sens, sink);
        }
    }

    /// Measurement `k`'s pose residuals: the model at `a` of the way along
    /// step `j`, between poses `ends` with sensitivities `sens`.
    fn pose_row(
        &self,
        b: &mut RowBuffers,
        k: usize,
        (j, a): (usize, f64),
        ends: (&[f64; 3], &[f64; 3]),
        sens: Option<(deadreckon::SensAt, deadreckon::SensAt)>,
        sink: &mut impl Sink,
    ) {
        let (r, p, free, run, o, with_jac) =
            (self.r, self.p, self.free, self.run, self.o, self.with_jac);
        let Some(gt) = &run.gt else { return };
        let np = p.len();
        let tau_i = r.delay;
        let x = lerp3(ends.0, ends.1, a);
        let vel: [f64; 3] = [0, 1, 2].map(|i| (ends.1[i] - ends.0[i]) / run.dt[j]);
        let u = &self.inputs.u[j.min(run.steps() - 1)];
        match &self.pose_kernels {
            Some(t) => {
                let h = t.value;
                let args = Runner::obs_args(h, &x, u, p, &[]);
                r.eval_into(h, &args, &mut b.pred, &mut b.scratch);
                if with_jac {
                    let fx = t.jac_x;
                    let args = Runner::obs_args(fx, &x, u, p, &[]);
                    r.eval_into(fx, &args, &mut b.hx, &mut b.scratch);
                    if let Some(fp) = t.jac_p {
                        let args = Runner::obs_args(fp, &x, u, p, &[]);
                        r.eval_into(fp, &args, &mut b.hp, &mut b.scratch);
                    }
                }
            }
            None => b.pred = x,
        }
        let width = free.len();
        if let (true, Some((s0, s1))) = (with_jac, sens) {
            for (ci, &c) in free.iter().enumerate() {
                for m in 0..3 {
                    b.ds[m * width + ci] = if Some(c) == tau_i {
                        -vel[m]
                    } else {
                        s0[(m, c)] + a * (s1[(m, c)] - s0[(m, c)])
                    };
                }
            }
        }
        let sig = [o.pos_sigma, o.pos_sigma, o.heading_sigma];
        let (hx, hp, ds) = (&b.hx, &b.hp[..], &b.ds);
        for i in 0..3 {
            let d = b.pred[i] - gt[k][i];
            let row = with_jac.then(|| {
                free.iter().enumerate().map(move |(ci, &c)| {
                    let direct = if c < np { hp[i * np + c] } else { 0.0 };
                    chain(&hx[i * 3..i * 3 + 3], |m| ds[m * width + ci], direct) / sig[i]
                })
            });
            sink.push(if i == 2 { wrap(d) } else { d } / sig[i], row);
        }
    }

    /// Step `k`'s gyro residual: the reading the step from pose `x` at
    /// `twist` predicts (as [`deadreckon::Track::gyro`]) against the gyro's,
    /// with `sens` the pose's sensitivities at `x`.
    fn gyro_row(
        &self,
        b: &mut RowBuffers,
        k: usize,
        (x, twist): (&[f64; 3], &[f64; 3]),
        sens: Option<deadreckon::SensAt>,
        sink: &mut impl Sink,
    ) {
        let (r, p, free, run, o) = (self.r, self.p, self.free, self.run, self.o);
        let (Some(g), Some(kernels)) = (&run.gyro, &self.gyro_kernels) else {
            return;
        };
        let np = p.len();
        let u = &self.inputs.u[k];
        let predicted = deadreckon::gyro_at(r, Some(kernels.value), p, u, x, twist, &mut b.scratch);
        let value = (predicted - g[k + 1]) / o.gyro_sigma;
        let Some(s) = sens.filter(|_| self.with_jac) else {
            sink.push(value, None::<std::iter::Empty<f64>>);
            return;
        };
        if let Some(hp) = kernels.jac_p {
            let args = Runner::obs_args(hp, x, u, p, &[]);
            r.eval_into(hp, &args, &mut b.jp, &mut b.scratch);
        }
        let hx = kernels.jac_x;
        r.eval_into(
            hx,
            &Runner::obs_args(hx, x, u, p, &[]),
            &mut b.jx,
            &mut b.scratch,
        );
        let (jp, jx) = (&b.jp, &b.jx);
        let row = free.iter().map(|&c| {
            let direct = if c < np { jp[c] } else { 0.0 };
            chain(jx, |m| s[(m, c)], direct) / o.gyro_sigma
        });
        sink.push(value, Some(row));
    }
}

/// The pose a landmark sighting is predicted from.
pub(super) enum SeenFrom<'a> {
    /// The measured pose (the log's ground truth), where the fit uses it: the
    /// sightings then calibrate the sensor alone. Seen from the dead-reckoned
    /// track, they were mostly that track's drift: on MRCLAM's 15-minute
    /// logs 2.4 m of it against the camera's 5 cm, and a camera that reads
    /// depth in place of range calibrated to 0.36 of it, not 1.
    Truth(&'a Column<[f64; 3]>),
    /// The model's track: without ground truth the sightings are the pose
    /// information, and calibrate the motion through it.
    Track(&'a deadreckon::Track),
}

/// Range and bearing residuals of every landmark observation (seed 001 eq. 6),
/// predicted from the pose at the observation time (see [`SeenFrom`]);
/// sigmas from the spec's `landmark` observation. Jacobian: H_p, plus H_x
/// times the interpolated pose sensitivity when seen from the track.
#[allow(clippy::too_many_arguments)]
pub(super) fn landmark_residuals(
    r: &Runner,
    p: &[f64],
    free: &[usize],
    run: &Run,
    seen_from: SeenFrom,
    with_jac: bool,
    sink: &mut impl Sink,
) {
    let Some(sensor) = r.ir.observation_kernels(RangeBearing) else {
        return;
    };
    let h = sensor.value;
    let sig = crate::model_on_log::landmarks::sigma(r);
    let np = p.len();
    for o in &run.landmarks {
        let (j, a, x) = match seen_from {
            SeenFrom::Track(track) => crate::model_on_log::innovations::locate_on(run, track, o.t),
            // a sighting the truth cannot place is no evidence about the sensor
            SeenFrom::Truth(gt) => match crate::model_on_log::innovations::truth_at(run, gt, o.t) {
                // (the fraction of the step matters only along the track)
                Some((j, x)) => (j, 0.0, x),
                None => continue,
            },
        };
        let u = &run.u[j.min(run.steps() - 1)];
        let lm = [o.xl, o.yl];
        let pred = r.eval(h, &Runner::obs_args(h, &x, u, p, &lm));
        let values = [
            (pred[0] - o.range) / sig[0],
            wrap(pred[1] - o.bearing) / sig[1],
        ];
        if !with_jac {
            for v in values {
                sink.push(v, None::<std::iter::Empty<f64>>);
            }
        } else {
            let hp = sensor.jac_p.map_or(vec![], |fp| {
                r.eval(fp, &Runner::obs_args(fp, &x, u, p, &lm))
            });
            let direct = |i: usize, c: usize| if c < np { hp[i * np + c] } else { 0.0 };
            // seen from the truth, the pose does not move with the parameters
            let through_track = match seen_from {
                SeenFrom::Track(track) => {
                    let fx = sensor.jac_x;
                    let hx = r.eval(fx, &Runner::obs_args(fx, &x, u, p, &lm));
                    Some((track.sens.as_ref().unwrap(), hx))
                }
                SeenFrom::Truth(_) => None,
            };
            for (i, value) in values.into_iter().enumerate() {
                let row = free.iter().map(|&c| match &through_track {
                    None => direct(i, c) / sig[i],
                    Some((sens, hx)) => {
                        let (s0, s1) = (sens.at(j), sens.at(j + 1));
                        let dx = |m: usize| s0[(m, c)] + a * (s1[(m, c)] - s0[(m, c)]);
                        chain(&hx[i * 3..i * 3 + 3], dx, direct(i, c)) / sig[i]
                    }
                });
                sink.push(value, Some(row));
            }
        }
    }
}

/// The residuals of `run`'s landmark sightings seen from its ground-truth
/// pose (empty without one; none for a sighting the truth cannot place, see
/// [`crate::model_on_log::innovations::truth_at`]), with their Jacobian in the `free` parameters
/// when `with_jac`: what calibrates the range-bearing sensor alone
/// (`crate::diagnosis::sensor`).
pub fn sightings_from_truth(
    r: &Runner,
    p: &[f64],
    free: &[usize],
    run: &Run,
    with_jac: bool,
) -> (Vec<f64>, Rows) {
    let mut kept = Kept::new(free.len());
    if let Some(gt) = &run.gt {
        let seen_from = SeenFrom::Truth(gt);
        landmark_residuals(r, p, free, run, seen_from, with_jac, &mut kept);
    }
    (kept.res, kept.jac)
}
