//! One pass of the extended Kalman filter over a run (seed 001 eq. 1-9), with
//! the prediction cut at each sighting's own time.
use super::active::ACTIVE;
use super::belief::{Belief, ErrorPart, Owner};
use super::noise_model::{Lingering, NoiseModel, PERSISTENT_START_S, SHARED_START_S};
use super::{EkfOptions, LocalizeError};
use crate::logs::log::wrap;
use crate::model_on_log::model::Runner;
use crate::model_on_log::run::Run;
use kinegen_jit::Evaluator;
use kinegen_model::decl::ObservationRole::RangeBearing;
use kinegen_model::ir::{ArgRole, Function, StepForm};
use nalgebra::{Matrix2, Matrix2x3, Matrix3, Matrix3x2, Vector2, Vector3};

/// A prediction shorter than this (s) moves nothing: a sighting at a row's
/// time, several sightings in one camera frame.
const NO_TIME: f64 = 1e-9;

/// The model's kernels the filter calls, fused so one call gives what a step
/// needs (the pose, F and G share the twist and the arc's sines).
pub struct Filter<'a> {
    r: &'a Runner,
    /// [pose (3), F_w (3 x nw)] of the exact step from the origin (F_x
    /// follows from the pose: see [`Belief::advance`]).
    step: Evaluator,
    /// [range, bearing (2), H_x (6)].
    observe: Evaluator,
    /// `[[noise]]` inputs of the spec (0: white noise on the body twist instead).
    nw: usize,
    obs_sigma: [f64; 2],
    gate: f64,
    start_sigma: [f64; 3],
}

/// The filter's state at one time: the prediction that reached it (with the
/// transition F from the node before) and the estimate after that time's
/// sightings.
#[derive(Debug, Clone)]
pub struct Node {
    pub t: f64,
    pub f: Matrix3<f64>,
    pub x_pred: Vector3<f64>,
    pub p_pred: Matrix3<f64>,
    pub x: Vector3<f64>,
    pub p: Matrix3<f64>,
}

/// A row's estimate.
#[derive(Debug, Clone, Copy)]
pub struct RowEstimate {
    pub x: [f64; 3],
    pub p: Matrix3<f64>,
}

/// One pass: the estimate at every row, every node (kept for the smoother),
/// and what the sightings said.
#[derive(Debug, Clone, Default)]
pub struct Pass {
    pub rows: Vec<RowEstimate>,
    /// Every node in time order, with `row_node[k]` the node of row k (kept
    /// only when asked for: the smoother reads them).
    pub nodes: Vec<Node>,
    pub row_node: Vec<usize>,
    /// (t, NIS) of each sighting used.
    pub nis: Vec<(f64, f64)>,
    pub accepted: usize,
    pub rejected: usize,
    /// Sightings outside the log's time span (not used, not rejected).
    pub outside: usize,
    /// The sightings' negative log-likelihood (robust beyond the gate: the
    /// noise estimate's objective).
    pub cost: f64,
}

impl Pass {
    /// A sighting this noise cannot be judged on: rejected, and the noise
    /// ruled out for the estimate (its cost infinite).
    fn unjudgeable(&mut self) {
        self.cost = f64::INFINITY;
        self.rejected += 1;
    }
}

