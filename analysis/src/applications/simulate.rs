//! Synthetic logs in exactly the real-log format (CONTRACT section 2).
//!
//! The robot's controller commands inputs (as its own sensors read them) through the
//! *base* model's inverse kinematics with the true parameters; the true motion is
//! integrated with the *truth* model, which may carry hidden effects, at 10
//! sub-steps per sample between jittered time stamps. Sensors: quantised cumulative
//! encoder counts, quantised wheel angles, noisy steering encoder, noisy motion
//! capture with wrapped heading, noisy gyro.
use crate::logs::log::wrap;
use crate::model_on_log::model::Runner;
use crate::model_on_log::steering;
use kinegen_model::decl::InputKind;
use kinegen_model::decl::ObservationRole::{Pose, RangeBearing, YawRate};
use kinegen_model::ir::StepForm;
use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, Normal};
use std::f64::consts::PI;

#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Trajectory {
    /// UMBMark bidirectional square (seed 004): a 1 m square counter-clockwise, then clockwise.
    Square,
    /// One UMBMark square, clockwise or counter-clockwise (for the UMBMark method,
    /// which needs separate runs in each direction).
    SquareCw,
    SquareCcw,
    FigureEight,
    /// Smooth random driving.
    Random,
    /// Turning in place, both ways (models that can).
    Spin,
    /// Driving 1.5 m along a line and back in reverse, with the small heading
    /// corrections of a robot's line following (Ivanjko's straight-line
    /// calibration run): a log that barely turns.
    BackAndForth,
    /// A smooth tour through the mapped landmarks in the map's order, stopping
    /// at the last (seed 001 sec. 3: the robot visits 12 beacons).
    Beacons,
}

/// A trajectory name `simulate` does not know.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("unknown trajectory `{0}` (square, square-cw, square-ccw, figure8, random, spin, back-and-forth, beacons)")]
pub struct UnknownTrajectory(pub String);

impl std::str::FromStr for Trajectory {
    type Err = UnknownTrajectory;
    fn from_str(s: &str) -> Result<Self, UnknownTrajectory> {
        match s {
            "square" | "umbmark" => Ok(Trajectory::Square),
            "square-cw" => Ok(Trajectory::SquareCw),
            "square-ccw" => Ok(Trajectory::SquareCcw),
            "figure8" | "figure-eight" => Ok(Trajectory::FigureEight),
            "random" => Ok(Trajectory::Random),
            "spin" | "turn-in-place" => Ok(Trajectory::Spin),
            "back-and-forth" | "straight" => Ok(Trajectory::BackAndForth),
            "beacons" => Ok(Trajectory::Beacons),
            _ => Err(UnknownTrajectory(s.to_string())),
        }
    }
}

#[derive(Debug, Clone)]
pub struct SimOptions {
    pub trajectory: Trajectory,
    pub seed: u64,
    pub rate_hz: f64,
    /// Repeat the trajectory this many times.
    pub laps: usize,
    pub pos_noise: f64,
    pub heading_noise: f64,
    pub gyro_noise: f64,
    /// Landmarks (id, x, y) to observe with the model's `landmark` observation at
    /// `landmark_hz`, up to `landmark_range` metres away.
    pub landmarks: Vec<(String, [f64; 2])>,
    pub landmark_hz: f64,
    pub landmark_range: f64,
    /// Cruise speed of the beacons tour, m/s.
    pub cruise_speed: f64,
}

impl Default for SimOptions {
    fn default() -> Self {
        SimOptions {
            trajectory: Trajectory::Square,
            seed: 1,
            rate_hz: 20.0,
            laps: 1,
            pos_noise: 0.001,
            heading_noise: 0.002,
            gyro_noise: 0.005,
            landmarks: Vec::new(),
            landmark_hz: 5.0,
            landmark_range: 10.0,
            cruise_speed: 0.5,
        }
    }
}

/// A simulated log and, when landmarks were given, its range-bearing observations
/// (t, id, range, bearing).
pub struct SimLog {
    pub header: Vec<String>,
    pub rows: Vec<Vec<f64>>,
    pub observations: Vec<(f64, String, f64, f64)>,
}

