//! `cargo bench -p kinegen-analysis --bench speed`
//!
//! 1. The IR evaluator against the compiled generated kernel on the same inputs
//!    (diff_drive and omni_caster step_exact and step_exact_jac_p): ns per call
//!    and their ratio.
//! 2. Calibration of a 1,000,000-sample diff_drive log: samples per second.
//!
//! (Diagnosis time per candidate is printed by `kinegen diagnose` itself, which
//! needs the CLI to derive the augmented models.)
//! Figures are medians of repeated runs in this process; ratios compare numbers
//! measured in the same run.
use kinegen_analysis::dataset::Run;
use kinegen_analysis::fit::{fit, FitOptions};
use kinegen_analysis::model::Runner;
use kinegen_model::ir::ModelIr;
use rand::{Rng, SeedableRng};
use std::hint::black_box;
use std::time::Instant;

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Median ns per call of `ir` and `generated` over `n` inputs (repeated `reps`
/// times, interleaved so both see the same machine state); prints the ratio.
fn time_pair(
    label: &str,
    n: usize,
    reps: usize,
    mut ir: impl FnMut(usize),
    mut generated: impl FnMut(usize),
) {
    let (mut t_ir, mut t_gen) = (Vec::new(), Vec::new());
    for _ in 0..reps {
        let t0 = Instant::now();
        (0..n).for_each(&mut ir);
        t_ir.push(t0.elapsed().as_secs_f64() / n as f64);
        let t0 = Instant::now();
        (0..n).for_each(&mut generated);
        t_gen.push(t0.elapsed().as_secs_f64() / n as f64);
    }
    let (a, b) = (median(t_ir), median(t_gen));
    println!("{label:<30} IR evaluator {:>9.1} ns/call, generated kernel {:>8.1} ns/call, ratio IR/generated {:.1}x", a * 1e9, b * 1e9, a / b);
}

fn ir() -> ModelIr {
    let p = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../generated/ir/diff_drive.json"
    );
    ModelIr::from_json(&std::fs::read_to_string(p).unwrap()).unwrap()
}

/// A synthetic log: smooth random wheel rates, ground truth from the model with
/// perturbed parameters plus motion-capture noise.
fn log(r: &Runner, n: usize, seed: u64) -> Run {
    let mut rng = rand::rngs::SmallRng::seed_from_u64(seed);
    let dt = 0.05;
    let (mut a, mut b) = (0.0f64, 0.0f64);
    let u: Vec<Vec<f64>> = (0..n - 1)
        .map(|k| {
            let t = k as f64 * dt;
            a = 3000.0 + 1500.0 * (0.05 * t).sin() + rng.gen_range(-50.0..50.0);
            b = 3000.0 + 1500.0 * (0.031 * t + 1.0).sin() + rng.gen_range(-50.0..50.0);
            vec![a, b]
        })
        .collect();
    let mut truth = r.clone();
    truth.p[0] *= 1.01;
    truth.p[2] *= 1.02;
    let mut run = Run {
        name: "bench".into(),
        path: "bench".into(),
        t: (0..n).map(|k| k as f64 * dt).collect(),
        dt: vec![dt; n - 1],
        u,
        gt: None,
        gyro: None,
        landmarks: Vec::new(),
        rate_inputs: Vec::new(),
    };
    let track = kinegen_analysis::deadreckon::run(&truth, &truth.p, &run, false);
    run.gt = Some(
        track
            .pose
            .iter()
            .map(|p| {
                [
                    p[0] + rng.gen_range(-1e-3..1e-3),
                    p[1] + rng.gen_range(-1e-3..1e-3),
                    p[2] + rng.gen_range(-2e-3..2e-3),
                ]
            })
            .collect(),
    );
    run
}

/// A generated step kernel: (x, u, w, p, dt) -> R.
type Kernel<const U: usize, const W: usize, const P: usize, R> =
    fn(&[f64; 3], &[f64; U], &[f64; W], &[f64; P], f64) -> R;

