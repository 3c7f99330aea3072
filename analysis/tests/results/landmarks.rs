//! Range-bearing landmarks (CONTRACT section 2), asserted on the library's
//! values: calibration and diagnosis from the sightings alone (no ground
//! truth), and the filter's estimate of a camera's errors (persistent per
//! landmark, shared by a frame) from its innovations. tests/landmarks.rs
//! keeps what only the command has (bad files, refusals, the text, the
//! report, the track file).

use crate::scenarios::*;
use kinegen_analysis::applications::localize_request::LocalizedFiles;
use std::path::{Path, PathBuf};

const MAP: &str = "id,x,y\nL1,3,2\nL2,-1,4\nL3,5,-2\nL4,0,-3\nL5,2,6\n";

/// The same log without its ground-truth columns (`gt_*`, or the skid-steer
/// spec's `body_*`), written beside it as `nogt.csv`.
fn without_ground_truth(log: &Path) -> PathBuf {
    let text = std::fs::read_to_string(log).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let keep: Vec<usize> = (0..header.len())
        .filter(|&i| !header[i].starts_with("gt_") && !header[i].starts_with("body_"))
        .collect();
    let pick = |l: &str| {
        let cells: Vec<&str> = l.split(',').collect();
        keep.iter().map(|&i| cells[i]).collect::<Vec<_>>().join(",")
    };
    let mut s = pick(&header.join(",")) + "\n";
    for l in lines {
        s += &(pick(l) + "\n");
    }
    let out = log.with_file_name("nogt.csv");
    std::fs::write(&out, s).unwrap();
    out
}

/// `log` without its ground truth, with its sightings `obs` of `map`.
fn sightings_alone<'a>(nogt: &'a [&'a Path; 1], obs: &'a [&'a Path; 1], map: &'a Path) -> Logs<'a> {
    Logs {
        data: nogt,
        observations: obs,
        landmarks: Some(map),
        ..Logs::default()
    }
}

#[test]
fn landmarks_alone_calibrate_the_wheelbase() {
    let tmp = tempfile::tempdir().unwrap();
    let map = tmp.path().join("map.csv");
    std::fs::write(&map, MAP).unwrap();
    let (log, obs) = Sim::new("spec/diff_drive.toml")
        .sets(&["b=0.205", "r_l=0.0418"])
        .drive("random", 4, 1)
        .sighting(&map)
        .write_sighted(tmp.path(), "lm.csv");
    let nogt = without_ground_truth(&log);
    let l = load_logs(
        "spec/diff_drive.toml",
        &sightings_alone(&[&nogt], &[&obs], &map),
    );
    let c = calibrated(&l);
    let (b, _) = estimate(&c, &l, "b");
    assert!((b - 0.205).abs() / 0.205 < 0.005, "b = {b}");
    let range = |e: &kinegen_analysis::model_on_log::evaluation::Evaluation| {
        e.landmarks.as_ref().unwrap().range_rmse_m
    };
    let (before, after) = (range(&c.before), range(&c.after));
    assert!(
        after * 5.0 < before,
        "range innovations fell only from {before} to {after}"
    );
    // after calibration the innovations are at the sensor noise of the spec (0.05 m)
    assert!(after < 0.07, "{after}");
}

/// Without a ground truth, diagnose holds out the last 40% of the sightings,
/// not of the rows: a robot that sees its landmarks only in the first quarter
/// of its log (a tour that leaves the mapped area) had a held-out part with
/// no sighting in it, and no effect could be significant however clear (a
/// 0.03 rad toe, estimated to 1%, the error 60% lower: "no catalogue effect
/// is significant"). What takes a ground truth (the model's own step) is
/// said not to be measured.
#[test]
fn landmarks_alone_name_an_effect_seen_only_early_in_the_log() {
    let tmp = tempfile::tempdir().unwrap();
    let map = spec("data/beacons.csv");
    let (log, obs) = Sim::new("spec/diff_drive.toml")
        .effects(&["wheel_misalignment=0.03"])
        .drive("random", 6, 3)
        .sighting(&map)
        .write_sighted(tmp.path(), "toed.csv");
    // the sightings end a quarter of the way through the log
    let last_time = |f: &Path| -> f64 {
        let text = std::fs::read_to_string(f).unwrap();
        let last = text.lines().last().unwrap();
        last.split(',').next().unwrap().parse().unwrap()
    };
    let (last_sighting, last_row) = (last_time(&obs), last_time(&log));
    assert!(
        last_sighting < 0.4 * last_row,
        "{last_sighting} of {last_row} s"
    );
    let nogt = without_ground_truth(&log);
    let (data, observations) = ([nogt.as_path()], [obs.as_path()]);
    let logs = sightings_alone(&data, &observations, &map);
    let d = diagnosed("spec/diff_drive.toml", &logs, &[])
        .outcome
        .diagnosis;
    assert_eq!(d.verdict(), Some("wheel_misalignment"));
    // the held-out part has sightings to score
    assert!(
        d.base_holdout_rmse > 0.5,
        "held-out error {}",
        d.base_holdout_rmse
    );
    assert!(!d.discretisation.measured);
}

