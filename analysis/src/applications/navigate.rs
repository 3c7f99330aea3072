//! Seed 004's navigation on odometry: the robot follows the cellular
//! automaton's path cell by cell with the e-puck's discrete moves (turn in
//! place toward the next cell, then drive straight to it), its wheel commands
//! computed by the generated inverse kinematics with the parameters it
//! believes, while the real robot (hidden true parameters, and motors that do
//! not quite do what they are told) moves on. Planned once (Behring et al.),
//! the move sequence is fixed at the start; recalculated every n moves (Oliveira
//! et al.), the robot re-plans from the cell its odometry puts it in and aims
//! each move from its odometry pose.
use crate::applications::grid::Grid;
use crate::model_on_log::model::Runner;
use kinegen_model::ir::{ArgRole, StepForm};
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use serde::Serialize;

#[derive(Debug, Clone)]
pub struct NavOptions {
    /// Re-plan every this many moves (None: planned once).
    pub recalc: Option<usize>,
    /// Relative standard deviation of each wheel's executed motion per move
    /// (motors that do not quite follow their commands; the encoders see it).
    pub actuation: f64,
    /// Robot radius for collisions, m (e-puck: 3.5 cm).
    pub radius: f64,
    /// Forward speed and turn rate of the moves.
    pub speed: f64,
    pub turn_rate: f64,
    /// Integration step, s.
    pub dt: f64,
    pub seed: u64,
}

impl Default for NavOptions {
    fn default() -> Self {
        NavOptions {
            recalc: None,
            actuation: 0.01,
            radius: 0.035,
            speed: 0.05,
            turn_rate: 1.0,
            dt: 0.02,
            seed: 1,
        }
    }
}

#[derive(Debug, Clone, Serialize)]
pub struct Drive {
    /// True and odometry poses at every integration step.
    #[serde(skip)]
    pub truth: Vec<[f64; 3]>,
    #[serde(skip)]
    pub odometry: Vec<[f64; 3]>,
    /// The planned cells (the first plan), as cell centres.
    pub planned: Vec<[f64; 2]>,
    pub moves: usize,
    /// Integration steps taken, and the stride at which `truth` and
    /// `odometry` keep them (see [`Drive::keep`]).
    #[serde(skip)]
    pub steps: usize,
    #[serde(skip)]
    pub stride: usize,
    /// Times the robot's disc newly touched an obstacle or the grid's border.
    pub collisions: usize,
    /// Times its centre newly entered a safety-zone cell.
    pub safety_intrusions: usize,
    /// True distance from the final pose to the goal cell's centre, m.
    pub final_error_m: f64,
    /// Whether the robot believes it reached the goal cell.
    pub reached: bool,
}

/// Most poses a drive keeps of each track: enough to draw it, and a bound
/// on its memory whatever the number of moves (every step kept, a corridor
/// of a million cells took 3.6 GB).
pub const MAX_TRACK_POINTS: usize = 100_000;

impl Drive {
    /// Keep one integration step's true and odometry poses: every
    /// `stride`-th step, the stride doubling (and every other pose kept so
    /// far dropped) whenever the tracks reach [`MAX_TRACK_POINTS`].
    fn keep(&mut self, truth: [f64; 3], odometry: [f64; 3]) {
        self.steps += 1;
        if !self.steps.is_multiple_of(self.stride) {
            return;
        }
        if self.truth.len() >= MAX_TRACK_POINTS {
            // pose j >= 1 is step j*stride (pose 0 the start): the even
            // ones are the steps of the doubled stride
            for track in [&mut self.truth, &mut self.odometry] {
                let mut j = 0;
                track.retain(|_| {
                    j += 1;
                    (j - 1) % 2 == 0
                });
            }
            self.stride *= 2;
            if !self.steps.is_multiple_of(self.stride) {
                return;
            }
        }
        self.truth.push(truth);
        self.odometry.push(odometry);
    }
}

/// Integration steps one move may take (see [`drive`]).
pub const MAX_STEPS_PER_MOVE: f64 = 1e5;

fn wrap(a: f64) -> f64 {
    crate::logs::log::wrap(a)
}

