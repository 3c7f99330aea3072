//! No crate of the workspace has a module cycle, at any level of its module
//! tree: for every module, its child modules (each standing for itself and
//! everything below it) never reach one another in a circle. A module may use
//! its own children and its children may use it (the facade a `mod.rs` or a
//! `fit.rs` beside `fit/` is); siblings, cousins and stages may not go round.
//!
//! The sources are parsed with `syn`, and every path is resolved as rustc
//! would: `crate::`, `super::` (repeated), `self::`, a child module's name,
//! grouped `use a::{b, c::d}` trees, and names a module re-exports with
//! `pub use` (followed to the module that defines them). Test modules
//! (`#[cfg(test)]`) may use anything and are left out.
//!
//! The analysis crate's top-level folders are also held in pipeline order: a
//! module never uses a module of a later stage.
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use syn::visit::Visit;

mod common;

/// A module path inside its crate (`["estimation", "fit", "solver"]`).
type ModPath = Vec<String>;

/// One module: where it is written, its child modules, the names it
/// re-exports (name -> the path it stands for, relative to this module) and
/// the paths its code names (with the file they are in, for the message).
#[derive(Default, Debug)]
struct Module {
    #[allow(dead_code)] // shown by Debug when a test fails
    file: PathBuf,
    children: BTreeSet<String>,
    reexports: BTreeMap<String, Vec<String>>,
    imports: BTreeMap<String, Vec<String>>,
    paths: Vec<Vec<String>>,
}

/// A crate's module tree, read from its root file.
#[derive(Default, Debug)]
struct Crate {
    modules: BTreeMap<ModPath, Module>,
}

fn is_test(attrs: &[syn::Attribute]) -> bool {
    attrs.iter().any(|a| {
        a.path().is_ident("cfg")
            && a.meta
                .require_list()
                .is_ok_and(|l| l.tokens.to_string().contains("test"))
    })
}

fn path_attr(attrs: &[syn::Attribute]) -> Option<String> {
    attrs
        .iter()
        .find(|a| a.path().is_ident("path"))
        .and_then(|a| {
            let nv = a.meta.require_name_value().ok()?;
            match &nv.value {
                syn::Expr::Lit(syn::ExprLit {
                    lit: syn::Lit::Str(s),
                    ..
                }) => Some(s.value()),
                _ => None,
            }
        })
}

/// The leaves of a `use` tree: (name bound, full path).
fn use_leaves(tree: &syn::UseTree, prefix: &mut Vec<String>, out: &mut Vec<(String, Vec<String>)>) {
    match tree {
        syn::UseTree::Path(p) => {
            prefix.push(p.ident.to_string());
            use_leaves(&p.tree, prefix, out);
            prefix.pop();
        }
        syn::UseTree::Name(n) => {
            let name = n.ident.to_string();
            if name == "self" {
                if let Some(last) = prefix.last() {
                    out.push((last.clone(), prefix.clone()));
                }
            } else {
                let mut p = prefix.clone();
                p.push(name.clone());
                out.push((name, p));
            }
        }
        syn::UseTree::Rename(r) => {
            let mut p = prefix.clone();
            p.push(r.ident.to_string());
            out.push((r.rename.to_string(), p));
        }
        syn::UseTree::Glob(_) => out.push(("*".into(), prefix.clone())),
        syn::UseTree::Group(g) => {
            for t in &g.items {
                use_leaves(t, prefix, out);
            }
        }
    }
}

/// Collects one module's paths and `use`s, without entering nested modules
/// (they are modules of their own).
struct Collector<'a> {
    module: &'a mut Module,
}

