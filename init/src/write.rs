//! The spec and the topic mapping as text a person would have written:
//! grouped as the spec reference groups them, every number followed by where
//! it came from. Printed with `format!` rather than serialised with
//! toml_edit: the comments carry as much as the values, and toml_edit's
//! decor API would spread each comment over three calls.
use crate::classify::{linear, num};
use crate::robot::{Class, InputRole, Kinematics, ParamOut, Robot};
use std::fmt::Write;

fn quote(s: &str) -> String {
    format!("\"{}\"", s.replace('\\', "\\\\").replace('"', "\\\""))
}

fn param(out: &mut String, p: &ParamOut) {
    let _ = writeln!(out, "\n# {}", p.source);
    let _ = writeln!(
        out,
        "[[parameter]]\nname = {}\nnominal = {}\nunit = {}",
        quote(&p.name),
        num(p.nominal),
        quote(p.unit)
    );
    if let Some(m) = p.min {
        let _ = writeln!(out, "min = {}", num(m));
    }
    if let Some(m) = p.max {
        let _ = writeln!(out, "max = {}", num(m));
    }
    if let Some(t) = p.tolerance {
        let _ = writeln!(out, "tolerance = {}", num(t));
    }
    if !p.free {
        let _ = writeln!(out, "free = false");
    }
    let _ = writeln!(out, "doc = {}", quote(&p.doc));
}

fn kinematics(out: &mut String, k: &Kinematics) {
    match k {
        Kinematics::Twist { vx, vy, omega, doc } => {
            let _ = writeln!(
                out,
                "\n[motion]\ndoc = {}\nvx = {}\nvy = {}\nomega = {}",
                quote(doc),
                quote(vx),
                quote(vy),
                quote(omega)
            );
        }
        Kinematics::Constraints { rows, doc } => {
            let _ = writeln!(
                out,
                "\n[constraints]\ndoc = {}\nnoise = [\"n_vx\", \"n_vy\", \"n_omega\"]",
                quote(doc)
            );
            for (rate, c) in rows {
                let _ = writeln!(
                    out,
                    "\n[[constraints.row]]\nrate = {}\ncoeffs = [{}, {}, {}]",
                    quote(rate),
                    quote(&c[0]),
                    quote(&c[1]),
                    quote(&c[2])
                );
            }
        }
    }
}

/// The noise terms the kinematics uses, as densities (the same at any log rate).
fn noise(out: &mut String, k: &Kinematics) {
    let text = match k {
        Kinematics::Twist { vx, vy, omega, .. } => format!("{vx} {vy} {omega}"),
        Kinematics::Constraints { .. } => "n_vx n_vy n_omega".into(),
    };
    for (name, unit, doc) in [
        (
            "n_vx",
            "m/s/sqrt(Hz)",
            "Forward velocity noise (a density: the same at any log rate).",
        ),
        ("n_vy", "m/s/sqrt(Hz)", "Lateral velocity noise."),
        ("n_omega", "rad/s/sqrt(Hz)", "Turn rate noise."),
    ] {
        if text.contains(name) {
            let _ = writeln!(
                out,
                "\n[[noise]]\nname = {}\nsigma = 0.01\nunit = {}\ndoc = {}",
                quote(name),
                quote(unit),
                quote(doc)
            );
        }
    }
}