impl SimLog {
    /// The log as a run of `r`'s model, read as its CSV would be (`name` names
    /// it in messages), without writing a file.
    pub fn to_run(
        &self,
        r: &Runner,
        name: &str,
    ) -> Result<crate::model_on_log::run::Run, crate::logs::log::LogError> {
        let columns = self
            .header
            .iter()
            .enumerate()
            .map(|(j, h)| (h.clone(), self.rows.iter().map(|row| row[j]).collect()))
            .collect();
        let log = crate::logs::log::Log {
            path: std::path::PathBuf::from(name),
            columns,
            header: self.header.clone(),
            len: self.rows.len(),
            // the lines of the CSV this log is written as
            first_line: 2,
        };
        crate::model_on_log::run::Run::from_log(&log, r)
    }

    /// Its sightings as a run holds them, placed on `map` (the landmarks it
    /// was simulated with), as `--observations` and `--landmarks` are read.
    pub fn sightings(
        &self,
        map: &[(String, [f64; 2])],
    ) -> Vec<crate::model_on_log::run::LandmarkObs> {
        (self.observations.iter())
            .filter_map(|(t, id, range, bearing)| {
                let (_, [xl, yl]) = map.iter().find(|(m, _)| m == id)?;
                Some(crate::model_on_log::run::LandmarkObs {
                    t: *t,
                    id: id.as_str().into(),
                    xl: *xl,
                    yl: *yl,
                    range: *range,
                    bearing: *bearing,
                })
            })
            .collect()
    }
}

/// One line of a 12-bit angle encoder (4096 lines per revolution): wheel angles
/// and steering angles are quantised to it.
const ENCODER_LINE: f64 = 2.0 * PI / 4096.0;

/// A zero-mean Gaussian sample with standard deviation `s` (0 when `s` is not positive).
fn gaussian(s: f64, rng: &mut SmallRng) -> f64 {
    if s > 0.0 {
        Normal::new(0.0, s).unwrap().sample(rng)
    } else {
        0.0
    }
}

/// A smooth 0 -> 1 ramp.
fn smooth(x: f64) -> f64 {
    let x = x.clamp(0.0, 1.0);
    x * x * (3.0 - 2.0 * x)
}

/// A segment of constant-shape motion: duration and a profile of body twist.
struct Seg {
    dur: f64,
    twist: [f64; 3],
}

/// Trapezoid-ish speed profile inside a segment (smooth start and stop).
fn profile(t: f64, dur: f64) -> f64 {
    let ramp = (0.2 * dur).min(0.8);
    smooth(t / ramp) * smooth((dur - t) / ramp)
}

fn square(can_spin: bool, dirs: &[f64]) -> Vec<Seg> {
    let (v, w) = (0.3, 0.8);
    let side = 1.0;
    let mut segs = Vec::new();
    for &dir in dirs {
        for _ in 0..4 {
            segs.push(Seg {
                dur: side / v * 1.35,
                twist: [v, 0.0, 0.0],
            });
            if can_spin {
                segs.push(Seg {
                    dur: (PI / 2.0) / w * 1.35,
                    twist: [0.0, 0.0, dir * w],
                });
            } else {
                // quarter arc of radius 0.5 m
                let r = 0.5;
                segs.push(Seg {
                    dur: (PI / 2.0 * r) / 0.2 * 1.35,
                    twist: [0.2, 0.0, dir * 0.2 / r],
                });
            }
            segs.push(Seg {
                dur: 0.5,
                twist: [0.0; 3],
            });
        }
    }
    segs
}

/// [`Trajectory::BackAndForth`]: 1.5 m forward at 0.3 m/s, a pause, the
/// same in reverse, and a pause, with heading corrections of 0.03 rad/s
/// (a line follower's) while moving.
fn back_and_forth() -> (Box<dyn Fn(f64) -> [f64; 3]>, f64) {
    let (v, run) = (0.3, 1.5 * 1.35 / 0.3);
    let leg = run + 1.0;
    (
        Box::new(move |t| {
            let (back, at) = (t >= leg, t % leg);
            if at >= run {
                return [0.0; 3];
            }
            let k = profile(at, run);
            let sign = if back { -1.0 } else { 1.0 };
            [sign * v * k, 0.0, 0.03 * (2.0 * PI * t / 3.0).sin() * k]
        }),
        2.0 * leg,
    )
}