impl<'a> Filter<'a> {
    pub fn new(r: &'a Runner, o: &EkfOptions) -> Result<Filter<'a>, LocalizeError> {
        let obs =
            r.ir.observation_kernels(RangeBearing)
                .ok_or(LocalizeError::NoLandmarkObservation)?;
        let exact = r.ir.step(StepForm::Exact);
        let nw = r.ir.noise.len();
        let mut parts = vec![exact.value];
        parts.extend(exact.jac_w.filter(|_| nw > 0));
        let nw = if parts.len() == 2 { nw } else { 0 };
        let fuse = |name: &str, parts: &[&Function]| {
            kinegen_model::fuse::fuse(name, parts)
                .expect("the parts of one model share argument sizes")
        };
        Ok(Filter {
            r,
            step: Evaluator::new(fuse("ekf_step", &parts)),
            observe: Evaluator::new(fuse("ekf_observe", &[obs.value, obs.jac_x])),
            nw,
            obs_sigma: crate::model_on_log::landmarks::sigma(r),
            gate: o.gate,
            start_sigma: o.start_sigma,
        })
    }

    /// The process noise the model itself declares, in its own form (or white
    /// noise on the twist, for a model without `[[noise]]`).
    pub fn declared_noise(&self) -> NoiseModel {
        if self.nw == 0 {
            return NoiseModel::twist_default();
        }
        NoiseModel {
            names: self.r.ir.noise.iter().map(|n| n.name.clone()).collect(),
            sigma: self.r.ir.noise.iter().map(|n| n.sigma).collect(),
            density: self.r.ir.noise.iter().map(|n| n.is_density()).collect(),
            obs_scale: [1.0; 2],
            persistent: Lingering::none(PERSISTENT_START_S),
            shared: Lingering::none(SHARED_START_S),
            range_reading: super::reading::RangeReading::STRAIGHT,
        }
    }

    /// The lingering parts of the sightings' errors that `noise` gives, as
    /// variances (the range's per metre of range).
    fn error_parts(&self, noise: &NoiseModel) -> Vec<ErrorPart> {
        [
            (&noise.persistent, Owner::Landmark(ACTIVE)),
            (&noise.shared, Owner::Sensor),
        ]
        .into_iter()
        .filter(|(part, _)| !part.is_none())
        .map(|(part, owner)| ErrorPart {
            var: Vector2::from_fn(|j, _| (self.obs_sigma[j] * part.factor[j]).powi(2)),
            memory_s: part.memory_s,
            owner,
        })
        .collect()
    }

    /// How many noise inputs the filter maps: the spec's `[[noise]]`, or the
    /// body twist's three.
    pub fn noise_count(&self) -> usize {
        if self.nw == 0 {
            3
        } else {
            self.nw
        }
    }

    /// What a run asks of the filter whatever its noise: the prediction
    /// segments (each row cut at its sightings' times) with their body-frame
    /// motion and noise Jacobian, computed once by the model's kernels.
    ///
    /// Every kinegen model moves its pose by a body twist that does not
    /// depend on the pose, so its exact step is SE(2)-equivariant (`kinegen
    /// verify` checks it): a segment's step from any pose is its step from
    /// the origin rotated and moved there, and its F and G follow. The noise
    /// estimate's hundred passes then cost a few 3x3 products a segment.
    pub fn plan(&self, run: &Run) -> Plan {
        let mut order: Vec<usize> = (0..run.landmarks.len()).collect();
        order.sort_by(|a, b| run.landmarks[*a].t.total_cmp(&run.landmarks[*b].t));
        let mut s = Scratch::new(self);
        let mut ids: std::collections::HashMap<&str, usize> = std::collections::HashMap::new();
        let landmark: Vec<usize> = run
            .landmarks
            .iter()
            .map(|z| {
                let n = ids.len();
                *ids.entry(&*z.id).or_insert(n)
            })
            .collect();
        let t_first = run.t[0];
        // the start's prior: the options' sigmas, plus the spread of the
        // sightings that placed it where the log has no ground truth (0.3-0.9
        // m on the MRCLAM robots, which a 5 cm prior made overconfident)
        let mut start_cov = Matrix3::from_diagonal(&Vector3::from(self.start_sigma.map(|s| s * s)));
        if let Some(c) = crate::model_on_log::deadreckon::start_covariance(self.r, &self.r.p, run) {
            start_cov += Matrix3::from_fn(|i, j| c[i][j]);
        }
        let mut plan = Plan {
            start: Vector3::from(crate::model_on_log::deadreckon::model_start(
                self.r, &self.r.p, run,
            )),
            start_cov,
            segments: Vec::with_capacity(run.steps() + run.landmarks.len()),
            sightings: Vec::with_capacity(run.landmarks.len()),
            first: 0,
            outside: 0,
            landmark,
            landmarks: ids.len(),
            nw: self.noise_count(),
            macros: Vec::new(),
        };
        let mut next = 0;
        while next < order.len() && run.landmarks[order[next]].t < t_first {
            plan.outside += 1;
            next += 1;
        }
        while next < order.len() && run.landmarks[order[next]].t <= t_first {
            plan.sightings.push((order[next], 0));
            next += 1;
        }
        plan.first = plan.sightings.len();
        for k in 0..run.steps() {
            let (t1, u) = (run.t[k + 1], &run.u[k]);
            let mut tau = run.t[k];
            loop {
                let at = order
                    .get(next)
                    .map(|&i| run.landmarks[i].t)
                    .filter(|&t| t <= t1);
                let until = at.unwrap_or(t1).max(tau);
                let from = plan.sightings.len();
                while let Some(&i) = order.get(next).filter(|&&i| run.landmarks[i].t <= until) {
                    plan.sightings.push((i, k));
                    next += 1;
                }
                let (delta, g) = self.body_step(u, until - tau, &mut s);
                plan.segments.push(Segment {
                    turn: delta[2].sin_cos(),
                    t: until,
                    h: until - tau,
                    dt_row: run.dt[k],
                    delta,
                    g,
                    sightings: (from, plan.sightings.len()),
                    row_end: at.is_none(),
                });
                tau = until;
                if at.is_none() {
                    break;
                }
            }
        }
        plan.outside += order.len() - next;
        plan.compose();
        plan
    }

    /// One segment's motion from the origin over `h` s with inputs `u`, and
    /// its noise Jacobian there (3 x noise inputs, row-major).
    fn body_step(&self, u: &[f64], h: f64, s: &mut Scratch) -> ([f64; 3], Vec<f64>) {
        let nw = self.noise_count();
        if h < NO_TIME {
            return ([0.0; 3], vec![0.0; 3 * nw]);
        }
        let origin = [0.0; 3];
        let dt = [h];
        {
            let args: Vec<&[f64]> = self
                .step
                .args
                .iter()
                .map(|a| Runner::step_arg(a, &origin, u, &self.r.p, &dt, &s.zeros))
                .collect();
            self.step.eval_into(&args, &mut s.step_out, &mut s.tape);
        }
        let o = &s.step_out;
        let g = if self.nw > 0 {
            o[3..3 + 3 * self.nw].to_vec()
        } else {
            // white noise on the body twist (vx, vy, omega)
            vec![h, 0.0, 0.0, 0.0, h, 0.0, 0.0, 0.0, h]
        };
        ([o[0], o[1], o[2]], g)
    }

    /// Run the filter over `run` with `noise`, keeping what `keep` says.
    pub fn run(&self, run: &Run, noise: &NoiseModel, keep: Keep) -> Result<Pass, LocalizeError> {
        self.run_plan(&self.plan(run), run, noise, keep)
    }

    /// Run the filter along a [`Plan`] of `run` with `noise`.
    pub fn run_plan(
        &self,
        plan: &Plan,
        run: &Run,
        noise: &NoiseModel,
        keep: Keep,
    ) -> Result<Pass, LocalizeError> {
        let mut s = Scratch::new(self);
        let mut b = Belief::new(
            plan.start,
            plan.start_cov,
            plan.landmarks,
            &self.error_parts(noise),
            run.t[0],
        );
        let mut pass = Pass {
            outside: plan.outside,
            ..Pass::default()
        };
        let mut at = Sightings {
            plan,
            run,
            noise,
            pass: &mut pass,
            s: &mut s,
        };
        self.sightings(&mut b, &mut at, (0, plan.first), run.t[0])?;
        let node = Node {
            t: run.t[0],
            f: Matrix3::identity(),
            x_pred: plan.start,
            p_pred: plan.start_cov,
            x: b.x,
            p: b.p,
        };
        close(at.pass, node, keep, true);
        if keep == Keep::Cost {
            for m in &plan.macros {
                predict_macro(&mut b, m, noise);
                self.sightings(&mut b, &mut at, m.sightings, m.t)?;
            }
            return Ok(pass);
        }
        for seg in &plan.segments {
            let f = predict(&mut b, seg, plan.nw, noise);
            let mut node = Node {
                t: seg.t,
                f,
                x_pred: b.x,
                p_pred: b.p,
                x: b.x,
                p: b.p,
            };
            self.sightings(&mut b, &mut at, seg.sightings, seg.t)?;
            node.x = b.x;
            node.p = b.p;
            close(at.pass, node, keep, seg.row_end);
        }
        Ok(pass)
    }

    /// Update with the plan's sightings `range` (at time `t`), then check
    /// that the estimate is still finite.
    fn sightings(
        &self,
        b: &mut Belief,
        at: &mut Sightings,
        range: (usize, usize),
        t: f64,
    ) -> Result<(), LocalizeError> {
        for &(i, k) in &at.plan.sightings[range.0..range.1] {
            self.update(b, at, i, &at.run.u[k]);
        }
        if b.x.iter().all(|v| v.is_finite()) {
            Ok(())
        } else {
            Err(LocalizeError::Diverged {
                path: at.run.path.clone(),
                t,
            })
        }
    }
}

/// Record a node (and a row's estimate when it ends a row).
fn close(pass: &mut Pass, node: Node, keep: Keep, row_end: bool) {
    if keep == Keep::Cost {
        return;
    }
    if row_end {
        pass.rows.push(RowEstimate {
            x: [node.x[0], node.x[1], node.x[2]],
            p: node.p,
        });
    }
    if keep == Keep::Nodes {
        if row_end {
            pass.row_node.push(pass.nodes.len());
        }
        pass.nodes.push(node);
    }
}

impl<'a> Filter<'a> {
    /// Update with sighting `i` (eq. 6-9), or reject it at the gate; add its
    /// share of the likelihood to the pass.
    fn update(&self, b: &mut Belief, at: &mut Sightings, i: usize, u: &[f64]) {
        let Sightings {
            plan,
            run,
            noise,
            pass,
            s,
        } = at;
        let z = &run.landmarks[i];
        let lm = [z.xl, z.yl];
        let Some((straight, reading_cost)) = noise.range_reading.taken_back(z.range, z.bearing)
        else {
            // not a reading the likelihood can judge
            pass.unjudgeable();
            return;
        };
        let read = Vector2::new(straight, z.bearing);
        b.catch_up(z.t);
        let held = b.slots_for(plan.landmark[i], z.t);
        let white = |j: usize| (self.obs_sigma[j] * noise.obs_scale[j]).powi(2);
        let (bias, pb, bb) = b.of(&held);
        let prior = Prior {
            bias,
            pb,
            bb,
            rm: Matrix2::new(white(0), 0.0, 0.0, white(1)),
        };
        let e = self.expand(b, &prior, &b.x, (&read, u, &lm), s);
        let Some(si) = e.sm.try_inverse() else {
            pass.rejected += 1;
            return;
        };
        let nis = (e.y.transpose() * si * e.y)[(0, 0)];
        if !(e.sm[(0, 0)] > 0.0 && e.sm.determinant() > 0.0 && nis >= 0.0) {
            // rounding has left the covariance indefinite: this noise is not
            // one the likelihood can judge
            pass.unjudgeable();
            return;
        }
        // beyond the gate the cost grows with the log of the NIS (a robust
        // tail, continuous in value and slope at the gate): outliers do not
        // pull the noise up, and a filter that rejects everything is still
        // told which way to go
        let robust = if nis <= self.gate {
            nis
        } else {
            self.gate * (1.0 + (nis / self.gate).ln())
        };
        pass.cost += e.sm.determinant().max(1e-300).ln() + robust + reading_cost;
        if !nis.is_finite() || nis > self.gate {
            pass.rejected += 1;
            return;
        }
        let (e, si) = if far_from_linear(b, e.h[0]) {
            self.iterate(b, &prior, (e, si), (&read, u, &lm), s)
        } else {
            (e, si)
        };
        b.fuse(&held, (&e.hm, &e.d), &e.ph, (&e.sm, &si), &e.y);
        pass.nis.push((z.t, nis));
        pass.accepted += 1;
    }

