//! `Model.localize`: the EKF over logs with landmark sightings, one call to
//! the library entry `kinegen localize` calls (same options, same noise
//! estimate), returned as NumPy series and the command line's document.
use crate::analysis::{logs_of, no_progress, rows_array, sources, PyLog};
use crate::errors::{self, usage};
use crate::model::PyModel;
use kinegen_analysis::applications::localize::{EkfOptions, NoiseSource};
use kinegen_analysis::applications::localize_document::localize_document;
use kinegen_analysis::applications::localize_request::{
    localize_files, LocalizeRequest, LocalizeRequestError,
};
use kinegen_analysis::model_on_log::derivation::AutodiffDeriver;
use kinegen_analysis::model_on_log::files::Files;
use numpy::{IntoPyArray, PyArray2, PyArray3, PyArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// One run's filter: the estimate at every row, its covariance, the
/// accepted sightings' times and normalised innovations squared, and its
/// figures (None where the log has no ground truth to score against).
#[pyclass(module = "kinegen", name = "RunLocalization", frozen)]
pub struct PyRunLocalization {
    track: Vec<[f64; 3]>,
    covariance: Vec<[[f64; 3]; 3]>,
    nis: Vec<[f64; 2]>,
    /// The run's file.
    #[pyo3(get)]
    path: String,
    /// Position RMSE against the ground truth (m).
    #[pyo3(get)]
    position_rmse: Option<f64>,
    /// Dead reckoning's position RMSE on the same rows (m).
    #[pyo3(get)]
    dead_reckoning_rmse: Option<f64>,
    /// Mean NIS of the accepted sightings (2 for a consistent filter).
    #[pyo3(get)]
    nis_mean: Option<f64>,
    /// Mean NEES at the rows with ground truth (3 for a consistent filter).
    #[pyo3(get)]
    nees_mean: Option<f64>,
    #[pyo3(get)]
    sightings_used: usize,
    #[pyo3(get)]
    sightings_rejected: usize,
}

#[pymethods]
impl PyRunLocalization {
    /// The estimated pose (x, y, theta) at every row of the log, (N, 3).
    #[getter]
    fn track<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        rows_array(py, &self.track)
    }

    /// The estimate's covariance at every row, (N, 3, 3).
    #[getter]
    fn covariance<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray3<f64>>> {
        let flat: Vec<f64> = self
            .covariance
            .iter()
            .flatten()
            .flatten()
            .copied()
            .collect();
        flat.into_pyarray(py).reshape([self.covariance.len(), 3, 3])
    }

    /// Time (s) and NIS of each accepted sighting, (M, 2).
    #[getter]
    fn innovations<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        rows_array(py, &self.nis)
    }

    fn __repr__(&self) -> String {
        match self.position_rmse {
            Some(e) => format!("RunLocalization({}: position_rmse={e:.4} m)", self.path),
            None => format!("RunLocalization({}: no ground truth)", self.path),
        }
    }
}

/// A localisation: each run's filter (training logs, then held-out ones)
/// and the document `kinegen localize --json` writes.
#[pyclass(module = "kinegen", name = "Localization", frozen)]
pub struct PyLocalization {
    #[pyo3(get)]
    runs: Vec<Py<PyRunLocalization>>,
    /// Where the noise came from, in a sentence.
    #[pyo3(get)]
    noise_source: String,
    json: String,
}

#[pymethods]
impl PyLocalization {
    /// The first run's position RMSE against the ground truth (m).
    #[getter]
    fn position_rmse(&self, py: Python<'_>) -> Option<f64> {
        self.runs.first().and_then(|r| r.borrow(py).position_rmse)
    }

    /// The first run's estimated track, (N, 3).
    #[getter]
    fn track<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        self.runs[0].borrow(py).track(py)
    }

    /// The first run's covariance at every row, (N, 3, 3).
    #[getter]
    fn covariance<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray3<f64>>> {
        self.runs[0].borrow(py).covariance(py)
    }

    /// The document `kinegen localize --json` writes for the same inputs.
    fn to_json(&self) -> String {
        self.json.clone()
    }

    fn __repr__(&self, py: Python<'_>) -> String {
        match self.position_rmse(py) {
            Some(e) => format!(
                "Localization({} run(s), position_rmse={e:.4} m)",
                self.runs.len()
            ),
            None => format!("Localization({} run(s))", self.runs.len()),
        }
    }
}