/// Pure pursuit of the landmarks in order from the start pose (0, 0, 0),
/// planned once on an ideal unicycle at 100 Hz: cruise at `speed` (m/s), turn toward
/// the next landmark at up to 1 rad/s (and within the curvature limit of a robot
/// that cannot turn in place), take the next one within 1 m, slow down into the
/// last. The twist is then replayed open-loop, like the other trajectories.
fn beacon_tour(
    landmarks: &[(String, [f64; 2])],
    can_spin: bool,
    speed: f64,
) -> (Box<dyn Fn(f64) -> [f64; 3]>, f64) {
    const DT: f64 = 0.01;
    let (mut x, mut y, mut th) = (0.0f64, 0.0f64, 0.0f64);
    let mut twists: Vec<[f64; 3]> = Vec::new();
    let mut next = 0;
    // a bound, so a landmark the robot cannot reach never loops forever
    while next < landmarks.len() && twists.len() < 200_000 {
        let [lx, ly] = landmarks[next].1;
        let d = (lx - x).hypot(ly - y);
        let last = next + 1 == landmarks.len();
        if d < if last { 0.05 } else { 1.0 } {
            next += 1;
            continue;
        }
        let err = crate::logs::log::wrap((ly - y).atan2(lx - x) - th);
        let t = twists.len() as f64 * DT;
        // smooth start, slow down into the last landmark, slow in sharp turns
        let mut v = speed * smooth(t / 2.0) * (1.0 - 0.8 * err.abs() / PI);
        if last {
            v = v.min(speed * d);
        }
        let mut w = (2.0 * err).clamp(-1.0, 1.0);
        if !can_spin {
            w = w.clamp(-0.8 * v, 0.8 * v);
        }
        twists.push([v, 0.0, w]);
        let a = w * DT;
        x += v * DT * (th + 0.5 * a).cos();
        y += v * DT * (th + 0.5 * a).sin();
        th += a;
    }
    let total = twists.len() as f64 * DT + 1.0;
    (
        Box::new(move |t| {
            let k = (t / DT) as usize;
            twists.get(k).copied().unwrap_or([0.0; 3])
        }),
        total,
    )
}

/// The desired body twist at time t, and the total duration.
fn planner(
    o: &SimOptions,
    can_spin: bool,
    lateral: bool,
    rng: &mut SmallRng,
) -> (Box<dyn Fn(f64) -> [f64; 3]>, f64) {
    match o.trajectory {
        Trajectory::Square | Trajectory::SquareCw | Trajectory::SquareCcw => {
            let dirs: &[f64] = match o.trajectory {
                Trajectory::SquareCw => &[-1.0],
                Trajectory::SquareCcw => &[1.0],
                _ => &[1.0, -1.0],
            };
            let segs = square(can_spin, dirs);
            let total: f64 = segs.iter().map(|s| s.dur).sum();
            (
                Box::new(move |t| {
                    let mut t0 = 0.0;
                    for s in &segs {
                        if t < t0 + s.dur {
                            let k = profile(t - t0, s.dur);
                            return [s.twist[0] * k, s.twist[1] * k, s.twist[2] * k];
                        }
                        t0 += s.dur;
                    }
                    [0.0; 3]
                }),
                total,
            )
        }
        Trajectory::FigureEight => (
            Box::new(|t| {
                let k = smooth(t / 2.0);
                [0.35 * k, 0.0, 0.7 * (2.0 * PI * t / 20.0).sin() * k]
            }),
            40.0,
        ),
        Trajectory::Random => {
            let ph: Vec<f64> = (0..9).map(|_| rng.gen_range(0.0..2.0 * PI)).collect();
            let fr: Vec<f64> = (0..9).map(|_| rng.gen_range(0.03..0.25)).collect();
            (
                Box::new(move |t| {
                    let k = smooth(t / 2.0);
                    let s = |i: usize| (2.0 * PI * fr[i] * t + ph[i]).sin();
                    let v = 0.3 + 0.1 * s(0) + 0.05 * s(1);
                    let vy = if lateral {
                        0.15 * s(6) + 0.05 * s(7)
                    } else {
                        0.0
                    };
                    [v * k, vy * k, (0.6 * s(2) + 0.3 * s(3) + 0.2 * s(4)) * k]
                }),
                90.0,
            )
        }
        Trajectory::Beacons => beacon_tour(&o.landmarks, can_spin, o.cruise_speed),
        Trajectory::BackAndForth => back_and_forth(),
        Trajectory::Spin => (
            Box::new(|t| {
                let k = smooth(t / 1.0);
                [
                    0.0,
                    0.0,
                    1.0 * (2.0 * PI * t / 12.0).sin().signum()
                        * k
                        * smooth((t % 6.0) / 1.0)
                        * smooth((6.0 - t % 6.0) / 1.0),
                ]
            }),
            36.0,
        ),
    }
}

