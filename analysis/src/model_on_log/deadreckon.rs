//! Dead reckoning with the exact step, optionally with the sensitivities
//! d pose_k / d p (forward sensitivity: S_{k+1} = Fx S_k + Fp) that calibration needs.
use crate::model_on_log::interp::{chain, lerp3};
use crate::model_on_log::landmarks::PlacedStart;
use crate::model_on_log::model::Runner;
use crate::model_on_log::run::{LandmarkObs, Run};
use kinegen_model::decl::ObservationRole::{Pose, YawRate};
use std::borrow::Cow;

pub struct Track {
    pub pose: Vec<[f64; 3]>,
    /// What the pose sensor reads (see [`Track::measured`]); empty when that
    /// is the pose itself, so a long log does not hold it twice.
    sensed: Vec<[f64; 3]>,
    /// Per row, the sensitivity of the pose to all runtime parameters and the
    /// start pose.
    pub sens: Option<Sens>,
    /// Model body twist of each step.
    pub twist: Vec<[f64; 3]>,
    /// What the gyro should read over each step: the model's yaw-rate
    /// observation (a gyro scale or bias written into it counts), or the yaw rate
    /// of the twist when the model has no such observation. Empty when the run
    /// has no gyro.
    pub gyro: Vec<f64>,
}

/// Pose sensitivities along a track: per row, a 3 x `width` matrix of the
/// columns kept (of the parameters, then the start pose), row-major in one
/// flat vector (a million-row fit would otherwise allocate a matrix per row
/// and pass). Each column obeys its own recursion (S_{k+1} = F_x S_k + F_p
/// column by column), so a fit keeps only the columns it reads: its free
/// parameters and the start heading, half of a differential drive's or less.
pub struct Sens {
    width: usize,
    /// For each column (parameter, then start pose), its place in a row, or
    /// `NOT_KEPT`.
    place: Vec<usize>,
    data: Vec<f64>,
}

const NOT_KEPT: usize = usize::MAX;

/// The sensitivity matrix of one row: `s[(m, c)]`, pose component m, column c
/// (a column that was not kept is a bug of the caller's: it panics).
#[derive(Clone, Copy)]
pub struct SensAt<'a> {
    width: usize,
    place: &'a [usize],
    d: &'a [f64],
}

impl Sens {
    #[inline]
    pub fn at(&self, k: usize) -> SensAt<'_> {
        let n = 3 * self.width;
        SensAt {
            width: self.width,
            place: &self.place,
            d: &self.data[k * n..(k + 1) * n],
        }
    }
}

impl std::ops::Index<(usize, usize)> for SensAt<'_> {
    type Output = f64;
    #[inline]
    fn index(&self, (m, c): (usize, usize)) -> &f64 {
        let at = self.place[c];
        assert!(at != NOT_KEPT, "sensitivity column {c} was not kept");
        &self.d[m * self.width + at]
    }
}

impl Track {
    /// What the pose sensor should read at each row: the track at t - time_offset
    /// (when the model has a measurement delay), seen through the `pose`
    /// observation (when it has one). Errors are measured on this.
    pub fn measured(&self) -> &[[f64; 3]] {
        if self.sensed.is_empty() {
            &self.pose
        } else {
            &self.sensed
        }
    }
}

/// The body pose whose measurement is `measured`: the identity unless the model
/// has a `pose` observation (e.g. an off-centre marker), which is inverted by a
/// fixed-point iteration (it is a small displacement of the identity). Also returns
/// d start / d p = -dh/dp (3 x P, row-major) for the sensitivities.
pub fn body_start(r: &Runner, p: &[f64], measured: [f64; 3], u: &[f64]) -> ([f64; 3], Vec<f64>) {
    let Some(h) = r.ir.observation_kernels(Pose).map(|o| o.value) else {
        return (measured, vec![0.0; 3 * p.len()]);
    };
    let mut x = measured;
    for _ in 0..5 {
        let m = r.eval(h, &Runner::obs_args(h, &x, u, p, &[]));
        for i in 0..3 {
            x[i] -= m[i] - measured[i];
        }
    }
    let hp =
        r.ir.observation_kernels(Pose)
            .and_then(|o| o.jac_p)
            .expect("derived with the pose observation");
    let d = r
        .eval(hp, &Runner::obs_args(hp, &x, u, p, &[]))
        .iter()
        .map(|v| -v)
        .collect();
    (x, d)
}

/// Where the landmarks place the start of a run whose ground truth does
/// not give it.
enum Placed {
    /// By the landmarks seen at rest at the start (`seen` None), or by the
    /// first sightings of a moving robot, at the times `seen`, and its
    /// odometry since the start.
    At {
        start: PlacedStart,
        seen: Option<(f64, f64)>,
    },
    /// Not at all: too few sightings to place it.
    Nowhere,
}

