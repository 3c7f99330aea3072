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

/// The firmware API of every module: `Params` names the runtime parameters in
/// the order of `PARAMS`, `Params::NOMINAL` is `PARAM_NOMINAL`, and the array
/// round trip is exact (a field emitted out of order fails this).
#[test]
fn params_structs_match_the_parameter_arrays() {
    macro_rules! check {
        ($($m:ident),*) => {$({
            use kinegen_generated::$m as m;
            assert_eq!(m::Params::NOMINAL.to_array(), m::PARAM_NOMINAL, stringify!($m));
            let p: [f64; m::PARAMS.len()] = core::array::from_fn(|i| 1.0 + i as f64);
            assert_eq!(m::Params::from_array(&p).to_array(), p, stringify!($m));
            let dbg = format!("{:?}", m::Params::from_array(&p));
            // fields in the order of PARAMS, each with its value
            let mut at = 0;
            for (i, name) in m::PARAMS.iter().enumerate() {
                let field = format!("{name}: {:?}", p[i]);
                let found = dbg[at..].find(&field).unwrap_or_else(|| panic!("{}: {field} in {dbg}", stringify!($m)));
                at += found + field.len();
            }
        })*};
    }
    check!(
        diff_drive,
        tricycle,
        tricycle_fwd,
        omni3,
        omni_caster,
        unicycle_ekf
    );
}
