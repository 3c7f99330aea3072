//! ROS 2 bags (MCAP) read as logs: the topics a mapping names become the
//! columns of a CSV log (CONTRACT section 2) on one time base, so everything
//! after reading (checks, runs, fits) is the same for a bag and a CSV.
//!
//! Rows are the messages of the first input's topic: a `JointState` (wheel
//! and steering joints) or a `Twist` / `TwistStamped` (velocity commands,
//! `/cmd_vel`). The other streams (more joint topics, the pose, the gyro) are
//! interpolated linearly to their stamps; velocity commands hold their value
//! until the next one. Rows outside any stream's span are dropped. Time is
//! the messages' header stamps (or the bag's receive time, if asked; an
//! unstamped `Twist` has only that), minus the first row's.
use crate::logs::log::{wrap, Log, LogError};
use crate::logs::mcap_messages::for_each_message;
use crate::logs::rosmsg::{self, decode};
use serde::Deserialize;
use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};

const JOINT_STATE: &str = "sensor_msgs/msg/JointState";
const IMU: &str = "sensor_msgs/msg/Imu";
const POSE_STAMPED: &str = "geometry_msgs/msg/PoseStamped";
const ODOMETRY: &str = "nav_msgs/msg/Odometry";
const TF: &str = "tf2_msgs/msg/TFMessage";
const POSE_TYPES: [&str; 3] = [POSE_STAMPED, ODOMETRY, TF];
const TWIST: &str = "geometry_msgs/msg/Twist";
const TWIST_STAMPED: &str = "geometry_msgs/msg/TwistStamped";
/// What an input column can be read from.
const INPUT_TYPES: [&str; 3] = [JOINT_STATE, TWIST, TWIST_STAMPED];

/// Is this path a bag (an `.mcap` file, or a rosbag2 directory holding one)?
pub fn is_bag(path: &Path) -> bool {
    path.extension().is_some_and(|e| e == "mcap") || path.is_dir()
}

/// Which stamps order the messages.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Stamps {
    /// The `header.stamp` of each message (when the data was measured).
    #[default]
    Header,
    /// The bag's log time (when the recorder received the message).
    Receive,
}

/// Where an input column comes from: a joint of a `JointState` topic (wheel
/// encoders, steering angles), or a component of a `Twist` / `TwistStamped`
/// topic (a velocity-commanded robot's `/cmd_vel`).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct InputSource {
    /// Default: the bag's only `JointState` topic.
    pub topic: Option<String>,
    /// For a `JointState` topic; default: the log column's name.
    pub joint: Option<String>,
    /// For a `Twist` or `TwistStamped` topic: `linear.x`, `linear.y` or
    /// `angular.z`.
    pub field: Option<TwistField>,
}

/// The component of a velocity command an input column reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
pub enum TwistField {
    #[serde(rename = "linear.x")]
    LinearX,
    #[serde(rename = "linear.y")]
    LinearY,
    #[serde(rename = "angular.z")]
    AngularZ,
}

impl TwistField {
    fn of(self, t: &rosmsg::Twist) -> f64 {
        match self {
            TwistField::LinearX => t.linear.x,
            TwistField::LinearY => t.linear.y,
            TwistField::AngularZ => t.angular.z,
        }
    }
}

/// Where the ground-truth pose comes from.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PoseSource {
    /// A `PoseStamped`, `Odometry` or `TFMessage` topic.
    pub topic: String,
    /// For `TFMessage`: the child frame whose pose is the robot's (e.g. `base_link`).
    pub frame: Option<String>,
}

/// Where the gyro's yaw rate comes from (`angular_velocity.z` of an `Imu` topic).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ImuSource {
    pub topic: String,
}

/// Where range-bearing observations of mapped landmarks come from: a topic of
/// any message type (its definition is read from the bag), and the paths of
/// the fields in each message. A path with `[]` gives one detection per
/// element (`detections[].range`); paths without one give one per message.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LandmarkSource {
    pub topic: String,
    /// The landmark's id (text or integer), as in the `--landmarks` map.
    pub id: String,
    /// Range (m) and bearing (rad, relative to the robot heading)...
    pub range: Option<String>,
    pub bearing: Option<String>,
    /// ...or the landmark's position in the robot frame (m).
    pub x: Option<String>,
    pub y: Option<String>,
    /// The stamp (`builtin_interfaces/Time`); default `header.stamp`.
    pub stamp: Option<String>,
}

