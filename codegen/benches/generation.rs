//! `cargo bench -p kinegen-codegen --bench generation`: time to derive every
//! bundled spec and render its Rust (what `kinegen generate` does, writing
//! nothing: `--check` mode), median of 5 runs after one warm-up, against
//! issue #13's target of 2 s; and each model's share.
use std::path::Path;

const RUNS: usize = 5;
const TARGET_S: f64 = 2.0;

fn main() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let (spec, out) = (root.join("spec"), root.join("generated"));
    let run = || {
        kinegen_codegen::generate::generate(&kinegen_codegen::generate::Config::new(
            &spec, &out, true,
        ))
        .expect("the bundled specs generate")
    };
    run(); // warm-up: symbolica's thread and its symbol table
    let mut reports: Vec<_> = (0..RUNS).map(|_| run()).collect();
    reports.sort_by_key(|r| r.total);
    let median = &reports[RUNS / 2];
    for (ir, took) in &median.models {
        println!("{:<16} {:>8.3} s", ir.name, took.as_secs_f64());
    }
    let total = median.total.as_secs_f64();
    println!(
        "generation of all {} bundled specs: {:.3} s (median of {RUNS}), {:.2} of the {TARGET_S} s target",
        median.models.len(),
        total,
        total / TARGET_S
    );
    if !median.stale.is_empty() {
        println!(
            "note: {} generated file(s) differ from what the specs give (run `kinegen generate`)",
            median.stale.len()
        );
    }
}
