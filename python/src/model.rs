//! `kinegen.Model`: a spec read and differentiated in this process (the
//! analysis's automatic differentiation, no symbolica), its declarations,
//! and its kernels over arrays of rows.
use crate::errors::{self, usage};
use kinegen_analysis::model_on_log::derivation::{AutodiffDeriver, Deriver};
use kinegen_analysis::model_on_log::model::Runner;
use kinegen_model::ir::{Function, StepForm};
use kinegen_model::spec::Model;
use numpy::{
    IntoPyArray, PyArray1, PyArrayDyn, PyArrayMethods, PyReadonlyArrayDyn, PyUntypedArrayMethods,
};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// A parameter as the spec declares it.
#[pyclass(module = "kinegen", name = "Parameter", frozen, get_all)]
#[derive(Clone)]
pub struct Parameter {
    pub name: String,
    pub nominal: f64,
    pub min: Option<f64>,
    pub max: Option<f64>,
    pub unit: String,
    pub doc: String,
    /// Calibrated by fit (True), or held at its nominal value.
    pub free: bool,
}

#[pymethods]
impl Parameter {
    fn __repr__(&self) -> String {
        format!("Parameter({} = {} {})", self.name, self.nominal, self.unit)
    }
}

/// An input (a log column) as the spec declares it.
#[pyclass(module = "kinegen", name = "Input", frozen, get_all)]
#[derive(Clone)]
pub struct Input {
    pub name: String,
    pub column: String,
    /// "cumulative" (an encoder: the log holds its running total) or "absolute".
    pub kind: String,
    pub unit: String,
    pub doc: String,
}

#[pymethods]
impl Input {
    fn __repr__(&self) -> String {
        format!(
            "Input({} <- column {}, {})",
            self.name, self.column, self.kind
        )
    }
}

/// A kinematic model from a spec.
#[pyclass(module = "kinegen", name = "Model", frozen)]
pub struct PyModel {
    pub spec: Model,
    /// The spec's file: the user's, or a temporary copy for a model made
    /// from text or with effects added (the analysis reads specs by path).
    pub path: PathBuf,
    _keep: Option<Arc<tempfile::TempDir>>,
    pub runner: Arc<Runner>,
}

impl PyModel {
    fn from_model(
        spec: Model,
        path: PathBuf,
        keep: Option<Arc<tempfile::TempDir>>,
    ) -> PyResult<PyModel> {
        let ir = AutodiffDeriver
            .derive(&spec, &path.display().to_string())
            .map_err(|e| {
                errors::located(
                    errors::Kind::Spec,
                    e.to_string(),
                    Some(path.display().to_string()),
                    None,
                    None,
                )
            })?;
        let runner = Runner::new(ir, &[]).map_err(errors::analysis)?;
        Ok(PyModel {
            spec,
            path,
            _keep: keep,
            runner: Arc::new(runner),
        })
    }

    /// A model of spec text kept in a temporary file named `name.toml`.
    fn from_text(text: &str, shown: &Path) -> PyResult<PyModel> {
        let parsed = Model::parse(shown, text).map_err(|e| errors::spec(&e))?;
        let dir = tempfile::tempdir().map_err(errors::analysis)?;
        let path = dir.path().join(format!("{}.toml", parsed.name));
        std::fs::write(&path, text).map_err(errors::analysis)?;
        let spec = Model::load(&path).map_err(|e| errors::spec(&e))?;
        PyModel::from_model(spec, path, Some(Arc::new(dir)))
    }

    fn function(&self, exact: bool, which: &str) -> PyResult<&Function> {
        let form = if exact {
            StepForm::Exact
        } else {
            StepForm::Euler
        };
        let k = self.runner.ir.step(form);
        match which {
            "value" => Ok(k.value),
            "x" => Ok(k.jac_x),
            "p" => k
                .jac_p
                .ok_or_else(|| usage("this model has no runtime parameters")),
            "u" => k.jac_u.ok_or_else(|| usage("this model has no inputs")),
            _ => unreachable!(),
        }
    }
}

