//! Fuzzing the automatic differentiation (issue 71): random expressions of
//! the spec language as a model's twist and observation. Whatever the
//! expressions, deriving never panics; every kernel evaluates without
//! panicking; and where the functions are smooth at the point, every
//! Jacobian of the exact step and of the observation agrees with central
//! differences of the kernel it differentiates.
//!
//! Bounded in time for CI: cases stop being checked after
//! `KINEGEN_FUZZ_SECONDS` (default 20) seconds; `PROPTEST_CASES` raises the
//! number of cases for a longer local run.
use kinegen_model::autodiff;
use kinegen_model::ir::{ArgRole, Function, Kernel, ModelIr, StepForm, Wrt};
use kinegen_model::spec::Model;
use proptest::prelude::*;
use std::path::Path;
use std::time::{Duration, Instant};

/// A random expression in `vars`, as spec text. `smooth`: no kinks (abs,
/// sign), so finite differences are a fair reference.
fn expr(vars: &'static [&'static str], smooth: bool) -> impl Strategy<Value = String> {
    let leaf = prop_oneof![
        prop::sample::select(vars).prop_map(str::to_string),
        (-2.0f64..2.0).prop_map(|c| format!("{c:.3}")),
    ];
    leaf.prop_recursive(3, 24, 2, move |inner| {
        let unary: Vec<&'static str> = if smooth {
            vec![
                "sin({})",
                "cos({})",
                "atan({})",
                "exp({}/4)",
                "sqrt(1 + ({})^2)",
                "ln(2 + sin({}))",
                "tan(atan({})/2)",
                "-({})",
            ]
        } else {
            vec!["abs({})", "sign({})*({})", "sin({})", "({})^3"]
        };
        prop_oneof![
            (prop::sample::select(unary), inner.clone()).prop_map(|(f, a)| f.replace("{}", &a)),
            (inner.clone(), inner.clone(), 0..6usize).prop_map(|(a, b, op)| match op {
                0 => format!("({a}) + ({b})"),
                1 => format!("({a}) - ({b})"),
                2 => format!("({a})*({b})"),
                3 => format!("({a})/(1 + ({b})^2)"),
                4 => format!("atan2({a}, 2 + cos({b}))"),
                _ => format!("(1.5 + sin({a}))^({b})"),
            }),
        ]
    })
}

fn spec(twist: [&str; 3], obs: &str) -> String {
    format!(
        r#"name = "fuzzed"
state = ["x", "y", "theta"]
[[input]]
name = "v"
column = "v"
kind = "absolute"
[[input]]
name = "w"
column = "w"
kind = "absolute"
[[parameter]]
name = "k"
nominal = 0.7
[[parameter]]
name = "c"
nominal = -0.4
[[noise]]
name = "n"
sigma = 0.1
[motion]
vx = "{}"
vy = "{}"
omega = "{} + n"
[[observation]]
name = "seen"
columns = ["s"]
expr = ["{obs}"]
sigma = [0.1]
"#,
        twist[0], twist[1], twist[2]
    )
}

/// The arguments of `f` at one point.
fn args(f: &Function, x: &[f64; 3], u: &[f64; 2], p: &[f64; 2], dt: f64) -> Vec<Vec<f64>> {
    f.args
        .iter()
        .map(|a| match a.role {
            ArgRole::State => x.to_vec(),
            ArgRole::Inputs => u.to_vec(),
            ArgRole::Params => p.to_vec(),
            ArgRole::Dt => vec![dt],
            _ => vec![0.0; a.names.len()],
        })
        .collect()
}

fn eval(f: &Function, a: &[Vec<f64>]) -> Vec<f64> {
    let refs: Vec<&[f64]> = a.iter().map(|v| &v[..]).collect();
    f.interpret(&refs)
}

