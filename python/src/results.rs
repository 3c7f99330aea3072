//! What `Model.fit` and `Model.diagnose` return: typed figures, NumPy
//! arrays, and `to_json()`.
use kinegen_analysis::diagnosis::document::diagnose_document;
use kinegen_analysis::diagnosis::next_steps::{Invocation, NextSteps};
use kinegen_analysis::diagnosis::request::Diagnosed;
use kinegen_analysis::estimation::fit::FitOptions;
use kinegen_analysis::estimation::fit_document::calibration_document;
use kinegen_analysis::estimation::fit_job::Calibrated;
use kinegen_analysis::model_on_log::load::{Loaded, Sources};
use kinegen_analysis::model_on_log::metrics::Errors;
use numpy::PyArray2;
use pyo3::prelude::*;
use std::collections::BTreeMap;

/// The error figures of one evaluation (position in m, heading in rad).
#[pyclass(module = "kinegen", name = "Errors", frozen, get_all)]
#[derive(Clone)]
pub struct PyErrors {
    pub position_rmse: f64,
    pub heading_rmse: f64,
    pub final_error: f64,
    pub final_heading_error: f64,
    pub max_error: f64,
}

impl From<&Errors> for PyErrors {
    fn from(e: &Errors) -> Self {
        PyErrors {
            position_rmse: e.rmse,
            heading_rmse: e.heading_rmse_rad,
            final_error: e.final_position_error_m,
            final_heading_error: e.final_heading_error_rad,
            max_error: e.max_position_error_m,
        }
    }
}

#[pymethods]
impl PyErrors {
    fn __repr__(&self) -> String {
        format!(
            "Errors(position_rmse={:.4} m, final_error={:.4} m)",
            self.position_rmse, self.final_error
        )
    }
}

/// A calibrated parameter: its nominal value, estimate and standard deviation
/// (None: the logs do not determine it).
#[pyclass(module = "kinegen", name = "Estimate", frozen, get_all)]
#[derive(Clone)]
pub struct PyEstimate {
    pub nominal: f64,
    pub estimate: f64,
    pub std: Option<f64>,
}

#[pymethods]
impl PyEstimate {
    fn __repr__(&self) -> String {
        match self.std {
            Some(s) => format!(
                "Estimate({} ± {}, nominal {})",
                self.estimate, s, self.nominal
            ),
            None => format!(
                "Estimate({}, not determined, nominal {})",
                self.estimate, self.nominal
            ),
        }
    }
}

/// `Model.fit`: the calibration, before and after.
#[pyclass(module = "kinegen", name = "Fit", frozen)]
pub struct PyFit {
    #[pyo3(get)]
    before: PyErrors,
    #[pyo3(get)]
    after: PyErrors,
    #[pyo3(get)]
    parameters: BTreeMap<String, PyEstimate>,
    /// Names of the calibrated parameters, the order of `covariance`.
    #[pyo3(get)]
    free: Vec<String>,
    covariance: Vec<Vec<f64>>,
    #[pyo3(get)]
    warnings: Vec<String>,
    json: String,
}

impl PyFit {
    pub fn new(prep: &Loaded, cal: &Calibrated, options: &FitOptions) -> PyFit {
        let r = &prep.runner;
        let res = &cal.fit;
        let std: Vec<Option<f64>> = (0..res.free.len())
            .map(|k| res.std.get(k).copied().filter(|s| s.is_finite()))
            .collect();
        let parameters = res
            .free
            .iter()
            .enumerate()
            .map(|(k, &i)| {
                (
                    r.names[i].clone(),
                    PyEstimate {
                        nominal: r.p[i],
                        estimate: res.p[i],
                        std: std[k],
                    },
                )
            })
            .collect();
        let n = res.free.len();
        let covariance = (0..n)
            .map(|a| {
                (0..n)
                    .map(|b| {
                        std[a].unwrap_or(f64::NAN) * std[b].unwrap_or(f64::NAN) * res.corr[(a, b)]
                    })
                    .collect()
            })
            .collect();
        let doc = calibration_document(prep, cal, options);
        PyFit {
            before: (&cal.before.errors).into(),
            after: (&cal.after.errors).into(),
            parameters,
            free: res.free.iter().map(|&i| r.names[i].clone()).collect(),
            covariance,
            warnings: res.warnings.clone(),
            json: doc.to_string(),
        }
    }
}