impl<'ast> Visit<'ast> for Collector<'_> {
    fn visit_item_mod(&mut self, _: &'ast syn::ItemMod) {}
    fn visit_item_use(&mut self, u: &'ast syn::ItemUse) {
        let mut leaves = Vec::new();
        use_leaves(&u.tree, &mut Vec::new(), &mut leaves);
        let public = !matches!(u.vis, syn::Visibility::Inherited);
        for (name, path) in leaves {
            if public && name != "*" {
                self.module.reexports.insert(name.clone(), path.clone());
            }
            if name != "*" {
                self.module.imports.insert(name, path.clone());
            }
            self.module.paths.push(path);
        }
    }
    fn visit_path(&mut self, p: &'ast syn::Path) {
        let segs: Vec<String> = p.segments.iter().map(|s| s.ident.to_string()).collect();
        if segs.len() >= 2 {
            self.module.paths.push(segs);
        }
        syn::visit::visit_path(self, p);
    }
    fn visit_item_fn(&mut self, f: &'ast syn::ItemFn) {
        if !is_test(&f.attrs) {
            syn::visit::visit_item_fn(self, f);
        }
    }
}

impl Crate {
    fn read(root_file: &Path) -> Crate {
        let mut c = Crate::default();
        let dir = root_file.parent().unwrap().to_path_buf();
        c.read_file(Vec::new(), root_file, &dir);
        c
    }

    /// Read a module's file; `child_dir` is where its `mod x;` files live.
    fn read_file(&mut self, path: ModPath, file: &Path, child_dir: &Path) {
        let text = std::fs::read_to_string(file).unwrap_or_else(|e| panic!("{file:?}: {e}"));
        let parsed = syn::parse_file(&text).unwrap_or_else(|e| panic!("{file:?}: {e}"));
        self.read_items(path, file, &parsed.items, child_dir);
    }

    fn read_items(&mut self, path: ModPath, file: &Path, items: &[syn::Item], child_dir: &Path) {
        let mut module = Module {
            file: file.to_path_buf(),
            ..Module::default()
        };
        for item in items {
            match item {
                syn::Item::Mod(m) if is_test(&m.attrs) => {}
                syn::Item::Mod(m) => {
                    let name = m.ident.to_string();
                    module.children.insert(name.clone());
                    let mut sub = path.clone();
                    sub.push(name.clone());
                    if let Some((_, inner)) = &m.content {
                        self.read_items(sub, file, inner, &child_dir.join(&name));
                    } else if let Some(p) = path_attr(&m.attrs) {
                        let f = child_dir.join(p);
                        let d = f.with_extension("");
                        self.read_file(sub, &f, &d);
                    } else if child_dir.join(format!("{name}.rs")).is_file() {
                        let f = child_dir.join(format!("{name}.rs"));
                        self.read_file(sub, &f, &child_dir.join(&name));
                    } else {
                        let d = child_dir.join(&name);
                        self.read_file(sub, &d.join("mod.rs"), &d);
                    }
                }
                other => Collector {
                    module: &mut module,
                }
                .visit_item(other),
            }
        }
        self.modules.insert(path, module);
    }

    /// The module a path names (the deepest module it passes through,
    /// following re-exports), or None for another crate's or a local name.
    fn resolve(&self, from: &[String], segs: &[String], depth: usize) -> Option<ModPath> {
        if depth > 16 || segs.is_empty() {
            return None;
        }
        let here = &self.modules[from];
        let (mut at, mut rest): (ModPath, &[String]) = match segs[0].as_str() {
            "crate" => (Vec::new(), &segs[1..]),
            "self" => (from.to_vec(), &segs[1..]),
            "super" => {
                let mut at = from.to_vec();
                let mut rest = segs;
                while rest.first().is_some_and(|s| s == "super") {
                    at.pop()?;
                    rest = &rest[1..];
                }
                (at, rest)
            }
            s if here.children.contains(s) => (from.to_vec(), segs),
            // a name a `use` brought in: the path it stands for
            s if here.imports.contains_key(s) && segs.len() > 1 => {
                let mut full = here.imports[s].clone();
                full.extend(segs[1..].iter().cloned());
                return self.resolve(from, &full, depth + 1);
            }
            _ => return None,
        };
        loop {
            let Some(next) = rest.first() else {
                return Some(at);
            };
            let m = &self.modules[&at];
            if m.children.contains(next) {
                at.push(next.clone());
                rest = &rest[1..];
            } else if let Some(target) = m.reexports.get(next) {
                let mut full = target.clone();
                full.extend(rest[1..].iter().cloned());
                return self.resolve(&at, &full, depth + 1).or(Some(at));
            } else {
                return Some(at);
            }
        }
    }