    /// The sighting's first-order expansion at pose `x` (the prior's pose,
    /// or an iterate's): H = [hm | d at each held slot], the lingering range
    /// errors being per metre of range. `read` is the sighting's [range,
    /// bearing], its range taken back to straight-line by the noise's
    /// [`RangeReading`](super::reading::RangeReading).
    fn expand(
        &self,
        b: &Belief,
        prior: &Prior,
        x: &Vector3<f64>,
        (read, u, lm): (&Vector2<f64>, &[f64], &[f64; 2]),
        s: &mut Scratch,
    ) -> Expansion {
        let xs = [x[0], x[1], x[2]];
        let args: Vec<&[f64]> = self
            .observe
            .args
            .iter()
            .map(|a| match a.role {
                ArgRole::State => &xs[..],
                ArgRole::Inputs => u,
                ArgRole::Params => &self.r.p[..],
                ArgRole::Landmark => &lm[..],
                _ => &s.zeros[..a.names.len()],
            })
            .collect();
        self.observe.eval_into(&args, &mut s.obs_out, &mut s.tape);
        let o = &s.obs_out;
        let h = Vector2::new(o[0], o[1]);
        let hm = Matrix2x3::from_row_slice(&o[2..8]);
        let d = Matrix2::new(h[0].abs(), 0.0, 0.0, 1.0);
        // the innovation as seen from the prior: at the prior's own pose the
        // plain one, at an iterate's with the expansion carried back to it
        let mut y = read - h - d * prior.bias + hm * (x - b.x);
        y[1] = wrap(y[1]);
        // P H^T for the pose rows, and S
        let ph = b.p * hm.transpose() + prior.pb * d;
        let sm = hm * ph + d * prior.pb.transpose() * hm.transpose() + d * prior.bb * d + prior.rm;
        Expansion {
            h,
            hm,
            d,
            y,
            ph,
            sm,
        }
    }

