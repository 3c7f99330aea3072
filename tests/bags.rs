//! ROS 2 bags (MCAP) as --data (issue 17). The bags are written by the test
//! tooling (`verify/bags/csv_to_bag.py`, which serialises with the `rosbags`
//! package's own ROS 2 type store, independently of kinegen's decoder) from a
//! simulated CSV log; kinegen must give the same answers from the bag as from
//! the CSV, and locate every problem in a bad bag (file, topic, message).
mod common;
use common::*;
use std::path::{Path, PathBuf};
use std::process::Command;

/// Write `log` as a rosbag2 directory `dir/name` (extra arguments for the writer).
fn bag(dir: &Path, log: &Path, name: &str, extra: &[&str]) -> PathBuf {
    let out = dir.join(name);
    let o = Command::new("python3")
        .arg(root().join("verify/bags/csv_to_bag.py"))
        .arg(log)
        .arg(&out)
        .args(["--joints", "enc_r,enc_l"])
        .args(extra)
        .output()
        .expect("python3");
    assert!(
        o.status.success(),
        "writing the test bag failed (pip install -r verify/bags/requirements.txt): {}",
        String::from_utf8_lossy(&o.stderr)
    );
    out
}

fn hidden_slip_log(dir: &Path) -> PathBuf {
    Sim::new("spec/diff_drive.toml")
        .sets(&["b=0.205"])
        .effects(&["lateral_slip=0.2"])
        .drive("random", 3, 1)
        .write(dir, "slip.csv")
}

fn estimates(d: &serde_json::Value) -> Vec<(String, f64)> {
    let mut v: Vec<(String, f64)> = d["parameters"]
        .as_object()
        .unwrap()
        .iter()
        .map(|(k, p)| (k.clone(), p["estimate"].as_f64().unwrap()))
        .collect();
    v.sort_by(|a, b| a.0.cmp(&b.0));
    v
}

#[test]
fn fit_and_diagnose_answer_the_same_from_the_bag_as_from_the_csv() {
    let tmp = tempfile::tempdir().unwrap();
    let csv = hidden_slip_log(tmp.path());
    let b = bag(tmp.path(), &csv, "run", &[]);
    let spec = "spec/diff_drive.toml";
    let (fc, fb) = (
        kinegen_json(&["fit", "--spec", spec, "--data", csv.to_str().unwrap()]),
        kinegen_json(&["fit", "--spec", spec, "--data", b.to_str().unwrap()]),
    );
    let (ec, eb) = (estimates(&fc), estimates(&fb));
    assert_eq!(ec.len(), eb.len());
    for ((n, c), (_, b)) in ec.iter().zip(&eb) {
        // stamps are whole nanoseconds in a bag, the CSV's t has 9 decimals
        assert!(((c - b) / c).abs() < 1e-6, "{n}: CSV {c} bag {b}");
    }
    let (dc, db) = (
        kinegen_json(&["diagnose", "--spec", spec, "--data", csv.to_str().unwrap()]),
        kinegen_json(&["diagnose", "--spec", spec, "--data", b.to_str().unwrap()]),
    );
    assert_eq!(dc["verdict"]["effect"], "lateral_slip", "{}", dc["verdict"]);
    assert_eq!(db["verdict"]["effect"], dc["verdict"]["effect"]);
    let k = |d: &serde_json::Value| {
        d["verdict"]["effects"][0]["parameters"]["k_slip"]["estimate"]
            .as_f64()
            .unwrap()
    };
    assert!(
        (k(&dc) - k(&db)).abs() < 1e-6 * k(&dc).abs(),
        "{} {}",
        k(&dc),
        k(&db)
    );
    // the .mcap file itself reads as the directory does
    let file = b.join("run.mcap");
    let ff = kinegen_json(&["fit", "--spec", spec, "--data", file.to_str().unwrap()]);
    assert_eq!(estimates(&ff), eb);
}

