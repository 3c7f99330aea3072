//! The calibration's results, asserted on the library's values: what `kinegen
//! fit` computes, on the logs `kinegen simulate` writes (and on the real
//! ones where they are present). tests/calibration.rs keeps what only the
//! command has: options, exit codes, the JSON's shape, files written.

use crate::scenarios::*;
use kinegen_analysis::estimation::fit::{FitOptions, Likelihood};
use kinegen_analysis::estimation::fit_job::{compare_methods, MethodsJob, MethodsOutcome};
use kinegen_analysis::estimation::methods::{MethodChoice, Settings};
use kinegen_analysis::model_on_log::load::Loaded;

/// `fit`'s options with `--likelihood NAME` (and `--loss huber`).
fn options(likelihood: &str, huber: bool) -> FitOptions {
    let fo = FitOptions {
        huber: huber.then_some(3.0),
        ..FitOptions::command_default()
    };
    Likelihood::parse(likelihood)
        .expect("a likelihood")
        .apply(fo)
}

/// `fit --method all` on `l` with the known truth `truth` (`NAME=VALUE`),
/// neural gyrodometry at the hidden sizes `hidden`, UMBMark's squares of
/// side `side`.
fn methods<'r>(l: &'r Loaded, truth: &[&str], hidden: &[u32], side: f64) -> MethodsOutcome<'r> {
    let fo = FitOptions::command_default();
    let truth: Vec<(String, f64)> = truth
        .iter()
        .map(|t| {
            let (n, v) = t.split_once('=').unwrap();
            (n.to_string(), v.parse().unwrap())
        })
        .collect();
    let job = MethodsJob {
        method: MethodChoice::All,
        settings: Settings {
            side,
            ..Settings::defaults(&fo)
        },
        hidden,
        truth: &truth,
    };
    compare_methods(l, &job, &|_| {}).unwrap()
}

/// The row of method `name` in `m`.
fn row<'a, 'r>(
    m: &'a MethodsOutcome<'r>,
    name: &str,
) -> &'a kinegen_analysis::estimation::fit_job::MethodRow<'r> {
    m.rows
        .iter()
        .find(|r| r.name == name)
        .expect("the method ran")
}

#[test]
fn fit_recovers_wheel_radii_and_wheelbase_within_0_2_percent_and_error_falls_tenfold() {
    let tmp = tempfile::tempdir().unwrap();
    let truth = [("r_r", 0.0425), ("r_l", 0.0418), ("b", 0.2050)];
    let log = Sim::new("spec/diff_drive.toml")
        .sets(&["r_r=0.0425", "r_l=0.0418", "b=0.2050"])
        .drive("square", 3, 1)
        .write(tmp.path(), "params.csv");
    let l = load("spec/diff_drive.toml", &[], &[&log], &[]);
    let c = calibrated(&l);
    for (name, value) in truth {
        let (est, std) = estimate(&c, &l, name);
        assert!(
            ((est - value) / value).abs() < 0.002,
            "{name}: {est} vs true {value}"
        );
        assert!(std > 0.0);
    }
    let (before, after) = (c.before.errors.rmse, c.after.errors.rmse);
    assert!(
        after * 10.0 < before,
        "error fell only from {before} to {after}"
    );
}

#[test]
fn every_bundled_model_can_be_fitted() {
    let tmp = tempfile::tempdir().unwrap();
    for (spec, set) in [
        ("diff_drive", "b=0.21"),
        ("tricycle", "L=1.03"),
        ("tricycle_fwd", "L=1.03"),
        ("omni3", "L=1.04"),
        ("omni_caster", "r2=0.103"),
        ("unicycle_ekf", "v_scale=1.05"),
    ] {
        let path = format!("spec/{spec}.toml");
        let log = Sim::new(&path)
            .sets(&[set])
            .drive("random", 2, 1)
            .write(tmp.path(), &format!("{spec}.csv"));
        let l = load(&path, &[], &[&log], &[]);
        let c = calibrated(&l);
        let (b, a) = (c.before.errors.rmse, c.after.errors.rmse);
        assert!(
            a < 0.5 * b,
            "{spec}: fit did not reduce the error ({b} -> {a})"
        );
    }
}

/// Seed 004's setting, UMBMark's squares both ways: every method of the
/// registry runs; LM is closest to the truth; UMBMark moves every parameter
/// toward it; the yaw-rate EKF (seed 000) improves the ratio it can see.
#[test]
fn seed_methods_run_and_are_compared_on_umbmark_squares() {
    let tmp = tempfile::tempdir().unwrap();
    let truth = ["r_r=0.0423", "r_l=0.0417", "b=0.206"];
    let logs: Vec<_> = ["cw", "ccw"]
        .map(|dir| {
            Sim::new("spec/diff_drive.toml")
                .sets(&truth)
                .drive(&format!("square-{dir}"), 1, 1)
                .write(tmp.path(), &format!("{dir}.csv"))
        })
        .into();
    let l = load("spec/diff_drive.toml", &[], &[&logs[0], &logs[1]], &[]);
    let m = methods(&l, &truth, &[], Settings::SIDE);
    for name in ["lm", "gd", "ekf", "umbmark"] {
        row(&m, name);
    }
    assert_eq!(m.closest.as_ref().unwrap().1, "lm");
    let nominal = [0.042, 0.042, 0.2];
    let p = |method: &str, name: &str| {
        row(&m, method).calibration.p[l.runner.param_index(name).unwrap()]
    };
    for ((name, t), n) in ["r_r", "r_l", "b"]
        .iter()
        .zip([0.0423, 0.0417, 0.206])
        .zip(nominal)
    {
        let est = p("umbmark", name);
        assert!(
            (est - t).abs() < (n - t).abs(),
            "umbmark {name}: {est}, truth {t}, nominal {n}"
        );
    }
    // omega = (r_r w_r - r_l w_l)/b: the EKF sees r_r/b
    let ratio = p("ekf", "r_r") / p("ekf", "b");
    assert!((ratio - 0.0423 / 0.206).abs() < (0.042 / 0.2 - 0.0423 / 0.206f64).abs());
}

