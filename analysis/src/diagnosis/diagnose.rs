//! Which physical effect is missing?
//!
//! 1. Calibrate the base model.
//! 2. For each applicable catalogue effect: calibrate the augmented model and score
//!    it on the weighted residual (RMS), the Bayesian information criterion (so an
//!    extra parameter that only fits noise is not rewarded) and the error on
//!    held-out segments (last 40% of every run, fitted on the first 60%).
//! 3. Evidence: how well the base model's residual lines up with the effect's own
//!    signature (the sensitivity of the predictions to its parameter at zero).
//! 4. Whiteness: regress the one-step prediction residuals of the best model on
//!    motion features; structure that motion explains means something is still
//!    missing, and the channel and feature say where.
use super::clock::{ClockVerdict, SightingClock, Unmeasured};
use super::folds::{FoldTest, Folds};
use super::propose::proposal::Proposal;
use super::sensor::{diagnose_sensor, SensorCandidate, SensorUnmeasured, SightingFit};
use crate::estimation::discretisation::Discretisation;
use crate::estimation::fit::{FitError, FitOptions, FitResult};
use crate::model_on_log::derivation::EffectChains;
use crate::model_on_log::model::Runner;
use crate::model_on_log::run::Run;
use serde::Serialize;

use super::estimate::Estimates;
use super::ranking::{rank, ranked_equivalents, Candidate};
use super::stage::{leaves_only_noise, split, stage, weighted_rms, Stage};
use super::structure::{whiteness, Structure};
use super::trial::{to_rank, winner_stage, Catalogue};

pub struct Diagnosis {
    pub baseline_rmse: f64,
    pub calibrated_rmse: f64,
    pub base_fit: FitResult,
    pub base_holdout_rmse: f64,
    pub candidates: Vec<Candidate>,
    /// Every effect found, in the order sequential diagnosis added them.
    pub chain: Vec<ChainStep>,
    /// What remains in the residuals of the final model (base plus chain).
    pub structure: Structure,
    /// The model's own discretisation error at the log's rate (counted with
    /// the noise floor when effects are judged): the calibrated base model's,
    /// or that of the chain's stage it was estimated at again (see
    /// [`RECHECK_STEP`]).
    pub discretisation: Discretisation,
    /// The noise floor (see `fit::noise_floor`) of the calibration the
    /// discretisation error was estimated at.
    pub noise_floor: f64,
    pub skipped: Vec<(String, String)>,
    /// How far the ground truth lags the landmark sightings, when the logs
    /// have both (what tells a late motion capture from a late command).
    pub clock: Option<SightingClock>,
    /// Why the logs' sightings and ground truth did not measure it.
    pub clock_unmeasured: Option<Unmeasured>,
    /// What the sightings say of the measurement delay the spec itself
    /// declares, as calibrated (None: it declares none, or no clock).
    pub spec_clock: Option<ClockVerdict>,
    /// The range-bearing sensor's effects, tested on the sightings seen from
    /// the ground truth (see [`super::sensor`]): the first round's
    /// candidates (their effects found are at the end of `chain`).
    pub sensor_candidates: Vec<SensorCandidate>,
    /// Why the sensor's effects were not tested, where the catalogue has some.
    pub sensor_unmeasured: Option<SensorUnmeasured>,
    /// Corrections beyond the catalogue (see [`super::propose`]): of the
    /// twist, when structure was left in the track after the last catalogue
    /// effect and a library term explains it, then of the range-bearing
    /// sensor, when a library term holds on the sightings.
    pub proposed: Vec<Proposal>,
    /// The final model and its calibrated parameters.
    pub final_runner: Runner,
    pub final_p: Vec<f64>,
}

impl Diagnosis {
    /// The verdict: the first effect of the chain (None: no catalogue effect is significant).
    pub fn verdict(&self) -> Option<&str> {
        self.chain.first().map(|c| c.effect.as_str())
    }

    /// What the sightings say of the measurement delay `base` (the spec as
    /// the user wrote it) declares, in words (see [`ClockVerdict::of_spec_delay`]).
    pub fn spec_clock_said(&self, base: &Runner) -> Option<String> {
        let name = base.delay.map(|i| base.names[i].as_str())?;
        self.spec_clock.map(|v| v.of_spec_delay(name))
    }
}

