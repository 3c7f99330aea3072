//! Focused emitter fixtures: one tiny spec per emitter feature
//! (`tests/fixtures/*.toml`) and the expected source of the kernels that show
//! it, reviewed as insta snapshots. The bundled models' whole modules are not
//! snapshotted here: `generated/` is committed and `kinegen generate --check`
//! guards it.
use kinegen_codegen::emit::{Backend, RustBackend};
use kinegen_model::spec::Model;

/// The source of `pub fn name(` through its closing brace in `module`.
fn function(module: &str, name: &str) -> String {
    let start = module
        .find(&format!("pub fn {name}("))
        .unwrap_or_else(|| panic!("no `{name}` in the emitted module"));
    // back to the doc comment above the function
    let head = module[..start].rfind("/**").unwrap_or(start);
    let end = start + module[start..].find("\n}\n").expect("closing brace") + 2;
    module[head..end].to_string()
}

fn emitted(fixture: &str) -> String {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(format!("{fixture}.toml"));
    let model = Model::load(&path).unwrap();
    let ir = kinegen_codegen::derive_model(&model, &Default::default()).unwrap();
    RustBackend.module(&ir, &format!("{fixture}.toml")).1
}

#[test]
fn emitter_features() {
    // (fixture, kernels that show its feature)
    let cases: [(&str, &[&str]); 4] = [
        // the series branch, computed only where its guard holds
        ("series", &["step_exact"]),
        // the least-squares twist through the closed-form 3x3 pseudo-inverse
        ("least_squares", &["twist"]),
        // x^5 as multiplications, a shared reciprocal, 2*pi folded
        ("powers_keyword", &["twist"]),
        // the landmark argument and a fused linearized observation
        ("landmark", &["obs_beacon", "obs_beacon_linearized"]),
    ];
    for (fixture, kernels) in cases {
        let module = emitted(fixture);
        for k in kernels {
            insta::assert_snapshot!(format!("{fixture}__{k}"), function(&module, k));
        }
        if fixture == "powers_keyword" {
            // a parameter named by a keyword is a raw identifier in Params
            assert!(module.contains("pub r#type: crate::Real"), "{module}");
        }
    }
}