/// The filter's options as `kinegen localize` takes them.
fn options(
    gate: Option<f64>,
    smooth: bool,
    spec_noise: bool,
    noise: Option<&Bound<'_, PyDict>>,
) -> PyResult<EkfOptions> {
    let mut noise_sigma = Vec::new();
    if let Some(d) = noise {
        for (k, v) in d.iter() {
            noise_sigma.push((k.extract::<String>()?, v.extract::<f64>()?));
        }
    }
    let defaults = EkfOptions::default();
    let gate = gate.unwrap_or(defaults.gate);
    if !(gate.is_finite() && gate > 0.0) {
        return Err(usage(format!("gate={gate}: a gate is a positive NIS")));
    }
    Ok(EkfOptions {
        gate,
        noise_sigma,
        noise: if spec_noise {
            NoiseSource::Spec
        } else {
            NoiseSource::Estimate
        },
        smooth,
        ..defaults
    })
}

#[pymethods]
impl PyModel {
    /// Localise the robot with the EKF over logs read with `observations`
    /// and `landmarks` (`kinegen localize`): the process noise estimated
    /// from the sightings unless `spec_noise` (the spec's) or `noise`
    /// (name=sigma, replacing the spec's) says otherwise; `gate`: the NIS
    /// beyond which a sighting is rejected; `smooth`: also run the RTS
    /// smoother (its track is in the document).
    #[pyo3(signature = (logs, holdout = None, gate = None, smooth = false, spec_noise = false, **noise))]
    #[allow(clippy::too_many_arguments)] // Python's keyword arguments
    fn localize(
        &self,
        py: Python<'_>,
        logs: &Bound<'_, PyAny>,
        holdout: Option<&Bound<'_, PyAny>>,
        gate: Option<f64>,
        smooth: bool,
        spec_noise: bool,
        noise: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<PyLocalization> {
        let logs = logs_of(logs)?;
        let mut src = sources(self, &logs, Vec::new())?;
        if let Some(h) = holdout {
            let held: Vec<PyRef<PyLog>> = logs_of(h)?;
            src.holdout = held.iter().map(|l| l.path.clone()).collect();
        }
        let request = LocalizeRequest {
            files: Files {
                sources: &src,
                effect_dirs: &[],
            },
            options: options(gate, smooth, spec_noise, noise)?,
            sweep: false,
            for_report: false,
        };
        let done =
            py.allow_threads(|| localize_files(&request, &AutodiffDeriver, &no_progress, &|_| {}));
        let files = match done {
            Ok(f) => f,
            Err(LocalizeRequestError::Files(e)) => return Err(errors::files(&e)),
            // the keyword arguments' own names, not the command line's options
            Err(LocalizeRequestError::UnknownNoise { name, known }) => {
                let why = format!("{name}=: the spec has no [[noise]] `{name}` (it has: {known})");
                return Err(usage(why));
            }
            Err(LocalizeRequestError::NegativeNoise { name, sigma }) => {
                return Err(usage(format!(
                    "{name}={sigma}: a standard deviation is 0 or more"
                )));
            }
            Err(e) => return Err(errors::analysis(e)),
        };
        let json =
            serde_json::to_string(&localize_document(&files)).expect("the localisation serialises");
        let runs = files
            .loaded
            .runs
            .iter()
            .chain(&files.loaded.holdout)
            .zip(&files.localized.runs)
            .map(|(run, (loc, s))| {
                Py::new(
                    py,
                    PyRunLocalization {
                        track: loc.track.clone(),
                        covariance: loc
                            .cov
                            .iter()
                            .map(|c| [0, 1, 2].map(|i| [0, 1, 2].map(|j| c[(i, j)])))
                            .collect(),
                        nis: loc.nis.iter().map(|&(t, v)| [t, v]).collect(),
                        path: run.path.clone(),
                        position_rmse: s.rmse,
                        dead_reckoning_rmse: s.dead_reckoning,
                        nis_mean: s.nis,
                        nees_mean: s.nees,
                        sightings_used: loc.accepted,
                        sightings_rejected: loc.rejected,
                    },
                )
            })
            .collect::<PyResult<Vec<_>>>()?;
        Ok(PyLocalization {
            runs,
            noise_source: files.localized.note.clone(),
            json,
        })
    }
}