    /// Every module's edges to the modules it names (itself left out).
    fn edges(&self) -> BTreeMap<ModPath, BTreeSet<ModPath>> {
        self.modules
            .iter()
            .map(|(m, module)| {
                let to = module
                    .paths
                    .iter()
                    .filter_map(|p| self.resolve(m, p, 0))
                    .filter(|t| t != m)
                    .collect();
                (m.clone(), to)
            })
            .collect()
    }
}

/// The child of `parent` that `m` lies under, if it lies under one.
fn child_under(parent: &[String], m: &[String]) -> Option<String> {
    (m.len() > parent.len() && m.starts_with(parent)).then(|| m[parent.len()].clone())
}

/// For every module, the graph of its children (each standing for its whole
/// subtree), and a cycle in it if there is one.
fn cycles(c: &Crate) -> Vec<String> {
    let edges = c.edges();
    let mut found = Vec::new();
    for (parent, module) in &c.modules {
        let mut g: BTreeMap<String, BTreeSet<String>> = module
            .children
            .iter()
            .map(|k| (k.clone(), BTreeSet::new()))
            .collect();
        for (from, to) in &edges {
            let Some(a) = child_under(parent, from) else {
                continue;
            };
            for t in to {
                if let Some(b) = child_under(parent, t) {
                    if a != b {
                        g.get_mut(&a).unwrap().insert(b);
                    }
                }
            }
        }
        if let Some(cy) = g.keys().find_map(|k| cycle(&g, k)) {
            let at = if parent.is_empty() {
                "crate".to_string()
            } else {
                parent.join("::")
            };
            found.push(format!("in {at}: {}", cy.join(" -> ")));
        }
    }
    found
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
    "src/main.rs",
    "model/src/lib.rs",
    "jit/src/lib.rs",
    "codegen/src/lib.rs",
    "analysis/src/lib.rs",
    "verify/src/lib.rs",
];

#[test]
fn no_crate_has_a_module_cycle_at_any_level() {
    let mut all = Vec::new();
    for krate in CRATES {
        let c = Crate::read(&common::root().join(krate));
        assert!(c.modules.len() >= 3, "{krate}: {:?}", c.modules.keys());
        all.extend(cycles(&c).into_iter().map(|s| format!("{krate}: {s}")));
    }
    assert!(all.is_empty(), "module cycles:\n{}", all.join("\n"));
}

/// The analysis crate's top-level folders: the pipeline's stages, in order.
const STAGES: [&str; 5] = [
    "logs",
    "model_on_log",
    "estimation",
    "diagnosis",
    "applications",
];

#[test]
fn no_analysis_module_uses_a_later_stage_of_the_pipeline() {
    let c = Crate::read(&common::root().join("analysis/src/lib.rs"));
    let stage = |m: &ModPath| {
        m.first()
            .and_then(|g| STAGES.iter().position(|s| s == g))
            .unwrap_or_else(|| panic!("analysis/src: `{}` is in no stage", m.join("::")))
    };
    let mut back = Vec::new();
    for (m, to) in c.edges() {
        if m.is_empty() {
            continue; // lib.rs itself: its doc example and declarations
        }
        for t in to.iter().filter(|t| !t.is_empty()) {
            if stage(t) > stage(&m) {
                back.push(format!("{} uses {}", m.join("::"), t.join("::")));
            }
        }
    }
    assert!(back.is_empty(), "{back:#?}");
}

