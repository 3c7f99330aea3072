//! Logs and the analysis: `kinegen.read_log`, `Model.compare`, `Model.fit`,
//! `Model.diagnose`, each one call to the library entry the command line
//! calls (same deriver, same default options), so the figures are the
//! command line's for the same inputs.
use crate::errors::{self, usage};
use crate::model::PyModel;
use crate::results::PyErrors;
use kinegen_analysis::diagnosis::diagnose_job::Hooks;
use kinegen_analysis::diagnosis::request::{diagnose_files, Request, RequestError};
use kinegen_analysis::estimation::fit::FitOptions;
use kinegen_analysis::estimation::fit_request::{
    fit_files, FitHooks, FitRequest, FitRequestError, Fitted,
};
use kinegen_analysis::model_on_log::comparison::compare_files;
use kinegen_analysis::model_on_log::derivation::AutodiffDeriver;
use kinegen_analysis::model_on_log::files::Files;
use kinegen_analysis::model_on_log::load::{load, Sources};
use kinegen_analysis::model_on_log::track_rows::TrackRows;
use numpy::{IntoPyArray, PyArray1, PyArray2, PyArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::{Path, PathBuf};

/// A log as read for a model: where it is (a CSV, or a bag with its topic
/// mapping), its range-bearing files, and its columns as arrays.
#[pyclass(module = "kinegen", name = "Log", frozen)]
pub struct PyLog {
    pub path: PathBuf,
    pub topics: Option<PathBuf>,
    pub observations: Option<PathBuf>,
    pub landmarks: Option<PathBuf>,
    t: Vec<f64>,
    inputs: Vec<Vec<f64>>,
    input_names: Vec<String>,
    gt: Option<Vec<[f64; 3]>>,
}

pub(crate) fn no_progress(_: &Path) -> Box<dyn Fn(usize, usize)> {
    Box::new(|_, _| {})
}

pub(crate) fn sources(m: &PyModel, logs: &[PyRef<PyLog>], sets: Vec<String>) -> PyResult<Sources> {
    let first = logs.first().ok_or_else(|| usage("no log given"))?;
    if logs
        .iter()
        .any(|l| l.topics != first.topics || l.landmarks != first.landmarks)
    {
        return Err(usage(
            "the logs of one call share their topic mapping and landmark map",
        ));
    }
    let with_obs = logs.iter().filter(|l| l.observations.is_some()).count();
    if with_obs != 0 && with_obs != logs.len() {
        return Err(usage(
            "either every log has range-bearing observations or none has",
        ));
    }
    Ok(Sources {
        spec: m.path.clone(),
        data: logs.iter().map(|l| l.path.clone()).collect(),
        holdout: Vec::new(),
        sets,
        topics: first.topics.clone(),
        observations: logs.iter().filter_map(|l| l.observations.clone()).collect(),
        landmarks: first.landmarks.clone(),
        max_gap: 3.0,
        truth_scores_only: false,
    })
}

pub(crate) fn sets_of(sets: Option<&Bound<'_, PyDict>>) -> PyResult<Vec<String>> {
    let mut out = Vec::new();
    if let Some(d) = sets {
        for (k, v) in d.iter() {
            out.push(format!(
                "{}={}",
                k.extract::<String>()?,
                v.extract::<f64>()?
            ));
        }
    }
    Ok(out)
}

/// Fixed-width rows (poses, pairs) as an (N, W) array; (0, W) when empty.
pub(crate) fn rows_array<'py, const W: usize>(
    py: Python<'py>,
    rows: &[[f64; W]],
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let flat: Vec<f64> = rows.iter().flatten().copied().collect();
    flat.into_pyarray(py).reshape([rows.len(), W])
}

/// One log or a list of logs, as Python gives them.
pub(crate) fn logs_of<'py>(logs: &Bound<'py, PyAny>) -> PyResult<Vec<PyRef<'py, PyLog>>> {
    if let Ok(one) = logs.extract::<PyRef<PyLog>>() {
        return Ok(vec![one]);
    }
    logs.extract::<Vec<PyRef<PyLog>>>()
        .map_err(|_| usage("expected a kinegen.Log or a list of them (kinegen.read_log)"))
}

