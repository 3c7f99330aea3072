//! `kinegen generate`: derive every spec and write (or check) the generated crate.
use crate::emit::{Backend, RustBackend};
use kinegen_model::ir::ModelIr;
use kinegen_model::options::GenOptions;
use kinegen_model::spec::Model;
use kinegen_model::SourceError;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// What one generation run did, for the CLI to print.
#[derive(Debug)]
pub struct Report {
    pub models: Vec<(ModelIr, Duration)>,
    /// Files that differ from what would be written (all of them when writing).
    pub stale: Vec<PathBuf>,
    pub total: Duration,
}

/// Generation failure: a bad spec (exit 2) or an I/O problem.
#[derive(Debug, thiserror::Error)]
pub enum GenerateError {
    #[error("{0}")]
    Spec(#[from] SourceError),
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> GenerateError + '_ {
    move |source| GenerateError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// Spec files (`*.toml`) directly in `spec_dir`, sorted.
pub fn spec_files(spec_dir: &Path) -> Result<Vec<PathBuf>, GenerateError> {
    kinegen_model::files::spec_files(spec_dir).map_err(io(spec_dir))
}

/// Write via a temporary file and rename ([`kinegen_model::files::write_atomic`]).
pub fn write_atomic(path: &Path, content: &str) -> Result<(), GenerateError> {
    kinegen_model::files::write_atomic(path, content).map_err(|e| GenerateError::Io {
        path: e.path,
        source: e.source,
    })
}

/// Files to write (path, content) and the derived models with their derivation times.
pub type Rendered = (Vec<(PathBuf, String)>, Vec<(ModelIr, Duration)>);

/// What `kinegen generate` does, as one value (prost-build's shape): the
/// specs, where the crate goes, whether only to check it, and the backend
/// that writes the code. [`Config::new`] is the Rust backend; a new backend
/// is an implementation of [`Backend`] given here.
pub struct Config<'a> {
    pub spec_dir: &'a Path,
    pub out_dir: &'a Path,
    /// Only list the files that differ instead of writing them.
    pub check: bool,
    pub backend: &'a dyn Backend,
    /// How derivation handles removable singularities; the emitter writes
    /// the switch the IR carries, and verification probes it there.
    pub options: GenOptions,
}

impl<'a> Config<'a> {
    /// The specs of `spec_dir` into the crate at `out_dir`, with the Rust backend.
    pub fn new(spec_dir: &'a Path, out_dir: &'a Path, check: bool) -> Config<'a> {
        Config {
            spec_dir,
            out_dir,
            check,
            backend: &RustBackend,
            options: GenOptions::DEFAULT,
        }
    }
}

/// Every file the generated crate should contain, with its content.
pub fn render(c: &Config) -> Result<Rendered, GenerateError> {
    let (spec_dir, out_dir) = (c.spec_dir, c.out_dir);
    let mut files = Vec::new();
    let mut models = Vec::new();
    let dir_name = spec_dir
        .file_name()
        .map(|n| n.to_string_lossy().to_string())
        .unwrap_or_else(|| "spec".into());
    let paths = spec_files(spec_dir)?;
    if paths.is_empty() {
        // writing would delete every model of an existing crate
        return Err(SourceError::new(
            spec_dir,
            None,
            "no spec files (*.toml) in this directory: nothing to generate",
        )
        .into());
    }
    let mut seen: Vec<(String, PathBuf)> = Vec::new();
    for path in paths {
        let model = Model::load(&path)?;
        if let Some((_, other)) = seen.iter().find(|(n, _)| n == &model.name) {
            return Err(SourceError::new(&path, None, format!("model name `{}` is also the name of {}: each spec needs its own name (it names the generated module)", model.name, other.display())).into());
        }
        seen.push((model.name.clone(), path.clone()));
        let t0 = Instant::now();
        let ir = crate::derive_model(&model, &c.options)?;
        let took = t0.elapsed();
        let rel = format!("{dir_name}/{}", path.file_name().unwrap().to_string_lossy());
        let (module, source) = c.backend.module(&ir, &rel);
        files.push((out_dir.join(module), source));
        files.push((
            out_dir.join("ir").join(format!("{}.json", ir.name)),
            ir.to_json() + "\n",
        ));
        models.push((ir, took));
    }
    let names: Vec<String> = models.iter().map(|(m, _)| m.name.clone()).collect();
    files.extend(
        c.backend
            .shared(&names)
            .into_iter()
            .map(|(p, text)| (out_dir.join(p), text)),
    );
    Ok((files, models))
}

/// Generated files present on disk that no spec produces any more.
fn orphans(out_dir: &Path, files: &[(PathBuf, String)]) -> Vec<PathBuf> {
    let mut v = Vec::new();
    for (sub, ext) in [("src", "rs"), ("ir", "json")] {
        if let Ok(rd) = std::fs::read_dir(out_dir.join(sub)) {
            for e in rd.flatten() {
                let p = e.path();
                if p.extension().is_some_and(|x| x == ext) && !files.iter().any(|(f, _)| *f == p) {
                    v.push(p);
                }
            }
        }
    }
    v.sort();
    v
}

/// The manifest of a generated crate written outside this workspace: the same
/// features and dependencies as `generated/Cargo.toml`.
const STANDALONE_MANIFEST: &str = r#"[package]
name = "kinegen-generated"
version = "0.1.0"
edition = "2021"
description = "Kinematic and observation kernels generated by kinegen (no_std, libm only). Do not edit the sources: change the specs and run `kinegen generate`."

[lib]
name = "kinegen_generated"

[features]
nalgebra = ["dep:nalgebra"]
# `call`: every kernel by name, for verification tools (not for firmware)
dispatch = []
# every kernel in f32 (`Real = f32`), for a single-precision FPU
f32 = []
# on a computer: std's (the C library's) exp and pow: faster than libm's
std = []

[dependencies]
libm = "0.2"
nalgebra = { version = "0.33", default-features = false, optional = true }
"#;

/// Derive all specs, then either write the files (atomically, only after every spec
/// derived without error) or, with `check`, only list the stale ones.
pub fn generate(c: &Config) -> Result<Report, GenerateError> {
    let t0 = Instant::now();
    let (out_dir, check) = (c.out_dir, c.check);
    let (files, models) = render(c)?;
    let mut stale: Vec<PathBuf> = files
        .iter()
        .filter(|(p, content)| std::fs::read_to_string(p).map_or(true, |old| old != *content))
        .map(|(p, _)| p.clone())
        .collect();
    let extra = orphans(out_dir, &files);
    stale.extend(extra.iter().cloned());
    if !check {
        for (p, content) in &files {
            write_atomic(p, content)?;
        }
        for p in &extra {
            std::fs::remove_file(p).map_err(io(p))?;
        }
        // a new crate gets a manifest so it builds as it is; an existing one
        // is the user's (name, version, workspace) and is never rewritten
        let manifest = out_dir.join("Cargo.toml");
        if !manifest.exists() {
            write_atomic(&manifest, STANDALONE_MANIFEST)?;
        }
    }
    Ok(Report {
        models,
        stale,
        total: t0.elapsed(),
    })
}
