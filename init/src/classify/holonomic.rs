//! Bases that move sideways: mecanum (four wheels on parallel axles, rollers
//! at 45 degrees) and omni (wheels whose axles point different ways). Both
//! are written as constraints, one row per wheel (rate = row . twist), which
//! kinegen solves by least squares (seed 000 eq. 9-10).
use super::*;
use crate::robot::{Class, ControllerOut, Kinematics, ParamOut};

fn constraint_robot(
    class: Class,
    inputs: Vec<InputOut>,
    params: Vec<ParamOut>,
    rows: Vec<(String, [String; 3])>,
    doc: String,
) -> Robot {
    Robot::new(
        class,
        inputs,
        params,
        Vec::new(),
        Kinematics::Constraints { rows, doc },
    )
}

/// Mecanum: wheel i at p = c + (sx lx, sy ly) with rollers in the X layout of
/// ros2's mecanum_drive_controller rolls at r w = vx - s vy - (p_y + s p_x) omega,
/// s = sx sy (front left: vx - vy - (lx + ly) omega at c = 0).
pub fn mecanum(cx: &Context, notes: &mut Vec<String>) -> Result<Robot, InitError> {
    let wheels: Vec<&Wheel> = cx.wheels.iter().filter(|w| !w.caster && !w.mimic).collect();
    let centre = Vector2::new(
        mean(wheels.iter().map(|w| w.position.x)),
        mean(wheels.iter().map(|w| w.position.y)),
    );
    let lx = mean(wheels.iter().map(|w| (w.position.x - centre.x).abs()));
    let ly = mean(wheels.iter().map(|w| (w.position.y - centre.y).abs()));
    for w in &wheels {
        let off = (w.position.x - centre.x).abs() - lx;
        let side = (w.position.y - centre.y).abs() - ly;
        if wheels.len() != 4 || off.abs() > 1e-9 || side.abs() > 1e-9 {
            return Err(InitError::at(
                cx.file,
                Some(w.line),
                format!("mecanum: kinegen expects four wheels at the corners of a rectangle; `{}` is not (a base of {} wheels)", w.joint, wheels.len()),
            ));
        }
    }
    let ctl = cx.controller.filter(|c| c.kind == ControllerKind::Mecanum);
    let radius = Quantity {
        name: "wheel_radius",
        unit: "m",
        doc: "Radius of the mecanum wheels (to the rollers' contact).".into(),
        floor: 0.01,
        urdf: radius_of(wheels[0]),
        controller: controller_value(ctl, "kinematics.wheels_radius", None)?,
    }
    .resolve(ctl, notes)?;
    let lines = joint_lines(&wheels);
    let mut params = vec![radius];
    for (name, value, axis) in [("half_wheelbase", lx, "x"), ("half_track", ly, "y")] {
        let mut p = Quantity {
            name,
            unit: "m",
            doc: format!("Half the distance between the wheels along {axis}."),
            floor: 0.02,
            urdf: FromUrdf {
                value,
                text: num(value),
                source: format!("{axis} of the wheel joints' origins, {}", lines),
            },
            controller: None,
        }
        .resolve(None, notes)?;
        p.free = name == "half_track";
        params.push(p);
    }
    if let Some(c) = controller_value(
        ctl,
        "kinematics.sum_of_robot_center_projection_on_X_Y_axis",
        None,
    )? {
        if (c.value - (lx + ly)).abs() > 1e-9 {
            notes.push(format!(
                "mecanum: the controller's lx + ly is {} ({}, line {}), the URDF's {}; the spec uses the URDF's half wheelbase and half track",
                c.shown, c.key, c.line, num(lx + ly)
            ));
        }
    }
    let mut inputs = Vec::new();
    let mut rows = Vec::new();
    for w in &wheels {
        let (sx, sy) = (
            (w.position.x - centre.x).signum(),
            (w.position.y - centre.y).signum(),
        );
        let s = sx * sy;
        let sign = forward_sign(w);
        inputs.push(wheel_input(
            w,
            format!(
                "mecanum wheel joint `{}` (URDF line {}): its angle's rate",
                w.joint, w.line
            ),
        ));
        // p_y + s p_x with p = c + (sx lx, sy ly)
        let turn = linear(
            -sign * (centre.y + s * centre.x),
            &[
                (-sign * sy, "half_track"),
                (-sign * s * sx, "half_wheelbase"),
            ],
        );
        rows.push((
            identifier(&w.joint),
            [
                format!("{}/wheel_radius", num(sign)),
                format!("{}/wheel_radius", num(-sign * s)),
                format!("({turn})/wheel_radius"),
            ],
        ));
    }
    let mut robot = constraint_robot(
        Class::Mecanum,
        inputs,
        params,
        rows,
        "Mecanum wheels (rollers at 45 degrees, X layout as ros2 mecanum_drive_controller): each wheel's rate from the twist; the twist is their least-squares solution.".into(),
    );
    robot.controller = ctl.map(|c| {
        ControllerOut::of(
            c,
            &[
                ("kinematics.wheels_radius", "wheel_radius"),
                (
                    "kinematics.sum_of_robot_center_projection_on_X_Y_axis",
                    "half_wheelbase + half_track",
                ),
            ],
        )
    });
    Ok(robot)
}

