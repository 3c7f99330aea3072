//! `Model.simulate`: a simulated log of the spec's robot (with hidden
//! effects and true parameter values of the caller's), one call to the
//! library entry `kinegen simulate` calls.
use crate::analysis::sets_of;
use crate::errors::{self, usage};
use crate::model::PyModel;
use kinegen_analysis::applications::simulate::{SimOptions, Trajectory};
use kinegen_analysis::applications::simulate_request::{
    simulate_files, SimulateError, SimulateRequest, Simulated,
};
use kinegen_analysis::model_on_log::derivation::AutodiffDeriver;
use numpy::PyArray2;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::PathBuf;

/// A simulated log: its columns (the contract's: t, the inputs, the motion
/// capture's x, y, theta, the gyro) as an (N, k) array, and the landmark
/// sightings when a map was given.
#[pyclass(module = "kinegen", name = "Simulation", frozen)]
pub struct PySimulation {
    sim: Simulated,
}

#[pymethods]
impl PySimulation {
    /// The column names, in the order of `data`'s columns.
    #[getter]
    fn columns(&self) -> Vec<String> {
        self.sim.log.header.clone()
    }

    /// The log's rows, (N, k).
    #[getter]
    fn data<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        PyArray2::from_vec2(py, &self.sim.log.rows).map_err(Into::into)
    }

    /// The sightings (t, landmark id, range, bearing), in time order.
    #[getter]
    fn observations(&self) -> Vec<(f64, String, f64, f64)> {
        self.sim.log.observations.clone()
    }

    /// Write the log as CSV to `path` (and the sightings to `observations`),
    /// as `kinegen simulate --out` writes them; `kinegen.read_log` reads it.
    #[pyo3(signature = (path, observations = None))]
    fn write(&self, path: PathBuf, observations: Option<PathBuf>) -> PyResult<()> {
        // (a write error names its file)
        let written = |e: kinegen_model::files::WriteError| usage(e.to_string());
        kinegen_model::files::write_atomic(&path, &self.sim.csv()).map_err(written)?;
        if let Some(o) = observations {
            kinegen_model::files::write_atomic(&o, &self.sim.observations_csv())
                .map_err(written)?;
        }
        Ok(())
    }

    fn __len__(&self) -> usize {
        self.sim.log.rows.len()
    }

    fn __repr__(&self) -> String {
        let rows = &self.sim.log.rows;
        format!(
            "Simulation({} rows, {:.1} s, {} sightings)",
            rows.len(),
            rows.last().map_or(0.0, |r| r[0]),
            self.sim.log.observations.len()
        )
    }
}

#[pymethods]
impl PyModel {
    /// Simulate the robot this spec describes driving `trajectory` (square,
    /// figure8, random, spin, beacons ...; see `kinegen simulate --help`):
    /// `effects` maps hidden effects the simulated robot has beyond the spec
    /// (`"lateral_slip"` or `"effect.param"`) to their values, `sets` its
    /// parameters' true values; `landmarks`, a map (id,x,y) to sight with the
    /// spec's `landmark` observation.
    #[pyo3(signature = (trajectory = "square", seed = 1, laps = 1, effects = None, landmarks = None, **sets))]
    #[allow(clippy::too_many_arguments)] // Python's keyword arguments
    fn simulate(
        &self,
        py: Python<'_>,
        trajectory: &str,
        seed: u64,
        laps: usize,
        effects: Option<&Bound<'_, PyDict>>,
        landmarks: Option<PathBuf>,
        sets: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<PySimulation> {
        let trajectory: Trajectory = trajectory
            .parse()
            .map_err(|e| usage(format!("trajectory: {e}")))?;
        let (effects, sets) = (sets_of(effects)?, sets_of(sets)?);
        let request = SimulateRequest {
            spec: &self.path,
            effects: &effects,
            sets: &sets,
            effect_dirs: &[],
            landmarks: landmarks.as_deref(),
            options: SimOptions {
                trajectory,
                seed,
                laps,
                ..SimOptions::default()
            },
        };
        match py.allow_threads(|| simulate_files(&request, &AutodiffDeriver)) {
            Ok(sim) => Ok(PySimulation { sim }),
            Err(SimulateError::Spec(e)) => Err(errors::spec(&e)),
            Err(SimulateError::Map(e)) => Err(errors::log(&e)),
            // the keyword arguments' own names, not the command line's options
            Err(SimulateError::NoLaps) => Err(usage("laps=0: at least one lap")),
            Err(SimulateError::TooLong { laps, rows, max }) => Err(usage(format!(
                "laps={laps}: {rows:.3e} rows, more than the {max:.0e} a simulation makes"
            ))),
            Err(SimulateError::EffectTwice { first, again }) => Err(usage(format!(
                "effects: {again} repeats {first}; give each effect once"
            ))),
            Err(SimulateError::BeaconsWithoutMap) => Err(usage(
                "trajectory=\"beacons\" tours the landmarks of landmarks=\"map.csv\"",
            )),
            Err(e) => Err(usage(e.to_string())),
        }
    }
}
