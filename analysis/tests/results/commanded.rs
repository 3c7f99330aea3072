//! Issue #34's velocity-commanded robot (`commanded_spec`, a spec as its
//! user writes it), asserted on the library's values: its timing effects
//! (a late command, a command lag, a deadband) named and calibrated, the
//! filter's noise as a density independent of the log's rate, the filter's
//! consistency counted against a ground truth with noise of its own.
//! tests/velocity_commands.rs keeps what only the command has (the real
//! robots' runs with their text, refusals, warnings, reports).

use crate::scenarios::*;
use kinegen_analysis::applications::localize::{Consistency, EkfOptions, Localization, Summary};
use kinegen_analysis::applications::localize_request::LocalizedFiles;
use kinegen_analysis::diagnosis::diagnose::Diagnosis;
use kinegen_analysis::diagnosis::ranking::Candidate;
use std::path::Path;

/// The landmark map the commanded robot's camera sights in these tests.
fn beacons() -> std::path::PathBuf {
    spec("data/beacons.csv")
}

fn candidate<'d>(d: &'d Diagnosis, effect: &str) -> &'d Candidate {
    (d.candidates.iter().find(|c| c.effect == effect))
        .unwrap_or_else(|| panic!("{effect} is a candidate"))
}

/// The first (only) run's filter output and figures.
fn first_run(l: &LocalizedFiles) -> &(Localization, Summary) {
    &l.localized.runs[0]
}

/// `log` and its sightings `obs` of the beacons, localised against `spec`.
fn localize_seen(spec: &Path, log: &Path, obs: &Path, options: EkfOptions) -> LocalizedFiles {
    let map = beacons();
    let logs = Logs {
        data: &[log],
        observations: &[obs],
        landmarks: Some(&map),
        ..Logs::default()
    };
    localized(spec.to_str().unwrap(), &logs, options)
}

/// Issue #34 / CONTRACT section 3: `input_delay`, the robot executing its
/// commands late. A commanded robot simulated with a 0.3 s delay: diagnose
/// names it first (its estimate within 0.005 s) or says that these
/// pose-only logs cannot tell it apart from what it names (a late motion
/// capture moves the track alike); with landmark sightings the two differ
/// and the fit of the spec with the effect recovers the delay from the
/// sightings alone. A robot without commands (encoders only) does not get
/// the candidate (a late measured input is `time_offset`).
#[test]
fn a_late_command_is_named_and_calibrated() {
    let tmp = tempfile::tempdir().unwrap();
    let commanded = commanded_spec(tmp.path(), "");
    let s = commanded.to_str().unwrap();
    let log = Sim::new(s)
        .effects(&["input_delay=0.3"])
        .drive("random", 3, 1)
        .write(tmp.path(), "late.csv");
    let d = diagnosis(s, &[&log]);
    let first = &d.chain[0];
    assert!(
        first.effect == "input_delay" || first.equivalent.iter().any(|e| e == "input_delay"),
        "{}, equivalent {:?}",
        first.effect,
        first.equivalent
    );
    let tau = candidate(&d, "input_delay").parameters["input_delay"].estimate;
    assert!((tau - 0.3).abs() < 0.005, "{tau}");
    // with landmarks only, the delay shows in the sightings
    let delayed = with_effect(
        &commanded,
        "input_delay",
        &[],
        &tmp.path().join("delayed.toml"),
    );
    let delayed = delayed.to_str().unwrap();
    let map = beacons();
    let (seen, obs) = Sim::new(delayed)
        .sets(&["input_delay=0.3"])
        .drive("random", 4, 1)
        .sighting(&map)
        .write_sighted(tmp.path(), "lm.csv");
    let logs = Logs {
        data: &[&seen],
        observations: &[&obs],
        landmarks: Some(&map),
        ..Logs::default()
    };
    let l = load_logs(delayed, &logs);
    let landmarks_only = kinegen_analysis::estimation::fit::FitOptions {
        use_pose: false,
        use_gyro: false,
        sightings_from_truth: false,
        ..kinegen_analysis::estimation::fit::FitOptions::command_default()
    };
    let c = calibrated_with(&l, &landmarks_only);
    let (est, sd) = estimate(&c, &l, "input_delay");
    assert!(
        (est - 0.3).abs() < 0.05 && (est - 0.3).abs() < 4.0 * sd.max(1e-3),
        "{est} ± {sd}"
    );
    let encoders = diagnosis("spec/diff_drive.toml", &[&spec("data/mystery_robot.csv")]);
    assert!(
        !encoders
            .candidates
            .iter()
            .any(|c| c.effect == "input_delay"),
        "an encoder robot got the input_delay candidate"
    );
}