/// Seed 000's setting: the Omni robot with the nominal parameters of eq. 27,
/// the truth the values the paper identified (eq. 28). Every method moves the
/// parameters toward the truth; LM, with the pose residuals that pin what the
/// yaw rate cannot see, leaves under 5% of the nominal values' distance; the
/// gyro-only methods are warned about the directions they cannot see.
#[test]
fn seed_000_setting_every_method_moves_toward_the_truth() {
    let tmp = tempfile::tempdir().unwrap();
    let log = Sim::seed_000(3).write(tmp.path(), "omni.csv");
    let l = load("spec/omni_caster.toml", &[], &[&log], &[]);
    let m = methods(&l, &SEED_000_TRUTH, &[], Settings::SIDE);
    for name in ["lm", "gd", "ekf"] {
        let d = row(&m, name).distance_to_truth.unwrap();
        assert!(
            d < 1.0,
            "{name} did not move toward the truth: {:.1}% of the nominal's distance left",
            100.0 * d
        );
    }
    assert_eq!(m.closest.as_ref().unwrap().1, "lm");
    assert!(row(&m, "lm").distance_to_truth.unwrap() < 0.05);
    assert!(row(&m, "ekf").note.contains("undetermined"));
}

/// Seed 000's neural gyrodometry against the calibrated model, three logs
/// fitted and one held out: the calibrated model predicts the held-out run
/// best, the larger network second.
#[test]
fn seed_000_neural_gyrodometry_loses_to_the_calibrated_model() {
    let tmp = tempfile::tempdir().unwrap();
    let log = |seed: u64| Sim::seed_000(seed).write(tmp.path(), &format!("omni{seed}.csv"));
    let (a, b, c, held) = (log(3), log(4), log(5), log(11));
    let l = load("spec/omni_caster.toml", &[], &[&a, &b, &c], &[&held]);
    let m = methods(&l, &[], &[9, 50], Settings::SIDE);
    let held_out = |name: &str| row(&m, name).holdout.as_ref().unwrap().rmse;
    let (lm, n50, n9) = (held_out("lm"), held_out("neural-50"), held_out("neural-9"));
    eprintln!("held-out position RMSE: calibrated (lm) {lm:.4} m, neural 50 {n50:.4} m, neural 9 {n9:.4} m, nominal {:?}", m.holdout_before);
    assert!(
        lm < n50 && n50 < n9,
        "lm {lm}, neural-50 {n50}, neural-9 {n9}"
    );
    let note = &row(&m, "neural-50").note;
    assert!(
        note.contains("50 hidden units") && note.contains("best on the validation split"),
        "{note}"
    );
}

/// Issue #11.8: on the real OptiOdom squares (runs 1, 2, 4, 5 fitted, 3 and 6
/// held out, side 0.75 m) the yaw-rate methods (seed 000) can end worse than
/// the nominal values on held-out runs; they must say so. And LM beats
/// UMBMark there (a wrong side of 1 m gives UMBMark a lucky 0.0086 m).
#[test]
fn a_method_worse_than_nominal_on_held_out_runs_says_so() {
    let Some(runs) = real_runs() else { return };
    let fitted = [&runs[0], &runs[1], &runs[3], &runs[4]].map(|p| p.as_path());
    let l = load("spec/diff_drive.toml", &[], &fitted, &[&runs[2], &runs[5]]);
    let m = methods(&l, &[], &[], 0.75);
    let nominal = m.holdout_before.unwrap();
    let mut warned = 0;
    for r in &m.rows {
        let held = r.holdout.as_ref().unwrap().rmse;
        let says = r.note.contains("worse than the nominal");
        assert_eq!(
            held > 1.001 * nominal,
            says,
            "{}: held-out {held} vs nominal {nominal}",
            r.name
        );
        warned += says as usize;
    }
    assert!(warned > 0, "expected gd or ekf to end worse than nominal");
    let held = |name: &str| row(&m, name).holdout.as_ref().unwrap().rmse;
    assert!(
        held("lm") < held("umbmark"),
        "lm {} vs umbmark {}",
        held("lm"),
        held("umbmark")
    );
}

