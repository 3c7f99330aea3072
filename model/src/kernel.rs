//! What a derived function is and what its arguments carry, as types.
//!
//! Every consumer of the IR (emitter, verification, analysis) asks for a kernel
//! by its [`Kernel`] and for an argument by its [`ArgRole`]; the emitted names
//! (`step_exact_jac_p`, `obs_gyro`, `dt`) are derived from them in one place.
use serde::{Deserialize, Serialize};

/// What an argument of a derived function carries.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ArgRole {
    /// The pose [x, y, theta].
    State,
    /// The inputs, in spec order.
    Inputs,
    /// The noise inputs, in spec order.
    Noise,
    /// The runtime (non-const) parameters, in spec order.
    Params,
    /// The step length, s: the one scalar argument.
    Dt,
    /// A mapped landmark's position [xl, yl].
    Landmark,
    /// A body twist [vx, vy, omega].
    Twist,
    /// A measured yaw rate [omega] (gyrodometry).
    YawRate,
    /// A pose increment [dx, dy, dtheta] in the start-of-step body frame.
    PoseIncrement,
    /// Absolute inputs the inverse kinematics needs as configuration.
    Configuration,
    /// Anonymous values (numeric checks inside the derive stage).
    Values,
}

impl ArgRole {
    /// The argument's name in emitted code and documentation.
    pub fn ident(self) -> &'static str {
        match self {
            ArgRole::State => "x",
            ArgRole::Inputs => "u",
            ArgRole::Noise => "w",
            ArgRole::Params => "p",
            ArgRole::Dt => "dt",
            ArgRole::Landmark => "lm",
            ArgRole::Twist => "twist",
            ArgRole::YawRate => "omega",
            ArgRole::PoseIncrement => "dpose",
            ArgRole::Configuration => "cfg",
            ArgRole::Values => "v",
        }
    }
}

/// Scalar or vector of n.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ArgKind {
    Scalar,
    Vector(usize),
}

/// One argument of a derived function: its role and the names of its elements.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ArgSpec {
    pub role: ArgRole,
    pub names: Vec<String>,
}

impl ArgSpec {
    /// `dt` is passed as a scalar, everything else as an array.
    pub fn kind(&self) -> ArgKind {
        match self.role {
            ArgRole::Dt => ArgKind::Scalar,
            _ => ArgKind::Vector(self.names.len()),
        }
    }

    pub fn ident(&self) -> &'static str {
        self.role.ident()
    }
}

/// Discretisation of the motion model.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StepForm {
    /// Constant twist over the step, integrated exactly on SE(2) (seed 003).
    Exact,
    /// Twist held at the start-of-step heading (seed 001 eq. 3).
    Euler,
}

impl StepForm {
    fn ident(self) -> &'static str {
        match self {
            StepForm::Exact => "exact",
            StepForm::Euler => "euler",
        }
    }
}

/// The argument a Jacobian differentiates with respect to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Wrt {
    State,
    Inputs,
    Noise,
    Params,
}

impl Wrt {
    /// The argument this Jacobian's columns belong to.
    pub fn role(self) -> ArgRole {
        match self {
            Wrt::State => ArgRole::State,
            Wrt::Inputs => ArgRole::Inputs,
            Wrt::Noise => ArgRole::Noise,
            Wrt::Params => ArgRole::Params,
        }
    }
}

/// Which derived function a tape is. Observation kernels refer to their
/// observation by position in [`crate::ir::ModelIr::observations`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Kernel {
    /// Body twist from the inputs (forward kinematics).
    Twist,
    /// Body velocity with a measured yaw rate (gyrodometry, seed 000 eq. 17).
    TwistGyro,
    /// One motion step, or its Jacobian with respect to `Wrt`.
    Step(StepForm, Option<Wrt>),
    /// Observation `index`, or its Jacobian.
    Observation(u16, Option<Wrt>),
    /// Inputs from a body twist.
    InverseTwist,
    /// Inputs from a pose increment over dt.
    InverseIncrement,
    /// Several kernels in one tape ([`crate::fuse`]): built by a consumer for
    /// its own loop, never part of an IR.
    Fused,
}

impl Kernel {
    /// The emitted function name; `observation` names observation kernels.
    pub fn name(self, observation: impl Fn(u16) -> String) -> String {
        let jac = |w: Option<Wrt>| match w {
            None => String::new(),
            Some(w) => format!("_jac_{}", w.role().ident()),
        };
        match self {
            Kernel::Twist => "twist".into(),
            Kernel::TwistGyro => "twist_gyro".into(),
            Kernel::Step(form, w) => format!("step_{}{}", form.ident(), jac(w)),
            Kernel::Observation(i, w) => format!("obs_{}{}", observation(i), jac(w)),
            Kernel::InverseTwist => "inverse_twist".into(),
            Kernel::InverseIncrement => "inverse_increment".into(),
            Kernel::Fused => "fused".into(),
        }
    }

    /// For a Jacobian: the kernel it differentiates and with respect to what.
    pub fn differentiates(self) -> Option<(Kernel, Wrt)> {
        match self {
            Kernel::Step(form, Some(w)) => Some((Kernel::Step(form, None), w)),
            Kernel::Observation(i, Some(w)) => Some((Kernel::Observation(i, None), w)),
            _ => None,
        }
    }

    /// A Jacobian of this kernel.
    pub fn jacobian(self, w: Wrt) -> Kernel {
        match self {
            Kernel::Step(form, _) => Kernel::Step(form, Some(w)),
            Kernel::Observation(i, _) => Kernel::Observation(i, Some(w)),
            other => other,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_follow_the_contract() {
        let obs = |_| "gyro".to_string();
        assert_eq!(
            Kernel::Step(StepForm::Exact, Some(Wrt::Params)).name(obs),
            "step_exact_jac_p"
        );
        assert_eq!(Kernel::Step(StepForm::Euler, None).name(obs), "step_euler");
        assert_eq!(
            Kernel::Observation(0, Some(Wrt::State)).name(obs),
            "obs_gyro_jac_x"
        );
        assert_eq!(
            Kernel::Observation(3, Some(Wrt::State)).differentiates(),
            Some((Kernel::Observation(3, None), Wrt::State))
        );
    }
}
