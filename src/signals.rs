//! Interrupted runs leave nothing behind: on SIGINT, SIGTERM or SIGHUP the
//! temporary files being written are removed and a `kinegen derive` child is
//! stopped (it would otherwise keep the machine's one symbolica thread busy for
//! a result nobody waits for), then the process exits with 130. (SIGKILL cannot
//! be caught; atomic writes still guarantee no half-written output then.) A
//! reader that stops reading stdout (`| head`) ends the run quietly, with the
//! same cleanup.
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

/// Remove the temporaries and stop the derive child.
fn clean_up() {
    kinegen_model::files::remove_temporaries();
    for pid in children().drain(..) {
        // SAFETY: kill(2) with a pid this process spawned and still waits on
        unsafe {
            libc::kill(pid as libc::pid_t, libc::SIGTERM);
        }
    }
}

/// Install the handlers (once, at start-up).
pub fn install() {
    // an error here only means no cleanup on signals, which is no reason to stop
    let _ = ctrlc::set_handler(|| {
        clean_up();
        std::process::exit(130);
    });
    // `kinegen compare ... | head`: once the reader has gone, printing fails
    // with EPIPE and `println!` panics. That is no error of the user's: stop
    // quietly, as a Unix filter does (exit 141 = 128 + SIGPIPE), leaving nothing
    // behind. Every other panic is reported as before.
    let default = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        let message = info
            .payload()
            .downcast_ref::<String>()
            .map(String::as_str)
            .or_else(|| info.payload().downcast_ref::<&str>().copied())
            .unwrap_or("");
        if message.starts_with("failed printing to std") && message.contains("Broken pipe") {
            clean_up();
            std::process::exit(141);
        }
        default(info);
    }));
}