/// One range-bearing detection read from a bag: time on the log's time base,
/// and where it came from (topic, message index) for errors.
#[derive(Debug, Clone)]
pub struct Detection {
    pub t: f64,
    pub id: String,
    pub range: f64,
    pub bearing: f64,
    pub topic: String,
    pub index: usize,
}

/// The `--topics FILE.toml` mapping from a bag's topics to a log's columns.
/// Everything is optional: an input column defaults to the joint of the same
/// name in the bag's only `JointState` topic, the pose to its only `PoseStamped`
/// or `Odometry` topic, the gyro to its only `Imu` topic.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TopicMap {
    #[serde(default)]
    pub stamps: Stamps,
    /// Log column (a spec input's `column`) -> its joint or command.
    #[serde(default)]
    pub inputs: BTreeMap<String, InputSource>,
    pub pose: Option<PoseSource>,
    pub gyro: Option<ImuSource>,
    pub landmarks: Option<LandmarkSource>,
}

impl TopicMap {
    pub fn read(path: &Path) -> Result<TopicMap, LogError> {
        let text = kinegen_model::files::read_text(path).map_err(|(at, e)| match at {
            Some((line, col)) => {
                LogError::new(path, Some(line), None, format!("column {col}: {e}"))
            }
            None => LogError::new(
                path,
                None,
                None,
                format!("cannot read the topic mapping: {e}"),
            ),
        })?;
        toml::from_str(&text).map_err(|e| {
            let Some(start) = e.span().map(|s| s.start.min(text.len())) else {
                return LogError::new(path, None, None, e.message().to_string());
            };
            let line = text[..start].matches('\n').count() + 1;
            let column = text[..start]
                .rsplit('\n')
                .next()
                .map_or(0, |l| l.chars().count())
                + 1;
            LogError::new(
                path,
                Some(line),
                None,
                format!("column {column}: {}", e.message()),
            )
        })
    }
}

/// The columns a model wants from a bag, by role.
pub struct Wanted {
    /// Input columns, in the spec's order.
    pub inputs: Vec<String>,
    /// Pose columns (x, y, heading).
    pub pose: [String; 3],
    pub gyro: String,
}

/// One message of a topic kinegen can decode: index in the topic (0-based),
/// receive time (ns) and CDR bytes.
struct Raw {
    index: usize,
    log_time: u64,
    data: Vec<u8>,
}

struct Topic {
    schema: String,
    /// The message definition and its encoding (`ros2msg`), as the bag stores it.
    definition: Option<(String, String)>,
    encoding: String,
    messages: Vec<Raw>,
}

/// A time series read from one topic.
struct Series {
    topic: String,
    /// Index of each value's message in its topic (counting from 0).
    index: Vec<usize>,
    t: Vec<f64>,
    values: Vec<Vec<f64>>,
    /// Each value holds until the next (velocity commands), rather than
    /// changing linearly between them (measurements).
    held: bool,
}

/// Read a bag as a log with the `wanted` columns. `progress(messages,
/// per_mille)` is called as messages are read: how many so far, and how far
/// into the file in thousandths.
/// Range-bearing detections come with it when the mapping names a landmark
/// topic.
pub fn read(
    path: &Path,
    wanted: &Wanted,
    map: &TopicMap,
    progress: &dyn Fn(usize, usize),
) -> Result<(Log, Vec<Detection>), LogError> {
    let file = resolve(path)?;
    let buf = kinegen_model::files::read_bounded(&file)
        .map_err(|e| LogError::new(&file, None, None, format!("cannot read the bag: {e}")))?;
    let keep = map.landmarks.as_ref().map(|l| l.topic.as_str());
    let (topics, all) = collect(&file, &buf, keep, progress)?;
    let bag = Bag {
        file: &file,
        topics,
        all,
    };
    let file = bag.file;
    let (mut series, mut columns) = input_series(&bag, wanted, map)?;
    let pose = match &map.pose {
        Some(p) => Some(p.clone()),
        None => bag
            .only(&[POSE_STAMPED, ODOMETRY], "ground-truth pose")?
            .map(|topic| PoseSource { topic, frame: None }),
    };
    if let Some(p) = pose {
        let t = bag.typed(&p.topic, &POSE_TYPES, "ground-truth pose")?;
        series.push(pose_series(file, &p, t, map.stamps)?);
        for (i, c) in wanted.pose.iter().enumerate() {
            columns.insert(c.clone(), (series.len() - 1, i));
        }
    }
    let gyro = match &map.gyro {
        Some(g) => Some(g.topic.clone()),
        None => bag.only(&[IMU], "gyro")?,
    };
    if let Some(topic) = gyro {
        let t = bag.typed(&topic, &[IMU], "gyro")?;
        series.push(imu_series(file, &topic, t, map.stamps)?);
        columns.insert(wanted.gyro.clone(), (series.len() - 1, 0));
    }
    let (log, t0) = align(file, &series, &columns, &wanted.pose[2])?;
    let detections = match &map.landmarks {
        None => Vec::new(),
        Some(l) => {
            let t = bag.topics.get(&l.topic).ok_or_else(|| {
                bag.err(format!(
                    "no topic `{}` for the landmark observations; {}",
                    l.topic,
                    bag.listing()
                ))
            })?;
            landmark_detections(file, l, t, map.stamps, t0)?
        }
    };
    Ok((log, detections))
}

