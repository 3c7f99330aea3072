//! A URDF read into typed links and joints, each with the line it is on, and
//! checked as a tree (one parent per link, no loops, one root).
//!
//! Only what kinematics needs is kept: joint types, origins, axes and limits;
//! links' cylinder and sphere geometry; which links carry an IMU.
use crate::error::InitError;
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};

/// A wheel-like shape of a link, in the link's frame.
#[derive(Debug, Clone, PartialEq)]
pub enum Shape {
    /// Axis along the shape frame's z.
    Cylinder {
        radius: f64,
        length: f64,
        line: usize,
    },
    Sphere {
        radius: f64,
        line: usize,
    },
}

impl Shape {
    pub fn radius(&self) -> f64 {
        match self {
            Shape::Cylinder { radius, .. } | Shape::Sphere { radius, .. } => *radius,
        }
    }
    pub fn line(&self) -> usize {
        match self {
            Shape::Cylinder { line, .. } | Shape::Sphere { line, .. } => *line,
        }
    }
    /// The printed radius as it stands in the file (for its precision).
    pub fn kind(&self) -> &'static str {
        match self {
            Shape::Cylinder { .. } => "cylinder",
            Shape::Sphere { .. } => "sphere",
        }
    }
}

#[derive(Debug, Clone)]
pub struct Link {
    pub name: String,
    pub line: usize,
    /// The collision shape if there is one (what touches the ground), else the visual's.
    pub shape: Option<Shape>,
    /// The radius exactly as the file writes it (its digits give its precision).
    pub radius_text: Option<String>,
    /// A mesh instead of a primitive (named in errors).
    pub has_mesh: bool,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum JointType {
    Continuous,
    Revolute,
    Fixed,
    Prismatic,
    Floating,
    Planar,
}

#[derive(Debug, Clone)]
pub struct Joint {
    pub name: String,
    pub line: usize,
    pub kind: JointType,
    pub parent: String,
    pub child: String,
    /// Child frame in the parent frame.
    pub origin: Isometry3<f64>,
    /// Unit axis in the joint (child) frame; URDF's default is x.
    pub axis: Vector3<f64>,
    /// `<mimic joint=...>`: this joint follows another (not an input of its own).
    pub mimic: Option<String>,
    /// `<limit lower upper>` of a revolute joint (rad).
    pub limits: Option<[f64; 2]>,
}

/// The description: links by name, joints in file order, and the links an
/// IMU is attached to (a `<sensor type="imu">` referencing it, or its name).
#[derive(Debug, Clone)]
pub struct Urdf {
    pub file: PathBuf,
    pub name: String,
    pub links: BTreeMap<String, Link>,
    pub joints: Vec<Joint>,
    pub imu_links: Vec<String>,
    /// Links an exteroceptive sensor (camera, laser) is attached to.
    pub sensor_links: Vec<String>,
    /// Joints a `<ros2_control>` block or a `<transmission>` commands.
    pub commanded: Vec<String>,
}

fn line_of(doc: &roxmltree::Document, node: roxmltree::Node) -> usize {
    doc.text_pos_at(node.range().start).row as usize
}

struct Reader<'a, 'input> {
    file: &'a Path,
    doc: &'a roxmltree::Document<'input>,
}

impl<'a, 'input> Reader<'a, 'input> {
    fn err(&self, node: roxmltree::Node, msg: impl Into<String>) -> InitError {
        InitError::at(self.file, Some(line_of(self.doc, node)), msg)
    }

    fn attr<'n>(&self, node: roxmltree::Node<'n, 'input>, name: &str) -> Result<&'n str, InitError>
    where
        'input: 'n,
    {
        node.attribute(name).ok_or_else(|| {
            self.err(
                node,
                format!("<{}> has no `{name}` attribute", node.tag_name().name()),
            )
        })
    }

    fn number(&self, node: roxmltree::Node, name: &str) -> Result<f64, InitError> {
        let text = self.attr(node, name)?;
        let v: f64 = text.trim().parse().map_err(|_| {
            self.err(
                node,
                format!(
                    "<{}> {name}=\"{text}\" is not a number",
                    node.tag_name().name()
                ),
            )
        })?;
        if !v.is_finite() {
            return Err(self.err(node, format!("{name}=\"{text}\" is not finite")));
        }
        Ok(v)
    }