/// Inputs (as the robot's sensors read them) that realise `twist` in `base`, with
/// the configuration inputs (e.g. caster steering angles, see [`config_inputs`])
/// at `cfg`, one value per configuration input. Absolute inputs the inverse
/// only reads (a car-like robot's steering angle, see [`crate::model_on_log::steering`]) are
/// solved for so that the model drives `twist`.
pub fn command_at(base: &Runner, twist: &[f64; 3], cfg: &[f64]) -> Vec<f64> {
    let cfg_idx = config_inputs(base);
    let given: Vec<String> = cfg_idx
        .iter()
        .map(|&i| base.ir.inputs[i].name.clone())
        .collect();
    let mut at: Vec<f64> = steering::configuration_names(base)
        .iter()
        .map(|n| given.iter().position(|g| g == n).map_or(0.0, |k| cfg[k]))
        .collect();
    steering::solve(base, twist, &mut at, &steering::to_solve(base, &given));
    steering::inputs_for(base, twist, &at)
}

/// [`command_at`] with every configuration input at 0.
pub fn command(base: &Runner, twist: &[f64; 3]) -> Vec<f64> {
    command_at(base, twist, &vec![0.0; config_inputs(base).len()])
}

/// The time of sub-step `j`'s middle in a step from `t0` with sub-steps of `h`.
fn tm_abs(t0: f64, j: usize, h: f64) -> f64 {
    t0 + (j as f64 + 0.5) * h
}

/// Absolute inputs whose column also feeds a cumulative input (a steerable wheel's
/// angle and its rate): the robot's configuration, which the simulator integrates
/// from the commanded rates instead of commanding it.
pub fn config_inputs(base: &Runner) -> Vec<usize> {
    let inputs = &base.ir.inputs;
    (0..inputs.len())
        .filter(|&i| {
            inputs[i].kind == InputKind::Absolute
                && inputs
                    .iter()
                    .any(|o| o.kind == InputKind::Cumulative && o.column == inputs[i].column)
        })
        .collect()
}

/// For each configuration input, the cumulative input that is its rate.
fn config_rates(base: &Runner, cfg: &[usize]) -> Vec<usize> {
    let inputs = &base.ir.inputs;
    cfg.iter()
        .map(|&i| {
            inputs
                .iter()
                .position(|o| o.kind == InputKind::Cumulative && o.column == inputs[i].column)
                .expect("config input has a rate")
        })
        .collect()
}

/// Can the base model turn in place (is the pure rotation in the image of its inputs)?
pub fn can_spin(base: &Runner) -> bool {
    let u = command(base, &[0.0, 0.0, 1.0]);
    let t = base.eval(base.ir.twist(), &[&u, &base.p]);
    (t[2] - 1.0).abs() < 1e-6 && t[0].abs() < 1e-9
}

/// Simulate a log.
pub fn simulate(base: &Runner, truth: &Runner, o: &SimOptions) -> SimLog {
    let mut rng = SmallRng::seed_from_u64(o.seed);
    let (plan, dur) = route(base, o, &mut rng);
    let times = sample_times(o, dur, &mut rng);
    let mut sim = Robot::new(base, truth, &plan, dur);
    let header = sim.header();
    let mut rows = Vec::with_capacity(times.len());
    for k in 0..times.len() {
        if k > 0 {
            sim.advance(times[k - 1], times[k]);
        }
        rows.push(sim.row(k, times[k], o, &mut rng));
    }
    let observations = observe_landmarks(truth, o, &times, &sim.history, &mut rng);
    SimLog {
        header,
        rows,
        observations,
    }
}