    /// The iterated update (Bell and Cathey, 1993: Gauss-Newton on the
    /// update's least squares): the sighting expanded again at the updated
    /// pose until the update stops moving it, the lingering errors taken at
    /// their prior. Returns the last expansion and its S^-1, which
    /// [`Belief::fuse`] applies to the prior.
    fn iterate(
        &self,
        b: &Belief,
        prior: &Prior,
        first: (Expansion, Matrix2<f64>),
        at: (&Vector2<f64>, &[f64], &[f64; 2]),
        s: &mut Scratch,
    ) -> (Expansion, Matrix2<f64>) {
        let (mut e, mut si) = first;
        let mut x = b.x + e.ph * si * e.y;
        for _ in 1..ITERATIONS {
            let next = self.expand(b, prior, &x, at, s);
            let Some(next_si) = next.sm.try_inverse() else {
                break;
            };
            (e, si) = (next, next_si);
            let moved = b.x + e.ph * si * e.y;
            let step = (moved - x).abs().max();
            x = moved;
            if step < CONVERGED {
                break;
            }
        }
        (e, si)
    }
}

/// Where a sighting's expansion starts: the lingering errors it reads (their
/// sum, its covariance with the pose, its own) and the white part's R.
struct Prior {
    bias: Vector2<f64>,
    pb: Matrix3x2<f64>,
    bb: Matrix2<f64>,
    rm: Matrix2<f64>,
}

/// A sighting's first-order expansion (see [`Filter::expand`]).
struct Expansion {
    h: Vector2<f64>,
    hm: Matrix2x3<f64>,
    d: Matrix2<f64>,
    y: Vector2<f64>,
    ph: Matrix3x2<f64>,
    sm: Matrix2<f64>,
}

/// Whether a sighting at `range` m from a pose as uncertain as `b`'s is
/// beyond the first-order expansion: the position's standard deviation over
/// a tenth of the range, or the heading's over 0.1 rad (the neglected
/// second-order term then exceeds about 1% of the correction). A robot
/// started without motion capture begins so, put metres off by its first
/// few sightings.
fn far_from_linear(b: &Belief, range: f64) -> bool {
    let position = b.p[(0, 0)] + b.p[(1, 1)];
    position > (0.1 * range).powi(2) || b.p[(2, 2)] > 0.1f64.powi(2)
}

/// The iterated update's most expansions, and the move (m, rad) under which
/// it has converged.
const ITERATIONS: usize = 8;
const CONVERGED: f64 = 1e-6;

/// What a pass keeps besides its likelihood and counts.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Keep {
    /// Nothing (the noise estimate's passes).
    Cost,
    /// Every row's estimate.
    Rows,
    /// The rows and every node (the smoother's input).
    Nodes,
}