    fn triple(
        &self,
        node: roxmltree::Node,
        name: &str,
        default: [f64; 3],
    ) -> Result<[f64; 3], InitError> {
        let Some(text) = node.attribute(name) else {
            return Ok(default);
        };
        let parts: Vec<&str> = text.split_whitespace().collect();
        let values: Option<Vec<f64>> = parts
            .iter()
            .map(|p| p.parse::<f64>().ok().filter(|v| v.is_finite()))
            .collect();
        match values {
            Some(v) if v.len() == 3 => Ok([v[0], v[1], v[2]]),
            _ => Err(self.err(
                node,
                format!(
                    "<{}> {name}=\"{text}\" is not three numbers",
                    node.tag_name().name()
                ),
            )),
        }
    }

    fn origin(&self, parent: roxmltree::Node) -> Result<Isometry3<f64>, InitError> {
        let Some(o) = child(parent, "origin") else {
            return Ok(Isometry3::identity());
        };
        let [x, y, z] = self.triple(o, "xyz", [0.0; 3])?;
        let [r, p, yaw] = self.triple(o, "rpy", [0.0; 3])?;
        // URDF's rpy: fixed-axis roll, pitch, yaw = Rz(yaw) Ry(p) Rx(r), nalgebra's convention
        Ok(Isometry3::from_parts(
            Translation3::new(x, y, z),
            UnitQuaternion::from_euler_angles(r, p, yaw),
        ))
    }

    /// The shape of a `<visual>` or `<collision>`: a cylinder or sphere (in
    /// the link's frame, through its origin), a mesh, or nothing usable.
    fn shape(
        &self,
        element: roxmltree::Node,
    ) -> Result<(Option<(Shape, String)>, bool), InitError> {
        let Some(g) = child(element, "geometry") else {
            return Ok((None, false));
        };
        if let Some(c) = child(g, "cylinder") {
            let shape = Shape::Cylinder {
                radius: self.number(c, "radius")?,
                length: self.number(c, "length")?,
                line: line_of(self.doc, c),
            };
            return Ok((
                Some((shape, self.attr(c, "radius")?.trim().to_string())),
                false,
            ));
        }
        if let Some(s) = child(g, "sphere") {
            let shape = Shape::Sphere {
                radius: self.number(s, "radius")?,
                line: line_of(self.doc, s),
            };
            return Ok((
                Some((shape, self.attr(s, "radius")?.trim().to_string())),
                false,
            ));
        }
        Ok((None, child(g, "mesh").is_some()))
    }

    fn link(&self, node: roxmltree::Node) -> Result<Link, InitError> {
        let name = self.attr(node, "name")?.to_string();
        let mut shape = None;
        let mut has_mesh = false;
        // collision first: it is the shape that meets the ground
        for tag in ["collision", "visual"] {
            for e in node.children().filter(|c| c.has_tag_name(tag)) {
                let (s, mesh) = self.shape(e)?;
                has_mesh |= mesh;
                if shape.is_none() {
                    shape = s;
                }
            }
        }
        let (shape, radius_text) = match shape {
            Some((s, t)) => (Some(s), Some(t)),
            None => (None, None),
        };
        Ok(Link {
            name,
            line: line_of(self.doc, node),
            shape,
            radius_text,
            has_mesh,
        })
    }

