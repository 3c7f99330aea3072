//! Bases that steer: a tricycle whose steered wheel drives, Ackermann /
//! bicycle / tricycle bases whose rear wheels drive (seed 001 eq. 14-16 for
//! the bicycle form), and Ackermann bases whose steered front wheels drive. The twist is written at the rear axle centre C (where
//! the lateral velocity is zero) and moved to the base link.
use super::*;
use crate::robot::{Class, ControllerOut, Kinematics, ParamOut};
use crate::wheels::Steer;

pub(super) fn steering_input(s: &Steer) -> InputOut {
    InputOut {
        name: identifier(&s.joint),
        column: s.joint.clone(),
        role: crate::robot::InputRole::Steering,
        range: s.limits,
        doc: format!(
            "steering joint `{}` (URDF line {}): its angle",
            s.joint, s.line
        ),
    }
}

/// The rear axle: the wheels that are not steered, and their centre.
fn rear_axle<'a>(cx: &'a Context) -> Result<(Vec<&'a Wheel>, Vector2<f64>), InitError> {
    let rear: Vec<&Wheel> = cx
        .wheels
        .iter()
        .filter(|w| w.steer.is_none() && !w.caster)
        .collect();
    if rear.is_empty() {
        return Err(InitError::at(
            cx.file,
            None,
            "every wheel is steered: kinegen writes steered bases with a fixed rear axle",
        ));
    }
    let c = Vector2::new(
        mean(rear.iter().map(|w| w.position.x)),
        mean(rear.iter().map(|w| w.position.y)),
    );
    Ok((rear, c))
}

fn wheelbase(
    cx: &Context,
    steered: &[&Wheel],
    c: Vector2<f64>,
    ctl: Option<&Controller>,
    notes: &mut Vec<String>,
) -> Result<ParamOut, InitError> {
    let l = mean(steered.iter().map(|w| w.position.x)) - c.x;
    let lines = joint_lines(steered);
    if l <= 0.0 {
        return Err(InitError::at(cx.file, Some(steered[0].line), "the steered wheels are behind the fixed axle: kinegen writes front-steered bases (x forward, REP 103)"));
    }
    Quantity {
        name: "wheelbase",
        unit: "m",
        doc: "Distance from the rear axle to the steered wheels' axle.".into(),
        floor: 0.01,
        urdf: FromUrdf {
            value: l,
            text: num(l),
            source: format!("x of the steered wheels ({}) minus the rear axle's", lines),
        },
        controller: controller_value(ctl, "wheelbase", None)?,
    }
    .resolve(ctl, notes)
}

/// A tricycle whose steered wheel drives: at steering angle d, with the
/// wheel at (L, y_f) from C, omega = r w sin(d)/L and
/// vx_C = r w (L cos(d) + y_f sin(d))/L.
pub fn front_driven_tricycle(cx: &Context, notes: &mut Vec<String>) -> Result<Robot, InitError> {
    let (_, c) = rear_axle(cx)?;
    let front: Vec<&Wheel> = cx.wheels.iter().filter(|w| w.steer.is_some()).collect();
    let w = front[0];
    let steer = w.steer.as_ref().expect("a steered wheel");
    let ctl = cx.controller.filter(|k| k.kind == ControllerKind::Tricycle);
    let mut params = vec![Quantity {
        name: "wheel_radius",
        unit: "m",
        doc: "Radius of the steered, driven wheel.".into(),
        floor: 0.01,
        urdf: radius_of(w),
        controller: controller_value(ctl, "wheel_radius", None)?,
    }
    .resolve(ctl, notes)?];
    params.push(wheelbase(cx, &front, c, ctl, notes)?);
    let yf = w.position.y - c.y;
    let (wn, sn) = (identifier(&w.joint), identifier(&steer.joint));
    let delta = signed(steer.sign, &sn);
    let defines = vec![
        (
            "wheel_speed".into(),
            format!("wheel_radius*{}", signed(forward_sign(w), &wn)),
            "Rim speed of the driven wheel (m/s).".into(),
        ),
        (
            "yaw_rate".into(),
            format!("wheel_speed*sin({delta})/wheelbase"),
            "Turn rate of the base.".into(),
        ),
    ];
    let vx_c = if yf.abs() > 1e-12 {
        format!(
            "wheel_speed*(wheelbase*cos({delta}) + {}*sin({delta}))/wheelbase",
            num(yf)
        )
    } else {
        format!("wheel_speed*cos({delta})")
    };
    let [vx, vy, omega] = at_base((&vx_c, None), c, "yaw_rate", NOISE);
    let mut robot = Robot::new(
        Class::TricycleFrontDriven,
        vec![
            wheel_input(w, format!("driven, steered wheel joint `{}` (URDF line {}): its angle's rate", w.joint, w.line)),
            steering_input(steer),
        ],
        params,
        defines,
        Kinematics::Twist { vx, vy, omega, doc: "Tricycle, steered wheel driven: the wheel rolls along its heading, the rear axle has no lateral velocity.".into() },
    );
    robot.controller = ctl.map(|k| {
        ControllerOut::of(
            k,
            &[("wheel_radius", "wheel_radius"), ("wheelbase", "wheelbase")],
        )
    });
    Ok(robot)
}