/// One input column's source: the topic and what to read in it.
struct InputColumn {
    column: String,
    topic: String,
    /// The joint (JointState topics): as given in --topics, else the
    /// column's own name.
    joint: String,
    /// Whether --topics named the joint: refused on a Twist topic, which
    /// has no joints (silently reading the command instead would hide a
    /// mapping error).
    joint_given: bool,
    /// The command component (Twist topics).
    field: Option<TwistField>,
}

/// The input columns' series, one per topic (its first is the log's clock),
/// and where each column is in them: (series, value).
#[allow(clippy::type_complexity)]
fn input_series(
    bag: &Bag,
    wanted: &Wanted,
    map: &TopicMap,
) -> Result<(Vec<Series>, HashMap<String, (usize, usize)>), LogError> {
    let mut inputs: Vec<InputColumn> = Vec::new();
    for col in &wanted.inputs {
        let src = map.inputs.get(col);
        let topic = match src.and_then(|s| s.topic.clone()) {
            Some(t) => t,
            None => bag
                .only(&[JOINT_STATE], "wheel and steering joints")?
                .ok_or_else(|| {
                    bag.err(format!(
                        "no {JOINT_STATE} topic for the input column `{col}` (a velocity command names its topic and component under [inputs] in --topics: `{col} = {{ topic = \"/cmd_vel\", field = \"linear.x\" }}`, or `\"linear.y\"`, `\"angular.z\"`); {}",
                        bag.listing()
                    ))
                })?,
        };
        inputs.push(InputColumn {
            column: col.clone(),
            topic,
            joint: src
                .and_then(|s| s.joint.clone())
                .unwrap_or_else(|| col.clone()),
            joint_given: src.is_some_and(|s| s.joint.is_some()),
            field: src.and_then(|s| s.field),
        });
    }
    let mut columns: HashMap<String, (usize, usize)> = HashMap::new();
    let mut series: Vec<Series> = Vec::new();
    for c in &inputs {
        if series.iter().all(|s| s.topic != c.topic) {
            let same: Vec<&InputColumn> = inputs.iter().filter(|o| o.topic == c.topic).collect();
            let what = format!("input column `{}`", c.column);
            let t = bag.typed(&c.topic, &INPUT_TYPES, &what)?;
            series.push(if t.schema == JOINT_STATE {
                if let Some(o) = same.iter().find(|o| o.field.is_some()) {
                    return Err(bag.err(format!(
                        "input column `{}`: topic `{}` is a {JOINT_STATE}: name a `joint`, not a `field`",
                        o.column, c.topic
                    )));
                }
                let names: Vec<&str> = same.iter().map(|o| o.joint.as_str()).collect();
                joint_series(bag.file, &c.topic, t, &names, map.stamps)?
            } else {
                if let Some(o) = same.iter().find(|o| o.joint_given) {
                    return Err(bag.err(format!(
                        "input column `{}`: topic `{}` carries {}, which has no joints: name a `field` (\"linear.x\", \"linear.y\" or \"angular.z\"), not a `joint`",
                        o.column, c.topic, t.schema
                    )));
                }
                let fields = same
                    .iter()
                    .map(|o| {
                        o.field.ok_or_else(|| {
                            bag.err(format!(
                                "input column `{}`: topic `{}` carries {}: say which component with `field = \"linear.x\"`, `\"linear.y\"` or `\"angular.z\"` under [inputs] in --topics",
                                o.column, c.topic, t.schema
                            ))
                        })
                    })
                    .collect::<Result<Vec<_>, _>>()?;
                twist_series(bag.file, &c.topic, t, &fields, map.stamps)?
            });
        }
        let s = series.iter().position(|s| s.topic == c.topic).unwrap();
        let v = inputs
            .iter()
            .filter(|o| o.topic == c.topic)
            .position(|o| o.column == c.column)
            .unwrap();
        columns.insert(c.column.clone(), (s, v));
    }
    Ok((series, columns))
}

