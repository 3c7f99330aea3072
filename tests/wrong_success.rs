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
    let log = Sim::new("spec/unicycle_ekf.toml")
        .drive("random", 1, 1)
        .sighting(&dir.join("map.csv"))
        .write_to(&dir.join("log.csv"), &dir.join("obs.csv"));
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

/// Issue #37.1: an output never destroys what is there. A device is written
/// in place (it stays a device; /dev/full's write error exits 2 naming it), a
/// symbolic link keeps being a link to the file that gets the new content, a
/// FIFO receives the document, and a read-only file is refused, unchanged.
/// (Before: /dev/null became a regular file as root, /dev/full exited 0, and
/// a 0444 file was replaced.)
#[test]
fn outputs_to_devices_links_pipes_and_read_only_files_are_written_or_refused_in_place() {
    use std::os::unix::fs::FileTypeExt;
    let tmp = tempfile::tempdir().unwrap();
    let (spec, data) = ("spec/diff_drive.toml", "data/mystery_robot.csv");
    let compare_to = |json: &std::path::Path| {
        kinegen(&[
            "compare",
            "--spec",
            spec,
            "--data",
            data,
            "--json",
            json.to_str().unwrap(),
        ])
    };
    let o = compare_to(std::path::Path::new("/dev/null"));
    assert!(o.status.success(), "{}", stderr(&o));
    let sim = kinegen(&[
        "simulate",
        "--spec",
        spec,
        "--trajectory",
        "square",
        "--out",
        "/dev/null",
    ]);
    assert!(sim.status.success(), "{}", stderr(&sim));
    assert!(std::fs::metadata("/dev/null")
        .unwrap()
        .file_type()
        .is_char_device());
    // /dev/stdout is a link to this process's stdout: the document arrives there
    let o = compare_to(std::path::Path::new("/dev/stdout"));
    assert!(
        o.status.success() && stdout(&o).contains("\"rmse\""),
        "{}",
        stderr(&o)
    );
    let e = refused(&[
        "fit",
        "--spec",
        spec,
        "--data",
        data,
        "--export",
        "ros2-yaml",
        "/dev/full",
    ]);
    assert!(e.contains("/dev/full"), "{}", e);
    // a link to a file: the file gets the document, the link stays
    let target = tmp.path().join("target.json");
    std::fs::write(&target, "{}").unwrap();
    let link = tmp.path().join("link.json");
    std::os::unix::fs::symlink(&target, &link).unwrap();
    assert!(compare_to(&link).status.success());
    assert!(std::fs::symlink_metadata(&link)
        .unwrap()
        .file_type()
        .is_symlink());
    assert!(std::fs::read_to_string(&target)
        .unwrap()
        .contains("\"rmse\""));
    // a FIFO: read by another process while kinegen writes
    let fifo = tmp.path().join("fifo");
    assert!(std::process::Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .unwrap()
        .success());
    let reader = {
        let fifo = fifo.clone();
        std::thread::spawn(move || std::fs::read_to_string(fifo).unwrap())
    };
    assert!(compare_to(&fifo).status.success());
    assert!(reader.join().unwrap().contains("\"rmse\""));
    assert!(std::fs::metadata(&fifo).unwrap().file_type().is_fifo());
    // read-only files are refused and left as they were
    let ro = tmp.path().join("ro.csv");
    std::fs::write(&ro, "old\n").unwrap();
    let mut perm = std::fs::metadata(&ro).unwrap().permissions();
    perm.set_readonly(true);
    std::fs::set_permissions(&ro, perm.clone()).unwrap();
    let e = refused(&[
        "simulate",
        "--spec",
        spec,
        "--trajectory",
        "square",
        "--out",
        ro.to_str().unwrap(),
    ]);
    assert!(e.contains("read-only"), "{}", e);
    let ro_toml = tmp.path().join("ro.toml");
    std::fs::write(&ro_toml, "old\n").unwrap();
    std::fs::set_permissions(&ro_toml, perm).unwrap();
    refused(&[
        "add-effect",
        "--spec",
        spec,
        "--effect",
        "lateral_slip",
        "--value",
        "k_slip=0.1",
        "--out",
        ro_toml.to_str().unwrap(),
    ]);
    for f in [&ro, &ro_toml] {
        assert_eq!(std::fs::read_to_string(f).unwrap(), "old\n");
    }
}