/// A run cut into prediction segments (see [`Filter::plan`]).
pub struct Plan {
    start: Vector3<f64>,
    start_cov: Matrix3<f64>,
    segments: Vec<Segment>,
    /// (sighting, row whose inputs hold then), in time order; the first
    /// `first` update the start.
    sightings: Vec<(usize, usize)>,
    first: usize,
    outside: usize,
    landmark: Vec<usize>,
    landmarks: usize,
    nw: usize,
    /// The segments from one sighting time to the next composed into one
    /// (see [`Macro`]): what the noise estimate's passes run on.
    macros: Vec<Macro>,
}

/// The segments between two sighting times as one prediction, in the body
/// frame of its start. The pose moves by `delta`; the process noise it adds
/// is `sum_i sigma_i^2 m[i]` (rotated into the world at run time), since
/// each segment's noise variance is sigma_i^2 times a factor of its length
/// and the transitions that carry it to the end do not depend on the noise.
/// A pass that needs no row estimates then costs one step per sighting time
/// rather than one per row.
struct Macro {
    delta: [f64; 3],
    turn: (f64, f64),
    /// Per noise input, its contribution at unit sigma (3 x 3, body frame),
    /// [as a density, as a per-row sigma].
    m: Vec<[Matrix3<f64>; 2]>,
    /// The sightings at the end (a range of `Plan::sightings`).
    sightings: (usize, usize),
    t: f64,
}