/// A user's robot whose lidar sits 0.35 m ahead of the body origin, and no
/// ground truth: the start pose comes from the landmarks seen at the start
/// through the spec's own observation (offset included), so calibration from
/// landmarks alone finds the wheel radius, the track and the offset, and the
/// innovations fall to the sensor noise (0.03 m). With the start pose of a
/// sensor at the origin, the fit stopped at 0.20 m with the radius 7% off.
#[test]
fn an_offset_sensor_calibrates_from_landmarks_alone() {
    let tmp = tempfile::tempdir().unwrap();
    let t = tmp.path();
    let lidar = t.join("my_skid.toml");
    let mut text = std::fs::read_to_string(spec("tests/user_specs/skid4.toml")).unwrap();
    text += r#"
[[parameter]]
name = "lidar_dx"
nominal = 0.0
unit = "m"
min = -1.0
max = 1.0

[[observation]]
name = "reflectors"
landmark = true
columns = ["range", "bearing"]
expr = ["sqrt((xl - x - lidar_dx*cos(theta))^2 + (yl - y - lidar_dx*sin(theta))^2)", "atan2(yl - y - lidar_dx*sin(theta), xl - x - lidar_dx*cos(theta)) - theta"]
angle = [false, true]
sigma = [0.03, 0.01]
"#;
    std::fs::write(&lidar, text).unwrap();
    let map = t.join("reflectors.csv");
    std::fs::write(&map, "id,x,y\nR1,4,3\nR2,-2,5\nR3,6,-3\nR4,0,-4\nR5,3,7\n").unwrap();
    let lidar = lidar.to_str().unwrap();
    let (log, obs) = Sim::new(lidar)
        .sets(&["lidar_dx=0.35", "track=0.6"])
        .drive("random", 2, 1)
        .sighting(&map)
        .write_sighted(t, "drive.csv");
    let nogt = without_ground_truth(&log);
    let l = load_logs(lidar, &sightings_alone(&[&nogt], &[&obs], &map));
    let c = calibrated(&l);
    let est = |n: &str| estimate(&c, &l, n).0;
    assert!(
        (est("radius") / 0.08 - 1.0).abs() < 0.005,
        "radius {}",
        est("radius")
    );
    assert!(
        (est("track") / 0.6 - 1.0).abs() < 0.005,
        "track {}",
        est("track")
    );
    assert!(
        (est("lidar_dx") - 0.35).abs() < 0.01,
        "lidar_dx {}",
        est("lidar_dx")
    );
    let after = c.after.landmarks.as_ref().unwrap().range_rmse_m;
    assert!(
        after < 0.035,
        "range innovations {after} m for 0.03 m of noise"
    );
}

/// The unicycle touring the landmarks of `map` (the `beacons` trajectory,
/// `laps` laps) with a camera sighting each twice a second within `reach`
/// m, driving `sets`; the log and its sightings in `dir`.
fn beacon_tour(
    dir: &Path,
    map: &Path,
    (laps, reach): (usize, f64),
    sets: &[&str],
) -> (PathBuf, PathBuf) {
    Sim::new("spec/unicycle_ekf.toml")
        .sets(sets)
        .drive("beacons", 1, laps)
        .sighting(map)
        .camera(2.0, reach)
        .write_sighted(dir, "run.csv")
}

/// `kinegen localize` of the unicycle's `log` with its sightings `obs` of
/// `map`, the noise estimated.
fn localize_tour(log: &Path, obs: &Path, map: &Path) -> LocalizedFiles {
    let logs = Logs {
        data: &[log],
        observations: &[obs],
        landmarks: Some(map),
        ..Logs::default()
    };
    localized("spec/unicycle_ekf.toml", &logs, filter_options(false))
}

