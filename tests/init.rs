//! `kinegen init`: eight robot descriptions (tests/robots/, six written
//! from the published dimensions of robots of different kinds, a
//! front-wheel-drive car and a swerve base of our own, with joint and
//! link names unlike the usual ones) become specs whose geometry is the
//! description's to 1e-9, that every analysis command runs without edits,
//! and whose calibration goes back into the controller file read. Bad
//! descriptions are refused at their line, writing nothing.
mod common;
use common::*;
use kinegen_model::spec::{Kinematics, Model};
use std::collections::HashMap;
use std::path::{Path, PathBuf};

fn robot(name: &str) -> PathBuf {
    root().join("tests/robots").join(name)
}

/// `kinegen init` for a fixture, run from a folder outside the checkout;
/// the spec's path.
fn init(name: &str, dir: &Path) -> PathBuf {
    let r = robot(name);
    let urdf = r.join("robot.urdf");
    let ctl = r.join("controllers.yaml");
    let spec = dir.join(format!("{name}.toml"));
    let mut args = vec![
        "init",
        "--urdf",
        urdf.to_str().unwrap(),
        "--out",
        spec.to_str().unwrap(),
    ];
    if ctl.exists() {
        args.extend(["--controller", ctl.to_str().unwrap()]);
    }
    let topics = dir.join(format!("{name}_topics.toml"));
    args.extend(["--topics-out", topics.to_str().unwrap()]);
    let o = kinegen_in(dir, &args);
    assert!(o.status.success(), "init {name}: {}", stderr(&o));
    commands_mapping_reads(&topics);
    spec
}

/// The topics file's commented mapping of the controller's velocity
/// commands (for a bag without the wheel joints), uncommented, is a
/// mapping kinegen reads: each command input names a Twist component.
fn commands_mapping_reads(topics: &Path) {
    let text = std::fs::read_to_string(topics).unwrap();
    let block = text
        .split_once("# [inputs]\n")
        .unwrap_or_else(|| panic!("no commands mapping in {text}"))
        .1;
    let toml = format!("[inputs]\n{}", block.replace("# ", ""));
    let path = topics.with_extension("commands.toml");
    std::fs::write(&path, &toml).unwrap();
    let map = kinegen_analysis::logs::bag::TopicMap::read(&path)
        .unwrap_or_else(|e| panic!("{e}: {toml}"));
    assert!(
        map.inputs.len() >= 2
            && map
                .inputs
                .values()
                .all(|i| i.field.is_some()
                    && i.topic.as_deref().is_some_and(|t| t.ends_with("cmd_vel"))),
        "{toml}"
    );
}

/// Evaluate a spec expression with its definitions expanded, parameters at
/// nominal, noise at zero.
fn eval(m: &Model, e: &kinegen_model::expr::Expr, inputs: &HashMap<&str, f64>) -> f64 {
    let params: HashMap<&str, f64> = m
        .params
        .iter()
        .map(|p| (p.name.as_str(), p.nominal))
        .collect();
    m.expand(e)
        .eval(&|v| {
            inputs
                .get(v)
                .or_else(|| params.get(v))
                .copied()
                .or_else(|| m.noise.iter().any(|n| n.name == v).then_some(0.0))
                .or((v == "pi").then_some(std::f64::consts::PI))
        })
        .unwrap_or_else(|| panic!("cannot evaluate {e:?}"))
}

fn twist(m: &Model, inputs: &HashMap<&str, f64>) -> [f64; 3] {
    let Kinematics::Twist(t) = &m.kinematics else {
        panic!("{}: expected a twist", m.name)
    };
    [
        eval(m, &t[0], inputs),
        eval(m, &t[1], inputs),
        eval(m, &t[2], inputs),
    ]
}

