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
        for f in ir.functions() {
            let of = f.kernel.differentiates().map(|(of, _)| of);
            let covered = report
                .findings
                .iter()
                .any(|x| x.kernel == f.kernel || Some(x.kernel) == of);
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
        assert_eq!(found.len(), ir.functions().len());
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
    kinegen_generated::for_each_model!(check);
}

/// The fused kernels (`step_exact_linearized`, `step_exact_with_jac_p`,
/// `obs_*_linearized`) return every part exactly, to the last bit, as the part
/// alone does, on random inputs and on a zero input (the series branch of the
/// removable singularity).
#[test]
fn fused_kernels_equal_their_parts_bit_for_bit() {
    let mut seed = 0x9e37_79b9_7f4a_7c15u64;
    let mut rnd = move || {
        seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (seed >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    };
    // Debug prints a float's shortest round-trip form: equal text, equal bits
    fn bits(v: &impl std::fmt::Debug) -> String {
        format!("{v:?}")
    }
    fn arr<const N: usize>(f: &mut impl FnMut() -> f64, zero: bool) -> [f64; N] {
        core::array::from_fn(|_| if zero { 0.0 } else { f() })
    }
    macro_rules! steps {
        ($($m:ident),*) => {$({
            use kinegen_generated::$m as m;
            for k in 0..50 {
                let zero = k % 5 == 0;
                let x = arr(&mut rnd, false);
                let u = arr(&mut rnd, zero);
                let w = arr(&mut rnd, zero);
                let p = m::Params::NOMINAL.to_array();
                let dt = 0.05;
                let (a, b, c) = m::step_exact_linearized(&x, &u, &w, &p, dt);
                assert_eq!(bits(&a), bits(&m::step_exact(&x, &u, &w, &p, dt)), stringify!($m));
                assert_eq!(bits(&b), bits(&m::step_exact_jac_x(&x, &u, &w, &p, dt)));
                assert_eq!(bits(&c), bits(&m::step_exact_jac_w(&x, &u, &w, &p, dt)));
                let (a, b, c) = m::step_exact_with_jac_p(&x, &u, &w, &p, dt);
                assert_eq!(bits(&a), bits(&m::step_exact(&x, &u, &w, &p, dt)));
                assert_eq!(bits(&b), bits(&m::step_exact_jac_x(&x, &u, &w, &p, dt)));
                assert_eq!(bits(&c), bits(&m::step_exact_jac_p(&x, &u, &w, &p, dt)));
            }
        })*};
    }
    kinegen_generated::for_each_model!(steps);
    use kinegen_generated::diff_drive as m;
    for _ in 0..50 {
        let x = arr(&mut rnd, false);
        let u = arr(&mut rnd, false);
        let lm = arr(&mut rnd, false);
        let p = m::Params::NOMINAL.to_array();
        let (h, hx, hp) = m::obs_landmark_linearized(&x, &u, &p, &lm);
        assert_eq!(bits(&h), bits(&m::obs_landmark(&x, &u, &p, &lm)));
        assert_eq!(bits(&hx), bits(&m::obs_landmark_jac_x(&x, &u, &p, &lm)));
        assert_eq!(bits(&hp), bits(&m::obs_landmark_jac_p(&x, &u, &p, &lm)));
    }
}