/// Read a log (CSV, or a ROS 2 bag `.mcap` with `topics`, a mapping file)
/// for `model`; `observations` and `landmarks` are range-bearing files.
/// Errors are `kinegen.LogError` with file, line (row) and column.
#[pyfunction]
#[pyo3(signature = (path, model, topics = None, observations = None, landmarks = None))]
pub fn read_log(
    path: PathBuf,
    model: &PyModel,
    topics: Option<PathBuf>,
    observations: Option<PathBuf>,
    landmarks: Option<PathBuf>,
) -> PyResult<PyLog> {
    let src = Sources {
        spec: model.path.clone(),
        data: vec![path.clone()],
        holdout: Vec::new(),
        sets: Vec::new(),
        topics: topics.clone(),
        observations: observations.iter().cloned().collect(),
        landmarks: landmarks.clone(),
        max_gap: f64::INFINITY,
        truth_scores_only: true,
    };
    let loaded = load(model.runner.ir.clone(), &src, &no_progress)
        .map_err(|e| errors::files(&kinegen_analysis::model_on_log::files::FilesError::Load(e)))?;
    let run = loaded
        .runs
        .first()
        .ok_or_else(|| usage(format!("{}: no run of 3 rows or more", path.display())))?;
    let inputs = (0..model.runner.ir.inputs.len())
        .map(|k| run.u.iter().map(|row| row[k]).collect())
        .collect();
    Ok(PyLog {
        t: run.t.to_vec(),
        gt: run.gt.as_ref().map(|g| g.to_vec()),
        inputs,
        input_names: model
            .runner
            .ir
            .inputs
            .iter()
            .map(|i| i.name.clone())
            .collect(),
        path,
        topics,
        observations,
        landmarks,
    })
}

#[pymethods]
impl PyLog {
    /// Time stamps (s), from the first row.
    #[getter]
    fn t<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        self.t.clone().into_pyarray(py)
    }

    /// Inputs as the model reads them over each step (row k to row k+1: a
    /// cumulative column's rate, an absolute one's mid-step value): (N-1, inputs).
    #[getter]
    fn u<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let steps = self.inputs.first().map_or(0, Vec::len);
        let rows: Vec<Vec<f64>> = (0..steps)
            .map(|i| self.inputs.iter().map(|c| c[i]).collect())
            .collect();
        Ok(PyArray2::from_vec2(py, &rows)?)
    }

    /// The ground-truth pose (N, 3), or None.
    #[getter]
    fn ground_truth<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyArray2<f64>>>> {
        self.gt.as_ref().map(|g| rows_array(py, g)).transpose()
    }

    /// The log as a pandas DataFrame (t, the inputs, gt_x, gt_y, gt_theta), when pandas is installed.
    fn to_pandas<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let pd = py
            .import("pandas")
            .map_err(|_| usage("to_pandas needs pandas (pip install pandas)"))?;
        let d = PyDict::new(py);
        d.set_item("t", self.t.clone().into_pyarray(py))?;
        for (name, col) in self.input_names.iter().zip(&self.inputs) {
            // a step's input on the row it starts from; the last row has none
            let mut c = col.clone();
            c.push(f64::NAN);
            d.set_item(name, c.into_pyarray(py))?;
        }
        if let Some(g) = &self.gt {
            for (k, c) in ["gt_x", "gt_y", "gt_theta"].iter().enumerate() {
                d.set_item(
                    *c,
                    g.iter()
                        .map(|p| p[k])
                        .collect::<Vec<f64>>()
                        .into_pyarray(py),
                )?;
            }
        }
        pd.call_method1("DataFrame", (d,))
    }

    fn __len__(&self) -> usize {
        self.t.len()
    }

    fn __repr__(&self) -> String {
        format!("Log({}, {} rows)", self.path.display(), self.t.len())
    }
}

/// `Model.compare`: the model with its parameters against the logs.
#[pyclass(module = "kinegen", name = "Comparison", frozen)]
pub struct PyComparison {
    #[pyo3(get)]
    errors: PyErrors,
    tracks: Vec<Vec<[f64; 3]>>,
    json: String,
}