/// A bag's topics as read: the decoded ones kinegen can use, and every
/// topic with its type, for the errors.
struct Bag<'a> {
    file: &'a Path,
    topics: HashMap<String, Topic>,
    all: Vec<(String, String)>,
}

impl Bag<'_> {
    fn err(&self, m: String) -> LogError {
        LogError::new(self.file, None, None, m)
    }

    /// What the bag holds, for an error that cannot find a topic.
    fn listing(&self) -> String {
        if self.all.is_empty() {
            "the bag has no messages".to_string()
        } else {
            format!(
                "the bag has: {}",
                self.all
                    .iter()
                    .map(|(t, s)| format!("{t} ({s})"))
                    .collect::<Vec<_>>()
                    .join(", ")
            )
        }
    }

    /// The one topic of `types` (None without one; an error naming them
    /// when several could be the `what`).
    fn only(&self, types: &[&str], what: &str) -> Result<Option<String>, LogError> {
        let found: Vec<&String> = self
            .all
            .iter()
            .filter(|(_, s)| types.contains(&s.as_str()))
            .map(|(t, _)| t)
            .collect();
        match found.as_slice() {
            [] => Ok(None),
            [one] => Ok(Some((*one).clone())),
            many => Err(self.err(format!(
                "{} topics could be the {what} ({}): name one in --topics",
                many.len(),
                many.iter()
                    .map(|t| t.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            ))),
        }
    }

    /// Topic `topic`, which must carry one of `types` in CDR, for the `what`.
    fn typed(&self, topic: &str, types: &[&str], what: &str) -> Result<&Topic, LogError> {
        let t = self.topics.get(topic).ok_or_else(|| {
            match self.all.iter().find(|(t, _)| t == topic) {
                Some((_, s)) => self.err(format!(
                    "topic `{topic}` carries {s}; the {what} needs {}",
                    types.join(" or ")
                )),
                None => self.err(format!(
                    "no topic `{topic}` for the {what}; {}",
                    self.listing()
                )),
            }
        })?;
        if !types.contains(&t.schema.as_str()) {
            return Err(self.err(format!(
                "topic `{topic}` carries {}; the {what} needs {}",
                t.schema,
                types.join(" or ")
            )));
        }
        if t.encoding != "cdr" {
            return Err(self.err(format!(
                "topic `{topic}` is encoded as `{}`; kinegen reads ROS 2 CDR messages",
                t.encoding
            )));
        }
        Ok(t)
    }
}

/// The field paths of a landmark topic's detections: the landmark's id, the
/// stamp, and either range and bearing or x and y (`polar.2` says which).
struct DetectionFields {
    id: crate::logs::rosdyn::FieldPath,
    stamp: crate::logs::rosdyn::FieldPath,
    polar: (
        crate::logs::rosdyn::FieldPath,
        crate::logs::rosdyn::FieldPath,
        bool,
    ),
}

impl DetectionFields {
    /// The topic's message schema and the fields `l` names in it.
    fn new(
        file: &Path,
        l: &LandmarkSource,
        t: &Topic,
    ) -> Result<(crate::logs::rosdyn::Schema, DetectionFields), LogError> {
        let topic = l.topic.as_str();
        let err = |m: String| LogError::new(file, None, None, format!("topic `{topic}`: {m}"));
        if t.encoding != "cdr" {
            return Err(err(format!(
                "encoded as `{}`; kinegen reads ROS 2 CDR messages",
                t.encoding
            )));
        }
        let schema = match &t.definition {
            Some((enc, text)) if enc == "ros2msg" => {
                crate::logs::rosdyn::Schema::parse(&t.schema, text)
                    .map_err(|e| err(format!("its message definition ({}): {e}", t.schema)))?
            }
            Some((enc, _)) => {
                return Err(err(format!(
                    "its message definition is `{enc}`; kinegen reads `ros2msg` definitions"
                )))
            }
            None => return Err(err("the bag stores no message definition for it".into())),
        };
        let path = |field: &str,
                    p: &Option<String>|
         -> Result<Option<crate::logs::rosdyn::FieldPath>, LogError> {
            p.as_deref()
                .map(|p| {
                    crate::logs::rosdyn::FieldPath::parse(p)
                        .map_err(|e| err(format!("[landmarks] {field}: {e}")))
                })
                .transpose()
        };
        let (range, bearing, x, y) = (
            path("range", &l.range)?,
            path("bearing", &l.bearing)?,
            path("x", &l.x)?,
            path("y", &l.y)?,
        );
        let polar = match (range, bearing, x, y) {
            (Some(r), Some(b), None, None) => (r, b, true),
            (None, None, Some(x), Some(y)) => (x, y, false),
            _ => {
                return Err(err(
                    "[landmarks] needs `range` and `bearing`, or `x` and `y` (the landmark in the robot frame), field paths in the message".into(),
                ))
            }
        };
        let id = path("id", &Some(l.id.clone()))?.unwrap();
        let stamp = path(
            "stamp",
            &Some(l.stamp.clone().unwrap_or("header.stamp".into())),
        )?
        .unwrap();
        Ok((schema, DetectionFields { id, stamp, polar }))
    }
}

