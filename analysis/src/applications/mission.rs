//! Seed 004's experiment, the one call `kinegen navigate` makes: the robot
//! crosses a grid on its odometry ([`drive`]) with the parameters it
//! believes (the spec's), then, when asked, its odometry is calibrated by a
//! registered method on square runs of the real robot simulated as its
//! UMBMark test would drive them, and it crosses again.
//!
//! ```ignore
//! let mission = Mission { spec: Path::new("epuck.toml"), grid: Path::new("grid.txt"), cell: 0.07,
//!     sets: &["b=0.054".into()], options: NavOptions::default(), calibrate: by_name("umbmark") };
//! let done = navigate_files(&mission, &my_deriver)?;
//! println!("{} collisions before, {:?} after", done.before.collisions, done.calibrated.map(|c| c.drive.collisions));
//! ```
use crate::applications::grid::Grid;
use crate::applications::navigate::{drive, Drive, NavOptions, NavigateError};
use crate::applications::simulate::{simulate, SimOptions, Trajectory};
use crate::estimation::methods::{Method, MethodError, Settings};
use crate::logs::log::LogError;
use crate::model_on_log::derivation::{DerivationFailed, Deriver};
use crate::model_on_log::model::{parse_sets, ModelError, Runner};
use kinegen_model::error::SourceError;
use kinegen_model::spec::Model;
use std::path::Path;

/// What to navigate: the robot's spec (what its odometry believes), the
/// grid with its cell side, the real robot's true values (`NAME=VALUE`),
/// the drive's options, and the registered method to calibrate with, if any.
pub struct Mission<'a> {
    pub spec: &'a Path,
    pub grid: &'a Path,
    pub cell: f64,
    pub sets: &'a [String],
    pub options: NavOptions,
    pub calibrate: Option<&'static dyn Method>,
}

/// The odometry calibrated by a method, and the crossing with it.
pub struct CalibratedDrive {
    pub method: String,
    pub note: String,
    /// The believed model with the calibrated values.
    pub odometry: Runner,
    pub drive: Drive,
}

/// The mission done: the grid, the believed and the real robot, and the
/// crossings before and after calibration.
pub struct Navigated {
    pub grid: Grid,
    pub belief: Runner,
    pub truth: Runner,
    pub before: Drive,
    pub calibrated: Option<CalibratedDrive>,
}

/// Why the mission could not be flown.
#[derive(Debug, thiserror::Error)]
pub enum MissionError {
    #[error(transparent)]
    Grid(LogError),
    #[error(transparent)]
    Spec(#[from] SourceError),
    #[error(transparent)]
    Derivation(#[from] DerivationFailed),
    #[error(transparent)]
    Model(#[from] ModelError),
    /// The crossing on the believed parameters (the grid's own errors name
    /// it; the rest are the spec's, named by its path).
    #[error("{}", drive_error(.spec, .error))]
    Drive { spec: String, error: NavigateError },
    #[error(transparent)]
    Squares(LogError),
    #[error(transparent)]
    Calibration(#[from] MethodError),
    #[error(transparent)]
    CalibratedDrive(NavigateError),
}

fn drive_error(spec: &str, e: &NavigateError) -> String {
    match e {
        NavigateError::CellTooLarge { .. } => e.to_string(),
        _ => format!("{spec}: {e}"),
    }
}

/// Fly `mission`, deriving its spec through `deriver`.
pub fn navigate_files(mission: &Mission, deriver: &dyn Deriver) -> Result<Navigated, MissionError> {
    let grid = Grid::read(mission.grid, mission.cell).map_err(MissionError::Grid)?;
    let model = Model::load(mission.spec)?;
    let ir = deriver.derive(&model, &mission.spec.display().to_string())?;
    let sets = parse_sets(mission.sets)?;
    let belief = Runner::new(ir.clone(), &[])?;
    let truth = Runner::new(ir, &sets)?;
    let before =
        drive(&grid, &belief, &truth, &mission.options).map_err(|error| MissionError::Drive {
            spec: mission.spec.display().to_string(),
            error,
        })?;
    let calibrated = match mission.calibrate {
        Some(method) => {
            let (p, note) = calibrate(method, &belief, &truth)?;
            let mut odometry = belief.clone();
            odometry.p = p;
            let drive = drive(&grid, &odometry, &truth, &mission.options)
                .map_err(MissionError::CalibratedDrive)?;
            Some(CalibratedDrive {
                method: method.name().to_string(),
                note,
                odometry,
                drive,
            })
        }
        None => None,
    };
    Ok(Navigated {
        grid,
        belief,
        truth,
        before,
        calibrated,
    })
}

/// Calibrate the believed parameters on 3 clockwise and 3 counter-clockwise
/// simulated 1 m squares of the real robot.
fn calibrate(
    m: &dyn Method,
    belief: &Runner,
    truth: &Runner,
) -> Result<(Vec<f64>, String), MissionError> {
    let mut runs = Vec::new();
    for (k, traj) in [Trajectory::SquareCw, Trajectory::SquareCcw]
        .into_iter()
        .cycle()
        .take(6)
        .enumerate()
    {
        let o = SimOptions {
            trajectory: traj,
            seed: 100 + k as u64,
            ..SimOptions::default()
        };
        // the real robot drives the squares (its commands from its true
        // geometry, as a robot's own controller would close them); the log is
        // its encoders and the tracker, read with the believed model
        let sim = simulate(truth, truth, &o);
        runs.push(
            sim.to_run(belief, &format!("square-{k}"))
                .map_err(MissionError::Squares)?,
        );
    }
    let fo = crate::estimation::fit::FitOptions::default();
    let c = m.calibrate(belief, &runs, &Settings::defaults(&fo))?;
    Ok((c.p, c.note))
}
