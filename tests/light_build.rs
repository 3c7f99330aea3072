//! The light build (`cargo build --no-default-features --bin kinegen`) has
//! no symbolica anywhere in its dependency tree, and neither have the
//! analysis and model crates in any build: the analysis differentiates by
//! itself (kinegen_model::autodiff). The full build has it (so this test can
//! fail).
use std::process::Command;

fn tree(args: &[&str]) -> String {
    let out = Command::new(env!("CARGO"))
        .args(["tree", "--locked", "-e", "normal", "--prefix", "none"])
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .expect("cargo tree runs");
    assert!(
        out.status.success(),
        "cargo tree {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).unwrap()
}

fn has_symbolica(tree: &str) -> bool {
    tree.lines().any(|l| l.starts_with("symbolica "))
}

#[test]
fn the_light_build_and_the_analysis_have_no_symbolica() {
    assert!(!has_symbolica(&tree(&[
        "-p",
        "kinegen",
        "--no-default-features"
    ])));
    for krate in [
        "kinegen-analysis",
        "kinegen-model",
        "kinegen-jit",
        "kinegen-verify",
        // the Python extension: what `pip install ./python` builds
        "kinegen-py",
    ] {
        assert!(
            !has_symbolica(&tree(&["-p", krate])),
            "{krate} reaches symbolica"
        );
    }
    assert!(
        has_symbolica(&tree(&["-p", "kinegen"])),
        "the full build should have symbolica: the check above would see nothing"
    );
}
