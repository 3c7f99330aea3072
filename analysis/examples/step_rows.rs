//! The Rust side of the Python package's step benchmark
//! (python/examples/bench_step.py runs it in the same session): a spec's
//! exact step over N rows of state, input and time step, written as a Rust
//! user of the library writes it (derive once, then one `eval_into` a row),
//! in the build profile `pip install ./python` uses (dev).
//!
//! `cargo run -p kinegen-analysis --example step_rows -- SPEC ROWS REPS`
//! prints one JSON line: {"rows", "ns_per_row" (median over REPS), "checksum"}.
//! The inputs are the Python script's: x ~ N(0, 1), u ~ N(0, 3000), dt in
//! [0.01, 0.2), from the same seeded formula on both sides.
use kinegen_analysis::model_on_log::derivation::{AutodiffDeriver, Deriver};
use kinegen_analysis::model_on_log::model::Runner;
use kinegen_model::ir::StepForm;
use kinegen_model::spec::Model;
use std::time::Instant;

/// The k-th input of a row: a cheap deterministic sequence both sides
/// compute (the Python script writes the same formula in NumPy), so neither
/// times a random number generator.
fn input(k: usize, scale: f64) -> f64 {
    scale * ((k as f64 * 0.618_033_988_75).fract() - 0.5)
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let [_, spec, rows, reps] = &args[..] else {
        eprintln!("usage: step_rows SPEC ROWS REPS");
        std::process::exit(2);
    };
    let (n, reps): (usize, usize) = (rows.parse().unwrap(), reps.parse().unwrap());
    let model = Model::load(std::path::Path::new(spec)).unwrap_or_else(|e| {
        eprintln!("{e}");
        std::process::exit(2)
    });
    let ir = AutodiffDeriver
        .derive(&model, spec)
        .expect("the spec derives");
    let runner = Runner::new(ir, &[]).expect("a model");
    let f = runner.ir.step(StepForm::Exact).value;
    let nu = runner.ir.inputs.len();
    let x: Vec<f64> = (0..3 * n).map(|k| input(k, 2.0)).collect();
    let u: Vec<f64> = (0..nu * n).map(|k| input(k + 7, 6000.0)).collect();
    let dt: Vec<f64> = (0..n).map(|k| 0.105 + input(k + 3, 0.19)).collect();
    let zeros = vec![0.0; 16.max(runner.ir.noise.len())];
    let mut times = Vec::new();
    let mut out = vec![0.0; 3 * n];
    for _ in 0..reps {
        let started = Instant::now();
        let mut scratch = Vec::new();
        for r in 0..n {
            let d = [dt[r]];
            let args = Runner::step_args(
                f,
                &x[3 * r..3 * r + 3],
                &u[nu * r..nu * (r + 1)],
                &runner.p,
                &d,
                &zeros,
            );
            runner.eval_into(f, &args, &mut out[3 * r..3 * r + 3], &mut scratch);
        }
        times.push(started.elapsed().as_secs_f64() * 1e9 / n as f64);
    }
    times.sort_by(f64::total_cmp);
    let checksum: f64 = out.iter().sum();
    println!(
        "{{\"rows\": {n}, \"ns_per_row\": {:.2}, \"checksum\": {checksum:.9e}}}",
        times[times.len() / 2]
    );
}