/// A drive that cannot start.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum NavigateError {
    #[error("model `{0}` cannot turn in place: each move of the navigation turns toward the next cell first")]
    CannotSpin(String),
    #[error("--cell {cell:e} m: shorter than the robot travels in one integration step ({travel} m): cells are about the robot's size (7 cm for the e-puck)")]
    CellTooSmall { cell: f64, travel: f64 },
    #[error("--cell {cell:e} m: a move to the next cell would take {steps:.3e} integration steps of {dt} s at {speed} m/s (at most {MAX_STEPS_PER_MOVE:.0e}): cells are about the robot's size (7 cm for the e-puck)")]
    CellTooLarge {
        cell: f64,
        steps: f64,
        dt: f64,
        speed: f64,
    },
    #[error(transparent)]
    NoInverse(#[from] kinegen_model::ir::NoInverse),
    #[error("actuation noise {0} is not a standard deviation")]
    Actuation(f64),
}

/// Drive `grid`'s path with the believed model `belief` on the real robot
/// `truth` (same spec, true parameter values).
pub fn drive(
    grid: &Grid,
    belief: &Runner,
    truth: &Runner,
    o: &NavOptions,
) -> Result<Drive, NavigateError> {
    if !crate::applications::simulate::can_spin(belief) {
        return Err(NavigateError::CannotSpin(belief.ir.name.clone()));
    }
    // one move to a diagonal neighbour, in integration steps: a cell of 1e300 m
    // made each move allocate until the process aborted
    let per_move = grid.cell * std::f64::consts::SQRT_2 / (o.speed * o.dt);
    // and one shorter than a single integration step cannot be driven as a
    // move at all (1e-300 m was accepted)
    if per_move < 1.0 {
        return Err(NavigateError::CellTooSmall {
            cell: grid.cell,
            travel: o.speed * o.dt,
        });
    }
    if per_move.is_nan() || per_move > MAX_STEPS_PER_MOVE {
        return Err(NavigateError::CellTooLarge {
            cell: grid.cell,
            steps: per_move,
            dt: o.dt,
            speed: o.speed,
        });
    }
    let mut mover = Mover {
        grid,
        belief,
        truth,
        o,
        inv: belief.ir.inverse_increment()?,
        step_b: belief.ir.step(StepForm::Exact).value,
        step_t: truth.ir.step(StepForm::Exact).value,
        rng: rand::rngs::SmallRng::seed_from_u64(o.seed),
        noise: Normal::new(0.0, o.actuation.max(0.0))
            .map_err(|_| NavigateError::Actuation(o.actuation))?,
        touching: false,
        in_safety: false,
    };
    let dist = grid.distances();
    let s = grid.centre(grid.start);
    // start facing the first move
    let first = grid.path(&dist, grid.start);
    let h0 = first.get(1).map_or(0.0, |&c| {
        let n = grid.centre(c);
        (n[1] - s[1]).atan2(n[0] - s[0])
    });
    let mut truth_pose = [s[0], s[1], h0];
    let mut odo = truth_pose;
    let mut out = Drive {
        truth: vec![truth_pose],
        odometry: vec![odo],
        planned: first.iter().map(|&c| grid.centre(c)).collect(),
        moves: 0,
        steps: 0,
        stride: 1,
        collisions: 0,
        safety_intrusions: 0,
        final_error_m: 0.0,
        reached: false,
    };
    let max_moves = 4 * grid.size().0 * grid.size().1;
    let mut plan = first;
    let mut k = 1; // index of the next cell in the plan
                   // the pose the robot believes it has: its odometry when it recalculates,
                   // else the planned pose (open loop)
    let mut planned_pose = truth_pose;
    while out.moves < max_moves {
        if let Some(n) = o.recalc {
            if out.moves > 0 && out.moves.is_multiple_of(n) {
                if let Some(cell) = grid.cell_at(odo[0], odo[1]) {
                    plan = grid.path(&dist, cell);
                    k = 1;
                }
            }
        }
        let Some(&next) = plan.get(k) else { break };
        let target = grid.centre(next);
        let from = if o.recalc.is_some() {
            odo
        } else {
            planned_pose
        };
        let (dx, dy) = (target[0] - from[0], target[1] - from[1]);
        let heading = dy.atan2(dx);
        let turn = wrap(heading - from[2]);
        let length = dx.hypot(dy);
        mover.execute(
            [0.0, 0.0, turn],
            turn.abs() / o.turn_rate + o.dt,
            &mut truth_pose,
            &mut odo,
            &mut out,
        );
        mover.execute(
            [length, 0.0, 0.0],
            length / o.speed + o.dt,
            &mut truth_pose,
            &mut odo,
            &mut out,
        );
        planned_pose = [target[0], target[1], heading];
        out.moves += 1;
        k += 1;
        if next == grid.goal {
            out.reached = true;
            break;
        }
    }
    // the tracks end where the robot did, whatever their stride
    if out.truth.last() != Some(&truth_pose) {
        out.truth.push(truth_pose);
        out.odometry.push(odo);
    }
    let g = grid.centre(grid.goal);
    out.final_error_m = (truth_pose[0] - g[0]).hypot(truth_pose[1] - g[1]);
    Ok(out)
}

