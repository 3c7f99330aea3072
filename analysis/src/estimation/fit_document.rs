//! The JSON document of a calibration: what `kinegen fit --json` writes,
//! its report embeds and the Python package's `to_json()` returns. Built
//! here, once, so the three are the same document.
use crate::estimation::fit::{FitOptions, FitResult};
use crate::estimation::fit_job::Calibrated;
use crate::model_on_log::evaluation::metric_name;
use crate::model_on_log::load::Loaded;
use crate::model_on_log::metrics::Errors;
use crate::model_on_log::model::Runner;
use crate::model_on_log::run::Run;
use serde_json::{json, Value};

/// `fit --json`'s document of a finished calibration (CONTRACT section 4);
/// the command line adds its per-run tables, the Python package returns it.
pub fn fit_document(
    r: &Runner,
    res: &FitResult,
    before: &Errors,
    after: &Errors,
    metric: &str,
) -> Value {
    let params: serde_json::Map<String, Value> = res
        .free
        .iter()
        .enumerate()
        .map(|(k, &i)| {
            let mut v = json!({"nominal": r.p[i], "estimate": res.p[i], "std": res.std[k],
                               "tolerance": r.ir.runtime_params()[i].tolerance});
            // where the nominal value's default prior took part: what the
            // data alone said, and whether they knew it worse than the prior
            if let Some(h) = res.near_nominal.iter().find(|h| h.param == i) {
                v["nominal_prior"] = json!({"std": h.tolerance, "data_estimate": h.data_estimate,
                    "data_std": h.data_std, "barely_determined": h.barely_determined()});
            }
            (r.names[i].clone(), v)
        })
        .collect();
    let names: Vec<&str> = res.free.iter().map(|&i| r.names[i].as_str()).collect();
    let corr: Vec<Vec<f64>> = (0..names.len())
        .map(|a| (0..names.len()).map(|b| res.corr[(a, b)]).collect())
        .collect();
    json!({
        "model": r.ir.name, "metric": metric,
        "before": {"rmse": before.rmse, "errors": before}, "after": {"rmse": after.rmse, "errors": after},
        "parameters": params, "correlation": {"parameters": names, "matrix": corr},
        "warnings": res.warnings, "iterations": res.iterations, "residuals": res.n_residuals,
    })
}

/// The whole document of `calibrate`'s result `cal` on the logs `prep`
/// with the options `fo`: the calibration, what it ran on and with which
/// loss, the landmarks' figures, each run's errors (fitted, then held out),
/// leave-one-out and every warning.
pub fn calibration_document(prep: &Loaded, cal: &Calibrated, fo: &FitOptions) -> Value {
    let r = &prep.runner;
    let (before, after) = (&cal.before.errors, &cal.after.errors);
    let mut doc = fit_document(r, &cal.fit, before, after, metric_name(&prep.runs));
    doc["unusable"] = json!(cal.unusable);
    doc["loss"] = json!(if fo.huber.is_some() { "huber" } else { "l2" });
    let kinds = [
        ("pose", fo.use_pose),
        ("gyro", fo.use_gyro),
        ("landmarks", fo.use_landmarks),
    ];
    let used: Vec<&str> = kinds.iter().filter(|k| k.1).map(|k| k.0).collect();
    doc["residual_kinds"] = json!(used);
    if let (Some(lb), Some(la)) = (&cal.before.landmarks, &cal.after.landmarks) {
        doc["landmarks"] = json!({"before": lb, "after": la});
    }
    let truth = (
        &cal.before.landmarks_from_truth,
        &cal.after.landmarks_from_truth,
    );
    if let (Some(lb), Some(la)) = truth {
        doc["landmarks_from_truth"] = json!({"before": lb, "after": la});
    }
    let (b, a) = (&cal.before.per_run, &cal.after.per_run);
    let mut runs = per_run(&prep.runs, b, a, &cal.starts, false);
    if let Some(h) = &cal.holdout {
        let (hb, ha) = (&h.before, &h.after);
        runs.extend(per_run(
            &prep.holdout,
            &hb.per_run,
            &ha.per_run,
            &h.starts,
            true,
        ));
        doc["holdout"] = json!({"before": {"rmse": hb.errors.rmse, "errors": hb.errors},
                               "after": {"rmse": ha.errors.rmse, "errors": ha.errors}});
    }
    doc["runs"] = json!(runs);
    doc["warnings"] = json!(cal.warnings());
    if !cal.leave_one_out.is_empty() {
        doc["leave_one_out"] = json!(cal.leave_one_out);
    }
    doc
}

/// Each run's entry, named by the path the user gave: its errors after the
/// calibration at the top, before it under `before`, whether it was held
/// out, and the start pose its dead reckoning used (a fitted run's measured
/// start with its refined heading, a held-out run's as measured).
fn per_run(
    runs: &[Run],
    before: &[Errors],
    after: &[Errors],
    starts: &[[f64; 3]],
    holdout: bool,
) -> Vec<Value> {
    let entry = |(i, run): (usize, &Run)| {
        let (b, a) = (&before[i], &after[i]);
        json!({
            "path": run.path, "holdout": holdout,
            "rmse": a.rmse, "final_error": a.final_position_error_m,
            "final_heading_error": a.final_heading_error_rad, "errors": a,
            "before": {"rmse": b.rmse, "final_error": b.final_position_error_m},
            "start_pose": starts.get(i),
        })
    };
    runs.iter().enumerate().map(entry).collect()
}