/// Issue #37.5: a counter that wraps like a 16- or 32-bit register, in a spec
/// that declares no `wrap`, is refused with its file, line and column and
/// the declaration to add (compare exited 0 with a gyro residual of 1e6 rad/s).
/// A held-out run that stands still for three rows gets its measured start
/// pose in the JSON (it was null).
#[test]
fn an_undeclared_wrapping_counter_is_named_and_a_standing_holdout_has_a_start_pose() {
    let tmp = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(root().join("data/mystery_robot.csv")).unwrap();
    for (bits, modulus) in [(16, 65536.0), (32, 4294967296.0)] {
        let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
        let col = lines[0].split(',').position(|h| h == "enc_r").unwrap();
        for line in lines.iter_mut().skip(501) {
            let mut v: Vec<String> = line.split(',').map(str::to_string).collect();
            v[col] = format!("{}", v[col].parse::<f64>().unwrap() - modulus);
            *line = v.join(",");
        }
        let log = tmp.path().join(format!("wrap{bits}.csv"));
        std::fs::write(&log, lines.join("\n") + "\n").unwrap();
        let e = refused(&[
            "compare",
            "--spec",
            "spec/diff_drive.toml",
            "--data",
            log.to_str().unwrap(),
        ]);
        assert!(
            e.contains(&format!("wrap{bits}.csv:502")) && e.contains("enc_r"),
            "{e}"
        );
        assert!(e.contains(&format!("wrap = {bits}")), "{e}");
    }
    let stand = tmp.path().join("stand.csv");
    std::fs::write(
        &stand,
        "t,enc_r,enc_l,gt_x,gt_y,gt_theta\n0,0,0,1,2,0.5\n0.05,0,0,1,2,0.5\n0.1,0,0,1,2,0.5\n",
    )
    .unwrap();
    let doc = kinegen_json(&[
        "fit",
        "--spec",
        "spec/diff_drive.toml",
        "--data",
        "data/mystery_robot.csv",
        "--holdout",
        stand.to_str().unwrap(),
    ]);
    let held = doc["runs"]
        .as_array()
        .unwrap()
        .iter()
        .find(|r| r["holdout"] == true)
        .unwrap();
    assert_eq!(
        held["start_pose"],
        serde_json::json!([1.0, 2.0, 0.5]),
        "{held}"
    );
}

/// Issue #37.4: errors with a place. A user's effect file with an unknown
/// symbol is named with its line; an out-of-bounds `--value` names the
/// option and the bounds; a `--topics` TOML error and bytes that are not
/// UTF-8 in a topic map, a grid or an effect file give line and column.
#[test]
fn errors_in_effect_files_topics_grids_and_values_are_located() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("fx");
    std::fs::create_dir(&dir).unwrap();
    let slip = std::fs::read_to_string(root().join("spec/effects/lateral_slip.toml")).unwrap();
    let bad = slip
        .replace("name = \"lateral_slip\"", "name = \"bad_slip\"")
        .replace("k_slip*(", "k_zz*(");
    std::fs::write(dir.join("bad.toml"), &bad).unwrap();
    let line = bad.lines().position(|l| l.contains("k_zz")).unwrap() + 1;
    let out = tmp.path().join("o.toml");
    let (o_s, d) = (out.to_str().unwrap(), dir.to_str().unwrap());
    let spec = "spec/diff_drive.toml";
    let e = refused(&[
        "add-effect",
        "--spec",
        spec,
        "--effect",
        "bad_slip",
        "--effects",
        d,
        "--out",
        o_s,
    ]);
    assert!(
        e.contains(&format!("bad.toml:{line}")) && e.contains("k_zz"),
        "{e}"
    );
    // diagnose skips it with the same place
    let doc = kinegen_json(&[
        "diagnose",
        "--spec",
        spec,
        "--data",
        "data/mystery_robot.csv",
        "--effects",
        d,
    ]);
    let skipped = doc["skipped"].to_string();
    assert!(skipped.contains(&format!("bad.toml:{line}")), "{skipped}");
    let e = refused(&[
        "add-effect",
        "--spec",
        spec,
        "--effect",
        "lateral_slip",
        "--value",
        "k_slip=5",
        "--out",
        o_s,
    ]);
    assert!(
        e.contains("--value k_slip=5") && e.contains("[-1, 1]"),
        "{e}"
    );
    assert!(!out.exists());
    let topics = tmp.path().join("t.toml");
    let data = "data/mystery_robot.csv";
    let fit_with_topics = |text: &[u8]| {
        std::fs::write(&topics, text).unwrap();
        refused(&[
            "fit",
            "--spec",
            spec,
            "--data",
            data,
            "--topics",
            topics.to_str().unwrap(),
        ])
    };
    let e = fit_with_topics(b"[inputs]\nenc_r = { topic = \"/j\" ");
    assert!(e.contains("t.toml:2: column 24"), "{e}");
    let e = fit_with_topics(b"[inputs]\n# caf\xe9\n");
    assert!(e.contains("t.toml:2: column 6: not UTF-8"), "{e}");
    let grid = tmp.path().join("g.txt");
    std::fs::write(&grid, b"....\n.S\xff.\n").unwrap();
    let e = refused(&[
        "navigate",
        "--spec",
        "data/seed004/epuck.toml",
        "--grid",
        grid.to_str().unwrap(),
    ]);
    assert!(e.contains("g.txt:2: column 3: not UTF-8"), "{e}");
    std::fs::write(dir.join("bad.toml"), b"name = \"x\"\ndoc = \"\xff\"\n").unwrap();
    let e = refused(&["compare", "--spec", spec, "--data", data, "--effects", d]);
    assert!(e.contains("bad.toml: line 2, column 8: not UTF-8"), "{e}");
}