/// The detections of a landmark topic, decoded with the definition the bag
/// carries, in the log's time (`t0` is its first row's stamp).
fn landmark_detections(
    file: &Path,
    l: &LandmarkSource,
    t: &Topic,
    stamps: Stamps,
    t0: f64,
) -> Result<Vec<Detection>, LogError> {
    let topic = l.topic.as_str();
    let (schema, fields) = DetectionFields::new(file, l, t)?;
    let DetectionFields { id, stamp, polar } = fields;
    let mut out = Vec::new();
    for raw in &t.messages {
        let here = |m: String| at(file, topic, raw.index, m);
        let v = schema
            .decode(&raw.data)
            .map_err(|e| here(format!("cannot decode {}: {e}", t.schema)))?;
        let time = match stamps {
            Stamps::Receive => raw.log_time as f64 * 1e-9,
            Stamps::Header => stamp
                .values(&v)
                .map_err(|e| here(e.to_string()))?
                .first()
                .and_then(|s| s.as_time())
                .ok_or_else(|| {
                    here(format!(
                        "`{}` is not a builtin_interfaces/Time stamp",
                        stamp.text()
                    ))
                })?,
        };
        let get =
            |p: &crate::logs::rosdyn::FieldPath| p.values(&v).map_err(|e| here(e.to_string()));
        let (ids, a, b) = (get(&id)?, get(&polar.0)?, get(&polar.1)?);
        let n = ids.len().max(a.len()).max(b.len());
        for (what, vals) in [(&id, &ids), (&polar.0, &a), (&polar.1, &b)] {
            if vals.len() != n && vals.len() != 1 {
                return Err(here(format!(
                    "`{}` has {} values where another field has {n}",
                    what.text(),
                    vals.len()
                )));
            }
        }
        // a field with one value serves every detection of the message
        fn pick<'v>(
            vals: &[&'v crate::logs::rosdyn::Value],
            k: usize,
        ) -> &'v crate::logs::rosdyn::Value {
            vals[if vals.len() == 1 { 0 } else { k }]
        }
        for k in 0..n {
            let ident = pick(&ids, k)
                .as_id()
                .ok_or_else(|| here(format!("`{}` is neither text nor an integer", id.text())))?;
            let num = |vals: &[&crate::logs::rosdyn::Value], p: &crate::logs::rosdyn::FieldPath| {
                pick(vals, k)
                    .as_f64()
                    .filter(|x| crate::logs::log::physical(*x))
                    .ok_or_else(|| here(format!("`{}` is not a finite number", p.text())))
            };
            let (p, q) = (num(&a, &polar.0)?, num(&b, &polar.1)?);
            let (range, bearing) = if polar.2 {
                (p, q)
            } else {
                (p.hypot(q), q.atan2(p))
            };
            if range.is_nan() || range <= 0.0 {
                return Err(here(format!("range {range} is not positive")));
            }
            out.push(Detection {
                t: time - t0,
                id: ident,
                range,
                bearing,
                topic: topic.to_string(),
                index: raw.index,
            });
        }
    }
    Ok(out)
}

/// The `.mcap` file of a path: the file itself, or the only one in a rosbag2
/// directory.
fn resolve(path: &Path) -> Result<PathBuf, LogError> {
    if !path.is_dir() {
        return Ok(path.to_path_buf());
    }
    let err = |m: String| LogError::new(path, None, None, m);
    let mut found: Vec<PathBuf> = std::fs::read_dir(path)
        .map_err(|e| err(format!("cannot read the bag directory: {e}")))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "mcap"))
        .collect();
    found.sort();
    match found.len() {
        1 => Ok(found.remove(0)),
        0 => Err(err(
            "no .mcap file in this directory (kinegen reads ROS 2 bags stored as MCAP)".into(),
        )),
        n => Err(err(format!(
            "{n} .mcap files in this directory: give one of them as --data"
        ))),
    }
}

