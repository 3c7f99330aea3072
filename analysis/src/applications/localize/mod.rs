//! EKF localisation with mapped landmarks (seed 001 eq. 1-9) on the model's own
//! kernels, for logs as robots write them: rows at irregular times, commands
//! that hold between rows, sightings between rows.
//!
//! - Predict with the exact step and its Jacobians with respect to the state
//!   (F, eq. 4) and the process noise (G, eq. 5), to each sighting's own time
//!   (the row's inputs hold over the row), then to the next row.
//! - Process noise: a `[[noise]]` sigma whose unit is a density
//!   (`/sqrt(Hz)`) adds variance in proportion to elapsed time; seed 001's
//!   per-step sigma adds it per row, spread over the pieces a sighting cuts a
//!   row into. A model without `[[noise]]` gets white noise on its body twist.
//! - Noise chosen from the log itself unless the user gives it
//!   ([`noise::estimate`]: the innovations' likelihood, maximised over the
//!   process-noise densities and the observation errors: a white part, a
//!   persistent part per landmark and a part every landmark shares, the
//!   lingering ones carried as states, see [`belief`]), with the sensor's
//!   range reading where the sightings show one ([`reading`]: a camera that
//!   reads depth, not range).
//! - Update with the range-bearing observation and its Jacobian (H, eq. 6-7),
//!   R from its sigmas; innovations beyond a chi-square gate are rejected and
//!   counted. Where the pose is too uncertain for one expansion (a robot
//!   started without motion capture), the update is iterated.
//! - Consistency: NIS (always) and NEES (against ground truth, when the log has
//!   it and the model measures the body pose directly) against their
//!   chi-square bounds; a fixed-interval RTS smoother over the same pass for
//!   offline use ([`smoother`]).
mod active;
mod belief;
pub mod bounds;
pub mod figures;
mod filter;
pub mod gate_tail;
pub mod noise;
pub mod noise_model;
pub mod reading;
mod simplex;
mod smoother;
pub mod summary;
pub mod timing;

pub use bounds::{chi2_quantile, mean_bounds, Bounds};
pub use filter::{Filter, Keep, Pass};
pub use gate_tail::GateTail;
pub use noise_model::{Lingering, NoiseModel, NoiseSource};
pub use summary::{
    side, summarise, Consistency, NeesParts, Overconfident, Side, SmoothedSummary, Spread, Summary,
};

use crate::logs::log::wrap;
use crate::model_on_log::model::Runner;
use crate::model_on_log::run::Run;
use kinegen_model::decl::ObservationRole::Pose;
pub use nalgebra::Matrix3;
use nalgebra::Vector3;

/// The default gate on a sighting's NIS: the 99.9% point of chi-square with
/// 2 degrees of freedom. A consistent filter rejects one good sighting in a
/// thousand; real cameras' errors have heavier tails than a Gaussian, and the
/// 99% point (9.21) rejected 2.5-6.4% of the sightings of real robots whose
/// gross errors (over 0.5 m in range) were 0.9-3.1%.
pub const DEFAULT_GATE: f64 = 13.82;

#[derive(Debug, Clone)]
pub struct EkfOptions {
    /// NIS above which an observation is rejected ([`DEFAULT_GATE`]).
    pub gate: f64,
    /// Start-pose standard deviations (x, y m; theta rad).
    pub start_sigma: [f64; 3],
    /// Process-noise sigmas by `[[noise]]` name, replacing the spec's (in the
    /// spec's form: a density where its unit says so, per row otherwise).
    pub noise_sigma: Vec<(String, f64)>,
    /// Where the sigmas `noise_sigma` does not give come from.
    pub noise: NoiseSource,
    /// Also run the RTS smoother over the filter's pass.
    pub smooth: bool,
    /// The command-timing parameters (input delay, command lag) to estimate
    /// with the noise (see [`timing`]), where the spec declares them and the
    /// noise is estimated; the others keep the spec's (or `--set`'s) value.
    pub estimate_timing: Vec<timing::Timing>,
}

impl Default for EkfOptions {
    fn default() -> Self {
        EkfOptions {
            gate: DEFAULT_GATE,
            start_sigma: [0.05, 0.05, 0.02],
            noise_sigma: Vec::new(),
            noise: NoiseSource::Spec,
            smooth: false,
            estimate_timing: Vec::new(),
        }
    }
}

/// The smoother's pose and covariance at every row.
pub type Smoothed = (Vec<[f64; 3]>, Vec<Matrix3<f64>>);

