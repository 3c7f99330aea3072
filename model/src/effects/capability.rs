//! What a model has, asked of its structure, never its name: the
//! capabilities an effect requires and the classes of inputs it patches.
use crate::spec::{InputKind, Kinematics, Model, ObservationRole};
use serde::Deserialize;

/// What a model must have for an effect to mean anything.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Capability {
    /// An explicit body twist (`[motion]`), which twist templates patch.
    Twist,
    /// No lateral body velocity in the twist (wheels that cannot slide sideways).
    Nonholonomic,
    /// An absolute input: a steering angle read by an encoder.
    Steering,
    /// Cumulative inputs that turn the body both ways (left and right wheels).
    Differential,
    /// A yaw-rate observation (a gyro).
    YawRate,
}

/// Classes of inputs an `[[each_input]]` patch applies to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum InputClass {
    /// Absolute inputs (steering encoders).
    Steering,
    /// Cumulative inputs that turn the body counter-clockwise when they advance.
    RightWheel,
    /// Cumulative inputs that turn the body clockwise when they advance.
    LeftWheel,
    /// Commands: absolute inputs that hold from their row until the next
    /// (a velocity-commanded robot's speed and turn-rate set points).
    Command,
}

/// Which way advancing each input turns the body: the sign of d omega / d u_i at
/// the nominal parameters (0 for absolute inputs and for inputs that do not turn
/// the body). Evaluated numerically on the spec's own expressions; None for
/// constraint models, whose twist comes from a least-squares solve.
pub fn turn_signs(m: &Model) -> Option<Vec<i8>> {
    let Kinematics::Twist(tw) = &m.kinematics else {
        return None;
    };
    let omega = m.expand(&tw[2]);
    let at = |k: Option<usize>| {
        omega.eval(&|v: &str| {
            if let Some(p) = m.params.iter().find(|p| p.name == v) {
                return Some(p.nominal);
            }
            m.inputs
                .iter()
                .position(|i| i.name == v)
                .map(|i| if Some(i) == k { 1.0 } else { 0.0 })
                .or_else(|| m.noise.iter().any(|n| n.name == v).then_some(0.0))
        })
    };
    let w0 = at(None)?;
    Some(
        m.inputs
            .iter()
            .enumerate()
            .map(|(k, i)| {
                if i.kind != InputKind::Cumulative {
                    return 0;
                }
                match at(Some(k)).map(|w| w - w0) {
                    Some(d) if d > 1e-12 => 1,
                    Some(d) if d < -1e-12 => -1,
                    _ => 0,
                }
            })
            .collect(),
    )
}

/// Inputs of a class, by name.
pub fn inputs_of(m: &Model, class: InputClass) -> Vec<String> {
    let signs = turn_signs(m);
    m.inputs
        .iter()
        .enumerate()
        .filter(|(k, i)| match class {
            // an angle sampled from a joint (Between::Linear), not a command
            // that holds between rows: a speed command has no zero offset to read
            InputClass::Steering => {
                i.kind == InputKind::Absolute && i.between() == crate::decl::Between::Linear
            }
            InputClass::Command => i.is_command(),
            InputClass::RightWheel => signs.as_ref().is_some_and(|s| s[*k] > 0),
            InputClass::LeftWheel => signs.as_ref().is_some_and(|s| s[*k] < 0),
        })
        .map(|(_, i)| i.name.clone())
        .collect()
}

/// Whether the model has a capability, and if not, what it lacks (for people).
pub fn has(m: &Model, c: Capability) -> Result<(), &'static str> {
    let ok = match c {
        Capability::Twist => matches!(m.kinematics, Kinematics::Twist(_)),
        // vy is zero up to process noise
        Capability::Nonholonomic => matches!(&m.kinematics, Kinematics::Twist(t) if {
            let vy = m.expand(&t[1]);
            vy.variables().iter().all(|(v, _)| m.noise.iter().any(|n| n.name == *v)) && vy.eval(&|_| Some(0.0)) == Some(0.0)
        }),
        Capability::Steering => !inputs_of(m, InputClass::Steering).is_empty(),
        Capability::Differential => {
            !inputs_of(m, InputClass::RightWheel).is_empty()
                && !inputs_of(m, InputClass::LeftWheel).is_empty()
        }
        Capability::YawRate => m
            .observations
            .iter()
            .any(|o| o.role == ObservationRole::YawRate),
    };
    if ok {
        return Ok(());
    }
    Err(match c {
        Capability::Twist => "it patches an explicit body twist ([motion]) and this model is given by kinematic constraints",
        Capability::Nonholonomic => "it gives lateral velocity to a model that has none (vy = 0), and this model already moves sideways (its vy is not 0)",
        Capability::Steering => "the model has no absolute steering input (an angle read between rows; commands that hold are not)",
        Capability::Differential => "the model has no wheels that turn the body in opposite directions",
        Capability::YawRate => "the model has no yaw-rate (gyro) observation",
    })
}
