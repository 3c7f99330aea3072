//! The pose observation `init` writes where the controller publishes
//! odometry (issue 68, item 3): of the controller's `base_frame_id`, placed
//! in the spec's base frame through the URDF's joints.
use kinegen_init::{from_text, Controller, Options};
use std::path::{Path, PathBuf};

fn robot(file: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../tests/robots/burger")
        .join(file)
}

/// The burger with its chassis 0.05 m ahead of, 0.02 m beside and turned
/// 0.1 rad from the footprint frame its controller's odometry is of.
fn offset_urdf() -> String {
    let text = std::fs::read_to_string(robot("robot.urdf")).unwrap();
    let at = r#"<origin xyz="0 0 0.010" rpy="0 0 0"/>"#;
    assert!(text.contains(at), "the burger's footprint joint changed");
    text.replacen(at, r#"<origin xyz="0.05 0.02 0.010" rpy="0 0 0.1"/>"#, 1)
}

fn written(base_link: Option<&str>) -> (String, String) {
    let ctl = Controller::read(&robot("controllers.yaml")).unwrap();
    let options = Options {
        base_link: base_link.map(str::to_string),
        ..Options::default()
    };
    let out = from_text(&robot("robot.urdf"), &offset_urdf(), Some(&ctl), &options).unwrap();
    (out.spec, out.topics)
}

/// With the chassis as the base frame, the footprint is at R(-0.1) (-0.05,
/// -0.02) = (-0.0517, -0.0149), turned -0.1 rad: the observation's
/// expressions say so, and the topics file measures the footprint. A writer
/// that placed the frame without its rotation (-0.05, -0.02) fails.
#[test]
fn the_odometry_frame_is_placed_through_the_urdf() {
    let (spec, topics) = written(Some("chassis_core"));
    let pose = &spec[spec.find("name = \"pose\"").expect("a pose observation")..];
    let expr = pose.lines().find(|l| l.starts_with("expr")).unwrap();
    let (c, s) = (0.1f64.cos(), 0.1f64.sin());
    let (ox, oy) = (-(0.05 * c + 0.02 * s), -(-0.05 * s + 0.02 * c));
    for v in [ox, oy] {
        assert!(
            expr.contains(&format!("{:.4}", v.abs())),
            "{v:.4} in {expr}"
        );
    }
    assert!(expr.contains("theta - 0.1"), "{expr}");
    assert!(pose.contains("role = \"pose\""), "{pose}");
    assert!(topics.contains("frame = \"footprint_frame\""), "{topics}");
}

/// With the controller's own frame as the base (the default), the pose
/// observation is the base pose itself.
#[test]
fn the_default_base_is_the_odometry_frame() {
    let (spec, _) = written(None);
    assert!(
        spec.contains("expr = [\"x\", \"y\", \"theta\"]\nangle = [false, false, true]"),
        "{spec}"
    );
}
