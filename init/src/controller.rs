//! A ros2_control controller configuration (the YAML the controller manager
//! loads) read for the drive controller's joints, geometry and frames.
//!
//! Known controllers: diff_drive_controller, tricycle_controller,
//! ackermann_steering_controller (and the bicycle/tricycle steering
//! controllers of the same library), mecanum_drive_controller. The node is
//! found by its `type` under `controller_manager`, else by its keys.
use crate::error::InitError;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use yaml_rust2::{Yaml, YamlLoader};

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ControllerKind {
    DiffDrive,
    Tricycle,
    /// Ackermann, bicycle and tricycle steering controllers (steering_controllers_library).
    Steering,
    Mecanum,
}

impl ControllerKind {
    pub fn type_name(self) -> &'static str {
        match self {
            ControllerKind::DiffDrive => "diff_drive_controller/DiffDriveController",
            ControllerKind::Tricycle => "tricycle_controller/TricycleController",
            ControllerKind::Steering => "ackermann_steering_controller/AckermannSteeringController",
            ControllerKind::Mecanum => "mecanum_drive_controller/MecanumDriveController",
        }
    }

    fn from_type(t: &str) -> Option<ControllerKind> {
        let t = t.to_ascii_lowercase();
        Some(if t.starts_with("diff_drive_controller") {
            ControllerKind::DiffDrive
        } else if t.starts_with("tricycle_controller") {
            ControllerKind::Tricycle
        } else if t.contains("steering_controller") {
            ControllerKind::Steering
        } else if t.starts_with("mecanum_drive_controller") {
            ControllerKind::Mecanum
        } else {
            return None;
        })
    }

    /// A node without a `type` is recognised by the keys only its kind has.
    fn from_keys(keys: &BTreeMap<String, Entry>) -> Option<ControllerKind> {
        let has = |k: &str| keys.contains_key(k);
        if has("left_wheel_names") || has("right_wheel_names") {
            Some(ControllerKind::DiffDrive)
        } else if has("traction_joint_name") {
            Some(ControllerKind::Tricycle)
        } else if has("rear_wheels_names")
            || has("front_wheels_names")
            || has("traction_joints_names")
        {
            Some(ControllerKind::Steering)
        } else if has("front_left_wheel_command_joint_name") {
            Some(ControllerKind::Mecanum)
        } else {
            None
        }
    }
}

/// One parameter of the controller node, flattened (`kinematics.wheels_radius`).
#[derive(Debug, Clone)]
pub struct Entry {
    pub value: Value,
    pub line: usize,
}

#[derive(Debug, Clone)]
pub enum Value {
    /// A number and its text as written (for its precision).
    Number(f64, String),
    Text(String),
    List(Vec<String>),
    Bool(bool),
}

/// The drive controller's node of a controller file.
#[derive(Debug, Clone)]
pub struct Controller {
    pub file: PathBuf,
    /// The file's text, for rewriting it with calibrated values.
    pub text: String,
    pub node: String,
    pub node_line: usize,
    pub kind: ControllerKind,
    /// The type as written (or the kind's standard one).
    pub type_name: String,
    pub params: BTreeMap<String, Entry>,
    /// The controller manager's `update_rate` (Hz), if given.
    pub update_rate: Option<f64>,
}

/// The first line at or after `from` (1-based) whose text, trimmed, starts with `key:`.
/// yaml-rust2's document tree keeps no positions; its keys are plain words
/// in these files, so finding the line by text is exact enough to point at.
fn line_of(text: &str, from: usize, key: &str) -> usize {
    let bare = key.rsplit('.').next().unwrap_or(key);
    text.lines()
        .enumerate()
        .skip(from.saturating_sub(1))
        .find(|(_, l)| {
            let t = l.trim_start();
            t.starts_with(&format!("{bare}:"))
                || t.starts_with(&format!("\"{bare}\":"))
                || t.starts_with(&format!("'{bare}':"))
        })
        .map_or(from, |(i, _)| i + 1)
}

fn scalar_text(y: &Yaml) -> Option<String> {
    match y {
        Yaml::String(s) | Yaml::Real(s) => Some(s.clone()),
        Yaml::Integer(i) => Some(i.to_string()),
        Yaml::Boolean(b) => Some(b.to_string()),
        _ => None,
    }
}

