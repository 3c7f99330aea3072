//! What a calibration is asked to do ([`FitOptions`], [`Likelihood`]) and
//! what it returns ([`FitResult`], [`FitError`]).
use super::WINDOW_S;
use nalgebra::{DMatrix, DVector};
use serde::Serialize;
use std::sync::Arc;

#[derive(Debug, Clone)]
pub struct FitOptions {
    pub pos_sigma: f64,
    pub heading_sigma: f64,
    pub gyro_sigma: f64,
    pub use_pose: bool,
    pub use_gyro: bool,
    pub use_landmarks: bool,
    /// Predict each landmark sighting from the run's ground-truth pose where
    /// it has one (see `residuals::SeenFrom`): the sightings then calibrate
    /// the range-bearing sensor alone. False where the ground truth is not
    /// to be used (`fit --residuals` without `pose`): they are then seen from
    /// the model's track, and calibrate the motion through it.
    pub sightings_from_truth: bool,
    pub max_iter: usize,
    /// Robust loss: residuals beyond this many sigmas count linearly instead of
    /// quadratically (Huber), so outliers (a motion-capture glitch, a wrong
    /// landmark association) do not drag the estimate. None: least squares.
    pub huber: Option<f64>,
    /// Refine each run's (segment's) start heading as a nuisance parameter: the
    /// measured start is one noisy sample, or a rest's mean, whose heading error
    /// rotates the whole track (a position error does not grow, so the position
    /// stays measured; freeing it would also let a wrong model re-centre its
    /// drift). A rest's mean is refined within its uncertainty (see
    /// `has_start_nuisance`). Estimated with the parameters, never reported as one.
    pub estimate_start: bool,
    /// Fit pose increments over windows of this many seconds instead of the
    /// absolute track: each window is dead-reckoned from its measured start and
    /// compared at its end only, so its residual depends on that window's inputs
    /// alone. Window increments are close to independent whatever drift the
    /// model leaves, and their sandwich covariance does not rely on the track's
    /// residuals being white (with every start heading refined, the absolute
    /// track's least-squares deviations matched the estimates' spread over 50
    /// simulated logs too; see analysis/tests/results/calibration.rs). None: absolute track.
    pub increments: Option<f64>,
    /// Pose residuals at the last row of each run only (see `increments`).
    pub endpoints_only: bool,
    /// Directions in parameter space (unscaled, one entry per free parameter)
    /// along which the parameters stay at their starting values: ones an
    /// earlier fit of the same data found undetermined (see [`fit_stage`]).
    pub hold: Vec<DVector<f64>>,
    /// Sub-steps per step of each run in the `runs` a fit is given (see
    /// [`deadreckon::substep_plan`]), fixed by a Levenberg-Marquardt stage for
    /// all its passes (see [`levenberg_marquardt`]). None: each pass chooses.
    pub substeps: Option<Arc<Vec<Option<Vec<u8>>>>>,
    /// Start-pose offsets a Levenberg-Marquardt stage begins from: an earlier
    /// fit's [`FitResult::starts`] on the same runs (see [`Search::From`](super::Search::From)).
    /// None, or a count that does not match the runs: the measured starts.
    pub start_offsets: Option<Arc<Vec<[f64; 3]>>>,
    /// A stage also ends when the decrease still to come, extrapolated from
    /// its last two steps (Gauss-Newton on a misspecified model converges
    /// linearly: each step gains a fixed fraction of the one before), is below
    /// this fraction of the cost. 0: only the statistical test (steps below a
    /// hundredth of a standard deviation) and round-off end it. For fits
    /// whose optimum is only a starting point ([`BASIN_TOLERANCE`]) or only
    /// compared ([`crate::diagnosis::diagnose`]'s ranking).
    pub cost_tolerance: f64,
    /// End [`fit`] on the whole runs: the search works on re-anchored
    /// [`SEGMENT_S`] segments (a long track from rough values is outside any
    /// basin), then refines from there on each run dead-reckoned from its
    /// start, as the user's odometry runs, and reports standard deviations
    /// that account for the track's drift ([`drift`]). Segments minimise
    /// something else: on a clean simulated 364 s log their optimum doubled
    /// the whole-run error (0.0015 m -> 0.0030 m) with estimates 8 reported
    /// standard deviations from the truth. What `kinegen fit` reports;
    /// diagnosis ranks candidate effects on the segments alone.
    pub whole_runs: bool,
    /// Also start the search from each positive free parameter scaled by
    /// 0.1, 0.3, 3 and 10 ([`START_FACTORS`]), and say when one of those
    /// starts found a better optimum than the starting values did. What
    /// `kinegen fit` does; diagnosis refines from a calibration already made.
    pub multi_start: bool,
}

