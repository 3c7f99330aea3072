//! Corrections of the range-bearing sensor beyond the catalogue: after the
//! sensor's catalogue chain ([`crate::diagnosis::sensor`]), a sparse
//! correction of its range and bearing, chosen from a library of terms a
//! camera or a lidar may be missing, each admitted only by the test a
//! catalogue sensor effect must pass (calibrated without each stretch of
//! the sightings in turn, it must predict the held-out stretch better, in a
//! paired t-test over the stretches, by more than the share worth naming).
//! So a clean log, or one whose sensor the catalogue explains, gets none.
//!
//! Why forward selection on the sightings, as for the twist
//! ([`super::twist`]): the sightings' errors persist for seconds, so a term
//! is judged by whole held-out stretches, not by its per-sighting fit; and
//! the same test the catalogue's sensor effects pass keeps the false
//! proposal rate at theirs.
use super::proposal::{Proposal, ScoredOn, Term, HEADER};
use crate::diagnosis::sensor::{candidate, grow, seeded, SensorDiagnosis};
use crate::estimation::fit::sensor::sensor_only;
use crate::model_on_log::derivation::EffectChains;
use crate::model_on_log::model::Runner;
use kinegen_model::effects::{Applicability, Effect};

/// At most this many terms in one proposal.
const MAX_TERMS: usize = 2;

/// The observation the terms correct, as an effect file names it.
const ROLE: &str = "range_bearing";

/// The library: `{0}` is the range read, `{1}` the bearing. Scales of the
/// range and offsets of the bearing are the catalogue's (`range_scale`,
/// `bearing_offset`), a depth read for the range too (`range_as_depth`), so
/// the library holds what they do not express.
const LIBRARY: &[Term] = &[
    Term {
        output: "range",
        short: "range_offset",
        expr: "1",
        unit: "m",
        reading: "a constant range error: the targets' centres behind their faces, or the sensor's zero off",
    },
    Term {
        output: "range",
        short: "range_squared",
        expr: "({0})^2",
        unit: "1/m",
        reading: "a range error growing with the distance squared: a stereo or target-size camera's depth error",
    },
    Term {
        output: "range",
        short: "range_by_side",
        expr: "({0})*sin({1})",
        unit: "1",
        reading: "ranges long on one side of the robot and short on the other: the sensor yawed against its targets, or a lens decentred",
    },
    Term {
        output: "bearing",
        short: "bearing_focal",
        expr: "sin(2*({1}))",
        unit: "rad",
        reading: "bearings stretched or squeezed off the axis (atan((1 + k) tan(bearing)) - bearing is about k/2 sin(2 bearing)): a camera's focal length or pixel size taken wrong",
    },
    Term {
        output: "bearing",
        short: "bearing_cubed",
        expr: "({1})^3",
        unit: "1/rad^2",
        reading: "bearings bent toward the edges of the view: radial lens distortion left uncorrected",
    },
];

/// The observation table of an effect adding `terms` to the channels.
fn observation_table(terms: &[&Term]) -> String {
    let channel = |c: &str, placeholder: &str| {
        let sum: Vec<String> = (terms.iter())
            .filter(|t| t.output == c)
            .map(|t| format!(" + {}*({})", t.gain(), t.expr))
            .collect();
        format!("({placeholder}){}", sum.concat())
    };
    format!(
        "\n[observation.{ROLE}]\nexpr = [\"{}\", \"{}\"]\n",
        channel("range", "{0}"),
        channel("bearing", "{1}")
    )
}

/// The library as effects (parsed like any effect file).
fn library() -> Vec<Effect> {
    LIBRARY
        .iter()
        .map(|t| {
            let text = format!(
                "name = \"term_{}\"\ndoc = \"{}\"\n{}{}",
                t.short,
                t.reading,
                t.parameter_table(),
                observation_table(&[t])
            );
            Effect::parse(std::path::Path::new("(proposal library)"), &text)
                .expect("the library's effect files parse")
        })
        .collect()
}

/// The proposal's effect file: every selected term added to its channel.
fn combined(name: &str, terms: &[&Term]) -> String {
    let params: String = terms.iter().map(|t| t.parameter_table()).collect();
    let readings: Vec<&str> = terms.iter().map(|t| t.reading).collect();
    format!(
        "{HEADER}name = \"{name}\"\ndoc = \"Proposed correction of the range-bearing sensor: {}.\"\n{params}{}",
        readings.join("; "),
        observation_table(terms)
    )
}

