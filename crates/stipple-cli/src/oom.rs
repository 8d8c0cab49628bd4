//! The last line of defence against running out of memory: a command whose memory estimate
//! passed ([`crate::memory`]) can still find an allocation refused (a `--memory` budget above
//! what `ulimit -v` allows, another process taking the memory meanwhile). Rust's standard
//! library then aborts with SIGABRT (and, with `RUST_BACKTRACE` set, a backtrace). Here the
//! binary's allocator remembers the size of the last refused request, and a SIGABRT handler
//! turns an abort that follows one into a one-line error and exit status 1 instead.
//!
//! Fallible requests (`try_reserve`, as the readers make for a file's columns) see the refusal as an ordinary error and
//! never abort, so their callers report it as they report any other error.

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

/// The size of the last allocation the system refused, 0 if none was.
static REFUSED: AtomicUsize = AtomicUsize::new(0);

/// The system allocator, remembering refusals (install with `#[global_allocator]`).
pub struct Remembering;

fn seen(p: *mut u8, size: usize) -> *mut u8 {
    if p.is_null() {
        REFUSED.store(size.max(1), Ordering::Relaxed);
    }
    p
}

// SAFETY: every call is forwarded unchanged to the system allocator.
unsafe impl GlobalAlloc for Remembering {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        seen(unsafe { System.alloc(layout) }, layout.size())
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        seen(unsafe { System.alloc_zeroed(layout) }, layout.size())
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        seen(unsafe { System.realloc(ptr, layout, new_size) }, new_size)
    }
}

/// Writes `n` in decimal into `out`, returning the digits' slice.
fn decimal(mut n: usize, out: &mut [u8; 24]) -> &[u8] {
    let mut i = out.len();
    loop {
        i -= 1;
        out[i] = b'0' + (n % 10) as u8;
        n /= 10;
        if n == 0 {
            return &out[i..];
        }
    }
}

#[cfg(unix)]
extern "C" fn on_abort(_: libc::c_int) {
    let refused = REFUSED.load(Ordering::Relaxed);
    if refused == 0 {
        // Not ours: abort as the default action would.
        // SAFETY: async-signal-safe calls only.
        unsafe {
            libc::signal(libc::SIGABRT, libc::SIG_DFL);
            libc::raise(libc::SIGABRT);
        }
        return;
    }
    let mut digits = [0u8; 24];
    let mib = decimal(refused.div_ceil(1 << 20), &mut digits);
    let parts: [&[u8]; 3] = [
        b"stipple: error: out of memory: the system refused an allocation of about ",
        mib,
        b" MiB, although the command's memory estimate passed. Free memory, raise \
          `ulimit -v`, or ask for less (fewer points, a smaller --size); a --memory budget \
          above what the machine has leads here.\n",
    ];
    for p in parts {
        // SAFETY: write(2) is async-signal-safe; the slices outlive the call.
        unsafe {
            libc::write(2, p.as_ptr().cast(), p.len());
        }
    }
    // SAFETY: _exit is async-signal-safe and runs no destructors or atexit handlers (which
    // could allocate again). Unfinished outputs stay at their temporary names, which a later
    // run recognises as left by a dead process.
    unsafe { libc::_exit(1) }
}

/// Installs the SIGABRT handler (once, at start-up).
pub fn install() {
    #[cfg(unix)]
    // SAFETY: installing a handler that only makes async-signal-safe calls.
    unsafe {
        libc::signal(
            libc::SIGABRT,
            on_abort as extern "C" fn(libc::c_int) as libc::sighandler_t,
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decimal_digits() {
        let mut d = [0u8; 24];
        assert_eq!(decimal(0, &mut d), b"0");
        assert_eq!(decimal(5795, &mut d), b"5795");
        assert_eq!(
            decimal(usize::MAX, &mut d),
            usize::MAX.to_string().as_bytes()
        );
    }
}