/// Without ground truth, the start pose is where the landmarks seen at the
/// start place the robot through the model's own observation (a sensor off the
/// body origin included): see [`crate::model_on_log::landmarks::start_from_landmarks`]; a
/// robot that moves from its first row, where its first sightings and its
/// odometry between them place it
/// ([`crate::model_on_log::landmarks::start_from_moving_sightings`]). None where the
/// ground truth gives the start, or the run has no sightings.
fn placed_by_landmarks(r: &Runner, p: &[f64], data: &Run, guess: [f64; 3]) -> Option<Placed> {
    if data.start_measured() || data.landmarks.is_empty() {
        return None;
    }
    if let Some(start) = crate::model_on_log::landmarks::start_from_landmarks(r, p, data, guess) {
        return Some(Placed::At { start, seen: None });
    }
    Some(match moving_start(r, p, data) {
        Some((start, seen)) => Placed::At {
            start,
            seen: Some(seen),
        },
        None => Placed::Nowhere,
    })
}

/// The start the landmarks place (see [`placed_by_landmarks`]), if they do.
fn landmark_start(r: &Runner, p: &[f64], data: &Run, guess: [f64; 3]) -> Option<PlacedStart> {
    match placed_by_landmarks(r, p, data, guess)? {
        Placed::At { start, .. } => Some(start),
        Placed::Nowhere => None,
    }
}

/// What the user should hear of a run's start where neither its ground
/// truth nor its first seconds' sightings place it: placed by later
/// sightings through the odometry before them (the track until then carries
/// that odometry's drift), or not placed at all. None otherwise.
pub fn start_note(r: &Runner, p: &[f64], data: &Run) -> Option<String> {
    use crate::model_on_log::landmarks::MOVING_START_S;
    let t0 = data.t[0];
    match placed_by_landmarks(r, p, data, data.start_pose())? {
        Placed::Nowhere => Some(format!(
            "{}: no ground truth at the start ({t0:.1} s) and too few sightings to place it (two landmarks within {MOVING_START_S} s): the run starts at the map's origin, heading 0",
            data.path
        )),
        Placed::At {
            seen: Some((from, to)),
            ..
        } if from - t0 > MOVING_START_S => Some(format!(
            "{}: no ground truth at the start ({t0:.1} s) and no two landmarks seen within {MOVING_START_S} s of it: the start is placed by the sightings of {from:.1}-{to:.1} s through the model's odometry since, so the track before {from:.1} s carries that odometry's drift",
            data.path
        )),
        Placed::At { .. } => None,
    }
}

/// [`crate::model_on_log::landmarks::start_from_moving_sightings`] with the model's
/// odometry from the start (the origin of its frame) to each of the run's
/// first sightings, interpolated between rows; with the times of the first
/// and the last of those sightings.
fn moving_start(r: &Runner, p: &[f64], data: &Run) -> Option<(PlacedStart, (f64, f64))> {
    let seen = crate::model_on_log::landmarks::first_sightings(data)?;
    let first = seen.iter().map(|o| o.t).fold(f64::INFINITY, f64::min);
    let last = seen.iter().map(|o| o.t).fold(data.t[0], f64::max);
    let rows = data.t.partition_point(|t| *t <= last).min(data.steps());
    let mut stepper = Stepper::new(r, p, data, false, None);
    let mut poses = vec![[0.0; 3]];
    for k in 0..rows {
        let (x, _) = stepper.step(k, poses[k], |_| {});
        poses.push(x);
    }
    let moved = |o: &LandmarkObs| {
        let (j, a) = data.locate(o.t);
        let (p0, p1) = (poses[j.min(rows)], poses[(j + 1).min(rows)]);
        [0, 1, 2].map(|i| p0[i] + a * (p1[i] - p0[i]))
    };
    crate::model_on_log::landmarks::start_from_moving_sightings(r, p, data, &seen, moved)
        .map(|s| (s, (first, last)))
}

/// The body pose dead reckoning starts from: the measured start seen through
/// the model's pose observation, or placed by the start's landmarks.
pub fn model_start(r: &Runner, p: &[f64], data: &Run) -> [f64; 3] {
    placed_start(r, p, data, data.start_pose(), [0.0; 3]).0
}

/// How uncertain [`model_start`] is where landmark sightings placed it (a
/// log without ground truth): their covariance ([`PlacedStart::cov`]). None
/// where the start was measured.
pub fn start_covariance(r: &Runner, p: &[f64], data: &Run) -> Option<[[f64; 3]; 3]> {
    landmark_start(r, p, data, data.start_pose()).map(|s| s.cov)
}