/// Every message of the topics kinegen can decode, by topic, and every topic
/// of the bag with its type (for messages that list them).
#[allow(clippy::type_complexity)]
fn collect(
    file: &Path,
    buf: &[u8],
    keep: Option<&str>,
    progress: &dyn Fn(usize, usize),
) -> Result<(HashMap<String, Topic>, Vec<(String, String)>), LogError> {
    let err = |m: String| LogError::new(file, None, None, m);
    let mut topics: HashMap<String, Topic> = HashMap::new();
    let mut all: Vec<(String, String)> = Vec::new();
    let mut counts: HashMap<String, usize> = HashMap::new();
    let mut n = 0usize;
    for_each_message(buf, |m, bytes_read| {
        let ch = &m.channel;
        let schema = ch
            .schema
            .as_ref()
            .map_or("(no schema)".to_string(), |s| s.name.clone());
        if !all.iter().any(|(t, _)| t == &ch.topic) {
            all.push((ch.topic.clone(), schema.clone()));
        }
        let index = counts.entry(ch.topic.clone()).or_default();
        if INPUT_TYPES.contains(&schema.as_str())
            || schema == IMU
            || POSE_TYPES.contains(&schema.as_str())
            || keep == Some(ch.topic.as_str())
        {
            topics
                .entry(ch.topic.clone())
                .or_insert_with(|| Topic {
                    schema: schema.clone(),
                    definition: ch.schema.as_ref().map(|s| {
                        (
                            s.encoding.clone(),
                            String::from_utf8_lossy(&s.data).into_owned(),
                        )
                    }),
                    encoding: ch.message_encoding.clone(),
                    messages: Vec::new(),
                })
                .messages
                .push(Raw {
                    index: *index,
                    log_time: m.log_time,
                    data: m.data.to_vec(),
                });
        }
        *index += 1;
        if n.is_multiple_of(4096) {
            progress(n, bytes_read * 1000 / buf.len().max(1));
        }
        n += 1;
    })
    .map_err(|c| {
        err(if c.after == 0 && all.is_empty() {
            format!("not a readable MCAP file: {}", c.why)
        } else {
            format!(
                "truncated or corrupt MCAP file after {} messages: {}",
                c.after, c.why
            )
        })
    })?;
    all.sort();
    Ok((topics, all))
}

/// "file: topic `/x` message 17": where a message problem is.
fn at(file: &Path, topic: &str, index: usize, m: impl std::fmt::Display) -> LogError {
    LogError::new(
        file,
        None,
        None,
        format!("topic `{topic}` message {index} (counting from 0): {m}"),
    )
}

fn stamp(raw: &Raw, header: &rosmsg::Header, stamps: Stamps) -> f64 {
    match stamps {
        Stamps::Header => header.stamp.seconds(),
        Stamps::Receive => raw.log_time as f64 * 1e-9,
    }
}

fn decoded<'a, T: Deserialize<'a>>(
    file: &Path,
    topic: &str,
    t: &Topic,
    raw: &'a Raw,
) -> Result<T, LogError> {
    decode(&raw.data).map_err(|e| {
        at(
            file,
            topic,
            raw.index,
            format!("cannot decode {}: {e}", t.schema),
        )
    })
}

fn joint_series(
    file: &Path,
    topic: &str,
    t: &Topic,
    joints: &[&str],
    stamps: Stamps,
) -> Result<Series, LogError> {
    let mut s = Series::new(topic);
    for raw in &t.messages {
        let m: rosmsg::JointState = decoded(file, topic, t, raw)?;
        let mut row = Vec::with_capacity(joints.len());
        for j in joints {
            let i = m.name.iter().position(|n| n == j).ok_or_else(|| {
                at(
                    file,
                    topic,
                    raw.index,
                    format!(
                        "field `name` has no joint `{j}` (it has: {}); map the input column to a joint in --topics",
                        m.name.join(", ")
                    ),
                )
            })?;
            let v = *m.position.get(i).ok_or_else(|| {
                at(
                    file,
                    topic,
                    raw.index,
                    format!(
                        "field `position` has {} values for {} joints",
                        m.position.len(),
                        m.name.len()
                    ),
                )
            })?;
            row.push(v);
        }
        s.index.push(raw.index);
        s.t.push(stamp(raw, &m.header, stamps));
        s.values.push(row);
    }
    Ok(s)
}

