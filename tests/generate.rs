//! `kinegen generate`: bad specs are rejected with file:line:column and exit 2 and
//! nothing is written; `--check` notices stale generated code.
mod common;
use common::*;

// `kinegen generate` derives with symbolica on one thread: scripts/test.sh runs this file's tests beside the others (`--skip symbolic_stage::` there), not alone
mod symbolic_stage {
    use super::*;

    #[test]
    fn every_bad_spec_is_rejected_at_the_right_place_and_nothing_is_written() {
        let dir = root().join("tests/bad_specs");
        let mut seen = 0;
        for entry in std::fs::read_dir(&dir).unwrap().flatten() {
            let path = entry.path();
            let text = std::fs::read_to_string(&path).unwrap();
            let expect = text
                .lines()
                .next()
                .unwrap()
                .strip_prefix("# expect: ")
                .expect("first line says what to expect");
            let (pos, message) = expect.split_once(" | ").unwrap();
            let tmp = tempfile::tempdir().unwrap();
            let spec_dir = tmp.path().join("spec");
            std::fs::create_dir(&spec_dir).unwrap();
            let name = path.file_name().unwrap().to_str().unwrap();
            std::fs::copy(&path, spec_dir.join(name)).unwrap();
            // a good spec beside it: its files must not be written either
            std::fs::copy(
                root().join("spec/diff_drive.toml"),
                spec_dir.join("diff_drive.toml"),
            )
            .unwrap();
            let out = tmp.path().join("out");
            let o = kinegen(&[
                "generate",
                "--spec-dir",
                spec_dir.to_str().unwrap(),
                "--out",
                out.to_str().unwrap(),
            ]);
            let err = stderr(&o);
            assert_eq!(o.status.code(), Some(2), "{name}: {err}");
            assert!(
                err.contains(&format!("{name}:{pos}:")),
                "{name}: expected position {pos} in {err}"
            );
            assert!(
                err.contains(message),
                "{name}: expected `{message}` in {err}"
            );
            assert!(
                !out.exists(),
                "{name}: generate wrote files despite the error"
            );
            seen += 1;
        }
        assert!(seen >= 6, "bad-spec fixtures missing");
    }

    #[test]
    fn check_passes_on_the_repository_and_fails_when_a_spec_changes() {
        let o = kinegen(&["generate", "--check"]);
        assert_eq!(
            o.status.code(),
            Some(0),
            "committed generated/ is stale: {}",
            stderr(&o)
        );

        let tmp = tempfile::tempdir().unwrap();
        let (spec, out) = (tmp.path().join("spec"), tmp.path().join("generated"));
        copy_dir(&root().join("spec"), &spec);
        let o = kinegen(&[
            "generate",
            "--spec-dir",
            spec.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ]);
        assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
        let check = |args: &[&str]| {
            kinegen(
                &[
                    &[
                        "generate",
                        "--check",
                        "--spec-dir",
                        spec.to_str().unwrap(),
                        "--out",
                        out.to_str().unwrap(),
                    ],
                    args,
                ]
                .concat(),
            )
        };
        assert_eq!(check(&[]).status.code(), Some(0));

        // Change a nominal value: the module and its IR are stale, and --check writes nothing.
        let f = spec.join("omni3.toml");
        let text = std::fs::read_to_string(&f)
            .unwrap()
            .replace("nominal = 0.15", "nominal = 0.16");
        std::fs::write(&f, text).unwrap();
        let before = std::fs::read_to_string(out.join("src/omni3.rs")).unwrap();
        let o = check(&[]);
        assert_eq!(o.status.code(), Some(1));
        assert!(
            stderr(&o).contains("stale:") && stderr(&o).contains("omni3.rs"),
            "{}",
            stderr(&o)
        );
        assert_eq!(
            before,
            std::fs::read_to_string(out.join("src/omni3.rs")).unwrap()
        );

        // A removed spec leaves an orphan module: also stale.
        std::fs::remove_file(&f).unwrap();
        assert_eq!(check(&[]).status.code(), Some(1));
    }
}
