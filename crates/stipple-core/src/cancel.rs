//! Cooperative cancellation of long work (normal estimation), for callers that can be
//! interrupted (the Python package on Ctrl-C). The caller runs the work inside
//! [`with_token`] on its own thread; the work asks [`cancelled`] between its steps (and
//! passes [`token`] into its parallel loops) and stops with an error when it is set.

use std::cell::RefCell;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

thread_local! {
    static TOKEN: RefCell<Option<Arc<AtomicBool>>> = const { RefCell::new(None) };
}

/// Runs `f` with `token` as this thread's cancellation flag.
pub fn with_token<R>(token: Arc<AtomicBool>, f: impl FnOnce() -> R) -> R {
    let before = TOKEN.with(|t| t.replace(Some(token)));
    let r = f();
    TOKEN.with(|t| *t.borrow_mut() = before);
    r
}

/// This thread's flag, to hand to worker threads.
pub fn token() -> Option<Arc<AtomicBool>> {
    TOKEN.with(|t| t.borrow().clone())
}

/// Whether a flag is set.
pub fn is_set(token: &Option<Arc<AtomicBool>>) -> bool {
    token.as_ref().is_some_and(|t| t.load(Ordering::Relaxed))
}

/// Whether this thread's work was asked to stop.
pub fn cancelled() -> bool {
    is_set(&token())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_flag_holds_inside_with_token_only() {
        assert!(!cancelled());
        let t = Arc::new(AtomicBool::new(false));
        with_token(t.clone(), || {
            assert!(!cancelled());
            t.store(true, Ordering::Relaxed);
            assert!(cancelled());
        });
        assert!(!cancelled());
    }
}
