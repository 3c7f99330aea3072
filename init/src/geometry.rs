//! Numbers of the description as parameters: one quantity measured from the
//! URDF, checked against the controller's value of it, with the chosen
//! nominal, its tolerance and a comment saying where both came from.
use crate::controller::Controller;
use crate::error::InitError;
use crate::robot::{tolerance, ParamOut};

/// A quantity as the URDF gives it.
pub struct FromUrdf {
    pub value: f64,
    /// The digits it was computed from (their precision is its tolerance).
    pub text: String,
    /// Where: "line 40, `left_wheel` cylinder radius".
    pub source: String,
}

/// A quantity as the controller gives it (already times its multiplier).
pub struct FromController {
    pub value: f64,
    /// The base number's digits (its precision).
    pub text: String,
    /// As shown to people: `0.35 x 1.02` with a multiplier.
    pub shown: String,
    pub key: String,
    pub line: usize,
}

/// Ratios between two numbers of one length that say "the other unit".
const UNIT_RATIOS: [(f64, &str); 5] = [
    (1000.0, "millimetres against metres"),
    (100.0, "centimetres against metres"),
    (25.4, "millimetres against inches"),
    (39.37007874015748, "inches against metres"),
    (10.0, "millimetres against centimetres"),
];

pub struct Quantity<'a> {
    pub name: &'a str,
    pub unit: &'static str,
    pub doc: String,
    /// Smallest relative tolerance (how well such a quantity is ever known).
    pub floor: f64,
    pub urdf: FromUrdf,
    pub controller: Option<FromController>,
}

impl Quantity<'_> {
    /// The parameter, and a note when the two sources disagree. A ratio of
    /// a power of ten (or of an inch) between them is refused as a unit error.
    pub fn resolve(
        mut self,
        ctl: Option<&Controller>,
        notes: &mut Vec<String>,
    ) -> Result<ParamOut, InitError> {
        let u_tol = tolerance(&self.urdf.text, self.urdf.value, self.floor);
        let Some(c) = self.controller.take() else {
            return Ok(self.param(
                self.urdf.value,
                u_tol,
                format!("URDF: {}", self.urdf.source),
            ));
        };
        let ctl = ctl.expect("a controller value comes from a controller");
        let ratio = c.value / self.urdf.value;
        for (r, what) in UNIT_RATIOS {
            if (ratio / r - 1.0).abs() < 0.02 || (ratio * r - 1.0).abs() < 0.02 {
                return Err(InitError::at(
                    &ctl.file,
                    Some(c.line),
                    format!(
                        "inconsistent units: {} is {} here ({}) and {} in the URDF ({}): {what}? Both files are in metres (REP 103)",
                        self.name, c.shown, c.key, self.urdf.text, self.urdf.source
                    ),
                ));
            }
        }
        let c_tol = tolerance(&c.text, c.value, self.floor);
        let source = format!(
            "controller {} (line {}); URDF: {}",
            c.key, c.line, self.urdf.source
        );
        let gap = (c.value - self.urdf.value).abs();
        if gap > u_tol.max(c_tol) * 1e-6 && gap > 1e-12 {
            notes.push(format!(
                "{}: the controller says {} ({}, line {}), the URDF {} ({}); the spec uses the controller's {} (what the robot's odometry runs with), with a tolerance that covers both",
                self.name, c.shown, c.key, c.line, self.urdf.text, self.urdf.source, c.shown
            ));
        }
        // a disagreement is itself a measure of how well the number is known
        let tol = c_tol.max(gap);
        Ok(self.param(c.value, tol, source))
    }

    fn param(&self, nominal: f64, tolerance: f64, source: String) -> ParamOut {
        ParamOut {
            name: self.name.to_string(),
            nominal,
            unit: self.unit,
            min: Some(0.0),
            max: None,
            tolerance: Some(tolerance),
            free: true,
            doc: self.doc.clone(),
            source,
        }
    }
}

/// A controller's number under `key` times the multiplier under `mult` (if
/// any): the value its odometry uses.
pub fn controller_value(
    ctl: Option<&Controller>,
    key: &str,
    mult: Option<&str>,
) -> Result<Option<FromController>, InitError> {
    let Some(ctl) = ctl else { return Ok(None) };
    let Some((v, line, text)) = ctl.number(key)? else {
        return Ok(None);
    };
    let multiplier = match mult {
        Some(m) => ctl.number(m)?.map(|(value, _, t)| (m, value, t)),
        None => None,
    };
    Ok(Some(match multiplier {
        Some((m, value, t)) if value != 1.0 => FromController {
            value: v * value,
            shown: format!("{text} x {t}"),
            text,
            key: format!("{}.{key} x {m}", ctl.node),
            line,
        },
        _ => FromController {
            value: v,
            shown: text.clone(),
            text,
            key: format!("{}.{key}", ctl.node),
            line,
        },
    }))
}
