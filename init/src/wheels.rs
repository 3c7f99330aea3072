//! The wheels of a description, in the base link's frame: where each one is,
//! how it spins, what it is (driven, steered, a caster, an omni or mecanum
//! wheel with rollers), and the joint that steers it.
use crate::error::InitError;
use crate::urdf::{Joint, JointType, Urdf};
use nalgebra::Vector3;

/// A joint that turns a wheel about the vertical.
#[derive(Debug, Clone)]
pub struct Steer {
    pub joint: String,
    pub line: usize,
    /// +1 when the joint's positive rotation turns the wheel to the left
    /// (axis up), -1 when its axis points down.
    pub sign: f64,
    /// The joint's limits (rad), for the input's range.
    pub limits: Option<[f64; 2]>,
}

#[derive(Debug, Clone)]
pub struct Wheel {
    /// The spin joint (the log's joint_states name).
    pub joint: String,
    pub line: usize,
    pub link: String,
    pub radius: f64,
    /// The radius as the file writes it, and where (for its precision and comments).
    pub radius_text: String,
    pub radius_line: usize,
    /// `cylinder` or `sphere`.
    pub shape: &'static str,
    /// The wheel centre in the base frame (m).
    pub position: Vector3<f64>,
    /// The unit spin axis in the base frame.
    pub axis: Vector3<f64>,
    /// A revolute joint about the vertical between the base and the wheel.
    pub steer: Option<Steer>,
    /// A free swivel about the vertical (a caster).
    pub caster: bool,
    /// The wheel carries rollers (continuous joints below it): omni or mecanum.
    pub rollers: bool,
    /// Follows another joint (`<mimic>`): not an input of its own.
    pub mimic: bool,
}

impl Wheel {
    /// The direction the wheel centre moves for a positive spin, in the base
    /// frame: v = r w (axis x z) for rolling without slip.
    pub fn rolling(&self) -> Vector3<f64> {
        self.axis.cross(&Vector3::z())
    }
}

/// Whether a joint turns about the vertical of the base frame.
fn vertical(axis_in_base: &Vector3<f64>) -> bool {
    axis_in_base.z.abs() > 0.9
}

/// The wheels below `base`. A wheel is a continuous joint (or a revolute one
/// the controller names as a wheel) whose axis is horizontal in the base
/// frame, not below another wheel (those are rollers).
pub fn find(urdf: &Urdf, base: &str, named_wheels: &[String]) -> Result<Vec<Wheel>, InitError> {
    let mut wheels: Vec<Wheel> = Vec::new();
    let mut wheel_links: Vec<String> = Vec::new();
    // parents before children: rollers come after their wheel
    let mut joints: Vec<&Joint> = urdf.joints.iter().collect();
    joints.sort_by_key(|j| urdf.depth(&j.child));
    for j in joints {
        let spins = j.kind == JointType::Continuous
            || (j.kind == JointType::Revolute && named_wheels.contains(&j.name));
        if !spins {
            continue;
        }
        let (pose, chain) = urdf.pose_in(base, &j.child);
        if chain.is_empty() {
            continue; // above the base link
        }
        let axis = pose.rotation * j.axis;
        if vertical(&axis) || axis.z.abs() > 0.2 {
            continue; // a swivel or a steering joint, not a wheel
        }
        // below a wheel: one of its rollers
        if let Some(hub) = chain.iter().find(|c| wheel_links.contains(&c.parent)) {
            if let Some(w) = wheels.iter_mut().find(|w| w.link == hub.parent) {
                w.rollers = true;
            }
            continue;
        }
        let link = &urdf.links[&j.child];
        let Some(shape) = &link.shape else {
            if named_wheels.contains(&j.name) || link.has_mesh || looks_like_wheel(&j.name) {
                return Err(InitError::at(
                    &urdf.file,
                    Some(link.line),
                    format!(
                        "wheel joint `{}` (line {}): its link `{}` has no cylinder or sphere geometry{}, so its radius is unknown; give the link a <collision> cylinder",
                        j.name,
                        j.line,
                        link.name,
                        if link.has_mesh { " (only a mesh)" } else { "" }
                    ),
                ));
            }
            continue;
        };
        let mut steer = None;
        let mut caster = false;
        for c in chain.iter().filter(|c| c.name != j.name) {
            let (cpose, _) = urdf.pose_in(base, &c.child);
            let caxis = cpose.rotation * c.axis;
            if !vertical(&caxis) {
                continue;
            }
            // a continuous joint about the vertical is a caster's swivel,
            // unless ros2_control commands it: a swerve module's steering
            let continuous = c.kind == JointType::Continuous;
            if c.kind == JointType::Revolute || (continuous && urdf.commanded.contains(&c.name)) {
                steer = Some(Steer {
                    joint: c.name.clone(),
                    line: c.line,
                    sign: caxis.z.signum(),
                    limits: c.limits,
                });
            } else if continuous {
                caster = true;
            }
        }
        wheel_links.push(j.child.clone());
        wheels.push(Wheel {
            joint: j.name.clone(),
            line: j.line,
            link: link.name.clone(),
            radius: shape.radius(),
            radius_text: link.radius_text.clone().unwrap_or_default(),
            radius_line: shape.line(),
            shape: shape.kind(),
            position: pose.translation.vector.map(crate::classify::tidy),
            axis: axis.map(crate::classify::tidy).normalize(),
            steer,
            caster,
            rollers: false,
            mimic: j.mimic.is_some(),
        });
    }
    if wheels.is_empty() {
        return Err(InitError::at(
            &urdf.file,
            None,
            format!(
                "no wheels found below `{base}`: a wheel is a continuous joint with a horizontal axis whose child link has a cylinder or sphere"
            ),
        ));
    }
    check_axles(urdf, &wheels)?;
    Ok(wheels)
}

fn looks_like_wheel(name: &str) -> bool {
    name.to_ascii_lowercase().contains("wheel")
}

/// Two wheels on one axle line (parallel axes through the same line) must
/// have the same radius: different radii there are a typing error.
fn check_axles(urdf: &Urdf, wheels: &[Wheel]) -> Result<(), InitError> {
    for (i, a) in wheels.iter().enumerate() {
        for b in &wheels[i + 1..] {
            let parallel = a.axis.cross(&b.axis).norm() < 1e-6;
            let offset = b.position - a.position;
            let on_line = offset.cross(&a.axis).norm() < 1e-6;
            let steered = a.steer.is_some() || b.steer.is_some() || a.caster || b.caster;
            let differ = (a.radius - b.radius).abs() > 1e-9 * a.radius.max(b.radius);
            if parallel && on_line && !steered && differ {
                return Err(InitError::at(
                    &urdf.file,
                    Some(b.radius_line),
                    format!(
                        "wheels `{}` (radius {} on line {}) and `{}` (radius {} on line {}) share an axle but have different radii",
                        a.joint, a.radius_text, a.radius_line, b.joint, b.radius_text, b.radius_line
                    ),
                ));
            }
        }
    }
    Ok(())
}