/// The steered wheels whose angle is read (a steering joint that mimics
/// another is not logged apart).
fn read_steering<'a>(cx: &'a Context) -> Vec<&'a Wheel> {
    (cx.wheels.iter())
        .filter(|w| {
            w.steer
                .as_ref()
                .is_some_and(|s| !cx.mimics.contains(&s.joint))
        })
        .collect()
}

/// The curvature of the rear axle centre `c`'s path: each steered wheel at
/// (L, y_i) from C points at the turn centre on the rear axle line, so the
/// curvature is tan(d_i)/(L + y_i tan(d_i)), averaged over the wheels read.
fn curvature(read: &[&Wheel], c: Vector2<f64>) -> String {
    let each: Vec<String> = (read.iter())
        .map(|w| {
            let s = w.steer.as_ref().expect("steered");
            let d = signed(s.sign, &identifier(&s.joint));
            let y = w.position.y - c.y;
            if y.abs() > 1e-12 {
                let to_centre = linear(0.0, &[(1.0, "wheelbase"), (y, &format!("tan({d})"))]);
                format!("tan({d})/({to_centre})")
            } else {
                format!("tan({d})/wheelbase")
            }
        })
        .collect();
    if each.len() == 1 {
        each[0].clone()
    } else {
        format!("({})/{}", each.join(" + "), each.len())
    }
}

/// What a steered base with a fixed rear axle is written from: the rear
/// axle centre's curvature and speed, moved to the base link, and the
/// controller's radius key with the parameter it holds.
struct AxleCentre<'a> {
    class: Class,
    curvature: String,
    speed: String,
    radius: (&'a str, &'a str),
    doc: &'a str,
}

impl AxleCentre<'_> {
    fn robot(
        self,
        (inputs, params): (Vec<InputOut>, Vec<ParamOut>),
        c: Vector2<f64>,
        ctl: Option<&Controller>,
    ) -> Robot {
        let defines = vec![
            (
                "curvature".into(),
                self.curvature,
                "Curvature of the rear axle centre's path (1/m).".into(),
            ),
            (
                "speed".into(),
                self.speed,
                "Speed of the rear axle centre (m/s).".into(),
            ),
            (
                "yaw_rate".into(),
                "speed*curvature".into(),
                "Turn rate of the base.".into(),
            ),
        ];
        let [vx, vy, omega] = at_base(("speed", None), c, "yaw_rate", NOISE);
        let doc = self.doc.to_string();
        let mut robot = Robot::new(
            self.class,
            inputs,
            params,
            defines,
            Kinematics::Twist { vx, vy, omega, doc },
        );
        robot.controller =
            ctl.map(|k| ControllerOut::of(k, &[self.radius, ("wheelbase", "wheelbase")]));
        robot
    }
}

