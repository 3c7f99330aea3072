//! What a proposal beyond the catalogue is, whichever residuals it was
//! found on: a complete effect file built from library terms, each term a
//! gain times a physically meaningful expression added to one output (a
//! twist component, or a channel of the range-bearing sensor), with its
//! held-out error before and after. The two proposers ([`super::twist`] on
//! the track, [`super::sightings`] on the sightings seen from the ground
//! truth) share this shape, so the command line, the report, the JSON and
//! the benchmark read both alike.
use crate::diagnosis::estimate::Estimates;
use serde::Serialize;

/// One term of a proposal library: the output it is added to (`omega`,
/// `range`...), its expression in the effect-file format (the output's
/// placeholders: `{omega}`, or `{0}` and `{1}` for an observation's
/// channels), the unit of its gain, and what a gain on it may be physically.
pub(crate) struct Term {
    pub output: &'static str,
    pub short: &'static str,
    pub expr: &'static str,
    pub unit: &'static str,
    pub reading: &'static str,
}

impl Term {
    /// The gain's parameter name, `k_` and the term's short name.
    pub fn gain(&self) -> String {
        format!("k_{}", self.short)
    }

    /// The gain's `[[parameter]]` table: nominal 0 (the spec as written),
    /// bounded so that a calibration cannot run away with it.
    pub fn parameter_table(&self) -> String {
        format!(
            "\n[[parameter]]\nname = \"{}\"\nnominal = 0.0\nunit = \"{}\"\nmin = -100.0\nmax = 100.0\ndoc = \"Gain of {}: {}.\"\n",
            self.gain(),
            self.unit,
            shown(self.expr),
            self.reading
        )
    }
}

/// Which residuals a proposal was found and scored on; its held-out figures
/// are in their units.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum ScoredOn {
    /// The track: the weighted RMS residual of `calibrated.holdout_rmse`.
    Track,
    /// The range-bearing sightings seen from the ground truth: the mean
    /// robust (Huber) loss of each stretch's sightings, calibrated without
    /// them, in units of the residuals' robust scale.
    Sightings,
}

/// A correction diagnose proposes: a complete effect file, its terms, its
/// calibrated gains and the held-out error before and after it.
#[derive(Debug, Clone, Serialize)]
pub struct Proposal {
    pub name: String,
    /// The effect file (`--effects DIR` format).
    pub toml: String,
    /// The terms, as the spec writes them (`|omega|*omega`, `bearing^3`).
    pub terms: Vec<String>,
    /// The output each term is added to (`omega`, `bearing`), and its gain's name.
    pub corrects: Vec<String>,
    pub gains: Vec<String>,
    pub parameters: Estimates,
    pub scored_on: ScoredOn,
    pub held_out_before: f64,
    pub held_out_after: f64,
    /// What the terms may be physically.
    pub reading: String,
    /// The catalogue effects the proposal stands instead of: empty when it
    /// is made on top of the diagnosis's chain; else the chain, which it
    /// predicts the held-out part better than (its effect file is then for
    /// the spec without them).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub instead_of: Vec<String>,
}

/// One term of a proposal as a reader wants it: the output it is added
/// to, the term, its gain's name and the gain as calibrated.
pub struct Correction<'a> {
    pub output: &'a str,
    pub term: &'a str,
    pub gain: &'a str,
    pub value: Option<&'a crate::diagnosis::estimate::Estimate>,
}

impl Proposal {
    /// Its terms, each with its output and its calibrated gain.
    pub fn corrections(&self) -> impl Iterator<Item = Correction<'_>> {
        (self.terms.iter().zip(&self.corrects).zip(&self.gains)).map(|((t, c), g)| Correction {
            output: c,
            term: t,
            gain: g,
            value: self.parameters.get(g),
        })
    }

    /// The proposal's fields that follow from its terms alone.
    pub(crate) fn of_terms(
        name: String,
        toml: String,
        terms: &[&Term],
        parameters: Estimates,
        scored_on: ScoredOn,
        held_out: (f64, f64),
    ) -> Proposal {
        Proposal {
            name,
            toml,
            terms: terms.iter().map(|t| shown(t.expr)).collect(),
            corrects: terms.iter().map(|t| t.output.to_string()).collect(),
            gains: terms.iter().map(|t| t.gain()).collect(),
            parameters,
            scored_on,
            held_out_before: held_out.0,
            held_out_after: held_out.1,
            reading: terms
                .iter()
                .map(|t| t.reading)
                .collect::<Vec<_>>()
                .join("; "),
            instead_of: Vec::new(),
        }
    }
}

/// The first line of every proposed effect file: what it is, and what not.
pub(crate) const HEADER: &str =
    "# proposed by kinegen diagnose: not a known physical effect, a correction the logs support\n";

/// A term as the spec writes it: `|omega|*omega`, `range^2`,
/// `sin(2*bearing)`: placeholders named, `abs` as bars, and the parentheses
/// around a lone name dropped where they are not a function's.
pub(crate) fn shown(expr: &str) -> String {
    let mut s = expr.to_string();
    for (placeholder, name) in [
        ("{vx}", "vx"),
        ("{omega}", "omega"),
        ("{0}", "range"),
        ("{1}", "bearing"),
    ] {
        s = s.replace(placeholder, name);
        s = s.replace(&format!("abs({name})"), &format!("|{name}|"));
        let wrapped = format!("({name})");
        while let Some(at) = (s.match_indices(&wrapped).map(|(i, _)| i))
            .find(|&i| !s[..i].ends_with(|c: char| c.is_alphanumeric()))
        {
            s.replace_range(at..at + wrapped.len(), name);
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn terms_read_as_the_spec_writes_them() {
        assert_eq!(shown("abs({omega})*({omega})"), "|omega|*omega");
        assert_eq!(shown("({1})^3"), "bearing^3");
        assert_eq!(shown("({0})^2"), "range^2");
        assert_eq!(shown("({0})*sin({1})"), "range*sin(bearing)");
        assert_eq!(shown("sin(2*({1}))"), "sin(2*bearing)");
        assert_eq!(shown("abs({vx})*({omega})"), "|vx|*omega");
    }
}
