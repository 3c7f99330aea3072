//! `add_effect`, the one call of `kinegen add-effect`: the effect written
//! into the user's spec at the values given, and every refusal typed (the
//! command line's tests check the messages and the exit codes).
use kinegen_model::effects::{add_effect, AddEffect, AddEffectError, Added};
use std::path::{Path, PathBuf};

fn diff_drive() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../spec/diff_drive.toml")
}

fn add(spec: &Path, effect: &str, values: &[(&str, f64)]) -> Result<Added, AddEffectError> {
    let values: Vec<(String, f64)> = values.iter().map(|(n, v)| (n.to_string(), *v)).collect();
    add_effect(&AddEffect {
        spec,
        effect,
        values: &values,
        effect_dirs: &[],
    })
}

#[test]
fn an_effect_is_written_into_the_spec_at_the_values_given() {
    let added = add(&diff_drive(), "lateral_slip", &[("k_slip", 0.2)]).unwrap();
    assert!(added.source.contains("name = \"k_slip\"") && added.source.contains("0.2"));
    assert!(added.change.contains("k_slip"), "{}", added.change);
    // the spec written is valid and has the effect: adding it again is refused
    let path = std::env::temp_dir().join(format!("kinegen-add-effect-{}.toml", std::process::id()));
    std::fs::write(&path, &added.source).unwrap();
    let again = add(&path, "lateral_slip", &[]);
    std::fs::remove_file(&path).unwrap();
    assert!(matches!(again, Err(AddEffectError::AlreadyIn { .. })));
}

#[test]
fn bad_requests_are_refused_by_kind() {
    let spec = diff_drive();
    let refused = |effect: &str, values: &[(&str, f64)]| add(&spec, effect, values).err().unwrap();
    assert!(matches!(
        refused("no_such_effect", &[]),
        AddEffectError::Unknown(_)
    ));
    let twice = refused("lateral_slip", &[("k_slip", 0.1), ("k_slip", 0.2)]);
    assert!(matches!(twice, AddEffectError::ValueTwice { first, .. } if first == 0.1));
    let outside = refused("lateral_slip", &[("k_slip", 3.0)]);
    assert!(
        matches!(outside, AddEffectError::OutsideBounds { lo, hi, .. } if lo == -1.0 && hi == 1.0)
    );
    assert!(matches!(
        refused("lateral_slip", &[("k_slop", 0.1)]),
        AddEffectError::Values(_)
    ));
    let missing = add(Path::new("/nonexistent/spec.toml"), "lateral_slip", &[]);
    assert!(matches!(missing, Err(AddEffectError::Spec(_))));
}
