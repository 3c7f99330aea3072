//! Machine code for one tape, and the cache an [`crate::Evaluator`] keeps it
//! in beside its function: empty until the tape is hot, emptied by a clone.
use cranelift_jit::JITModule;
use std::sync::atomic::AtomicU32;
use std::sync::{Arc, Mutex, OnceLock};

/// `fn(args: *const *const f64, out: *mut f64)`: `args[a]` points at argument
/// `a`'s values, `out` receives the outputs.
pub(crate) type Entry = unsafe extern "C" fn(*const *const f64, *mut f64);

/// A compiled tape.
pub struct Native {
    pub(crate) entry: Entry,
    /// Values each argument must have (its largest index read, plus one).
    pub(crate) arg_len: Vec<usize>,
    pub(crate) outputs: usize,
    /// Owns the code memory `entry` points into; freed with the `Native`.
    pub(crate) module: Mutex<Option<JITModule>>,
}

// SAFETY: after `finalize_definitions` the code `entry` points into is immutable
// and only ever called; the module is touched again only by `Drop`, under the
// mutex. The entry point reads its arguments and writes `out`, nothing shared.
unsafe impl Send for Native {}
unsafe impl Sync for Native {}

impl Drop for Native {
    fn drop(&mut self) {
        if let Some(m) = self.module.get_mut().ok().and_then(Option::take) {
            // SAFETY: `self` is being dropped, so `entry` can no longer be called.
            unsafe { m.free_memory() };
        }
    }
}

/// The compiled form of a tape, filled on demand. Cloning gives an empty cache:
/// a clone may be edited (the mutation sweep corrupts tapes), and must never run
/// the original's code. An unedited clone finds its code again in the JIT's
/// process-wide table.
#[derive(Default)]
pub struct NativeCache {
    /// Evaluations so far (a tape is compiled once it is hot).
    pub(crate) calls: AtomicU32,
    /// `Some(None)`: no machine code for this tape (no backend).
    pub(crate) code: OnceLock<Option<Arc<Native>>>,
}

impl Clone for NativeCache {
    fn clone(&self) -> Self {
        NativeCache::default()
    }
}

impl std::fmt::Debug for NativeCache {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let state = match self.code.get() {
            Some(Some(_)) => "compiled",
            Some(None) => "interpreted (no backend)",
            None => "interpreted",
        };
        write!(f, "NativeCache({state})")
    }
}

/// A cache is not part of what a function is.
impl PartialEq for NativeCache {
    fn eq(&self, _: &Self) -> bool {
        true
    }
}