/// The body twist the robot is commanded at each time after the log starts
/// (from the trajectory's planner, limited in curvature for a robot that
/// cannot turn in place, after a second at rest), and the length of one lap.
fn route(base: &Runner, o: &SimOptions, rng: &mut SmallRng) -> (impl Fn(f64) -> [f64; 3], f64) {
    let lateral = {
        let u = command(base, &[0.0, 1.0, 0.0]);
        base.eval(base.ir.twist(), &[&u, &base.p])[1] > 0.5
    };
    let spin = can_spin(base);
    let (plan1, dur0) = planner(o, spin, lateral, rng);
    // a vehicle that cannot turn in place is limited in curvature (|omega| <= 0.8 v,
    // i.e. radius >= 1.25 m; a 1 m tricycle then steers at most ~39 degrees)
    let plan0 = move |t: f64| {
        let mut w = plan1(t);
        if !spin {
            let lim = 0.8 * w[0].abs();
            w[2] = w[2].clamp(-lim, lim);
        }
        w
    };
    // logs start with the robot at rest for a second, as real ones do
    const REST: f64 = 1.0;
    let plan = move |t: f64| if t < REST { [0.0; 3] } else { plan0(t - REST) };
    (plan, dur0 + REST)
}

/// The most rows a simulation makes: about 2 GB of CSV, and what its rows
/// take in memory while they are written.
pub const MAX_ROWS: f64 = 20e6;

/// How many rows `simulate(base, _, o)` makes (the same route, drawn from
/// the same seed), so a request can be refused before it takes the memory.
pub fn planned_rows(base: &Runner, o: &SimOptions) -> f64 {
    let mut rng = SmallRng::seed_from_u64(o.seed);
    let (_, dur) = route(base, o, &mut rng);
    rows_of(o, dur)
}

/// The rows of `o.laps` laps of `dur` seconds at `o.rate_hz`.
fn rows_of(o: &SimOptions, dur: f64) -> f64 {
    (dur * o.laps as f64 * o.rate_hz).ceil() + 1.0
}

/// The rows' times: `o.laps` laps of `dur` at `o.rate_hz`, each but the first
/// jittered by up to a tenth of a period.
fn sample_times(o: &SimOptions, dur: f64, rng: &mut SmallRng) -> Vec<f64> {
    let n = rows_of(o, dur) as usize;
    let period = 1.0 / o.rate_hz;
    let jitter = 0.1 * period;
    (0..n)
        .map(|k| {
            if k == 0 {
                0.0
            } else {
                k as f64 * period + rng.gen_range(-jitter..jitter)
            }
        })
        .collect()
}

/// The simulated robot: the true model driven along the route, its pose
/// history, encoder counts, steering configuration and commands.
struct Robot<'a, P: Fn(f64) -> [f64; 3]> {
    base: &'a Runner,
    truth: &'a Runner,
    plan: &'a P,
    /// one lap's length (the plan repeats)
    dur: f64,
    step: &'a kinegen_model::ir::Function,
    obs_pose: Option<&'a kinegen_model::ir::Function>,
    obs_gyro: Option<&'a kinegen_model::ir::Function>,
    /// each cumulative input's integral
    cum: Vec<f64>,
    x: [f64; 3],
    cfg_idx: Vec<usize>,
    cfg_rate: Vec<usize>,
    /// the inputs with a log column of their own
    written: Vec<usize>,
    /// ground truth is recorded with the delay of a `time_offset` parameter
    delay: f64,
    history: Vec<(f64, [f64; 3])>,
    t_now: f64,
    /// configuration (steering angles of caster wheels): starts straight ahead and
    /// follows its commanded rate, integrated with the midpoint rule
    cfg: Vec<f64>,
    last_u: Vec<f64>,
    /// commands (absolute inputs that hold between rows, see Input::between):
    /// the robot executes the value logged at the row before, until the next
    hold_idx: Vec<usize>,
    held: Vec<f64>,
    /// Under an input delay the robot executes, at time s, the command logged
    /// at the last row before s - delay (crate::model_on_log::timeline): the rows' commands
    /// are kept to look back into.
    input_delay: f64,
    logged: Vec<(f64, Vec<f64>)>,
    /// Under an input lag the robot follows the (delayed) commands with a
    /// first-order response (crate::model_on_log::timeline): its state, one per command.
    input_lag: f64,
    responses: Vec<crate::model_on_log::timeline::Response>,
    /// The gyro reports the mean yaw rate over the sample interval (an
    /// integrating or low-pass-filtered MEMS gyro), which is what a step of the
    /// model predicts.
    gyro_mean: f64,
}