/// The README's command: calibrate from a bag, write diff_drive_controller parameters.
#[test]
fn fit_from_a_bag_exports_controller_parameters() {
    let tmp = tempfile::tempdir().unwrap();
    let csv = hidden_slip_log(tmp.path());
    let b = bag(tmp.path(), &csv, "run", &[]);
    let yaml = tmp.path().join("diff_drive_controller.yaml");
    let o = kinegen(&[
        "fit",
        "--spec",
        "spec/diff_drive.toml",
        "--data",
        b.join("run.mcap").to_str().unwrap(),
        "--export",
        "ros2-yaml",
        yaml.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = std::fs::read_to_string(&yaml).unwrap();
    assert!(
        text.contains("wheel_separation:") && text.contains("left_wheel_radius_multiplier:"),
        "{text}"
    );
}

/// Odometry and TF ground truth give the same trajectory errors as the CSV's.
#[test]
fn odometry_and_tf_poses_are_read_as_ground_truth() {
    let tmp = tempfile::tempdir().unwrap();
    let csv = hidden_slip_log(tmp.path());
    let rmse = |data: &Path, topics: Option<&Path>| {
        let mut a = vec![
            "compare",
            "--spec",
            "spec/diff_drive.toml",
            "--data",
            data.to_str().unwrap(),
        ];
        if let Some(t) = topics {
            a.extend(["--topics", t.to_str().unwrap()]);
        }
        kinegen_json(&a)["errors"]["rmse"].as_f64().unwrap()
    };
    let want = rmse(&csv, None);
    assert!(want > 0.01, "{want}");
    let odom = bag(tmp.path(), &csv, "odom", &["--pose", "odometry"]);
    assert!((rmse(&odom, None) / want - 1.0).abs() < 1e-6);
    let tf = bag(tmp.path(), &csv, "tf", &["--pose", "tf"]);
    let map = tmp.path().join("topics.toml");
    std::fs::write(&map, "[pose]\ntopic = \"/tf\"\nframe = \"base_link\"\n").unwrap();
    assert!((rmse(&tf, Some(&map)) / want - 1.0).abs() < 1e-6);
    // a TF topic needs its frame
    std::fs::write(&map, "[pose]\ntopic = \"/tf\"\n").unwrap();
    let o = kinegen(&[
        "compare",
        "--spec",
        "spec/diff_drive.toml",
        "--data",
        tf.to_str().unwrap(),
        "--topics",
        map.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("which child frame"), "{}", stderr(&o));
}

/// Bad bags: exit 2 and a message that names the file, the topic and the message.
#[test]
fn bad_bags_are_located() {
    let tmp = tempfile::tempdir().unwrap();
    let t = tmp.path();
    let csv = hidden_slip_log(t);
    let good = bag(t, &csv, "good", &[]);
    let run = |data: &Path, topics: Option<&str>| {
        let mut a = vec![
            "fit".to_string(),
            "--spec".into(),
            "spec/diff_drive.toml".into(),
            "--data".into(),
            data.display().to_string(),
        ];
        if let Some(text) = topics {
            let p = t.join("map.toml");
            std::fs::write(&p, text).unwrap();
            a.extend(["--topics".into(), p.display().to_string()]);
        }
        let a: Vec<&str> = a.iter().map(String::as_str).collect();
        let o = kinegen(&a);
        assert_eq!(o.status.code(), Some(2), "{a:?}: {}", stderr(&o));
        stderr(&o)
    };
    // the mapped topic is not in the bag: the topics it has are listed
    let e = run(&good, Some("[gyro]\ntopic = \"/imu\"\n"));
    assert!(
        e.contains("good.mcap")
            && e.contains("no topic `/imu`")
            && e.contains("/imu/data (sensor_msgs/msg/Imu)")
            && e.contains("/joint_states (sensor_msgs/msg/JointState)"),
        "{e}"
    );
    // a topic of the wrong type
    let e = run(&good, Some("[pose]\ntopic = \"/imu/data\"\n"));
    assert!(
        e.contains("topic `/imu/data` carries sensor_msgs/msg/Imu") && e.contains("PoseStamped"),
        "{e}"
    );
    // a joint the messages do not have
    let e = run(
        &good,
        Some("[inputs]\nenc_r = { joint = \"right_wheel_joint\" }\n"),
    );
    assert!(
        e.contains("topic `/joint_states` message 0")
            && e.contains("no joint `right_wheel_joint` (it has: enc_r, enc_l)"),
        "{e}"
    );
    // a mapping file with a typo is located
    let e = run(&good, Some("[pose]\ntopc = \"/x\"\n"));
    assert!(
        e.contains("map.toml:2") && e.contains("unknown field `topc`"),
        "{e}"
    );
    // unsorted stamps: the message is named, and the way out
    let swapped = bag(t, &csv, "swapped", &["--swap-stamps", "/imu/data:7"]);
    let e = run(&swapped, None);
    assert!(
        e.contains("topic `/imu/data` message 8") && e.contains("unsorted or duplicated stamps"),
        "{e}"
    );
    // ... which the bag's receive times order
    let map = t.join("receive.toml");
    std::fs::write(&map, "stamps = \"receive\"\n").unwrap();
    let o = kinegen(&[
        "fit",
        "--spec",
        "spec/diff_drive.toml",
        "--data",
        swapped.to_str().unwrap(),
        "--topics",
        map.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    // two candidate topics: name one
    let two = bag(t, &csv, "two", &["--extra-topic"]);
    let e = run(&two, None);
    assert!(
        e.contains("/joint_states, /other/joint_states") && e.contains("--topics"),
        "{e}"
    );
    // truncated
    let bytes = std::fs::read(good.join("good.mcap")).unwrap();
    let cut = t.join("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    let e = run(&cut, None);
    assert!(
        e.contains("cut.mcap") && e.contains("truncated or corrupt MCAP file after"),
        "{e}"
    );
    // not a bag at all
    let junk = t.join("junk.mcap");
    std::fs::write(&junk, "t,enc_r\n0,1\n").unwrap();
    let e = run(&junk, None);
    assert!(e.contains("junk.mcap") && e.contains("MCAP"), "{e}");
    // a directory without a bag
    let empty = t.join("empty");
    std::fs::create_dir(&empty).unwrap();
    let e = run(&empty, None);
    assert!(e.contains("no .mcap file"), "{e}");
}

/// Range-bearing observations from a topic of the robot's own message type
/// (its definition read from the bag): calibration from landmarks alone (no
/// ground truth) gives the same estimates from the bag as from the CSV files,
/// in both shapes a robot publishes (an array of detections per message, or
/// one detection per message as a point in the robot frame); and every
/// mistake in the mapping is located at the topic, message and field.
/// The `--topics` mapping of the test bags' landmark topic (an array of
/// id, range and bearing per message).
const ARRAY_TOPICS: &str = "[landmarks]\ntopic = \"/landmarks\"\nid = \"landmarks[].id\"\nrange = \"landmarks[].range\"\nbearing = \"landmarks[].bearing\"\n";

/// A simulated diff-drive log (t, enc_r, enc_l, gt_*, gyro) of random
/// driving with sightings of five landmarks, in `dir`: (log, sightings, map).
fn sighted_log(dir: &Path) -> (PathBuf, PathBuf, PathBuf) {
    let map = dir.join("map.csv");
    std::fs::write(&map, "id,x,y\nL1,3,2\nL2,-1,4\nL3,5,-2\nL4,0,-3\nL5,2,6\n").unwrap();
    let obs = dir.join("obs.csv");
    let csv = Sim::new("spec/diff_drive.toml")
        .sets(&["b=0.205"])
        .drive("random", 4, 1)
        .sighting(&map)
        .write_to(&dir.join("lm.csv"), &obs);
    (csv, obs, map)
}

/// A bag's landmark bearing in degrees is refused at its message, as a CSV
/// one is at its line.
#[test]
fn a_bag_bearing_in_degrees_is_located() {
    let tmp = tempfile::tempdir().unwrap();
    let t = tmp.path();
    let (csv, obs, map) = sighted_log(t);
    let text = std::fs::read_to_string(&obs).unwrap();
    let degrees = edit_cells(&text, |c, v| match c {
        3 => v.parse::<f64>().unwrap().to_degrees().to_string(),
        _ => v.to_string(),
    });
    let obs_deg = t.join("obs_deg.csv");
    std::fs::write(&obs_deg, degrees).unwrap();
    let deg = bag(
        t,
        &csv,
        "deg",
        &[
            "--pose",
            "none",
            "--observations",
            obs_deg.to_str().unwrap(),
        ],
    );
    let topics = t.join("topics.toml");
    std::fs::write(&topics, ARRAY_TOPICS).unwrap();
    let o = kinegen(&[
        "compare",
        "--spec",
        "spec/diff_drive.toml",
        "--data",
        deg.to_str().unwrap(),
        "--topics",
        topics.to_str().unwrap(),
        "--landmarks",
        map.to_str().unwrap(),
    ]);
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{e}");
    assert!(
        e.contains("deg.mcap: topic `/landmarks` message 0 ")
            && e.contains("(counting from 0): bearing ")
            && e.contains("beyond a full turn (2 pi): bearings are in radians (is it in degrees?)"),
        "{e}"
    );
}

#[test]
fn landmark_topics_of_a_user_message_type() {
    let tmp = tempfile::tempdir().unwrap();
    let t = tmp.path();
    let (csv, obs, map) = sighted_log(t);
    // the CSV log without ground truth, so the landmarks alone calibrate
    let text = std::fs::read_to_string(&csv).unwrap();
    let no_gt: String = text
        .lines()
        .map(|l| {
            let c: Vec<&str> = l.split(',').collect();
            format!("{},{},{},{}\n", c[0], c[1], c[2], c[6])
        })
        .collect();
    let csv_no_gt = t.join("no_gt.csv");
    std::fs::write(&csv_no_gt, no_gt).unwrap();
    let fit = |data: &Path, more: &[&str]| {
        let mut a = vec![
            "fit",
            "--spec",
            "spec/diff_drive.toml",
            "--data",
            data.to_str().unwrap(),
            "--landmarks",
            map.to_str().unwrap(),
        ];
        a.extend(more);
        kinegen_json(&a)
    };
    let want = fit(&csv_no_gt, &["--observations", obs.to_str().unwrap()]);
    assert_eq!(want["metric"], "landmark_range_rmse_m", "{want}");
    let (obs_s, pose_none) = (obs.to_str().unwrap(), ["--pose", "none"]);
    let array = bag(
        t,
        &csv,
        "array",
        &[&pose_none[..], &["--observations", obs_s]].concat(),
    );
    let point = bag(
        t,
        &csv,
        "point",
        &[
            &pose_none[..],
            &["--observations", obs_s, "--observation-form", "point"],
        ]
        .concat(),
    );
    let topics = |name: &str, text: &str| {
        let p = t.join(name);
        std::fs::write(&p, text).unwrap();
        p
    };
    let ta = topics("array.toml", ARRAY_TOPICS);
    let tp = topics(
        "point.toml",
        "[landmarks]\ntopic = \"/landmarks\"\nid = \"id\"\nx = \"position.x\"\ny = \"position.y\"\n",
    );
    for (b, tm) in [(&array, &ta), (&point, &tp)] {
        let got = fit(b, &["--topics", tm.to_str().unwrap()]);
        assert_eq!(got["metric"], "landmark_range_rmse_m", "{got}");
        for ((n, a), (m, e)) in estimates(&got).iter().zip(estimates(&want)) {
            assert_eq!(n, &m);
            assert!(
                (a - e).abs() <= 1e-9 * e.abs().max(1.0),
                "{n}: {a} from the bag, {e} from the CSV"
            );
        }
    }
    landmark_topic_mistakes_are_located(t, &array, &ta, &map);
}

/// Mistakes in a landmark topic mapping, each located: a topic the bag does
/// not have, a field its messages do not have, no map, a map without some
/// or all of the ids seen (`array`: a bag of LandmarkArray messages, `ta`
/// its right mapping).
fn landmark_topic_mistakes_are_located(t: &Path, array: &Path, ta: &Path, map: &Path) {
    let topics = |name: &str, text: &str| {
        let p = t.join(name);
        std::fs::write(&p, text).unwrap();
        p
    };
    let fails = |data: &Path, topics_text: &str, with_map: bool| {
        let tm = topics("bad.toml", topics_text);
        let mut a = vec![
            "compare",
            "--spec",
            "spec/diff_drive.toml",
            "--data",
            data.to_str().unwrap(),
            "--topics",
            tm.to_str().unwrap(),
        ];
        if with_map {
            a.extend(["--landmarks", map.to_str().unwrap()]);
        }
        let o = kinegen(&a);
        assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
        stderr(&o)
    };
    let e = fails(
        array,
        "[landmarks]\ntopic = \"/marks\"\nid = \"id\"\nrange = \"r\"\nbearing = \"b\"\n",
        true,
    );
    assert!(
        e.contains("no topic `/marks`") && e.contains("/landmarks (test_msgs/msg/LandmarkArray)"),
        "{e}"
    );
    let e = fails(
        array,
        "[landmarks]\ntopic = \"/landmarks\"\nid = \"landmarks[].id\"\nrange = \"landmarks[].rng\"\nbearing = \"landmarks[].bearing\"\n",
        true,
    );
    assert!(
        e.contains("topic `/landmarks` message 0")
            && e.contains("no field `rng` (it has: id, range, bearing)"),
        "{e}"
    );
    let e = fails(array, &std::fs::read_to_string(ta).unwrap(), false);
    assert!(e.contains("needs --landmarks MAP.csv"), "{e}");
    // a map without some of the ids seen: those detections are left out and
    // said with the first one's message; a map with none of them is an error
    std::fs::write(map, "id,x,y\nL1,3,2\nL2,-1,4\n").unwrap();
    let o = kinegen(&[
        "compare",
        "-v",
        "--spec",
        "spec/diff_drive.toml",
        "--data",
        array.to_str().unwrap(),
        "--topics",
        ta.to_str().unwrap(),
        "--landmarks",
        map.to_str().unwrap(),
    ]);
    let said = String::from_utf8_lossy(&o.stdout);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(
        said.contains("(topic `/landmarks`): ")
            && said.contains("`L3`, `L4`, `L5` left out: not in the map")
            && said.contains("(the first at topic `/landmarks` message"),
        "{said}"
    );
    std::fs::write(map, "id,x,y\nM1,3,2\n").unwrap();
    let e = fails(array, &std::fs::read_to_string(ta).unwrap(), true);
    assert!(
        e.contains("no sighting's landmark is in the map: `L1`, `L2`, `L3`")
            && e.contains("topic `/landmarks` message"),
        "{e}"
    );
}

/// Issue #68: a velocity-commanded robot's bag has no wheel joints, only
/// the commands it was sent on `/cmd_vel`. Its input columns read a
/// `Twist`'s (unstamped: timed by the bag's receive time) or a
/// `TwistStamped`'s components, and calibrate as the CSV does; a mapping
/// that names no component, or one a Twist lacks, is refused at its place.
#[test]
fn velocity_commands_are_read_from_cmd_vel() {
    let tmp = tempfile::tempdir().unwrap();
    // the MRCLAM robots' spec as a user writes it (its camera unused here)
    let spec = commanded_spec(tmp.path(), "");
    let s = spec.to_str().unwrap();
    let csv = Sim::new(s)
        .sets(&["k_v=1.06", "k_w=0.93"])
        .drive("random", 5, 1)
        .write(tmp.path(), "commanded.csv");
    let topics = tmp.path().join("topics.toml");
    std::fs::write(
        &topics,
        "[inputs]\nv = { topic = \"/cmd_vel\", field = \"linear.x\" }\nomega = { topic = \"/cmd_vel\", field = \"angular.z\" }\n",
    )
    .unwrap();
    let fit = |data: &Path, map: Option<&Path>| {
        let mut a = vec!["fit", "--spec", s, "--data", data.to_str().unwrap()];
        if let Some(m) = map {
            a.extend(["--topics", m.to_str().unwrap()]);
        }
        estimates(&kinegen_json(&a))
    };
    let from_csv = fit(&csv, None);
    assert!(
        (from_csv[0].1 - 1.06).abs() < 0.01 && (from_csv[1].1 - 0.93).abs() < 0.01,
        "{from_csv:?}"
    );
    for kind in ["twist", "stamped"] {
        let extra = [
            "--joints",
            "none",
            "--imu",
            "none",
            "--cmd-vel",
            "v,omega",
            "--cmd-vel-type",
            kind,
        ];
        let b = bag(tmp.path(), &csv, &format!("cmd_{kind}"), &extra);
        let from_bag = fit(&b, Some(&topics));
        for ((n, c), (_, b)) in from_csv.iter().zip(&from_bag) {
            assert!(((c - b) / c).abs() < 1e-6, "{kind}: {n}: CSV {c} bag {b}");
        }
    }
    // mistakes: no component named; a component a Twist lacks; a joint's
    // topic; a joint named on a Twist (it would be ignored, not read)
    let b = tmp.path().join("cmd_twist");
    let refused = |text: &str, says: &[&str]| {
        let m = tmp.path().join("bad_topics.toml");
        std::fs::write(&m, text).unwrap();
        let a = [
            "compare",
            "--spec",
            s,
            "--data",
            b.to_str().unwrap(),
            "--topics",
            m.to_str().unwrap(),
        ];
        let o = kinegen(&a);
        let e = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{text}: {e}");
        for w in says {
            assert!(e.contains(w), "{text}: `{w}` not in: {e}");
        }
    };
    refused(
        "[inputs]\nv = { topic = \"/cmd_vel\" }\nomega = { topic = \"/cmd_vel\", field = \"angular.z\" }\n",
        &["input column `v`", "`/cmd_vel`", "field = \"linear.x\""],
    );
    refused(
        "[inputs]\nv = { topic = \"/cmd_vel\", field = \"angular.x\" }\n",
        &["bad_topics.toml:2", "linear.x"],
    );
    refused(
        "[inputs]\nv = { topic = \"/mocap/pose\", field = \"linear.x\" }\nomega = { topic = \"/cmd_vel\", field = \"angular.z\" }\n",
        &["`/mocap/pose` carries geometry_msgs/msg/PoseStamped", "JointState or geometry_msgs/msg/Twist"],
    );
    refused(
        "[inputs]\nv = { topic = \"/cmd_vel\", joint = \"left_wheel\", field = \"linear.x\" }\nomega = { topic = \"/cmd_vel\", field = \"angular.z\" }\n",
        &["input column `v`", "`/cmd_vel`", "has no joints", "not a `joint`"],
    );
}
