//! The analysis crate's folders are the pipeline's stages in order (logs,
//! the model on a log, estimation, diagnosis, applications), none using a
//! later one. Read from the sources: every `crate::NAME` outside comments
//! and test modules is an edge. (That no module reaches a module that
//! reaches it back, here and in every crate, is `tests/module_cycles.rs`.)
use std::collections::{BTreeMap, BTreeSet};

/// The pipeline's folders, in order: a module may use modules of its own
/// folder and of the folders before it, never of one after it.
const STAGES: [&str; 5] = [
    "logs",
    "model_on_log",
    "estimation",
    "diagnosis",
    "applications",
];

/// Every module's source (a module with a folder of submodules, such as
/// `fit` or `localize`, is one module), with the stage it sits in.
fn sources() -> BTreeMap<String, (usize, String)> {
    let src = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut text: BTreeMap<String, (usize, String)> = BTreeMap::new();
    let mut add = |module: String, stage: usize, path: &std::path::Path| {
        let body = std::fs::read_to_string(path).unwrap();
        // test modules may use anything
        let body = body.split("#[cfg(test)]").next().unwrap().to_string();
        text.entry(module)
            .or_insert((stage, String::new()))
            .1
            .push_str(&body);
    };
    for (stage, folder) in STAGES.iter().enumerate() {
        let dir = src.join(folder);
        assert!(dir.is_dir(), "{} is missing", dir.display());
        for e in std::fs::read_dir(&dir).unwrap().flatten() {
            let p = e.path();
            if p.extension().is_some_and(|x| x == "rs") {
                add(p.file_stem().unwrap().to_string_lossy().into(), stage, &p);
            } else if p.is_dir() {
                // a module's submodules belong to it
                for f in std::fs::read_dir(&p).unwrap().flatten() {
                    add(
                        p.file_name().unwrap().to_string_lossy().into(),
                        stage,
                        &f.path(),
                    );
                }
            }
        }
    }
    // nothing outside the stages but lib.rs
    for e in std::fs::read_dir(&src).unwrap().flatten() {
        let name = e.file_name().to_string_lossy().to_string();
        assert!(
            name == "lib.rs" || STAGES.contains(&name.as_str()),
            "src/{name} is in no stage of the pipeline"
        );
    }
    text
}

fn edges() -> BTreeMap<String, BTreeSet<String>> {
    let text: BTreeMap<String, String> = sources()
        .into_iter()
        .map(|(m, (_, body))| (m, body))
        .collect();
    let modules: BTreeSet<String> = text.keys().cloned().collect();
    text.iter()
        .map(|(m, body)| {
            let mut to = BTreeSet::new();
            for line in body.lines().filter(|l| !l.trim_start().starts_with("//")) {
                for (i, _) in line.match_indices("crate::") {
                    let name: String = line[i + 7..]
                        .chars()
                        .take_while(|c| c.is_alphanumeric() || *c == '_')
                        .collect();
                    if modules.contains(&name) && &name != m {
                        to.insert(name);
                    }
                }
            }
            (m.clone(), to)
        })
        .collect()
}

#[test]
fn no_module_uses_a_later_stage_of_the_pipeline() {
    let stage: BTreeMap<String, usize> = sources().into_iter().map(|(m, (s, _))| (m, s)).collect();
    let mut back = Vec::new();
    for (m, to) in edges() {
        for t in to {
            if stage[&t] > stage[&m] {
                back.push(format!(
                    "{m} ({}) uses {t} ({})",
                    STAGES[stage[&m]], STAGES[stage[&t]]
                ));
            }
        }
    }
    assert!(back.is_empty(), "{back:#?}");
}