/// Write a small crate to a temporary folder; each entry is (file, text).
fn scratch(files: &[(&str, &str)]) -> (tempfile::TempDir, Crate) {
    let dir = tempfile::tempdir().unwrap();
    for (f, text) in files {
        let p = dir.path().join(f);
        std::fs::create_dir_all(p.parent().unwrap()).unwrap();
        std::fs::write(p, text).unwrap();
    }
    let c = Crate::read(&dir.path().join("lib.rs"));
    (dir, c)
}

/// The check sees cycles through every kind of path: `super::`, grouped
/// `use` trees, re-exports, and a child module named from its parent's
/// sibling; and lets a module and its own children use each other.
#[test]
fn a_cycle_through_any_kind_of_path_is_found() {
    let cases: [(&str, &[(&str, &str)]); 4] = [
        (
            "super",
            &[
                ("lib.rs", "pub mod g { pub mod a; pub mod b; }"),
                ("g/a.rs", "pub struct A; pub fn f(_: super::b::B) {}"),
                ("g/b.rs", "pub struct B; pub fn f(_: super::a::A) {}"),
            ],
        ),
        (
            "grouped use",
            &[
                ("lib.rs", "pub mod a; pub mod b;"),
                ("a.rs", "use crate::{b::{B, f}, a as _x}; pub struct A;"),
                ("b.rs", "pub struct B; pub fn f() { let _ = crate::a::A; }"),
            ],
        ),
        (
            "re-export",
            &[
                ("lib.rs", "pub mod p;"),
                ("p.rs", "mod a; mod b; pub use a::A; pub use b::B;"),
                ("p/a.rs", "use super::B; pub struct A;"),
                ("p/b.rs", "pub struct B; fn f(_: super::A) {}"),
            ],
        ),
        (
            "super::super",
            &[
                (
                    "lib.rs",
                    "pub mod x { pub mod deep { pub mod d; } } pub mod y;",
                ),
                (
                    "x/deep/d.rs",
                    "use super::super::super::y::Y; pub struct D;",
                ),
                ("y.rs", "pub struct Y; fn f(_: crate::x::deep::d::D) {}"),
            ],
        ),
    ];
    for (kind, files) in cases {
        let (_dir, c) = scratch(files);
        assert!(!cycles(&c).is_empty(), "{kind}: no cycle found in {c:#?}");
    }
    // a facade and its children are not a cycle; a test module is left out
    let (_dir, c) = scratch(&[
        ("lib.rs", "pub mod p;"),
        ("p.rs", "mod a; pub use a::A; pub struct Shared; #[cfg(test)] mod t { use super::b::*; }\nmod b;"),
        ("p/a.rs", "pub struct A(pub super::Shared);"),
        ("p/b.rs", "#[cfg(test)] mod tests { use super::super::a::A; }"),
    ]);
    assert!(cycles(&c).is_empty(), "{:?}", cycles(&c));
}

/// The real crates' edges include paths of each kind: a `super::` path
/// between siblings and a path through a grouping folder.
#[test]
fn the_real_crates_edges_are_read() {
    let c = Crate::read(&common::root().join("analysis/src/lib.rs"));
    let e = c.edges();
    let p = |s: &str| s.split("::").map(String::from).collect::<ModPath>();
    assert!(
        e[&p("model_on_log::deadreckon")].contains(&p("model_on_log::run")),
        "{:?}",
        e[&p("model_on_log::deadreckon")]
    );
    let m = Crate::read(&common::root().join("model/src/lib.rs"));
    assert!(m.edges()[&p("fuse")].contains(&p("ir")));
}