#[pymethods]
impl PyComparison {
    /// Position RMSE against the ground truth (m).
    #[getter]
    fn position_rmse(&self) -> f64 {
        self.errors.position_rmse
    }

    /// The dead-reckoned track of the first log (N, 3: x, y, theta).
    #[getter]
    fn track<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        rows_array(py, &self.tracks[0])
    }

    /// Every log's track, in order.
    #[getter]
    fn tracks<'py>(&self, py: Python<'py>) -> PyResult<Vec<Bound<'py, PyArray2<f64>>>> {
        self.tracks.iter().map(|t| rows_array(py, t)).collect()
    }

    /// The document `kinegen compare --json` writes for the same inputs.
    fn to_json(&self) -> String {
        self.json.clone()
    }
}

#[pymethods]
impl PyModel {
    /// Run the model with its nominal parameters (`sets`: name=value
    /// overrides) against one log or a list of them.
    #[pyo3(signature = (logs, **sets))]
    fn compare(
        &self,
        logs: &Bound<'_, PyAny>,
        sets: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<PyComparison> {
        let logs = logs_of(logs)?;
        let src = sources(self, &logs, sets_of(sets)?)?;
        let files = Files {
            sources: &src,
            effect_dirs: &[],
        };
        compare_files(&files, &AutodiffDeriver, &no_progress, |done| {
            let json = serde_json::to_string(&done.document()).expect("the comparison serialises");
            let cmp = &done.comparison;
            let tracks = cmp
                .tracks
                .iter()
                .zip(&cmp.runs)
                .map(|(t, run)| t.rows(run).map(|r| r.pose).collect())
                .collect();
            PyComparison {
                errors: (&cmp.errors).into(),
                tracks,
                json,
            }
        })
        .map_err(|e| errors::files(&e))
    }

    /// Calibrate the spec's free parameters on the logs (Levenberg-Marquardt,
    /// `kinegen fit`'s defaults); `holdout`: logs to score it on, not fitted.
    #[pyo3(signature = (logs, holdout = None, **sets))]
    fn fit(
        &self,
        logs: &Bound<'_, PyAny>,
        holdout: Option<&Bound<'_, PyAny>>,
        sets: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<crate::results::PyFit> {
        let logs = logs_of(logs)?;
        let mut src = sources(self, &logs, sets_of(sets)?)?;
        if let Some(h) = holdout {
            src.holdout = logs_of(h)?.iter().map(|l| l.path.clone()).collect();
        }
        let files = Files {
            sources: &src,
            effect_dirs: &[],
        };
        let fo = FitOptions::command_default();
        let request = FitRequest::Calibrate {
            options: &fo,
            truth: &[],
        };
        let hooks = FitHooks {
            loaded: &|_| {},
            method: &|_| {},
        };
        let made = fit_files(
            &files,
            &request,
            &AutodiffDeriver,
            &no_progress,
            &hooks,
            |prep, fitted| match fitted {
                Fitted::Calibrated(cal) => Ok(crate::results::PyFit::new(prep, &cal, &fo)),
                Fitted::Methods(_) => Err(usage("a method comparison is not a calibration")),
            },
        );
        match made {
            Ok(r) => r,
            Err(FitRequestError::Files(e)) => Err(errors::files(&e)),
            Err(e) => Err(errors::analysis(e)),
        }
    }

    /// Calibrate, then test each applicable effect of the catalogue: which
    /// one is missing, and beyond it a proposed correction.
    #[pyo3(signature = (logs, **sets))]
    fn diagnose(
        &self,
        py: Python<'_>,
        logs: &Bound<'_, PyAny>,
        sets: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<crate::results::PyDiagnosis> {
        let logs = logs_of(logs)?;
        let src = sources(self, &logs, sets_of(sets)?)?;
        let req = Request {
            files: Files {
                sources: &src,
                effect_dirs: &[],
            },
            for_report: false,
        };
        let done = diagnose_files(&req, &AutodiffDeriver, &no_progress, &Hooks::none());
        match done {
            Ok(d) => crate::results::PyDiagnosis::new(py, &d, &src),
            Err(RequestError::Files(e)) => Err(errors::files(&e)),
            Err(e) => Err(errors::analysis(e)),
        }
    }
}