/// The body start pose from the `measured` one (see [`model_start`]) plus a
/// calibration's `offset`, with its derivative with respect to the parameters
/// (3 x P, row-major).
pub fn placed_start(
    r: &Runner,
    p: &[f64],
    data: &Run,
    measured: [f64; 3],
    offset: [f64; 3],
) -> ([f64; 3], Vec<f64>) {
    match landmark_start(r, p, data, measured) {
        Some(s) => ([0, 1, 2].map(|i| s.pose[i] + offset[i]), s.d_dp),
        None => {
            let u0 = data.u.first().map(<[f64]>::to_vec).unwrap_or_default();
            body_start(r, p, [0, 1, 2].map(|i| measured[i] + offset[i]), &u0)
        }
    }
}

/// Integrate the model over a run from the run's start pose ([`Run::start_pose`]).
/// Sensitivities (with `with_sens`) have P + 3 columns: the parameters, then the
/// start pose (x, y, theta), for calibrations that refine the start.
pub fn run(r: &Runner, p: &[f64], data: &Run, with_sens: bool) -> Track {
    run_from(r, p, data, with_sens, [0.0; 3], None)
}

/// [`run`] with `start_offset` added to the measured start pose: the start pose
/// as a nuisance parameter of calibration (a single noisy start heading would
/// otherwise rotate the whole track and masquerade as a physical effect).
pub fn run_from(
    r: &Runner,
    p: &[f64],
    data: &Run,
    with_sens: bool,
    start_offset: [f64; 3],
    plan: Option<&[u8]>,
) -> Track {
    // the commands as executed (an input delay, a lag), with their
    // derivatives in the timing parameters for the sensitivities
    let (executed, timing) =
        crate::model_on_log::timeline::executed_with_rates(r, p, data, with_sens);
    run_executed(
        r,
        p,
        (&executed, &timing),
        with_sens,
        start_offset,
        plan,
        None,
    )
}

/// [`run_from`] on a run whose inputs are already as executed
/// ([`crate::model_on_log::timeline::executed_with_rates`], with their derivatives in the
/// timing parameters when `with_sens`): for a caller that needs those inputs
/// too (the fit's observations read them) and computes them once.
///
/// `kept`: the sensitivity columns to keep (parameters, then the start pose
/// at `p.len()..p.len() + 3`), all of them when None.
pub fn run_executed(
    r: &Runner,
    p: &[f64],
    executed: (&Run, &[(usize, crate::logs::rows::Rows)]),
    with_sens: bool,
    start_offset: [f64; 3],
    plan: Option<&[u8]>,
    kept: Option<&[usize]>,
) -> Track {
    let data = executed.0;
    let mut pose = Vec::with_capacity(data.steps() + 1);
    let mut twist = Vec::with_capacity(data.steps());
    let mut flat = Vec::new();
    let layout = reckon(r, p, executed, with_sens, start_offset, plan, kept, |s| {
        if s.k == 0 {
            pose.push(s.from);
            flat.reserve_exact(s.sens_from.map_or(0, |x| x.d.len()) * (data.steps() + 1));
            flat.extend_from_slice(s.sens_from.map_or(&[][..], |x| x.d));
        }
        pose.push(s.to);
        twist.push(s.twist);
        flat.extend_from_slice(s.sens_to.map_or(&[][..], |x| x.d));
    });
    if pose.is_empty() {
        pose.push(layout.start);
        flat = layout.sens_start;
    }
    let sens = with_sens.then_some(Sens {
        width: layout.width,
        place: layout.place,
        data: flat,
    });
    let sensed = predicted_measurements(r, p, data, &pose);
    let gyro = predicted_gyro(r, p, data, &pose, &twist);
    Track {
        pose,
        sensed,
        sens,
        twist,
        gyro,
    }
}

/// One step of a dead reckoning as [`reckon`] makes it: step `k` from pose
/// `from` to pose `to` at the mean body twist `twist`, with the pose's
/// sensitivities at both ends (without sensitivities: None).
pub struct StepMade<'a> {
    pub k: usize,
    pub from: [f64; 3],
    pub to: [f64; 3],
    pub twist: [f64; 3],
    pub sens_from: Option<SensAt<'a>>,
    pub sens_to: Option<SensAt<'a>>,
}

/// Where a dead reckoning started, and how its sensitivity rows are laid
/// out (see [`Sens`]).
pub struct Layout {
    pub start: [f64; 3],
    sens_start: Vec<f64>,
    width: usize,
    place: Vec<usize>,
}

