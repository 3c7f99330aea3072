//! Issue #37.3: inputs that used to pass silently are refused, and the
//! simulator never writes data its own tools refuse.
mod common;
use common::*;

/// `add-effect --value k_slip=0.1 --value k_slip=0.2` kept the last silently.
#[test]
fn a_value_given_twice_is_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("s.toml");
    let o = kinegen(&[
        "add-effect",
        "--spec",
        "spec/diff_drive.toml",
        "--effect",
        "lateral_slip",
        "--value",
        "k_slip=0.1",
        "--value",
        "k_slip=0.2",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("given twice"), "{}", stderr(&o));
    assert!(!out.exists(), "nothing written");
}

/// `--effects DIR` is read by every command that takes it (invalid TOML there
/// made compare exit 0), and two files of one directory naming the same
/// effect are refused with both names.
#[test]
fn an_effect_directory_is_checked_by_every_command() {
    let tmp = tempfile::tempdir().unwrap();
    let broken = tmp.path().join("broken");
    std::fs::create_dir_all(&broken).unwrap();
    std::fs::write(
        broken.join("mine.toml"),
        "name = \"mine\"\ndoc = [unclosed\n",
    )
    .unwrap();
    for cmd in ["compare", "fit"] {
        let o = kinegen(&[
            cmd,
            "--spec",
            "spec/diff_drive.toml",
            "--data",
            "data/mystery_robot.csv",
            "--effects",
            broken.to_str().unwrap(),
        ]);
        assert_eq!(o.status.code(), Some(2), "{cmd}: {}", stderr(&o));
        assert!(stderr(&o).contains("mine.toml"), "{cmd}: {}", stderr(&o));
    }
    let twice = tmp.path().join("twice");
    std::fs::create_dir_all(&twice).unwrap();
    let slip = std::fs::read_to_string(root().join("spec/effects/lateral_slip.toml")).unwrap();
    std::fs::write(twice.join("a.toml"), &slip).unwrap();
    std::fs::write(twice.join("b.toml"), &slip).unwrap();
    let o = kinegen(&[
        "compare",
        "--spec",
        "spec/diff_drive.toml",
        "--data",
        "data/mystery_robot.csv",
        "--effects",
        twice.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    let e = stderr(&o);
    assert!(
        e.contains("a.toml") && e.contains("b.toml") && e.contains("lateral_slip"),
        "{e}"
    );
}

/// A landmark right where the robot starts: its simulated ranges stay
/// positive (the noise used to make some negative, which localize refuses),
/// and localize reads them.
#[test]
fn simulated_ranges_beside_a_landmark_stay_positive() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    std::fs::write(dir.join("map.csv"), "id,x,y\nhere,0,0\nfar,4,3\n").unwrap();
    let log = simulate(
        dir,
        "log.csv",
        &[
            "--spec",
            "spec/unicycle_ekf.toml",
            "--trajectory",
            "random",
            "--landmarks",
            dir.join("map.csv").to_str().unwrap(),
            "--observations",
            dir.join("obs.csv").to_str().unwrap(),
        ],
    );
    let obs = std::fs::read_to_string(dir.join("obs.csv")).unwrap();
    let near: Vec<f64> = obs
        .lines()
        .skip(1)
        .filter(|l| l.contains(",here,"))
        .map(|l| l.split(',').nth(2).unwrap().parse().unwrap())
        .collect();
    assert!(!near.is_empty());
    assert!(
        near.iter().all(|r| *r > 0.0),
        "a range of {:?}",
        near.iter().cloned().fold(f64::INFINITY, f64::min)
    );
    let o = kinegen(&[
        "localize",
        "--spec",
        "spec/unicycle_ekf.toml",
        "--data",
        log.to_str().unwrap(),
        "--observations",
        dir.join("obs.csv").to_str().unwrap(),
        "--landmarks",
        dir.join("map.csv").to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
}

/// A `--topics` `[inputs]` entry for a column the spec does not read was
/// ignored (a misspelt column passed silently); it is refused, naming the
/// file and the column.
#[test]
fn a_topic_entry_for_an_unknown_column_is_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let map = tmp.path().join("topics.toml");
    std::fs::write(&map, "[inputs.enc_rigth]\njoint = \"right_wheel\"\n").unwrap();
    let o = kinegen(&[
        "compare",
        "--spec",
        "spec/diff_drive.toml",
        "--data",
        "data/mystery_robot.csv",
        "--topics",
        map.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    let e = stderr(&o);
    assert!(
        e.contains("topics.toml") && e.contains("enc_rigth") && e.contains("enc_r"),
        "{e}"
    );
}