/// Each constraint row at nominal parameters, in the order of `joints`.
fn rows(m: &Model, joints: &[&str]) -> Vec<[f64; 3]> {
    let Kinematics::Constraints(c) = &m.kinematics else {
        panic!("{}: expected constraints", m.name)
    };
    let none = HashMap::new();
    joints
        .iter()
        .map(|j| {
            let (_, row) = c
                .rows
                .iter()
                .find(|(r, _)| r == j)
                .unwrap_or_else(|| panic!("no row for {j}"));
            [
                eval(m, &row[0], &none),
                eval(m, &row[1], &none),
                eval(m, &row[2], &none),
            ]
        })
        .collect()
}

fn close(a: f64, b: f64, what: &str) {
    assert!(
        (a - b).abs() <= 1e-9 * (1.0 + b.abs()),
        "{what}: spec {a}, description {b}"
    );
}

/// Inputs spread over a robot's range (a few rad/s, steering within its lock).
fn samples() -> Vec<[f64; 4]> {
    (0..20)
        .map(|k| {
            let s = |i: usize| ((k * 7 + i * 13) as f64 * 0.61).sin();
            [3.0 * s(1), 3.0 * s(2), 0.4 * s(3), 0.4 * s(4)]
        })
        .collect()
}

#[test]
fn a_two_wheel_diff_drive_with_a_caster_is_its_turtlebot_geometry() {
    let dir = tempfile::tempdir().unwrap();
    let m = Model::load(&init("burger", dir.path())).unwrap();
    assert_eq!(
        m.inputs
            .iter()
            .map(|i| i.column.as_str())
            .collect::<Vec<_>>(),
        ["propulsor_port", "propulsor_stbd"]
    );
    for [wl, wr, ..] in samples() {
        let t = twist(
            &m,
            &HashMap::from([("propulsor_port", wl), ("propulsor_stbd", wr)]),
        );
        close(t[0], 0.033 * (wl + wr) / 2.0, "vx");
        close(t[1], 0.0, "vy");
        close(t[2], 0.033 * (wr - wl) / 0.160, "omega");
    }
}

#[test]
fn a_four_wheel_skid_steer_is_its_husky_geometry_with_the_controllers_effective_track() {
    let dir = tempfile::tempdir().unwrap();
    let m = Model::load(&init("hauler", dir.path())).unwrap();
    let b = m
        .params
        .iter()
        .find(|p| p.name == "wheel_separation")
        .unwrap();
    assert_eq!(b.tolerance, None, "a skid-steer track has no prior");
    for [a, b2, c, d] in samples() {
        let u = HashMap::from([
            ("corner_fp", a),
            ("corner_ap", b2),
            ("corner_fs", c),
            ("corner_as", d),
        ]);
        let t = twist(&m, &u);
        let (vl, vr) = (0.1651 * (a + b2) / 2.0, 0.1651 * (c + d) / 2.0);
        close(t[0], (vl + vr) / 2.0, "vx");
        close(t[2], (vr - vl) / (0.5708 * 1.875), "omega");
    }
}

#[test]
fn a_mecanum_base_has_the_ros2_controllers_rows() {
    let dir = tempfile::tempdir().unwrap();
    let m = Model::load(&init("sidestep", dir.path())).unwrap();
    let (r, l) = (0.05, 0.085 + 0.134);
    // ros2 mecanum_drive_controller's inverse kinematics, per wheel
    let expect = [
        [1.0, -1.0, -l],
        [1.0, 1.0, l],
        [1.0, 1.0, -l],
        [1.0, -1.0, l],
    ];
    let got = rows(&m, &["paw_fl", "paw_fr", "paw_rl", "paw_rr"]);
    for (g, e) in got.iter().zip(expect) {
        for k in 0..3 {
            close(g[k], e[k] / r, "mecanum row");
        }
    }
}