/// Motion-capture glitches (3% of rows thrown 0.8 m off) bias a least-squares
/// fit; the Huber loss keeps the estimates near the truth.
#[test]
fn huber_loss_resists_ground_truth_outliers() {
    let tmp = tempfile::tempdir().unwrap();
    let truth = [("r_r", 0.0425), ("r_l", 0.0418), ("b", 0.205)];
    let log = Sim::new("spec/diff_drive.toml")
        .sets(&["r_r=0.0425", "r_l=0.0418", "b=0.205"])
        .drive("square", 3, 1)
        .write(tmp.path(), "sq.csv");
    let text = std::fs::read_to_string(&log).unwrap();
    let mut lines: Vec<String> = text.lines().map(String::from).collect();
    let header: Vec<&str> = lines[0].split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let (ix, iy) = (col("gt_x"), col("gt_y"));
    // deterministic glitches: every 33rd row
    for (k, line) in lines.iter_mut().enumerate().skip(1) {
        if k % 33 == 0 {
            let mut cells: Vec<String> = line.split(',').map(String::from).collect();
            let s = if k % 66 == 0 { 0.8 } else { -0.8 };
            cells[ix] = format!("{}", cells[ix].parse::<f64>().unwrap() + s);
            cells[iy] = format!("{}", cells[iy].parse::<f64>().unwrap() - s);
            *line = cells.join(",");
        }
    }
    let bad = tmp.path().join("glitches.csv");
    std::fs::write(&bad, lines.join("\n") + "\n").unwrap();
    let l = load("spec/diff_drive.toml", &[], &[&bad], &[]);
    let errors = |huber: bool| {
        let c = calibrated_with(&l, &options("track", huber));
        truth.map(|(n, t)| (estimate(&c, &l, n).0 - t).abs() / t)
    };
    let (l2, huber) = (errors(false), errors(true));
    assert!(huber.iter().all(|e| *e < 0.004), "huber errors {huber:?}");
    let worst = |v: [f64; 3]| v.iter().cloned().fold(0.0, f64::max);
    assert!(
        worst(huber) < worst(l2),
        "huber {huber:?} is not better than l2 {l2:?}"
    );
}

/// Turning in place shows only the ratios r/b: the fit warns by name that the
/// common scale of r_r, r_l and b is not identifiable, reports their standard
/// deviations as none (not as a small number), keeps them near nominal instead
/// of wandering along the null direction, and still fits the ratio it can see.
#[test]
fn turning_in_place_leaves_the_common_scale_unidentified_and_says_so() {
    let tmp = tempfile::tempdir().unwrap();
    let log = Sim::new("spec/diff_drive.toml")
        .sets(&["b=0.21"])
        .drive("spin", 1, 1)
        .write(tmp.path(), "spin.csv");
    let l = load("spec/diff_drive.toml", &[], &[&log], &[]);
    let c = calibrated(&l);
    let warnings = c.warnings();
    assert!(
        warnings
            .iter()
            .any(|w| w.contains("not identifiable")
                && ["r_r", "r_l", "b"].iter().all(|n| w.contains(n))),
        "{warnings:?}"
    );
    let est = |n: &str| estimate(&c, &l, n);
    for n in ["r_r", "r_l", "b"] {
        assert!(!est(n).1.is_finite(), "{n}: std {}", est(n).1);
    }
    let b = est("b").0;
    assert!((b / 0.2 - 1.0).abs() < 0.1, "b wandered to {b}");
    let ratio = (est("r_r").0 + est("r_l").0) / b;
    assert!(
        (ratio / (0.084 / 0.21) - 1.0).abs() < 0.005,
        "(r_r + r_l)/b = {ratio}, truth {}",
        0.084 / 0.21
    );
}

/// A cart whose only steering is a fixed toe angle: the log shows the curvature
/// tan(toe)/L and nothing else, a curved set of equally good (L, toe) pairs.
/// From toe = 0 the fit must still reach the curvature (before: the
/// undetermined direction found at the optimum, held from the start, was
/// nearly the toe axis there, and the fit ended where it began, 0.77 m RMSE)
/// and say that L and toe cannot be separated.
#[test]
fn a_curved_undetermined_direction_does_not_stop_the_fit_at_its_start() {
    let tmp = tempfile::tempdir().unwrap();
    let cart = tmp.path().join("cart.toml");
    std::fs::write(&cart, TOE_CART).unwrap();
    let cart = cart.to_str().unwrap();
    let log = Sim::new(cart)
        .sets(&["toe=0.05"])
        .drive("figure8", 4, 1)
        .write(tmp.path(), "cart.csv");
    let l = load(cart, &[], &[&log], &[]);
    let c = calibrated(&l);
    let after = c.after.errors.rmse;
    assert!(
        after < 0.01,
        "position RMSE after the fit {after} m: {:?}",
        c.warnings()
    );
    let curvature = estimate(&c, &l, "toe").0.tan() / estimate(&c, &l, "L").0;
    let truth = 0.05f64.tan() / 0.65;
    assert!(
        (curvature / truth - 1.0).abs() < 0.01,
        "tan(toe)/L = {curvature}, truth {truth}"
    );
    let warnings = c.warnings().join("\n");
    assert!(
        warnings.contains("combination of L and toe")
            || warnings.contains("combination of toe and L"),
        "{warnings}"
    );
}