fn pose_series(file: &Path, p: &PoseSource, t: &Topic, stamps: Stamps) -> Result<Series, LogError> {
    let topic = p.topic.as_str();
    let mut s = Series::new(topic);
    let mut children: Vec<String> = Vec::new();
    for raw in &t.messages {
        let (header, pose) = match t.schema.as_str() {
            POSE_STAMPED => {
                let m: rosmsg::PoseStamped = decoded(file, topic, t, raw)?;
                (m.header, (m.pose.position, m.pose.orientation))
            }
            ODOMETRY => {
                let m: rosmsg::Odometry = decoded(file, topic, t, raw)?;
                (m.header, (m.pose.pose.position, m.pose.pose.orientation))
            }
            _ => {
                let frame = p.frame.as_deref().ok_or_else(|| {
                    LogError::new(file, None, None, format!("topic `{topic}` is a {TF}: say which child frame is the robot with `frame = \"...\"` under [pose] in --topics"))
                })?;
                let m: rosmsg::TfMessage = decoded(file, topic, t, raw)?;
                let Some(tr) = m.transforms.into_iter().find(|tr| {
                    if !children.contains(&tr.child_frame_id) {
                        children.push(tr.child_frame_id.clone());
                    }
                    tr.child_frame_id == frame
                }) else {
                    continue;
                };
                (tr.header, (tr.transform.translation, tr.transform.rotation))
            }
        };
        s.index.push(raw.index);
        s.t.push(stamp(raw, &header, stamps));
        s.values.push(vec![pose.0.x, pose.0.y, pose.1.yaw()]);
    }
    if s.t.is_empty() && t.schema == TF {
        return Err(LogError::new(
            file,
            None,
            None,
            format!(
                "topic `{topic}` never has the frame `{}` (its child frames: {})",
                p.frame.as_deref().unwrap_or(""),
                children.join(", ")
            ),
        ));
    }
    // headings are interpolated unwrapped (and wrapped again in the log)
    let yaw: Vec<f64> = s.values.iter().map(|v| v[2]).collect();
    for (v, y) in s.values.iter_mut().zip(crate::logs::log::unwrap(&yaw)) {
        v[2] = y;
    }
    Ok(s)
}

fn imu_series(file: &Path, topic: &str, t: &Topic, stamps: Stamps) -> Result<Series, LogError> {
    let mut s = Series::new(topic);
    for raw in &t.messages {
        let m: rosmsg::Imu = decoded(file, topic, t, raw)?;
        s.index.push(raw.index);
        s.t.push(stamp(raw, &m.header, stamps));
        s.values.push(vec![m.angular_velocity.z]);
    }
    Ok(s)
}

/// Velocity commands: the `fields` of each `Twist` or `TwistStamped`
/// message. An unstamped `Twist` is timed by the bag's receive time, the only
/// one it has. A command holds until the next one (a [`Series::held`]).
fn twist_series(
    file: &Path,
    topic: &str,
    t: &Topic,
    fields: &[TwistField],
    stamps: Stamps,
) -> Result<Series, LogError> {
    let mut s = Series::new(topic);
    s.held = true;
    for raw in &t.messages {
        let (time, twist) = if t.schema == TWIST_STAMPED {
            let m: rosmsg::TwistStamped = decoded(file, topic, t, raw)?;
            (stamp(raw, &m.header, stamps), m.twist)
        } else {
            let m: rosmsg::Twist = decoded(file, topic, t, raw)?;
            (raw.log_time as f64 * 1e-9, m)
        };
        s.index.push(raw.index);
        s.t.push(time);
        s.values.push(fields.iter().map(|f| f.of(&twist)).collect());
    }
    Ok(s)
}

impl Series {
    fn new(topic: &str) -> Series {
        Series {
            topic: topic.to_string(),
            index: Vec::new(),
            t: Vec::new(),
            values: Vec::new(),
            held: false,
        }
    }
}