/// Omni wheels (free rollers across the rim): wheel i at p rolling along d
/// turns at r w = d . (v + omega x p) = d_x vx + d_y vy + (p x d)_z omega.
pub fn omni(cx: &Context, notes: &mut Vec<String>) -> Result<Robot, InitError> {
    let wheels: Vec<&Wheel> = cx.wheels.iter().filter(|w| !w.caster && !w.mimic).collect();
    if wheels.len() < 3 {
        return Err(InitError::at(cx.file, Some(wheels[0].line), format!("omni: a base with wheel axles in different directions needs at least three wheels; found {}", wheels.len())));
    }
    let centre = Vector2::new(
        mean(wheels.iter().map(|w| w.position.x)),
        mean(wheels.iter().map(|w| w.position.y)),
    );
    let dist = |w: &Wheel| (Vector2::new(w.position.x, w.position.y) - centre).norm();
    let l = mean(wheels.iter().map(|w| dist(w)));
    let round = wheels.iter().all(|w| (dist(w) - l).abs() < 1e-9);
    let equal_radii = wheels
        .iter()
        .all(|w| (w.radius - wheels[0].radius).abs() < 1e-12);
    if !equal_radii {
        return Err(InitError::at(
            cx.file,
            Some(wheels[1].radius_line),
            "omni: the wheels have different radii; kinegen expects one wheel size on an omni base",
        ));
    }
    let lines = joint_lines(&wheels);
    let mut params = vec![Quantity {
        name: "wheel_radius",
        unit: "m",
        doc: "Radius of the omni wheels.".into(),
        floor: 0.01,
        urdf: radius_of(wheels[0]),
        controller: None,
    }
    .resolve(None, notes)?];
    if round {
        params.push(
            Quantity {
                name: "base_radius",
                unit: "m",
                doc: "Distance from the base's centre to each wheel.".into(),
                floor: 0.01,
                urdf: FromUrdf {
                    value: l,
                    text: num(l),
                    source: format!("the wheel joints' origins, {}", lines),
                },
                controller: None,
            }
            .resolve(None, notes)?,
        );
    } else {
        notes.push(
            "omni: the wheels are not on one circle; their positions are written as numbers".into(),
        );
    }
    let mut inputs = Vec::new();
    let mut rows = Vec::new();
    for w in &wheels {
        let d = w.rolling();
        let d = Vector2::new(d.x, d.y).normalize();
        let p = Vector2::new(w.position.x, w.position.y);
        let q = p - centre;
        let cross = |a: Vector2<f64>, b: Vector2<f64>| a.x * b.y - a.y * b.x;
        let turn = if round {
            linear(cross(centre, d), &[(cross(q / l, d), "base_radius")])
        } else {
            num(tidy(cross(p, d)))
        };
        inputs.push(wheel_input(
            w,
            format!(
                "omni wheel joint `{}` (URDF line {}): its angle's rate",
                w.joint, w.line
            ),
        ));
        rows.push((
            identifier(&w.joint),
            [
                format!("{}/wheel_radius", num(tidy(d.x))),
                format!("{}/wheel_radius", num(tidy(d.y))),
                format!("({turn})/wheel_radius"),
            ],
        ));
    }
    Ok(constraint_robot(
        Class::Omni,
        inputs,
        params,
        rows,
        "Omni wheels: each wheel's rim speed is the base velocity at the wheel along its rolling direction; the twist is their least-squares solution.".into(),
    ))
}
