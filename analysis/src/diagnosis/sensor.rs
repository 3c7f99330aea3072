//! What the range-bearing sensor itself misses: a camera that reads a
//! landmark's depth in place of its range, a range scale, a sensor turned on
//! its mount. These are the catalogue's effects whose parameters only the
//! landmark observation reads ([`sensor_only`]).
//!
//! Why apart from the motion's ranking ([`super::diagnose`]): their residuals
//! are the sightings', 2-3% of a log's (a camera at 2-4 Hz beside motion
//! capture at 100 Hz), so what they explain never moves the weighted error
//! the motion's candidates are judged by. Seen from the ground-truth pose,
//! the sightings do not depend on the motion model at all, so the sensor's
//! chain and the motion's are separate questions: each is calibrated and
//! tested on its own residuals. On MRCLAM's five real robots the camera's
//! range residual, seen from Vicon, falls from 5-12 cm to 2-4 cm (median
//! absolute) once the range is read as depth: the range was the largest
//! error the localisation's likelihood was paying for.
//!
//! Tested as the motion's long logs are: calibrated without each of
//! [`crate::estimation::fit::sensor::FOLDS`] stretches of the sightings in turn, the effect must predict the
//! held-out stretch better than the current model does, in a paired t-test
//! over the stretches ([`super::folds::paired`]), because a camera's errors
//! persist for seconds and its sightings are not independent. The loss is
//! Huber's, so a misread barcode does not decide it; the standard deviations
//! are the stretches' jackknife, for the same reason.
use super::estimate::{Estimate, Estimates};
use super::folds::{paired, FoldTest};
use crate::estimation::fit::sensor::{calibrate_with_folds, Sightings};
pub use crate::estimation::fit::sensor::{sensor_only, SensorUnmeasured};
use crate::model_on_log::derivation::EffectChains;
use crate::model_on_log::model::Runner;
use crate::model_on_log::robust::median;
use crate::model_on_log::run::Run;
use rayon::prelude::*;
use serde::Serialize;

/// Most sensor effects found in a row.
const MAX_CHAIN: usize = 3;

/// How an effect fits the sightings, seen from the ground truth.
#[derive(Debug, Clone, Serialize)]
pub struct SightingFit {
    /// Sightings with a ground-truth pose beside them.
    pub sightings: usize,
    /// Median absolute range residual, m, before and after the effect.
    pub range_before: f64,
    pub range_after: f64,
    /// Median absolute bearing residual, rad, before and after.
    pub bearing_before: f64,
    pub bearing_after: f64,
    /// The mean robust loss of a stretch's sightings, in units of the
    /// residuals' robust scale, before the effect and with it calibrated
    /// without that stretch.
    pub held_out_before: f64,
    pub held_out_after: f64,
    /// The stretch-by-stretch test against the current model.
    pub folds: FoldTest,
}

/// A sensor effect, calibrated on the sightings and tested.
#[derive(Debug, Clone, Serialize)]
pub struct SensorCandidate {
    pub effect: String,
    #[serde(skip)]
    pub doc: String,
    pub parameters: Estimates,
    pub fit: SightingFit,
    pub significant: bool,
    /// Why its estimates are not the physical effect (never a verdict then).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub unphysical: Option<String>,
    /// The calibrated parameter vector of its runner.
    #[serde(skip)]
    pub p: Vec<f64>,
}

/// Median absolute residual of each channel, in the spec's units.
fn medians(r: &Runner, res: &[f64]) -> [f64; 2] {
    let sig = crate::model_on_log::landmarks::sigma(r);
    [0, 1].map(|c| {
        let mut v: Vec<f64> = res
            .iter()
            .skip(c)
            .step_by(2)
            .map(|e| (e * sig[c]).abs())
            .collect();
        median(&mut v)
    })
}