/// Rows of an array: (N, width) from a (N, width) or (width,) array.
fn rows(
    a: &PyReadonlyArrayDyn<f64>,
    width: usize,
    what: &str,
) -> PyResult<(Vec<f64>, Option<usize>)> {
    let shape = a.shape().to_vec();
    let data: Vec<f64> = a.as_array().iter().copied().collect();
    match shape.as_slice() {
        [w] if *w == width => Ok((data, None)),
        [n, w] if *w == width => Ok((data, Some(*n))),
        _ => Err(usage(format!(
            "{what}: expected shape (N, {width}) or ({width},), got {shape:?}"
        ))),
    }
}

/// The number of rows of arguments given as rows (None: one row for all);
/// arguments with rows must agree.
fn common_rows(args: &[(&str, Option<usize>)]) -> PyResult<usize> {
    let n = args.iter().filter_map(|a| a.1).max().unwrap_or(1);
    match args.iter().find(|a| a.1.is_some_and(|m| m != n)) {
        Some((what, m)) => Err(usage(format!(
            "{what}: {} rows where another argument has {n}",
            m.unwrap_or(0)
        ))),
        None => Ok(n),
    }
}

/// The i-th row of a broadcast array (one row for every i when `n` is None).
fn row(data: &[f64], n: Option<usize>, width: usize, i: usize) -> &[f64] {
    match n {
        Some(_) => &data[i * width..(i + 1) * width],
        None => &data[..width],
    }
}

#[pymethods]
impl PyModel {
    /// Read a spec file (TOML). Errors are `kinegen.SpecError` with file, line and column.
    #[staticmethod]
    fn from_file(path: PathBuf) -> PyResult<PyModel> {
        let spec = Model::load(&path).map_err(|e| errors::spec(&e))?;
        PyModel::from_model(spec, path, None)
    }

    /// A spec given as text (`name` names it in errors).
    #[staticmethod]
    #[pyo3(signature = (text, name = "<string>"))]
    fn from_str(text: &str, name: &str) -> PyResult<PyModel> {
        PyModel::from_text(text, Path::new(name))
    }

    /// The model's name (the spec's `name`).
    #[getter]
    fn name(&self) -> String {
        self.spec.name.clone()
    }

    /// The state: always the planar pose ["x", "y", "theta"].
    #[getter]
    fn states(&self) -> Vec<String> {
        vec!["x".into(), "y".into(), "theta".into()]
    }

    /// The inputs, in the spec's order (the columns of `u`).
    #[getter]
    fn inputs(&self) -> Vec<Input> {
        self.spec
            .inputs
            .iter()
            .map(|i| Input {
                name: i.name.clone(),
                column: i.column.clone(),
                kind: format!("{:?}", i.kind).to_lowercase(),
                unit: i.unit.clone(),
                doc: i.doc.clone(),
            })
            .collect()
    }

    /// The runtime parameters, in the order of `p` (constants folded into the model are left out).
    #[getter]
    fn parameters(&self) -> Vec<Parameter> {
        self.runner
            .ir
            .runtime_params()
            .iter()
            .map(|p| Parameter {
                name: p.name.clone(),
                nominal: p.nominal,
                min: p.min,
                max: p.max,
                unit: p.unit.clone(),
                doc: p.doc.clone(),
                free: p.free,
            })
            .collect()
    }