#[test]
fn an_ackermann_car_is_its_f1tenth_geometry_seen_from_the_middle_of_the_car() {
    let dir = tempfile::tempdir().unwrap();
    let m = Model::load(&init("racer", dir.path())).unwrap();
    let steering: Vec<&str> = m
        .inputs
        .iter()
        .filter(|i| i.kind == kinegen_model::decl::InputKind::Absolute)
        .map(|i| i.name.as_str())
        .collect();
    let mut sorted = steering.clone();
    sorted.sort();
    assert_eq!(
        sorted,
        ["knuckle_l", "knuckle_r"],
        "both steering joints are inputs"
    );
    let (r, wb, half) = (0.0508, 0.3302, 0.12);
    for [wl, wr, dl, dr] in samples() {
        let u = HashMap::from([
            ("axle_drive_l", wl),
            ("axle_drive_r", wr),
            ("knuckle_l", dl),
            ("knuckle_r", dr),
        ]);
        let t = twist(&m, &u);
        let v = r * (wl + wr) / 2.0;
        // each front wheel points at the turn centre on the rear axle line
        let k = (dl.tan() / (wb + half * dl.tan()) + dr.tan() / (wb - half * dr.tan())) / 2.0;
        close(t[0], v, "vx");
        // the base link is 0.1651 m ahead of the rear axle
        close(t[1], 0.1651 * v * k, "vy");
        close(t[2], v * k, "omega");
    }
}

/// A front-wheel-drive car (#68): its steered front wheels drive, the rear
/// roll freely, and the right steering joint mimics the left, so only the
/// left angle is an input; the right wheel's angle is the one that points
/// it at the turn centre. Each front wheel rolls along its heading.
#[test]
fn a_front_wheel_drive_car_is_driven_by_its_steered_wheels() {
    let dir = tempfile::tempdir().unwrap();
    let m = Model::load(&init("runabout", dir.path())).unwrap();
    let mut names: Vec<&str> = m.inputs.iter().map(|i| i.name.as_str()).collect();
    names.sort();
    assert_eq!(names, ["drive_l", "drive_r", "pivot_l"], "{}", m.doc);
    assert!(m.doc.contains("steered and driven front"), "{}", m.doc);
    let (r, l, y, ahead) = (0.085, 0.52, 0.2, 0.12);
    for [wl, wr, d, _] in samples() {
        let u = HashMap::from([("drive_l", wl), ("drive_r", wr), ("pivot_l", d)]);
        let t = twist(&m, &u);
        // the left wheel points at the turn centre on the rear axle line;
        // the right, through the linkage, at the same centre
        let k = d.tan() / (l + y * d.tan());
        let dr = (k * l).atan2(1.0 + k * y);
        let v = (r * wl * (l * d.cos() + y * d.sin()) + r * wr * (l * dr.cos() - y * dr.sin()))
            / (2.0 * l);
        close(t[0], v, "vx");
        close(t[1], ahead * v * k, "vy");
        close(t[2], v * k, "omega");
    }
}

/// A swerve base (#68): every module steers (continuous joints commanded by
/// ros2_control, one axis pointing down) and drives; the twist is the
/// least-squares solution of the modules' velocities, at the base link
/// 0.05 m behind the modules' centre.
#[test]
fn a_swerve_base_is_the_least_squares_twist_of_its_modules() {
    let dir = tempfile::tempdir().unwrap();
    let m = Model::load(&init("crab", dir.path())).unwrap();
    assert!(
        m.doc.contains("every wheel steered and driven"),
        "{}",
        m.doc
    );
    assert_eq!(m.inputs.len(), 8);
    let (r, a, b, behind) = (0.0508, 0.30, 0.28, 0.05);
    let modules = [
        ("fl", a, b, 1.0),
        ("fr", a, -b, 1.0),
        ("rl", -a, b, 1.0),
        ("rr", -a, -b, -1.0),
    ];
    for k in 0..20 {
        let s = |i: usize| ((k * 7 + i * 13) as f64 * 0.61).sin();
        let mut u = HashMap::new();
        let (mut vx, mut vy, mut turn) = (0.0, 0.0, 0.0);
        for (i, (name, qx, qy, sign)) in modules.iter().enumerate() {
            let (w, joint_angle) = (3.0 * s(2 * i), 1.5 * s(2 * i + 1));
            u.insert(format!("roll_{name}"), w);
            u.insert(format!("turn_{name}"), joint_angle);
            let d = sign * joint_angle;
            vx += r * w * d.cos() / 4.0;
            vy += r * w * d.sin() / 4.0;
            turn += r * w * (qx * d.sin() - qy * d.cos());
        }
        let omega = turn / (4.0 * (a * a + b * b));
        let u: HashMap<&str, f64> = u.iter().map(|(k, v)| (k.as_str(), *v)).collect();
        let t = twist(&m, &u);
        close(t[0], vx, "vx");
        close(t[1], vy - behind * omega, "vy");
        close(t[2], omega, "omega");
    }
}