impl<'a, P: Fn(f64) -> [f64; 3]> Robot<'a, P> {
    fn new(base: &'a Runner, truth: &'a Runner, plan: &'a P, dur: f64) -> Self {
        let inputs = &truth.ir.inputs;
        let cfg_idx = config_inputs(base);
        let cfg_rate = config_rates(base, &cfg_idx);
        // one column per log column: a steering angle feeds both an angle and a rate
        // input, and is written once, from the angle
        let written: Vec<usize> = (0..inputs.len())
            .filter(|&i| {
                cfg_idx.contains(&i)
                    || !(cfg_idx
                        .iter()
                        .any(|&c| inputs[c].column == inputs[i].column)
                        || inputs[..i].iter().any(|o| o.column == inputs[i].column))
            })
            .collect();
        let cfg = vec![0.0; cfg_idx.len()];
        let last_u = command_at(base, &plan(0.0), &cfg);
        let hold_idx: Vec<usize> = (0..inputs.len())
            .filter(|&i| inputs[i].is_command() && !cfg_idx.contains(&i))
            .collect();
        let x = [0.0, 0.0, 0.0];
        Robot {
            base,
            truth,
            plan,
            dur,
            step: truth.ir.step(StepForm::Exact).value,
            obs_pose: truth.ir.observation_kernels(Pose).map(|o| o.value),
            obs_gyro: truth.ir.observation_kernels(YawRate).map(|o| o.value),
            cum: vec![0.0; inputs.len()],
            x,
            cfg_idx,
            cfg_rate,
            written,
            delay: crate::model_on_log::timeline::delay(truth, &truth.p),
            history: vec![(0.0, x)],
            t_now: 0.0,
            cfg,
            held: last_u.clone(),
            last_u,
            hold_idx,
            input_delay: crate::model_on_log::timeline::input_delay(truth, &truth.p),
            logged: Vec::new(),
            input_lag: crate::model_on_log::timeline::input_lag(truth, &truth.p),
            responses: Vec::new(),
            gyro_mean: 0.0,
        }
    }

    /// The log's header: time, each written input's column, the pose columns
    /// and the gyro's.
    fn header(&self) -> Vec<String> {
        let inputs = &self.truth.ir.inputs;
        let mut header: Vec<String> = vec!["t".into()];
        header.extend(self.written.iter().map(|&i| inputs[i].column.clone()));
        // the columns the spec reads measurements from (its pose and yaw-rate observations)
        header.extend(self.base.ir.pose_columns());
        if self.obs_gyro.is_some() {
            header.push(self.base.ir.gyro_column());
        }
        header
    }

    /// The inputs at sub-step `j` (of length `h`) of the step from `t0`:
    /// commanded along the plan, the configuration advanced by the midpoint
    /// rule, the held commands as the robot executes them.
    fn inputs_at(&mut self, t0: f64, j: usize, h: f64) -> Vec<f64> {
        let (base, plan) = (self.base, self.plan);
        let tm = (t0 + (j as f64 + 0.5) * h) % self.dur;
        let mut u = if self.cfg.is_empty() {
            command(base, &plan(tm))
        } else {
            let u0 = command_at(base, &plan(tm), &self.cfg);
            let mid: Vec<f64> = self
                .cfg
                .iter()
                .zip(&self.cfg_rate)
                .map(|(c, &r)| c + 0.5 * h * u0[r])
                .collect();
            let u = command_at(base, &plan(tm), &mid);
            for (c, &r) in self.cfg.iter_mut().zip(&self.cfg_rate) {
                *c += h * u[r];
            }
            u
        };
        let executing = if self.input_delay == 0.0 {
            &self.held
        } else {
            let at = tm_abs(t0, j, h) - self.input_delay;
            let n = self.logged.partition_point(|(t, _)| *t <= at);
            self.logged
                .get(n.saturating_sub(1))
                .map_or(&self.held, |(_, c)| c)
        };
        if self.input_lag == 0.0 {
            for &i in &self.hold_idx {
                u[i] = executing[i];
            }
            return u;
        }
        if self.responses.is_empty() {
            // the robot was executing its first command when the log began
            self.responses = self
                .hold_idx
                .iter()
                .map(|&i| crate::model_on_log::timeline::Response {
                    y: executing[i],
                    dy: 0.0,
                })
                .collect();
        }
        for (resp, &i) in self.responses.iter_mut().zip(&self.hold_idx) {
            // the sub-step's mean response: exact for its held target
            u[i] = resp.follow(executing[i], h, self.input_lag).0 / h;
        }
        u
    }