    fn joint(&self, node: roxmltree::Node) -> Result<Joint, InitError> {
        let name = self.attr(node, "name")?.to_string();
        let kind = match self.attr(node, "type")? {
            "continuous" => JointType::Continuous,
            "revolute" => JointType::Revolute,
            "fixed" => JointType::Fixed,
            "prismatic" => JointType::Prismatic,
            "floating" => JointType::Floating,
            "planar" => JointType::Planar,
            other => {
                return Err(self.err(
                    node,
                    format!("joint `{name}` has type \"{other}\" (URDF's are continuous, revolute, fixed, prismatic, floating, planar)"),
                ))
            }
        };
        let link_of = |tag: &str| -> Result<String, InitError> {
            let e = child(node, tag)
                .ok_or_else(|| self.err(node, format!("joint `{name}` has no <{tag}>")))?;
            Ok(self.attr(e, "link")?.to_string())
        };
        let axis = match child(node, "axis") {
            Some(a) => {
                let v = Vector3::from(self.triple(a, "xyz", [1.0, 0.0, 0.0])?);
                if v.norm() < 1e-12 {
                    return Err(self.err(a, format!("joint `{name}`: its axis is zero")));
                }
                v.normalize()
            }
            None => Vector3::x(),
        };
        Ok(Joint {
            parent: link_of("parent")?,
            child: link_of("child")?,
            origin: self.origin(node)?,
            axis,
            limits: match child(node, "limit") {
                Some(l) if l.attribute("lower").is_some() && l.attribute("upper").is_some() => {
                    Some([self.number(l, "lower")?, self.number(l, "upper")?])
                }
                _ => None,
            },
            mimic: child(node, "mimic").and_then(|m| m.attribute("joint").map(str::to_string)),
            kind,
            line: line_of(self.doc, node),
            name,
        })
    }
}

fn child<'a, 'input>(
    node: roxmltree::Node<'a, 'input>,
    tag: &str,
) -> Option<roxmltree::Node<'a, 'input>> {
    node.children().find(|c| c.has_tag_name(tag))
}

impl Urdf {
    /// Parse URDF text (`file` names it in errors) and check it is a tree.
    pub fn parse(file: &Path, text: &str) -> Result<Urdf, InitError> {
        let doc = roxmltree::Document::parse(text).map_err(|e| {
            let p = e.pos();
            InitError {
                file: file.to_path_buf(),
                line: Some(p.row as usize),
                column: Some(p.col as usize),
                message: format!("not well-formed XML: {e}"),
            }
        })?;
        let r = Reader { file, doc: &doc };
        let root = doc.root_element();
        if !root.has_tag_name("robot") {
            return Err(r.err(
                root,
                format!(
                    "the root element is <{}>, not <robot>: is this a URDF?",
                    root.tag_name().name()
                ),
            ));
        }
        let mut links = BTreeMap::new();
        let mut joints = Vec::new();
        let mut imu_links = Vec::new();
        let mut sensor_links = Vec::new();
        let mut commanded = Vec::new();
        for node in root.children().filter(|n| n.is_element()) {
            match node.tag_name().name() {
                "link" => {
                    let l = r.link(node)?;
                    if let Some(first) = links.get(&l.name).map(|f: &Link| f.line) {
                        return Err(r.err(
                            node,
                            format!(
                                "link `{}` is declared twice (first on line {first})",
                                l.name
                            ),
                        ));
                    }
                    links.insert(l.name.clone(), l);
                }
                "joint" => joints.push(r.joint(node)?),
                "gazebo" => {
                    let imu = node
                        .descendants()
                        .any(|s| s.has_tag_name("sensor") && s.attribute("type") == Some("imu"));
                    let exteroceptive = node.descendants().any(|s| {
                        s.has_tag_name("sensor")
                            && matches!(
                                s.attribute("type"),
                                Some(
                                    "camera"
                                        | "depth"
                                        | "ray"
                                        | "gpu_ray"
                                        | "lidar"
                                        | "gpu_lidar"
                                        | "rgbd_camera"
                                )
                            )
                    });
                    if let Some(link) = node.attribute("reference") {
                        if imu {
                            imu_links.push(link.to_string());
                        }
                        if exteroceptive {
                            sensor_links.push(link.to_string());
                        }
                    }
                }
                "ros2_control" => {
                    for j in node.children().filter(|c| c.has_tag_name("joint")) {
                        let commands = j.children().any(|c| c.has_tag_name("command_interface"));
                        if let (true, Some(n)) = (commands, j.attribute("name")) {
                            commanded.push(n.to_string());
                        }
                    }
                }
                "transmission" => {
                    for j in node.children().filter(|c| c.has_tag_name("joint")) {
                        if let Some(n) = j.attribute("name") {
                            commanded.push(n.to_string());
                        }
                    }
                }
                _ => {}
            }
        }
        if links.is_empty() {
            return Err(r.err(root, "the robot has no <link>"));
        }
        for l in links.keys() {
            if l.to_ascii_lowercase().contains("imu") && !imu_links.contains(l) {
                imu_links.push(l.clone());
            }
        }
        for l in links.keys() {
            let n = l.to_ascii_lowercase();
            let named = ["camera", "laser", "lidar", "scan"]
                .iter()
                .any(|s| n.contains(s));
            if named && !sensor_links.contains(l) {
                sensor_links.push(l.clone());
            }
        }
        let urdf = Urdf {
            file: file.to_path_buf(),
            name: root.attribute("name").unwrap_or("robot").to_string(),
            links,
            joints,
            imu_links,
            sensor_links,
            commanded,
        };
        urdf.check_tree()?;
        Ok(urdf)
    }