/// `init --commands` (#68): for bags that logged only the velocity commands,
/// a spec driven by them (the commanded forward speed and turn rate, and the
/// sideways speed of a base that moves sideways, each with a gain) and the
/// mapping of the controller's command topic, which kinegen reads. Its
/// gains come back from a robot that achieves 94% of its commanded speed
/// and 107% of its turn rate.
#[test]
fn a_commands_spec_calibrates_what_the_robot_achieves_of_its_commands() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let init_commands = |name: &str| {
        let r = robot(name);
        let (spec, topics) = (
            d.join(format!("{name}_cmd.toml")),
            d.join(format!("{name}_cmd_topics.toml")),
        );
        let o = kinegen_in(
            d,
            &[
                "init",
                "--urdf",
                r.join("robot.urdf").to_str().unwrap(),
                "--controller",
                r.join("controllers.yaml").to_str().unwrap(),
                "--commands",
                "--out",
                spec.to_str().unwrap(),
                "--topics-out",
                topics.to_str().unwrap(),
            ],
        );
        assert!(o.status.success(), "{name}: {}", stderr(&o));
        assert!(
            stdout(&o).contains("driven by its velocity commands"),
            "{}",
            stdout(&o)
        );
        let map = kinegen_analysis::logs::bag::TopicMap::read(&topics).unwrap();
        let columns: Vec<&str> = map.inputs.keys().map(String::as_str).collect();
        assert!(
            (map.inputs.values()).all(|i| i.field.is_some()
                && i.topic.as_deref().is_some_and(|t| t.ends_with("/cmd_vel"))),
            "{name}: {columns:?}"
        );
        let m = Model::load(&spec).unwrap();
        let inputs: Vec<String> = m.inputs.iter().map(|i| i.name.clone()).collect();
        (spec, inputs)
    };
    let (_, sideways) = init_commands("sidestep");
    assert_eq!(sideways, ["v_cmd", "vy_cmd", "omega_cmd"]);
    let (spec, inputs) = init_commands("burger");
    assert_eq!(inputs, ["v_cmd", "omega_cmd"]);
    let s = spec.to_str().unwrap();
    let log = Sim::new(s)
        .sets(&["k_v=0.94", "k_omega=1.07"])
        .drive("random", 3, 1)
        .write(d, "commanded.csv");
    let fit = kinegen_json(&["fit", "--spec", s, "--data", log.to_str().unwrap()]);
    for (name, truth) in [("k_v", 0.94), ("k_omega", 1.07)] {
        let est = fit["parameters"][name]["estimate"].as_f64().unwrap();
        assert!((est - truth).abs() < 0.01, "{name}: {est} against {truth}");
    }
}

#[test]
fn a_tricycle_whose_steered_wheel_drives_uses_the_controllers_wheelbase() {
    let dir = tempfile::tempdir().unwrap();
    let m = Model::load(&init("forklift", dir.path())).unwrap();
    for [w, _, d, _] in samples() {
        let t = twist(
            &m,
            &HashMap::from([("tread_drive", w), ("mast_turn", 2.0 * d)]),
        );
        let d = 2.0 * d;
        close(t[0], 0.125 * w * d.cos(), "vx");
        close(t[1], 0.0, "vy");
        close(t[2], 0.125 * w * d.sin() / 1.21, "omega");
    }
}