/// The dead reckoning of [`run_executed`], each step given to `visit` as it
/// is made and nothing kept: a caller that reads each step once (the fit's
/// residuals) holds no track, which on a million-row log was 150 bytes a
/// row.
#[allow(clippy::too_many_arguments)]
pub fn reckon(
    r: &Runner,
    p: &[f64],
    (data, timing): (&Run, &[(usize, crate::logs::rows::Rows)]),
    with_sens: bool,
    start_offset: [f64; 3],
    plan: Option<&[u8]>,
    kept: Option<&[usize]>,
    mut visit: impl FnMut(StepMade<'_>),
) -> Layout {
    let (start, dstart) = reckoning_start(r, p, data, start_offset);
    let np = p.len();
    // columns: parameters, then the start pose (identity at the start)
    let kept: Vec<usize> = kept.map_or_else(|| (0..np + 3).collect(), <[usize]>::to_vec);
    let cols = kept.len();
    let mut place = vec![NOT_KEPT; np + 3];
    for (at, &c) in kept.iter().enumerate() {
        place[c] = at;
    }
    // the sensitivity of the current (sub)step's pose, and the next one's
    let mut cur: Vec<f64> = Vec::new();
    if with_sens {
        for m in 0..3 {
            cur.extend(kept.iter().map(|&c| match c {
                c if c < np => dstart[m * np + c],
                c => f64::from(u8::from(c == np + m)),
            }));
        }
    }
    let sens_start = cur.clone();
    let mut before = cur.clone();
    let mut next = vec![0.0; cur.len()];
    let mut stepper = Stepper::with_inputs(r, p, data, Cow::Borrowed(&data.u), with_sens, plan);
    let mut by_timing: Vec<(usize, [f64; 3])> = Vec::with_capacity(timing.len());
    let mut x = start;
    for k in 0..data.steps() {
        // the step's response to each timing parameter: F_u d(executed u)/d q
        by_timing.clear();
        by_timing.extend(
            timing
                .iter()
                .map(|(q, du)| (*q, input_response(r, p, &du[k], data, k, x))),
        );
        // the timing response is the whole step's, from its start pose: it
        // enters at the first sub-step and the later ones carry it on
        let mut first = true;
        let (to, mean_twist) = stepper.step(k, x, |out| {
            if with_sens {
                // S_{j+1} = F_x S_j + [F_p | 0], written out
                let (jx, jp) = (&out[6..15], &out[15..]);
                for m in 0..3 {
                    for (at, &c) in kept.iter().enumerate() {
                        let prev = |i: usize| cur[i * cols + at];
                        let mut direct = if c < np { jp[m * np + c] } else { 0.0 };
                        for (q, d) in by_timing.iter().filter(|_| first) {
                            if c == *q {
                                direct += d[m];
                            }
                        }
                        next[m * cols + at] = chain(&jx[m * 3..m * 3 + 3], prev, direct);
                    }
                }
                std::mem::swap(&mut cur, &mut next);
            }
            first = false;
        });
        let view = |d| SensAt {
            width: cols,
            place: &place,
            d,
        };
        visit(StepMade {
            k,
            from: x,
            to,
            twist: mean_twist,
            sens_from: with_sens.then(|| view(&before)),
            sens_to: with_sens.then(|| view(&cur)),
        });
        before.copy_from_slice(&cur);
        x = to;
    }
    Layout {
        start,
        sens_start,
        width: cols,
        place,
    }
}

/// How step k's end pose moves with a timing parameter (the input delay,
/// the lag): the exact step's directional derivative along `du`, its
/// executed inputs' derivative in the parameter
/// ([`crate::model_on_log::timeline::executed_with_rates`]), by central differences (the fused
/// tape has no input Jacobian; the step is smooth in its inputs, so the
/// difference is accurate to ~1e-8 of the step). Zero where the executed
/// commands do not move with it.
fn input_response(
    r: &Runner,
    p: &[f64],
    du: &[f64],
    executed: &Run,
    k: usize,
    x: [f64; 3],
) -> [f64; 3] {
    let size = du.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    // a rate this small moves nothing (and 1/size would overflow)
    if size < 1e-300 {
        return [0.0; 3];
    }
    let u = &executed.u[k];
    let scale = u.iter().fold(1.0f64, |m, v| m.max(v.abs()));
    let h = 1e-6 * scale / size;
    let step = r.ir.step(kinegen_model::ir::StepForm::Exact).value;
    let zeros = [0.0; 16];
    let at = |sign: f64| {
        let v: Vec<f64> = u.iter().zip(du).map(|(u, d)| u + sign * h * d).collect();
        r.eval(
            step,
            &Runner::step_args(step, &x, &v, p, &[executed.dt[k]], &zeros),
        )
    };
    let (a, b) = (at(1.0), at(-1.0));
    [0, 1, 2].map(|m| (a[m] - b[m]) / (2.0 * h))
}

/// The body pose dead reckoning of `data` starts from: the measured start
/// (with a measurement delay, the measurement at t0 + delay, which saw the
/// pose at t0) plus `start_offset`, placed through the model's pose
/// observation; with d start / d p (3 x P, row-major).
pub(crate) fn reckoning_start(
    r: &Runner,
    p: &[f64],
    data: &Run,
    start_offset: [f64; 3],
) -> ([f64; 3], Vec<f64>) {
    let start = data.start_pose();
    // With delayed measurements the pose at t0 is seen at t0 + time_offset.
    let tau_i = r.delay;
    let (start, gt_vel) = match (tau_i.map(|i| p[i]), &data.gt) {
        (Some(tau), Some(g)) if tau != 0.0 && g.len() > 1 => {
            let (j, a) = data.locate(data.t[0] + tau);
            let dtj = data.t[j + 1] - data.t[j];
            let vel = [0, 1, 2].map(|i| (g[j + 1][i] - g[j][i]) / dtj);
            // the rest-averaged start when the robot has not moved yet
            let at = lerp3(&g[j], &g[j + 1], a);
            if data.rest_steps() > 0 {
                (start, [0.0; 3])
            } else {
                (at, vel)
            }
        }
        _ => (start, [0.0; 3]),
    };
    let (start, mut dstart) = placed_start(r, p, data, start, start_offset);
    if let Some(ti) = tau_i {
        for m in 0..3 {
            dstart[m * p.len() + ti] += gt_vel[m];
        }
    }
    (start, dstart)
}

/// One step of dead reckoning at a time, through the model's fused step tape
/// (pose and twist, then with sensitivities F_x and F_p): what [`run_from`]
/// keeps for a whole track, and what a track read a row at a time
/// (`crate::model_on_log::track_rows`) does not.
pub(crate) struct Stepper<'a> {
    r: &'a Runner,
    p: &'a [f64],
    data: &'a Run,
    /// `data`'s inputs as executed ([`crate::model_on_log::timeline::executed`]).
    u: Cow<'a, crate::logs::rows::Rows>,
    plan: Option<&'a [u8]>,
    f: &'a kinegen_jit::Evaluator,
    out: Vec<f64>,
    scratch: Vec<f64>,
    u_sub: Vec<f64>,
    /// Whether every input moves continuously (rates, sampled angles), so
    /// the twist changes across a step as it does between steps; a held
    /// command does not (see [`swing_offset`]).
    continuous: bool,
    /// The last three steps taken, oldest first, for [`swing_offset`].
    recent: [Option<Stepped>; 3],
}