/// The persistent range error [`add_persistent_range_errors`] adds per metre.
const RANGE_ERROR_PER_M: f64 = 0.04;

/// Check that localize found the persistent range error of
/// [`RANGE_ERROR_PER_M`] and is consistent with its sightings; the position
/// RMSE.
fn persistent_range_error_found(l: &LocalizedFiles) -> f64 {
    let fraction = RANGE_ERROR_PER_M;
    // the spec's range sigma is 0.05 m: the persistent part per metre of range
    let per_m = 0.05 * l.localized.noise.persistent.factor[0];
    let (_, s) = &l.localized.runs[0];
    let (nis, b) = (s.nis.unwrap(), s.nis_bounds.unwrap());
    eprintln!("persistent range error {per_m:.4} per m (true {fraction}), NIS {nis:.2}");
    assert!(
        (0.5 * fraction..2.0 * fraction).contains(&per_m),
        "persistent range error {per_m} per m, true {fraction}"
    );
    // consistent with its sightings (the ground truth's own noise makes NEES
    // meaningless at the millimetre errors of a simulated robot)
    assert!(nis > b.lo && nis < b.hi, "NIS {nis} [{}, {}]", b.lo, b.hi);
    s.rmse.unwrap()
}

/// A camera whose range error is persistent (per landmark, changing over
/// seconds) and grows with the range, as the MRCLAM robots' cameras do:
/// 4% of the range, a 3 s time constant, on top of the spec's white 5 cm.
/// With the noise estimated from the sightings alone, the filter finds the
/// persistent part per metre of range near the truth, and stays consistent.
/// (A filter that carried the error as a constant, or the estimate wired to
/// the wrong Jacobian, finds it several times too large and is overconfident.)
#[test]
fn a_range_error_that_grows_with_the_range_is_estimated_per_metre() {
    let tmp = tempfile::tempdir().unwrap();
    let map = landmark_map(tmp.path(), &SIX_LANDMARKS);
    let (log, obs) = beacon_tour(tmp.path(), &map, (3, 10.0), &[]);
    add_persistent_range_errors(&obs, RANGE_ERROR_PER_M, 3.0);
    let rmse = persistent_range_error_found(&localize_tour(&log, &obs, &map));
    eprintln!("RMSE {rmse:.4} m");
}

/// A map of more landmarks than the filter carries persistent errors for
/// (`localize::active`: the most recently sighted 24) along a tour that
/// passes them in turn: those let go restart from their prior when sighted
/// again, and the filter stays as good as the six-landmark case above
/// (persistent error found, NIS within its bounds, the drift of a robot 5%
/// faster than its spec divided).
#[test]
fn a_map_larger_than_the_errors_carried_still_localises() {
    let tmp = tempfile::tempdir().unwrap();
    let ring: Vec<(f64, f64)> = (0..40)
        .map(|k| {
            let a = k as f64 * std::f64::consts::TAU / 40.0;
            (7.0 * a.cos(), 7.0 * a.sin())
        })
        .collect();
    let map = landmark_map(tmp.path(), &ring);
    // sighted only within 4 m, by a robot 5% faster than its spec (dead
    // reckoning drifts)
    let (log, obs) = beacon_tour(tmp.path(), &map, (1, 4.0), &["v_scale=1.05"]);
    add_persistent_range_errors(&obs, RANGE_ERROR_PER_M, 3.0);
    let l = localize_tour(&log, &obs, &map);
    let rmse = persistent_range_error_found(&l);
    let (loc, s) = &l.localized.runs[0];
    let dr = s.dead_reckoning.unwrap();
    let (used, rejected) = (loc.accepted as f64, loc.rejected as f64);
    eprintln!("RMSE {rmse:.4} m (dead reckoning {dr:.4}), {used} used, {rejected} rejected");
    assert!(
        used >= 0.97 * (used + rejected),
        "{used} used, {rejected} rejected"
    );
    assert!(rmse < 0.5 * dr, "RMSE {rmse} against dead reckoning {dr}");
}

