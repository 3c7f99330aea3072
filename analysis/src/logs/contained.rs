//! A third-party decoder's panic on hostile bytes, turned into an error.
//!
//! The `mcap` crate (0.26, the newest) indexes and subtracts lengths it
//! read from the file without checking them all: a corrupt chunk makes it
//! panic ("attempt to subtract with overflow", found by the hostile-input
//! campaign). mcap_messages.rs checks the lengths it can before the crate
//! parses a record, and every call into the crate still runs here: a panic
//! becomes the caller's located error, and its message is not printed (a
//! panic hook that stays silent on this thread while a contained call runs,
//! and defers to the one before it elsewhere).
use std::cell::Cell;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::Once;

thread_local!(static CONTAINED: Cell<bool> = const { Cell::new(false) });
static QUIET_HOOK: Once = Once::new();

/// `f()`, or what it panicked with.
pub fn contained<T>(f: impl FnOnce() -> T) -> Result<T, String> {
    QUIET_HOOK.call_once(|| {
        let before = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if !CONTAINED.with(Cell::get) {
                before(info);
            }
        }));
    });
    let was = CONTAINED.with(|c| c.replace(true));
    let result = catch_unwind(AssertUnwindSafe(f));
    CONTAINED.with(|c| c.set(was));
    result.map_err(|payload| {
        (payload.downcast_ref::<&str>().map(|s| s.to_string()))
            .or_else(|| payload.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "a panic".into())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A panic inside becomes its message; a value passes through; a panic
    /// outside a contained call still panics.
    #[test]
    fn a_panic_inside_is_an_error() {
        assert_eq!(contained(|| 2 + 2), Ok(4));
        let e = contained(|| -> u32 { panic!("length {} past the end", 9) }).unwrap_err();
        assert_eq!(e, "length 9 past the end");
        assert!(std::panic::catch_unwind(|| panic!("outside")).is_err());
    }
}