/// The IR evaluator against the generated `step_exact` and `step_exact_jac_p` of
/// one model, on the same (x, u) inputs. For the least-squares model the IR
/// evaluator decomposes each pseudo-inverse once per call (cache), the generated
/// code once per matrix too.
fn ir_vs_generated<const U: usize, const W: usize, const P: usize>(
    model: &str,
    ir: &ModelIr,
    p: &[f64; P],
    inputs: &[([f64; 3], [f64; U])],
    reps: usize,
    step: Kernel<U, W, P, [f64; 3]>,
    jac_p: Kernel<U, W, P, [[f64; P]; 3]>,
) {
    let w = [0.0; W];
    for name in ["step_exact", "step_exact_jac_p"] {
        let f = ir.function(name).unwrap();
        let mut out = vec![0.0; f.rows * f.cols];
        let mut scratch = Vec::new();
        time_pair(
            &format!("{model} {name}"),
            inputs.len(),
            reps,
            |k| {
                let (x, u) = &inputs[k];
                f.eval_into(&[x, u, &w, p, &[0.05]], &mut out, &mut scratch);
                black_box(&out);
            },
            |k| {
                let (x, u) = &inputs[k];
                if name == "step_exact" {
                    black_box(step(black_box(x), u, &w, p, 0.05));
                } else {
                    black_box(jac_p(black_box(x), u, &w, p, 0.05));
                }
            },
        );
    }
}

fn omni_caster_kernels() {
    use kinegen_generated::omni_caster;
    let p = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../generated/ir/omni_caster.json"
    );
    let ir = ModelIr::from_json(&std::fs::read_to_string(p).unwrap()).unwrap();
    let mut rng = rand::rngs::SmallRng::seed_from_u64(3);
    let inputs: Vec<([f64; 3], [f64; 9])> = (0..20_000)
        .map(|_| {
            (
                [
                    rng.gen_range(-5.0..5.0),
                    rng.gen_range(-5.0..5.0),
                    rng.gen_range(-3.0..3.0),
                ],
                std::array::from_fn(|i| {
                    if i < 3 {
                        rng.gen_range(-1.0..1.0)
                    } else {
                        rng.gen_range(-5.0..5.0)
                    }
                }),
            )
        })
        .collect();
    ir_vs_generated::<9, 3, 12>(
        "omni_caster",
        &ir,
        &omni_caster::PARAM_NOMINAL,
        &inputs,
        5,
        omni_caster::step_exact,
        omni_caster::step_exact_jac_p,
    );
}

fn main() {
    let ir = ir();
    let r = Runner::new(ir.clone(), &[]).unwrap();
    let n_calls = 200_000;
    let inputs: Vec<([f64; 3], [f64; 2])> = {
        let mut rng = rand::rngs::SmallRng::seed_from_u64(1);
        (0..n_calls)
            .map(|_| {
                (
                    [
                        rng.gen_range(-5.0..5.0),
                        rng.gen_range(-5.0..5.0),
                        rng.gen_range(-3.0..3.0),
                    ],
                    [
                        rng.gen_range(-4000.0..4000.0),
                        rng.gen_range(-4000.0..4000.0),
                    ],
                )
            })
            .collect()
    };
    let p: [f64; 5] = r.p.clone().try_into().unwrap();
    ir_vs_generated::<2, 2, 5>(
        "diff_drive",
        &ir,
        &p,
        &inputs,
        7,
        kinegen_generated::diff_drive::step_exact,
        kinegen_generated::diff_drive::step_exact_jac_p,
    );

    omni_caster_kernels();

    let n = 1_000_000;
    let run = log(&r, n, 2);
    let o = FitOptions::default();
    let mut times = Vec::new();
    let mut last = None;
    for _ in 0..3 {
        let t0 = Instant::now();
        last = Some(fit(&r, std::slice::from_ref(&run), &o).unwrap());
        times.push(t0.elapsed().as_secs_f64());
    }
    let res = last.unwrap();
    let t = median(times);
    println!(
        "fit on a {n}-sample diff_drive log: {t:.2} s ({:.0} samples/s, {} LM iterations, b = {:.5} for a true {:.5})",
        n as f64 / t,
        res.iterations,
        res.p[2],
        r.p[2] * 1.02
    );
}
