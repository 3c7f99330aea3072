//! The light build (`cargo build --no-default-features --bin kinegen`) has
//! no symbolica anywhere in its dependency tree, and neither have the
//! analysis and model crates in any build: the analysis differentiates by
//! itself (kinegen_model::autodiff). The full build has it (so this test can
//! fail).
use std::process::Command;

fn tree(args: &[&str]) -> String {
    cargo_tree(&[&["-e", "normal"], args].concat())
}

/// `cargo tree --locked --prefix none ARGS` in the workspace.
fn cargo_tree(args: &[&str]) -> String {
    let out = Command::new(env!("CARGO"))
        .args(["tree", "--locked", "--prefix", "none"])
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

/// Each dependency's feature sets, as `cargo tree -f "{p} [{f}]"` prints
/// them: (name version) -> every set it is built with (host and target).
fn feature_sets(args: &[&str]) -> std::collections::BTreeMap<String, Vec<String>> {
    let text = cargo_tree(&[&["-f", "{p} [{f}]"], args].concat());
    let mut sets: std::collections::BTreeMap<String, Vec<String>> = Default::default();
    for line in text.lines() {
        let Some((package, features)) = line.split_once(" [") else {
            continue;
        };
        let mut words = package.split_whitespace();
        let name = format!(
            "{} {}",
            words.next().unwrap_or(""),
            words.next().unwrap_or("")
        );
        let features = features.trim_end_matches([']', ')', '*', ' ', '(']);
        let set = sets.entry(name).or_default();
        if !set.iter().any(|f| f == features) {
            set.push(features.to_string());
        }
    }
    sets
}

/// `pip install ./python` (maturin: `-p kinegen-py` alone) resolves each
/// shared dependency with the features `cargo build --workspace` gave it,
/// so it reuses that build instead of compiling cranelift, the analysis and
/// pyo3 a second time (148 s of the test command on a fresh clone). The
/// features python/Cargo.toml turns on for that must follow the workspace:
/// a dependency whose set differs is named here.
#[test]
fn the_python_package_builds_with_the_workspaces_features() {
    let python = feature_sets(&["-p", "kinegen-py", "-e", "normal,build"]);
    let workspace = feature_sets(&["--workspace", "-e", "normal,build,dev"]);
    let differ: Vec<String> = (python.iter())
        .flat_map(|(name, sets)| {
            let theirs = workspace.get(name).cloned().unwrap_or_default();
            (sets.iter())
                .filter(move |s| !theirs.contains(s))
                .map(move |s| format!("{name} [{s}]"))
        })
        .collect();
    assert!(
        differ.is_empty(),
        "built with other features by `-p kinegen-py` than by the workspace (turn on the workspace's in python/Cargo.toml):\n{}",
        differ.join("\n")
    );
}