/// A step as [`swing_offset`] reads it: its index, sub-steps, mean twist,
/// length and mid-step heading.
#[derive(Debug, Clone, Copy)]
struct Stepped {
    k: usize,
    substeps: usize,
    twist: [f64; 3],
    dt: f64,
    heading: f64,
}

impl<'a> Stepper<'a> {
    pub(crate) fn new(
        r: &'a Runner,
        p: &'a [f64],
        data: &'a Run,
        with_sens: bool,
        plan: Option<&'a [u8]>,
    ) -> Self {
        // the commands as the robot executed them (an input delay, a lag)
        let u = match crate::model_on_log::timeline::executed(r, p, data) {
            Cow::Borrowed(run) => Cow::Borrowed(&run.u),
            Cow::Owned(run) => Cow::Owned(run.u),
        };
        Self::with_inputs(r, p, data, u, with_sens, plan)
    }

    /// [`Stepper::new`] with `data`'s inputs as executed already computed.
    pub(crate) fn with_inputs(
        r: &'a Runner,
        p: &'a [f64],
        data: &'a Run,
        u: Cow<'a, crate::logs::rows::Rows>,
        with_sens: bool,
        plan: Option<&'a [u8]>,
    ) -> Self {
        let f = if with_sens {
            &r.step_linearized
        } else {
            &r.step_twist
        };
        Stepper {
            r,
            p,
            data,
            u,
            plan,
            f,
            out: vec![0.0; f.rows],
            scratch: Vec::new(),
            u_sub: Vec::new(),
            continuous: !r.ir.inputs.iter().any(|i| i.is_command()),
            recent: [None; 3],
        }
    }

    /// Step `k` from pose `x`: the pose at row k + 1 and the step's mean body
    /// twist. `each` sees the tape's outputs after every sub-step.
    pub(crate) fn step(
        &mut self,
        k: usize,
        mut x: [f64; 3],
        mut each: impl FnMut(&[f64]),
    ) -> ([f64; 3], [f64; 3]) {
        let (r, p, data) = (self.r, self.p, self.data);
        let zeros = [0.0; 16];
        let start_heading = x[2];
        let n = data.swing.as_ref().map_or(1, |s| {
            if let Some(plan) = self.plan {
                return usize::from(plan[k]);
            }
            substeps(
                r,
                p,
                &self.u[k],
                &s[k],
                data.dt[k],
                &mut self.u_sub,
                &mut self.scratch,
            )
        });
        let dt = [data.dt[k] / n as f64];
        let mut mean_twist = [0.0; 3];
        for j in 0..n {
            let u: &[f64] = if n == 1 {
                &self.u[k]
            } else {
                // absolute inputs move linearly across the step, sampled at
                // each sub-step's middle; rates stay the step's mean
                let at = (j as f64 + 0.5) / n as f64 - 0.5;
                let swing = &data.swing.as_ref().expect("n > 1 needs a swing")[k];
                self.u_sub.clear();
                self.u_sub
                    .extend(self.u[k].iter().zip(swing).map(|(u, s)| u + at * s));
                &self.u_sub
            };
            let mut args: [&[f64]; 8] = [&[]; 8];
            for (slot, a) in args.iter_mut().zip(&self.f.args) {
                *slot = Runner::step_arg(a, &x, u, p, &dt, &zeros);
            }
            self.f
                .eval_into(&args[..self.f.args.len()], &mut self.out, &mut self.scratch);
            for (m, t) in mean_twist.iter_mut().zip(&self.out[3..6]) {
                *m += t / n as f64;
            }
            each(&self.out);
            x = [self.out[0], self.out[1], self.out[2]];
        }
        if self.continuous {
            let d = self.deferred_offset(Stepped {
                k,
                substeps: n,
                twist: mean_twist,
                dt: data.dt[k],
                heading: 0.5 * (start_heading + x[2]),
            });
            x[0] += d[0];
            x[1] += d[1];
        }
        (x, mean_twist)
    }

