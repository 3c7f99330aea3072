//! The analysis crate is layered: no module reaches, directly or through
//! others, a module that reaches it back (issue 10 removed the cycle dataset ->
//! landmarks -> deadreckon -> dataset), and its folders are the pipeline's
//! stages in order (logs, the model on a log, estimation, diagnosis,
//! applications), none using a later one. Read from the sources: every
//! `crate::NAME` outside comments and test modules is an edge.
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

/// A cycle through `from`, if any (depth-first search).
fn cycle(g: &BTreeMap<String, BTreeSet<String>>, from: &str) -> Option<Vec<String>> {
    fn go(
        g: &BTreeMap<String, BTreeSet<String>>,
        path: &mut Vec<String>,
        done: &mut BTreeSet<String>,
    ) -> Option<Vec<String>> {
        let at = path.last().unwrap().clone();
        for next in &g[&at] {
            if let Some(i) = path.iter().position(|m| m == next) {
                let mut c = path[i..].to_vec();
                c.push(next.clone());
                return Some(c);
            }
            if done.insert(next.clone()) {
                path.push(next.clone());
                if let Some(c) = go(g, path, done) {
                    return Some(c);
                }
                path.pop();
            }
        }
        None
    }
    go(g, &mut vec![from.to_string()], &mut BTreeSet::new())
}

#[test]
fn the_analysis_modules_form_no_cycle() {
    let g = edges();
    assert!(g.len() > 20 && g["deadreckon"].contains("run"), "{g:?}");
    for m in g.keys() {
        if let Some(c) = cycle(&g, m) {
            panic!("module cycle: {}", c.join(" -> "));
        }
    }
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

#[test]
fn a_cycle_is_found() {
    let mut g = edges();
    g.get_mut("run").unwrap().insert("deadreckon".into());
    assert!(cycle(&g, "run").is_some());
}