const TOE_CART: &str = r#"name = "cart"
state = ["x", "y", "theta"]

[[input]]
name = "w"
column = "wheel_rad"
kind = "cumulative"
unit = "rad/s"

[[parameter]]
name = "r"
nominal = 0.11
unit = "m"
min = 0.01

[[parameter]]
name = "L"
nominal = 0.65
unit = "m"
min = 0.1

[[parameter]]
name = "toe"
nominal = 0.0
unit = "rad"
min = -0.2
max = 0.2

[motion]
vx = "r*w"
vy = "0"
omega = "r*w*tan(toe)/L"

[[observation]]
name = "mocap"
columns = ["mx", "my", "myaw"]
expr = ["x", "y", "theta"]
angle = [false, false, true]
sigma = [0.003, 0.003, 0.005]
"#;

/// Issue #11: a front-wheel-drive tricycle (tests/user_specs) whose steering
/// gain is 5x off its nominal value and whose tracker sits 1.8 m ahead of the
/// rear axle. From the nominal values a whole-track fit falls into the "robot
/// that does not move" minimum; the continuation ladder (short re-anchored
/// segments first) must reach the optimum a fit started at the truth
/// reaches, on a short (83 s) and a long (546 s) log, and cut each run's
/// error tenfold.
#[test]
fn fit_from_rough_nominal_values_reaches_the_optimum_of_a_fit_started_at_the_truth() {
    let tmp = tempfile::tempdir().unwrap();
    let spec = "tests/user_specs/fwd_tricycle.toml";
    let truth = ["steer_gain=0.005", "r=0.23"];
    for (traj, laps, name) in [("square", 1, "square.csv"), ("random", 6, "long.csv")] {
        let log = Sim::new(spec)
            .sets(&truth)
            .drive(traj, 7, laps)
            .write(tmp.path(), name);
        let nominal = load(spec, &[], &[&log], &[]);
        let at_truth = load(spec, &truth, &[&log], &[]);
        let (from_nominal, from_truth) = (calibrated(&nominal), calibrated(&at_truth));
        for p in ["r", "L", "steer_gain"] {
            let (ea, _) = estimate(&from_nominal, &nominal, p);
            let (eb, std) = estimate(&from_truth, &at_truth, p);
            assert!(
                (ea - eb).abs() <= 2.0 * std,
                "{traj}: {p} from nominal {ea}, from the truth {eb} (std {std})"
            );
        }
        assert!(
            from_nominal.unusable.is_empty(),
            "{traj}: {:?}",
            from_nominal.unusable
        );
        let (after, before) = (
            &from_nominal.after.per_run[0],
            &from_nominal.before.per_run[0],
        );
        assert!(after.rmse < 0.1 * before.rmse, "{traj}");
    }
}

/// Issue #70.4: on a spec that lacks the effect the robot has (a misspecified
/// model), fit from rough nominal values (the truth 2-3x off them) reaches
/// the error a fit started at the true values reaches, within 10%, on four
/// models; the front-drive tricycle that collapses its wheel names what it
/// could not reconcile.
#[test]
fn fit_from_rough_nominal_values_on_a_spec_missing_an_effect_reaches_what_the_truth_reaches() {
    let tmp = tempfile::tempdir().unwrap();
    let cases: [(&str, &[&str], &str); 4] = [
        (
            "spec/diff_drive.toml",
            &["b=0.5", "r_l=0.08", "r_r=0.08"],
            "lateral_slip=0.2",
        ),
        (
            "spec/tricycle.toml",
            &["L=3.0", "r=0.06"],
            "steering_offset=0.05",
        ),
        ("spec/tricycle_fwd.toml", &["L=0.3"], "steering_offset=0.08"),
        ("spec/omni3.toml", &["L=0.3"], "wheel_radius_asymmetry=0.05"),
    ];
    for (k, (spec, truth, effect)) in cases.iter().enumerate() {
        let log = Sim::new(spec)
            .sets(truth)
            .effects(&[effect])
            .drive("random", 11, 1)
            .write(tmp.path(), &format!("log{k}.csv"));
        let nominal = load(spec, &[], &[&log], &[]);
        let at_truth = load(spec, truth, &[&log], &[]);
        let fit = calibrated(&nominal);
        let (from_nominal, from_truth) = (
            fit.after.errors.rmse,
            calibrated(&at_truth).after.errors.rmse,
        );
        assert!(
            from_nominal <= 1.1 * from_truth,
            "{spec} with {effect}: {from_nominal} from nominal, {from_truth} from the truth"
        );
        if spec.ends_with("tricycle_fwd.toml") {
            let warnings = fit.warnings().join("\n");
            assert!(warnings.contains("cannot reconcile"), "{warnings}");
        }
    }
}

