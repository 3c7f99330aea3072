//! Calibration that knows what one session cannot tell (issue 70, item 5):
//! `fit::for_use`, what `fit`, the Python API and `bench-real` hand to the
//! user, against the maximum-likelihood fit it starts from.
use kinegen_analysis::applications::simulate::{simulate, SimLog, SimOptions, Trajectory};
use kinegen_analysis::estimation::fit::{fit, for_use, FitOptions, FitResult, Search};
use kinegen_analysis::model_on_log::metrics;
use kinegen_analysis::model_on_log::model::Runner;
use kinegen_analysis::model_on_log::run::Run;
use kinegen_model::ir::ModelIr;
use std::f64::consts::PI;
use std::path::Path;

fn runner(model: &str) -> Runner {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("../generated/ir/{model}.json"));
    let ir = ModelIr::from_json(&std::fs::read_to_string(p).unwrap()).unwrap();
    Runner::new(ir, &[]).unwrap()
}

fn with(base: &Runner, sets: &[(&str, f64)]) -> Runner {
    let mut r = base.clone();
    for &(name, v) in sets {
        let i = r.param_index(name).unwrap();
        r.p[i] = v;
    }
    r
}

fn log(base: &Runner, truth: &Runner, trajectory: Trajectory, laps: usize, seed: u64) -> SimLog {
    let o = SimOptions {
        trajectory,
        seed,
        laps,
        ..SimOptions::default()
    };
    simulate(base, truth, &o)
}

/// The log without its gyro column: the real straight runs had none, and a
/// gyro reads the turn rate the wheelbase sets, however little it turns.
fn without_gyro(mut log: SimLog) -> SimLog {
    if let Some(c) = log.header.iter().position(|h| h == "gyro_z") {
        log.header.remove(c);
        log.rows.iter_mut().for_each(|row| {
            row.remove(c);
        });
    }
    log
}

/// The left wheel's counts made 2% more or less on a 7 s cycle: a wheel
/// slightly out of round, or slipping, which the spec does not model. Real
/// logs always have some such error; it is what makes a barely excited
/// parameter wander (the real straight runs' wheelbase went to 0.29-0.33 m).
fn left_wheel_wobbling(mut log: SimLog) -> SimLog {
    let (t, enc) = (0, log.header.iter().position(|h| h == "enc_l").unwrap());
    let (mut prev, mut acc) = (0.0, 0.0);
    for row in &mut log.rows {
        let d = row[enc] - prev;
        prev = row[enc];
        acc += d * (1.0 + 0.02 * (2.0 * PI * row[t] / 7.0).sin());
        row[enc] = acc.round();
    }
    log
}

fn named(r: &Runner, res: &FitResult, name: &str) -> (f64, f64) {
    let i = r.param_index(name).unwrap();
    let k = res.free.iter().position(|&j| j == i).unwrap();
    (res.p[i], res.std[k])
}