/// What a calibration compares with the ground truth (`--likelihood`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Likelihood {
    /// Each whole run dead-reckoned from its start, found through re-anchored
    /// segments ([`FitOptions::whole_runs`]).
    Track,
    /// The re-anchored [`SEGMENT_S`] segments only (what diagnosis ranks on).
    Segments,
    /// Pose increments over [`WINDOW_S`] windows ([`FitOptions::increments`]).
    Increments,
}

impl Likelihood {
    pub const NAMES: [&'static str; 3] = ["track", "segments", "increments"];

    pub fn parse(name: &str) -> Option<Likelihood> {
        match name {
            "track" => Some(Likelihood::Track),
            "segments" => Some(Likelihood::Segments),
            "increments" => Some(Likelihood::Increments),
            _ => None,
        }
    }

    /// `o` comparing this.
    pub fn apply(self, o: FitOptions) -> FitOptions {
        FitOptions {
            whole_runs: self == Likelihood::Track,
            increments: (self == Likelihood::Increments).then_some(WINDOW_S),
            ..o
        }
    }
}

/// [`FitOptions::cost_tolerance`] of a stage that only has to reach the
/// optimum's basin for the next one (the measured-start stage of a calibration
/// with start headings): 1e-5 of the cost, where that stage spent 25 of its 59
/// passes over a diagnosis log gaining 1e-4 of it.
pub const BASIN_TOLERANCE: f64 = 1e-5;

impl FitOptions {
    /// The fixed sub-step counts of run `i`, if any.
    pub(super) fn plan(&self, i: usize) -> Option<&[u8]> {
        self.substeps.as_ref()?.get(i)?.as_deref()
    }
}

impl Default for FitOptions {
    fn default() -> Self {
        FitOptions {
            pos_sigma: 0.01,
            heading_sigma: 0.01,
            gyro_sigma: 0.01,
            use_pose: true,
            use_gyro: true,
            use_landmarks: true,
            sightings_from_truth: true,
            max_iter: 100,
            huber: None,
            estimate_start: true,
            increments: None,
            endpoints_only: false,
            hold: Vec::new(),
            substeps: None,
            start_offsets: None,
            cost_tolerance: 0.0,
            whole_runs: false,
            multi_start: false,
        }
    }
}

#[derive(Debug, Clone, Serialize)]
pub struct ParamEstimate {
    pub nominal: f64,
    pub estimate: f64,
    pub std: f64,
}

impl FitOptions {
    /// `kinegen fit`'s options when none is given: every kind of residual
    /// the logs have, least squares, several starts, the whole track's
    /// likelihood (the Python package calibrates with these too).
    pub fn command_default() -> FitOptions {
        let fo = FitOptions {
            multi_start: true,
            ..FitOptions::default()
        };
        crate::estimation::fit::Likelihood::parse("track")
            .expect("a known likelihood")
            .apply(fo)
    }
}

#[derive(Debug, Clone)]
pub struct FitResult {
    pub p: Vec<f64>,
    pub free: Vec<usize>,
    pub std: Vec<f64>,
    pub corr: DMatrix<f64>,
    pub cost_before: f64,
    pub cost_after: f64,
    pub iterations: usize,
    pub n_residuals: usize,
    pub warnings: Vec<String>,
    /// Fitted start-pose offsets of the (segmented) runs, see [`FitOptions::estimate_start`].
    pub starts: Vec<[f64; 3]>,
    /// Unit directions in parameter space (unscaled, indexed like `free`) that
    /// the data do not determine.
    pub undetermined: Vec<DVector<f64>>,
    /// What the search found on its way (a local minimum avoided): carried
    /// through later stages, and said with the warnings at the end of [`fit`].
    pub search_notes: Vec<String>,
    /// The parameters the nominal values' default prior moved, with what the
    /// data alone said ([`super::nominal_prior`]; empty before it is applied).
    pub near_nominal: Vec<HeldNearNominal>,
    /// Those of the `undetermined` directions the data do determine (their
    /// information is well above the noise) but the normal equations cannot
    /// resolve: below the round-off of a sum whose strongest direction
    /// carries 1e14 times more. Held like the others and warned about, until
    /// a later stage resolves them (see `fit::on_whole_runs`).
    pub below_round_off: Vec<BelowRoundOff>,
    /// Those of `warnings` that say two parameters are strongly correlated:
    /// a later covariance (a sandwich's) replaces exactly these.
    pub correlated: Vec<String>,
}

/// An undetermined direction of a [`FitResult`] that only round-off hides.
#[derive(Debug, Clone, PartialEq)]
pub struct BelowRoundOff {
    /// the direction, as in [`FitResult::undetermined`]
    pub direction: DVector<f64>,
    /// the parameters taking part in it (indices into `free`)
    pub params: Vec<usize>,
    /// the warning said of it, among [`FitResult::warnings`]
    pub warning: String,
}

impl FitResult {
    /// A fit of a differential drive's r_r, r_l and b (free parameters 0, 1,
    /// 2) with standard deviations `std`, uncorrelated, and `warnings`: the
    /// unit tests' fixture.
    #[cfg(test)]
    pub(super) fn of_three(std: [f64; 3], warnings: &[&str]) -> FitResult {
        FitResult {
            p: vec![0.042, 0.042, 0.2],
            free: vec![0, 1, 2],
            std: std.to_vec(),
            corr: DMatrix::identity(3, 3),
            cost_before: 2.0,
            cost_after: 1.0,
            iterations: 3,
            n_residuals: 100,
            warnings: warnings.iter().map(|w| w.to_string()).collect(),
            starts: vec![[0.0; 3]],
            undetermined: vec![],
            search_notes: vec![],
            near_nominal: vec![],
            below_round_off: vec![],
            correlated: vec![],
        }
    }