/// Issue #11.2: reported standard deviations are honest. Over 50 simulated
/// seeds of a differential drive (random driving, 91 s, parameter errors),
/// the spread of each estimate matches the mean reported standard deviation
/// within 30%, with the increments likelihood and with the default
/// absolute-track one. The track's standard deviations were 3-9x too small
/// while a start heading averaged over the logs' rest was held fixed: its
/// leftover error rotated the whole track, differently in every log, which
/// the residuals' random walk took the blame for.
#[test]
fn fifty_seeds_spread_matches_the_reported_standard_deviation() {
    let tmp = tempfile::tempdir().unwrap();
    let names = ["r_r", "r_l", "b"];
    let (mut increments, mut track) = (Estimates::new(&names), Estimates::new(&names));
    for seed in 1..=50 {
        let log = Sim::new("spec/diff_drive.toml")
            .sets(&["r_r=0.0425", "b=0.205"])
            .drive("random", seed, 1)
            .write(tmp.path(), &format!("s{seed}.csv"));
        let l = load("spec/diff_drive.toml", &[], &[&log], &[]);
        increments.push(&l, &calibrated_with(&l, &options("increments", false)));
        track.push(&l, &calibrated(&l));
    }
    for (likelihood, e) in [("increments", &increments), ("track", &track)] {
        for (k, n) in names.iter().enumerate() {
            let ratio = spread_of(&e.est[k]) / mean(&e.std[k]);
            eprintln!("{n}: {likelihood} {ratio:.2}");
            assert!(
                (0.7..=1.3).contains(&ratio),
                "{n}, {likelihood} likelihood: spread {:.3e} against reported {:.3e} (ratio {ratio:.2})",
                spread_of(&e.est[k]),
                mean(&e.std[k])
            );
        }
    }
}

/// Issue #35.2: a clean long log (364 s at 20 Hz, quantised encoders, white
/// motion-capture noise, simulated with exactly the nominal values) is not
/// made worse by calibration: over 20 seeds the whole-run position RMSE
/// after the fit stays within 5% of the nominal values' (the fit ends on
/// the whole runs), every estimate lies within 2 reported standard
/// deviations of the truth, their mean within half a standard deviation of
/// it, and the reported standard deviations match the spread of the
/// estimates over the seeds within 30% (a sandwich over the track's drift).
/// The re-anchored segments alone (what the fit used to report) fail the
/// first check on seed 2: 0.0015 m -> 0.0030 m, estimates 8 standard
/// deviations off.
///
/// Measured over these seeds: after/before at most 0.997; the largest error
/// of an estimate 1.8 standard deviations, their mean 0.3; spread / mean
/// std 0.91 (r_r, r_l) and 1.02 (b). Dead reckoning that held each step's
/// mean wheel rates (no `deadreckon::swing_offset`) put the mean 1.2-1.3
/// standard deviations short, 17 estimates of 60 beyond 2 and one at 6: the
/// simulated wheels, like real ones, speed up and slow down within a step.
#[test]
fn a_clean_long_log_keeps_its_whole_run_error_and_honest_standard_deviations() {
    let tmp = tempfile::tempdir().unwrap();
    let names = ["r_r", "r_l", "b"];
    let mut e = Estimates::new(&names);
    for seed in 1..=20 {
        let log = Sim::new("spec/diff_drive.toml")
            .drive("random", seed, 4)
            .write(tmp.path(), &format!("c{seed}.csv"));
        let l = load("spec/diff_drive.toml", &[], &[&log], &[]);
        let c = calibrated(&l);
        assert_whole_run_kept(&c, 1.05, &format!("seed {seed}"));
        e.push(&l, &c);
        if seed == 2 {
            let seg = calibrated_with(&l, &options("segments", false));
            let grown = seg.after.errors.rmse / seg.before.errors.rmse;
            assert!(
                grown > 1.05,
                "the segments alone no longer degrade this log ({grown:.2})"
            );
        }
    }
    e.assert_honest(&[0.042, 0.042, 0.2], Within::TwoStd);
}

/// A clean 9,100 s log (100 laps of random driving, 182,000 rows): the
/// standard deviations stay honest where the information is this uneven.
/// The wheel radii carry 1e13 times the information of their weakest
/// combination with the track width; summed as J^T J, that combination's
/// eigenvalue (4e-13 of the largest in each unknown's own units) was
/// round-off, the drift-aware sandwich dropped it, and reported r_r
/// 0.0420005 ± 0.00000000003: 20,000 standard deviations from the truth
/// (b 17). Kept as a square root (`fit/square_root.rs`): every estimate
/// within 0.8 standard deviations (r_r ± 0.00000068).
#[test]
fn a_very_long_log_keeps_honest_standard_deviations() {
    let tmp = tempfile::tempdir().unwrap();
    let log = Sim::new("spec/diff_drive.toml")
        .drive("random", 1, 100)
        .write(tmp.path(), "long.csv");
    let l = load("spec/diff_drive.toml", &[], &[&log], &[]);
    let c = calibrated(&l);
    for (name, value) in [("r_r", 0.042), ("r_l", 0.042), ("b", 0.2)] {
        let (e, sd) = estimate(&c, &l, name);
        assert!(
            (e - value).abs() <= 3.0 * sd,
            "{name} {e} ± {sd} (truth {value})"
        );
    }
}

