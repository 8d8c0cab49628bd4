//! The library's errors as Python exceptions: file problems are `OSError`
//! (`FileNotFoundError` for a missing file), malformed files and bad options `ValueError`
//! naming the option as Python spells it, anything else `RuntimeError`.

use pyo3::exceptions::{PyFileNotFoundError, PyOSError, PyRuntimeError, PyValueError};
use pyo3::PyErr;

/// The command line's flag names in a message (`--fill-iterations`) as the keyword arguments
/// that set them (`fill_iterations`).
pub fn python_names(msg: &str) -> String {
    let mut out = String::with_capacity(msg.len());
    let b = msg.as_bytes();
    let mut i = 0;
    while i < b.len() {
        let flag = b[i] == b'-'
            && b.get(i + 1) == Some(&b'-')
            && b.get(i + 2).is_some_and(|c| c.is_ascii_lowercase())
            && (i == 0 || !b[i - 1].is_ascii_alphanumeric());
        if flag {
            let mut j = i + 2;
            while j < b.len() && (b[j].is_ascii_alphanumeric() || b[j] == b'-') {
                j += 1;
            }
            out.push_str(&msg[i + 2..j].replace('-', "_"));
            i = j;
        } else {
            let c = msg[i..].chars().next().expect("in bounds");
            out.push(c);
            i += c.len_utf8();
        }
    }
    out
}

/// An error of the library (through the CLI's layer) as a Python exception.
pub fn to_py(e: anyhow::Error) -> PyErr {
    let msg = python_names(&stipple_cli::message(&e));
    for cause in e.chain() {
        if let Some(io) = cause.downcast_ref::<stipple_io::IoError>() {
            return match io {
                stipple_io::IoError::Io { source, .. }
                    if source.kind() == std::io::ErrorKind::NotFound =>
                {
                    PyFileNotFoundError::new_err(msg)
                }
                stipple_io::IoError::Io { .. } => PyOSError::new_err(msg),
                _ => PyValueError::new_err(msg),
            };
        }
        if let Some(io) = cause.downcast_ref::<std::io::Error>() {
            return if io.kind() == std::io::ErrorKind::NotFound {
                PyFileNotFoundError::new_err(msg)
            } else {
                PyOSError::new_err(msg)
            };
        }
        if let Some(stipple_lod::LodError::Interrupted) = cause.downcast_ref() {
            return pyo3::exceptions::PyKeyboardInterrupt::new_err(msg);
        }
    }
    let text = stipple_cli::message(&e);
    if text.contains("already exists") || text.contains("refusing to overwrite") {
        return pyo3::exceptions::PyFileExistsError::new_err(msg);
    }
    // Errors about what was asked (a value out of range, a flag that needs another) name the
    // option, and are the caller's to fix.
    if stipple_cli::message(&e).contains("--") {
        PyValueError::new_err(msg)
    } else {
        PyRuntimeError::new_err(msg)
    }
}

pub fn value_error(msg: impl Into<String>) -> PyErr {
    PyValueError::new_err(msg.into())
}
