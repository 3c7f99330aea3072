//! The ROS 2 messages kinegen reads from bags, as serde types for CDR decoding
//! (the `cdr` crate): field order and types follow the `.msg` definitions of
//! ROS 2 (Humble and later), which is all CDR needs, since it carries no field
//! names. Only what kinegen uses is interpreted; the rest is decoded and skipped.
use serde::Deserialize;

/// `builtin_interfaces/msg/Time`
#[derive(Debug, Clone, Copy, Deserialize)]
pub struct Time {
    pub sec: i32,
    pub nanosec: u32,
}

impl Time {
    pub fn seconds(&self) -> f64 {
        self.sec as f64 + self.nanosec as f64 * 1e-9
    }
}

/// `std_msgs/msg/Header`
#[derive(Debug, Clone, Deserialize)]
pub struct Header {
    pub stamp: Time,
    #[serde(deserialize_with = "crate::logs::rosdyn::cdr_string")]
    pub frame_id: String,
}

/// `geometry_msgs/msg/Vector3` (also the layout of `Point`)
#[derive(Debug, Clone, Copy, Deserialize)]
pub struct Vector3 {
    pub x: f64,
    pub y: f64,
    pub z: f64,
}

/// `geometry_msgs/msg/Quaternion`
#[derive(Debug, Clone, Copy, Deserialize)]
pub struct Quaternion {
    pub x: f64,
    pub y: f64,
    pub z: f64,
    pub w: f64,
}

impl Quaternion {
    /// Rotation about z of the frame (yaw), for a robot on a plane.
    pub fn yaw(&self) -> f64 {
        let q = self;
        (2.0 * (q.w * q.z + q.x * q.y)).atan2(1.0 - 2.0 * (q.y * q.y + q.z * q.z))
    }
}

/// `geometry_msgs/msg/Pose`
#[derive(Debug, Clone, Copy, Deserialize)]
pub struct Pose {
    pub position: Vector3,
    pub orientation: Quaternion,
}

/// A 6x6 covariance (`float64[36]`). CDR writes fixed arrays without a length,
/// so two rows of 18 decode exactly as 36 values; serde derives arrays only up
/// to 32 elements.
type Covariance36 = [[f64; 18]; 2];

/// `sensor_msgs/msg/JointState`
#[derive(Debug, Clone, Deserialize)]
pub struct JointState {
    pub header: Header,
    #[serde(deserialize_with = "crate::logs::rosdyn::cdr_strings")]
    pub name: Vec<String>,
    pub position: Vec<f64>,
    pub velocity: Vec<f64>,
    pub effort: Vec<f64>,
}

/// `sensor_msgs/msg/Imu`
#[derive(Debug, Clone, Deserialize)]
pub struct Imu {
    pub header: Header,
    pub orientation: Quaternion,
    pub orientation_covariance: [f64; 9],
    pub angular_velocity: Vector3,
    pub angular_velocity_covariance: [f64; 9],
    pub linear_acceleration: Vector3,
    pub linear_acceleration_covariance: [f64; 9],
}

/// `geometry_msgs/msg/PoseStamped`
#[derive(Debug, Clone, Deserialize)]
pub struct PoseStamped {
    pub header: Header,
    pub pose: Pose,
}

/// `geometry_msgs/msg/PoseWithCovariance`
#[derive(Debug, Clone, Deserialize)]
pub struct PoseWithCovariance {
    pub pose: Pose,
    pub covariance: Covariance36,
}

/// `geometry_msgs/msg/Twist`
#[derive(Debug, Clone, Deserialize)]
pub struct Twist {
    pub linear: Vector3,
    pub angular: Vector3,
}

/// `geometry_msgs/msg/TwistStamped`
#[derive(Debug, Clone, Deserialize)]
pub struct TwistStamped {
    pub header: Header,
    pub twist: Twist,
}

/// `geometry_msgs/msg/TwistWithCovariance`
#[derive(Debug, Clone, Deserialize)]
pub struct TwistWithCovariance {
    pub twist: Twist,
    pub covariance: Covariance36,
}

/// `nav_msgs/msg/Odometry`
#[derive(Debug, Clone, Deserialize)]
pub struct Odometry {
    pub header: Header,
    #[serde(deserialize_with = "crate::logs::rosdyn::cdr_string")]
    pub child_frame_id: String,
    pub pose: PoseWithCovariance,
    pub twist: TwistWithCovariance,
}

/// `geometry_msgs/msg/Transform`
#[derive(Debug, Clone, Copy, Deserialize)]
pub struct Transform {
    pub translation: Vector3,
    pub rotation: Quaternion,
}

/// `geometry_msgs/msg/TransformStamped`
#[derive(Debug, Clone, Deserialize)]
pub struct TransformStamped {
    pub header: Header,
    #[serde(deserialize_with = "crate::logs::rosdyn::cdr_string")]
    pub child_frame_id: String,
    pub transform: Transform,
}

/// `tf2_msgs/msg/TFMessage`
#[derive(Debug, Clone, Deserialize)]
pub struct TfMessage {
    pub transforms: Vec<TransformStamped>,
}

/// Decode one CDR message (with its 4-byte encapsulation header, as rosbag2
/// stores it).
pub fn decode<'de, T: Deserialize<'de>>(data: &'de [u8]) -> Result<T, cdr::Error> {
    cdr::deserialize::<T>(data)
}