/// Issue #35.2 on logs kinegen did not simulate: the clean 200 s logs of
/// [`elsewhere::diff_drive`] keep their whole-run RMSE within 5% of the
/// nominal values' and every estimate within 2 reported standard deviations
/// of the truth. Fit used to keep the whole-run refinement only where the
/// re-anchored segments' cost stayed within 10% of theirs at their own
/// optimum; on these information-rich logs the whole-run estimate often
/// cost more there, and the segments' estimate made the whole-run error
/// worse than the nominal values' on 4 seeds of 40 (x1.10-2.01; seeds 15,
/// 16, 19 and 40). It is now also kept where its 5 s drift is no worse:
/// over the 40 seeds the error after the fit is 0.50-0.997 of the nominal
/// values', every estimate within 1.6 standard deviations. The seeds here
/// hold three of the four.
#[test]
fn clean_logs_from_another_simulator_keep_their_whole_run_error() {
    let tmp = tempfile::tempdir().unwrap();
    let truth = [("r_r", 0.042), ("r_l", 0.042), ("b", 0.2)];
    for seed in 13..=20 {
        let log = tmp.path().join(format!("clean{seed}.csv"));
        elsewhere::diff_drive(&log, seed, 200);
        let l = load("spec/diff_drive.toml", &[], &[&log], &[]);
        let c = calibrated(&l);
        assert_whole_run_kept(&c, 1.05, &format!("seed {seed}"));
        for (name, value) in truth {
            let (e, sd) = estimate(&c, &l, name);
            assert!(
                (e - value).abs() <= 2.0 * sd,
                "seed {seed}: {name} {e} ± {sd} (truth {value})"
            );
        }
    }
}

/// Issue #35.2 with an angle read by an encoder: clean tricycle logs from
/// [`elsewhere::tricycle`], the steering rounded to an 11-bit encoder (3.1
/// mrad). Over 30 seeds, each parameter's reported standard deviation
/// matches the spread of its estimates within 30%. The steering's rounding
/// is an error in every row that the track integrates; too small to stand
/// out in the residuals, it is counted from the log's own resolution
/// (`fit/rounding.rs`). Measured: spread / std 0.78 (r), 0.80 (L), 1.02
/// (steer_offset), the worst estimate 2.25 std off; without it the steering
/// offset's spread was 2.21x its reported standard deviation, one estimate
/// 10.4 std off. Left: with a 10-bit encoder r and L come out 0.63-0.69
/// (too cautious); with a 12-bit one, or none, the offset 1.37 (an error
/// the rounding does not explain).
#[test]
fn a_rounded_steering_angle_is_counted_in_the_standard_deviations() {
    let tmp = tempfile::tempdir().unwrap();
    let names = ["r", "L", "steer_offset"];
    let spec = "spec/benchmarks/optiodom/tricycle.toml";
    let mut e = Estimates::new(&names);
    for seed in 1..=30 {
        let log = tmp.path().join(format!("tricycle{seed}.csv"));
        elsewhere::tricycle(&log, seed, 2048.0);
        let l = load(spec, &[], &[&log], &[]);
        e.push(&l, &calibrated(&l));
    }
    e.assert_honest(&[0.0325, 0.15, 0.0], Within::Spread);
}

/// Issue #35.2's standard deviations on long logs from a simulator other
/// than kinegen's: 30 clean 600 s logs at 50 Hz ([`elsewhere::diff_drive`],
/// quantised encoders). Each parameter's reported standard deviation
/// matches the spread of its estimates over the seeds within 30%, their mean
/// lies within half a standard deviation of the truth, and no fit leaves the
/// whole-run error above the nominal values'.
#[test]
fn long_clean_logs_from_another_simulator_get_honest_standard_deviations() {
    let tmp = tempfile::tempdir().unwrap();
    let names = ["r_r", "r_l", "b"];
    let mut e = Estimates::new(&names);
    for seed in 101..=130 {
        let log = tmp.path().join(format!("long{seed}.csv"));
        elsewhere::diff_drive(&log, seed, 600);
        let l = load("spec/diff_drive.toml", &[], &[&log], &[]);
        let c = calibrated(&l);
        assert_whole_run_kept(&c, 1.0, &format!("seed {seed}"));
        e.push(&l, &c);
    }
    e.assert_honest(&[0.042, 0.042, 0.2], Within::Spread);
}

