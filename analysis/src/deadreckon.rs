//! Dead reckoning with the exact step, optionally with the sensitivities
//! d pose_k / d p (forward sensitivity: S_{k+1} = Fx S_k + Fp) that calibration needs.
use crate::interp::{chain, lerp3};
use crate::model::Runner;
use crate::run::Run;
use kinegen_model::decl::ObservationRole::{Pose, YawRate};

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

/// Pose sensitivities along a track: per row, a 3 x `cols` matrix (the
/// parameters, then the start pose), row-major in one flat vector (a
/// million-row fit would otherwise allocate a matrix per row and pass).
pub struct Sens {
    cols: usize,
    data: Vec<f64>,
}

/// The sensitivity matrix of one row: `s[(m, c)]`, pose component m, column c.
pub struct SensAt<'a> {
    cols: usize,
    d: &'a [f64],
}

impl Sens {
    pub fn at(&self, k: usize) -> SensAt<'_> {
        let n = 3 * self.cols;
        SensAt {
            cols: self.cols,
            d: &self.data[k * n..(k + 1) * n],
        }
    }
}

impl std::ops::Index<(usize, usize)> for SensAt<'_> {
    type Output = f64;
    fn index(&self, (m, c): (usize, usize)) -> &f64 {
        &self.d[m * self.cols + c]
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

    /// The first row where the track stops being a number, with what did: a
    /// predicted pose or gyro reading that is not finite (parameters that
    /// divide by almost zero, an input that overflows), or a pose error against
    /// the log that overflows (a cell like 1e308). Results past such a row
    /// would be NaN or infinite, so commands refuse instead.
    pub fn first_non_finite(&self, run: &Run) -> Option<(usize, String)> {
        let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
        // a logged pose so large its square overflows is no position at all
        // (and the start pose, estimated from the first rows, inherits it)
        if let Some(g) = &run.gt {
            if let Some(k) = g
                .iter()
                .position(|p| p.iter().any(|v| !(v * v).is_finite()))
            {
                return Some((
                    k,
                    format!("the measured pose {:?} is out of any physical range", g[k]),
                ));
            }
        }
        for (k, m) in self.measured().iter().enumerate() {
            if !finite(m) {
                return Some((k, format!("the model's predicted pose is not finite ({m:?}): check the parameter values and the inputs up to this row")));
            }
            if let Some(g) = &run.gt {
                let e = [g[k][0] - m[0], g[k][1] - m[1]];
                if !(e[0].hypot(e[1])).is_finite() || !(e[0] * e[0] + e[1] * e[1]).is_finite() {
                    return Some((
                        k,
                        format!(
                            "the pose error against the log overflows (measured pose {:?})",
                            g[k]
                        ),
                    ));
                }
            }
            if k > 0 {
                if let Some(w) = self
                    .gyro
                    .get(k - 1)
                    .filter(|w| !w.is_finite() || w.abs() > 1e150)
                {
                    return Some((k, format!("the model's predicted gyro reading is {w:.3e}: check the parameter values and the inputs")));
                }
            }
        }
        None
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
        let m = h.eval(&Runner::obs_args(h, &x, u, p, &[]));
        for i in 0..3 {
            x[i] -= m[i] - measured[i];
        }
    }
    let hp =
        r.ir.observation_kernels(Pose)
            .and_then(|o| o.jac_p)
            .expect("derived with the pose observation");
    let d = hp
        .eval(&Runner::obs_args(hp, &x, u, p, &[]))
        .iter()
        .map(|v| -v)
        .collect();
    (x, d)
}

/// Without ground truth, the start pose is where the landmarks seen at the
/// start place the robot through the model's own observation (a sensor off the
/// body origin included): see [`crate::landmarks::start_from_landmarks`].
fn landmark_start(
    r: &Runner,
    p: &[f64],
    data: &Run,
    guess: [f64; 3],
) -> Option<([f64; 3], Vec<f64>)> {
    if data.gt.is_some() || data.landmarks.is_empty() {
        return None;
    }
    crate::landmarks::start_from_landmarks(r, p, data, guess)
}