fn flatten(text: &str, from: usize, prefix: &str, y: &Yaml, out: &mut BTreeMap<String, Entry>) {
    let Yaml::Hash(h) = y else { return };
    for (k, v) in h {
        let Some(k) = scalar_text(k) else { continue };
        let key = if prefix.is_empty() {
            k.clone()
        } else {
            format!("{prefix}.{k}")
        };
        let line = line_of(text, from, &k);
        let value = match v {
            Yaml::Hash(_) => {
                flatten(text, line, &key, v, out);
                continue;
            }
            Yaml::Real(s) => Value::Number(s.parse().unwrap_or(f64::NAN), s.clone()),
            Yaml::Integer(i) => Value::Number(*i as f64, i.to_string()),
            Yaml::Boolean(b) => Value::Bool(*b),
            Yaml::String(s) => Value::Text(s.clone()),
            Yaml::Array(a) => Value::List(a.iter().filter_map(scalar_text).collect()),
            _ => continue,
        };
        out.insert(key, Entry { value, line });
    }
}

impl Controller {
    pub fn read(file: &Path) -> Result<Controller, InitError> {
        // bounded, and a byte that is not UTF-8 named at its line
        let text = kinegen_model::files::read_text(file).map_err(|(at, e)| {
            InitError::at(
                file,
                at.map(|(line, _)| line),
                format!("cannot read the controller configuration: {e}"),
            )
        })?;
        Controller::parse(file, &text)
    }

    pub fn parse(file: &Path, text: &str) -> Result<Controller, InitError> {
        let docs = YamlLoader::load_from_str(text).map_err(|e| InitError {
            file: file.to_path_buf(),
            line: Some(e.marker().line()),
            column: Some(e.marker().col() + 1),
            message: format!("not valid YAML: {}", e.info()),
        })?;
        let Some(Yaml::Hash(top)) = docs.first() else {
            return Err(InitError::at(
                file,
                Some(1),
                "a controller configuration is a YAML map of node names",
            ));
        };
        let manager = top
            .iter()
            .find(|(k, _)| {
                k.as_str()
                    .is_some_and(|k| k.trim_start_matches('/').ends_with("controller_manager"))
            })
            .map(|(_, v)| &v["ros__parameters"]);
        let mut found = Vec::new();
        for (k, v) in top {
            let Some(node) = k.as_str() else { continue };
            let params = &v["ros__parameters"];
            if node.ends_with("controller_manager") || params.is_badvalue() {
                continue;
            }
            let short = node.rsplit('/').next().unwrap_or(node);
            let node_line = line_of(text, 1, node);
            let mut flat = BTreeMap::new();
            flatten(text, node_line, "", params, &mut flat);
            let declared = manager.and_then(|m| m[short]["type"].as_str().map(str::to_string));
            let kind = declared
                .as_deref()
                .and_then(ControllerKind::from_type)
                .or_else(|| ControllerKind::from_keys(&flat));
            if let Some(kind) = kind {
                found.push(Controller {
                    file: file.to_path_buf(),
                    text: text.to_string(),
                    node: node.to_string(),
                    node_line,
                    kind,
                    type_name: declared.unwrap_or_else(|| kind.type_name().to_string()),
                    params: flat,
                    update_rate: manager.and_then(|m| match &m["update_rate"] {
                        Yaml::Integer(i) => Some(*i as f64),
                        Yaml::Real(r) => r.parse().ok(),
                        _ => None,
                    }),
                });
            }
        }
        match found.len() {
            1 => Ok(found.remove(0)),
            0 => Err(InitError::at(
                file,
                None,
                "no drive controller found: kinegen reads diff_drive_controller, tricycle_controller, ackermann_steering_controller (and bicycle/tricycle_steering_controller) and mecanum_drive_controller nodes (`<node>: ros__parameters:` with their keys)",
            )),
            _ => Err(InitError::at(
                file,
                Some(found[1].node_line),
                format!(
                    "two drive controllers ({} on line {} and {}): keep one in the file given to init",
                    found[0].node, found[0].node_line, found[1].node
                ),
            )),
        }
    }

    /// A number parameter: value, line, text. A key holding something else is an error.
    pub fn number(&self, key: &str) -> Result<Option<(f64, usize, String)>, InitError> {
        match self.params.get(key) {
            None => Ok(None),
            Some(Entry {
                value: Value::Number(v, t),
                line,
            }) if v.is_finite() => Ok(Some((*v, *line, t.clone()))),
            Some(e) => Err(InitError::at(
                &self.file,
                Some(e.line),
                format!("{}.{key} is not a number", self.node),
            )),
        }
    }

    /// Joint names: a list, or a single name.
    pub fn names(&self, key: &str) -> Vec<String> {
        match self.params.get(key).map(|e| &e.value) {
            Some(Value::List(v)) => v.clone(),
            Some(Value::Text(s)) => vec![s.clone()],
            _ => Vec::new(),
        }
    }

    pub fn text(&self, key: &str) -> Option<String> {
        match self.params.get(key).map(|e| &e.value) {
            Some(Value::Text(s)) => Some(s.clone()),
            _ => None,
        }
    }

    pub fn line(&self, key: &str) -> Option<usize> {
        self.params.get(key).map(|e| e.line)
    }
}