/// A camera whose error every landmark in a frame shares (it tilts, it
/// rocks: the MRCLAM robots' bearing errors of two landmarks in one frame
/// correlate 0.68-0.87 against Vicon): a bearing error of 30 mrad common to
/// all sightings at one time, changing over 5 s, beside the spec's white
/// 20 mrad. The filter finds it as the shared part, near its size, is
/// consistent with its sightings, and tracks to 6 mm. (Without the shared
/// part, the likelihood spreads it over each landmark's own error, and the
/// track is 4.4 times worse: 25 mm.)
#[test]
fn a_camera_error_every_landmark_shares_is_estimated_once() {
    let tmp = tempfile::tempdir().unwrap();
    let map = landmark_map(tmp.path(), &SIX_LANDMARKS);
    let (log, obs) = beacon_tour(tmp.path(), &map, (3, 10.0), &[]);
    add_shared_bearing_errors(&obs, SHARED_BEARING_ERROR, 5.0);
    let l = localize_tour(&log, &obs, &map);
    // the spec's bearing sigma is 0.02 rad
    let shared = 0.02 * l.localized.noise.shared.factor[1];
    let (_, s) = &l.localized.runs[0];
    let (nis, b, rmse) = (s.nis.unwrap(), s.nis_bounds.unwrap(), s.rmse.unwrap());
    eprintln!(
        "shared bearing error {shared:.4} rad (true {SHARED_BEARING_ERROR}), NIS {nis:.2} [{}, {}], RMSE {rmse:.4} m",
        b.lo, b.hi
    );
    assert!(
        (0.5 * SHARED_BEARING_ERROR..2.0 * SHARED_BEARING_ERROR).contains(&shared),
        "shared bearing error {shared}, true {SHARED_BEARING_ERROR}"
    );
    assert!(nis > b.lo && nis < b.hi, "NIS {nis} [{}, {}]", b.lo, b.hi);
    assert!(rmse < 0.012, "RMSE {rmse} m");
}

/// The shared bearing error [`add_shared_bearing_errors`] adds (rad).
const SHARED_BEARING_ERROR: f64 = 0.03;

/// Scale each sighting's range in `obs` by 1 + e, with e a first-order
/// Gauss-Markov error per landmark (stationary sd `fraction`, time constant
/// `memory` s): a camera that ranges by a target's apparent size.
fn add_persistent_range_errors(obs: &Path, fraction: f64, memory: f64) {
    let by_landmark = |f: &[String]| f[1].clone();
    add_gauss_markov_errors(obs, (fraction, memory, 11), by_landmark, |f, e| {
        let range: f64 = f[2].parse().unwrap();
        f[2] = format!("{}", range * (1.0 + e));
    });
}

/// Add to every bearing in `obs` an error e common to all sightings at one
/// time, a first-order Gauss-Markov process (stationary sd `sd`, time
/// constant `memory` s).
fn add_shared_bearing_errors(obs: &Path, sd: f64, memory: f64) {
    add_gauss_markov_errors(
        obs,
        (sd, memory, 12),
        |_| String::new(),
        |f, e| {
            let bearing: f64 = f[3].parse().unwrap();
            f[3] = format!("{}", bearing + e);
        },
    );
}

/// Rewrite each sighting of `obs` by `apply(fields, e)`, with e the value
/// at its time of a first-order Gauss-Markov process (stationary sd, time
/// constant in s, random seed: `process`), one process for each `key` of
/// the sighting's fields.
fn add_gauss_markov_errors(
    obs: &Path,
    (sd, memory, seed): (f64, f64, u64),
    key: impl Fn(&[String]) -> String,
    apply: impl Fn(&mut [String], f64),
) {
    use rand::{Rng, SeedableRng};
    use rand_distr::StandardNormal;
    let mut rng = rand::rngs::SmallRng::seed_from_u64(seed);
    let mut error: std::collections::HashMap<String, (f64, f64)> = Default::default();
    let text = std::fs::read_to_string(obs).unwrap();
    let mut out = String::new();
    for (i, line) in text.lines().enumerate() {
        if i == 0 {
            out += line;
            out += "\n";
            continue;
        }
        let mut f: Vec<String> = line.split(',').map(String::from).collect();
        let t: f64 = f[0].parse().unwrap();
        let e = error
            .entry(key(&f))
            .or_insert_with(|| (t, sd * rng.sample::<f64, _>(StandardNormal)));
        let phi = (-(t - e.0) / memory).exp();
        let kick: f64 = rng.sample(StandardNormal);
        *e = (t, phi * e.1 + sd * (1.0 - phi * phi).sqrt() * kick);
        apply(&mut f, e.1);
        out += &f.join(",");
        out += "\n";
    }
    std::fs::write(obs, out).unwrap();
}
