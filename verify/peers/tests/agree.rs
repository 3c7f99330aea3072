//! Every side of the peer benchmark computes the same outputs as kinegen's
//! kernels, row by row, on both sides of the series switch (the benchmark
//! checks this before timing; here it runs with the test suite, on simulated
//! driving, so that a peer or an adapter that writes the wrong place fails
//! CI rather than a benchmark run). And the check is not blind: a kernel
//! that is off by 1e-6 in one output fails it.
use kinegen_generated::diff_drive as dd;
use kinegen_peers::inputs::{samples, Motion};
use kinegen_peers::{disagreement, sides, Args, Kernel, Layout, Model, Row};

/// Motions at 50 Hz and over 1 s steps, turning at up to 2 rad/s: steps on
/// either side of the switch.
fn motions() -> Vec<Motion> {
    (0..400)
        .map(|k| {
            let f = k as f64 / 400.0;
            Motion {
                vx: 1.0 - 1.5 * f,
                vy: 0.3 * (7.0 * f).sin(),
                omega: 2.0 * (13.0 * f).cos(),
                dt: if k % 2 == 0 { 0.02 } else { 1.0 },
            }
        })
        .collect()
}

fn args_for(model: Model) -> (Vec<kinegen_peers::inputs::Sample>, Vec<Args>) {
    let s = samples(model, &motions(), 3);
    let a = s.iter().map(|x| x.args()).collect();
    (s, a)
}

#[test]
fn every_peer_build_agrees_with_kinegen_on_every_row() {
    let sides = sides();
    assert!(
        sides.len() >= 5,
        "kinegen twice, CasADi and wrenfold's two Rust builds at least"
    );
    for model in [Model::DiffDrive, Model::Unicycle, Model::OmniCaster] {
        let (samples, _) = args_for(model);
        if model != Model::Unicycle {
            let (series, closed) = samples
                .iter()
                .partition::<Vec<_>, _>(|s| s.turn.abs() <= 0.05);
            assert!(
                series.len() > 50 && closed.len() > 50,
                "{model:?}: both sides of the switch"
            );
        }
        for row in Row::ALL.into_iter().filter(|r| r.model() == model) {
            let reference = ((sides[0].kernel)(row).unwrap(), Layout::RowMajor);
            let args: Vec<Args> = (samples.iter())
                .filter(|s| row.agrees_at(s.turn))
                .map(|s| s.args())
                .collect();
            assert!(args.len() > 50, "{}: too few samples", row.label());
            for side in &sides[1..] {
                let Some(k) = (side.kernel)(row) else {
                    continue;
                };
                let worst = disagreement(row, reference, (k, side.layout), &args);
                assert!(
                    worst < 1e-9,
                    "{}: {} differs from kinegen by {worst:.1e}",
                    row.label(),
                    side.name
                );
            }
        }
    }
}

/// diff_drive's step with its y moved by 1e-6 m.
unsafe extern "C" fn step_off_by_a_micron(a: &Args, o: *mut f64) {
    let s = dd::step_exact(
        &*(a.x as *const [f64; 3]),
        &*(a.u as *const [f64; 2]),
        &*(a.w as *const [f64; 2]),
        &*(a.p as *const [f64; 5]),
        a.dt,
    );
    o.cast::<[f64; 3]>()
        .write_unaligned([s[0], s[1] + 1e-6, s[2]]);
}

#[test]
fn a_kernel_off_by_a_micron_is_caught() {
    let (_samples, args) = args_for(Model::DiffDrive);
    let good: Kernel = (sides()[0].kernel)(Row::DdStep).unwrap();
    let worst = disagreement(
        Row::DdStep,
        (good, Layout::RowMajor),
        (step_off_by_a_micron, Layout::RowMajor),
        &args,
    );
    assert!(worst > 1e-9, "a 1e-6 error went unseen ({worst:.1e})");
}

/// The bench reads each block's inputs before timing it through
/// `Args::touch` with `Model::lengths`: those must be what every sample of
/// the model holds, or the read would run past a sample's values.
#[test]
fn each_models_lengths_are_those_of_its_samples() {
    for model in [Model::DiffDrive, Model::Unicycle, Model::OmniCaster] {
        let [x, u, w, p, lm] = model.lengths();
        for s in samples(model, &motions(), 3) {
            let held = (s.x.len(), s.u.len(), s.w.len(), s.p.len());
            assert_eq!(held, (x, u, w, p), "{model:?}");
            assert!(lm <= s.lm.len(), "{model:?}");
        }
    }
}