#[test]
fn a_three_wheel_omni_base_has_its_robotino_rows_and_an_upside_down_gyro() {
    let dir = tempfile::tempdir().unwrap();
    let m = Model::load(&init("trio", dir.path())).unwrap();
    let (r, l) = (0.040, 0.135);
    // wheels at 90, 210 and 330 degrees, axles radial: each rolls tangentially
    let got = rows(&m, &["roll_a", "roll_b", "roll_c"]);
    for (g, deg) in got.iter().zip([90.0f64, 210.0, 330.0]) {
        let a = deg.to_radians();
        close(g[0], a.sin() / r, "omni row x");
        close(g[1], -a.cos() / r, "omni row y");
        close(g[2], -l / r, "omni row omega");
    }
    assert!(
        m.observations.iter().any(|o| o.name == "gyro"),
        "a gyro from the IMU link"
    );
    assert!(
        m.source.contains("expr = [\"-omega\"]"),
        "the IMU is mounted upside down"
    );
}

/// simulate (with landmarks), compare, fit, diagnose and localize on the
/// spec init wrote, unedited, from a folder outside the checkout.
fn every_command_runs(name: &str) {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let spec = init(name, d);
    let map = root().join("data/beacons.csv");
    let (s, m) = (spec.to_str().unwrap(), map.to_str().unwrap());
    let run = |args: &[&str]| {
        let o = kinegen_in(d, args);
        assert!(
            o.status.success(),
            "{name}: kinegen {args:?}: {}",
            stderr(&o)
        );
        stdout(&o)
    };
    run(&[
        "simulate",
        "--spec",
        s,
        "--trajectory",
        "random",
        "--seed",
        "4",
        "--landmarks",
        m,
        "--observations",
        "obs.csv",
        "--out",
        "log.csv",
    ]);
    for cmd in ["compare", "fit", "diagnose"] {
        let out = run(&[cmd, "--spec", s, "--data", "log.csv"]);
        assert!(out.contains("answer:"), "{name} {cmd}: {out}");
    }
    let out = run(&[
        "localize",
        "--spec",
        s,
        "--data",
        "log.csv",
        "--observations",
        "obs.csv",
        "--landmarks",
        m,
    ]);
    assert!(
        out.contains("answer: position RMSE"),
        "{name} localize: {out}"
    );
}

#[test]
fn the_diff_drive_spec_runs_every_command_unedited() {
    every_command_runs("burger");
}
#[test]
fn the_skid_steer_spec_runs_every_command_unedited() {
    every_command_runs("hauler");
}
#[test]
fn the_mecanum_spec_runs_every_command_unedited() {
    every_command_runs("sidestep");
}
#[test]
fn the_ackermann_spec_runs_every_command_unedited() {
    every_command_runs("racer");
}
#[test]
fn the_swerve_spec_runs_every_command_unedited() {
    every_command_runs("crab");
}

#[test]
fn the_front_wheel_drive_spec_runs_every_command_unedited() {
    every_command_runs("runabout");
}

#[test]
fn the_tricycle_spec_runs_every_command_unedited() {
    every_command_runs("forklift");
}
#[test]
fn the_omni_spec_runs_every_command_unedited() {
    every_command_runs("trio");
}

/// The numbers under `node: ros__parameters:` of a controller file, by key.
fn yaml_numbers(text: &str) -> HashMap<String, f64> {
    text.lines()
        .filter_map(|l| {
            let (k, v) = l.trim().split_once(':')?;
            Some((
                k.trim().to_string(),
                v.split('#').next()?.trim().parse().ok()?,
            ))
        })
        .collect()
}