    /// The offset [`swing_offset`] gives the step before `now`, once `now`
    /// tells how the twist went on changing. It is added to `now`'s end:
    /// an exact step moves with its start, so an offset at the end of one
    /// step is the same offset at the end of the next, and every pose but
    /// the latest has all of its steps' offsets. Steps read out of order
    /// (a new start) begin again.
    fn deferred_offset(&mut self, now: Stepped) -> [f64; 2] {
        match self.recent {
            [.., Some(last)] if last.k + 1 == now.k => {
                self.recent = [self.recent[1], self.recent[2], Some(now)];
            }
            _ => {
                self.recent = [None, None, Some(now)];
                return [0.0; 2];
            }
        }
        let [first, Some(step), Some(after)] = self.recent else {
            return [0.0; 2];
        };
        let like = |a: &Stepped| a.dt <= 3.0 * step.dt && step.dt <= 3.0 * a.dt;
        if !like(&after) {
            return [0.0; 2];
        }
        // the twist's slope through the steps around it, at their middles
        let (before, span) = match first {
            Some(b) if like(&b) => (b, 0.5 * b.dt + step.dt + 0.5 * after.dt),
            _ => (step, 0.5 * (step.dt + after.dt)),
        };
        let change = [0, 1, 2].map(|i| (after.twist[i] - before.twist[i]) / span * step.dt);
        let turns = (step.twist[2].abs() + change[2].abs()) * step.dt;
        // sub-steps that followed a swinging input leave 1/n^2 of it
        let d = swing_offset(step.twist, change, step.dt, step.heading)
            .map(|v| v / (step.substeps * step.substeps) as f64);
        // the expansion holds while the step turns little; beyond a radian
        // (absurd parameters) the step is left as it is, and the checks
        // name its own values
        if turns < 1.0 && d.iter().all(|v| v.is_finite()) {
            d
        } else {
            [0.0; 2]
        }
    }
}

/// The sub-steps each step of `data` needs at parameters `p` ([`substeps`]),
/// for a fit that fixes them across its passes; None when the run has no
/// absolute input that swings.
pub fn substep_plan(r: &Runner, p: &[f64], data: &Run) -> Option<Vec<u8>> {
    let swing = data.swing.as_ref()?;
    let (mut buf, mut scratch) = (Vec::new(), Vec::new());
    Some(
        (0..data.steps())
            .map(|k| {
                substeps(
                    r,
                    p,
                    &data.u[k],
                    &swing[k],
                    data.dt[k],
                    &mut buf,
                    &mut scratch,
                ) as u8
            })
            .collect(),
    )
}

/// Error of one step (m, or rad over [`ARM`]) that sub-stepping keeps a step
/// under: a 25th of the best motion capture's noise (0.1 mm), summed over
/// thousands of steps, stays far below it. 1e-6 before: the clean 20 Hz
/// fwd_tricycle logs of `the_models_own_step_is_checked_against_the_noise`
/// measure the same step error with either (0.249, 0.060 and 0.121 of the
/// noise floor; 1.523 at 5 Hz), `bench-diagnose` names the same effects in
/// every case, and omni_caster's diagnoses take 0.72-0.86x the time (its
/// steering swings: 1.9 sub-steps a step on average at 1e-6).
const STEP_TOL: f64 = 4e-6;
/// The most sub-steps a step is cut into (a step that needs more has inputs
/// that jump rather than move; more sub-steps would not make them smooth).
const MAX_SUBSTEPS: usize = 8;
/// Length (m) at which a heading error counts as much as a position error.
const ARM: f64 = 1.0;

