//! kinegen-init: a spec from the robot's own description.
//!
//! A ROS robot has its geometry written down already: in its URDF (wheel
//! joints, their origins, the wheels' cylinders, steering joints, casters)
//! and in its ros2_control controller configuration (which joints drive,
//! wheel_separation, wheel_radius, multipliers). `kinegen init` reads both and
//! writes the spec a person would have written, and a `--topics` mapping for
//! the robot's bags:
//!
//! ```text
//! URDF (urdf) ──► wheels (wheels) ──► class and geometry (classify) ──► Robot ──► spec text (write)
//! controller YAML (controller) ──┘        numbers checked against each other (geometry)
//! ```
//!
//! ```
//! let urdf = r#"<robot name="cart">
//!   <link name="chassis"/>
//!   <link name="wl"><collision><geometry><cylinder radius="0.05" length="0.02"/></geometry></collision></link>
//!   <link name="wr"><collision><geometry><cylinder radius="0.05" length="0.02"/></geometry></collision></link>
//!   <joint name="drive_l" type="continuous"><parent link="chassis"/><child link="wl"/>
//!     <origin xyz="0 0.15 0" rpy="-1.5707963267948966 0 0"/><axis xyz="0 0 1"/></joint>
//!   <joint name="drive_r" type="continuous"><parent link="chassis"/><child link="wr"/>
//!     <origin xyz="0 -0.15 0" rpy="-1.5707963267948966 0 0"/><axis xyz="0 0 1"/></joint>
//! </robot>"#;
//! let out = kinegen_init::from_text("cart.urdf".as_ref(), urdf, None, &Default::default()).unwrap();
//! assert_eq!(out.class, kinegen_init::Class::DiffDrive);
//! assert!(out.spec.contains("name = \"wheel_separation\"\nnominal = 0.3"));
//! ```
mod classify;
mod commands;
mod controller;
pub mod controller_write;
mod error;
mod geometry;
mod robot;
mod urdf;
mod wheels;
mod write;
mod xacro;

pub use controller::{Controller, ControllerKind};
pub use error::InitError;
pub use robot::Class;

use classify::Context;
use std::path::Path;
use urdf::Urdf;
use wheels::Wheel;

/// What `init` can be told besides the files.
#[derive(Debug, Clone, Default)]
pub struct Options {
    /// The robot's body frame (default: the controller's `base_frame_id`,
    /// else the URDF's root link).
    pub base_link: Option<String>,
    /// Where the spec will be written: the controller file is recorded
    /// relative to it.
    pub spec_path: Option<std::path::PathBuf>,
    /// A spec of the velocity commands (`cmd_vel`) rather than the wheel
    /// joints, for bags that logged only what the controller was sent.
    pub commands: bool,
}

/// A spec and its topic mapping, with what the user should know about them.
#[derive(Debug, Clone)]
pub struct Initialised {
    pub class: Class,
    pub name: String,
    pub base_link: String,
    pub spec: String,
    pub topics: String,
    /// Wheels found: joint, role.
    pub wheels: Vec<(String, String)>,
    pub notes: Vec<String>,
}

/// Read the URDF (expanding a `.xacro` with the `xacro` tool) and the
/// optional controller file, and write the spec.
pub fn from_files(
    urdf: &Path,
    controller: Option<&Path>,
    options: &Options,
) -> Result<Initialised, InitError> {
    let text = xacro::read(urdf)?;
    let ctl = controller.map(Controller::read).transpose()?;
    from_text(urdf, &text, ctl.as_ref(), options)
}

fn choose_base(
    urdf: &Urdf,
    ctl: Option<&Controller>,
    options: &Options,
) -> Result<String, InitError> {
    if let Some(b) = &options.base_link {
        if !urdf.links.contains_key(b) {
            let known: Vec<&str> = urdf.links.keys().map(String::as_str).collect();
            return Err(InitError::at(
                Path::new("--base-link"),
                None,
                format!(
                    "`{b}` is not a link of {} (its links: {})",
                    urdf.file.display(),
                    known.join(", ")
                ),
            ));
        }
        return Ok(b.clone());
    }
    if let Some(b) = ctl
        .and_then(|c| c.text("base_frame_id"))
        .filter(|b| urdf.links.contains_key(b))
    {
        return Ok(b);
    }
    match urdf.roots().as_slice() {
        [one] => Ok(one.to_string()),
        many => Err(InitError::at(
            &urdf.file,
            None,
            format!("no base link: the links {} are each the root of a tree; choose one with --base-link", many.join(", ")),
        )),
    }
}