#[test]
fn fit_writes_the_calibration_into_the_controller_file_init_read() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let spec = init("burger", d);
    let s = spec.to_str().unwrap();
    // the robot's real track is 3% wider and its right wheel 1% larger
    let o = kinegen_in(
        d,
        &[
            "simulate",
            "--spec",
            s,
            "--trajectory",
            "random",
            "--seed",
            "5",
            "--set",
            "wheel_separation=0.1648",
            "--set",
            "wheel_radius_right=0.03333",
            "--out",
            "log.csv",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let o = kinegen_in(
        d,
        &[
            "fit",
            "--spec",
            s,
            "--data",
            "log.csv",
            "--export",
            "ros2-yaml",
            "calibrated.yaml",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let original = std::fs::read_to_string(robot("burger").join("controllers.yaml")).unwrap();
    let written = std::fs::read_to_string(d.join("calibrated.yaml")).unwrap();
    // the same file, line for line, but for the calibrated numbers (and a head of comments)
    let body: Vec<&str> = written.lines().skip_while(|l| l.starts_with('#')).collect();
    let before: Vec<&str> = original.lines().collect();
    assert_eq!(body.len(), before.len(), "{written}");
    let changed: Vec<&str> = body
        .iter()
        .zip(&before)
        .filter(|(a, b)| a != b)
        .map(|(a, _)| a.trim())
        .collect();
    assert!(
        changed
            .iter()
            .all(|l| l.contains("wheel_") && l.contains(": ")),
        "only the calibrated keys change: {changed:?}"
    );
    let v = yaml_numbers(&written);
    assert!((v["wheel_separation"] - 0.1648).abs() < 0.002, "{written}");
    let right = v["wheel_radius"] * v["right_wheel_radius_multiplier"];
    let left = v["wheel_radius"] * v["left_wheel_radius_multiplier"];
    assert!(
        (right - 0.03333).abs() < 0.0003 && (left - 0.033).abs() < 0.0003,
        "{written}"
    );
    assert!(
        written.contains("wheel_separation_multiplier: 1.0\n"),
        "a double stays a double for ROS 2: {written}"
    );
}

#[test]
fn a_bag_with_the_descriptions_joint_names_calibrates_with_the_written_mapping() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let spec = init("burger", d);
    let s = spec.to_str().unwrap();
    let o = kinegen_in(
        d,
        &[
            "simulate",
            "--spec",
            s,
            "--trajectory",
            "random",
            "--seed",
            "6",
            "--set",
            "wheel_separation=0.1648",
            "--out",
            "log.csv",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let o = std::process::Command::new("python3")
        .arg(root().join("verify/bags/csv_to_bag.py"))
        .args([
            "log.csv",
            "run_bag",
            "--joints",
            "propulsor_port,propulsor_stbd",
            "--pose",
            "tf",
            "--frame",
            "footprint_frame",
        ])
        .current_dir(d)
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "writing the bag (pip install -r verify/bags/requirements.txt): {}",
        stderr(&o)
    );
    let o = kinegen_in(
        d,
        &[
            "fit",
            "--spec",
            s,
            "--data",
            "run_bag",
            "--topics",
            "burger_topics.toml",
            "--json",
            "-",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let b = j["parameters"]["wheel_separation"]["estimate"]
        .as_f64()
        .unwrap();
    assert!((b - 0.1648).abs() < 0.002, "calibrated from the bag: {b}");
}

/// `init` on a description that must be refused: exit 2, the message names
/// the file and `line`, and neither output file is written.
fn refused_at(urdf: &str, controller: Option<&str>, line: usize, says: &str) {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("robot.urdf"), urdf).unwrap();
    let mut args = vec![
        "init",
        "--urdf",
        "robot.urdf",
        "--out",
        "spec.toml",
        "--topics-out",
        "topics.toml",
    ];
    if let Some(c) = controller {
        std::fs::write(d.join("controllers.yaml"), c).unwrap();
        args.extend(["--controller", "controllers.yaml"]);
    }
    let o = kinegen_in(d, &args);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{err}");
    let file = if controller.is_some() && says.contains("units") {
        "controllers.yaml"
    } else {
        "robot.urdf"
    };
    assert!(
        err.contains(&format!("{file}:{line}")),
        "expected {file}:{line} in: {err}"
    );
    assert!(err.contains(says), "expected `{says}` in: {err}");
    assert!(!err.contains("panicked"), "{err}");
    assert!(
        !d.join("spec.toml").exists() && !d.join("topics.toml").exists(),
        "nothing is written"
    );
}

fn burger_with(from: &str, to: &str) -> String {
    let text = std::fs::read_to_string(robot("burger").join("robot.urdf")).unwrap();
    assert!(text.contains(from), "the fixture has `{from}`");
    text.replacen(from, to, 1)
}

fn line_of(text: &str, what: &str) -> usize {
    text.lines()
        .position(|l| l.contains(what))
        .unwrap_or_else(|| panic!("no `{what}`"))
        + 1
}

#[test]
fn malformed_xml_is_refused_at_its_line() {
    let bad = burger_with("<link name=\"tyre_stbd\">", "<link name=\"tyre_stbd\"");
    refused_at(
        &bad,
        None,
        line_of(&bad, "<link name=\"tyre_stbd\"") + 1,
        "not well-formed XML",
    );
}

#[test]
fn a_description_with_two_roots_asks_for_a_base_link() {
    let bad = burger_with(
        "<parent link=\"footprint_frame\"/>",
        "<parent link=\"chassis_core\"/>",
    );
    // footprint_frame -> chassis_core made chassis_core its own parent's child: a loop
    refused_at(
        &bad,
        None,
        line_of(&bad, "name=\"footprint_to_core\""),
        "loop",
    );
    let orphan = burger_with(
        "<link name=\"footprint_frame\"/>",
        "<link name=\"footprint_frame\"/>\n  <link name=\"stray_plate\"/>",
    );
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("robot.urdf"), &orphan).unwrap();
    let o = kinegen_in(
        dir.path(),
        &["init", "--urdf", "robot.urdf", "--out", "spec.toml"],
    );
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("--base-link") && stderr(&o).contains("stray_plate"),
        "{}",
        stderr(&o)
    );
    assert!(!dir.path().join("spec.toml").exists());
    // named, it goes through
    let o = kinegen_in(
        dir.path(),
        &[
            "init",
            "--urdf",
            "robot.urdf",
            "--base-link",
            "footprint_frame",
            "--out",
            "spec.toml",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let o = kinegen_in(
        dir.path(),
        &[
            "init",
            "--urdf",
            "robot.urdf",
            "--base-link",
            "no_such",
            "--out",
            "other.toml",
        ],
    );
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("--base-link") && stderr(&o).contains("no_such"),
        "{}",
        stderr(&o)
    );
}

#[test]
fn a_description_without_wheels_is_refused() {
    let text = std::fs::read_to_string(robot("burger").join("robot.urdf")).unwrap();
    let bad = text.replace("type=\"continuous\"", "type=\"fixed\"");
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("robot.urdf"), &bad).unwrap();
    let o = kinegen_in(
        dir.path(),
        &["init", "--urdf", "robot.urdf", "--out", "spec.toml"],
    );
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("robot.urdf: no wheels found"),
        "{}",
        stderr(&o)
    );
    assert!(!dir.path().join("spec.toml").exists());
}

#[test]
fn a_wheel_without_geometry_is_refused_at_its_link() {
    let bad = burger_with(
        "<collision><geometry><cylinder length=\"0.018\" radius=\"0.033\"/></geometry></collision>",
        "<visual><geometry><mesh filename=\"package://rover/tyre.stl\"/></geometry></visual>",
    );
    refused_at(
        &bad,
        None,
        line_of(&bad, "<link name=\"tyre_port\">"),
        "no cylinder or sphere geometry",
    );
}

#[test]
fn two_wheels_on_one_axle_at_different_radii_are_refused() {
    let text = std::fs::read_to_string(robot("burger").join("robot.urdf")).unwrap();
    let at = text.rfind("radius=\"0.033\"").unwrap();
    let bad = format!(
        "{}radius=\"0.036\"{}",
        &text[..at],
        &text[at + "radius=\"0.033\"".len()..]
    );
    refused_at(
        &bad,
        None,
        line_of(&bad, "radius=\"0.036\""),
        "share an axle but have different radii",
    );
}

#[test]
fn a_controller_in_millimetres_is_refused_as_inconsistent_units() {
    let urdf = std::fs::read_to_string(robot("burger").join("robot.urdf")).unwrap();
    let ctl = std::fs::read_to_string(robot("burger").join("controllers.yaml"))
        .unwrap()
        .replace("wheel_radius: 0.033", "wheel_radius: 33.0");
    refused_at(
        &urdf,
        Some(&ctl),
        line_of(&ctl, "wheel_radius: 33"),
        "inconsistent units",
    );
}

#[test]
fn a_controller_naming_a_joint_the_urdf_lacks_is_refused_at_its_key() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let ctl = std::fs::read_to_string(robot("burger").join("controllers.yaml"))
        .unwrap()
        .replace("[\"propulsor_port\"]", "[\"left_wheel_joint\"]");
    std::fs::write(d.join("c.yaml"), &ctl).unwrap();
    let urdf = robot("burger").join("robot.urdf");
    let o = kinegen_in(
        d,
        &[
            "init",
            "--urdf",
            urdf.to_str().unwrap(),
            "--controller",
            "c.yaml",
            "--out",
            "s.toml",
        ],
    );
    assert_eq!(o.status.code(), Some(2));
    let want = format!("c.yaml:{}", line_of(&ctl, "left_wheel_names"));
    assert!(
        stderr(&o).contains(&want) && stderr(&o).contains("left_wheel_joint"),
        "{}",
        stderr(&o)
    );
    std::fs::write(
        d.join("c.yaml"),
        "rover_base:\n  ros__parameters:\n    wheel_radius: [0.03\n",
    )
    .unwrap();
    let o = kinegen_in(
        d,
        &[
            "init",
            "--urdf",
            urdf.to_str().unwrap(),
            "--controller",
            "c.yaml",
            "--out",
            "s.toml",
        ],
    );
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("c.yaml:") && stderr(&o).contains("not valid YAML"),
        "{}",
        stderr(&o)
    );
    assert!(!d.join("s.toml").exists());
}

