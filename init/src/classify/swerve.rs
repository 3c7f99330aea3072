//! Swerve drive: every wheel steered and driven by itself, no fixed axle.
//! Wheel i at q_i from the wheels' centre, steered to d_i with rim speed
//! v_i, moves at v_i (cos d_i, sin d_i) = v_c + omega x q_i. The least-squares
//! twist of those 2n equations, with the wheels' centre as origin (so that
//! sum q_i = 0 decouples them), is
//! vx_c = mean(v_i cos d_i), vy_c = mean(v_i sin d_i) and
//! omega = sum(q_ix v_i sin d_i - q_iy v_i cos d_i) / sum |q_i|^2,
//! moved to the base link. The steering angles are inputs, so the twist is
//! written out rather than as constant constraint rows.
use super::steered::steering_input;
use super::*;
use crate::robot::{Class, Kinematics, ParamOut};

/// A four-module base on a rectangle about its centre: its half wheelbase
/// and half track, each from the modules' joints.
fn rectangle(wheels: &[&Wheel], c: Vector2<f64>) -> Option<(f64, f64)> {
    let q: Vec<Vector2<f64>> = (wheels.iter())
        .map(|w| Vector2::new(w.position.x, w.position.y) - c)
        .collect();
    let (a, b) = (q[0].x.abs(), q[0].y.abs());
    let on = q
        .iter()
        .all(|q| (q.x.abs() - a).abs() < 1e-9 && (q.y.abs() - b).abs() < 1e-9);
    (wheels.len() == 4 && on && a > 0.0 && b > 0.0).then_some((a, b))
}

/// The modules' wheel radius, and their half wheelbase and half track when
/// they sit on a rectangle about their centre (else a note: the positions
/// are written as numbers).
fn module_params(
    wheels: &[&Wheel],
    rect: Option<(f64, f64)>,
    notes: &mut Vec<String>,
) -> Result<Vec<ParamOut>, InitError> {
    let lines = joint_lines(wheels);
    let mut params: Vec<ParamOut> = vec![Quantity {
        name: "wheel_radius",
        unit: "m",
        doc: "Radius of the modules' wheels.".into(),
        floor: 0.01,
        urdf: radius_of(wheels[0]),
        controller: None,
    }
    .resolve(None, notes)?];
    if let Some((a, b)) = rect {
        for (name, value, doc) in [
            (
                "half_wheelbase",
                a,
                "Half the distance between the front and rear modules.",
            ),
            (
                "half_track",
                b,
                "Half the distance between the left and right modules.",
            ),
        ] {
            let q = Quantity {
                name,
                unit: "m",
                doc: doc.into(),
                floor: 0.01,
                urdf: FromUrdf {
                    value,
                    text: num(tidy(value)),
                    source: format!("the steering modules' origins, {lines}"),
                },
                controller: None,
            };
            params.push(q.resolve(None, notes)?);
        }
    } else {
        notes.push(
            "swerve: the modules are not on a rectangle about their centre; their positions are written as numbers".into(),
        );
    }
    Ok(params)
}

pub fn swerve(cx: &Context, notes: &mut Vec<String>) -> Result<Robot, InitError> {
    let wheels: Vec<&Wheel> = cx.wheels.iter().filter(|w| !w.caster).collect();
    let equal_radii = (wheels.iter()).all(|w| (w.radius - wheels[0].radius).abs() < 1e-12);
    if !equal_radii {
        return Err(InitError::at(
            cx.file,
            Some(wheels[1].radius_line),
            "swerve: the modules' wheels have different radii; kinegen expects one wheel size",
        ));
    }
    let c = Vector2::new(
        mean(wheels.iter().map(|w| w.position.x)),
        mean(wheels.iter().map(|w| w.position.y)),
    );
    let rect = rectangle(&wheels, c);
    let params = module_params(&wheels, rect, notes)?;
    let mut inputs = Vec::new();
    let (mut along_x, mut along_y, mut turn) = (Vec::new(), Vec::new(), Vec::new());
    let mut spread = 0.0;
    for w in &wheels {
        let s = w.steer.as_ref().expect("every module steers");
        inputs.push(wheel_input(
            w,
            format!(
                "module wheel joint `{}` (URDF line {}): its angle's rate",
                w.joint, w.line
            ),
        ));
        inputs.push(steering_input(s));
        let (wn, d) = (
            signed(forward_sign(w), &identifier(&w.joint)),
            signed(s.sign, &identifier(&s.joint)),
        );
        along_x.push(format!("{wn}*cos({d})"));
        along_y.push(format!("{wn}*sin({d})"));
        let q = Vector2::new(w.position.x, w.position.y) - c;
        spread += q.norm_squared();
        let (qx, qy) = match rect {
            Some(_) => (
                format!("{}half_wheelbase", if q.x < 0.0 { "-" } else { "" }),
                format!("{}half_track", if q.y < 0.0 { "-" } else { "" }),
            ),
            None => (num(tidy(q.x)), num(tidy(q.y))),
        };
        turn.push(format!("({qx})*{wn}*sin({d}) - ({qy})*{wn}*cos({d})"));
    }
    let n = wheels.len();
    let spread = match rect {
        Some(_) => format!("{n}*(half_wheelbase^2 + half_track^2)"),
        None => num(tidy(spread)),
    };
    let sum = |terms: &[String]| terms.join(" + ").replace("+ -", "- ");
    let defines = vec![
        (
            "vx_centre".into(),
            format!("wheel_radius*({})/{n}", sum(&along_x)),
            "Forward velocity of the modules' centre (m/s).".into(),
        ),
        (
            "vy_centre".into(),
            format!("wheel_radius*({})/{n}", sum(&along_y)),
            "Leftward velocity of the modules' centre (m/s).".into(),
        ),
        (
            "yaw_rate".into(),
            format!("wheel_radius*({})/({spread})", sum(&turn)),
            "Turn rate of the base.".into(),
        ),
    ];
    let [vx, vy, omega] = at_base(("vx_centre", Some("vy_centre")), c, "yaw_rate", NOISE);
    Ok(Robot::new(
        Class::Swerve,
        inputs,
        params,
        defines,
        Kinematics::Twist {
            vx,
            vy,
            omega,
            doc: "Swerve: each module's wheel rolls along its steered heading; the twist is the least-squares solution of the modules' velocities.".into(),
        },
    ))
}