/// A spec that already has the robot's input delay leaves only noise: the
/// residuals diagnose searches for structure (and plots an effect's
/// signature with) are those of the commands as the robot executed them.
/// Before, they were the logged commands, and the right model of a robot
/// 0.3 s late was reported with periodic heading residuals (74% of their
/// variance) that its own delay explains.
#[test]
fn a_model_with_its_input_delay_leaves_no_structure() {
    let tmp = tempfile::tempdir().unwrap();
    let commanded = commanded_spec(tmp.path(), "");
    let log = Sim::new(commanded.to_str().unwrap())
        .effects(&["input_delay=0.3"])
        .drive("random", 4, 1)
        .write(tmp.path(), "late.csv");
    let delayed = tmp.path().join("delayed.toml");
    with_effect(&commanded, "input_delay", &[("input_delay", 0.3)], &delayed);
    let d = diagnosis(delayed.to_str().unwrap(), &[&log]);
    assert!(d.chain.is_empty(), "{:?}", d.verdict());
    assert!(!d.structure.structured, "{:?}", d.structure.findings);
}

/// Issue #34: a robot that does not follow small commands. A commanded
/// robot simulated with a deadband of 0.03 m/s and 0.08 rad/s: diagnose
/// names `command_deadband` first and estimates both widths within 5%; on
/// the same robot without one it names nothing and the widths stay at 0
/// within their standard deviations. The kink at d = 0 has a slope (sign(0)
/// = 0): with the derivative of |x| as x/|x| the Jacobians are NaN at the
/// stopped robot's command 0 and the fit cannot start.
#[test]
fn a_command_deadband_is_named_and_calibrated() {
    let tmp = tempfile::tempdir().unwrap();
    let commanded = commanded_spec(tmp.path(), "");
    let s = commanded.to_str().unwrap();
    let widths = ["deadband_v_cmd", "deadband_w_cmd"];
    let log = Sim::new(s)
        .effects(&[
            "command_deadband.deadband_v_cmd=0.03",
            "command_deadband.deadband_w_cmd=0.08",
        ])
        .drive("random", 3, 1)
        .write(tmp.path(), "deadband.csv");
    let d = diagnosis(s, &[&log]);
    assert_eq!(d.verdict(), Some("command_deadband"));
    for (p, truth) in widths.iter().zip([0.03, 0.08]) {
        let est = candidate(&d, "command_deadband").parameters[*p].estimate;
        assert!((est - truth).abs() < 0.05 * truth, "{p}: {est} for {truth}");
    }
    let clean = Sim::new(s)
        .drive("random", 3, 1)
        .write(tmp.path(), "clean.csv");
    let d = diagnosis(s, &[&clean]);
    assert!(d.chain.is_empty(), "{:?}", d.verdict());
    for p in widths {
        let e = &candidate(&d, "command_deadband").parameters[p];
        assert!(
            e.estimate.abs() < 4.0 * e.std.max(1e-6),
            "{p}: {} ± {}",
            e.estimate,
            e.std
        );
    }
}

/// Issue #34: a robot that reaches its commands through a first-order
/// response (a motor controller, acceleration limits), which the MRCLAM
/// robots show against Vicon (their turn rate follows the commands with a
/// time constant of 0.1-0.3 s at a gain near 1). A commanded robot
/// simulated with a 0.3 s time constant: diagnose names `command_lag`
/// first, with the time constant within 0.01 s, and not the pure delay
/// (which fits it six times worse); the fit of the spec with the effect
/// finds it too.
#[test]
fn a_command_lag_is_named_and_calibrated() {
    let tmp = tempfile::tempdir().unwrap();
    let commanded = commanded_spec(tmp.path(), "");
    let s = commanded.to_str().unwrap();
    let log = Sim::new(s)
        .effects(&["command_lag=0.3"])
        .drive("random", 5, 1)
        .write(tmp.path(), "lag.csv");
    let d = diagnosis(s, &[&log]);
    assert_eq!(d.verdict(), Some("command_lag"));
    let tau = d.chain[0].parameters["command_lag"].estimate;
    assert!((tau - 0.3).abs() < 0.01, "{tau}");
    let rmse = |name: &str| candidate(&d, name).rmse;
    assert!(rmse("input_delay") > 3.0 * rmse("command_lag"));
    let lagged = tmp.path().join("lagged.toml");
    with_effect(&commanded, "command_lag", &[], &lagged);
    let l = load(lagged.to_str().unwrap(), &[], &[&log], &[]);
    let (est, sd) = estimate(&calibrated(&l), &l, "command_lag");
    assert!(
        (est - 0.3).abs() < 0.01 && (est - 0.3).abs() < 4.0 * sd.max(1e-4),
        "{est} ± {sd}"
    );
}