/// The joints the controller drives, checked against the URDF.
fn controller_joints(urdf: &Urdf, ctl: &Controller) -> Result<Vec<String>, InitError> {
    let keys: &[&str] = match ctl.kind {
        ControllerKind::DiffDrive => &["left_wheel_names", "right_wheel_names"],
        ControllerKind::Tricycle => &["traction_joint_name", "steering_joint_name"],
        ControllerKind::Steering => &[
            "rear_wheels_names",
            "traction_joints_names",
            "front_wheels_names",
            "steering_joints_names",
        ],
        ControllerKind::Mecanum => &[
            "front_left_wheel_command_joint_name",
            "front_right_wheel_command_joint_name",
            "rear_left_wheel_command_joint_name",
            "rear_right_wheel_command_joint_name",
        ],
    };
    let mut out = Vec::new();
    for k in keys {
        for name in ctl.names(k) {
            if !urdf.joints.iter().any(|j| j.name == name) {
                return Err(InitError::at(
                    &ctl.file,
                    ctl.line(k),
                    format!(
                        "{}.{k} names joint `{name}`, which {} does not have",
                        ctl.node,
                        urdf.file.display()
                    ),
                ));
            }
            out.push(name);
        }
    }
    // the steering library's front wheels are steered, not driven (front_steering: true)
    if ctl.kind == ControllerKind::Steering {
        let steer: Vec<String> = ctl
            .names("front_wheels_names")
            .into_iter()
            .chain(ctl.names("steering_joints_names"))
            .collect();
        out.retain(|j| !steer.contains(j));
    }
    Ok(out)
}

fn choose_class(
    wheels: &[Wheel],
    cx: &Context,
    notes: &mut Vec<String>,
) -> Result<robot::Robot, InitError> {
    let rolling: Vec<&Wheel> = wheels.iter().filter(|w| !w.caster).collect();
    let parallel = rolling
        .iter()
        .all(|w| w.axis.cross(&rolling[0].axis).norm() < 1e-6);
    if rolling.len() >= 3 && rolling.iter().all(|w| w.steer.is_some()) {
        return classify::swerve(cx, notes);
    }
    if wheels.iter().any(|w| w.steer.is_some()) {
        let steered: Vec<&Wheel> = wheels.iter().filter(|w| w.steer.is_some()).collect();
        let drives = |w: &&Wheel| cx.driven.contains(&w.joint);
        if steered.len() == 1 && drives(&steered[0]) {
            return classify::front_driven_tricycle(cx, notes);
        }
        let rear_drives = (rolling.iter()).any(|w| w.steer.is_none() && drives(w));
        if steered.iter().any(drives) && !rear_drives {
            return classify::front_driven_steering(cx, notes);
        }
        return classify::rear_driven_steering(cx, notes);
    }
    let mecanum_ctl = cx
        .controller
        .is_some_and(|c| c.kind == ControllerKind::Mecanum);
    if mecanum_ctl || (parallel && rolling.iter().any(|w| w.rollers)) {
        return classify::mecanum(cx, notes);
    }
    if !parallel {
        return classify::omni(cx, notes);
    }
    classify::differential(cx, notes)
}

/// The spec for a URDF given as text (`file` names it in messages).
pub fn from_text(
    file: &Path,
    text: &str,
    ctl: Option<&Controller>,
    options: &Options,
) -> Result<Initialised, InitError> {
    let urdf = Urdf::parse(file, text)?;
    let base = choose_base(&urdf, ctl, options)?;
    let named: Vec<String> = match ctl {
        Some(c) => controller_joints(&urdf, c)?,
        None => Vec::new(),
    };
    let wheels = wheels::find(&urdf, &base, &named)?;
    let mut notes = Vec::new();
    let mut driven: Vec<String> = named.clone();
    if driven.is_empty() {
        driven = urdf.commanded.clone();
    }
    if driven.is_empty() {
        driven = wheels
            .iter()
            .filter(|w| !w.caster && w.steer.is_none())
            .map(|w| w.joint.clone())
            .collect();
        notes.push(
            "no controller file and no <ros2_control> block: every fixed wheel is taken as driven"
                .into(),
        );
    }
    for w in wheels.iter().filter(|w| w.caster) {
        notes.push(format!(
            "`{}` (line {}) is a caster: passive, not in the kinematics",
            w.joint, w.line
        ));
    }
    let mimics = urdf
        .joints
        .iter()
        .filter(|j| j.mimic.is_some())
        .map(|j| j.name.clone())
        .collect();
    let cx = Context {
        file,
        wheels: &wheels,
        driven,
        mimics,
        controller: ctl,
    };
    let mut robot = choose_class(&wheels, &cx, &mut notes)?;
    robot.name = classify::identifier(&urdf.name);
    robot.doc = format!(
        "{} `{}`, written by kinegen init from its URDF{}.",
        capital(robot.class.describe()),
        urdf.name,
        if ctl.is_some() {
            " and controller configuration"
        } else {
            ""
        }
    );
    robot.gyro = urdf.imu_links.first().map(|l| {
        let (pose, _) = urdf.pose_in(&base, l);
        (
            (pose.rotation * nalgebra::Vector3::z()).z.signum(),
            l.clone(),
        )
    });
    robot.landmark_sensor = urdf.sensor_links.first().map(|l| {
        let (pose, _) = urdf.pose_in(&base, l);
        (
            l.clone(),
            [pose.translation.vector.x, pose.translation.vector.y],
        )
    });
    robot.odometry_frame = ctl.and_then(|c| odometry_frame(&urdf, c, &base));
    if let (Some(c), Some(out)) = (ctl, robot.controller.as_mut()) {
        out.file = relative_to(&c.file, options.spec_path.as_deref());
    }
    if let Some(c) = &robot.controller {
        robot.command_topic = format!("/{}/cmd_vel", c.node);
    }
    if options.commands {
        robot = commands::commanded(robot);
        robot.doc = format!(
            "{} `{}` driven by its velocity commands, written by kinegen init from its URDF.",
            capital(robot.class.describe()),
            urdf.name
        );
    }
    finish(file, &urdf, &base, &wheels, robot, notes)
}

