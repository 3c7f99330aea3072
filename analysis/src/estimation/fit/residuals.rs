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
#[allow(clippy::too_many_arguments)]
pub(super) fn run_residuals_into(
    r: &Runner,
    p: &[f64],
    free: &[usize],
    run: &Run,
    o: &FitOptions,
    with_jac: bool,
    (start, plan): ([f64; 3], Option<&[u8]>),
    nuis: bool,
    sink: &mut impl Sink,
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
    let track =
        deadreckon::run_executed(r, p, (&inputs, &timing), with_jac, start, plan, Some(&cols));
    let cx = RunCx {
        r,
        p,
        free: &cols,
        run,
        o,
        with_jac,
        track: &track,
        inputs: &inputs,
    };
    if o.use_pose {
        cx.pose_residuals(sink);
    }
    if let Some(sd) = start_prior(run, o).filter(|_| nuis) {
        // the start-heading offset against its measurement's uncertainty
        let m = cols.len() - 1;
        let row = (0..=m).map(|c| if c == m { 1.0 / sd } else { 0.0 });
        sink.push(start[2] / sd, with_jac.then_some(row));
    }
    if o.use_landmarks && !run.landmarks.is_empty() {
        let seen_from = match &run.gt {
            Some(gt) if o.sightings_from_truth => SeenFrom::Truth(gt),
            _ => SeenFrom::Track(&track),
        };
        landmark_residuals(r, p, &cols, run, seen_from, with_jac, sink);
    }
    if o.use_gyro {
        cx.gyro_residuals(sink);
    }
}

/// d pose / d pose: the pose residuals' Jacobian where the model has no pose
/// observation of its own.
const IDENTITY: [f64; 9] = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0];

/// One run's track and what its residuals read.
struct RunCx<'a> {
    r: &'a Runner,
    p: &'a [f64],
    /// sensitivity columns to read: the free parameters, then the start heading
    free: &'a [usize],
    run: &'a Run,
    o: &'a FitOptions,
    with_jac: bool,
    track: &'a deadreckon::Track,
    /// the inputs as executed (an input delay)
    inputs: &'a Run,
}

impl RunCx<'_> {
    /// The pose residuals against the ground truth (through the model's pose
    /// observation where it has one).
    #[allow(clippy::needless_range_loop)] // k indexes several per-row arrays of the run together
    fn pose_residuals(&self, sink: &mut impl Sink) {
        let (r, p, free, run, o, with_jac) =
            (self.r, self.p, self.free, self.run, self.o, self.with_jac);
        let (track, inputs) = (self.track, self.inputs);
        let np = p.len();
        // A measurement delay (crate::model_on_log::timeline): measurement k is compared with the
        // model at t_k - delay, linearly interpolated between rows (exact sensitivities
        // of the interpolation, and d/d delay = minus the interpolated velocity).
        let tau_i = r.delay;
        let tau = crate::model_on_log::timeline::delay(r, p);
        let shifted = |k: usize| crate::model_on_log::timeline::model_instant(run, k, tau);
        if let Some(gt) = &run.gt {
            let tracker = r.ir.observation_kernels(Pose);
            let first = if o.endpoints_only { gt.len() - 1 } else { 1 };
            let (mut pred, mut hx, mut hp) = ([0.0; 3], IDENTITY, vec![0.0; 3 * np]);
            let scratch = &mut Vec::new();
            // the state's sensitivities at the measurement's instant, d x_m /
            // d column, made once per row for its three residuals (`ds[m *
            // width + c]`: a third of the interpolations it took per residual)
            let width = free.len();
            let mut ds = vec![0.0; 3 * width];
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
                // the pose observation and its Jacobians, into buffers made
                // once (a million rows took three allocations each per pass)
                match tracker {
                    Some(t) => {
                        let h = t.value;
                        r.eval_into(h, &Runner::obs_args(h, &x, u, p, &[]), &mut pred, scratch);
                        if with_jac {
                            let fx = t.jac_x;
                            let args = Runner::obs_args(fx, &x, u, p, &[]);
                            r.eval_into(fx, &args, &mut hx, scratch);
                            if let Some(fp) = t.jac_p {
                                let args = Runner::obs_args(fp, &x, u, p, &[]);
                                r.eval_into(fp, &args, &mut hp, scratch);
                            }
                        }
                    }
                    None => pred = x,
                }
                if with_jac {
                    let sens = track.sens.as_ref().unwrap();
                    let (s0, s1) = (sens.at(j), sens.at(j + 1));
                    for (ci, &c) in free.iter().enumerate() {
                        for m in 0..3 {
                            ds[m * width + ci] = if Some(c) == tau_i {
                                -vel[m]
                            } else {
                                s0[(m, c)] + a * (s1[(m, c)] - s0[(m, c)])
                            };
                        }
                    }
                }
                let sig = [o.pos_sigma, o.pos_sigma, o.heading_sigma];
                let (hx, hp, ds) = (&hx, &hp[..], &ds);
                for i in 0..3 {
                    let d = pred[i] - gt[k][i];
                    let row = with_jac.then(|| {
                        free.iter().enumerate().map(move |(ci, &c)| {
                            let direct = if c < np { hp[i * np + c] } else { 0.0 };
                            chain(&hx[i * 3..i * 3 + 3], |m| ds[m * width + ci], direct) / sig[i]
                        })
                    });
                    sink.push(if i == 2 { wrap(d) } else { d } / sig[i], row);
                }
            }
        }
    }

    /// The gyro residuals: the track's predicted readings against the gyro's.
    fn gyro_residuals(&self, sink: &mut impl Sink) {
        let (r, p, free, run, o, with_jac) =
            (self.r, self.p, self.free, self.run, self.o, self.with_jac);
        let (track, inputs) = (self.track, self.inputs);
        let np = p.len();
        let mut scratch = Vec::new();
        if let (Some(g), Some(gyro)) = (&run.gyro, r.ir.observation_kernels(YawRate)) {
            let (hx, hp) = (gyro.jac_x, gyro.jac_p);
            let mut jp = vec![0.0; np];
            let mut jx = [0.0; 3];
            for k in 0..run.steps() {
                let x = track.pose[k];
                // the track already predicted the reading (Track::gyro)
                let value = (track.gyro[k] - g[k + 1]) / o.gyro_sigma;
                if !with_jac {
                    sink.push(value, None::<std::iter::Empty<f64>>);
                } else {
                    if let Some(hp) = hp {
                        r.eval_into(
                            hp,
                            &Runner::obs_args(hp, &x, &inputs.u[k], p, &[]),
                            &mut jp,
                            &mut scratch,
                        );
                    }
                    r.eval_into(
                        hx,
                        &Runner::obs_args(hx, &x, &inputs.u[k], p, &[]),
                        &mut jx,
                        &mut scratch,
                    );
                    let s = track.sens.as_ref().unwrap().at(k);
                    let row = free.iter().map(|&c| {
                        let direct = if c < np { jp[c] } else { 0.0 };
                        chain(&jx, |m| s[(m, c)], direct) / o.gyro_sigma
                    });
                    sink.push(value, Some(row));
                }
            }
        }
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
