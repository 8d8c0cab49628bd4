//! `stipple._stipple`: the Python package's native module (PyO3 + numpy). The classes and
//! functions are documented for Python users in `python/stipple/__init__.pyi`; this crate
//! only turns Python values into the library's and back:
//!
//! * render options are the command line's flags (`fill_iterations=2` is
//!   `--fill-iterations=2`), parsed by the same `clap` definitions
//!   ([`stipple_cli::api::parse_render_args`]) and rendered by the same code
//!   ([`stipple_cli::api::render_prepared`]), so a render from Python equals the CLI's;
//! * long work (reading, normal estimation, rendering, building a tree) runs on a worker thread
//!   with the GIL released, while the calling thread checks for signals, so Ctrl-C raises
//!   `KeyboardInterrupt` at once (a tree build stops and removes what it wrote; a render
//!   finishes in the background and its result is dropped);
//! * a panic never reaches Python: it becomes a `RuntimeError`.

mod camera;
mod cloud;
mod errors;
mod options;
mod render;

use pyo3::prelude::*;
use std::sync::mpsc::{self, RecvTimeoutError};
use std::time::Duration;

/// Runs `work` on a worker thread with the GIL released, checking for signals every 50 ms:
/// an interrupt raises `KeyboardInterrupt` (`on_interrupt` is called first: it may tell the
/// work to stop, and returns whether to wait for the worker to end, for work that stops soon
/// and cleans up; a second interrupt ends the wait. Work not waited for finishes in the
/// background and its result is dropped).
/// A panic in `work` becomes a `RuntimeError`.
pub(crate) fn run_detached<T: Send + 'static>(
    py: Python<'_>,
    work: impl FnOnce() -> T + Send + 'static,
    on_interrupt: impl FnOnce() -> bool,
) -> PyResult<T> {
    let (tx, rx) = mpsc::channel();
    std::thread::Builder::new()
        .name("stipple-worker".into())
        .spawn(move || {
            let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(work));
            let _ = tx.send(r);
        })
        .map_err(|e| {
            pyo3::exceptions::PyRuntimeError::new_err(format!("could not start a thread: {e}"))
        })?;
    let mut rx = rx;
    loop {
        // The receiver goes into the GIL-free closure and comes back (it is not `Sync`).
        let (got, back) = py.detach(move || (rx.recv_timeout(Duration::from_millis(50)), rx));
        rx = back;
        match got {
            Ok(Ok(v)) => return Ok(v),
            Ok(Err(panic)) => {
                return Err(pyo3::exceptions::PyRuntimeError::new_err(format!(
                    "stipple: internal error (please report it): {}",
                    panic_message(panic.as_ref())
                )));
            }
            Err(RecvTimeoutError::Timeout) => {
                if let Err(e) = py.check_signals() {
                    if on_interrupt() {
                        // Until the work has stopped, or a second interrupt.
                        loop {
                            let (got, back) =
                                py.detach(move || (rx.recv_timeout(Duration::from_millis(50)), rx));
                            rx = back;
                            if !matches!(got, Err(RecvTimeoutError::Timeout))
                                || py.check_signals().is_err()
                            {
                                break;
                            }
                        }
                    }
                    return Err(e);
                }
            }
            Err(RecvTimeoutError::Disconnected) => {
                return Err(pyo3::exceptions::PyRuntimeError::new_err(
                    "stipple: the worker thread ended without a result",
                ))
            }
        }
    }
}

/// Runs `f` on the calling thread, turning a panic into a `RuntimeError` (pyo3 would raise
/// its own `PanicException`, which is not an `Exception`).
pub(crate) fn guard<T>(f: impl FnOnce() -> T) -> PyResult<T> {
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)).map_err(|panic| {
        pyo3::exceptions::PyRuntimeError::new_err(format!(
            "stipple: internal error (please report it): {}",
            panic_message(panic.as_ref())
        ))
    })
}

fn panic_message(panic: &(dyn std::any::Any + Send)) -> String {
    panic
        .downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| panic.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "unknown panic".into())
}

#[pymodule]
fn _stipple(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_class::<cloud::Cloud>()?;
    m.add_class::<camera::Camera>()?;
    m.add_class::<render::Renderer>()?;
    m.add_class::<render::RenderResult>()?;
    m.add_function(wrap_pyfunction!(cloud::read, m)?)?;
    m.add_function(wrap_pyfunction!(cloud::demo, m)?)?;
    m.add_function(wrap_pyfunction!(render::render, m)?)?;
    m.add_function(wrap_pyfunction!(render::build_lod, m)?)?;
    m.add_function(wrap_pyfunction!(options::render_options, m)?)?;
    Ok(())
}