/// The robot of a navigation run: what it believes (its spec), what it is
/// (the truth), how its motors err, and whether it is touching an obstacle
/// or inside the safety zone (a new contact counts once).
struct Mover<'a> {
    grid: &'a Grid,
    belief: &'a Runner,
    truth: &'a Runner,
    o: &'a NavOptions,
    inv: &'a kinegen_model::ir::Function,
    step_b: &'a kinegen_model::ir::Function,
    step_t: &'a kinegen_model::ir::Function,
    rng: rand::rngs::SmallRng,
    noise: Normal<f64>,
    touching: bool,
    in_safety: bool,
}

impl Mover<'_> {
    /// One discrete motion (dpose in the start-of-move body frame) over
    /// `dur`: the believed model's inputs for it, executed with the motors'
    /// error by the true model (and dead-reckoned by the believed one).
    fn execute(
        &mut self,
        dpose: [f64; 3],
        dur: f64,
        truth_pose: &mut [f64; 3],
        odo: &mut [f64; 3],
        out: &mut Drive,
    ) {
        let o = self.o;
        let n = (dur / o.dt).ceil().max(1.0) as usize;
        let dt = dur / n as f64;
        let per = [
            dpose[0] / n as f64,
            dpose[1] / n as f64,
            dpose[2] / n as f64,
        ];
        let args: Vec<&[f64]> = self
            .inv
            .args
            .iter()
            .map(|a| match a.role {
                ArgRole::PoseIncrement => &per[..],
                ArgRole::Dt => std::slice::from_ref(&dt),
                _ => &self.belief.p[..],
            })
            .collect();
        let cmd = self.belief.eval(self.inv, &args);
        // what the motors really do this move (the encoders measure it)
        let done: Vec<f64> = cmd
            .iter()
            .map(|c| c * (1.0 + self.noise.sample(&mut self.rng)))
            .collect();
        for _ in 0..n {
            let t = self.truth.eval(
                self.step_t,
                &Runner::step_args(
                    self.step_t,
                    truth_pose,
                    &done,
                    &self.truth.p,
                    &[dt],
                    &[0.0; 16],
                ),
            );
            *truth_pose = [t[0], t[1], t[2]];
            let b = self.belief.eval(
                self.step_b,
                &Runner::step_args(self.step_b, odo, &done, &self.belief.p, &[dt], &[0.0; 16]),
            );
            *odo = [b[0], b[1], b[2]];
            out.keep(*truth_pose, *odo);
            let hit = self.grid.collides(truth_pose[0], truth_pose[1], o.radius);
            if hit && !self.touching {
                out.collisions += 1;
            }
            self.touching = hit;
            let safe = self.grid.in_safety_zone(truth_pose[0], truth_pose[1]);
            if safe && !self.in_safety {
                out.safety_intrusions += 1;
            }
            self.in_safety = safe;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A million integration steps keep at most MAX_TRACK_POINTS poses of
    /// each track, each kept pose the step its index and stride say.
    #[test]
    fn the_tracks_stay_bounded_whatever_the_drive() {
        let mut d = Drive {
            truth: vec![[0.0; 3]],
            odometry: vec![[0.0; 3]],
            planned: vec![],
            moves: 0,
            steps: 0,
            stride: 1,
            collisions: 0,
            safety_intrusions: 0,
            final_error_m: 0.0,
            reached: false,
        };
        for step in 1..=1_000_000u32 {
            let p = [f64::from(step), 0.0, 0.0];
            d.keep(p, p);
        }
        assert!(d.truth.len() <= MAX_TRACK_POINTS + 1, "{}", d.truth.len());
        assert!(d.truth.len() > MAX_TRACK_POINTS / 3);
        for (j, p) in d.truth.iter().enumerate().skip(1) {
            assert_eq!(p[0], (j * d.stride) as f64);
        }
        assert_eq!(d.truth.len(), d.odometry.len());
    }
}