/// Calibration methods are chosen by type: the CLI parses `--method` once
/// (`MethodChoice::parse`), and no code compares a method's name with a
/// string or looks one up by a literal name.
#[test]
fn no_method_is_chosen_by_a_string() {
    let mut found = Vec::new();
    for dir in ["src", "analysis/src"] {
        let mut files = Vec::new();
        fn walk(d: &Path, out: &mut Vec<PathBuf>) {
            for e in std::fs::read_dir(d).unwrap().flatten() {
                let p = e.path();
                if p.is_dir() {
                    walk(&p, out);
                } else if p.extension().is_some_and(|x| x == "rs") {
                    out.push(p);
                }
            }
        }
        walk(&common::root().join(dir), &mut files);
        for f in files {
            let text = std::fs::read_to_string(&f).unwrap();
            for (n, line) in text.lines().enumerate() {
                let code = line.split("//").next().unwrap_or("");
                let named = code.contains("by_name(\"")
                    || ["method ==", "method !=", "method.as_str() =="]
                        .iter()
                        .any(|p| code.contains(p) && code.contains('"'));
                if named {
                    found.push(format!("{}:{}: {}", f.display(), n + 1, line.trim()));
                }
            }
        }
    }
    assert!(
        found.is_empty(),
        "methods chosen by string:\n{}",
        found.join("\n")
    );
}

/// The library's functions a report module names (`use` leaves and paths
/// under `kinegen_analysis`, whose last segment is a function's lowercase
/// name), except `readers`.
fn library_calls(text: &str, readers: &[&str]) -> Vec<String> {
    struct Calls<'r> {
        readers: &'r [&'r str],
        found: Vec<String>,
    }
    impl Calls<'_> {
        fn check(&mut self, path: &[String]) {
            let last = path.last().map(String::as_str).unwrap_or("");
            let function = last.starts_with(|c: char| c.is_ascii_lowercase());
            if path.first().is_some_and(|s| s == "kinegen_analysis")
                && function
                && !self.readers.contains(&last)
            {
                self.found.push(path.join("::"));
            }
        }
    }
    impl<'ast> Visit<'ast> for Calls<'_> {
        fn visit_item_use(&mut self, u: &'ast syn::ItemUse) {
            let mut leaves = Vec::new();
            use_leaves(&u.tree, &mut Vec::new(), &mut leaves);
            for (_, path) in leaves {
                self.check(&path);
            }
        }
        fn visit_path(&mut self, p: &'ast syn::Path) {
            let segs: Vec<String> = p.segments.iter().map(|s| s.ident.to_string()).collect();
            self.check(&segs);
            syn::visit::visit_path(self, p);
        }
    }
    let file = syn::parse_file(text).expect("a report module parses");
    let mut calls = Calls {
        readers,
        found: Vec::new(),
    };
    calls.visit_file(&file);
    calls.found
}

/// A report only draws (issue 69 item 3): the modules of src/report/ call
/// no function of the library. What a page shows is computed by the
/// library and carried in the command's result (a diagnosis's sightings'
/// range errors, a localisation's figures). The one reader allowed reads a
/// result as it is computed: a long log's track is not held in memory
/// (`model_on_log::track_rows`). A report that computes, as the diagnose
/// page once did with `landmarks::sigma` and `fit::sightings_from_truth`,
/// fails.
#[test]
fn reports_only_draw() {
    const READERS: [&str; 1] = ["against_truth"];
    let dir = common::root().join("src/report");
    let mut found = Vec::new();
    for e in std::fs::read_dir(&dir).unwrap().flatten() {
        let text = std::fs::read_to_string(e.path()).unwrap();
        for f in library_calls(&text, &READERS) {
            found.push(format!("{}: {f}", e.path().display()));
        }
    }
    assert!(
        found.is_empty(),
        "reports that compute:\n{}",
        found.join("\n")
    );
    // the check sees a call by its full path and one imported first
    let computing = "use kinegen_analysis::estimation::fit::sightings_from_truth;\n\
        fn chart(r: &Runner) { let s = kinegen_analysis::model_on_log::landmarks::sigma(r); }\n";
    let seen = library_calls(computing, &READERS);
    assert_eq!(seen.len(), 2, "{seen:?}");
    assert!(seen[0].contains("sightings_from_truth") && seen[1].contains("landmarks::sigma"));
}
