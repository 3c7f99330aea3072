//! The spec-to-be, as types: inputs, parameters with where each number came
//! from, the kinematics, observations, and the controller values a calibration
//! writes back. `classify` builds it; `write` prints it.

/// The kinematic class chosen from the wheels.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Class {
    DiffDrive,
    SkidSteer,
    Mecanum,
    Omni,
    /// One steered wheel that is also driven (rear wheels passive).
    TricycleFrontDriven,
    /// Steered front wheel(s), driven rear wheels: Ackermann, bicycle, tricycle.
    RearDrivenSteering,
    /// Steered front wheels that drive, passive rear wheels: a front-wheel
    /// drive Ackermann car.
    FrontDrivenSteering,
    /// Every wheel steered and driven by itself (swerve modules).
    Swerve,
}

impl Class {
    pub fn describe(self) -> &'static str {
        match self {
            Class::DiffDrive => "differential drive",
            Class::SkidSteer => "skid steer",
            Class::Mecanum => "mecanum",
            Class::Omni => "omnidirectional (omni wheels)",
            Class::TricycleFrontDriven => "tricycle (steered wheel driven)",
            Class::RearDrivenSteering => "Ackermann / bicycle (steered front, driven rear)",
            Class::FrontDrivenSteering => "Ackermann (steered and driven front, passive rear)",
            Class::Swerve => "swerve drive (every wheel steered and driven)",
        }
    }
}

/// What an input is: a wheel's angle (cumulative), a steering angle
/// (absolute, rad), or a velocity command (absolute, in `unit`) read from the
/// controller's command topic at `field`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum InputRole {
    Wheel,
    Steering,
    Command {
        unit: &'static str,
        field: &'static str,
    },
}

#[derive(Debug, Clone)]
pub struct InputOut {
    pub name: String,
    /// The joint_states name.
    pub column: String,
    pub role: InputRole,
    pub range: Option<[f64; 2]>,
    pub doc: String,
}

#[derive(Debug, Clone)]
pub struct ParamOut {
    pub name: String,
    pub nominal: f64,
    pub unit: &'static str,
    pub min: Option<f64>,
    pub max: Option<f64>,
    /// Absolute; `None`: no prior.
    pub tolerance: Option<f64>,
    /// Calibrated by fit (free) or held (free = false).
    pub free: bool,
    pub doc: String,
    /// Where the number came from (a comment above it).
    pub source: String,
}

#[derive(Debug, Clone)]
pub enum Kinematics {
    Twist {
        vx: String,
        vy: String,
        omega: String,
        doc: String,
    },
    /// rate = coeffs . (vx, vy, omega), one row per wheel.
    Constraints {
        rows: Vec<(String, [String; 3])>,
        doc: String,
    },
}

/// Where the calibrated values go in the controller's configuration.
#[derive(Debug, Clone)]
pub struct ControllerOut {
    pub node: String,
    pub type_name: String,
    /// The file read, relative to the spec when it can be.
    pub file: String,
    /// Controller key -> expression over the spec's parameters.
    pub values: Vec<(String, String)>,
}

#[derive(Debug, Clone)]
pub struct Robot {
    pub name: String,
    pub class: Class,
    pub doc: String,
    pub inputs: Vec<InputOut>,
    pub params: Vec<ParamOut>,
    /// Named intermediate quantities ([[define]]): name, expression, doc.
    pub defines: Vec<(String, String, String)>,
    pub kinematics: Kinematics,
    /// The sign of omega in the IMU's z (-1: mounted upside down), and its link.
    pub gyro: Option<(f64, String)>,
    /// The exteroceptive sensor's link and its mounting (x, y) in the base frame.
    pub landmark_sensor: Option<(String, [f64; 2])>,
    /// The frame the controller's odometry is of (its `base_frame_id`) and
    /// its pose (x, y, yaw) in the base frame: what a measured pose of the
    /// robot is taken of.
    pub odometry_frame: Option<(String, [f64; 3])>,
    pub controller: Option<ControllerOut>,
    /// The topic the controller's velocity commands arrive on.
    pub command_topic: String,
    /// Facts the user should read: disagreements, choices, what was ignored.
    pub notes: Vec<String>,
}

impl Robot {
    /// A robot of `class` with its kinematics; the name, doc, sensors,
    /// controller and notes are filled in after the class is chosen.
    pub fn new(
        class: Class,
        inputs: Vec<InputOut>,
        params: Vec<ParamOut>,
        defines: Vec<(String, String, String)>,
        kinematics: Kinematics,
    ) -> Robot {
        Robot {
            name: String::new(),
            class,
            doc: String::new(),
            inputs,
            params,
            defines,
            kinematics,
            gyro: None,
            landmark_sensor: None,
            odometry_frame: None,
            controller: None,
            command_topic: "/cmd_vel".into(),
            notes: Vec::new(),
        }
    }
}

impl ControllerOut {
    /// The node of `ctl` with `values` (key, expression over the parameters);
    /// the file is set where the spec's path is known.
    pub fn of(ctl: &crate::controller::Controller, values: &[(&str, &str)]) -> ControllerOut {
        ControllerOut {
            node: ctl.node.clone(),
            type_name: ctl.type_name.clone(),
            file: String::new(),
            values: values
                .iter()
                .map(|(k, e)| (k.to_string(), e.to_string()))
                .collect(),
        }
    }
}

/// One standard deviation of what a printed number says about the quantity:
/// half a unit of its last printed digit, but never less than `floor` of its
/// value (a CAD number printed to the micrometre still says nothing finer
/// than how a real tyre deforms).
pub fn tolerance(text: &str, value: f64, floor: f64) -> f64 {
    let t = text.trim().to_ascii_lowercase();
    let mantissa = t.split('e').next().unwrap_or("");
    let exp: i32 = t
        .split('e')
        .nth(1)
        .and_then(|e| e.parse().ok())
        .unwrap_or(0);
    let decimals = mantissa.split('.').nth(1).map_or(0, str::len) as i32;
    let printed = 0.5 * 10f64.powi(exp - decimals);
    printed.max(floor * value.abs())
}