fn proposal_name(terms: &[&Term]) -> String {
    let range = terms.iter().any(|t| t.output == "range");
    let bearing = terms.iter().any(|t| t.output == "bearing");
    match (range, bearing) {
        (true, true) => "proposed_sensor_correction",
        (true, false) => "proposed_range_correction",
        _ => "proposed_bearing_correction",
    }
    .to_string()
}

/// The proposal on top of the sensor's diagnosis `sd` (on top of the
/// motion's chain `motion`, calibrated as `motion_runner`), or None when no
/// term of the library holds on the sightings.
pub(crate) fn propose(
    sd: &SensorDiagnosis,
    motion_runner: &Runner,
    chains: &EffectChains,
    motion: &[String],
) -> Option<Proposal> {
    let lib: Vec<Effect> = (library().into_iter())
        .filter(|e| e.applicability(chains.spec) == Applicability::Applies)
        .collect();
    if lib.is_empty() {
        return None;
    }
    let mut extended: Vec<Effect> = chains.catalogue.to_vec();
    extended.extend(lib.iter().cloned());
    let library_chains = EffectChains {
        catalogue: &extended,
        ..*chains
    };
    let effects: Vec<(String, String)> = (lib.iter())
        .map(|e| (e.name.clone(), e.doc.clone()))
        .collect();
    let at = &sd.chain;
    let s = &sd.sightings;
    let grown = grow(
        s,
        motion_runner,
        (motion, at.clone()),
        &effects,
        &library_chains,
        MAX_TERMS,
    );
    let terms: Vec<&Term> = (grown.found[at.found.len()..].iter())
        .filter_map(|c| (LIBRARY.iter()).find(|t| format!("term_{}", t.short) == c.effect))
        .collect();
    if terms.is_empty() {
        return None;
    }
    // the terms as one effect, calibrated afresh from the selection's values
    // and tested once more against the sensor's catalogue chain
    let name = proposal_name(&terms);
    let toml = combined(&name, &terms);
    let effect = Effect::parse(std::path::Path::new("(proposal)"), &toml).ok()?;
    let mut with: Vec<Effect> = chains.catalogue.to_vec();
    with.push(effect);
    let final_chains = EffectChains {
        catalogue: &with,
        ..*chains
    };
    let mut list: Vec<String> = motion.to_vec();
    list.extend(at.found.iter().map(|c| c.effect.clone()));
    list.push(name.clone());
    let runner = final_chains.runner(&list).ok()?;
    let start = seeded(&runner, &grown.runner, &grown.p);
    let free: Vec<usize> = (runner.free.iter().copied())
        .filter(|&i| motion_runner.param_index(&runner.names[i]).is_none())
        .filter(|&i| sensor_only(&runner, &[i]))
        .collect();
    let new: Vec<usize> = (free.iter().copied())
        .filter(|&i| at.runner.param_index(&runner.names[i]).is_none())
        .collect();
    let (base, _) = s.residuals(&at.runner, &at.p, &[], false);
    let c = candidate(s, &with, (&name, ""), (&runner, &start), &free, &base, &new);
    c.significant.then(|| {
        Proposal::of_terms(
            name,
            toml,
            &terms,
            c.parameters,
            ScoredOn::Sightings,
            (c.fit.held_out_before, c.fit.held_out_after),
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every term of the library, and a proposal of two, is an effect file
    /// that parses, with its gains as parameters.
    #[test]
    fn the_library_and_its_proposals_are_effect_files() {
        assert_eq!(library().len(), LIBRARY.len());
        let terms: Vec<&Term> = vec![&LIBRARY[1], &LIBRARY[4]];
        let toml = combined(&proposal_name(&terms), &terms);
        let e = Effect::parse(std::path::Path::new("p.toml"), &toml).unwrap();
        assert_eq!(e.name, "proposed_sensor_correction");
        let names: Vec<&str> = e.parameters.iter().map(|p| p.name.as_str()).collect();
        assert_eq!(names, ["k_range_squared", "k_bearing_cubed"]);
        assert!(
            toml.contains(
                "expr = [\"({0}) + k_range_squared*(({0})^2)\", \"({1}) + k_bearing_cubed*(({1})^3)\"]"
            ),
            "{toml}"
        );
    }
}