/// Issue #37.4: a fit that cannot start names the logs it was given: no
/// ground truth, gyro or landmarks ("nothing to fit"), and neural
/// gyrodometry without a gyro.
#[test]
fn a_fit_that_cannot_start_names_its_logs() {
    let tmp = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(root().join("data/mystery_robot.csv")).unwrap();
    let cut = |n: usize, name: &str| {
        let t: String = text
            .lines()
            .map(|l| l.split(',').take(n).collect::<Vec<_>>().join(",") + "\n")
            .collect();
        let p = tmp.path().join(name);
        std::fs::write(&p, t).unwrap();
        p
    };
    let (bare, no_gyro) = (cut(3, "bare.csv"), cut(6, "no_gyro.csv"));
    let spec = "spec/diff_drive.toml";
    let e = refused(&["fit", "--spec", spec, "--data", bare.to_str().unwrap()]);
    assert!(e.contains("bare.csv: nothing to fit"), "{}", e);
    let e = refused(&[
        "fit",
        "--spec",
        spec,
        "--data",
        no_gyro.to_str().unwrap(),
        "--method",
        "neural",
    ]);
    assert!(e.contains("no_gyro.csv: neural gyrodometry"), "{}", e);
}

/// Issue #37.4: a noise input in a denominator (`w/dv`) makes a kernel
/// infinite at zero noise; generate says so and how to fix it, naming the
/// spec, instead of "non-real constant `⧞`" alone, and writes nothing.
#[test]
fn a_noise_in_a_denominator_is_explained() {
    let tmp = tempfile::tempdir().unwrap();
    let specs = tmp.path().join("specs");
    std::fs::create_dir(&specs).unwrap();
    let text = std::fs::read_to_string(root().join("spec/tricycle_fwd.toml")).unwrap();
    let (i, j) = (
        text.find("[inverse]").unwrap(),
        text.find("[[observation]]").unwrap(),
    );
    let text = format!("{}{}", &text[..i], &text[j..]);
    let line = text.lines().find(|l| l.starts_with("vx = ")).unwrap();
    let text = text.replace(line, "vx = \"r*w/dv\"");
    std::fs::write(specs.join("divided.toml"), text).unwrap();
    let out = tmp.path().join("gen");
    let e = refused(&[
        "generate",
        "--spec-dir",
        specs.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(
        e.contains("divided.toml") && e.contains("divides by zero") && e.contains("noise"),
        "{e}"
    );
    assert!(!out.exists() || std::fs::read_dir(&out).unwrap().next().is_none());
}

/// Issue #37.4: a user's effect that cannot be derived on the spec (a noise
/// input in a denominator) is skipped by diagnose with the user's spec and
/// the effect named, not kinegen's cache file.
#[test]
fn an_effect_that_cannot_be_derived_is_named_by_spec_and_effect() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("fx");
    std::fs::create_dir(&dir).unwrap();
    std::fs::write(
        dir.join("curve.toml"),
        "name = \"speed_curve\"\ndoc = \"A speed-dependent drive gain.\"\nrequires = [\"twist\"]\n\n\
         [[parameter]]\nname = \"k_nl\"\nnominal = 0.0\nunit = \"1\"\nmin = -1.0\nmax = 1.0\n\n\
         [motion]\nvx = \"({vx})*(1 + k_nl/dv)\"\n",
    )
    .unwrap();
    let d = kinegen_json(&[
        "diagnose",
        "--spec",
        "spec/diff_drive.toml",
        "--data",
        "data/mystery_robot.csv",
        "--effects",
        dir.to_str().unwrap(),
    ]);
    let skipped = d["skipped"].to_string();
    assert!(skipped.contains("speed_curve"), "{skipped}");
    assert!(
        skipped.contains("spec/diff_drive.toml with speed_curve added"),
        "{skipped}"
    );
    assert!(!skipped.contains("kinegen-ir-cache"), "{skipped}");
}