/// Issue #33: whatever the robot (six bundled specs and four users'), a
/// calibration that leaves a held-out run worse than the nominal values says
/// why (the fitted runs do not cover or determine what the held-out run
/// needs). Every trajectory but the turns in place halves the held-out
/// error; the turns in place are the cases that show the warning works.
#[test]
fn calibration_never_leaves_held_out_runs_worse_than_nominal_without_saying_why() {
    let tmp = tempfile::tempdir().unwrap();
    let specs = [
        "spec/diff_drive.toml",
        "spec/tricycle.toml",
        "spec/tricycle_fwd.toml",
        "spec/omni3.toml",
        "spec/unicycle_ekf.toml",
        "spec/omni_caster.toml",
        "tests/user_specs/fwd_tricycle.toml",
        "tests/user_specs/mecanum4.toml",
        "tests/user_specs/offset_diff.toml",
        "tests/user_specs/skid4.toml",
    ];
    let (mut worse, mut cases) = (Vec::new(), 0);
    for spec_path in specs {
        let model = kinegen_model::spec::Model::load(&spec(spec_path)).unwrap();
        let truth: Vec<String> = (model.params.iter())
            .filter(|p| p.free && !p.constant && p.nominal != 0.0)
            .enumerate()
            .map(|(k, p)| {
                let f = if k % 2 == 0 { 1.03 } else { 0.97 };
                format!("{}={}", p.name, p.nominal * f)
            })
            .collect();
        let truth: Vec<&str> = truth.iter().map(String::as_str).collect();
        let sim = |file: &str, traj: &str, laps: usize, seed: u64| {
            (Sim::new(spec_path).sets(&truth).drive(traj, seed, laps))
                .write(tmp.path(), &format!("{}-{file}", model.name))
        };
        let hold = sim("held.csv", "random", 2, 99);
        for (traj, laps) in [
            ("square", 1),
            ("figure8", 4),
            ("random", 1),
            ("spin", 1),
            ("spin", 4),
        ] {
            let log = sim(&format!("{traj}-{laps}.csv"), traj, laps, 3);
            let l = load(spec_path, &[], &[&log], &[&hold]);
            let c = calibrated(&l);
            cases += 1;
            let h = c.holdout.as_ref().unwrap();
            let (before, after) = (h.before.errors.rmse, h.after.errors.rmse);
            let case = format!(
                "{} {traj} x{laps}: held out {before:.4} m -> {after:.4} m",
                model.name
            );
            if traj != "spin" {
                assert!(after < 0.5 * before, "{case}");
            }
            let said = c.warnings().iter().any(|w| {
                w.contains("worse than the nominal parameters on the held-out runs")
                    && (w.contains("do not cover") || w.contains("do not determine"))
            });
            assert_eq!(after > 1.001 * before, said, "{case}: {:?}", c.warnings());
            if said {
                worse.push(case);
            }
        }
    }
    eprintln!(
        "{} of {cases} calibrations left the held-out run worse, each with its reason: {worse:#?}",
        worse.len()
    );
    // The unicycle's logged commands are what it executes (they hold between
    // rows, issue 34), so turning in place its speed command is exactly 0 and
    // its speed scale stays nominal, undetermined; the 12-parameter
    // omni_caster turning in place is the other case left worse, and says why.
    let expected = [
        "unicycle_ekf spin x4",
        "omni_caster spin x1",
        "omni_caster spin x4",
    ];
    assert!(!worse.is_empty(), "no case shows the warning");
    for c in &worse {
        assert!(expected.iter().any(|e| c.starts_with(e)), "{c}");
    }
}

/// A calibration whose model stops turning: a tricycle log whose steering
/// reads 0.1 rad high. The model turns 0 rad where the measurements turn
/// 21.2 rad, fits the gyro worse, and its wheelbase ends thousands of times
/// its drawing: unusable, each reason said.
#[test]
fn a_calibration_that_stops_turning_is_unusable() {
    let tmp = tempfile::tempdir().unwrap();
    let clean = Sim::new("spec/tricycle.toml")
        .drive("random", 4001, 2)
        .write(tmp.path(), "clean.csv");
    let text = std::fs::read_to_string(&clean).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let alpha = header.iter().position(|h| *h == "alpha").unwrap();
    let mut shifted = header.join(",") + "\n";
    for line in lines {
        let mut v: Vec<String> = line.split(',').map(str::to_string).collect();
        v[alpha] = (v[alpha].parse::<f64>().unwrap() + 0.1).to_string();
        shifted += &(v.join(",") + "\n");
    }
    let log = tmp.path().join("steer_high.csv");
    std::fs::write(&log, shifted).unwrap();
    let l = load("spec/tricycle.toml", &[], &[&log], &[]);
    let c = calibrated(&l);
    let unusable = c.unusable.join("\n");
    // (the segments' optimum turns 0.0 rad; refined on the whole run, 2.1)
    assert!(
        unusable.contains("rad in all while the measurements turn 21.2 rad"),
        "{unusable}"
    );
    assert!(unusable.contains("fits the gyro worse"), "{unusable}");
    let warnings = c.warnings().join("\n");
    assert!(warnings.contains("times its nominal value"), "{warnings}");
}

