//! No crate of the workspace has a module cycle: no module reaches, directly or
//! through others, a module that reaches it back. Read from the sources: in
//! each crate every `crate::NAME` outside comments and test modules is an
//! edge; a module with a folder of submodules is one module, and the folders
//! that only group modules (`analysis/src/logs/`...) are looked through.
//! The analysis crate's folders are also held in pipeline order: a module
//! never uses a module of a later stage.
use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

mod common;

/// A module's source and the grouping folder it sits in ("" at the top).
#[derive(Default)]
struct Source {
    group: String,
    text: String,
}

/// A crate's modules.
fn modules(src: &Path) -> BTreeMap<String, Source> {
    let mut found = BTreeMap::new();
    collect(src, src, &mut found);
    found
}

/// A crate's modules and the modules each uses.
fn edges(src: &Path) -> BTreeMap<String, BTreeSet<String>> {
    let text = modules(src);
    let modules: BTreeSet<String> = text.keys().cloned().collect();
    text.iter()
        .map(|(m, Source { text: body, .. })| {
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

/// The modules under `dir`: a file is a module; a folder is one module when
/// a file or `mod.rs` makes it one (`fit.rs` beside `fit/`), and a group of
/// modules otherwise.
fn collect(root: &Path, dir: &Path, text: &mut BTreeMap<String, Source>) {
    let group = dir
        .strip_prefix(root)
        .unwrap()
        .to_string_lossy()
        .to_string();
    for e in std::fs::read_dir(dir).unwrap().flatten() {
        let p = e.path();
        let name = p.file_stem().unwrap().to_string_lossy().to_string();
        if p.extension().is_some_and(|x| x == "rs") {
            if dir == root && (name == "lib" || name == "main") {
                continue;
            }
            add(text, &name, &group, &p);
        } else if p.is_dir() {
            let is_module = p.join("mod.rs").is_file() || dir.join(format!("{name}.rs")).is_file();
            if is_module {
                for f in walk(&p) {
                    add(text, &name, &group, &f);
                }
            } else {
                collect(root, &p, text);
            }
        }
    }
}

fn walk(dir: &Path) -> Vec<std::path::PathBuf> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).unwrap().flatten() {
        let p = e.path();
        if p.is_dir() {
            out.extend(walk(&p));
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
    out
}

fn add(text: &mut BTreeMap<String, Source>, module: &str, group: &str, path: &Path) {
    let body = std::fs::read_to_string(path).unwrap();
    // test modules may use anything
    let body = body.split("#[cfg(test)]").next().unwrap().to_string();
    let entry = text.entry(module.to_string()).or_default();
    entry.group = group.to_string();
    entry.text.push_str(&body);
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

const CRATES: [&str; 6] = [
    "src",
    "model/src",
    "jit/src",
    "codegen/src",
    "analysis/src",
    "verify/src",
];

#[test]
fn no_crate_has_a_module_cycle() {
    for krate in CRATES {
        let g = edges(&common::root().join(krate));
        assert!(g.len() >= 2, "{krate}: {g:?}");
        for m in g.keys() {
            if let Some(c) = cycle(&g, m) {
                panic!("{krate}: module cycle {}", c.join(" -> "));
            }
        }
    }
}

/// The analysis crate's folders: the pipeline's stages, in order.
const STAGES: [&str; 5] = [
    "logs",
    "model_on_log",
    "estimation",
    "diagnosis",
    "applications",
];

#[test]
fn no_analysis_module_uses_a_later_stage_of_the_pipeline() {
    let src = common::root().join("analysis/src");
    let stage: BTreeMap<String, usize> = modules(&src)
        .into_iter()
        .map(|(m, s)| {
            let k = STAGES.iter().position(|g| *g == s.group);
            (
                m.clone(),
                k.unwrap_or_else(|| panic!("analysis/src: `{m}` is in no stage of the pipeline")),
            )
        })
        .collect();
    let mut back = Vec::new();
    for (m, to) in edges(&src) {
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

/// The check sees a cycle where there is one: the model crate's IR reaching
/// the fusion that builds on it (as its JIT cache once made the IR reach the
/// compiler) is found.
#[test]
fn a_cycle_is_found() {
    let mut g = edges(&common::root().join("model/src"));
    assert!(g["fuse"].contains("ir"), "{:?}", g["fuse"]);
    g.get_mut("ir").unwrap().insert("fuse".into());
    assert!(cycle(&g, "ir").is_some());
    // the analysis crate's grouping folders are looked through
    let a = edges(&common::root().join("analysis/src"));
    assert!(a["deadreckon"].contains("run"), "{:?}", a.keys());
}
