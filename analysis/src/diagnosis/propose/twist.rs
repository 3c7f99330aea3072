//! Corrections of the twist beyond the catalogue: when structure is left after the last
//! catalogue effect, a sparse correction of the twist, chosen from a library
//! of physically meaningful terms by forward selection, each term admitted
//! only when it passes the same held-out and fold tests a catalogue effect
//! must pass (so a clean log, or one the catalogue explains, gets none), and
//! rendered as a complete effect file that `add-effect --effects DIR`
//! applies.
//!
//! Forward selection rather than SINDy's thresholded least squares: each
//! term's worth is judged on the whole trajectory (a term in the turn rate
//! acts on the pose through the integration, which a regression on
//! per-step residuals does not see), with the calibration and significance
//! tests the catalogue's effects already have.
use super::proposal::{Proposal, ScoredOn, Term, HEADER};
use crate::diagnosis::estimate::{Estimate, Estimates};
use crate::diagnosis::folds::Folds;
use crate::diagnosis::ranking::rank;
use crate::diagnosis::stage::{seeded, stage_from, Stage};
use crate::diagnosis::trial::{to_rank, winner_stage, Catalogue};
use crate::estimation::fit::FitOptions;
use crate::model_on_log::derivation::EffectChains;
use crate::model_on_log::model::Runner;
use crate::model_on_log::run::Run;
use kinegen_model::effects::Effect;

/// At most this many terms in one proposal: more would fit noise before
/// the held-out test could tell.
const MAX_TERMS: usize = 2;

const LIBRARY: &[Term] = &[
    Term {
        output: "omega",
        short: "omega_abs_omega",
        expr: "abs({omega})*({omega})",
        unit: "s/rad",
        reading: "turn rate lost in proportion to |omega|: tyre scrub or skidding in tight turns",
    },
    Term {
        output: "omega",
        short: "sign_omega",
        expr: "sign({omega})",
        unit: "rad/s",
        reading:
            "a constant turn rate lost whenever the robot turns: friction or a deadband in turning",
    },
    Term {
        output: "omega",
        short: "omega_cubed",
        expr: "({omega})^3",
        unit: "s^2/rad^2",
        reading: "turn rate saturating at high rates: a motor or controller limit",
    },
    Term {
        output: "omega",
        short: "speed_omega",
        expr: "abs({vx})*({omega})",
        unit: "s/m",
        reading: "turn rate falling with speed: understeer",
    },
    Term {
        output: "vx",
        short: "vx_abs_vx",
        expr: "abs({vx})*({vx})",
        unit: "s/m",
        reading: "speed lost in proportion to speed squared: slip or drag growing with speed",
    },
    Term {
        output: "vx",
        short: "sign_vx",
        expr: "sign({vx})",
        unit: "m/s",
        reading: "a constant speed lost whenever the robot drives: a deadband or static friction",
    },
    Term {
        output: "vx",
        short: "turning_vx",
        expr: "abs({omega})*({vx})",
        unit: "s/rad",
        reading: "forward speed lost while turning: longitudinal slip in turns",
    },
    Term {
        output: "vx",
        short: "vx_cubed",
        expr: "({vx})^3",
        unit: "s^2/m^2",
        reading: "speed saturating at high commands: a motor limit",
    },
];

/// The effect file of one library term (its gain at 0, bounded).
fn term_effect(t: &Term) -> String {
    let c = t.output;
    format!(
        "name = \"term_{}\"\ndoc = \"{}\"\nrequires = [\"twist\"]\n{}\n[motion]\n{c} = \"({{{c}}}) + {}*({})\"\n",
        t.short,
        t.reading,
        t.parameter_table(),
        t.gain(),
        t.expr
    )
}

/// The library as effects (parsed like any effect file).
fn library() -> Vec<Effect> {
    LIBRARY
        .iter()
        .map(|t| {
            Effect::parse(std::path::Path::new("(proposal library)"), &term_effect(t))
                .expect("the library's effect files parse")
        })
        .collect()
}