/// A straight back-and-forth run, as the real calibration sessions that
/// made the other sessions worse: the fit alone puts the wheelbase at more
/// than 1.5 times its true value (its own standard deviation over 50%), and
/// the calibration handed to the user keeps it within 1% of the nominal
/// value (the truth here), says so and names the runs that determine it,
/// while the right wheel's larger radius, which the straight runs
/// determine, is found within two standard deviations. A run that turns is dead-reckoned better with it than
/// with the fit alone. Without the prior step (`for_use` returning its
/// input) the second assertion fails, and so it does with the Gaussian
/// posterior's factor instead of `nominal_prior`'s (the wheelbase 3.3%
/// off).
#[test]
fn a_straight_run_keeps_the_wheelbase_near_nominal_and_says_so() {
    let base = runner("diff_drive");
    let truth = with(&base, &[("r_r", 0.0424)]);
    let straight = left_wheel_wobbling(without_gyro(log(
        &base,
        &truth,
        Trajectory::BackAndForth,
        3,
        1,
    )));
    let runs = [straight.to_run(&base, "straight").unwrap()];
    let o = FitOptions::command_default();
    let alone = fit(&base, &runs, &o, Search::Global).unwrap();
    let used = for_use(&base, &runs, &o, alone.clone());
    let (b_alone, _) = named(&base, &alone, "b");
    let (b, b_std) = named(&base, &used, "b");
    eprintln!(
        "b: {b_alone} alone, {b} ± {b_std} for use; {:?}",
        used.warnings
    );
    assert!(
        b_alone > 0.3,
        "the scenario: the fit alone is far off ({b_alone})"
    );
    assert!((b - 0.2).abs() < 0.002, "b {b}");
    let said = used
        .warnings
        .iter()
        .find(|w| w.starts_with("b barely determined"));
    assert!(
        said.is_some_and(|w| w.contains("runs turning both ways")),
        "{:?}",
        used.warnings
    );
    let b_index = base.param_index("b").unwrap();
    let held = used
        .near_nominal
        .iter()
        .find(|h| h.param == b_index)
        .unwrap();
    assert!(held.barely_determined() && held.data_estimate == b_alone);
    let (r_r, r_std) = named(&base, &used, "r_r");
    assert!((r_r - 0.0424).abs() < 2.0 * r_std, "r_r {r_r} ± {r_std}");
    // a run that turns, dead-reckoned from its measured start
    let turning = log(&base, &truth, Trajectory::Random, 1, 7);
    let turning = turning.to_run(&base, "turning").unwrap();
    let error = |p: &[f64]| metrics::from_measured_start(&base, p, &turning).rmse;
    let (e_alone, e_used) = (error(&alone.p), error(&used.p));
    assert!(e_used < 0.5 * e_alone, "{e_used} m against {e_alone} m");
}

/// A log that turns determines a wheelbase 30% off its drawing to a small
/// fraction of the prior's 10%: the calibration handed to the user is the
/// fit's, within a tenth of its standard deviation, and says nothing about
/// the nominal values.
#[test]
fn a_well_determined_parameter_far_from_nominal_keeps_its_fitted_value() {
    let base = runner("diff_drive");
    let truth = with(&base, &[("b", 0.26), ("r_l", 0.0415)]);
    let random = without_gyro(log(&base, &truth, Trajectory::Random, 1, 3));
    let runs = [random.to_run(&base, "random").unwrap()];
    let o = FitOptions::command_default();
    let alone = fit(&base, &runs, &o, Search::Global).unwrap();
    let used = for_use(&base, &runs, &o, alone.clone());
    for name in ["b", "r_l", "r_r"] {
        let ((a, sd), (u, _)) = (named(&base, &alone, name), named(&base, &used, name));
        assert!((u - a).abs() < 0.1 * sd, "{name}: {u} from {a} ± {sd}");
    }
    let (b, b_std) = named(&base, &used, "b");
    assert!((b - 0.26).abs() < 3.0 * b_std, "b {b} ± {b_std}");
    assert!(
        used.warnings
            .iter()
            .all(|w| !w.contains("barely determined")),
        "{:?}",
        used.warnings
    );
}

fn one_way_said(trajectory: Trajectory) -> Option<String> {
    let base = runner("diff_drive");
    let truth = with(&base, &[("r_r", 0.0422)]);
    let runs: Vec<Run> = vec![log(&base, &truth, trajectory, 1, 2)
        .to_run(&base, "square")
        .unwrap()];
    let o = FitOptions::command_default();
    let used = for_use(
        &base,
        &runs,
        &o,
        fit(&base, &runs, &o, Search::Global).unwrap(),
    );
    used.warnings
        .into_iter()
        .find(|w| w.contains("turn one way"))
}

/// A square driven one way only cannot tell the wheelbase from unequal
/// wheel radii (UMBmark drives it both ways): the calibration says so, and
/// says nothing of the kind for the square driven both ways.
#[test]
fn a_log_turning_one_way_is_said_and_one_turning_both_ways_is_not() {
    let said = one_way_said(Trajectory::SquareCcw).expect("one way: said");
    assert!(
        said.contains("is counter-clockwise") && said.contains("b)"),
        "{said}"
    );
    assert_eq!(one_way_said(Trajectory::Square), None);
}