    fn err(&self, line: usize, msg: impl Into<String>) -> InitError {
        InitError::at(&self.file, Some(line), msg)
    }

    /// Every joint names declared links, every link has at most one parent
    /// joint, and following parents never comes back (no loop).
    fn check_tree(&self) -> Result<(), InitError> {
        let mut parent_of: HashMap<&str, &Joint> = HashMap::new();
        let mut names: HashMap<&str, usize> = HashMap::new();
        for j in &self.joints {
            if let Some(first) = names.insert(&j.name, j.line) {
                return Err(self.err(
                    j.line,
                    format!(
                        "joint `{}` is declared twice (first on line {first})",
                        j.name
                    ),
                ));
            }
            for l in [&j.parent, &j.child] {
                if !self.links.contains_key(l) {
                    return Err(self.err(
                        j.line,
                        format!(
                            "joint `{}` names link `{l}`, which the robot does not declare",
                            j.name
                        ),
                    ));
                }
            }
            if j.parent == j.child {
                return Err(self.err(
                    j.line,
                    format!(
                        "joint `{}` joins link `{}` to itself: the joints form a loop",
                        j.name, j.child
                    ),
                ));
            }
            if let Some(other) = parent_of.insert(&j.child, j) {
                return Err(self.err(
                    j.line,
                    format!(
                        "link `{}` is the child of joint `{}` (line {}) and of joint `{}`: the joints form a loop (a URDF is a tree)",
                        j.child, other.name, other.line, j.name
                    ),
                ));
            }
        }
        for j in &self.joints {
            let mut at = j.parent.as_str();
            let mut steps = 0;
            while let Some(up) = parent_of.get(at) {
                if up.name == j.name || steps > self.joints.len() {
                    return Err(self.err(
                        j.line,
                        format!(
                            "joint `{}` is part of a loop of joints (a URDF is a tree)",
                            j.name
                        ),
                    ));
                }
                at = &up.parent;
                steps += 1;
            }
        }
        Ok(())
    }

    /// The link no joint has as its child (the tree's root).
    pub fn roots(&self) -> Vec<&str> {
        self.links
            .keys()
            .filter(|l| !self.joints.iter().any(|j| &j.child == *l))
            .map(String::as_str)
            .collect()
    }

    /// How many joints lie between the root and `link`.
    pub fn depth(&self, link: &str) -> usize {
        self.chain(link).len()
    }

    /// The joint whose child is `link`.
    pub fn parent_joint(&self, link: &str) -> Option<&Joint> {
        self.joints.iter().find(|j| j.child == link)
    }

    /// The joints from the tree's root down to `link` (outermost first).
    fn chain(&self, link: &str) -> Vec<&Joint> {
        let mut chain = Vec::new();
        let mut at = link;
        while let Some(j) = self.parent_joint(at) {
            chain.push(j);
            at = &j.parent;
        }
        chain.reverse();
        chain
    }

    /// `link`'s frame in `base`'s frame (every joint at zero), and the joints
    /// between them that are not also above `base` (outermost first).
    pub fn pose_in(&self, base: &str, link: &str) -> (Isometry3<f64>, Vec<&Joint>) {
        let in_root = |l: &str| {
            self.chain(l)
                .iter()
                .fold(Isometry3::identity(), |acc, j| acc * j.origin)
        };
        let above_base = self.chain(base);
        let own: Vec<&Joint> = self
            .chain(link)
            .into_iter()
            .filter(|j| !above_base.iter().any(|a| a.name == j.name))
            .collect();
        (in_root(base).inverse() * in_root(link), own)
    }
}
