//! Whether an effect's improvement holds all along a long log: k-fold
//! cross-validation over the calibration's segments, with a paired t-test on
//! the folds' held-out errors.
//!
//! Why a second test beside [`super::diagnose`]'s: on a real robot most of
//! what the model leaves is random (wheel slip, a command not followed, the
//! floor), not a missing effect, and it dwarfs the sensor noise. A real effect
//! then explains a few percent of the error, never "most of the excess over the
//! noise floor" nor 20% of it, and the residuals are far from independent, so
//! the BIC's gain (thousands) says nothing either. What does hold is that the
//! effect, calibrated without a stretch of the log, predicts that stretch
//! better, and does so in every stretch: a lag of the commands behind the
//! motion is in every turn. The folds are scored on the motion over a second
//! (see [`WINDOW_S`]), which a minute's random drift does not swamp. Each
//! segment is dead-reckoned from its own start, so segments are nearly
//! independent, and the test counts folds, not residuals.
use crate::estimation::fit::{fit, segmented, FitOptions, FitResult, Search};
use crate::logs::log::wrap;
use crate::model_on_log::model::Runner;
use crate::model_on_log::run::Run;
use rayon::prelude::*;

/// Fewest folds the test is run on: with fewer segments (a log under about
/// five minutes) a t-test on the folds has too little power to be worth its
/// calibrations, and the other criteria decide alone.
pub const MIN_FOLDS: usize = 5;

/// Most folds: more cost a calibration each and add little power.
const MAX_FOLDS: usize = 8;

/// One-sided level of the paired t-test. Strict, because each diagnosis round
/// tests up to a dozen candidates and a chain has up to three rounds: about
/// 3% for a false effect in a whole diagnosis of a model that misses none.
const LEVEL: f64 = 1e-3;

/// Smallest held-out improvement of the mean square error, summed over the
/// folds, worth naming an effect for: below it the effect may be real, but
/// the user's odometry would not notice it (on real logs, a dozen candidates
/// improve every fold by 0.1-0.4%).
const MIN_GAIN: f64 = 0.05;

/// Window of the relative motions the folds are scored on, s: the pose a
/// second later seen from the pose now, so what the robot did at random
/// before (the slip that dominates a minute's dead reckoning) is not in it,
/// while an effect on the motion itself (a lag of a few tenths of a second,
/// a scale) is. A second is the horizon an EKF predicts over between
/// sightings. On five real velocity-commanded robots (MRCLAM), the 60 s
/// segments' own error gave their command lag t = 0.4-1.6 over 8 folds.
pub const WINDOW_S: f64 = 1.0;

/// The segments of a calibration (as [`segmented`] cuts them, in order),
/// grouped into consecutive folds.
pub struct Folds {
    segments: Vec<Run>,
    /// Fold k is `segments[bounds[k]..bounds[k + 1]]`.
    bounds: Vec<usize>,
}

/// The outcome of the paired test of a candidate against the current model.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct FoldTest {
    pub folds: usize,
    /// Held-out improvement of the mean square error, summed over folds,
    /// relative to the current model's.
    pub gain: f64,
    /// The paired t statistic of the folds' improvements.
    pub t: f64,
    /// Its critical value at [`LEVEL`] for `folds - 1` degrees of freedom.
    pub critical: f64,
    /// The segments the folds hold.
    pub segments: usize,
}

impl FoldTest {
    /// An improvement that holds in the folds beyond chance and is worth naming.
    pub fn holds(&self) -> bool {
        self.t > self.critical && self.gain > MIN_GAIN
    }
}

impl FoldTest {
    /// Why a test that beats chance still does not hold, for people: empty
    /// when it holds or does not beat chance.
    pub fn too_small(&self) -> String {
        if self.t > self.critical && self.gain <= MIN_GAIN {
            format!(
                "; consistent, but under the {:.0}% worth naming",
                100.0 * MIN_GAIN
            )
        } else {
            String::new()
        }
    }
}

impl std::fmt::Display for FoldTest {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "held out fold by fold: error {:+.1}% in {} folds (t = {:.1}, needs {:.1}{})",
            -100.0 * self.gain,
            self.folds,
            self.t,
            self.critical,
            self.too_small()
        )
    }
}

impl Folds {
    /// The folds of `runs`, or None when they make fewer than [`MIN_FOLDS`]
    /// segments.
    pub fn of(runs: &[Run]) -> Option<Folds> {
        let segments = segmented(runs);
        let n = segments.len();
        if n < MIN_FOLDS {
            return None;
        }
        let k = n.min(MAX_FOLDS);
        let bounds = (0..=k).map(|i| i * n / k).collect();
        Some(Folds { segments, bounds })
    }