/// Calibrate the sensor parameters `free` of `aug` (started at `start`) on
/// all the sightings and stretch by stretch, and test them against the
/// current model's sightings (`base`); the estimates reported are those of
/// `new`, the effect's own.
pub(crate) fn candidate(
    s: &Sightings,
    catalogue: &[kinegen_model::effects::Effect],
    (name, doc): (&str, &str),
    (aug, start): (&Runner, &[f64]),
    free: &[usize],
    base: &[f64],
    new: &[usize],
) -> SensorCandidate {
    let fit = calibrate_with_folds(s, aug, start, free);
    let (res, _) = s.residuals(aug, &fit.p, &[], false);
    let base_loss: Vec<f64> = (0..s.folds).map(|k| s.loss(base, |f| f == k)).collect();
    let aug_loss: Vec<f64> = fit.held_out.iter().map(|(l, _)| *l).collect();
    let folds = paired(&base_loss, &aug_loss, s.folds);
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
    let parameters = new
        .iter()
        .map(|&i| {
            let k = free
                .iter()
                .position(|&j| j == i)
                .expect("new ones are free");
            let estimate = Estimate {
                estimate: fit.p[i],
                std: fit.std[k],
            };
            (aug.names[i].clone(), estimate)
        })
        .collect();
    let ([range_before, bearing_before], [range_after, bearing_after]) =
        (medians(aug, base), medians(aug, &res));
    let unphysical = super::estimate::unphysical(catalogue, name, &parameters);
    SensorCandidate {
        effect: name.to_string(),
        doc: doc.to_string(),
        parameters,
        fit: SightingFit {
            sightings: s.count(),
            range_before,
            range_after,
            bearing_before,
            bearing_after,
            held_out_before: mean(&base_loss),
            held_out_after: mean(&aug_loss),
            folds,
        },
        significant: folds.holds() && unphysical.is_none(),
        unphysical,
        p: fit.p,
    }
}

/// The sensor's diagnosis: its chain, and the sightings it was judged on
/// (what a proposal beyond the catalogue is judged on too, at the same
/// scale).
pub struct SensorDiagnosis<'a> {
    pub chain: SensorChain,
    pub sightings: Sightings<'a>,
}

/// Test the sensor effects `effects` (name, doc) on top of `motion` (the
/// effects the motion's diagnosis found, `cur` its runner calibrated at
/// `p`): rank them by their held-out gain, add the best that holds, re-test
/// the rest, up to three (`MAX_CHAIN`).
pub fn diagnose_sensor<'a>(
    cur: &Runner,
    p: &[f64],
    runs: &'a [Run],
    effects: &[(String, String)],
    chains: &EffectChains,
    motion: &[String],
) -> Result<SensorDiagnosis<'a>, SensorUnmeasured> {
    let s = Sightings::of(cur, p, runs)?;
    let start = SensorChain {
        candidates: vec![],
        found: vec![],
        runner: cur.clone(),
        p: p.to_vec(),
    };
    let chain = grow(&s, cur, (motion, start), effects, chains, MAX_CHAIN);
    Ok(SensorDiagnosis {
        chain,
        sightings: s,
    })
}

/// A sensor chain: its first round's candidates, the effects found in
/// order (each calibrated with the ones before it), and the runner with all
/// of them at their calibrated values.
#[derive(Clone)]
pub struct SensorChain {
    pub candidates: Vec<SensorCandidate>,
    pub found: Vec<SensorCandidate>,
    pub runner: Runner,
    pub p: Vec<f64>,
}

