//! The automatically differentiated IR (what the analysis runs on) against
//! the committed symbolic IR of every bundled spec, and both against finite
//! differences; a deliberately wrong derivative on either side is caught.
//! (Specs without a committed IR, and every catalogue effect, are held to a
//! fresh symbolic derivation in the workspace's `tests/autodiff.rs`.)
use kinegen_model::autodiff;
use kinegen_model::ir::{Kernel, ModelIr, Op, StepForm, Wrt};
use kinegen_model::spec::Model;
use kinegen_verify::crosscheck::autodiff_agrees;
use kinegen_verify::{run_all, IrKernel};
use std::path::{Path, PathBuf};

fn bundled() -> Vec<(PathBuf, ModelIr)> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let mut out = Vec::new();
    for entry in std::fs::read_dir(root.join("spec")).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "toml") {
            let model = Model::load(&path).unwrap();
            let ir_path = root
                .join("generated/ir")
                .join(format!("{}.json", model.name));
            let ir = ModelIr::from_json(&std::fs::read_to_string(ir_path).unwrap()).unwrap();
            assert_eq!(
                ir.spec_fingerprint,
                model.fingerprint(),
                "stale IR of {}",
                path.display()
            );
            out.push((path, ir));
        }
    }
    assert!(out.len() >= 6, "the bundled specs were not found");
    out
}

fn ad(path: &Path) -> ModelIr {
    autodiff::derive(&Model::load(path).unwrap(), &Default::default()).unwrap()
}

#[test]
fn autodiff_agrees_with_the_symbolic_ir_of_every_bundled_spec() {
    for (path, symbolic) in bundled() {
        let ad = ad(&path);
        let found = autodiff_agrees(&symbolic, &ad, 40, 3);
        let compared = found.len();
        // every kernel but the inverse kinematics
        let expected = symbolic
            .functions()
            .iter()
            .filter(|f| !matches!(f.kernel, Kernel::InverseTwist | Kernel::InverseIncrement))
            .count();
        assert_eq!(compared, expected, "{}: kernels compared", symbolic.name);
        for f in &found {
            assert!(
                f.passed(),
                "{} {}: {} at {:?} ({})",
                f.model,
                f.function,
                f.ratio,
                f.entry,
                f.worst_input
            );
        }
    }
}

#[test]
fn the_autodiff_ir_passes_every_property_check() {
    for (path, _) in bundled() {
        let ir = ad(&path);
        let report = run_all(&ir, &IrKernel, 24, 5);
        let failures = report.failures();
        assert!(
            failures.is_empty(),
            "{}: {:?}",
            ir.name,
            failures
                .iter()
                .map(|f| (&f.function, f.check, f.ratio))
                .collect::<Vec<_>>()
        );
    }
}

/// One derivative rule gone wrong in a Jacobian's tape: the first cosine
/// becomes a sine (what d sin = -cos would do with its sign lost is caught
/// the same way).
fn broken_rule(ir: &ModelIr, kernel: Kernel) -> ModelIr {
    let mut file: kinegen_model::ir::IrFile = ir.clone().into();
    let f = file
        .functions
        .iter_mut()
        .find(|f| f.kernel == kernel)
        .expect("the kernel");
    let at = f
        .tape
        .iter()
        .position(|o| matches!(o, Op::Cos(_)))
        .expect("a cosine to break");
    if let Op::Cos(a) = f.tape[at] {
        f.tape[at] = Op::Sin(a);
    }
    ModelIr::try_from(file).unwrap()
}

#[test]
fn a_wrong_derivative_on_either_side_fails_the_cross_check() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let (path, symbolic) = bundled()
        .into_iter()
        .find(|(p, _)| p.ends_with("diff_drive.toml"))
        .unwrap();
    let ad = ad(&path);
    let _ = root;
    for kernel in [
        Kernel::Step(StepForm::Exact, Some(Wrt::Params)),
        Kernel::Step(StepForm::Euler, Some(Wrt::State)),
    ] {
        for (side, sym, auto) in [
            ("autodiff", symbolic.clone(), broken_rule(&ad, kernel)),
            ("symbolic", broken_rule(&symbolic, kernel), ad.clone()),
        ] {
            let found = autodiff_agrees(&sym, &auto, 20, 3);
            let bad = found.iter().find(|f| f.kernel == kernel).unwrap();
            assert!(
                !bad.passed(),
                "a broken {side} {kernel:?} passed ({})",
                bad.ratio
            );
            assert!(
                found
                    .iter()
                    .filter(|f| f.kernel != kernel)
                    .all(|f| f.passed()),
                "only the broken kernel fails"
            );
        }
    }
}