/// One run's filter output.
#[derive(Debug, Clone)]
pub struct Localization {
    /// Estimated pose at every row, and its covariance.
    pub track: Vec<[f64; 3]>,
    pub cov: Vec<Matrix3<f64>>,
    /// The smoothed pose and covariance at every row (with `smooth`).
    pub smoothed: Option<Smoothed>,
    /// Time and normalised innovation squared of each accepted observation.
    pub nis: Vec<(f64, f64)>,
    /// Normalised estimation error squared at each row with ground truth.
    pub nees: Vec<Nees>,
    pub accepted: usize,
    pub rejected: usize,
    /// The NIS beyond which a sighting was rejected.
    pub gate: f64,
    /// Sightings outside the run's time span.
    pub outside: usize,
}

/// A run the filter cannot work on.
#[derive(Debug, Clone, thiserror::Error)]
pub enum LocalizeError {
    #[error("the model has no range-bearing (`landmark = true`) observation")]
    NoLandmarkObservation,
    #[error("{path}: the filter diverged at t = {t}")]
    Diverged { path: String, t: f64 },
    #[error("{path}: at t = {t} the filter's covariance is no longer one (not finite, or not positive semi-definite): the process noise is too large to compute with; give a smaller --noise or [[noise]] sigma")]
    NotACovariance { path: String, t: f64 },
}

/// The noise for the runs of one robot (`o` says where it comes from; an
/// estimate pools every run's sightings), with a sentence saying how it was
/// chosen.
pub fn noise_for(
    r: &Runner,
    runs: &[Run],
    o: &EkfOptions,
) -> Result<(NoiseModel, String), LocalizeError> {
    // the commands as the robot executed them (an input delay and lag:
    // timeline); without either the runs as they are, not copies
    if crate::model_on_log::timeline::input_delay(r, &r.p) == 0.0
        && crate::model_on_log::timeline::input_lag(r, &r.p) == 0.0
    {
        return noise::choose(&Filter::new(r, o)?, runs, o);
    }
    let executed: Vec<Run> = runs
        .iter()
        .map(|run| crate::model_on_log::timeline::executed(r, &r.p, run).into_owned())
        .collect();
    noise::choose(&Filter::new(r, o)?, &executed, o)
}

/// One robot's logs localised: the noise and where it came from, and each
/// run's filter output.
#[derive(Debug, Clone)]
pub struct Localized {
    pub noise: NoiseModel,
    pub note: String,
    /// The command timing the filter ran with, for each parameter estimated.
    pub timing: Vec<timing::TimingEstimate>,
    /// The filter over `runs`, then over `holdout`, in order, each with its
    /// figures.
    pub runs: Vec<(Localization, Summary)>,
}

/// Localise one robot's runs: the noise from `runs` (estimated on their
/// sightings pooled unless `o` gives it), then the filter over `runs` and
/// the `holdout` runs with that noise.
pub fn localize_runs(
    r: &Runner,
    runs: &[Run],
    holdout: &[Run],
    o: &EkfOptions,
) -> Result<Localized, LocalizeError> {
    let (noise, note) = noise_for(r, runs, o)?;
    let f = Filter::new(r, o)?;
    let (timed, noise, timing) = if noise::estimated(&f, runs, o) {
        let (_, given) = noise::with_given(&f, o);
        timing::estimate(r, runs, o, noise, (&given, &o.estimate_timing))
    } else {
        (r.clone(), noise, Vec::new())
    };
    let runs = runs
        .iter()
        .chain(holdout)
        .map(|run| {
            localize_with(&timed, run, &noise, o).map(|loc| {
                let figures = summarise(r, run, &loc);
                (loc, figures)
            })
        })
        .collect::<Result<_, _>>()?;
    Ok(Localized {
        noise,
        note,
        timing,
        runs,
    })
}

