//! `kinegen generate`: derive every spec and write (or check) the generated crate.
use crate::emit::{emit_lib, emit_linalg, emit_math, emit_module};
use kinegen_model::ir::ModelIr;
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
    let mut v: Vec<PathBuf> = std::fs::read_dir(spec_dir)
        .map_err(io(spec_dir))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    v.sort();
    Ok(v)
}

/// Files to write (path, content) and the derived models with their derivation times.
pub type Rendered = (Vec<(PathBuf, String)>, Vec<(ModelIr, Duration)>);

/// Every file the generated crate should contain, with its content.
pub fn render(spec_dir: &Path, out_dir: &Path) -> Result<Rendered, GenerateError> {
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
        let ir = crate::derive_model(&model)?;
        let took = t0.elapsed();
        let rel = format!("{dir_name}/{}", path.file_name().unwrap().to_string_lossy());
        files.push((
            out_dir.join("src").join(format!("{}.rs", ir.name)),
            emit_module(&ir, &rel),
        ));
        files.push((
            out_dir.join("ir").join(format!("{}.json", ir.name)),
            ir.to_json() + "\n",
        ));
        models.push((ir, took));
    }
    let names: Vec<String> = models.iter().map(|(m, _)| m.name.clone()).collect();
    files.push((out_dir.join("src").join("lib.rs"), emit_lib(&names)));
    files.push((out_dir.join("src").join("linalg.rs"), emit_linalg()));
    files.push((out_dir.join("src").join("math.rs"), emit_math()));
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

/// Derive all specs, then either write the files (atomically, only after every spec
/// derived without error) or, with `check`, only list the stale ones.
pub fn generate(spec_dir: &Path, out_dir: &Path, check: bool) -> Result<Report, GenerateError> {
    let t0 = Instant::now();
    let (files, models) = render(spec_dir, out_dir)?;
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
    }
    Ok(Report {
        models,
        stale,
        total: t0.elapsed(),
    })
}

/// Temporary files being written now, so a signal handler can remove them
/// (`remove_temporaries`): a run interrupted while writing leaves nothing behind.
static TEMPORARIES: std::sync::Mutex<Vec<std::path::PathBuf>> = std::sync::Mutex::new(Vec::new());

fn temporaries() -> std::sync::MutexGuard<'static, Vec<std::path::PathBuf>> {
    // a panic elsewhere while holding the lock leaves the list itself intact
    TEMPORARIES.lock().unwrap_or_else(|e| e.into_inner())
}

/// `std::fs::write`, except that with `KINEGEN_TEST_WRITE_PAUSE_MS=N` in the
/// environment it writes half, pauses N ms, then writes the rest: the one way a
/// test can interrupt a write at a known moment (the cleanup on signals is
/// otherwise untestable, the window being microseconds wide).
fn write_slowly_if_asked(tmp: &Path, content: &str) -> std::io::Result<()> {
    use std::io::Write;
    let pause = std::env::var("KINEGEN_TEST_WRITE_PAUSE_MS")
        .ok()
        .and_then(|v| v.parse::<u64>().ok());
    let Some(ms) = pause else {
        return std::fs::write(tmp, content);
    };
    let mut f = std::fs::File::create(tmp)?;
    let half = content.len() / 2;
    f.write_all(&content.as_bytes()[..half])?;
    f.flush()?;
    std::thread::sleep(std::time::Duration::from_millis(ms));
    f.write_all(&content.as_bytes()[half..])
}

/// Remove every temporary file a `write_atomic` in this process is writing
/// (from the CLI's SIGINT/SIGTERM/SIGHUP handler).
pub fn remove_temporaries() {
    for p in temporaries().drain(..) {
        let _ = std::fs::remove_file(p);
    }
}

/// Write via a temporary file in the same directory and rename, so a reader never
/// sees a half-written file.
pub fn write_atomic(path: &Path, content: &str) -> Result<(), GenerateError> {
    let dir = path.parent().unwrap_or(Path::new("."));
    std::fs::create_dir_all(dir).map_err(io(dir))?;
    // unique per writer, so concurrent writers of the same file never share a temp file
    static COUNTER: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let n = COUNTER.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let tmp = dir.join(format!(
        ".{}.{}-{n}.kinegen-tmp",
        path.file_name().unwrap().to_string_lossy(),
        std::process::id()
    ));
    temporaries().push(tmp.clone());
    // errors name the file the user asked for, not the temporary one
    let done = write_slowly_if_asked(&tmp, content).and_then(|()| std::fs::rename(&tmp, path));
    if done.is_err() {
        let _ = std::fs::remove_file(&tmp); // never leave a half-written temporary
    }
    temporaries().retain(|p| p != &tmp);
    done.map_err(io(path))
}