impl Plan {
    /// Compose the segments into [`Macro`]s.
    fn compose(&mut self) {
        let nw = self.nw;
        let mut out = Vec::new();
        let mut from = 0;
        while from < self.segments.len() {
            let mut to = from;
            while to + 1 < self.segments.len()
                && self.segments[to].sightings.0 == self.segments[to].sightings.1
            {
                to += 1;
            }
            let segs = &self.segments[from..=to];
            // positions after each segment, from the origin
            let (mut x, mut y, mut th) = (0.0f64, 0.0f64, 0.0f64);
            let mut after = Vec::with_capacity(segs.len());
            let mut heading = Vec::with_capacity(segs.len());
            for seg in segs {
                heading.push(th);
                let (sn, cs) = th.sin_cos();
                let [dx, dy, dth] = seg.delta;
                x += cs * dx - sn * dy;
                y += sn * dx + cs * dy;
                th += dth;
                after.push((x, y));
            }
            let mut m = vec![[Matrix3::zeros(); 2]; nw];
            for (j, seg) in segs.iter().enumerate() {
                if seg.h < NO_TIME {
                    continue;
                }
                let (sn, cs) = heading[j].sin_cos();
                // the transition from this segment's end to the macro's end
                let (xj, yj) = after[j];
                let (a, c) = (-(y - yj), x - xj);
                for (i, mi) in m.iter_mut().enumerate() {
                    let (gx, gy, gt) = (seg.g[i], seg.g[nw + i], seg.g[2 * nw + i]);
                    let g =
                        Vector3::new(cs * gx - sn * gy + a * gt, sn * gx + cs * gy + c * gt, gt);
                    let gg = g * g.transpose();
                    // variance per unit sigma^2: see NoiseModel::step_variance
                    mi[0] += gg / seg.h;
                    mi[1] += gg * (seg.dt_row / seg.h);
                }
            }
            let last = &segs[segs.len() - 1];
            out.push(Macro {
                delta: [x, y, th],
                turn: th.sin_cos(),
                m,
                sightings: last.sightings,
                t: last.t,
            });
            from = to + 1;
        }
        self.macros = out;
    }
}

/// One prediction: `h` s of a row of `dt_row` s, ending at `t` with the
/// sightings `sightings` (a range of `Plan::sightings`).
struct Segment {
    t: f64,
    h: f64,
    dt_row: f64,
    /// The motion from the origin (body frame of the segment's start).
    delta: [f64; 3],
    /// The noise Jacobian there (3 x nw, row-major).
    g: Vec<f64>,
    /// sin and cos of the segment's heading change.
    turn: (f64, f64),
    sightings: (usize, usize),
    row_end: bool,
}

/// Predict one segment (seed 001 eq. 2-5) from the body-frame step: the
/// pose moves by the rotated increment, F = d(pose')/d(pose) of that
/// composition (see [`Belief::advance`]), G the body noise Jacobian rotated;
/// returns F. The heading's sine and cosine are carried along and turned by
/// the segment's own, computed once in the plan, rather than recomputed from
/// the heading every segment.
fn predict(b: &mut Belief, seg: &Segment, nw: usize, noise: &NoiseModel) -> Matrix3<f64> {
    if seg.h < NO_TIME {
        return Matrix3::identity();
    }
    let (sn, cs) = b.sin_cos;
    let mut q = Matrix3::zeros();
    for i in 0..nw {
        let var = noise.step_variance(i, seg.h, seg.dt_row);
        let (gx, gy, gt) = (seg.g[i], seg.g[nw + i], seg.g[2 * nw + i]);
        let g = Vector3::new(cs * gx - sn * gy, sn * gx + cs * gy, gt);
        q += g * g.transpose() * var;
    }
    b.advance(seg.delta, seg.turn, q)
}