    /// Drive from `t0` to `t1` in ten exact sub-steps, integrating the
    /// encoders and averaging the gyro.
    fn advance(&mut self, t0: f64, t1: f64) {
        let truth = self.truth;
        let zeros = [0.0; 16];
        self.gyro_mean = 0.0;
        let m = 10;
        let h = (t1 - t0) / m as f64;
        for j in 0..m {
            let u = self.inputs_at(t0, j, h);
            let dt = [h];
            self.x = {
                let out = truth.eval(
                    self.step,
                    &Runner::step_args(self.step, &self.x, &u, &truth.p, &dt, &zeros),
                );
                [out[0], out[1], out[2]]
            };
            for (c, ui) in self.cum.iter_mut().zip(&u) {
                *c += ui * h;
            }
            self.t_now += h;
            self.history.push((self.t_now, self.x));
            if let Some(g) = self.obs_gyro {
                self.gyro_mean +=
                    truth.eval(g, &Runner::obs_args(g, &self.x, &u, &truth.p, &[]))[0] / m as f64;
            }
            self.last_u = u;
        }
    }

    /// Row `k` at time `t`: the inputs as logged, the pose as measured (with
    /// noise and any measurement delay) and the gyro.
    fn row(&mut self, k: usize, t: f64, o: &SimOptions, rng: &mut SmallRng) -> Vec<f64> {
        let (base, plan, dur) = (self.base, self.plan, self.dur);
        let inputs = &self.truth.ir.inputs;
        let mut row = vec![t];
        // the inputs commanded at t_k, which absolute sensors sample (computed once per row)
        let mut commanded: Option<Vec<f64>> = None;
        if !self.hold_idx.is_empty() {
            let c = command(base, &plan(t % dur));
            for &i in &self.hold_idx {
                self.held[i] = c[i];
            }
            if self.input_delay != 0.0 {
                self.logged.push((t, self.held.clone()));
            }
            commanded = Some(c);
        }
        for &i in &self.written {
            let inp = &inputs[i];
            if let Some(c) = self.cfg_idx.iter().position(|&c| c == i) {
                // absolute steering encoder, wrapped to (-pi, pi]
                row.push(wrap((self.cfg[c] / ENCODER_LINE).round() * ENCODER_LINE));
                continue;
            }
            row.push(match inp.kind {
                InputKind::Cumulative if inp.counts_events() => self.cum[i].floor(),
                // wheel-angle encoders
                InputKind::Cumulative => (self.cum[i] / ENCODER_LINE).floor() * ENCODER_LINE,
                // absolute angle sensors (steering encoders, 12 bit like the caster
                // wheels' above) sample the value at t_k; other absolute inputs get
                // Gaussian noise
                InputKind::Absolute if inp.unit == "rad" => {
                    (commanded.get_or_insert_with(|| command(base, &plan(t % dur)))[i]
                        / ENCODER_LINE)
                        .round()
                        * ENCODER_LINE
                }
                // a command is logged as sent: what the robot executes until the next row
                InputKind::Absolute if self.hold_idx.contains(&i) => self.held[i],
                InputKind::Absolute => {
                    commanded.get_or_insert_with(|| command(base, &plan(t % dur)))[i]
                        + gaussian(0.002, rng)
                }
            });
        }
        self.measure(k, t, o, rng, &mut row);
        row
    }