/// The proposal's effect file: every selected term added to its component
/// of the original twist.
fn combined(name: &str, terms: &[&Term]) -> String {
    let mut motion = String::new();
    for c in ["vx", "omega"] {
        let sum: Vec<String> = (terms.iter())
            .filter(|t| t.output == c)
            .map(|t| format!("{}*({})", t.gain(), t.expr))
            .collect();
        if !sum.is_empty() {
            motion += &format!("{c} = \"({{{c}}}) + {}\"\n", sum.join(" + "));
        }
    }
    let params: String = terms.iter().map(|t| t.parameter_table()).collect();
    let readings: Vec<&str> = terms.iter().map(|t| t.reading).collect();
    format!(
        "{HEADER}name = \"{name}\"\ndoc = \"Proposed correction: {}.\"\nrequires = [\"twist\"]\n{params}\n[motion]\n{motion}",
        readings.join("; ")
    )
}

fn proposal_name(terms: &[&Term]) -> String {
    let speed = terms.iter().any(|t| t.output == "vx");
    let turn = terms.iter().any(|t| t.output == "omega");
    match (speed, turn) {
        (true, true) => "proposed_twist_correction",
        (true, false) => "proposed_speed_correction",
        _ => "proposed_turn_rate_correction",
    }
    .to_string()
}

/// Everything the selection reads from the diagnosis it extends.
pub(crate) struct Context<'a> {
    pub chains: &'a EffectChains<'a>,
    /// The catalogue effects the chain found (applied before any term).
    pub chain: &'a [String],
    pub runs: &'a [Run],
    pub train: &'a [Run],
    pub test: &'a [Run],
    pub folds: Option<&'a Folds>,
    pub o: &'a FitOptions,
}

/// `start` calibrated from its values on all runs and on the training part
/// (the training part refined from the whole runs' optimum).
fn refined(start: Runner, cx: &Context) -> Option<Stage> {
    use crate::estimation::fit::{fit, Search};
    let all = fit(&start, cx.runs, cx.o, Search::Local).ok()?;
    let mut from = start.clone();
    from.p = all.p.clone();
    let part = Search::OnPart {
        whole: cx.runs,
        starts: &all.starts,
    };
    let train = fit(&from, cx.train, cx.o, part).ok()?;
    Some(stage_from(start, all, train, cx.runs, cx.test, cx.o))
}

/// At most this many terms of a round are calibrated and tested: the ones
/// whose first-order gain on the current residual is largest.
const SCREENED: usize = 3;

/// The terms of `augmented` worth calibrating: by how much of the current
/// residual a Gauss-Newton step could remove with the term's gain and every
/// free parameter, beyond what the free parameters alone remove (orthogonal
/// matching pursuit's choice, the term's column taken orthogonal to the
/// calibration's), the [`SCREENED`] largest. Calibrating and testing every
/// term took 95 s of a 119 s diagnosis on a 61,000-row MRCLAM log.
fn screened(
    at: &Stage,
    augmented: Vec<(String, String, Runner)>,
    cx: &Context,
) -> Vec<(String, String, Runner)> {
    use rayon::prelude::*;
    let mut gains: Vec<(f64, (String, String, Runner))> = augmented
        .into_par_iter()
        .map(|(name, doc, aug)| {
            let start = seeded(&aug, &at.runner, &at.fit.p);
            let term = crate::diagnosis::ranking::effect_params(&start, &at.runner);
            (explained_beyond(&start, &term, cx), (name, doc, aug))
        })
        .collect();
    gains.sort_by(|a, b| b.0.total_cmp(&a.0));
    gains.into_iter().take(SCREENED).map(|g| g.1).collect()
}

/// |J x|^2 - |J0 x0|^2: the residual's squared norm a linearised step
/// removes with the free parameters and `term` (J), less what it removes
/// with the free parameters alone (J0).
fn explained_beyond(start: &Runner, term: &[usize], cx: &Context) -> f64 {
    use crate::estimation::fit::residuals;
    use nalgebra::{DMatrix, DVector};
    let o = FitOptions {
        estimate_start: false,
        ..cx.o.clone()
    };
    let mut cols: Vec<usize> = start
        .free
        .iter()
        .copied()
        .filter(|i| !term.contains(i))
        .collect();
    let base = cols.len();
    cols.extend(term);
    let (res, jac) = residuals(start, &start.p, &cols, cx.runs, &o, true, &[]);
    let Some(j) = jac else { return 0.0 };
    let r = DVector::from_vec(res);
    let explained = |m: DMatrix<f64>| -> f64 {
        if m.ncols() == 0 {
            return 0.0;
        }
        // scaled columns: the parameters' units differ by orders of magnitude
        let scale: Vec<f64> = (0..m.ncols())
            .map(|c| m.column(c).norm().max(1e-300))
            .collect();
        let mut s = m.clone();
        for (c, k) in scale.iter().enumerate() {
            s.column_mut(c).scale_mut(1.0 / k);
        }
        let Some(svd) = crate::model_on_log::linalg::svd(s.clone()) else {
            return 0.0;
        };
        let tol = 1e-9 * svd.singular_values.max();
        svd.solve(&r, tol).map_or(0.0, |x| (&s * x).norm_squared())
    };
    let j_all = DMatrix::from_iterator(j.nrows(), j.ncols(), j.iter().copied());
    let j_free = j_all.columns(0, base).into_owned();
    explained(j_all) - explained(j_free)
}