/// Predict a whole [`Macro`]: the same as its segments one by one, to
/// rounding.
fn predict_macro(b: &mut Belief, m: &Macro, noise: &NoiseModel) -> Matrix3<f64> {
    let (sn, cs) = b.sin_cos;
    let mut qb = Matrix3::zeros();
    for (i, mi) in m.m.iter().enumerate() {
        let s2 = noise.sigma[i] * noise.sigma[i];
        qb += mi[usize::from(!noise.density[i])] * s2;
    }
    let rot = Matrix3::new(cs, -sn, 0.0, sn, cs, 0.0, 0.0, 0.0, 1.0);
    b.advance(m.delta, m.turn, rot * qb * rot.transpose())
}

/// Buffers reused by every call of a pass.
struct Scratch {
    zeros: Vec<f64>,
    step_out: Vec<f64>,
    obs_out: Vec<f64>,
    tape: Vec<f64>,
}

impl Scratch {
    fn new(f: &Filter) -> Scratch {
        Scratch {
            zeros: vec![0.0; 64],
            step_out: vec![0.0; f.step.rows * f.step.cols],
            obs_out: vec![0.0; f.observe.rows * f.observe.cols],
            tape: Vec::new(),
        }
    }
}

/// What an update needs besides the belief: the pass's plan, log and noise,
/// and where its results and buffers go.
struct Sightings<'p, 'q> {
    plan: &'p Plan,
    run: &'p Run,
    noise: &'p NoiseModel,
    pass: &'q mut Pass,
    s: &'q mut Scratch,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model_on_log::run::LandmarkObs;
    use kinegen_model::ir::ModelIr;

    /// The iterated update is the MAP pose of one sighting from a prior
    /// metres uncertain (a robot started without motion capture): at its
    /// result the normal equations hold, P^-1 (x - x0) = H^T R^-1 (z - h(x))
    /// with H and h taken there. The single expansion's result is far from
    /// them (it linearised the bearing 0.4 rad off).
    #[test]
    fn an_update_from_a_very_uncertain_pose_is_iterated_to_the_map_pose() {
        let ir =
            ModelIr::from_json(include_str!("../../../../generated/ir/unicycle_ekf.json")).unwrap();
        let r = Runner::new(ir, &[]).unwrap();
        let f = Filter::new(&r, &EkfOptions::default()).unwrap();
        let p0 = Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, 0.25));
        let b = Belief::new(Vector3::new(0.5, -0.3, 0.4), p0, 1, &[], 0.0);
        // the robot is at the origin facing +x; the landmark 3 m ahead
        let z = LandmarkObs {
            t: 0.0,
            id: "a".into(),
            xl: 3.0,
            yl: 0.0,
            range: 3.0,
            bearing: 0.0,
        };
        let (u, lm, read) = ([0.0; 2], [z.xl, z.yl], Vector2::new(z.range, z.bearing));
        let prior = Prior {
            bias: Vector2::zeros(),
            pb: Matrix3x2::zeros(),
            bb: Matrix2::zeros(),
            rm: Matrix2::new(0.05f64.powi(2), 0.0, 0.0, 0.02f64.powi(2)),
        };
        let mut s = Scratch::new(&f);
        assert!(far_from_linear(&b, 3.0));
        let first = f.expand(&b, &prior, &b.x, (&read, &u, &lm), &mut s);
        let si = first.sm.try_inverse().unwrap();
        let once = b.x + first.ph * si * first.y;
        let (e, si) = f.iterate(&b, &prior, (first, si), (&read, &u, &lm), &mut s);
        let iterated = b.x + e.ph * si * e.y;
        // the normal equations' residual at a pose
        let mut residual = |x: &Vector3<f64>| -> f64 {
            let at = f.expand(&b, &prior, x, (&read, &u, &lm), &mut s);
            let mut miss = Vector2::new(z.range - at.h[0], z.bearing - at.h[1]);
            miss[1] = wrap(miss[1]);
            let g = p0.try_inverse().unwrap() * (x - b.x)
                - at.hm.transpose() * prior.rm.try_inverse().unwrap() * miss;
            g.norm()
        };
        let (at_once, at_iterated) = (residual(&once), residual(&iterated));
        eprintln!(
            "normal equations residual: one expansion {at_once:.3e}, iterated {at_iterated:.3e}"
        );
        assert!(at_iterated < 1e-6, "iterated: {at_iterated}");
        assert!(at_once > 1.0, "one expansion: {at_once}");
    }
}
