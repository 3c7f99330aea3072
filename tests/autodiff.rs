//! The analysis's automatically differentiated IR against a fresh symbolic
//! derivation for every bundled spec, every robot in tests/user_specs and
//! every catalogue effect that applies to each (the committed IRs alone are
//! checked in verify/tests/autodiff.rs, where no symbolica is at hand), and
//! a spec only the automatic differentiation takes.
use kinegen_model::autodiff;
use kinegen_model::effects::catalogue;
use kinegen_model::ir::{ModelIr, StepForm};
use kinegen_model::spec::Model;
use kinegen_verify::crosscheck::autodiff_agrees;
use kinegen_verify::{run_all, IrKernel};
use std::path::{Path, PathBuf};

// symbolica derives on one thread under a machine-wide lock: scripts/test.sh runs this file's tests beside the others (`--skip symbolic_stage::` there), not alone
mod symbolic_stage {
    use super::*;

    fn specs() -> Vec<PathBuf> {
        let root = Path::new(env!("CARGO_MANIFEST_DIR"));
        let mut v = Vec::new();
        for dir in ["spec", "tests/user_specs"] {
            for e in std::fs::read_dir(root.join(dir)).unwrap() {
                let p = e.unwrap().path();
                if p.extension().is_some_and(|x| x == "toml") {
                    v.push(p);
                }
            }
        }
        v.sort();
        v
    }

    fn agree(label: &str, model: &Model) -> usize {
        let symbolic = kinegen_codegen::derive_model(model, &Default::default())
            .unwrap_or_else(|e| panic!("{label}: symbolic: {e}"));
        let ad = autodiff::derive(model, &Default::default())
            .unwrap_or_else(|e| panic!("{label}: autodiff: {e}"));
        let found = autodiff_agrees(&symbolic, &ad, 12, 11);
        for f in &found {
            assert!(
                f.passed(),
                "{label}: {} autodiff vs symbolic {} at {:?} ({})",
                f.function,
                f.ratio,
                f.entry,
                f.worst_input
            );
        }
        found.len()
    }

    #[test]
    fn every_spec_and_every_applicable_effect_agree_with_the_symbolic_stage() {
        let cat = catalogue(&[]).unwrap();
        let (mut models, mut kernels) = (0, 0);
        for path in specs() {
            let model = Model::load(&path).unwrap();
            let label = path.display().to_string();
            kernels += agree(&label, &model);
            models += 1;
            for effect in &cat {
                if let Ok(with) = effect.added_to(&model) {
                    kernels += agree(&format!("{label} with {}", effect.name), &with);
                    models += 1;
                }
            }
        }
        assert!(models > 60, "only {models} models were compared");
        eprintln!("{models} models, {kernels} kernels: autodiff agrees with the symbolic stage");
    }

    /// A piecewise deadband written with abs and sign, a saturating turn with
    /// atan and a power with a variable exponent: the analysis takes it, its
    /// Jacobians match finite differences, and where the symbolic stage takes
    /// it too the two agree.
    #[test]
    fn a_spec_with_kinks_and_variable_powers_works_in_analysis() {
        let text = r#"
name = "kinky"
state = ["x", "y", "theta"]
[[input]]
name = "v"
column = "v_cmd"
kind = "absolute"
[[input]]
name = "w"
column = "w_cmd"
kind = "absolute"
[[parameter]]
name = "band"
nominal = 0.05
min = 0.0
[[parameter]]
name = "expo"
nominal = 1.1
min = 0.5
max = 2.0
[[parameter]]
name = "w_max"
nominal = 2.0
min = 0.1
[motion]
vx = "sign(v)*(abs(v) - band + abs(abs(v) - band))/2"
vy = "0"
omega = "w_max*atan(w/w_max)*(1 + abs(v))^(expo - 1)"
"#;
        let model = Model::parse(Path::new("kinky.toml"), text).unwrap();
        let ad = autodiff::derive(&model, &Default::default()).unwrap();
        let report = run_all(&ad, &IrKernel, 32, 9);
        assert!(
            report.failures().is_empty(),
            "{:?}",
            report
                .failures()
                .iter()
                .map(|f| (&f.function, f.check, f.ratio))
                .collect::<Vec<_>>()
        );
        assert!(ad.step(StepForm::Exact).jac_p.is_some());
        if let Ok(symbolic) = kinegen_codegen::derive_model(&model, &Default::default()) {
            let found: Vec<_> = autodiff_agrees(&symbolic, &ad, 24, 4);
            assert!(found.iter().all(|f| f.passed()));
        }
    }

    /// The committed IRs are current, so the analysis of a bundled spec runs
    /// on the kernels `generate` emits; this only guards that the test above
    /// compared what it claims.
    #[test]
    fn committed_irs_exist_for_the_bundled_specs() {
        for path in specs()
            .iter()
            .filter(|p| p.parent().unwrap().ends_with("spec"))
        {
            let model = Model::load(path).unwrap();
            let ir = Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("generated/ir")
                .join(format!("{}.json", model.name));
            let ir = ModelIr::from_json(&std::fs::read_to_string(ir).unwrap()).unwrap();
            assert_eq!(ir.spec_fingerprint, model.fingerprint());
        }
    }
}