/// The proposal on top of `cur` (the diagnosis's final motion stage), or
/// None when no term of the library is significant.
pub(crate) fn propose(
    cur: &Stage,
    cx: &Context,
    progress: &(dyn Fn(&str) + Sync),
) -> Option<Proposal> {
    let twist =
        kinegen_model::effects::has(cx.chains.spec, kinegen_model::effects::Capability::Twist)
            .is_ok();
    if !twist {
        return None;
    }
    let mut extended: Vec<Effect> = cx.chains.catalogue.to_vec();
    let lib = library();
    extended.extend(lib.iter().cloned());
    let chains = EffectChains {
        catalogue: &extended,
        ..*cx.chains
    };
    let cat = Catalogue {
        effects: lib
            .iter()
            .map(|e| (e.name.clone(), e.doc.clone()))
            .collect(),
        chains: &chains,
    };
    let mut names: Vec<String> = cx.chain.to_vec();
    let mut chosen: Vec<&Term> = Vec::new();
    let mut remaining = cat.effects.clone();
    let mut stage_now: Option<Stage> = None;
    while chosen.len() < MAX_TERMS && !remaining.is_empty() {
        let at = stage_now.as_ref().unwrap_or(cur);
        let (mut skipped, mut sensor) = (Vec::new(), Vec::new());
        let augmented = to_rank(
            at,
            &names,
            &remaining,
            &cat,
            cx.runs,
            cx.o,
            (&mut skipped, &mut sensor),
        );
        let augmented = screened(at, augmented, cx);
        let ranked = rank(
            at, false, &augmented, cx.runs, cx.train, cx.test, cx.folds, None, &extended, cx.o,
            progress,
        );
        let Some(w) = ranked.first().filter(|c| c.significant) else {
            break;
        };
        let next = winner_stage(at, &augmented, w, cx.runs, cx.test, cx.o);
        let term = LIBRARY
            .iter()
            .find(|t| format!("term_{}", t.short) == w.effect)?;
        chosen.push(term);
        names.push(w.effect.clone());
        remaining.retain(|(n, _)| n != &w.effect);
        stage_now = Some(next);
    }
    let selected = stage_now?;
    // the terms as one effect, calibrated afresh from the selection's values
    let name = proposal_name(&chosen);
    let toml = combined(&name, &chosen);
    let effect = Effect::parse(std::path::Path::new("(proposal)"), &toml).ok()?;
    let mut with: Vec<Effect> = cx.chains.catalogue.to_vec();
    with.push(effect);
    let final_chains = EffectChains {
        catalogue: &with,
        ..*cx.chains
    };
    let mut list = cx.chain.to_vec();
    list.push(name.clone());
    let runner = final_chains.runner(&list).ok()?;
    let start = seeded(&runner, &selected.runner, &selected.fit.p);
    // the selection's values are the optimum's basin already: refined
    // locally (a global search again took two minutes on a 61,000-row
    // MRCLAM log and found the same optimum)
    let done = refined(start, cx)?;
    progress("proposed correction calibrated");
    let parameters: Estimates = chosen
        .iter()
        .filter_map(|t| {
            let g = t.gain();
            let i = done.runner.param_index(&g)?;
            let k = done.fit.free.iter().position(|&f| f == i)?;
            Some((
                g,
                Estimate {
                    estimate: done.fit.p[i],
                    std: done.fit.std.get(k).copied().unwrap_or(f64::NAN),
                },
            ))
        })
        .collect();
    Some(Proposal::of_terms(
        name,
        toml,
        &chosen,
        parameters,
        ScoredOn::Track,
        (cur.holdout_rmse, done.holdout_rmse),
    ))
}
