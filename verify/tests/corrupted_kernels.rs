//! The checks can fail: kernels with one deliberate mistake are caught, and the
//! report names the model, the function, the entry and the worst input.
use kinegen_model::ir::{Kernel, StepForm, Wrt};
use kinegen_verify::checks::{
    gyrodometry_consistency, inverse_round_trips, jacobians_vs_finite_differences, where_,
};
use kinegen_verify::{models, Corrupted, IrKernel};

#[test]
fn a_sign_flipped_derivative_term_is_reported_with_model_function_entry_and_input() {
    let ir = models::load("diff_drive");
    // d theta_next / d b of the exact step, entry (2, 2)
    let jac_p = Kernel::Step(StepForm::Exact, Some(Wrt::Params));
    let bad = Corrupted::flip_term(&ir, jac_p, 2 * 5 + 2);
    let found = jacobians_vs_finite_differences(&ir, &bad, 5, 3);
    let f = found.iter().find(|f| f.kernel == jac_p).unwrap();
    assert!(!f.passed(), "corruption not detected");
    let msg = where_(f);
    assert!(
        msg.contains("diff_drive::step_exact_jac_p entry (2, 2) d theta / d b"),
        "{msg}"
    );
    assert!(msg.contains("worst input x: [x="), "{msg}");
    // the uncorrupted functions still pass
    assert!(found
        .iter()
        .filter(|f| f.function != "step_exact_jac_p")
        .all(|f| f.passed()));
}

#[test]
fn a_wrong_sign_in_an_inverse_kinematics_row_is_reported() {
    for model in ["diff_drive", "omni3", "tricycle", "omni_caster"] {
        let ir = models::load(model);
        let bad = Corrupted::flip_term(&ir, Kernel::InverseTwist, 0);
        let found = inverse_round_trips(&ir, &bad, 10, 4);
        let f = found
            .iter()
            .find(|f| f.kernel == Kernel::InverseTwist)
            .unwrap();
        assert!(!f.passed(), "{model}: wrong IK sign not detected");
        assert!(
            where_(f).starts_with(&format!("{model}::inverse_twist entry")),
            "{}",
            where_(f)
        );
        assert!(inverse_round_trips(&ir, &IrKernel, 10, 4)
            .iter()
            .all(|f| f.passed()));
    }
}

#[test]
fn a_wrong_term_in_gyrodometry_is_reported() {
    for model in ["omni_caster", "diff_drive"] {
        let ir = models::load(model);
        for entry in 0..2 {
            let bad = Corrupted::flip_term(&ir, Kernel::TwistGyro, entry);
            let f = gyrodometry_consistency(&ir, &bad, 20, 5);
            // diff_drive's vy is identically 0: flipping its sign changes nothing
            if model == "diff_drive" && entry == 1 {
                assert!(f.passed());
                continue;
            }
            assert!(
                !f.passed(),
                "{model}: corrupted twist_gyro entry {entry} not detected"
            );
        }
        assert!(gyrodometry_consistency(&ir, &IrKernel, 20, 5).passed());
    }
}

/// Mutation sweep: flipping one term of ANY Jacobian entry that is not identically
/// zero, in any model, is caught by the finite-difference check.
#[test]
fn every_nonzero_jacobian_entry_is_guarded() {
    let mut missed = Vec::new();
    let mut tried = 0;
    for ir in models::all() {
        for f in ir
            .functions()
            .iter()
            .filter(|f| f.kernel.differentiates().is_some())
        {
            for entry in 0..f.outputs.len() {
                if matches!(f.tape[f.outputs[entry] as usize], kinegen_model::ir::Op::Const(c) if c == 0.0)
                {
                    continue; // structurally zero: nothing to corrupt
                }
                tried += 1;
                let bad = Corrupted::flip_term(&ir, f.kernel, entry);
                let found = jacobians_vs_finite_differences(&ir, &bad, 3, 8);
                if found
                    .iter()
                    .find(|x| x.kernel == f.kernel)
                    .unwrap()
                    .passed()
                {
                    missed.push(format!("{}::{} entry {entry}", ir.name, f.name));
                }
            }
        }
    }
    println!("{tried} corrupted entries tried, {} missed", missed.len());
    assert!(tried > 100);
    assert!(
        missed.is_empty(),
        "corruptions not caught:\n{}",
        missed.join("\n")
    );
}