/// The body pose dead reckoning starts from: the measured start seen through
/// the model's pose observation, or placed by the start's landmarks.
pub fn model_start(r: &Runner, p: &[f64], data: &Run) -> [f64; 3] {
    placed_start(r, p, data, data.start_pose(), [0.0; 3]).0
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
        Some((x, d)) => ([0, 1, 2].map(|i| x[i] + offset[i]), d),
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
    run_from(r, p, data, with_sens, [0.0; 3])
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
) -> Track {
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
    let np = p.len();
    let zeros = [0.0; 16];
    let mut scratch = Vec::new();
    let mut pose = Vec::with_capacity(data.steps() + 1);
    pose.push(start);
    // columns: parameters, then the start pose (identity at the start)
    let cols = np + 3;
    let mut sens = with_sens.then(|| {
        let mut data = Vec::with_capacity(3 * cols * (data.steps() + 1));
        for m in 0..3 {
            data.extend((0..cols).map(|c| match c {
                c if c < np => dstart[m * np + c],
                c => f64::from(u8::from(c == np + m)),
            }));
        }
        Sens { cols, data }
    });
    let mut twist = Vec::with_capacity(data.steps());
    // pose and twist, then (with sensitivities) F_x and F_p, from one fused tape
    let f = if with_sens {
        &r.step_linearized
    } else {
        &r.step_twist
    };
    let mut out = vec![0.0; f.rows];
    for k in 0..data.steps() {
        let x = *pose.last().unwrap();
        let dt = [data.dt[k]];
        let mut args: [&[f64]; 8] = [&[]; 8];
        for (slot, a) in args.iter_mut().zip(&f.args) {
            *slot = Runner::step_arg(a, &x, &data.u[k], p, &dt, &zeros);
        }
        f.eval_into(&args[..f.args.len()], &mut out, &mut scratch);
        twist.push([out[3], out[4], out[5]]);
        if let Some(s) = sens.as_mut() {
            // S_{k+1} = F_x S_k + [F_p | 0], written out
            let (jx, jp) = (&out[6..15], &out[15..]);
            let start = s.data.len() - 3 * cols;
            for m in 0..3 {
                for c in 0..cols {
                    let prev = |i: usize| s.data[start + i * cols + c];
                    let direct = if c < np { jp[m * np + c] } else { 0.0 };
                    s.data.push(chain(&jx[m * 3..m * 3 + 3], prev, direct));
                }
            }
        }
        pose.push([out[0], out[1], out[2]]);
    }
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
    let Some(h) = r.ir.observation_kernels(YawRate).map(|o| o.value) else {
        return twist.iter().map(|w| w[2]).collect();
    };
    let (mut out, mut scratch) = ([0.0], Vec::new());
    (0..data.steps())
        .map(|k| {
            h.eval_into(
                &Runner::obs_args(h, &pose[k], &data.u[k], p, &[]),
                &mut out,
                &mut scratch,
            );
            out[0]
        })
        .collect()
}

/// The pose measurements a track predicts (see [`Track::measured`]); empty
/// when they are the track's poses themselves (no delay, no pose observation).
fn predicted_measurements(r: &Runner, p: &[f64], data: &Run, pose: &[[f64; 3]]) -> Vec<[f64; 3]> {
    let tau = crate::timeline::delay(r, p);
    let h = r.ir.observation_kernels(Pose).map(|o| o.value);
    if h.is_none() && (tau == 0.0 || pose.len() < 2) {
        return Vec::new();
    }
    (0..pose.len())
        .map(|k| {
            let x = if tau == 0.0 || pose.len() < 2 {
                pose[k]
            } else {
                let (j, a) = crate::timeline::model_instant(data, k, tau);
                lerp3(&pose[j], &pose[j + 1], a)
            };
            match h {
                Some(h) => {
                    let u = &data.u[k.min(data.steps().saturating_sub(1))];
                    let m = h.eval(&Runner::obs_args(h, &x, u, p, &[]));
                    [m[0], m[1], m[2]]
                }
                None => x,
            }
        })
        .collect()
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
    let tg = r.ir.twist_gyro();
    let start = model_start(r, p, data);
    let mut pose = Vec::with_capacity(data.steps() + 1);
    pose.push(start);
    let (mut omega, mut twist) = (
        Vec::with_capacity(data.steps()),
        Vec::with_capacity(data.steps()),
    );
    let mut scratch = Vec::new();
    let mut v = [0.0; 2];
    for k in 0..data.steps() {
        let w = omega_of(k);
        tg.eval_into(&[&data.u[k], &[w], p], &mut v, &mut scratch);
        let x = *pose.last().unwrap();
        pose.push(arc_step(x, [v[0], v[1], w], data.dt[k]));
        omega.push(w);
        twist.push([v[0], v[1], w]);
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