/// Issue #34: localize estimates a declared input delay with the noise,
/// from the sightings alone. A commanded robot simulated with a 0.3 s delay,
/// its spec carrying `input_delay` at 0 (as add-effect adds it): the filter
/// finds the delay within 0.05 s, says so, and tracks better than with the
/// spec's 0 fixed by --set (which it then keeps, and says nothing about).
#[test]
fn localize_estimates_a_declared_input_delay_from_the_sightings() {
    localize_estimates_a_declared_timing("input_delay", 0.05);
}

/// The same for a command the robot follows with a 0.3 s time constant
/// (`command_lag`): the lag is estimated like the delay.
#[test]
fn localize_estimates_a_declared_command_lag_from_the_sightings() {
    localize_estimates_a_declared_timing("command_lag", 0.05);
}

/// Simulate the commanded robot with `effect` at 0.3 s, localize it with
/// the effect declared at 0: estimated within `within` s, and better than
/// 0 fixed by --set.
fn localize_estimates_a_declared_timing(effect: &str, within: f64) {
    let tmp = tempfile::tempdir().unwrap();
    let commanded = commanded_spec(tmp.path(), "m/s/sqrt(Hz)");
    let timed = with_effect(&commanded, effect, &[], &tmp.path().join("timed.toml"));
    let timed = timed.to_str().unwrap();
    let truth = format!("{effect}=0.3");
    let map = beacons();
    let (log, obs) = Sim::new(timed)
        .sets(&[&truth])
        .drive("random", 5, 1)
        .sighting(&map)
        .write_sighted(tmp.path(), "late.csv");
    let localize = |sets: &[&str]| {
        let logs = Logs {
            sets,
            data: &[&log],
            observations: &[&obs],
            landmarks: Some(&map),
            ..Logs::default()
        };
        localized(timed, &logs, filter_options(false))
    };
    let estimated = localize(&[]);
    let found = &estimated.localized.timing;
    let d = found.iter().find(|d| d.name == effect).expect("estimated");
    assert!(
        (d.estimate_s - 0.3).abs() < within,
        "estimated {effect} {}",
        d.estimate_s
    );
    assert_eq!(d.spec_s, 0.0);
    let zero = format!("{effect}=0");
    let fixed = localize(&[&zero]);
    assert!(
        fixed.localized.timing.is_empty(),
        "--set fixes the {effect}"
    );
    let rmse = |l: &LocalizedFiles| first_run(l).1.rmse.unwrap();
    assert!(
        rmse(&estimated) < rmse(&fixed),
        "with the {effect} estimated {} m, with 0 s {} m",
        rmse(&estimated),
        rmse(&fixed)
    );
}

/// NEES compares the filter with a ground truth that has noise of its own:
/// the simulator's motion capture adds 1 mm and 2 mrad. A robot whose model
/// is exact, seen by many landmarks, is localised to about a millimetre, and
/// against the raw truth read as overconfident (mean NEES 16 of 3). The
/// truth's noise, estimated from its third differences, is counted.
#[test]
fn nees_counts_the_ground_truths_own_noise() {
    let tmp = tempfile::tempdir().unwrap();
    let commanded = commanded_spec(tmp.path(), "m/s/sqrt(Hz)");
    let map = beacons();
    let (log, obs) = Sim::new(commanded.to_str().unwrap())
        .drive("random", 2, 1)
        .sighting(&map)
        .write_sighted(tmp.path(), "exact.csv");
    let l = localize_seen(&commanded, &log, &obs, filter_options(false));
    let (_, s) = first_run(&l);
    let [pos, _, heading] = s.truth_noise.unwrap();
    assert!((pos / 0.001 - 1.0).abs() < 0.3, "{pos}");
    assert!((heading / 0.002 - 1.0).abs() < 0.3, "{heading}");
    let nees = s.nees.unwrap();
    assert!(
        (1.5..4.5).contains(&nees),
        "mean NEES {nees} (3 if consistent)"
    );
    // spread as chi-square's: medians near its, and NIS and NEES agree
    for (key, spread) in [("NIS", s.nis_spread), ("NEES", s.nees_spread)] {
        let x = spread.unwrap();
        let ratio = x.median / x.chi2_median;
        assert!(
            (0.5..2.0).contains(&ratio),
            "{key}: median {} against {}",
            x.median,
            x.chi2_median
        );
    }
    assert!(matches!(s.consistency(), Some(Consistency::Agree)));
    // the gate rejects no more than a consistent filter does by chance
    assert!(!s.gate_tail.unwrap().overconfident());
    // each of the pose's parts against its own marginal: near its degrees
    // of freedom (position 2, heading 1)
    let parts = s.nees_parts.unwrap();
    for (key, mean, dof) in [
        ("position", parts.position.0, 2.0),
        ("heading", parts.heading.0, 1.0),
    ] {
        let ratio = mean / dof;
        assert!((0.5..1.5).contains(&ratio), "{key}: {mean}");
    }
}