/// The first of `keys` the steering controller gives (else the first).
fn radius_key(ctl: Option<&Controller>, keys: [&'static str; 2]) -> &'static str {
    (keys.into_iter())
        .find(|k| ctl.is_some_and(|c| c.params.contains_key(*k)))
        .unwrap_or(keys[0])
}

/// Steered front wheel(s), driven rear wheels: each steered wheel at
/// (L, y_i) from C points at the turn centre, so the curvature is
/// tan(d_i)/(L + y_i tan(d_i)); the spec averages it over the steered
/// wheels it reads, and vx_C is the driven wheels' mean rim speed.
pub fn rear_driven_steering(cx: &Context, notes: &mut Vec<String>) -> Result<Robot, InitError> {
    let (rear, c) = rear_axle(cx)?;
    let driven: Vec<&Wheel> = rear
        .iter()
        .copied()
        .filter(|w| cx.driven.contains(&w.joint) && !w.mimic)
        .collect();
    if driven.is_empty() {
        return Err(InitError::at(cx.file, Some(rear[0].line), "no rear wheel is driven (neither the controller nor a <ros2_control> block commands one)"));
    }
    let steered: Vec<&Wheel> = cx.wheels.iter().filter(|w| w.steer.is_some()).collect();
    let read = read_steering(cx);
    let ctl = cx.controller.filter(|k| k.kind == ControllerKind::Steering);
    let radius_key = radius_key(ctl, ["rear_wheels_radius", "traction_wheels_radius"]);
    let mut params = vec![Quantity {
        name: "rear_wheel_radius",
        unit: "m",
        doc: "Radius of the driven rear wheels.".into(),
        floor: 0.01,
        urdf: radius_of(driven[0]),
        controller: controller_value(ctl, radius_key, None)?,
    }
    .resolve(ctl, notes)?];
    params.push(wheelbase(cx, &steered, c, ctl, notes)?);
    let mut inputs = Vec::new();
    let terms: Vec<String> = driven
        .iter()
        .map(|w| {
            inputs.push(wheel_input(
                w,
                format!(
                    "driven rear wheel joint `{}` (URDF line {}): its angle's rate",
                    w.joint, w.line
                ),
            ));
            signed(forward_sign(w), &identifier(&w.joint))
        })
        .collect();
    inputs.extend(
        read.iter()
            .map(|w| steering_input(w.steer.as_ref().expect("steered"))),
    );
    let curvature = curvature(&read, c);
    let n = driven.len();
    let ybar = mean(driven.iter().map(|w| w.position.y - c.y));
    let sum = terms.join(" + ").replace("+ -", "- ");
    let mut speed = if n == 1 {
        format!("rear_wheel_radius*{sum}")
    } else {
        format!("rear_wheel_radius*({sum})/{n}")
    };
    if ybar.abs() > 1e-12 {
        speed = format!("({speed})/({})", linear(1.0, &[(-ybar, "curvature")]));
    }
    let axle = AxleCentre {
        class: Class::RearDrivenSteering,
        curvature,
        speed,
        radius: (radius_key, "rear_wheel_radius"),
        doc: "Steered front, driven rear (seed 001 eq. 14 for one steered wheel): each steered wheel points at the turn centre on the rear axle line.",
    };
    Ok(axle.robot((inputs, params), c, ctl))
}

/// Steered front wheels that drive (a front-wheel-drive car), the rear
/// wheels passive: the curvature as for a rear-driven base, and each driven
/// wheel i at (L, y_i) from C rolling along its heading d_i gives the rear
/// axle centre's speed r w_i (L cos(d_i) + y_i sin(d_i))/L (the tricycle's
/// form for each wheel); the spec averages it over the driven wheels. A
/// driven wheel whose steering joint is not logged (it mimics the other)
/// takes the angle the curvature gives it, atan2(k L, 1 - k y_i).
pub fn front_driven_steering(cx: &Context, notes: &mut Vec<String>) -> Result<Robot, InitError> {
    let (_, c) = rear_axle(cx)?;
    let steered: Vec<&Wheel> = cx.wheels.iter().filter(|w| w.steer.is_some()).collect();
    let driven: Vec<&Wheel> = (steered.iter().copied())
        .filter(|w| cx.driven.contains(&w.joint) && !w.mimic)
        .collect();
    let read = read_steering(cx);
    let ctl = cx.controller.filter(|k| k.kind == ControllerKind::Steering);
    let radius_key = radius_key(ctl, ["front_wheels_radius", "traction_wheels_radius"]);
    let mut params = vec![Quantity {
        name: "front_wheel_radius",
        unit: "m",
        doc: "Radius of the driven, steered front wheels.".into(),
        floor: 0.01,
        urdf: radius_of(driven[0]),
        controller: controller_value(ctl, radius_key, None)?,
    }
    .resolve(ctl, notes)?];
    params.push(wheelbase(cx, &steered, c, ctl, notes)?);
    let mut inputs: Vec<InputOut> = (driven.iter())
        .map(|w| {
            let doc = format!(
                "driven front wheel joint `{}` (URDF line {}): its angle's rate",
                w.joint, w.line
            );
            wheel_input(w, doc)
        })
        .collect();
    inputs.extend(
        read.iter()
            .map(|w| steering_input(w.steer.as_ref().expect("steered"))),
    );
    let speeds: Vec<String> = (driven.iter())
        .map(|w| {
            let s = w.steer.as_ref().expect("steered");
            let y = w.position.y - c.y;
            let d = if read.iter().any(|r| r.joint == w.joint) {
                signed(s.sign, &identifier(&s.joint))
            } else {
                let across = linear(1.0, &[(-y, "curvature")]);
                format!("atan2(curvature*wheelbase, {across})")
            };
            let rim = format!(
                "front_wheel_radius*{}",
                signed(forward_sign(w), &identifier(&w.joint))
            );
            if y.abs() > 1e-12 {
                let along = linear(
                    0.0,
                    &[
                        (1.0, &format!("wheelbase*cos({d})")),
                        (y, &format!("sin({d})")),
                    ],
                );
                format!("{rim}*({along})/wheelbase")
            } else {
                format!("{rim}*cos({d})")
            }
        })
        .collect();
    let speed = if speeds.len() == 1 {
        speeds[0].clone()
    } else {
        format!("({})/{}", speeds.join(" + "), speeds.len())
    };
    let axle = AxleCentre {
        class: Class::FrontDrivenSteering,
        curvature: curvature(&read, c),
        speed,
        radius: (radius_key, "front_wheel_radius"),
        doc: "Steered, driven front wheels, passive rear axle: each front wheel points at the turn centre on the rear axle line and rolls along its heading.",
    };
    Ok(axle.robot((inputs, params), c, ctl))
}
