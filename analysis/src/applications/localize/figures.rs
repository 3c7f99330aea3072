//! What `localize --report` draws of each run, computed here so that the
//! page only draws: the dead-reckoning track beside the filter's, and the
//! position error over time with its 3-sigma bound, where the motion
//! capture sees the robot (as the figures' table measures it), and the NIS
//! over time with the band its windowed mean should stay in.
use super::{mean_bounds, Localization, Matrix3, Sensed, Summary};
use crate::model_on_log::model::Runner;
use crate::model_on_log::run::Run;

/// One run's figures.
pub struct RunFigures {
    /// Dead reckoning with the spec's values, every row.
    pub dead_reckoning: Vec<[f64; 3]>,
    /// Position error against time (s from the run's start), at the rows
    /// with ground truth; None without ground truth.
    pub errors: Option<ErrorFigures>,
    /// The NIS of each sighting used, over time (empty without one).
    pub nis: NisFigure,
}

/// Sightings averaged by the NIS curve.
pub const NIS_WINDOW: usize = 50;

/// The NIS of each sighting used, (t, NIS) from the run's start, its mean
/// over windows of `window` sightings (at each window's middle), and the
/// 95% band of such a mean.
pub struct NisFigure {
    pub window: usize,
    pub points: Vec<(f64, f64)>,
    pub mean: Vec<(f64, f64)>,
    pub band: (f64, f64),
}

fn nis_figure(run: &Run, loc: &Localization, summary: &Summary) -> NisFigure {
    let t0 = run.t[0];
    let points: Vec<(f64, f64)> = loc.nis.iter().map(|(t, n)| (t - t0, *n)).collect();
    let w = NIS_WINDOW.min(points.len()).max(1);
    let mean = points
        .windows(w)
        .map(|win| {
            (
                win[w / 2].0,
                win.iter().map(|q| q.1).sum::<f64>() / w as f64,
            )
        })
        .collect();
    // the band of a window's mean counts its sightings as the independent
    // values they are worth, at the run's share ([`super::Bounds`])
    let worth = summary
        .nis_bounds
        .map_or(1.0, |b| b.independent / points.len().max(1) as f64);
    NisFigure {
        window: w,
        band: mean_bounds((w as f64 * worth).max(1.0), 2.0),
        points,
        mean,
    }
}

/// Position errors and their 3-sigma bounds: the filter's, and the
/// smoother's with `--smooth`.
pub struct ErrorFigures {
    pub filter: ErrorCurve,
    pub smoothed: Option<ErrorCurve>,
}

/// A track's position error and its 3-sigma bound, (t, m) points.
pub struct ErrorCurve {
    pub error: Vec<(f64, f64)>,
    pub bound: Vec<(f64, f64)>,
}

/// The figures of `run` localised as `loc`, with its `summary`.
pub fn run_figures(r: &Runner, run: &Run, (loc, summary): (&Localization, &Summary)) -> RunFigures {
    let dead_reckoning = crate::model_on_log::deadreckon::run(r, &r.p, run, false).pose;
    let errors = run.gt.as_ref().map(|gt| {
        let sensor = Sensed::new(r, run);
        let t0 = run.t[0];
        let error = |track: &[[f64; 3]]| -> Vec<(f64, f64)> {
            track
                .iter()
                .zip(gt)
                .enumerate()
                // rows where the motion capture lost the robot have none
                .filter(|(_, (_, g))| g[0].is_finite())
                .map(|(k, (x, g))| {
                    let m = sensor.at(k, x).0;
                    (run.t[k] - t0, (m[0] - g[0]).hypot(m[1] - g[1]))
                })
                .collect()
        };
        let bound = |cov: &[Matrix3<f64>]| -> Vec<(f64, f64)> {
            cov.iter()
                .enumerate()
                .map(|(k, c)| (run.t[k] - t0, 3.0 * (c[(0, 0)] + c[(1, 1)]).max(0.0).sqrt()))
                .collect()
        };
        let curve = |track: &[[f64; 3]], cov: &[Matrix3<f64>]| ErrorCurve {
            error: error(track),
            bound: bound(cov),
        };
        ErrorFigures {
            filter: curve(&loc.track, &loc.cov),
            smoothed: loc.smoothed.as_ref().map(|(s, c)| curve(s, c)),
        }
    });
    RunFigures {
        dead_reckoning,
        errors,
        nis: nis_figure(run, loc, summary),
    }
}