/// Run the filter (and the smoother, with `o.smooth`) over one run with `noise`.
pub fn localize_with(
    r: &Runner,
    run: &Run,
    noise: &NoiseModel,
    o: &EkfOptions,
) -> Result<Localization, LocalizeError> {
    let f = Filter::new(r, o)?;
    let executed = crate::model_on_log::timeline::executed(r, &r.p, run);
    let run: &Run = &executed;
    let keep = if o.smooth { Keep::Nodes } else { Keep::Rows };
    let pass = f.run(run, noise, keep)?;
    let smoothed = o.smooth.then(|| smoother::smooth(&pass));
    let track: Vec<[f64; 3]> = pass.rows.iter().map(|n| n.x).collect();
    let cov: Vec<Matrix3<f64>> = pass.rows.iter().map(|n| n.p).collect();
    // a noise too large for f64 (a sigma of 1e6 or 1e100) leaves a
    // covariance that is no covariance: said, not reported as a NEES of -966
    // (one row estimate per log row)
    if let Some(k) = pass.rows.iter().position(|n| !is_covariance(&n.p)) {
        return Err(LocalizeError::NotACovariance {
            path: run.path.clone(),
            t: run.t[k.min(run.t.len() - 1)],
        });
    }
    Ok(Localization {
        nees: nees_of(r, run, &track, &cov),
        track,
        cov,
        smoothed,
        nis: pass.nis,
        accepted: pass.accepted,
        rejected: pass.rejected,
        gate: o.gate,
        outside: pass.outside,
    })
}

/// [`noise_for`] the one run, then [`localize_with`] it.
pub fn localize(r: &Runner, run: &Run, o: &EkfOptions) -> Result<Localization, LocalizeError> {
    let (noise, _) = noise_for(r, std::slice::from_ref(run), o)?;
    localize_with(r, run, &noise, o)
}

/// NEES of `track` with covariances `cov` (a filter's or a smoother's)
/// against the run's ground truth at every row after the first that has it.
/// A model that observes an offset tracker (`sensor_offset`) is compared
/// where the tracker sees it, with the covariance carried there by the
/// observation's Jacobian. The ground truth's own noise ([`truth_noise`]) is
/// added to the covariance: a filter more precise than the motion capture (a
/// simulated robot seen by many landmarks: 1.3 mm against 1 mm of tracker
/// noise) would otherwise read as overconfident.
pub fn nees_of(r: &Runner, run: &Run, track: &[[f64; 3]], cov: &[Matrix3<f64>]) -> Vec<Nees> {
    let Some(g) = run.gt.as_ref() else {
        return Vec::new();
    };
    let s = truth_noise(run).unwrap_or([0.0; 3]);
    let truth = Matrix3::from_diagonal(&nalgebra::Vector3::new(
        s[0] * s[0],
        s[1] * s[1],
        s[2] * s[2],
    ));
    let sensor = Sensed::new(r, run);
    // (rows where the motion capture lost the robot are not scored)
    (1..track.len().min(g.len()))
        .filter(|&k| g[k].iter().all(|v| v.is_finite()))
        .filter_map(|k| {
            let (m, h) = sensor.at(k, &track[k]);
            let e = nalgebra::Vector3::new(m[0] - g[k][0], m[1] - g[k][1], wrap(m[2] - g[k][2]));
            Nees::of(k, &e, &(h * cov[k] * h.transpose() + truth))
        })
        .collect()
}

/// One row's normalised estimation error squared: of the whole pose (3
/// degrees of freedom), and of its position (2) and heading (1) alone, each
/// against its own marginal covariance. The parts tell which of the
/// filter's beliefs is wrong: on the MRCLAM robots the pose's NEES is
/// overconfident while the heading's alone is at or below its bounds, on
/// the NIS's side.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Nees {
    pub row: usize,
    pub pose: f64,
    pub position: f64,
    pub heading: f64,
}

impl Nees {
    /// Row `row`'s NEES for pose error `e` (x, y, heading) with covariance
    /// `c`: each part against its marginal (not its conditional: the
    /// position's error is judged by all the position uncertainty the
    /// filter believes in, whatever the heading's). None: `c` is singular.
    pub fn of(row: usize, e: &Vector3<f64>, c: &Matrix3<f64>) -> Option<Nees> {
        let position = c.fixed_view::<2, 2>(0, 0).into_owned().try_inverse()?;
        let ep = e.fixed_rows::<2>(0);
        Some(Nees {
            row,
            pose: (e.transpose() * c.try_inverse()? * e)[(0, 0)],
            position: (ep.transpose() * position * ep)[(0, 0)],
            heading: e[2] * e[2] / c[(2, 2)],
        })
    }
}

/// Where the motion capture sees a body pose: through the model's pose
/// observation (an off-centre marker), or the pose itself.
pub struct Sensed<'a> {
    r: &'a Runner,
    run: &'a Run,
    kernels: Option<kinegen_model::ir::ObservationKernels<'a>>,
}