fn observations(out: &mut String, r: &Robot) {
    if let Some((link, [ox, oy, yaw])) = &r.odometry_frame {
        pose_observation(out, link, [*ox, *oy, *yaw]);
    }
    if let Some((sign, link)) = &r.gyro {
        let _ = writeln!(
            out,
            "\n# the IMU on link `{link}`: its z axis {} the base's\n[[observation]]\nname = \"gyro\"\ndoc = \"Yaw rate from the IMU's angular_velocity.z.\"\ncolumns = [\"gyro_z\"]\nexpr = [{}]\nsigma = [0.005]",
            if *sign < 0.0 { "opposes" } else { "is" },
            quote(if *sign < 0.0 { "-omega" } else { "omega" })
        );
    }
    if let Some((link, [sx, sy])) = &r.landmark_sensor {
        // the sensor's position in the world: the base pose moved by its mounting
        let px = linear(
            0.0,
            &[(1.0, "x"), (*sx, "cos(theta)"), (-*sy, "sin(theta)")],
        );
        let py = linear(0.0, &[(1.0, "y"), (*sx, "sin(theta)"), (*sy, "cos(theta)")]);
        let (dx, dy) = if px == "x" {
            ("xl - x".to_string(), "yl - y".to_string())
        } else {
            (format!("xl - ({px})"), format!("yl - ({py})"))
        };
        let _ = writeln!(
            out,
            "\n# range and bearing to mapped landmarks, from the sensor on link `{link}` at ({}, {}) in the base frame\n[[observation]]\nname = \"landmark\"\ndoc = \"Range and bearing to a known landmark from the sensor's mounting point.\"\nlandmark = true\ncolumns = [\"range\", \"bearing\"]\nexpr = [{}, {}]\nangle = [false, true]\nsigma = [0.05, 0.02]",
            num(*sx),
            num(*sy),
            quote(&format!("sqrt(({dx})^2 + ({dy})^2)")),
            quote(&format!("atan2({dy}, {dx}) - theta")),
        );
    }
}

fn controller(out: &mut String, r: &Robot) {
    let Some(c) = &r.controller else { return };
    let _ = writeln!(
        out,
        "\n# where `fit --export ros2-yaml` writes the calibrated values: this node of the\n# controller file, each key the value of its expression over the parameters\n[controller]\nnode = {}\ntype = {}\nfile = {}\n\n[controller.values]",
        quote(&c.node),
        quote(&c.type_name),
        quote(&c.file)
    );
    for (k, e) in &c.values {
        let _ = writeln!(out, "{} = {}", quote(k), quote(e));
    }
}

/// The spec text. `header` is the comment block that opens it.
pub fn spec(r: &Robot, header: &str) -> String {
    let mut out = String::new();
    for l in header.lines() {
        let _ = writeln!(out, "# {l}");
    }
    let _ = writeln!(
        out,
        "name = {}\ndoc = {}\nstate = [\"x\", \"y\", \"theta\"]",
        quote(&r.name),
        quote(&r.doc)
    );
    for i in &r.inputs {
        let _ = writeln!(
            out,
            "\n[[input]]\nname = {}\ncolumn = {}",
            quote(&i.name),
            quote(&i.column)
        );
        let (kind, unit) = match i.role {
            InputRole::Wheel => ("cumulative", "rad/s"),
            InputRole::Steering => ("absolute", "rad"),
            InputRole::Command { unit, .. } => ("absolute", unit),
        };
        let _ = writeln!(out, "kind = {}\nunit = {}", quote(kind), quote(unit));
        if let Some([lo, hi]) = i.range {
            let _ = writeln!(out, "range = [{}, {}]", num(lo), num(hi));
        }
        let _ = writeln!(out, "doc = {}", quote(&capitalise(&i.doc)));
    }
    for p in &r.params {
        param(&mut out, p);
    }
    noise(&mut out, &r.kinematics);
    for (name, expr, doc) in &r.defines {
        let _ = writeln!(
            out,
            "\n[[define]]\nname = {}\nexpr = {}\ndoc = {}",
            quote(name),
            quote(expr),
            quote(doc)
        );
    }
    kinematics(&mut out, &r.kinematics);
    observations(&mut out, r);
    controller(&mut out, r);
    out
}

fn capitalise(s: &str) -> String {
    let mut c = s.chars();
    c.next().map_or(String::new(), |f| {
        f.to_uppercase().collect::<String>() + c.as_str()
    })
}