    /// This fit as the continuation of `earlier` (a fit of the same data
    /// from the same starting values): the starting cost is the earlier one's,
    /// the iterations are both fits'.
    pub(super) fn continuing(self, earlier: &FitResult) -> FitResult {
        let mut notes = earlier.search_notes.clone();
        notes.extend(
            self.search_notes
                .iter()
                .filter(|n| !notes.contains(n))
                .cloned()
                .collect::<Vec<_>>(),
        );
        FitResult {
            cost_before: earlier.cost_before,
            iterations: earlier.iterations + self.iterations,
            search_notes: notes,
            ..self
        }
    }
}

#[derive(Debug, thiserror::Error)]
pub enum FitError {
    #[error("nothing to fit: the logs have no ground truth ({pose}), no gyro ({gyro}) and no landmark observations the model can predict")]
    NoResiduals { pose: String, gyro: String },
    #[error("the fit diverged: {0}")]
    Diverged(String),
}

/// A parameter the nominal value's prior moved: what the data alone said.
#[derive(Debug, Clone, PartialEq)]
pub struct HeldNearNominal {
    /// Runtime parameter index.
    pub param: usize,
    /// The nominal value's standard deviation (absolute).
    pub tolerance: f64,
    /// The nominal value and the estimate reported.
    pub nominal: f64,
    pub estimate: f64,
    /// The fit's estimate and standard deviation from the data alone.
    pub data_estimate: f64,
    pub data_std: f64,
    /// What motion determines it (None: the model's twist could not say).
    pub excited_by: Option<Motion>,
}

impl HeldNearNominal {
    /// Whether the data alone knew the parameter worse than its nominal value
    /// is known, and the estimate reported stayed nearer the nominal value
    /// than the data put it: the user is told. (A nominal value the data
    /// contradict is not held to, however poorly they know it.)
    pub fn barely_determined(&self) -> bool {
        self.data_std > self.tolerance
            && (self.estimate - self.nominal).abs()
                < 0.5 * (self.data_estimate - self.nominal).abs()
    }
}

/// The body motion a parameter acts on, which is what a log must contain
/// to determine it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Motion {
    Forward,
    Sideways,
    Turning,
}

impl Motion {
    /// The runs that determine a parameter acting on this motion.
    pub fn runs_that_determine(self) -> &'static str {
        match self {
            Motion::Forward => "straight runs of measured length",
            Motion::Sideways => "runs that drive sideways",
            Motion::Turning => "runs turning both ways (in place or along arcs)",
        }
    }

    pub(super) fn of_twist_component(j: usize) -> Motion {
        [Motion::Forward, Motion::Sideways, Motion::Turning][j]
    }
}