    /// The nominal values as a NumPy array in the order of `parameters`.
    fn nominal_parameters<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        self.runner.p.clone().into_pyarray(py)
    }

    /// This model with a catalogue effect added (`values`: its parameters'
    /// values, else their nominal ones), e.g. `m.with_effect("lateral_slip", k_slip=0.05)`.
    #[pyo3(signature = (name, **values))]
    fn with_effect(&self, name: &str, values: Option<&Bound<'_, PyDict>>) -> PyResult<PyModel> {
        let cat = kinegen_model::effects::catalogue(&[]).map_err(|e| {
            errors::located(
                errors::Kind::Spec,
                e.to_string(),
                Some(e.file.display().to_string()),
                None,
                None,
            )
        })?;
        let eff = kinegen_model::effects::find(&cat, name).map_err(|e| usage(e.to_string()))?;
        let mut vals = Vec::new();
        if let Some(d) = values {
            for (k, v) in d.iter() {
                vals.push((k.extract::<String>()?, v.extract::<f64>()?));
            }
        }
        // checked as `kinegen add-effect` checks it: applies, values in bounds
        let added = kinegen_model::effects::added_to(&self.spec, eff, &vals)
            .map_err(|e| usage(e.to_string()))?;
        PyModel::from_text(&added.source, &self.path)
    }

    /// One step of the model for every row: x (N, 3), u (N, inputs), dt
    /// (a number or (N,)), p (parameters or (N, parameters); default the
    /// nominal values); `exact` (default) or Euler. Returns (N, 3).
    #[pyo3(signature = (x, u, dt, p = None, exact = true))]
    fn step<'py>(
        &self,
        py: Python<'py>,
        x: PyReadonlyArrayDyn<f64>,
        u: PyReadonlyArrayDyn<f64>,
        dt: &Bound<'py, PyAny>,
        p: Option<PyReadonlyArrayDyn<f64>>,
        exact: bool,
    ) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        self.over_rows(py, "value", x, u, dt, p, exact)
    }

    /// The step's Jacobian with respect to the state: (N, 3, 3).
    #[pyo3(signature = (x, u, dt, p = None, exact = true))]
    fn step_jac_x<'py>(
        &self,
        py: Python<'py>,
        x: PyReadonlyArrayDyn<f64>,
        u: PyReadonlyArrayDyn<f64>,
        dt: &Bound<'py, PyAny>,
        p: Option<PyReadonlyArrayDyn<f64>>,
        exact: bool,
    ) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        self.over_rows(py, "x", x, u, dt, p, exact)
    }

    /// The step's Jacobian with respect to the runtime parameters: (N, 3, parameters).
    #[pyo3(signature = (x, u, dt, p = None, exact = true))]
    fn step_jac_p<'py>(
        &self,
        py: Python<'py>,
        x: PyReadonlyArrayDyn<f64>,
        u: PyReadonlyArrayDyn<f64>,
        dt: &Bound<'py, PyAny>,
        p: Option<PyReadonlyArrayDyn<f64>>,
        exact: bool,
    ) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        self.over_rows(py, "p", x, u, dt, p, exact)
    }

    /// The step's Jacobian with respect to the inputs: (N, 3, inputs).
    #[pyo3(signature = (x, u, dt, p = None, exact = true))]
    fn step_jac_u<'py>(
        &self,
        py: Python<'py>,
        x: PyReadonlyArrayDyn<f64>,
        u: PyReadonlyArrayDyn<f64>,
        dt: &Bound<'py, PyAny>,
        p: Option<PyReadonlyArrayDyn<f64>>,
        exact: bool,
    ) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        self.over_rows(py, "u", x, u, dt, p, exact)
    }

    /// The observation `name` (a spec `[[observation]]`) for every row: (N,
    /// values); `jac_x=True` gives its Jacobian with respect to the state,
    /// (N, values, 3). A landmark observation takes `landmark` (N, 2) or (2,).
    #[pyo3(signature = (name, x, u = None, p = None, landmark = None, jac_x = false))]
    #[allow(clippy::too_many_arguments)]
    fn observe<'py>(
        &self,
        py: Python<'py>,
        name: &str,
        x: PyReadonlyArrayDyn<f64>,
        u: Option<PyReadonlyArrayDyn<f64>>,
        p: Option<PyReadonlyArrayDyn<f64>>,
        landmark: Option<PyReadonlyArrayDyn<f64>>,
        jac_x: bool,
    ) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        let ir = &self.runner.ir;
        let i = ir
            .observations()
            .iter()
            .position(|o| o.name == name)
            .ok_or_else(|| {
                let known: Vec<&str> = ir.observations().iter().map(|o| o.name.as_str()).collect();
                usage(format!(
                    "no observation `{name}` (the spec has: {})",
                    known.join(", ")
                ))
            })?;
        let k = ir.observation_kernels_at(i);
        let f = if jac_x { k.jac_x } else { k.value };
        let n_in = ir.inputs.len();
        let np = self.runner.p.len();
        let (xs, nx) = rows(&x, 3, "x")?;
        let (us, nu) = match &u {
            Some(u) => rows(u, n_in, "u")?,
            None => (vec![0.0; n_in], None),
        };
        let (ps, npn) = match &p {
            Some(p) => rows(p, np, "p")?,
            None => (self.runner.p.clone(), None),
        };
        let (ls, nl) = match &landmark {
            Some(l) => rows(l, 2, "landmark")?,
            None => (vec![0.0; 2], None),
        };
        let n = common_rows(&[("x", nx), ("u", nu), ("p", npn), ("landmark", nl)])?;
        let runner = self.runner.clone();
        let width = f.rows * f.cols;
        let out = py.allow_threads(|| {
            let mut out = vec![0.0; n * width];
            let mut scratch = Vec::new();
            for r in 0..n {
                let args = Runner::obs_args(
                    f,
                    row(&xs, nx, 3, r),
                    row(&us, nu, n_in, r),
                    row(&ps, npn, np, r),
                    row(&ls, nl, 2, r),
                );
                runner.eval_into(f, &args, &mut out[r * width..(r + 1) * width], &mut scratch);
            }
            out
        });
        let shape: Vec<usize> = if jac_x {
            vec![n, f.rows, f.cols]
        } else {
            vec![n, width]
        };
        out.into_pyarray(py).reshape(shape)
    }

    fn __repr__(&self) -> String {
        format!(
            "Model({}: {} inputs, {} parameters, from {})",
            self.spec.name,
            self.spec.inputs.len(),
            self.runner.p.len(),
            self.path.display()
        )
    }
}

