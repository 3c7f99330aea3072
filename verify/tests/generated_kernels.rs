//! Every function of every generated model: all checks, against the compiled
//! kernels, plus compiled kernels == IR evaluator.
use kinegen_verify::checks::{kernels_agree, where_};
use kinegen_verify::{models, run_all, Generated, IrKernel};

const SAMPLES: usize = 200;

#[test]
fn every_generated_kernel_passes_every_check() {
    let mut failures = Vec::new();
    for ir in models::all() {
        let report = run_all(&ir, &Generated(ir.name.clone()), SAMPLES, 11);
        println!("== {}\n{}", ir.name, report.table());
        // every function is covered by at least one check
        for f in &ir.functions {
            let covered = report.findings.iter().any(|x| {
                x.function == f.name || x.function == f.name.split("_jac_").next().unwrap()
            });
            assert!(
                covered,
                "{}::{} is not covered by any check",
                ir.name, f.name
            );
        }
        failures.extend(
            report
                .failures()
                .into_iter()
                .map(|f| format!("{}: {}", f.check, where_(f))),
        );
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn generated_rust_matches_the_ir_evaluator() {
    for ir in models::all() {
        let found = kernels_agree(&ir, &Generated(ir.name.clone()), &IrKernel, SAMPLES, 5);
        assert_eq!(found.len(), ir.functions.len());
        for f in &found {
            assert!(f.passed(), "{}: max rel err {:e}", where_(f), f.max_err);
        }
    }
}