/// How many sub-steps step `dt` needs so that holding the absolute inputs at
/// their mid-step values (a steering angle swinging by `swing` over the step)
/// is not the model's largest error. The twist bends along the swing (cos and
/// sin of a steering angle): the mean twist over the step differs from the
/// twist at the mid-step inputs by a sixth of its second difference (Simpson),
/// and a yaw rate that changes across the step shears the arc by
/// |v| |d omega| dt^2 / 12. Both fall as 1/n^2 with n sub-steps. A log at
/// 20 Hz of a robot that steers 0.25 rad in a step gave its own spec a
/// calibrated error of 1.6x the noise floor without this (issue 12 item 3).
fn substeps(
    r: &Runner,
    p: &[f64],
    u: &[f64],
    swing: &[f64],
    dt: f64,
    buf: &mut Vec<f64>,
    scratch: &mut Vec<f64>,
) -> usize {
    if swing.iter().all(|s| *s == 0.0) {
        return 1;
    }
    let tw = r.ir.twist();
    let (zeros, origin, dt) = ([0.0; 16], [0.0; 3], [dt]);
    let mut at = |frac: f64| {
        buf.clear();
        buf.extend(u.iter().zip(swing).map(|(u, s)| u + frac * s));
        let mut args: [&[f64]; 8] = [&[]; 8];
        for (slot, a) in args.iter_mut().zip(&tw.args) {
            *slot = Runner::step_arg(a, &origin, buf, p, &dt, &zeros);
        }
        let mut out = [0.0; 3];
        r.eval_into(tw, &args[..tw.args.len()], &mut out, scratch);
        out
    };
    let (a, m, b) = (at(-0.5), at(0.0), at(0.5));
    let scale = [1.0, 1.0, ARM];
    let bend = (0..3)
        .map(|i| (a[i] - 2.0 * m[i] + b[i]).abs() * scale[i])
        .fold(0.0, f64::max)
        * dt[0]
        / 6.0;
    let shear = m[0].hypot(m[1]) * (b[2] - a[2]).abs() * dt[0] * dt[0] / 12.0;
    let err = bend + shear;
    if !err.is_finite() {
        return 1;
    }
    ((err / STEP_TOL).sqrt().ceil() as usize).clamp(1, MAX_SUBSTEPS)
}

/// Where a step whose twist moves linearly across it (by `dv`, `twist` in
/// the middle) ends, against the exact step of its mean twist, to second
/// order: R(theta_mid) J (dV omega - V d omega) dt^2 / 12 in the world
/// frame, J the quarter turn. A yaw rate that grows across a step curves its
/// first half less than its second; a speed that grows in a turn drives its
/// second half further round. Holding the mean twist misplaces every such
/// step sideways, the same way wherever the robot speeds up into a turn, so
/// the error adds up along a track: a simulated 20 Hz differential-drive log
/// of smooth random driving (364 s) calibrated its radii and wheelbase 2-6
/// standard deviations short, all one way, without it (within 2, the mean
/// within 0.3, with it). The change across a step is read from the twists
/// of the steps around it, which costs no evaluation; a held command's
/// twist is constant within its step and gets no offset. The offset is
/// second order in the step, about a micrometre at 20 Hz, and its
/// derivatives are left out of the sensitivities, which those estimates and
/// their standard deviations (the spread over seeds within 10%) do not miss.
fn swing_offset(twist: [f64; 3], dv: [f64; 3], dt: f64, heading: f64) -> [f64; 2] {
    let body = [0, 1].map(|i| (dv[i] * twist[2] - twist[i] * dv[2]) * dt * dt / 12.0);
    // the quarter turn J, then the mid-step heading
    let (lx, ly) = (-body[1], body[0]);
    let (s, c) = heading.sin_cos();
    [c * lx - s * ly, s * lx + c * ly]
}

/// The gyro readings a track predicts (see [`Track::gyro`]).
fn predicted_gyro(
    r: &Runner,
    p: &[f64],
    data: &Run,
    pose: &[[f64; 3]],
    twist: &[[f64; 3]],
) -> Vec<f64> {
    if data.gyro.is_none() {
        return Vec::new();
    }
    let h = r.ir.observation_kernels(YawRate).map(|o| o.value);
    let mut scratch = Vec::new();
    (0..data.steps())
        .map(|k| gyro_at(r, h, p, &data.u[k], &pose[k], &twist[k], &mut scratch))
        .collect()
}

/// What the gyro reads over a step (see [`Track::gyro`]) with inputs `u` of
/// a track at `pose` (its first row) moving with `twist`, through the
/// yaw-rate observation `h` when the model has one.
pub(crate) fn gyro_at(
    r: &Runner,
    h: Option<&kinegen_model::ir::Function>,
    p: &[f64],
    u: &[f64],
    pose: &[f64; 3],
    twist: &[f64; 3],
    scratch: &mut Vec<f64>,
) -> f64 {
    let Some(h) = h else { return twist[2] };
    let mut out = [0.0];
    r.eval_obs_into(h, (pose, u, p), &mut out, scratch);
    out[0]
}