impl<'a> Sensed<'a> {
    pub fn new(r: &'a Runner, run: &'a Run) -> Sensed<'a> {
        Sensed {
            r,
            run,
            kernels: r.ir.observation_kernels(Pose),
        }
    }

    /// The sensed pose at row `k` for body pose `x`, and its Jacobian in
    /// the body pose.
    pub fn at(&self, k: usize, x: &[f64; 3]) -> ([f64; 3], Matrix3<f64>) {
        let Some(h) = &self.kernels else {
            return (*x, Matrix3::identity());
        };
        let u = &self.run.u[k.min(self.run.steps().saturating_sub(1))];
        let p = &self.r.p;
        let m = self
            .r
            .eval(h.value, &Runner::obs_args(h.value, x, u, p, &[]));
        let j = self
            .r
            .eval(h.jac_x, &Runner::obs_args(h.jac_x, x, u, p, &[]));
        ([m[0], m[1], m[2]], Matrix3::from_row_slice(&j[..9]))
    }
}

/// The ground truth's own white noise (x, y and heading standard
/// deviations), from its third differences on evenly sampled stretches
/// (each within 20% of the median step): white noise of sd s gives third
/// differences of sd s sqrt(20), while a smooth motion's jerk adds little at
/// a tracker's rate (a median absolute deviation, robust to its manoeuvres).
/// On the simulator's logs it finds 1.2 mm and 2.2 mrad (it adds 1 mm and 2
/// mrad); on the MRCLAM robots' Vicon 0.05 mm and 0.2 mrad. None: too few
/// even stretches to tell (the truth is taken as exact).
pub fn truth_noise(run: &Run) -> Option<[f64; 3]> {
    let g = run.gt.as_ref()?;
    let mut dt: Vec<f64> = run.dt.to_vec();
    dt.sort_by(f64::total_cmp);
    let median = *dt.get(dt.len() / 2)?;
    let even = |k: usize| {
        (k..k + 3).all(|j| (run.dt[j] - median).abs() < 0.2 * median)
            && (k..k + 4).all(|j| g[j].iter().all(|v| v.is_finite()))
    };
    let third = |k: usize, i: usize| {
        let v = |j: usize| if i == 2 { g[j][2] } else { g[j][i] };
        let d = v(k + 3) - 3.0 * v(k + 2) + 3.0 * v(k + 1) - v(k);
        if i == 2 {
            wrap(d)
        } else {
            d
        }
    };
    let windows: Vec<usize> = (0..g.len().saturating_sub(3))
        .filter(|&k| even(k))
        .collect();
    if windows.len() < 20 {
        return None;
    }
    let mad = |mut v: Vec<f64>| {
        v.sort_by(f64::total_cmp);
        1.4826 * v[v.len() / 2] / 20f64.sqrt()
    };
    let position = mad(windows
        .iter()
        .flat_map(|&k| [third(k, 0).abs(), third(k, 1).abs()])
        .collect());
    let heading = mad(windows.iter().map(|&k| third(k, 2).abs()).collect());
    Some([position, position, heading])
}

/// Whether `p` is a covariance to within rounding: finite, a non-negative
/// diagonal, and every 2x2 principal minor non-negative (relative to its
/// diagonal, so a zero covariance at a known start passes).
fn is_covariance(p: &Matrix3<f64>) -> bool {
    if p.iter().any(|v| !v.is_finite()) || (0..3).any(|i| p[(i, i)] < 0.0) {
        return false;
    }
    [(0, 1), (0, 2), (1, 2)].iter().all(|&(i, j)| {
        let (a, b, c) = (p[(i, i)], p[(j, j)], p[(i, j)]);
        a * b - c * c >= -1e-9 * a * b - f64::MIN_POSITIVE
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_part_of_the_nees_is_judged_by_its_marginal() {
        // heading and x correlated 0.9: an error of one sd in each, along
        // that correlation, is one sd of each part's own marginal, and
        // little of the pose's (the conditional heading's sd is 0.44)
        let c = Matrix3::new(1.0, 0.0, 0.9, 0.0, 1.0, 0.0, 0.9, 0.0, 1.0);
        let n = Nees::of(7, &Vector3::new(1.0, 0.0, 1.0), &c).unwrap();
        assert_eq!(n.row, 7);
        assert!((n.position - 1.0).abs() < 1e-12, "{n:?}");
        assert!((n.heading - 1.0).abs() < 1e-12, "{n:?}");
        // (1, 1) C^-1 (1, 1)^T for the [[1, .9], [.9, 1]] block: 2 / 1.9
        assert!((n.pose - 2.0 / 1.9).abs() < 1e-12, "{n:?}");
        assert!(Nees::of(0, &Vector3::zeros(), &Matrix3::zeros()).is_none());
    }
}
