//! Diagnosis beyond the catalogue (issue 70, items 2, 3 and 6), through
//! the recovery benchmark's library call: logs simulated with effects
//! written for these tests (tests/proposal_effects/: in neither the
//! catalogue nor the proposal libraries) get a proposal that removes at
//! least half of the held-out error the true effect removes, in at least 5
//! of 6 cases (3 magnitudes x 2 noise levels); clean logs, and logs whose
//! only missing effect is in the catalogue, get none. One kind of effect a
//! test: on the forward speed, on the turn rate's commands, on the camera.
//! (The command line's side, its options and JSON, is tests/proposals.rs.)
use kinegen_analysis::applications::diagnose_bench::{bench, ModelRates, Settings, Table};
use kinegen_analysis::model_on_log::derivation::AutodiffDeriver;
use kinegen_model::spec::Model;
use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The benchmark of `spec` hiding `effects` (catalogue or beyond), one seed.
fn beyond(spec: &str, effects: &[&str]) -> Table {
    let spec = Model::load(&root().join(spec)).unwrap();
    let settings = Settings {
        seeds: 1,
        laps: 1,
        shard: None,
        effects: effects.iter().map(|e| e.to_string()).collect(),
        beyond: vec![root().join("tests/proposal_effects")],
    };
    bench(&[spec], &settings, &AutodiffDeriver, &|f| panic!("{f}")).unwrap()
}

/// 5 of the 6 cases of the effect beyond the catalogue recovered, and no
/// proposal on the clean logs (and the catalogue effect's logs, if any).
fn recovered_without_false_proposals(m: &ModelRates, catalogue_cases: usize) {
    assert_eq!(m.beyond_recovered.of, 6, "{m:?}");
    assert!(m.beyond_recovered.found >= 5, "{m:?}");
    assert_eq!(m.false_proposals.of, 4 + catalogue_cases, "{m:?}");
    assert_eq!(m.false_proposals.found, 0, "{m:?}");
}

#[test]
fn forward_speed_lost_while_turning_gets_a_proposal() {
    let table = beyond("spec/diff_drive.toml", &["turn_speed_loss"]);
    recovered_without_false_proposals(&table.models[0], 0);
}

#[test]
fn a_curved_turn_rate_command_response_gets_a_proposal() {
    let table = beyond("spec/unicycle_ekf.toml", &["yaw_cmd_curve"]);
    recovered_without_false_proposals(&table.models[0], 0);
}

/// A catalogue effect is named, not proposed beyond the catalogue.
#[test]
fn a_catalogue_effect_gets_no_proposal() {
    let table = beyond("spec/diff_drive.toml", &["turn_saturation", "lateral_slip"]);
    let m = &table.models[0];
    recovered_without_false_proposals(m, 6);
    assert_eq!(
        m.top1,
        kinegen_analysis::applications::diagnose_bench::Rate { found: 6, of: 6 }
    );
}

/// A camera whose focal length is taken wrong (its bearings atan((1 + k)
/// tan(bearing))) gets a proposal on the sightings; clean logs with
/// sightings, and logs whose only sensor error is the catalogue's
/// `range_scale`, get none, and `range_scale` is still named.
#[test]
fn a_camera_focal_length_taken_wrong_gets_a_proposal_on_the_sightings() {
    let table = beyond(
        "spec/diff_drive.toml",
        &["camera_focal_error", "range_scale"],
    );
    let m = &table.models[0];
    recovered_without_false_proposals(m, 6);
    assert_eq!(m.top1.of, 6, "{m:?}");
    assert!(m.top1.found >= 5, "{m:?}");
    for c in table.cases.iter().filter(|c| c.beyond) {
        let p = c.proposed.as_ref().expect("a proposal");
        assert_eq!(p.name, "proposed_bearing_correction", "{c:?}");
        let t = c.truth.expect("scored against the truth");
        assert!(t.held_out_true < t.held_out_before, "{c:?}");
    }
}