/// A robot calibrated on runs that turn one way is warned: a scale and an
/// offset of the turn rate trade off there (UMBmark drives both ways). A
/// circle driven counter-clockwise says so; the same circle with one driven
/// clockwise too does not. On the real tricycle: one clockwise circle is
/// warned, the session's two circles are not.
#[test]
fn runs_that_turn_one_way_are_warned() {
    let tmp = tempfile::tempdir().unwrap();
    let spec = tmp.path().join("wheels.toml");
    std::fs::write(
        &spec,
        r#"name = "wheels"
state = ["x", "y", "theta"]
[[input]]
name = "wr"
column = "phi_r"
kind = "cumulative"
[[input]]
name = "wl"
column = "phi_l"
kind = "cumulative"
[[parameter]]
name = "r_r"
nominal = 0.05
min = 0.0
[[parameter]]
name = "r_l"
nominal = 0.05
min = 0.0
[[parameter]]
name = "b"
nominal = 0.3
min = 0.0
[motion]
vx = "(r_r*wr + r_l*wl)/2"
vy = "0"
omega = "(r_r*wr - r_l*wl)/b"
"#,
    )
    .unwrap();
    // a circle at constant wheel rates, exactly integrated, one way or the other
    let circle = |name: &str, sign: f64| {
        let (wr, wl) = if sign > 0.0 { (10.0, 8.0) } else { (8.0, 10.0) };
        let (v, w) = (0.05 * (wr + wl) / 2.0, 0.05 * (wr - wl) / 0.3);
        let mut s = String::from("t,phi_r,phi_l,gt_x,gt_y,gt_theta\n");
        for k in 0..=600 {
            let t = 0.05 * k as f64;
            let th = w * t;
            let (x, y) = (v / w * th.sin(), v / w * (1.0 - th.cos()));
            let wrapped = (th + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU)
                - std::f64::consts::PI;
            s += &format!("{t:.2},{},{},{x:.6},{y:.6},{wrapped:.6}\n", wr * t, wl * t);
        }
        let path = tmp.path().join(name);
        std::fs::write(&path, s).unwrap();
        path
    };
    let (ccw, cw) = (circle("ccw.csv", 1.0), circle("cw.csv", -1.0));
    let warnings = |spec: &str, logs: &[&std::path::Path]| {
        calibrated(&load(spec, &[], logs, &[]))
            .warnings()
            .join("\n")
    };
    let fit = |logs: &[&std::path::Path]| warnings(spec.to_str().unwrap(), logs);
    let one = fit(&[&ccw]);
    assert!(
        one.contains("turn one way") && one.contains("counter-clockwise"),
        "{one}"
    );
    let both = fit(&[&ccw, &cw]);
    assert!(!both.contains("turn one way"), "{both}");
    let Some(dir) = real_data("optiodom-dev") else {
        return;
    };
    let session = dir.join("tricyc-circular-140120211440");
    let real = |runs: &[&str]| {
        let logs: Vec<_> = runs.iter().map(|r| session.join(r)).collect();
        let logs: Vec<&std::path::Path> = logs.iter().map(|p| p.as_path()).collect();
        warnings("spec/benchmarks/optiodom/tricycle.toml", &logs)
    };
    assert!(real(&["run-01.csv"]).contains("turn one way"));
    assert!(!real(&["run-01.csv", "run-02.csv"]).contains("turn one way"));
}

/// Each parameter's estimates and reported standard deviations over seeds.
struct Estimates<'a> {
    names: &'a [&'a str],
    est: Vec<Vec<f64>>,
    std: Vec<Vec<f64>>,
}

/// What [`Estimates::assert_honest`] also asks of each estimate.
#[derive(PartialEq)]
enum Within {
    /// Only the spread and the mean.
    Spread,
    /// And each estimate within 2 of its standard deviations of the truth.
    TwoStd,
}

impl<'a> Estimates<'a> {
    fn new(names: &'a [&'a str]) -> Estimates<'a> {
        let n = names.len();
        Estimates {
            names,
            est: vec![vec![]; n],
            std: vec![vec![]; n],
        }
    }

    fn push(&mut self, l: &Loaded, c: &kinegen_analysis::estimation::fit_job::Calibrated) {
        for (k, n) in self.names.iter().enumerate() {
            let (e, s) = estimate(c, l, n);
            self.est[k].push(e);
            self.std[k].push(s);
        }
    }

    /// Each parameter's reported standard deviations match the spread of its
    /// estimates over the seeds within 30%, and their mean lies within half
    /// a standard deviation of `truth`.
    fn assert_honest(&self, truth: &[f64], within: Within) {
        for (k, n) in self.names.iter().enumerate() {
            let (est, std) = (&self.est[k], &self.std[k]);
            let ratio = spread_of(est) / mean(std);
            let bias = (mean(est) - truth[k]) / mean(std);
            let offs = est.iter().zip(std).map(|(e, s)| ((e - truth[k]) / s).abs());
            let worst = offs.fold(0.0, f64::max);
            eprintln!("{n}: spread / std {ratio:.2}, bias {bias:.2} std, worst {worst:.2} std");
            assert!(
                (0.7..=1.3).contains(&ratio),
                "{n}: spread {:.3e}, mean std {:.3e} ({ratio:.2})",
                spread_of(est),
                mean(std)
            );
            assert!(
                bias.abs() < 0.5,
                "{n}: the estimates' mean is {bias:.2} std off"
            );
            if within == Within::TwoStd {
                assert!(
                    worst <= 2.0,
                    "{n}: an estimate {worst:.2} std off the truth"
                );
            }
        }
    }
}

/// The calibration leaves the whole-run error at most `factor` times the
/// nominal values'.
fn assert_whole_run_kept(
    c: &kinegen_analysis::estimation::fit_job::Calibrated,
    factor: f64,
    case: &str,
) {
    let (before, after) = (c.before.errors.rmse, c.after.errors.rmse);
    assert!(
        after <= factor * before,
        "{case}: whole-run RMSE {before} -> {after}"
    );
}