    pub fn len(&self) -> usize {
        self.bounds.len() - 1
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The segments the folds hold.
    pub fn segments(&self) -> usize {
        self.segments.len()
    }

    /// Each fold's mean square error of `r` in its [`WINDOW_S`] relative
    /// motions ([`relative_motion_errors`]), calibrated on the other folds:
    /// locally, from `whole` (its calibration on all the runs) and that
    /// calibration's start poses.
    pub fn held_out(&self, r: &Runner, whole: &FitResult, o: &FitOptions) -> Vec<f64> {
        let mut at = r.clone();
        at.p = whole.p.clone();
        (0..self.len())
            .into_par_iter()
            .map(|k| {
                let (a, b) = (self.bounds[k], self.bounds[k + 1]);
                let outside = |i: &usize| *i < a || *i >= b;
                let train: Vec<Run> = (0..self.segments.len())
                    .filter(outside)
                    .map(|i| self.segments[i].clone())
                    .collect();
                let starts: Vec<[f64; 3]> = (0..self.segments.len())
                    .filter(outside)
                    .filter_map(|i| whole.starts.get(i).copied())
                    .collect();
                // a calibration that fails on the other folds leaves the
                // whole log's: that fold's error is then in-sample, which
                // can only favour the model it belongs to
                let p = fit(&at, &train, o, Search::From(&starts))
                    .map(|f| f.p)
                    .unwrap_or_else(|_| whole.p.clone());
                let (sum, n) = self.segments[a..b]
                    .iter()
                    .map(|seg| relative_motion_errors(&at, &p, seg, o))
                    .fold((0.0, 0usize), |(s, n), (s1, n1)| (s + s1, n + n1));
                sum / n.max(1) as f64
            })
            .collect()
    }
}

/// The weighted squared error of the pose sensor's motion over consecutive
/// [`WINDOW_S`] windows of `run`, in the frame of each window's start (the
/// relative pose error of odometry benchmarks), and how many residuals it
/// sums. The model is dead-reckoned over the whole run, so an effect with a
/// memory (a late or lagging command) has its history at every window; the
/// motion relative to the window's start does not depend on where the track
/// has drifted to by then.
fn relative_motion_errors(r: &Runner, p: &[f64], run: &Run, o: &FitOptions) -> (f64, usize) {
    let Some(gt) = &run.gt else {
        return (0.0, 0);
    };
    let track = crate::model_on_log::deadreckon::run(r, p, run, false);
    let model = track.measured();
    let sig = [o.pos_sigma, o.pos_sigma, o.heading_sigma];
    let relative = |a: &[f64; 3], b: &[f64; 3]| {
        let (c, s) = (a[2].cos(), a[2].sin());
        let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
        [c * dx + s * dy, -s * dx + c * dy, wrap(b[2] - a[2])]
    };
    let (mut sum, mut n, mut a) = (0.0, 0, 0);
    for b in 1..run.t.len() {
        if run.t[b] - run.t[a] < WINDOW_S {
            continue;
        }
        let (m, g) = (relative(&model[a], &model[b]), relative(&gt[a], &gt[b]));
        for i in 0..3 {
            let e = if i == 2 {
                wrap(m[i] - g[i])
            } else {
                m[i] - g[i]
            };
            sum += (e / sig[i]).powi(2);
        }
        n += 3;
        a = b;
    }
    (sum, n)
}

/// The paired t-test of a candidate's held-out fold errors `aug` against the
/// current model's `base`, on folds holding `segments` segments.
pub fn paired(base: &[f64], aug: &[f64], segments: usize) -> FoldTest {
    let k = base.len().min(aug.len());
    // log ratios: a fold with more turning shows a lag more than one driving
    // straight, and the test asks whether each fold improves, not by how much
    let d: Vec<f64> = base
        .iter()
        .zip(aug)
        .map(|(b, a)| (b.max(1e-300) / a.max(1e-300)).ln())
        .collect();
    let mean = d.iter().sum::<f64>() / k as f64;
    let var = d.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (k as f64 - 1.0);
    let t = if var > 0.0 {
        mean / (var / k as f64).sqrt()
    } else if mean > 0.0 {
        f64::INFINITY
    } else {
        0.0
    };
    let total: f64 = base.iter().take(k).sum();
    let improved: f64 = base.iter().zip(aug).map(|(b, a)| b - a).sum();
    FoldTest {
        folds: k,
        gain: improved / total.max(1e-300),
        t,
        critical: t_critical(k.saturating_sub(1)),
        segments,
    }
}

/// The one-sided critical value of Student's t at [`LEVEL`] for `dof`
/// degrees of freedom.
fn t_critical(dof: usize) -> f64 {
    student_t_quantile(dof, 1.0 - LEVEL)
}

/// The `p` quantile of Student's t with `dof` degrees of freedom (at least
/// one), from `statrs`; infinite where it has none.
pub(super) fn student_t_quantile(dof: usize, p: f64) -> f64 {
    use statrs::distribution::{ContinuousCDF, StudentsT};
    match StudentsT::new(0.0, 1.0, dof.max(1) as f64) {
        Ok(t) => t.inverse_cdf(p),
        Err(_) => f64::INFINITY,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn critical_values_are_students() {
        // tables: t(0.999; 4) = 7.173, t(0.999; 7) = 4.785
        assert!((t_critical(4) - 7.173).abs() < 1e-3);
        assert!((t_critical(7) - 4.785).abs() < 1e-3);
    }

    #[test]
    fn a_consistent_improvement_holds_and_a_mixed_one_does_not() {
        let base = [1.0, 1.1, 0.9, 1.2, 1.0, 0.95];
        let better: Vec<f64> = base.iter().map(|b| b * 0.95).collect();
        let test = paired(&base, &better, 6);
        assert!(test.holds(), "{test:?}");
        // the same total gain, won in one fold and lost in another
        let mixed = [0.7, 1.1, 0.9, 1.2, 1.05, 0.95];
        let test = paired(&base, &mixed, 6);
        assert!(!test.holds(), "{test:?}");
        // consistent but too small to matter
        let tiny: Vec<f64> = base.iter().map(|b| b * 0.995).collect();
        let test = paired(&base, &tiny, 6);
        assert!(!test.holds() && !test.too_small().is_empty(), "{test:?}");
    }
}
