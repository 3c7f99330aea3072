//! kinegen's errors as Python exceptions: `kinegen.Error` and a subclass per
//! kind of input, each carrying `file`, `line` and `column` (None where the
//! problem has no place), as the command line's exit-2 messages name them.
use kinegen_analysis::logs::log::LogError as RustLogError;
use kinegen_analysis::model_on_log::files::FilesError;
use kinegen_analysis::model_on_log::load::LoadError;
use kinegen_model::error::SourceError;
use pyo3::create_exception;
use pyo3::exceptions::PyException;
use pyo3::prelude::*;

create_exception!(
    kinegen,
    Error,
    PyException,
    "Anything kinegen refuses; `file`, `line` and `column` say where (None when the problem has no place)."
);
create_exception!(
    kinegen,
    SpecError,
    Error,
    "A spec (or effect file) kinegen cannot read."
);
create_exception!(
    kinegen,
    LogError,
    Error,
    "A log (CSV or bag) kinegen cannot read."
);
create_exception!(
    kinegen,
    UsageError,
    Error,
    "An argument kinegen cannot use."
);
create_exception!(
    kinegen,
    AnalysisError,
    Error,
    "An analysis that could not run on these logs."
);

/// Which exception class.
#[derive(Clone, Copy)]
pub enum Kind {
    Spec,
    Log,
    Usage,
    Analysis,
}

/// An exception of `kind` with its place attached.
pub fn located(
    kind: Kind,
    message: String,
    file: Option<String>,
    line: Option<usize>,
    column: Option<String>,
) -> PyErr {
    let err = match kind {
        Kind::Spec => SpecError::new_err(message),
        Kind::Log => LogError::new_err(message),
        Kind::Usage => UsageError::new_err(message),
        Kind::Analysis => AnalysisError::new_err(message),
    };
    Python::with_gil(|py| {
        let v = err.value(py);
        let _ = v.setattr("file", file);
        let _ = v.setattr("line", line);
        let _ = v.setattr("column", column);
    });
    err
}

pub fn usage(message: impl Into<String>) -> PyErr {
    located(Kind::Usage, message.into(), None, None, None)
}

pub fn analysis(message: impl ToString) -> PyErr {
    located(Kind::Analysis, message.to_string(), None, None, None)
}

pub fn spec(e: &SourceError) -> PyErr {
    located(
        Kind::Spec,
        e.to_string(),
        Some(e.file.display().to_string()),
        e.pos.map(|p| p.line),
        e.pos.map(|p| p.column.to_string()),
    )
}

pub fn log(e: &RustLogError) -> PyErr {
    located(
        Kind::Log,
        e.to_string(),
        Some(e.file.display().to_string()),
        e.row,
        e.column.clone(),
    )
}

pub fn files(e: &FilesError) -> PyErr {
    match e {
        FilesError::Spec(s) => spec(s),
        FilesError::Load(LoadError::Log(l)) => log(l),
        FilesError::Catalogue(c) => located(
            Kind::Spec,
            c.to_string(),
            Some(c.file.display().to_string()),
            None,
            None,
        ),
        other => located(Kind::Log, other.to_string(), None, None, None),
    }
}