/// Every Jacobian of `value` (the kernels `jacobians` name) against central
/// differences at the point; None where the point is not a fair one (a
/// non-finite or huge value nearby).
fn check(
    ir: &ModelIr,
    value: Kernel,
    x: &[f64; 3],
    u: &[f64; 2],
    p: &[f64; 2],
) -> Result<(), String> {
    let f = ir.kernel(value).unwrap();
    for w in [Wrt::State, Wrt::Inputs, Wrt::Params] {
        let Some(j) = ir.kernel(value.jacobian(w)) else {
            continue;
        };
        let a = args(j, x, u, p, 0.1);
        let jac = eval(j, &a);
        let col_of = f.arg(w.role()).unwrap();
        for c in 0..j.cols {
            let h = 1e-6 * (1.0 + a[col_of][c].abs());
            let at = |s: f64| {
                let mut b = a.clone();
                b[col_of][c] += s;
                eval(f, &b)
            };
            let (hi, lo) = (at(h), at(-h));
            for r in 0..j.rows {
                let fd = (hi[r] - lo[r]) / (2.0 * h);
                let an = jac[r * j.cols + c];
                if !fd.is_finite() || fd.abs() > 1e6 || !an.is_finite() {
                    continue; // not a fair point for a finite difference
                }
                if (an - fd).abs() > 1e-4 * (1.0 + fd.abs()) {
                    return Err(format!("{} ({r}, {c}): {an} against {fd}", j.name));
                }
            }
        }
    }
    Ok(())
}

fn out_of_time() -> bool {
    static START: std::sync::OnceLock<Instant> = std::sync::OnceLock::new();
    let limit = std::env::var("KINEGEN_FUZZ_SECONDS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(20.0);
    START.get_or_init(Instant::now).elapsed() > Duration::from_secs_f64(limit)
}

const TWIST_VARS: &[&str] = &["v", "w", "k", "c"];
const OBS_VARS: &[&str] = &["x", "y", "theta", "k", "v"];

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]

    #[test]
    fn smooth_random_models_differentiate_as_finite_differences_say(
        vx in expr(TWIST_VARS, true),
        vy in expr(TWIST_VARS, true),
        om in expr(TWIST_VARS, true),
        obs in expr(OBS_VARS, true),
        point in prop::array::uniform7(-1.5f64..1.5),
    ) {
        if out_of_time() {
            return Ok(());
        }
        let text = spec([&vx, &vy, &om], &obs);
        // an exponent beyond the language's bound is refused by the parser
        // (its own fuzz test checks that): not a model to differentiate
        let Ok(model) = Model::parse(Path::new("fuzzed.toml"), &text) else {
            return Ok(());
        };
        let ir = match autodiff::derive(&model, &Default::default()) {
            Ok(ir) => ir,
            // a located refusal (a constant that folds to infinity) is fine
            Err(e) => { prop_assert!(e.pos.is_some() || !e.message.is_empty()); return Ok(()); }
        };
        let [a, b, c, d, e, f, g] = point;
        let (x, u, p) = ([a, b, c], [d, e], [0.7 + 0.3 * f, -0.4 + 0.3 * g]);
        let r = check(&ir, Kernel::Step(StepForm::Exact, None), &x, &u, &p)
            .and_then(|_| check(&ir, Kernel::Observation(0, None), &x, &u, &p));
        prop_assert!(r.is_ok(), "{}\n{}", r.unwrap_err(), text);
    }

    #[test]
    fn kinked_random_models_derive_and_evaluate_without_panicking(
        vx in expr(TWIST_VARS, false),
        om in expr(TWIST_VARS, false),
        obs in expr(OBS_VARS, false),
        point in prop::array::uniform7(-1.5f64..1.5),
    ) {
        if out_of_time() {
            return Ok(());
        }
        let text = spec([&vx, "0", &om], &obs);
        // an exponent beyond the language's bound is refused by the parser
        // (its own fuzz test checks that): not a model to differentiate
        let Ok(model) = Model::parse(Path::new("fuzzed.toml"), &text) else {
            return Ok(());
        };
        if let Ok(ir) = autodiff::derive(&model, &Default::default()) {
            let [a, b, c, d, e, f, g] = point;
            for func in ir.functions() {
                let v = eval(func, &args(func, &[a, b, c], &[d, e], &[f, g], 0.1));
                prop_assert_eq!(v.len(), func.rows * func.cols);
            }
        }
    }
}
