//! A simulated log asked for by files and options: what `kinegen simulate`
//! and Python's `Model.simulate` call, once. The spec gives the model the
//! analysis will see; hidden effects and `sets` make the robot that drives.
use crate::applications::hidden::{with_hidden, Hidden, HiddenError, Robots};
use crate::applications::simulate::{
    planned_rows, simulate, to_csv, SimLog, SimOptions, Trajectory, MAX_ROWS,
};
use crate::logs::log::LogError;
use crate::model_on_log::derivation::Deriver;
use crate::model_on_log::landmarks::read_map;
use crate::model_on_log::model::{parse_sets, ModelError};
use kinegen_model::decl::{InputKind, ObservationRole::RangeBearing};
use kinegen_model::error::SourceError;
use kinegen_model::spec::Model;
use std::path::{Path, PathBuf};

/// What to simulate: the spec, the effects the simulated robot has beyond it
/// (`NAME=VALUE` or `NAME.PARAM=VALUE`) and its parameters' true values
/// (`NAME=VALUE`), the catalogue's extra folders, a landmark map to sight
/// (with the model's `landmark` observation), and the drive.
pub struct SimulateRequest<'a> {
    pub spec: &'a Path,
    pub effects: &'a [String],
    pub sets: &'a [String],
    pub effect_dirs: &'a [PathBuf],
    pub landmarks: Option<&'a Path>,
    /// The drive; its `landmarks` are filled from the map.
    pub options: SimOptions,
}

/// A simulated log, with which inputs count whole events (written as
/// integers).
pub struct Simulated {
    pub log: SimLog,
    pub counts: Vec<bool>,
}

impl Simulated {
    /// The log as CSV text, in the contract's columns.
    pub fn csv(&self) -> String {
        to_csv(&self.log.header, &self.log.rows, &self.counts)
    }

    /// The range-bearing sightings as CSV text (`t,id,range,bearing`).
    pub fn observations_csv(&self) -> String {
        let mut text = String::from("t,id,range,bearing\n");
        for (t, id, r, b) in &self.log.observations {
            text += &format!("{t:.9},{id},{r:.9},{b:.9}\n");
        }
        text
    }
}

/// Why a simulation could not be made.
#[derive(Debug, thiserror::Error)]
pub enum SimulateError {
    #[error(transparent)]
    Spec(#[from] SourceError),
    #[error(transparent)]
    Sets(#[from] ModelError),
    #[error(transparent)]
    Effect(#[from] HiddenError),
    #[error(transparent)]
    Map(#[from] LogError),
    #[error("--laps 0: at least one lap")]
    NoLaps,
    #[error("--laps {laps}: {rows:.3e} rows, more than the {max:.0e} a simulation makes (about 2 GB of CSV); fewer laps, or several simulations with other seeds")]
    TooLong { laps: usize, rows: f64, max: f64 },
    #[error("--effect {again}: already given (--effect {first}); give it once")]
    EffectTwice { first: String, again: String },
    #[error("{0}: the model has no `landmark` observation to simulate range-bearing data with")]
    NoLandmarkObservation(PathBuf),
    #[error("--trajectory beacons tours the landmarks of --landmarks MAP.csv (with --observations OBS.csv)")]
    BeaconsWithoutMap,
}

/// Simulate the robot the request describes.
pub fn simulate_files(
    req: &SimulateRequest,
    deriver: &dyn Deriver,
) -> Result<Simulated, SimulateError> {
    if req.options.laps == 0 {
        return Err(SimulateError::NoLaps);
    }
    let sets = parse_sets(req.sets)?;
    let spec = Model::load(req.spec)?;
    let hidden = req
        .effects
        .iter()
        .map(|e| e.parse::<Hidden>())
        .collect::<Result<Vec<_>, _>>()?;
    // one effect (and parameter) given twice is a mistake, not a choice
    for (k, h) in hidden.iter().enumerate() {
        let mut earlier = hidden[..k].iter();
        if let Some(first) = earlier.find(|f| f.effect == h.effect && f.param == h.param) {
            return Err(SimulateError::EffectTwice {
                first: first.text.clone(),
                again: h.text.clone(),
            });
        }
    }
    let Robots { spec: base, robot } =
        with_hidden(&spec, &hidden, &sets, req.effect_dirs, deriver)?;
    let mut options = req.options.clone();
    if let Some(m) = req.landmarks {
        if robot.ir.observation_kernels(RangeBearing).is_none() {
            return Err(SimulateError::NoLandmarkObservation(req.spec.to_path_buf()));
        }
        let map = read_map(m)?;
        options.landmarks = map
            .ids
            .iter()
            .map(|id| (id.clone(), map.position(id)))
            .collect();
    }
    if options.trajectory == Trajectory::Beacons && options.landmarks.is_empty() {
        return Err(SimulateError::BeaconsWithoutMap);
    }
    let rows = planned_rows(&base, &options);
    if rows > MAX_ROWS {
        let (laps, max) = (options.laps, MAX_ROWS);
        return Err(SimulateError::TooLong { laps, rows, max });
    }
    let log = simulate(&base, &robot, &options);
    let counts = robot
        .ir
        .inputs
        .iter()
        .map(|i| i.kind == InputKind::Cumulative && i.counts_events())
        .collect();
    Ok(Simulated { log, counts })
}