/// The link the controller's odometry is of, where the controller
/// publishes odometry (it names an `odom_frame_id` or a `base_frame_id`):
/// its `base_frame_id` (ros2_control's default `base_link`) when the URDF
/// has it, else the base; with its pose (x, y, yaw) in the base frame.
fn odometry_frame(urdf: &Urdf, ctl: &Controller, base: &str) -> Option<(String, [f64; 3])> {
    let named = ctl.text("base_frame_id");
    if named.is_none() && ctl.text("odom_frame_id").is_none() {
        return None;
    }
    let link = named
        .or_else(|| Some("base_link".to_string()))
        .filter(|l| urdf.links.contains_key(l))
        .unwrap_or_else(|| base.to_string());
    let (pose, _) = urdf.pose_in(base, &link);
    let (_, _, yaw) = pose.rotation.euler_angles();
    let at = pose.translation.vector;
    Some((link, [at.x, at.y, yaw]))
}

pub(crate) fn capital(s: &str) -> String {
    let mut c = s.chars();
    c.next().map_or(String::new(), |f| {
        f.to_uppercase().collect::<String>() + c.as_str()
    })
}

/// `file` as the spec at `spec` would reach it (relative to its folder, which
/// need not exist yet), else as given.
fn relative_to(file: &Path, spec: Option<&Path>) -> String {
    let dir = spec.map(|s| s.parent().unwrap_or(Path::new("")));
    match (dir.map(std::path::absolute), std::path::absolute(file)) {
        (Some(Ok(dir)), Ok(f)) => pathdiff(&f, &dir),
        _ => file.display().to_string(),
    }
}

/// `f` relative to `dir` (both absolute), walking up with `..` as needed.
fn pathdiff(f: &Path, dir: &Path) -> String {
    let (fc, dc): (Vec<_>, Vec<_>) = (f.components().collect(), dir.components().collect());
    let common = fc.iter().zip(&dc).take_while(|(a, b)| a == b).count();
    let mut out = std::path::PathBuf::new();
    for _ in common..dc.len() {
        out.push("..");
    }
    for c in &fc[common..] {
        out.push(c);
    }
    out.display().to_string()
}

fn finish(
    file: &Path,
    urdf: &Urdf,
    base: &str,
    wheels: &[Wheel],
    mut robot: robot::Robot,
    notes: Vec<String>,
) -> Result<Initialised, InitError> {
    let header = format!(
        "{}: written by kinegen init from {} (base link `{base}`).\nEvery number says where it came from; edit freely (the spec reference: spec/README.md).",
        robot.name,
        file.display()
    );
    robot.notes = notes;
    let spec = write::spec(&robot, &header);
    // never hand the user a spec the tools would refuse
    if let Err(e) = kinegen_model::spec::Model::parse(Path::new("(spec written by init)"), &spec) {
        return Err(InitError::at(file, None, format!("kinegen init wrote a spec it cannot read back ({e}); please report this with the URDF")));
    }
    let roles = wheels
        .iter()
        .map(|w| {
            let role = if w.caster {
                "caster"
            } else if w.steer.is_some() {
                "steered"
            } else if w.rollers {
                "rollers"
            } else {
                "wheel"
            };
            (
                w.joint.clone(),
                format!(
                    "{role}, radius {} m at ({}, {})",
                    w.radius_text,
                    classify::num(w.position.x),
                    classify::num(w.position.y)
                ),
            )
        })
        .collect();
    let _ = urdf;
    Ok(Initialised {
        class: robot.class,
        name: robot.name.clone(),
        base_link: base.to_string(),
        topics: write::topics(
            &robot,
            base,
            &format!(
                "{}: the --topics mapping for bags, written by kinegen init",
                robot.name
            ),
        ),
        spec,
        wheels: roles,
        notes: robot.notes,
    })
}