/// Put every series on the time base of the first (the first input's), check
/// the stamps, and build the log; with the stamp of its first row (its time 0).
fn align(
    file: &Path,
    series: &[Series],
    columns: &HashMap<String, (usize, usize)>,
    heading: &str,
) -> Result<(Log, f64), LogError> {
    let err = |m: String| LogError::new(file, None, None, m);
    for s in series {
        if s.t.len() < 2 {
            return Err(err(format!(
                "topic `{}` has {} message(s) to read",
                s.topic,
                s.t.len()
            )));
        }
        if let Some(k) = s
            .values
            .iter()
            .position(|v| !v.iter().all(|x| crate::logs::log::physical(*x)))
        {
            return Err(at(
                file,
                &s.topic,
                s.index[k],
                format!(
                    "a value kinegen reads is NaN, infinite or out of any physical range ({:?})",
                    s.values[k]
                ),
            ));
        }
        for k in 1..s.t.len() {
            if s.t[k] <= s.t[k - 1] || !s.t[k].is_finite() {
                return Err(at(file, &s.topic, s.index[k], format!(
                    "stamp {:.9} s does not follow {:.9} s (unsorted or duplicated stamps; `stamps = \"receive\"` in --topics orders by the bag's receive time)",
                    s.t[k], s.t[k - 1]
                )));
            }
        }
    }
    let clock = &series[0];
    let (lo, hi) = series
        .iter()
        .fold((f64::NEG_INFINITY, f64::INFINITY), |(a, b), s| {
            (a.max(s.t[0]), b.min(*s.t.last().unwrap()))
        });
    let rows: Vec<usize> = (0..clock.t.len())
        .filter(|&k| clock.t[k] >= lo && clock.t[k] <= hi)
        .collect();
    if rows.len() < 3 {
        return Err(err(format!(
            "the topics overlap in time for {} message(s) of `{}` ({:.3} s to {:.3} s): they must be recorded together",
            rows.len(),
            clock.topic,
            lo,
            hi
        )));
    }
    let t0 = clock.t[rows[0]];
    let mut out: HashMap<String, Vec<f64>> = HashMap::new();
    out.insert("t".into(), rows.iter().map(|&k| clock.t[k] - t0).collect());
    for (col, &(si, vi)) in columns {
        let s = &series[si];
        let mut j = 0;
        let v: Vec<f64> = rows
            .iter()
            .map(|&k| {
                let t = clock.t[k];
                while j + 2 < s.t.len() && s.t[j + 1] < t {
                    j += 1;
                }
                let a = ((t - s.t[j]) / (s.t[j + 1] - s.t[j])).clamp(0.0, 1.0);
                let v = if s.held {
                    // the command in force at t: the last one sent at or before it
                    s.values[if a >= 1.0 { j + 1 } else { j }][vi]
                } else {
                    s.values[j][vi] + a * (s.values[j + 1][vi] - s.values[j][vi])
                };
                if col == heading {
                    wrap(v)
                } else {
                    v
                }
            })
            .collect();
        if let Some(k) = v.iter().position(|x| !x.is_finite()) {
            return Err(err(format!(
                "column `{col}` from topic `{}` is not a finite number near {:.3} s",
                s.topic,
                clock.t[rows[k]] - t0
            )));
        }
        out.insert(col.clone(), v);
    }
    let mut header: Vec<String> = out.keys().cloned().collect();
    header.sort();
    Ok((
        Log {
            path: file.to_path_buf(),
            len: rows.len(),
            header,
            columns: out,
            // as its CSV export would number them
            first_line: 2,
        },
        t0,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn series(topic: &str, t: &[f64], v: &[f64], held: bool) -> Series {
        Series {
            topic: topic.into(),
            index: (0..t.len()).collect(),
            t: t.to_vec(),
            values: v.iter().map(|x| vec![*x]).collect(),
            held,
        }
    }

    /// On the clock's rows, a measurement changes linearly between its
    /// messages, a velocity command holds until the next one.
    #[test]
    fn commands_hold_and_measurements_interpolate() {
        let clock = series(
            "/joint_states",
            &[0.0, 0.5, 1.0, 1.5, 2.0],
            &[0.0; 5],
            false,
        );
        let pose = series("/pose", &[0.0, 1.0, 2.0], &[0.0, 1.0, 2.0], false);
        let cmd = series("/cmd_vel", &[0.0, 1.0, 2.0], &[0.1, 0.3, 0.5], true);
        let columns = HashMap::from([
            ("enc".to_string(), (0, 0)),
            ("gt_x".to_string(), (1, 0)),
            ("v".to_string(), (2, 0)),
        ]);
        let (log, _) = align(
            Path::new("b.mcap"),
            &[clock, pose, cmd],
            &columns,
            "gt_theta",
        )
        .unwrap();
        assert_eq!(log.columns["gt_x"], vec![0.0, 0.5, 1.0, 1.5, 2.0]);
        assert_eq!(log.columns["v"], vec![0.1, 0.1, 0.3, 0.3, 0.5]);
    }
}
