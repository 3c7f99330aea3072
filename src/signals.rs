//! Interrupted runs leave nothing behind: on SIGINT, SIGTERM or SIGHUP the
//! temporary files being written are removed and a `kinegen derive` child is
//! stopped (it would otherwise keep the machine's one symbolica thread busy for
//! a result nobody waits for), then the process exits with 130. (SIGKILL cannot
//! be caught; atomic writes still guarantee no half-written output then.)
use std::sync::Mutex;

static CHILDREN: Mutex<Vec<u32>> = Mutex::new(Vec::new());

fn children() -> std::sync::MutexGuard<'static, Vec<u32>> {
    CHILDREN.lock().unwrap_or_else(|e| e.into_inner())
}

pub fn child_started(pid: u32) {
    children().push(pid);
}

pub fn child_finished(pid: u32) {
    children().retain(|p| *p != pid);
}

/// Install the handler (once, at start-up).
pub fn install() {
    // an error here only means no cleanup on signals, which is no reason to stop
    let _ = ctrlc::set_handler(|| {
        kinegen_codegen::generate::remove_temporaries();
        for pid in children().drain(..) {
            // SAFETY: kill(2) with a pid this process spawned and still waits on
            unsafe {
                libc::kill(pid as libc::pid_t, libc::SIGTERM);
            }
        }
        std::process::exit(130);
    });
}
