//! The generation options are a value: derivation builds the series branches
//! of removable singularities with the switch and order it is given, the
//! emitter writes that switch, and verification probes the switch the IR
//! carries, so a poor choice is caught rather than assumed.
use kinegen_codegen::emit::{Backend, RustBackend};
use kinegen_model::ir::{Kernel, ModelIr, StepForm};
use kinegen_model::options::GenOptions;
use kinegen_model::spec::Model;
use kinegen_verify::checks::singularities;
use kinegen_verify::IrKernel;

fn derived(series_switch: f64, series_order: i64) -> ModelIr {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("spec/diff_drive.toml");
    let model = Model::load(&path).unwrap();
    let options = GenOptions {
        series_switch,
        series_order,
    };
    kinegen_codegen::derive_model(&model, &options).unwrap()
}

#[test]
fn the_series_switch_and_order_given_are_the_ones_derived_emitted_and_verified() {
    let ir = derived(0.1, 8);
    let exact = ir
        .functions()
        .iter()
        .find(|f| f.kernel == Kernel::Step(StepForm::Exact, None))
        .unwrap();
    assert_eq!(exact.series_switches(), vec![0.1]);
    let source = RustBackend.module(&ir, "diff_drive.toml").1;
    assert!(source.contains("series_switch(0.1)"), "emitted switch");
    assert!(
        !source.contains("series_switch(0.05)"),
        "the default leaked"
    );
    let found = singularities(&ir, &IrKernel, 20, 1);
    assert!(!found.is_empty());
    for f in &found {
        assert!(f.passed(), "{}: {}", f.function, f.ratio);
    }
}

#[test]
fn a_series_too_short_for_its_switch_fails_verification() {
    // first order at 0.3 rad: the series and the closed form differ by
    // about s^2/6 ~ 1.5% at the switch, a jump the continuity probe sees
    let ir = derived(0.3, 1);
    let found = singularities(&ir, &IrKernel, 20, 1);
    assert!(
        found.iter().any(|f| !f.passed()),
        "a 1st-order series switched at 0.3 passed verification"
    );
}
