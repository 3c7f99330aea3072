//! One round of candidates: each effect of a list added to the current
//! stage, checked for redundancy with the calibration, and the winner's
//! stage. The catalogue's rounds ([`super::diagnose`]) and the proposal
//! library's ([`super::propose`]) both run them.
use super::ranking::{effect_params, Candidate};
use super::sensor::sensor_only;
use super::stage::{seeded, stage_from, Stage};
use crate::estimation::fit::{residuals, FitOptions};
use crate::model_on_log::derivation::EffectChains;
use crate::model_on_log::model::Runner;
use crate::model_on_log::run::Run;
use nalgebra::DVector;
use rayon::prelude::*;

/// Effects (or anything) by name, with a text: a doc, a reason.
pub(crate) type Named = Vec<(String, String)>;

/// The effects a diagnosis tries, and how it gets the spec with a list of
/// them added.
pub struct Catalogue<'a> {
    /// (name, doc) of every applicable effect, in catalogue order.
    pub effects: Vec<(String, String)>,
    pub chains: &'a EffectChains<'a>,
}

/// Whether an effect adds nothing the calibrated model cannot already do on
/// these logs: the residual Jacobian columns of its parameters lie in the span of
/// the free parameters' columns (checked on the data, at the current estimates).
/// Returns the reason when it is redundant.
pub fn redundancy(
    start: &Runner,
    effect_params: &[usize],
    runs: &[Run],
    o: &FitOptions,
) -> Option<String> {
    let o = &FitOptions {
        estimate_start: false,
        huber: None,
        ..o.clone()
    };
    // a bounded sample of the data is enough to see the span
    let mut sample = Vec::new();
    let mut steps = 0;
    for run in runs {
        if steps >= 4000 {
            break;
        }
        let end = (run.t.len()).min(4000 - steps + 1).max(3);
        sample.push(run.slice(0, end));
        steps += end;
    }
    let (_, jac) = residuals(start, &start.p, &start.free, &sample, o, true, &[]);
    let j = jac?;
    let base: Vec<usize> = (0..start.free.len())
        .filter(|c| !effect_params.contains(&start.free[*c]))
        .collect();
    let unit = |c: usize| {
        let col = j.column(c).into_owned();
        let n = col.norm();
        (n > 0.0).then(|| col / n)
    };
    let cols: Vec<(usize, DVector<f64>)> = base
        .iter()
        .filter_map(|&c| unit(c).map(|v| (c, v)))
        .collect();
    if cols.is_empty() {
        return None;
    }
    let b = nalgebra::DMatrix::from_columns(&cols.iter().map(|x| x.1.clone()).collect::<Vec<_>>());
    let svd = crate::model_on_log::linalg::svd(b.clone())?;
    let mut reasons = Vec::new();
    for &pi in effect_params {
        let c = start.free.iter().position(|&f| f == pi)?;
        let Some(e) = unit(c) else {
            reasons.push(format!(
                "{} changes nothing these logs measure",
                start.names[pi]
            ));
            continue;
        };
        let x = svd.solve(&e, 1e-10).ok()?;
        let left = (&b * &x - &e).norm();
        if left > 1e-3 {
            return None;
        }
        let big = x.amax();
        let by: Vec<&str> = cols
            .iter()
            .zip(x.iter())
            .filter(|(_, v)| v.abs() > 0.1 * big)
            .map(|((c, _), _)| start.names[start.free[*c]].as_str())
            .collect();
        reasons.push(format!(
            "{} is a combination of the calibrated {}",
            start.names[pi],
            by.join(", ")
        ));
    }
    let kind = if reasons.iter().all(|r| r.contains("changes nothing")) {
        "not observable in these logs"
    } else {
        "redundant"
    };
    Some(format!(
        "{kind}: {} (residual Jacobian columns, {} samples)",
        reasons.join("; "),
        steps
    ))
}

