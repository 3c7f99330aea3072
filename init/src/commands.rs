//! A spec of the robot's velocity commands rather than its wheels (`kinegen
//! init --commands`): for bags that logged what the controller was sent
//! (`cmd_vel`), not the wheel joints. The inputs are the commanded twist's
//! components, the parameters how much of each command the robot achieves
//! (1: it does what it is told; calibration finds the rest), the sensors the
//! description's. The base's class says whether it moves sideways.
use crate::robot::{Class, InputOut, InputRole, Kinematics, ParamOut, Robot};

/// One commanded component: its input, column, Twist field, unit and gain.
struct Component {
    input: &'static str,
    column: &'static str,
    field: &'static str,
    unit: &'static str,
    gain: &'static str,
    what: &'static str,
}

const FORWARD: Component = Component {
    input: "v_cmd",
    column: "v",
    field: "linear.x",
    unit: "m/s",
    gain: "k_v",
    what: "forward speed",
};
const SIDEWAYS: Component = Component {
    input: "vy_cmd",
    column: "v_y",
    field: "linear.y",
    unit: "m/s",
    gain: "k_vy",
    what: "leftward speed",
};
const TURN: Component = Component {
    input: "omega_cmd",
    column: "omega",
    field: "angular.z",
    unit: "rad/s",
    gain: "k_omega",
    what: "turn rate",
};

/// `robot` (its class, sensors and name) driven by its velocity commands.
pub fn commanded(mut robot: Robot) -> Robot {
    let sideways = matches!(robot.class, Class::Mecanum | Class::Omni | Class::Swerve);
    let components: Vec<&Component> = if sideways {
        vec![&FORWARD, &SIDEWAYS, &TURN]
    } else {
        vec![&FORWARD, &TURN]
    };
    let topic = robot.command_topic.clone();
    robot.inputs = (components.iter())
        .map(|c| InputOut {
            name: c.input.into(),
            column: c.column.into(),
            role: InputRole::Command {
                unit: c.unit,
                field: c.field,
            },
            range: None,
            doc: format!("commanded {} ({topic} {})", c.what, c.field),
        })
        .collect();
    robot.params = (components.iter())
        .map(|c| ParamOut {
            name: c.gain.into(),
            nominal: 1.0,
            unit: "1",
            min: Some(0.0),
            max: Some(2.0),
            // a command's gain is known only roughly before calibration:
            // tyres, load and the controller's own tuning all move it
            tolerance: Some(0.2),
            free: true,
            doc: format!("Share of the commanded {} the robot achieves.", c.what),
            source: "a command gain: 1 is a robot that does what it is told".into(),
        })
        .collect();
    robot.defines.clear();
    let term = |c: &Component, noise: &str| format!("{}*{} + {noise}", c.gain, c.input);
    robot.kinematics = Kinematics::Twist {
        vx: term(&FORWARD, "n_vx"),
        vy: if sideways {
            term(&SIDEWAYS, "n_vy")
        } else {
            "0".into()
        },
        omega: term(&TURN, "n_omega"),
        doc: "The commanded twist, each component scaled by what the robot achieves of it.".into(),
    };
    // the controller's wheel geometry is not in this spec: nothing to write back
    robot.controller = None;
    robot
}