/// The pose measurements a track predicts (see [`Track::measured`]); empty
/// when they are the track's poses themselves (no delay, no pose observation).
fn predicted_measurements(r: &Runner, p: &[f64], data: &Run, pose: &[[f64; 3]]) -> Vec<[f64; 3]> {
    let tau = crate::model_on_log::timeline::delay(r, p);
    let h = r.ir.observation_kernels(Pose).map(|o| o.value);
    if h.is_none() && (tau == 0.0 || pose.len() < 2) {
        return Vec::new();
    }
    (0..pose.len())
        .map(|k| {
            let x = if tau == 0.0 || pose.len() < 2 {
                pose[k]
            } else {
                let (j, a) = crate::model_on_log::timeline::model_instant(data, k, tau);
                lerp3(&pose[j], &pose[j + 1], a)
            };
            sensed_at(r, h, p, data, k, &x)
        })
        .collect()
}

/// What the pose sensor reads at row `k` of a track that was at body pose `x`
/// when the measurement was taken: `x` through the pose observation `h` (an
/// off-centre marker), or `x` itself when the model has none.
pub(crate) fn sensed_at(
    r: &Runner,
    h: Option<&kinegen_model::ir::Function>,
    p: &[f64],
    data: &Run,
    k: usize,
    x: &[f64; 3],
) -> [f64; 3] {
    match h {
        Some(h) => {
            let u = &data.u[k.min(data.steps().saturating_sub(1))];
            let m = r.eval(h, &Runner::obs_args(h, x, u, p, &[]));
            [m[0], m[1], m[2]]
        }
        None => *x,
    }
}

/// Gyrodometry (seed 000 eq. 13-18): the heading integrated from the gyro
/// (eq. 13, theta_k = theta_{k-1} + T omega_k) and the translation from the
/// inputs given that yaw rate (`twist_gyro`, eq. 17), each step moved along the
/// arc of that constant twist. None when the run has no gyro column.
pub fn gyrodometry(r: &Runner, p: &[f64], data: &Run) -> Option<Track> {
    let gyro = data.gyro.as_ref()?;
    gyrodometry_with(r, p, data, &|k| gyro[k + 1])
}

/// Gyrodometry with the yaw rate of step k from `omega(k)`: the gyro's, or a
/// virtual gyro's (seed 000 sec. 3.2's neural network). None when the model
/// has no `twist_gyro`.
pub fn gyrodometry_with(
    r: &Runner,
    p: &[f64],
    data: &Run,
    omega_of: &dyn Fn(usize) -> f64,
) -> Option<Track> {
    let start = model_start(r, p, data);
    let mut pose = Vec::with_capacity(data.steps() + 1);
    pose.push(start);
    let (mut omega, mut twist) = (
        Vec::with_capacity(data.steps()),
        Vec::with_capacity(data.steps()),
    );
    let mut scratch = Vec::new();
    for k in 0..data.steps() {
        let w = omega_of(k);
        let (x, tw) = gyro_step(r, p, data, k, w, *pose.last().unwrap(), &mut scratch);
        pose.push(x);
        omega.push(w);
        twist.push(tw);
    }
    let sensed = predicted_measurements(r, p, data, &pose);
    Some(Track {
        pose,
        sensed,
        sens: None,
        gyro: omega,
        twist,
    })
}

/// Step `k` of gyrodometry from pose `x` with yaw rate `w`: the next pose and
/// the step's twist (the translation `twist_gyro` gives for that yaw rate).
pub(crate) fn gyro_step(
    r: &Runner,
    p: &[f64],
    data: &Run,
    k: usize,
    w: f64,
    x: [f64; 3],
    scratch: &mut Vec<f64>,
) -> ([f64; 3], [f64; 3]) {
    let mut v = [0.0; 2];
    r.eval_into(r.ir.twist_gyro(), &[&data.u[k], &[w], p], &mut v, scratch);
    let tw = [v[0], v[1], w];
    (arc_step(x, tw, data.dt[k]), tw)
}

/// Pose after moving with the constant body twist `tw` for `dt` (exact SE(2)
/// integration). Written out here rather than taken from a generated step because
/// the generated steps take inputs, and gyrodometry has a twist; below
/// |omega dt| = 1e-6 the arc is a straight line to within 1e-13 m per metre.
pub fn arc_step(x: [f64; 3], tw: [f64; 3], dt: f64) -> [f64; 3] {
    let a = tw[2] * dt;
    let (s, c) = if a.abs() < 1e-6 {
        (dt * (1.0 - a * a / 6.0), dt * a / 2.0)
    } else {
        (a.sin() / tw[2], (1.0 - a.cos()) / tw[2])
    };
    let (bx, by) = (s * tw[0] - c * tw[1], c * tw[0] + s * tw[1]);
    let (st, ct) = x[2].sin_cos();
    [x[0] + ct * bx - st * by, x[1] + st * bx + ct * by, x[2] + a]
}