/// The discretisation error of `stage`'s calibration at the log's rate (see
/// `crate::estimation::discretisation`).
/// The effects of `remaining` to rank on top of `cur` (with the chain
/// `names` found so far), each with its runner. Left out: those the
/// calibrated parameters already express on these logs and those that do
/// not derive, said in `skipped` (in the first round only), and those only
/// the range-bearing sensor reads, collected in `sensor` for the sensor's
/// own chain (see [`super::sensor`]).
pub(crate) fn to_rank(
    cur: &Stage,
    names: &[String],
    remaining: &[(String, String)],
    cat: &Catalogue,
    runs: &[Run],
    o: &FitOptions,
    (skipped, sensor): (&mut Named, &mut Named),
) -> Vec<(String, String, Runner)> {
    let first_round = names.is_empty();
    // each candidate derived and tried on its own thread: derivation is
    // in-process automatic differentiation, with no lock to wait for
    let tried: Vec<Tried> = remaining
        .par_iter()
        .map(|(name, _)| {
            let mut list = names.to_vec();
            list.push(name.clone());
            let mut aug = match cat.chains.runner(&list) {
                Ok(aug) => aug,
                Err(why) => return Tried::Failed(why.to_string()),
            };
            let start = seeded(&aug, &cur.runner, &cur.fit.p);
            let added = effect_params(&start, &cur.runner);
            if sensor_only(&start, &added) {
                return Tried::SensorOnly;
            }
            // an effect on the motion or the tracker that also moves the
            // range-bearing sensor (a sensor_offset has both mountings):
            // the sensor's share is calibrated and tested on the sightings,
            // in the sensor's chain; the motion's ranking, whose residuals
            // do not see it, holds it at its nominal value
            let sensor_part: Vec<usize> = added
                .iter()
                .copied()
                .filter(|&i| sensor_only(&start, &[i]))
                .collect();
            aug.free.retain(|i| !sensor_part.contains(i));
            let start = seeded(&aug, &cur.runner, &cur.fit.p);
            let motion_part = effect_params(&start, &cur.runner);
            // (tried there only where the logs have sightings to try it on)
            let also_sensor =
                !sensor_part.is_empty() && runs.iter().any(|r| !r.landmarks.is_empty());
            match redundancy(&start, &motion_part, runs, o) {
                Some(why) if also_sensor => Tried::SensorAndFailed(why),
                Some(why) => Tried::Failed(why),
                None => Tried::Ranked(Box::new(aug), also_sensor),
            }
        })
        .collect();
    let mut augmented = Vec::new();
    for ((name, doc), tried) in remaining.iter().zip(tried) {
        let to_sensor = matches!(
            tried,
            Tried::SensorOnly | Tried::SensorAndFailed(_) | Tried::Ranked(_, true)
        );
        if to_sensor && first_round {
            sensor.push((name.clone(), doc.clone()));
        }
        match tried {
            Tried::Ranked(aug, _) => augmented.push((name.clone(), doc.clone(), *aug)),
            Tried::Failed(why) if first_round => skipped.push((name.clone(), why)),
            Tried::SensorAndFailed(why) if first_round => skipped.push((
                name.clone(),
                format!("{why} (its range-bearing mounting is tested on the sightings)"),
            )),
            _ => {}
        }
    }
    augmented
}

/// What became of one candidate effect before ranking.
enum Tried {
    /// To be ranked, with its runner; and tried in the sensor's chain too
    /// (true) when part of it only the range-bearing sensor reads.
    Ranked(Box<Runner>, bool),
    /// Only the range-bearing sensor reads it: for the sensor's own chain.
    SensorOnly,
    /// Its motion part redundant with the calibration (why); its sensor
    /// part for the sensor's chain.
    SensorAndFailed(String),
    /// Not derived, or redundant with the calibration: why.
    Failed(String),
}

/// The stage after `w` won a round ranked from `augmented`: the ranking
/// calibrated the winner already, on all runs and on the training part.
/// Its step error is the current stage's until it is measured again.
pub(crate) fn winner_stage(
    cur: &Stage,
    augmented: &[(String, String, Runner)],
    w: &Candidate,
    runs: &[Run],
    test: &[Run],
    o: &FitOptions,
) -> Stage {
    let (_, _, aug) = augmented
        .iter()
        .find(|a| a.0 == w.effect)
        .expect("ranked from augmented");
    let mut runner = aug.clone();
    runner.p = w.fit.p.clone();
    Stage {
        step_error: cur.step_error,
        ..stage_from(runner, w.fit.clone(), w.train_fit.clone(), runs, test, o)
    }
}
