"""Type stubs of kinegen's extension module (re-exported by `kinegen`)."""
from typing import Any, Optional, Sequence, Union

import numpy as np
import numpy.typing as npt

ArrayLike = npt.ArrayLike

class Error(Exception):
    """Anything kinegen refuses; where it is, when it has a place."""
    file: Optional[str]
    line: Optional[int]
    column: Optional[str]

class SpecError(Error): ...
class LogError(Error): ...
class UsageError(Error): ...
class AnalysisError(Error): ...

class Parameter:
    name: str
    nominal: float
    min: Optional[float]
    max: Optional[float]
    unit: str
    doc: str
    free: bool

class Input:
    name: str
    column: str
    kind: str
    unit: str
    doc: str

class Errors:
    position_rmse: float
    heading_rmse: float
    final_error: float
    final_heading_error: float
    max_error: float

class Log:
    t: np.ndarray
    """Time stamps (s), from the first row: (N,)."""
    u: np.ndarray
    """Inputs over each step (row k to k+1): (N-1, inputs)."""
    ground_truth: Optional[np.ndarray]
    """Ground-truth pose (N, 3), or None."""
    def to_pandas(self) -> Any: ...
    def __len__(self) -> int: ...

class Comparison:
    errors: Errors
    position_rmse: float
    track: np.ndarray
    """The first log's dead-reckoned track (N, 3)."""
    tracks: list[np.ndarray]
    def to_json(self) -> str:
        """The document `kinegen compare --json` writes for the same inputs."""

class RunLocalization:
    path: str
    position_rmse: Optional[float]
    """Against the ground truth (m); None without one."""
    dead_reckoning_rmse: Optional[float]
    nis_mean: Optional[float]
    nees_mean: Optional[float]
    sightings_used: int
    sightings_rejected: int
    track: np.ndarray
    """The filter's pose (x, y, theta) at every row, (N, 3)."""
    covariance: np.ndarray
    """Its covariance at every row, (N, 3, 3)."""
    innovations: np.ndarray
    """Time (s) and NIS of each accepted sighting, (M, 2)."""

class Localization:
    runs: list[RunLocalization]
    noise_source: str
    position_rmse: Optional[float]
    track: np.ndarray
    covariance: np.ndarray
    def to_json(self) -> str:
        """The document `kinegen localize --json` writes for the same inputs."""

class Simulation:
    columns: list[str]
    data: np.ndarray
    """The log's rows, (N, len(columns))."""
    observations: list[tuple[float, str, float, float]]
    def write(self, path: str, observations: Optional[str] = None) -> None:
        """Write the log (and the sightings) as `kinegen simulate` writes them."""
    def __len__(self) -> int: ...

class Estimate:
    nominal: float
    estimate: float
    std: Optional[float]

class Fit:
    before: Errors
    after: Errors
    parameters: dict[str, Estimate]
    free: list[str]
    covariance: np.ndarray
    warnings: list[str]
    def to_json(self) -> str: ...

class Verdict:
    effect: Optional[str]
    effects: list[dict[str, Any]]
    proposed: list[dict[str, Any]]
    unexplained_structure: bool
    apply: list[str]

class Diagnosis:
    verdict: Verdict
    baseline_error: float
    calibrated_error: float
    candidates: list[dict[str, Any]]
    def to_json(self) -> str: ...

Logs = Union[Log, Sequence[Log]]

class Model:
    @staticmethod
    def from_file(path: str) -> "Model":
        """Read a spec file (TOML); errors are SpecError with file, line and column."""
    @staticmethod
    def from_str(text: str, name: str = "<string>") -> "Model": ...
    name: str
    states: list[str]
    inputs: list[Input]
    parameters: list[Parameter]
    def nominal_parameters(self) -> np.ndarray: ...
    def with_effect(self, name: str, **values: float) -> "Model":
        """This model with a catalogue effect added, e.g. with_effect("lateral_slip", k_slip=0.05)."""
    def step(self, x: ArrayLike, u: ArrayLike, dt: Union[float, ArrayLike], p: Optional[ArrayLike] = None, exact: bool = True) -> np.ndarray:
        """One step for every row: x (N, 3), u (N, inputs), dt scalar or (N,), p (parameters,) or (N, parameters) -> (N, 3)."""
    def step_jac_x(self, x: ArrayLike, u: ArrayLike, dt: Union[float, ArrayLike], p: Optional[ArrayLike] = None, exact: bool = True) -> np.ndarray:
        """(N, 3, 3)"""
    def step_jac_u(self, x: ArrayLike, u: ArrayLike, dt: Union[float, ArrayLike], p: Optional[ArrayLike] = None, exact: bool = True) -> np.ndarray:
        """(N, 3, inputs)"""
    def step_jac_p(self, x: ArrayLike, u: ArrayLike, dt: Union[float, ArrayLike], p: Optional[ArrayLike] = None, exact: bool = True) -> np.ndarray:
        """(N, 3, parameters)"""
    def observe(self, name: str, x: ArrayLike, u: Optional[ArrayLike] = None, p: Optional[ArrayLike] = None, landmark: Optional[ArrayLike] = None, jac_x: bool = False) -> np.ndarray:
        """The observation `name` for every row: (N, values), or with jac_x its Jacobian (N, values, 3)."""
    def compare(self, logs: Logs, **sets: float) -> Comparison:
        """The model with its nominal parameters (sets: overrides) against the logs."""
    def fit(self, logs: Logs, holdout: Optional[Logs] = None, **sets: float) -> Fit:
        """Calibrate the free parameters (Levenberg-Marquardt, `kinegen fit`'s defaults)."""
    def diagnose(self, logs: Logs, **sets: float) -> Diagnosis:
        """Which catalogue effect is missing, and beyond it a proposed correction."""
    def simulate(self, trajectory: str = "square", seed: int = 1, laps: int = 1,
                 effects: Optional[dict[str, float]] = None, landmarks: Optional[str] = None,
                 **sets: float) -> Simulation:
        """A simulated log of this robot with hidden `effects` and true parameter values `sets`."""
    def localize(self, logs: Logs, holdout: Optional[Logs] = None, gate: Optional[float] = None,
                 smooth: bool = False, spec_noise: bool = False, **noise: float) -> Localization:
        """The EKF over logs read with observations and landmarks (`kinegen localize`):
        the process noise estimated from the sightings unless `spec_noise` or `noise`
        (name=sigma) gives it."""

def read_log(path: str, model: Model, topics: Optional[str] = None, observations: Optional[str] = None, landmarks: Optional[str] = None) -> Log:
    """A CSV log, or a ROS 2 bag with its topic mapping (`topics`), read for `model`."""
