//! Proposals beyond the catalogue on the range-bearing sensor (issue 70,
//! item 2's observation kind), through the recovery benchmark's library
//! call: a camera whose focal length is taken wrong (an effect written for
//! the test, `tests/proposal_effects/camera_focal_error.toml`, not in the
//! catalogue nor in the proposal library) gets a proposal on the sightings
//! that removes at least half of the held-out loss the true effect removes;
//! clean logs with sightings, and logs whose only sensor error is the
//! catalogue's `range_scale`, get none.
use kinegen_analysis::applications::diagnose_bench::{bench, Settings};
use kinegen_analysis::model_on_log::derivation::AutodiffDeriver;
use kinegen_model::spec::Model;
use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

#[test]
fn a_camera_focal_length_taken_wrong_gets_a_proposal_on_the_sightings() {
    let spec = Model::load(&root().join("spec/diff_drive.toml")).unwrap();
    let settings = Settings {
        seeds: 1,
        laps: 1,
        shard: None,
        effects: vec!["camera_focal_error".into(), "range_scale".into()],
        beyond: vec![root().join("tests/proposal_effects")],
    };
    let table = bench(&[spec], &settings, &AutodiffDeriver, &|f| panic!("{f}")).unwrap();
    let m = &table.models[0];
    // 3 magnitudes x 2 noise levels of the focal length, each recovered
    assert_eq!(m.beyond_recovered.of, 6, "{m:?}");
    assert!(m.beyond_recovered.found >= 5, "{m:?}");
    // 4 clean logs and 6 of range_scale: no proposal on any
    assert_eq!(m.false_proposals.of, 10, "{m:?}");
    assert_eq!(m.false_proposals.found, 0, "{m:?}");
    // the catalogue's own sensor effect is still named on the sightings
    assert_eq!(m.top1.of, 6, "{m:?}");
    assert!(m.top1.found >= 5, "{m:?}");
    for c in table.cases.iter().filter(|c| c.beyond) {
        let p = c.proposed.as_ref().expect("a proposal");
        assert_eq!(p.name, "proposed_bearing_correction", "{c:?}");
        let t = c.truth.expect("scored against the truth");
        assert!(t.held_out_true < t.held_out_before, "{c:?}");
    }
}