    /// The pose and gyro columns of row `k` at time `t`.
    fn measure(&self, k: usize, t: f64, o: &SimOptions, rng: &mut SmallRng, row: &mut Vec<f64>) {
        let truth = self.truth;
        let seen = if self.delay == 0.0 {
            self.x
        } else {
            at_time(&self.history, t - self.delay)
        };
        let pose = match self.obs_pose {
            Some(h) => truth.eval(h, &Runner::obs_args(h, &seen, &self.last_u, &truth.p, &[])),
            None => seen.to_vec(),
        };
        row.push(pose[0] + gaussian(o.pos_noise, rng));
        row.push(pose[1] + gaussian(o.pos_noise, rng));
        row.push(wrap(pose[2] + gaussian(o.heading_noise, rng)));
        if let Some(g) = self.obs_gyro {
            let v = if k == 0 {
                truth.eval(
                    g,
                    &Runner::obs_args(g, &self.x, &self.last_u, &truth.p, &[]),
                )[0]
            } else {
                self.gyro_mean
            };
            row.push(v + gaussian(o.gyro_noise, rng));
        }
    }
}

/// Range-bearing observations of the landmarks in range, through the truth
/// model's `landmark` observation (seed 001 eq. 6) at the true pose, with the
/// noise the spec declares for it (bearing wrapped).
fn observe_landmarks(
    truth: &Runner,
    o: &SimOptions,
    times: &[f64],
    history: &[(f64, [f64; 3])],
    rng: &mut SmallRng,
) -> Vec<(f64, String, f64, f64)> {
    let Some(h) = truth.ir.observation_kernels(RangeBearing).map(|o| o.value) else {
        return vec![];
    };
    if o.landmarks.is_empty() {
        return vec![];
    }
    // the noise localize and fit assume: a spec without `sigma` (zeros)
    // gets the defaults, not exact sightings that no filter could weigh
    let sig = crate::model_on_log::landmarks::sigma(truth);
    let u0 = vec![0.0; truth.ir.inputs.len()];
    let mut out = Vec::new();
    let mut next = times[0];
    for &t in times {
        if t + 1e-9 < next {
            continue;
        }
        next = t + 1.0 / o.landmark_hz;
        let x = at_time(history, t);
        for (id, lm) in &o.landmarks {
            if ((lm[0] - x[0]).powi(2) + (lm[1] - x[1]).powi(2)).sqrt() > o.landmark_range {
                continue;
            }
            let v = truth.eval(h, &Runner::obs_args(h, &x, &u0, &truth.p, lm));
            // a range sensor reports no negative range: right beside a
            // landmark the noise is drawn again (a truncated Gaussian), so
            // the simulator never writes what `localize` rightly refuses
            let mut range = v[0] + gaussian(sig[0], rng);
            for _ in 0..100 {
                if range > 0.0 {
                    break;
                }
                range = v[0] + gaussian(sig[0], rng);
            }
            if range <= 0.0 {
                continue;
            }
            out.push((t, id.clone(), range, wrap(v[1] + gaussian(sig[1], rng))));
        }
    }
    out
}

/// The true pose at time `t` (linear interpolation of the sub-step history; the
/// first pose before the start, extrapolated past the end).
fn at_time(h: &[(f64, [f64; 3])], t: f64) -> [f64; 3] {
    if t <= h[0].0 || h.len() < 2 {
        return h[0].1;
    }
    let j = h.partition_point(|e| e.0 <= t).clamp(1, h.len() - 1);
    let ((t0, a), (t1, b)) = (h[j - 1], h[j]);
    let w = (t - t0) / (t1 - t0);
    [0, 1, 2].map(|i| a[i] + w * (b[i] - a[i]))
}

/// Format a simulated log as CSV text.
pub fn to_csv(header: &[String], rows: &[Vec<f64>], cumulative_counts: &[bool]) -> String {
    let mut s = header.join(",") + "\n";
    for r in rows {
        let cells: Vec<String> = r
            .iter()
            .enumerate()
            .map(|(i, v)| {
                if i > 0 && cumulative_counts.get(i - 1).copied().unwrap_or(false) {
                    format!("{}", *v as i64)
                } else {
                    format!("{v:.9}")
                }
            })
            .collect();
        s += &cells.join(",");
        s.push('\n');
    }
    s
}