/// Grow the chain `from` (on top of the effects `before` it; `motion` the
/// runner the sightings' parameters are counted against) with the best of
/// `effects` that holds on `s`, re-testing the rest, up to `max` effects;
/// the candidates of the result are this growth's first round.
pub(crate) fn grow(
    s: &Sightings,
    motion: &Runner,
    (before, from): (&[String], SensorChain),
    effects: &[(String, String)],
    chains: &EffectChains,
    max: usize,
) -> SensorChain {
    let SensorChain {
        mut found,
        mut runner,
        mut p,
        ..
    } = from;
    let at_start = found.len();
    let mut first: Option<Vec<SensorCandidate>> = None;
    let mut remaining = effects.to_vec();
    while found.len() - at_start < max && !remaining.is_empty() {
        let (base, _) = s.residuals(&runner, &p, &[], false);
        // each candidate on its own thread (derivation takes no lock)
        let mut ranked: Vec<(SensorCandidate, Runner)> = remaining
            .par_iter()
            .filter_map(|(name, doc)| {
                let mut list: Vec<String> = before.to_vec();
                list.extend(found.iter().map(|c| c.effect.clone()));
                list.push(name.clone());
                let aug = chains.runner(&list).ok()?;
                let start = seeded(&aug, &runner, &p);
                // the sensor's parameters: every one the motion's model lacks
                let free: Vec<usize> = aug
                    .free
                    .iter()
                    .copied()
                    .filter(|&i| motion.param_index(&aug.names[i]).is_none())
                    // the sensor's own: a mixed effect's other parameters
                    // (a tracker's offset) the sightings do not see
                    .filter(|&i| sensor_only(&aug, &[i]))
                    .collect();
                // what the spec change sets: the effect's own parameters
                let new: Vec<usize> = free
                    .iter()
                    .copied()
                    .filter(|&i| runner.param_index(&aug.names[i]).is_none())
                    .collect();
                let c = candidate(
                    s,
                    chains.catalogue,
                    (name, doc),
                    (&aug, &start),
                    &free,
                    &base,
                    &new,
                );
                Some((c, aug))
            })
            .collect();
        ranked.sort_by(|(a, _), (b, _)| {
            b.significant
                .cmp(&a.significant)
                .then(b.fit.folds.gain.total_cmp(&a.fit.folds.gain))
        });
        if first.is_none() {
            first = Some(ranked.iter().map(|(c, _)| c.clone()).collect());
        }
        let Some((w, aug)) = ranked.into_iter().next().filter(|(c, _)| c.significant) else {
            break;
        };
        remaining.retain(|(n, _)| n != &w.effect);
        (runner, p) = (aug, w.p.clone());
        found.push(w);
    }
    SensorChain {
        candidates: first.unwrap_or_default(),
        found,
        runner,
        p,
    }
}

/// `aug`'s parameters at `from`'s values where it has them.
pub(crate) fn seeded(aug: &Runner, from: &Runner, p: &[f64]) -> Vec<f64> {
    let mut q = aug.p.clone();
    for (i, n) in from.names.iter().enumerate() {
        if let Some(j) = aug.param_index(n) {
            q[j] = p[i];
        }
    }
    q
}

/// Every sighting's range error (measured - predicted, m) against its
/// bearing, seen from the ground truth, for `r` at `p`: what a camera that
/// reads depth looks like (short at the edges of its view). A sighting the
/// truth cannot place is left out, as the sensor's calibration leaves it.
pub fn range_errors_by_bearing(r: &Runner, p: &[f64], runs: &[Run]) -> Vec<(f64, f64)> {
    let sigma_range = crate::model_on_log::landmarks::sigma(r)[0];
    runs.iter()
        .flat_map(|run| {
            let (res, _) = crate::estimation::fit::sightings_from_truth(r, p, &[], run, false);
            // the same sightings, in the same order, as the residuals
            let placed = run.landmarks.iter().filter(|o| {
                run.gt.as_ref().is_some_and(|gt| {
                    crate::model_on_log::innovations::truth_at(run, gt, o.t).is_some()
                })
            });
            let range = res
                .chunks(2)
                .map(|c| -c[0] * sigma_range)
                .collect::<Vec<_>>();
            placed.map(|o| o.bearing).zip(range).collect::<Vec<_>>()
        })
        .collect()
}
