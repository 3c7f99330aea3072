//! kinegen-codegen: the derivation stage and the Rust emitter.
//!
//! This is the only crate that links symbolica. [`derive_model`] runs every
//! symbolic computation on one dedicated worker thread per process, after taking a
//! machine-wide lock file, because unlicensed symbolica allows one thread per user
//! machine-wide and aborts a second one. Concurrent callers (test threads, parallel
//! processes) therefore queue instead of crashing.
//!
//! The stage in one example (not run here: a doctest would be a second
//! process deriving beside the tests): spec -> model -> IR -> Rust.
//!
//! ```no_run
//! use kinegen_codegen::{derive_model, emit::emit_module, generate};
//! use kinegen_model::spec::Model;
//! use std::path::Path;
//!
//! let model = Model::load(Path::new("spec/diff_drive.toml")).unwrap();
//! // every symbolic step (Jacobians, the exact step, inverse kinematics,
//! // removable singularities) on this crate's one symbolica thread
//! let ir = derive_model(&model, &Default::default()).unwrap();
//! // one model's Rust module, or a crate of every spec in a folder
//! let module: String = emit_module(&ir, "spec/diff_drive.toml");
//! let config = generate::Config::new(Path::new("spec"), Path::new("generated"), false);
//! generate::generate(&config).unwrap();
//! ```
pub mod derive;
pub mod emit;
pub mod generate;
mod symbolic;
mod tape;

use kinegen_model::ir::ModelIr;
use kinegen_model::options::GenOptions;
use kinegen_model::spec::Model;
use kinegen_model::SourceError;
use std::sync::mpsc::{channel, Sender};
use std::sync::{Mutex, OnceLock};

type Job = Box<dyn FnOnce() + Send>;

fn worker() -> &'static Mutex<Sender<Job>> {
    static WORKER: OnceLock<Mutex<Sender<Job>>> = OnceLock::new();
    WORKER.get_or_init(|| {
        let (tx, rx) = channel::<Job>();
        std::thread::Builder::new()
            .name("kinegen-symbolica".into())
            .spawn(move || {
                // Held until the process exits, like symbolica's own per-thread permit.
                let _lock = machine_lock();
                for job in rx {
                    job();
                }
            })
            .expect("spawn the symbolica worker thread");
        Mutex::new(tx)
    })
}

/// Block until this process may use symbolica (no other kinegen process is deriving).
fn machine_lock() -> Option<fd_lock::RwLockWriteGuard<'static, std::fs::File>> {
    // Keep symbolica's licence banner off stdout: machine-readable output goes there.
    std::env::set_var("SYMBOLICA_HIDE_BANNER", "1");
    let path = std::env::temp_dir().join("kinegen-symbolica.lock");
    let file = std::fs::OpenOptions::new()
        .create(true)
        .truncate(false)
        .write(true)
        .open(&path)
        .ok()?;
    let lock: &'static mut fd_lock::RwLock<std::fs::File> =
        Box::leak(Box::new(fd_lock::RwLock::new(file)));
    let guard = lock.write().ok();
    wait_for_symbolica_permit();
    guard
}

/// Wait (politely, without taking it) until symbolica's own per-user thread permit
/// is free, so a permit still held by another program, or by a kinegen process that
/// is exiting, makes us wait instead of making symbolica abort. The lock file is
/// symbolica's: same directory rule (SYMBOLICA_LOCK_DIR, else the per-user runtime
/// or cache directory), same name, same flock.
fn wait_for_symbolica_permit() {
    let dir = std::env::var_os("SYMBOLICA_LOCK_DIR")
        .map(std::path::PathBuf::from)
        .or_else(|| {
            directories::ProjectDirs::from("io", "symbolica", "symbolica").map(|d| {
                d.runtime_dir()
                    .unwrap_or_else(|| d.cache_dir())
                    .join("locks")
            })
        });
    let Some(dir) = dir else { return };
    if let Ok(f) = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .open(dir.join("symbolica-restricted-thread-0.lock"))
    {
        if f.lock().is_ok() {
            let _ = f.unlock();
        }
    }
}

/// A job on the symbolica thread that did not return.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ThreadError {
    /// The job panicked (with this message); the thread lives on.
    #[error("{0}")]
    Panicked(String),
    /// The thread could not take the job or answer it.
    #[error("the symbolica thread is gone: {0}")]
    Gone(String),
}

/// Run `f` on the process's symbolica thread and wait for its result. A panic in
/// `f` is caught there (the thread survives for the next job) and returned as Err.
pub fn on_symbolica_thread<T: Send + 'static>(
    f: impl FnOnce() -> T + Send + 'static,
) -> Result<T, ThreadError> {
    let (tx, rx) = channel();
    let job: Job = Box::new(move || {
        let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)).map_err(|p| {
            ThreadError::Panicked(
                p.downcast_ref::<String>()
                    .cloned()
                    .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
                    .unwrap_or_default(),
            )
        });
        let _ = tx.send(r);
    });
    let gone = |e: String| ThreadError::Gone(e);
    worker()
        .lock()
        .map_err(|e| gone(e.to_string()))?
        .send(job)
        .map_err(|e| gone(e.to_string()))?;
    rx.recv().map_err(|e| gone(e.to_string()))?
}

/// Derive the IR of a validated model (symbolica, on the dedicated thread),
/// its removable singularities' series as `options` say.
pub fn derive_model(model: &Model, options: &GenOptions) -> Result<ModelIr, SourceError> {
    let (m, o) = (model.clone(), *options);
    on_symbolica_thread(move || derive::derive(&m, &o)).unwrap_or_else(|panic| {
        Err(SourceError::new(
            &model.path,
            None,
            format!("internal error while deriving: {panic}"),
        ))
    })
}