impl PyModel {
    /// A step kernel (`which`: value, x, u, p) over the rows of its arguments,
    /// in Rust with the GIL released.
    #[allow(clippy::too_many_arguments)]
    fn over_rows<'py>(
        &self,
        py: Python<'py>,
        which: &str,
        x: PyReadonlyArrayDyn<f64>,
        u: PyReadonlyArrayDyn<f64>,
        dt: &Bound<'py, PyAny>,
        p: Option<PyReadonlyArrayDyn<f64>>,
        exact: bool,
    ) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        let f = self.function(exact, which)?;
        let n_in = self.runner.ir.inputs.len();
        let np = self.runner.p.len();
        let (xs, nx) = rows(&x, 3, "x")?;
        let (us, nu) = rows(&u, n_in, "u")?;
        let (ps, npn) = match &p {
            Some(p) => rows(p, np, "p")?,
            None => (self.runner.p.clone(), None),
        };
        let (dts, ndt) = match dt.extract::<f64>() {
            Ok(v) => (vec![v], None),
            Err(_) => {
                let a: PyReadonlyArrayDyn<f64> = dt.extract()?;
                let v: Vec<f64> = a.as_array().iter().copied().collect();
                let len = v.len();
                (v, Some(len))
            }
        };
        let n = common_rows(&[("x", nx), ("u", nu), ("p", npn), ("dt", ndt)])?;
        let runner = self.runner.clone();
        let width = f.rows * f.cols;
        let zeros = vec![0.0; 16.max(runner.ir.noise.len())];
        let out = py.allow_threads(|| {
            let mut out = vec![0.0; n * width];
            let mut scratch = Vec::new();
            for r in 0..n {
                let d = [row(&dts, ndt, 1, r)[0]];
                let args = Runner::step_args(
                    f,
                    row(&xs, nx, 3, r),
                    row(&us, nu, n_in, r),
                    row(&ps, npn, np, r),
                    &d,
                    &zeros,
                );
                runner.eval_into(f, &args, &mut out[r * width..(r + 1) * width], &mut scratch);
            }
            out
        });
        let shape: Vec<usize> = if which == "value" {
            vec![n, 3]
        } else {
            vec![n, f.rows, f.cols]
        };
        out.into_pyarray(py).reshape(shape)
    }
}
