//! The analysis crate is layered: no module reaches, directly or through
//! others, a module that reaches it back (issue 10 removed the cycle dataset ->
//! landmarks -> deadreckon -> dataset). Read from the sources: every
//! `crate::NAME` outside comments and test modules is an edge.
use std::collections::{BTreeMap, BTreeSet};

fn edges() -> BTreeMap<String, BTreeSet<String>> {
    let src = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut text: BTreeMap<String, String> = BTreeMap::new();
    let mut add = |module: String, path: &std::path::Path| {
        let body = std::fs::read_to_string(path).unwrap();
        // test modules may use anything
        let body = body.split("#[cfg(test)]").next().unwrap().to_string();
        text.entry(module).or_default().push_str(&body);
    };
    for e in std::fs::read_dir(&src).unwrap().flatten() {
        let p = e.path();
        if p.extension().is_some_and(|x| x == "rs") {
            add(p.file_stem().unwrap().to_string_lossy().into(), &p);
        } else if p.is_dir() {
            // a module's submodules belong to it
            for f in std::fs::read_dir(&p).unwrap().flatten() {
                add(p.file_name().unwrap().to_string_lossy().into(), &f.path());
            }
        }
    }
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
fn a_cycle_is_found() {
    let mut g = edges();
    g.get_mut("run").unwrap().insert("deadreckon".into());
    assert!(cycle(&g, "run").is_some());
}