/// One step of the chain found by sequential diagnosis.
#[derive(Debug, Clone, Serialize)]
pub struct ChainStep {
    pub effect: String,
    pub parameters: Estimates,
    /// Error (weighted residual RMS) after adding this effect and recalibrating.
    pub rmse_after: f64,
    pub doc: String,
    /// Other significant candidates these logs cannot tell apart from it:
    /// their fit's likelihood ratio to its own under [`EQUIVALENT`] (a late
    /// command and a late motion capture move a pose-only log alike).
    pub equivalent: Vec<String>,
    /// The fold-by-fold test, when it is what proved the effect.
    pub folds: Option<FoldTest>,
    /// For an effect of the range-bearing sensor, how it fits the sightings
    /// seen from the ground truth, which is what proved it (the motion's
    /// error, `rmse_after`, does not move).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sightings: Option<SightingFit>,
}

/// A diagnosis that cannot run.
#[derive(Debug, thiserror::Error)]
pub enum DiagnoseError {
    #[error("{run}: {rows} rows; diagnosis needs at least {MIN_ROWS} per run (it holds out the last 40% of each)")]
    TooFewRows { run: String, rows: usize },
    #[error(transparent)]
    Fit(#[from] FitError),
}

fn step_error(stage: &Stage, runs: &[Run], o: &FitOptions) -> Discretisation {
    let mut d = crate::estimation::discretisation::estimate(
        &stage.runner,
        &stage.fit.p,
        &stage.fit.starts,
        runs,
        o,
    );
    // the asymptotic e(2h) = 4 e(h) overstates the error of a coarse log
    // (larger steps err faster than that); the step cannot leave more than
    // what the calibrated model leaves above the noise
    let excess = (stage.rmse * stage.rmse - stage.floor * stage.floor)
        .max(0.0)
        .sqrt();
    d.error = d.error.min(excess);
    d
}

/// Share of a chain stage's noise floor above which the step's error, as
/// estimated at an earlier stage, is estimated again at this one. A model
/// far off the log (a rover missing a 0.08 rad steering offset: error 230
/// against a floor of 13) gives a meaningless Richardson estimate (its fits
/// at the two rates differ for reasons of their own), capped only by its own
/// excess: 3.8, which then hid every further effect (a 0.1 s time offset)
/// of the stage that reached 1.5. Stages whose step's error is already small
/// next to their floor (every bench case) are not checked again.
const RECHECK_STEP: f64 = 0.5;

/// Fewest rows per run diagnosis accepts.
pub const MIN_ROWS: usize = 20;

/// Longest chain sequential diagnosis builds: more effects than this at once
/// are not told apart reliably by a log of ordinary length.
pub const MAX_CHAIN: usize = 3;

/// The sightings' clock on `runs` (see [`super::clock`]) through the base
/// model's calibration, or why it was not measured; and what it says of the
/// measurement delay the spec itself declares, as calibrated.
fn read_clock(
    first: &Stage,
    runs: &[Run],
) -> (
    Option<SightingClock>,
    Option<Unmeasured>,
    Option<ClockVerdict>,
) {
    let (clock, unmeasured) = match super::clock::measure(&first.runner, &first.fit.p, runs) {
        Some(Ok(c)) => (Some(c), None),
        Some(Err(why)) => (None, Some(why)),
        None => (None, None),
    };
    let spec = clock.zip(first.runner.delay).and_then(|(c, _)| {
        c.judge(
            0.0,
            crate::model_on_log::timeline::delay(&first.runner, &first.fit.p),
        )
    });
    (clock, unmeasured, spec)
}

/// The sensor's diagnosis after the motion's (see [`super::sensor`]): its
/// first round's candidates, or why it did not run, and the final model.
struct SensorOutcome {
    candidates: Vec<SensorCandidate>,
    /// A correction beyond the catalogue the sightings support.
    proposed: Option<Proposal>,
    unmeasured: Option<SensorUnmeasured>,
    runner: Runner,
    p: Vec<f64>,
}

/// Test the range-bearing sensor's `effects` on top of the motion's final
/// stage `cur`, appending the ones found to `chain` (the motion's error does
/// not move with them: they are proved on the sightings).
fn sensor_chain(
    cur: Stage,
    runs: &[Run],
    effects: &[(String, String)],
    chains: &EffectChains,
    chain: &mut Vec<ChainStep>,
) -> SensorOutcome {
    let unchanged = |unmeasured| SensorOutcome {
        candidates: vec![],
        proposed: None,
        unmeasured,
        runner: cur.runner.clone(),
        p: cur.fit.p.clone(),
    };
    if effects.is_empty() {
        return unchanged(None);
    }
    let motion: Vec<String> = chain.iter().map(|c| c.effect.clone()).collect();
    match diagnose_sensor(&cur.runner, &cur.fit.p, runs, effects, chains, &motion) {
        Ok(sd) => {
            let proposed = super::propose::sightings::propose(&sd, &cur.runner, chains, &motion);
            chain.extend(sd.chain.found.iter().map(|c| ChainStep {
                effect: c.effect.clone(),
                parameters: c.parameters.clone(),
                rmse_after: cur.rmse,
                doc: c.doc.clone(),
                equivalent: vec![],
                folds: None,
                sightings: Some(c.fit.clone()),
            }));
            SensorOutcome {
                candidates: sd.chain.candidates,
                proposed,
                unmeasured: None,
                runner: sd.chain.runner,
                p: sd.chain.p,
            }
        }
        Err(why) => unchanged(Some(why)),
    }
}

impl ChainStep {
    /// The chain's step for a round's winner `w`, with the candidates the
    /// logs cannot tell apart from it.
    fn won(w: &Candidate, equivalent: Vec<String>) -> ChainStep {
        ChainStep {
            effect: w.effect.clone(),
            parameters: w.parameters.clone(),
            rmse_after: w.rmse,
            doc: w.doc.clone(),
            equivalent,
            folds: w.folds.filter(|_| w.by_folds()),
            sightings: None,
        }
    }
}

/// The twist's proposal beyond the catalogue: on top of the chain's last
/// stage `cur` (`cx.chain` its effects), or, where none holds there,
/// instead of the chain, from the calibrated spec `base`, when it predicts
/// the held-out part better than the chain does. A catalogue effect can
/// stand in for one the catalogue cannot express (a command deadband as
/// wide as the largest turn-rate commands, for a response that falls off
/// at them), and once it is in, no term on top of it passes the tests.
///
/// Tried where the one-step residuals show structure (`structured`), or
/// where the track's error is still above the noise floor: an effect on the
/// turn rate that a noisy ground truth hides step by step (a curved command
/// response under 3x the simulator's noise: no structure found, 5.6 -> 0.49
/// with the true effect) still moves the whole track. The proposal's own
/// held-out and fold tests keep a clean log clean.
fn track_proposal(
    cur: &Stage,
    base: &Stage,
    structured: bool,
    cx: &super::propose::twist::Context,
    progress: &(dyn Fn(&str) + Sync),
) -> Option<Proposal> {
    use super::propose::twist::{propose, Context};
    if !structured && leaves_only_noise(cur) {
        return None;
    }
    if let Some(p) = propose(cur, cx, progress) {
        return Some(p);
    }
    if cx.chain.is_empty() {
        return None;
    }
    let from_base = Context { chain: &[], ..*cx };
    let mut p = propose(base, &from_base, progress)?;
    // instead of the chain only where it beats it on the held-out part
    (p.held_out_after < cur.holdout_rmse).then(|| {
        p.instead_of = cx.chain.to_vec();
        p
    })
}

/// Run the diagnosis: calibrate the base model, rank every applicable effect,
/// add the best significant one, re-test the rest on the augmented model, and
/// repeat until nothing is significant. `skipped` collects effects not tested,
/// with the reason (redundant on these logs, not derivable...).
///
/// `progress` is called with a step's name after each calibration (from worker
/// threads), for a progress bar.
pub fn diagnose(
    base: &Runner,
    runs: &[Run],
    cat: &Catalogue,
    mut skipped: Vec<(String, String)>,
    progress: &(dyn Fn(&str) + Sync),
) -> Result<Diagnosis, DiagnoseError> {
    // Beside a ground truth the sightings measure the sensor, not the motion
    // (fit sees them from the truth's pose): they are the sensor's chain's
    // to judge ([`super::sensor`]). In the motion's cost they only moved
    // `sensor_offset`'s range-bearing half, which then stood in for a camera
    // reading depth (named first on a simulated robot whose camera does).
    // Without a ground truth they are the motion's only pose information.
    let o = FitOptions {
        use_landmarks: runs
            .iter()
            .any(|r| r.gt.is_none() && !r.landmarks.is_empty()),
        ..FitOptions::default()
    };
    if let Some(r) = runs.iter().find(|r| r.t.len() < MIN_ROWS) {
        return Err(DiagnoseError::TooFewRows {
            run: r.name.clone(),
            rows: r.t.len(),
        });
    }
    let baseline_rmse = weighted_rms(base, &base.p, runs, &o);
    let (train, test) = split(runs, 0.6);
    let folds = Folds::of(runs);
    let first = stage(base.clone(), runs, &train, &test, &o)?;
    progress("base model calibrated");
    let (clock, clock_unmeasured, spec_clock) = read_clock(&first, runs);
    let mut disc = step_error(&first, runs, &o);
    let first = Stage {
        step_error: disc.error,
        ..first
    };
    let (calibrated_rmse, base_fit, base_holdout_rmse) =
        (first.rmse, first.fit.clone(), first.holdout_rmse);
    let mut noise_floor = first.floor;

    let base_stage = first.clone();
    let mut cur = first;
    let mut chain: Vec<ChainStep> = Vec::new();
    let mut first_candidates: Option<Vec<Candidate>> = None;
    let mut remaining: Vec<(String, String)> = cat.effects.clone();
    let mut sensor_effects: Vec<(String, String)> = Vec::new();
    while chain.len() < MAX_CHAIN
        && !remaining.is_empty()
        && (chain.is_empty() || !leaves_only_noise(&cur))
    {
        let names: Vec<String> = chain.iter().map(|c| c.effect.clone()).collect();
        let first_round = (&mut skipped, &mut sensor_effects);
        let augmented = to_rank(&cur, &names, &remaining, cat, runs, &o, first_round);
        let ranked = rank(
            &cur,
            chain.is_empty(),
            &augmented,
            runs,
            &train,
            &test,
            folds.as_ref(),
            clock.as_ref(),
            cat.chains.catalogue,
            &o,
            progress,
        );
        let winner = ranked.first().filter(|c| c.significant).cloned();
        let equivalent = winner
            .as_ref()
            .map(|w| ranked_equivalents(&ranked, w))
            .unwrap_or_default();
        if first_candidates.is_none() {
            first_candidates = Some(ranked);
        }
        let Some(w) = winner else { break };
        let mut next = winner_stage(&cur, &augmented, &w, runs, &test, &o);
        if next.step_error > RECHECK_STEP * next.floor {
            disc = step_error(&next, runs, &o);
            (next.step_error, noise_floor) = (disc.error, next.floor);
        }
        chain.push(ChainStep::won(&w, equivalent));
        remaining.retain(|(n, _)| n != &w.effect);
        cur = next;
    }
    let structure = whiteness(&cur.runner, &cur.fit.p, runs);
    let names: Vec<String> = chain.iter().map(|c| c.effect.clone()).collect();
    let cx = super::propose::twist::Context {
        chains: cat.chains,
        chain: &names,
        runs,
        train: &train,
        test: &test,
        folds: folds.as_ref(),
        o: &o,
    };
    let proposed = track_proposal(&cur, &base_stage, structure.structured, &cx, progress);
    let sensor = sensor_chain(cur, runs, &sensor_effects, cat.chains, &mut chain);
    progress("sensor effects tested");
    Ok(Diagnosis {
        baseline_rmse,
        calibrated_rmse,
        base_fit,
        base_holdout_rmse,
        candidates: first_candidates.unwrap_or_default(),
        chain,
        structure,
        discretisation: disc,
        noise_floor,
        skipped,
        clock,
        clock_unmeasured,
        spec_clock,
        sensor_candidates: sensor.candidates,
        sensor_unmeasured: sensor.unmeasured,
        proposed: proposed.into_iter().chain(sensor.proposed).collect(),
        final_runner: sensor.runner,
        final_p: sensor.p,
    })
}
