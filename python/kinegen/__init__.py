"""kinegen: wheeled-robot kinematic models in Python.

Declare a model once in a spec file, then compare it with logged data,
calibrate it, find which physical effect it is missing, and run its kernels
over NumPy arrays. The same library as the ``kinegen`` command line (no
symbolica: the spec is differentiated in-process).

    >>> import kinegen
    >>> m = kinegen.Model.from_file("spec/diff_drive.toml")
    >>> log = kinegen.read_log("run.csv", m)
    >>> m.compare(log).position_rmse
    >>> f = m.fit([log]); f.parameters["b"].estimate, f.parameters["b"].std
    >>> d = m.diagnose([log]); d.verdict.effect, d.verdict.proposed
    >>> m.localize(kinegen.read_log("run.csv", m, observations="obs.csv", landmarks="map.csv")).track

Errors are ``kinegen.Error`` subclasses (``SpecError``, ``LogError``,
``UsageError``, ``AnalysisError``) carrying ``file``, ``line`` and ``column``.
"""
from ._kinegen import (  # noqa: F401
    AnalysisError,
    Comparison,
    Diagnosis,
    Error,
    Errors,
    Estimate,
    Fit,
    Input,
    Localization,
    Log,
    LogError,
    Model,
    Parameter,
    RunLocalization,
    Simulation,
    SpecError,
    UsageError,
    Verdict,
    read_log,
)

__all__ = [
    "Model", "Parameter", "Input", "Log", "read_log", "Comparison", "Errors", "Fit", "Estimate",
    "Diagnosis", "Verdict", "Localization", "RunLocalization", "Simulation", "Error", "SpecError", "LogError", "UsageError", "AnalysisError",
]
