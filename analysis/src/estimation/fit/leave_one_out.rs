//! Leave-one-run-out: does the calibration carry over to runs it was not
//! fitted on? Each run in turn is left out, the calibration refined on the
//! others (locally, from the estimate on all runs), and the left-out run
//! dead-reckoned from its measured start with that refinement and with the
//! starting values. A run the others' calibration dead-reckons worse than the
//! starting values does not support the estimate: short or poorly exciting
//! runs that pull a parameter their own way (two real differential sessions
//! of 19, 4 and 4 s runs calibrated their wheelbase 2% off, worse than
//! nominal on every other session, and fit said nothing).
use super::{fit, FitOptions, Search};
use crate::model_on_log::metrics;
use crate::model_on_log::model::Runner;
use crate::model_on_log::run::Run;
use rayon::prelude::*;
use serde::Serialize;

/// One left-out run's whole-run position RMSE, m.
#[derive(Debug, Clone, Serialize)]
pub struct LeftOut {
    /// The run's log, as the user named it.
    pub path: String,
    /// With the starting (nominal) values.
    pub nominal_rmse_m: f64,
    /// With the calibration refined on the other runs.
    pub calibrated_rmse_m: f64,
}

impl LeftOut {
    /// The others' calibration dead-reckons this run worse than the starting
    /// values, beyond [`WORSE`].
    pub fn unsupported(&self) -> bool {
        self.calibrated_rmse_m > (WORSE * self.nominal_rmse_m).max(self.nominal_rmse_m + FLOOR_M)
    }
}

/// How much worse than the starting values a left-out run may come out
/// before it is named: 5% (on clean simulated logs, noise alone moves a
/// left-out run's error by a few percent either way).
pub const WORSE: f64 = 1.05;

/// ... and by more than this, m: a millimetre's difference in a whole-run
/// error is below what motion capture resolves (the short turns in place of
/// a real differential session moved by 1-3 mm either way).
pub const FLOOR_M: f64 = 0.001;

/// At most this many runs are left out in turn (one refinement each).
pub const MAX_RUNS: usize = 30;

/// Each run with ground truth left out in turn (see the module doc); `p` is
/// the calibration on all of `runs`, `r.p` the starting values. Empty with
/// fewer than two such runs or more than [`MAX_RUNS`].
pub fn leave_one_out(r: &Runner, p: &[f64], runs: &[Run], o: &FitOptions) -> Vec<LeftOut> {
    let measured: Vec<usize> = (0..runs.len()).filter(|&i| runs[i].gt.is_some()).collect();
    if measured.len() < 2 || measured.len() > MAX_RUNS || r.free.is_empty() {
        return Vec::new();
    }
    let mut from = r.clone();
    from.p = p.to_vec();
    measured
        .par_iter()
        .filter_map(|&i| {
            let others: Vec<Run> = (0..runs.len())
                .filter(|&j| j != i)
                .map(|j| runs[j].clone())
                .collect();
            let refit = fit(&from, &others, o, Search::Local).ok()?;
            Some(LeftOut {
                path: runs[i].path.clone(),
                nominal_rmse_m: metrics::from_measured_start(r, &r.p, &runs[i]).rmse,
                calibrated_rmse_m: metrics::from_measured_start(r, &refit.p, &runs[i]).rmse,
            })
        })
        .collect()
}
