//! The JSON document of a localisation: what `kinegen localize --json`
//! writes, its report embeds and the Python package's `to_json()` returns.
//! Built here, once, so the three are the same document.
use crate::applications::localize::reading::RangeReading;
use crate::applications::localize::timing::Timing;
use crate::applications::localize::{
    Consistency, Localization, NoiseModel, Overconfident, Spread, Summary,
};
use crate::applications::localize_request::LocalizedFiles;
use crate::model_on_log::run::Run;
use serde_json::{json, Value};

/// The whole document: the model, the gate, the noise the filter ran with,
/// each run's figures (training runs, then held-out ones), the sweep and the
/// warnings.
pub fn localize_document(files: &LocalizedFiles) -> Value {
    let LocalizedFiles {
        loaded,
        options,
        localized,
        sweep,
        ..
    } = files;
    let mut noise = noise_json(&localized.noise, &localized.note);
    for d in &localized.timing {
        let key = match d.timing {
            Timing::Delay => "input_delay",
            Timing::Lag => "command_lag",
        };
        noise[key] = json!({"name": d.name, "spec_s": d.spec_s, "estimate_s": d.estimate_s, "likelihood_gain": d.gain});
    }
    let runs: Vec<Value> = loaded
        .runs
        .iter()
        .chain(&loaded.holdout)
        .zip(&localized.runs)
        .map(|(run, (loc, summary))| run_json(run, loc, summary))
        .collect();
    json!({"model": loaded.runner.ir.name, "gate": options.gate, "noise": noise, "runs": runs, "sweep": sweep, "warnings": loaded.warnings})
}

/// A run's entry in the document.
fn run_json(run: &Run, loc: &Localization, s: &Summary) -> Value {
    let last = loc.cov.last().unwrap();
    json!({
        "path": run.path, "steps": run.steps(),
        "observations_used": loc.accepted, "observations_rejected": loc.rejected,
        "observations_outside_log": loc.outside,
        "position_rmse_m": s.rmse, "dead_reckoning_rmse_m": s.dead_reckoning,
        "nis_mean": s.nis, "nis_bounds": s.nis_bounds.map(|b| [b.lo, b.hi]),
        "nis_independent": s.nis_bounds.map(|b| b.independent),
        "gate_tail": s.gate_tail.map(|g| json!({
            "rejected_share": g.share(), "consistent_share": g.expected,
            "consistent_share_bound": g.bound, "overconfident": g.overconfident(),
        })),
        "nees_mean": s.nees, "nees_bounds": s.nees_bounds.map(|b| [b.lo, b.hi]),
        "nees_independent": s.nees_bounds.map(|b| b.independent),
        "nis_spread": s.nis_spread.map(spread_json), "nees_spread": s.nees_spread.map(spread_json),
        "consistency": s.consistency().map(|c| match c {
            Consistency::Agree => "agree",
            Consistency::HeavyTails { pessimistic_core: true } => "heavy_tails_pessimistic_core",
            Consistency::HeavyTails { pessimistic_core: false } => "heavy_tails_overconfident_core",
            Consistency::Contradict => "contradict",
        }),
        "nees_parts": s.nees_parts.map(|p| json!({
            "position_mean": p.position.0, "position_bounds": [p.position.1.lo, p.position.1.hi],
            "heading_mean": p.heading.0, "heading_bounds": [p.heading.1.lo, p.heading.1.hi],
            "near_sightings_mean": p.near_sightings, "far_from_sightings_mean": p.far_from_sightings,
            "overconfident": s.overconfident_part().map(|o| match o {
                Overconfident::Heading => "heading",
                Overconfident::PositionNearSightings => "position_near_sightings",
                Overconfident::PositionFarFromSightings => "position_far_from_sightings",
                Overconfident::Position => "position",
            }),
        })),
        "ground_truth_noise": s.truth_noise.map(|n| json!({"position_m": n[0], "heading_rad": n[2]})),
        "smoothed": s.smoothed.map(|x| json!({
            "position_rmse_m": x.rmse, "nees_mean": x.nees,
            "nees_bounds": x.nees_bounds.map(|b| [b.lo, b.hi]),
            "nees_independent": x.nees_bounds.map(|b| b.independent),
        })),
        "final_pose": loc.track.last(),
        "final_std": [last[(0, 0)].sqrt(), last[(1, 1)].sqrt(), last[(2, 2)].sqrt()],
    })
}

fn spread_json(x: Spread) -> Value {
    json!({"median": x.median, "chi2_median": x.chi2_median, "beyond_95": x.beyond_95, "point_95": x.point_95})
}

/// The noise the filter ran with, and where it came from (`note`).
fn noise_json(n: &NoiseModel, note: &str) -> Value {
    let process: serde_json::Map<String, Value> = n
        .names
        .iter()
        .zip(&n.sigma)
        .zip(&n.density)
        .map(|((name, s), d)| {
            (
                name.clone(),
                json!({"sigma": s, "form": if *d { "density_per_sqrt_s" } else { "per_row" }}),
            )
        })
        .collect();
    // null: the spec's straight-line range, as written
    let r = &n.range_reading;
    let range_reading = (!r.is_straight()).then(|| {
        let mut j = json!({"effect": RangeReading::EFFECT});
        for (k, v) in r.parameters() {
            j[k] = json!(v);
        }
        j
    });
    json!({"process": process, "observation_scale": {"range": n.obs_scale[0], "bearing": n.obs_scale[1]}, "persistent": {"range_per_m": n.persistent.factor[0], "bearing": n.persistent.factor[1]}, "memory_s": n.persistent.memory_s, "shared": {"range_per_m": n.shared.factor[0], "bearing": n.shared.factor[1], "memory_s": n.shared.memory_s}, "range_reading": range_reading, "source": note})
}