#[test]
fn a_xacro_description_is_expanded_or_refused_with_how_to_expand_it() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let text = std::fs::read_to_string(robot("burger").join("robot.urdf")).unwrap();
    // the wheel radius as a xacro property
    let xacro = text
        .replace("<robot name=\"pocket_rover\">", "<robot name=\"pocket_rover\" xmlns:xacro=\"http://www.ros.org/wiki/xacro\">\n  <xacro:property name=\"tyre_r\" value=\"0.034\"/>")
        .replace("radius=\"0.033\"", "radius=\"${tyre_r}\"");
    std::fs::write(d.join("robot.urdf.xacro"), xacro).unwrap();
    let o = kinegen_in(
        d,
        &["init", "--urdf", "robot.urdf.xacro", "--out", "s.toml"],
    );
    let has_xacro = std::process::Command::new("python3")
        .args(["-c", "import xacro"])
        .status()
        .is_ok_and(|s| s.success());
    if has_xacro {
        assert!(o.status.success(), "{}", stderr(&o));
        let m = Model::load(&d.join("s.toml")).unwrap();
        assert_eq!(
            m.params
                .iter()
                .find(|p| p.name == "wheel_radius_left")
                .unwrap()
                .nominal,
            0.034
        );
    } else {
        assert_eq!(o.status.code(), Some(2));
        assert!(stderr(&o).contains("pip install xacro"), "{}", stderr(&o));
    }
}