/// The same log at twice its rate: a row between every two, its commands
/// held from the row before (what the robot executed), its ground truth
/// interpolated (the heading along the shorter arc).
fn doubled(log: &Path, out: &Path) {
    let text = std::fs::read_to_string(log).unwrap();
    let mut lines = text.lines();
    let header = lines.next().unwrap();
    let cols: Vec<&str> = header.split(',').collect();
    let rows: Vec<Vec<f64>> = lines
        .map(|l| l.split(',').map(|c| c.parse().unwrap()).collect())
        .collect();
    let held: Vec<bool> = cols.iter().map(|c| ["v", "omega"].contains(c)).collect();
    let mut s = format!("{header}\n");
    let fmt = |r: &[f64]| {
        r.iter()
            .map(|v| format!("{v:.12}"))
            .collect::<Vec<_>>()
            .join(",")
    };
    for w in rows.windows(2) {
        s += &(fmt(&w[0]) + "\n");
        let mid: Vec<f64> = (0..cols.len())
            .map(|i| {
                if held[i] {
                    w[0][i]
                } else if cols[i] == "gt_theta" {
                    let d = (w[1][i] - w[0][i] + std::f64::consts::PI)
                        .rem_euclid(std::f64::consts::TAU)
                        - std::f64::consts::PI;
                    w[0][i] + d / 2.0
                } else {
                    (w[0][i] + w[1][i]) / 2.0
                }
            })
            .collect();
        s += &(fmt(&mid) + "\n");
    }
    s += &(fmt(rows.last().unwrap()) + "\n");
    std::fs::write(out, s).unwrap();
}

/// Process noise given per second (a density) gives the same filter on a log
/// and on the same log at twice its rate: the same track error and the same
/// final uncertainty. Seed 001's per-row sigma does not (the check fails
/// with it: half the variance at twice the rate).
#[test]
fn process_noise_per_second_gives_the_same_filter_at_twice_the_rate() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let map = dir.join("map.csv");
    std::fs::write(&map, "id,x,y\nA,6,1\nB,-5,4\nC,2,-7\nD,-3,-5\n").unwrap();
    let density = commanded_spec(dir, "m/s/sqrt(Hz)");
    let per_row = commanded_spec(dir, "");
    let (log, obs) = Sim::new(density.to_str().unwrap())
        .sets(&["k_v=1.05"])
        .drive("random", 3, 1)
        .sighting(&map)
        .write_sighted(dir, "log.csv");
    let fast = dir.join("fast.csv");
    doubled(&log, &fast);
    let filter = |spec: &Path, data: &Path| {
        let logs = Logs {
            data: &[data],
            observations: &[&obs],
            landmarks: Some(&map),
            ..Logs::default()
        };
        let l = localized(spec.to_str().unwrap(), &logs, filter_options(true));
        let (loc, s) = first_run(&l);
        let last = loc.cov.last().unwrap();
        let std = [0, 1, 2].map(|i| last[(i, i)].sqrt());
        (s.rmse.unwrap(), std)
    };
    let (slow_rmse, slow_std) = filter(&density, &log);
    let (fast_rmse, fast_std) = filter(&density, &fast);
    assert!(
        (fast_rmse / slow_rmse - 1.0).abs() < 0.02,
        "density noise: RMSE {slow_rmse} at the log's rate, {fast_rmse} at twice it"
    );
    for i in 0..3 {
        assert!(
            (fast_std[i] / slow_std[i] - 1.0).abs() < 0.02,
            "density noise: final sd {slow_std:?} at the log's rate, {fast_std:?} at twice it"
        );
    }
    // the per-row form is not rate-independent, which the check above sees
    let (_, slow_std) = filter(&per_row, &log);
    let (_, fast_std) = filter(&per_row, &fast);
    assert!(
        (0..3).any(|i| (fast_std[i] / slow_std[i] - 1.0).abs() > 0.1),
        "per-row noise should change with the rate: {slow_std:?} vs {fast_std:?}"
    );
}