/// The `--topics` mapping for bags: every input's joint, the IMU, and where
/// ground truth would come from.
pub fn topics(r: &Robot, base_frame: &str, header: &str) -> String {
    let mut out = String::new();
    // the frame the spec's pose observation is of, where it has one
    let measured = r
        .odometry_frame
        .as_ref()
        .map_or(base_frame, |(l, _)| l.as_str());
    for l in header.lines() {
        let _ = writeln!(out, "# {l}");
    }
    let commands = r
        .inputs
        .iter()
        .any(|i| matches!(i.role, InputRole::Command { .. }));
    let _ = writeln!(
        out,
        "stamps = \"header\"\n\n# {}\n[inputs]",
        if commands {
            "each input column is a component of the velocity commands (geometry_msgs Twist or TwistStamped)"
        } else {
            "each input column is the joint of the same name in sensor_msgs/JointState"
        }
    );
    for i in &r.inputs {
        let source = match i.role {
            InputRole::Command { field, .. } => format!(
                "topic = {}, field = {}",
                quote(&r.command_topic),
                quote(field)
            ),
            _ => format!("topic = \"/joint_states\", joint = {}", quote(&i.column)),
        };
        let _ = writeln!(out, "{} = {{ {source} }}", quote(&i.column));
    }
    let _ = writeln!(
        out,
        "\n# ground truth for compare/fit/diagnose: a motion-capture or map-localised pose of\n# `{measured}` (PoseStamped, Odometry or TF). Not the controller's own odometry:\n# that is the wheel model itself. Rename the topic to yours.\n[pose]\ntopic = \"/tf\"\nframe = {}",
        quote(measured)
    );
    if r.gyro.is_some() {
        let _ = writeln!(out, "\n# the IMU (sensor_msgs/Imu): its angular_velocity.z is gyro_z\n[gyro]\ntopic = \"/imu/data\"");
    }
    if !commands {
        let _ = writeln!(out, "{}", commands_hint(r));
    }
    out
}

/// The pose observation of the controller's odometry frame `link`, at
/// (x, y, yaw) in the base frame: what a motion-capture or map-localised
/// pose of that frame (the topics file's `[pose]`) measures.
fn pose_observation(out: &mut String, link: &str, [ox, oy, yaw]: [f64; 3]) {
    let px = linear(0.0, &[(1.0, "x"), (ox, "cos(theta)"), (-oy, "sin(theta)")]);
    let py = linear(0.0, &[(1.0, "y"), (ox, "sin(theta)"), (oy, "cos(theta)")]);
    // rounded as the coefficients are: a yaw of 0.1 read back as 0.09999999999999999
    let heading = linear(crate::classify::tidy(yaw), &[(1.0, "theta")]);
    let place = if [ox, oy, yaw].iter().all(|v| v.abs() < 1e-12) {
        "the base frame itself".to_string()
    } else {
        format!(
            "at x {ox:.4} m, y {oy:.4} m, yaw {yaw:.4} rad in the base frame (the URDF's joints)"
        )
    };
    let _ = writeln!(
        out,
        "\n# the controller's odometry frame `{link}` ({place}):\n# a measured pose of it (gt_x, gt_y, gt_theta) is seen through this observation\n[[observation]]\nname = \"pose\"\nrole = \"pose\"\ndoc = \"Pose of `{link}`, the frame the controller's odometry is of.\"\ncolumns = [\"gt_x\", \"gt_y\", \"gt_theta\"]\nexpr = [{}, {}, {}]\nangle = [false, false, true]\nsigma = [0.01, 0.01, 0.01]",
        quote(&px),
        quote(&py),
        quote(&heading)
    );
}

/// For a bag that logged the robot's velocity commands and not its wheel
/// joints: the mapping of the controller's command topic, commented out (its
/// inputs are a spec of commands, not this one's wheels).
fn commands_hint(r: &Robot) -> String {
    let topic = &r.command_topic;
    let sideways = matches!(r.class, Class::Mecanum | Class::Omni | Class::Swerve);
    let mut hint = format!(
        "\n# A bag without the wheel joints, only the velocity commands the controller\n\
         # was sent (geometry_msgs Twist or TwistStamped): give the spec command inputs\n\
         # (`kinegen init --commands` writes that spec and this mapping) and map them:\n\
         # [inputs]\n\
         # v = {{ topic = \"{topic}\", field = \"linear.x\" }}\n"
    );
    if sideways {
        hint += &format!("# v_y = {{ topic = \"{topic}\", field = \"linear.y\" }}\n");
    }
    hint += &format!("# omega = {{ topic = \"{topic}\", field = \"angular.z\" }}");
    hint
}