#[pymethods]
impl PyFit {
    /// The covariance of the calibrated parameters (order: `free`).
    #[getter]
    fn covariance<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        Ok(PyArray2::from_vec2(py, &self.covariance)?)
    }

    /// The calibration's JSON document: `kinegen fit --json`'s, built by the
    /// same library function.
    fn to_json(&self) -> String {
        self.json.clone()
    }

    fn __repr__(&self) -> String {
        format!(
            "Fit(position RMSE {:.4} -> {:.4} m, {} parameters)",
            self.before.position_rmse,
            self.after.position_rmse,
            self.free.len()
        )
    }
}

/// `Model.diagnose`'s verdict.
#[pyclass(module = "kinegen", name = "Verdict", frozen)]
pub struct PyVerdict {
    /// The first effect found (None: no catalogue effect is significant).
    #[pyo3(get)]
    effect: Option<String>,
    #[pyo3(get)]
    unexplained_structure: bool,
    effects: String,
    proposed: String,
    /// The `kinegen add-effect` commands that add the effects found, in
    /// order (the command line's `verdict.apply`).
    #[pyo3(get)]
    apply: Vec<String>,
}

#[pymethods]
impl PyVerdict {
    /// Every effect found, in order: dicts of effect, parameters, rmse_after.
    #[getter]
    fn effects<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        loads(py, &self.effects)
    }

    /// Corrections beyond the catalogue (dicts of name, toml, terms,
    /// parameters, held_out_before, held_out_after); empty when none.
    #[getter]
    fn proposed<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        loads(py, &self.proposed)
    }

    fn __repr__(&self) -> String {
        format!(
            "Verdict(effect={:?}, unexplained_structure={})",
            self.effect, self.unexplained_structure
        )
    }
}

fn loads<'py>(py: Python<'py>, text: &str) -> PyResult<Bound<'py, PyAny>> {
    py.import("json")?.call_method1("loads", (text,))
}

/// `Model.diagnose`: which effect is missing.
#[pyclass(module = "kinegen", name = "Diagnosis", frozen)]
pub struct PyDiagnosis {
    #[pyo3(get)]
    verdict: Py<PyVerdict>,
    #[pyo3(get)]
    baseline_error: f64,
    #[pyo3(get)]
    calibrated_error: f64,
    candidates: String,
    json: String,
}

impl PyDiagnosis {
    /// The diagnosis `done` of the logs `sources` names.
    pub fn new(py: Python<'_>, done: &Diagnosed, sources: &Sources) -> PyResult<PyDiagnosis> {
        let d = &done.outcome.diagnosis;
        let r = &done.loaded.runner;
        let steps = NextSteps::of(d, &r.ir.name, &Invocation::of(sources, &[]));
        let verdict = PyVerdict {
            effect: d.verdict().map(str::to_string),
            unexplained_structure: d.structure.structured,
            effects: serde_json::to_string(&d.chain).expect("serialises"),
            proposed: serde_json::to_string(&d.proposed).expect("serialises"),
            apply: steps.apply.clone(),
        };
        Ok(PyDiagnosis {
            verdict: Py::new(py, verdict)?,
            baseline_error: d.baseline_rmse,
            calibrated_error: d.calibrated_rmse,
            candidates: serde_json::to_string(&d.candidates).expect("serialises"),
            json: diagnose_document(done, &steps).to_string(),
        })
    }
}

#[pymethods]
impl PyDiagnosis {
    /// The effects tested, most likely first (dicts as in the JSON document).
    #[getter]
    fn candidates<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        loads(py, &self.candidates)
    }

    /// The diagnosis's JSON document: `kinegen diagnose --json`'s, built by
    /// the same library function (its timing is this call's).
    fn to_json(&self) -> String {
        self.json.clone()
    }
}
