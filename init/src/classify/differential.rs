//! Differential drive and skid steer.
use super::*;
use crate::controller::ControllerKind;
use crate::robot::{Class, ControllerOut, Kinematics};

/// Differential drive and skid steer: the driven wheels on each side of the
/// axle centre, all spinning about the base's y axis.
pub fn differential(cx: &Context, notes: &mut Vec<String>) -> Result<Robot, InitError> {
    let driven: Vec<&Wheel> = cx
        .wheels
        .iter()
        .filter(|w| cx.driven.contains(&w.joint) && !w.mimic)
        .collect();
    let centre = Vector2::new(
        mean(driven.iter().map(|w| w.position.x)),
        mean(driven.iter().map(|w| w.position.y)),
    );
    let (left, right): (Vec<&Wheel>, Vec<&Wheel>) =
        driven.iter().partition(|w| w.position.y > centre.y);
    if left.is_empty() || right.is_empty() {
        return Err(InitError::at(
            cx.file,
            Some(driven[0].line),
            "the driven wheels are all on one side of the robot: no differential drive or skid steer (check the wheel joints' origins)",
        ));
    }
    let class = if left.len() == 1 && right.len() == 1 {
        Class::DiffDrive
    } else {
        Class::SkidSteer
    };
    let ctl = cx
        .controller
        .filter(|c| c.kind == ControllerKind::DiffDrive);
    let track = mean(left.iter().map(|w| w.position.y)) - mean(right.iter().map(|w| w.position.y));
    let separation = Quantity {
        name: "wheel_separation",
        unit: "m",
        doc: if class == Class::SkidSteer {
            "Effective track: the geometric one, widened by the wheels' skidding in turns (calibrate it).".into()
        } else {
            "Distance between the wheels' contact points.".into()
        },
        floor: if class == Class::SkidSteer { 0.5 } else { 0.02 },
        urdf: FromUrdf {
            value: track,
            text: num(track),
            source: format!(
                "y of the wheel joints' origins, {} and {}",
                joint_lines(&left),
                joint_lines(&right)
            ),
        },
        controller: controller_value(ctl, "wheel_separation", Some("wheel_separation_multiplier"))?,
    };
    let mut params = vec![separation.resolve(ctl, notes)?];
    for (side, wheels) in [("left", &left), ("right", &right)] {
        let q = Quantity {
            name: if side == "left" {
                "wheel_radius_left"
            } else {
                "wheel_radius_right"
            },
            unit: "m",
            doc: format!(
                "Radius of the {side} wheel{}.",
                if wheels.len() > 1 { "s" } else { "" }
            ),
            floor: 0.01,
            urdf: radius_of(wheels[0]),
            controller: controller_value(
                ctl,
                "wheel_radius",
                Some(if side == "left" {
                    "left_wheel_radius_multiplier"
                } else {
                    "right_wheel_radius_multiplier"
                }),
            )?,
        };
        params.push(q.resolve(ctl, notes)?);
    }
    if class == Class::SkidSteer {
        let p = &mut params[0];
        p.tolerance = None;
        p.min = Some(0.5 * track);
        p.max = Some(4.0 * track);
        notes.push(format!(
            "skid steer: wheel_separation starts at the geometric track {} m and has no prior; a skid-steered base turns as if its track were 1.2-2x wider, which fit measures",
            num(track)
        ));
    }
    let mut inputs = Vec::new();
    let mut defines = Vec::new();
    for (side, wheels) in [("left", &left), ("right", &right)] {
        let terms: Vec<String> = wheels
            .iter()
            .map(|w| {
                inputs.push(wheel_input(
                    w,
                    format!(
                        "{side} wheel joint `{}` (URDF line {}): its angle's rate",
                        w.joint, w.line
                    ),
                ));
                signed(forward_sign(w), &identifier(&w.joint))
            })
            .collect();
        let sum = if terms.len() == 1 {
            terms[0].clone()
        } else {
            format!(
                "({})/{}",
                terms.join(" + ").replace("+ -", "- "),
                terms.len()
            )
        };
        defines.push((
            format!("v_{side}"),
            format!("wheel_radius_{side}*{sum}"),
            format!("Speed of the {side} side's wheel contact (m/s)."),
        ));
    }
    defines.push((
        "yaw_rate".into(),
        "(v_right - v_left)/wheel_separation".into(),
        "Turn rate of the base.".into(),
    ));
    let [vx, vy, omega] = at_base(("(v_right + v_left)/2", None), centre, "yaw_rate", NOISE);
    let controller = ctl.map(|c| {
        ControllerOut::of(
            c,
            &[
                ("wheel_separation", "wheel_separation"),
                ("wheel_separation_multiplier", "1"),
                ("wheel_radius", "(wheel_radius_left + wheel_radius_right)/2"),
                (
                    "left_wheel_radius_multiplier",
                    "2*wheel_radius_left/(wheel_radius_left + wheel_radius_right)",
                ),
                (
                    "right_wheel_radius_multiplier",
                    "2*wheel_radius_right/(wheel_radius_left + wheel_radius_right)",
                ),
            ],
        )
    });
    let mut robot = Robot::new(
        class,
        inputs,
        params,
        defines,
        Kinematics::Twist {
            vx,
            vy,
            omega,
            doc: format!(
                "{}: the sides' contact speeds v = r w, their mean the axle centre's speed, their difference over the separation the turn rate{}.",
                crate::capital(class.describe()),
                if centre.norm() > 1e-12 {
                    format!("; moved from the axle centre ({}, {}) to the base link by v + omega x p", num(centre.x), num(centre.y))
                } else {
                    String::new()
                }
            ),
        },
    );
    robot.controller = controller;
    Ok(robot)
}
