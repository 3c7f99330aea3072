//! A track read a row at a time (`track_rows::Recipe`: what compare, fit,
//! their reports and the coverage check read, so that a long log's tracks are
//! never held, issue 11 item 5) gives exactly the rows of the track computed
//! at once (`deadreckon::run_from`, `gyrodometry_with`), and the metrics and
//! landmark innovations read from either agree: with a measurement delay
//! either way, an off-centre pose sensor, a refined start, sub-stepped
//! steering, gyrodometry with the logged gyro and with a learned yaw rate.
mod common;

use kinegen_analysis::applications::simulate::{simulate, SimOptions, Trajectory};
use kinegen_analysis::model_on_log::deadreckon;
use kinegen_analysis::model_on_log::innovations::innovations;
use kinegen_analysis::model_on_log::metrics::{degenerate, errors, where_it_fails};
use kinegen_analysis::model_on_log::model::Runner;
use kinegen_analysis::model_on_log::run::{LandmarkObs, Run};
use kinegen_analysis::model_on_log::track_rows::{Heading, Recipe, Row, TrackRows};
use kinegen_model::ir::ModelIr;
use std::path::Path;
use std::sync::Arc;

fn load(ir: &Path) -> Runner {
    Runner::new(
        ModelIr::from_json(&std::fs::read_to_string(ir).unwrap()).unwrap(),
        &[],
    )
    .unwrap()
}

/// The bundled diff drive with a measurement delay and an off-centre tracker,
/// derived as a user's spec would be.
fn delayed_offset_diff_drive(dir: &Path) -> Runner {
    let root = common::root();
    let (a, b) = (dir.join("a.toml"), dir.join("b.toml"));
    let spec = root.join("spec/diff_drive.toml");
    for (from, effect, to) in [
        (spec.as_path(), "time_offset", a.as_path()),
        (a.as_path(), "sensor_offset", b.as_path()),
    ] {
        let o = common::kinegen(&[
            "add-effect",
            "--spec",
            from.to_str().unwrap(),
            "--effect",
            effect,
            "--out",
            to.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", common::stderr(&o));
    }
    let ir = dir.join("b.json");
    let o = common::kinegen(&[
        "derive",
        "--spec",
        b.to_str().unwrap(),
        "--ir-out",
        ir.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", common::stderr(&o));
    load(&ir)
}

fn bundled(model: &str) -> Runner {
    load(&common::root().join(format!("generated/ir/{model}.json")))
}

/// A random drive of `r` with landmarks observed along it.
fn log(r: &Runner) -> Run {
    let o = SimOptions {
        trajectory: Trajectory::Random,
        seed: 5,
        landmarks: vec![("a".into(), [3.0, 2.0]), ("b".into(), [-2.0, 4.0])],
        landmark_range: 100.0,
        ..SimOptions::default()
    };
    let sim = simulate(r, r, &o);
    let mut run = sim.to_run(r, "drive").unwrap();
    let at = |id: &str| o.landmarks.iter().find(|l| l.0 == id).unwrap().1;
    run.landmarks = sim
        .observations
        .iter()
        .map(|(t, id, range, bearing)| LandmarkObs {
            t: *t,
            id: id.as_str().into(),
            xl: at(id)[0],
            yl: at(id)[1],
            range: *range,
            bearing: *bearing,
        })
        .collect();
    run
}

fn rows(t: &dyn TrackRows, run: &Run) -> Vec<Row> {
    t.rows(run).collect()
}

/// Rows, metrics and innovations of `recipe` equal those of `computed`.
fn same(recipe: &Recipe, computed: &deadreckon::Track, run: &Run, what: &str) {
    let (a, b) = (rows(recipe, run), rows(computed, run));
    assert_eq!(a.len(), run.t.len(), "{what}");
    assert_eq!(a, b, "{what}: rows differ");
    let (a, b) = (
        [(run, recipe as &dyn TrackRows)],
        [(run, computed as &dyn TrackRows)],
    );
    let text = |x: &[(&Run, &dyn TrackRows)]| {
        format!(
            "{:?} {:?} {:?}",
            errors(x),
            where_it_fails(x),
            degenerate(x)
        )
    };
    assert_eq!(text(&a), text(&b), "{what}: metrics differ");
    let (ia, ib) = (
        innovations(recipe.r, &recipe.p, run, recipe),
        innovations(recipe.r, &recipe.p, run, computed),
    );
    assert_eq!(
        format!("{ia:?}"),
        format!("{ib:?}"),
        "{what}: innovations differ"
    );
}

#[test]
fn a_track_read_row_by_row_is_the_track_computed_at_once() {
    let dir = tempfile::tempdir().unwrap();
    let r = delayed_offset_diff_drive(dir.path());
    let run = log(&bundled("diff_drive"));
    assert!(!run.landmarks.is_empty() && run.gyro.is_some());
    let index = |name: &str| r.param_index(name).unwrap();
    // a delay of 3.5 rows either way, a tracker 0.2 m ahead and 0.05 m left
    for delay in [0.175, -0.175, 0.0] {
        let mut p = r.p.clone();
        p[index("time_offset")] = delay;
        p[index("sensor_dx")] = 0.2;
        p[index("sensor_dy")] = 0.05;
        let offset = [0.01, -0.02, 0.03];
        let recipe = Recipe {
            r: &r,
            p: p.clone(),
            offset,
            heading: Heading::Model,
        };
        let computed = deadreckon::run_from(&r, &p, &run, false, offset, None);
        same(&recipe, &computed, &run, &format!("delay {delay} s"));
    }

    // sub-stepped absolute steering inputs
    let caster = bundled("omni_caster");
    let run = log(&caster);
    assert!(run.swing.is_some());
    let recipe = Recipe {
        r: &caster,
        p: caster.p.clone(),
        offset: [0.0; 3],
        heading: Heading::Model,
    };
    let computed = deadreckon::run(&caster, &caster.p, &run, false);
    same(&recipe, &computed, &run, "omni_caster");

    // gyrodometry with the gyro, and with a learned yaw rate
    let dd = bundled("diff_drive");
    let run = log(&dd);
    let gyro = Recipe {
        r: &dd,
        p: dd.p.clone(),
        offset: [0.0; 3],
        heading: Heading::Gyro,
    };
    let computed = deadreckon::gyrodometry(&dd, &dd.p, &run).unwrap();
    same(&gyro, &computed, &run, "gyrodometry");
    let learned = |u: &[f64]| 0.3 * (u[0] - u[1]);
    let virtual_gyro = Recipe {
        heading: Heading::Learned(Arc::new(learned)),
        ..gyro
    };
    let computed = deadreckon::gyrodometry_with(&dd, &dd.p, &run, &|k| learned(&run.u[k])).unwrap();
    same(&virtual_gyro, &computed, &run, "learned yaw rate");
}
