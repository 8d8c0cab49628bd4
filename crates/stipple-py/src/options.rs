//! Keyword arguments as `stipple render`'s flags: `fill_iterations=2` → `--fill-iterations=2`,
//! `no_lighting=True` → `--no-lighting`, `background=(0, 0, 0)` → `--background=0,0,0`,
//! `light="disc:1,2,0,0.2"` → `--light=disc:1,2,0,0.2`. Names are checked against
//! the command's own list, so every flag of `stipple render` (and only those) is an option.

use crate::errors::{python_names, value_error};
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyFloat, PyInt, PyList, PyString, PyTuple};
use stipple_cli::api::{parse_render_args, render_options as cli_options, OptionInfo};
use stipple_cli::cmd::render::RenderArgs;

/// Flags that the Python API gives another way.
fn reserved(name: &str) -> Option<&'static str> {
    Some(match name {
        "size" | "eye" | "target" | "up" | "fov" | "ortho" => {
            "is part of the camera: give it to stipple.Camera(...)"
        }
        "output" | "depth_out" | "normal_out" | "camera_out" | "layer_images" | "stats" => {
            "is a file output of `stipple render`; the result holds it as arrays \
             (.image, .depth, .normals, .camera, .stats)"
        }
        "save_normals" => {
            "is a file output of `stipple render`; a cloud keeps the normals a render estimated \
             (cloud.normals)"
        }
        "input" | "demo" | "points" | "seed" => {
            "names the input: pass a stipple.Cloud, a file path or stipple.demo(...)"
        }
        "pipeline" | "backend" => "is given once, as its own argument",
        _ => return None,
    })
}

fn scalar(v: &Bound<'_, PyAny>) -> Option<String> {
    if v.is_instance_of::<PyBool>() {
        return None;
    }
    if v.is_instance_of::<PyInt>() {
        return v.extract::<i64>().ok().map(|x| x.to_string());
    }
    if v.is_instance_of::<PyFloat>() {
        // Rust's shortest representation reads back to the same f64.
        return v.extract::<f64>().ok().map(|x| format!("{x:?}"));
    }
    if v.is_instance_of::<PyString>() {
        return v.extract::<String>().ok();
    }
    // NumPy scalars and other numbers.
    if let Ok(x) = v.extract::<i64>() {
        return Some(x.to_string());
    }
    v.extract::<f64>().ok().map(|x| format!("{x:?}"))
}

/// One option's command-line arguments.
fn option_args(info: &OptionInfo, key: &str, v: &Bound<'_, PyAny>) -> PyResult<Vec<String>> {
    let flag = format!("--{}", info.long);
    if !info.takes_value {
        return match v.extract::<bool>() {
            Ok(true) if v.is_instance_of::<PyBool>() => Ok(vec![flag]),
            Ok(false) if v.is_instance_of::<PyBool>() => Ok(vec![]),
            _ => Err(value_error(format!(
                "{key}: a switch: pass True or False, not {}",
                v.repr()?
            ))),
        };
    }
    if let Some(s) = scalar(v) {
        return Ok(vec![format!("{flag}={s}")]);
    }
    if v.is_instance_of::<PyBool>() {
        return Err(value_error(format!(
            "{key}: takes a value (see stipple.render_options()), not {}",
            v.repr()?
        )));
    }
    if v.is_instance_of::<PyList>() || v.is_instance_of::<PyTuple>() || v.hasattr("__len__")? {
        let items: Vec<Bound<'_, PyAny>> = v.try_iter()?.collect::<PyResult<_>>()?;
        // Numbers only: `background=(0, 0, 0)`, `range=(10, 250)`.
        let parts: Option<Vec<String>> = items
            .iter()
            .map(|i| {
                if i.is_instance_of::<PyString>() {
                    None
                } else {
                    scalar(i)
                }
            })
            .collect();
        if let Some(p) = parts.filter(|p| !p.is_empty()) {
            return Ok(vec![format!("{flag}={}", p.join(","))]);
        }
    }
    Err(value_error(format!(
        "{key}: expected a number, a string or a sequence of numbers, not {}",
        v.repr()?
    )))
}

/// The command-line arguments for `pipeline`, `backend` and the keyword options.
pub fn to_args(
    pipeline: &str,
    backend: &str,
    options: Option<&Bound<'_, PyDict>>,
) -> PyResult<Vec<String>> {
    let known = cli_options();
    let mut args = vec![
        format!("--pipeline={pipeline}"),
        format!("--backend={backend}"),
    ];
    if let Some(d) = options {
        for (k, v) in d.iter() {
            let key: String = k.extract()?;
            if v.is_none() {
                continue;
            }
            if let Some(why) = reserved(&key) {
                return Err(value_error(format!("{key}: {why}")));
            }
            let long = key.replace('_', "-");
            let Some(info) = known.iter().find(|o| o.long == long) else {
                let close: Vec<String> = known
                    .iter()
                    .filter(|o| {
                        reserved(&o.long.replace('-', "_")).is_none()
                            && (o.long.contains(&long)
                                || long.contains(&o.long)
                                || o.long.split('-').next() == long.split('-').next())
                    })
                    .map(|o| o.long.replace('-', "_"))
                    .collect();
                return Err(value_error(format!(
                    "unknown option `{key}`{} (stipple.render_options() lists them all)",
                    if close.is_empty() {
                        String::new()
                    } else {
                        format!("; did you mean {}?", close.join(", "))
                    }
                )));
            };
            args.extend(option_args(info, &key, &v)?);
        }
    }
    Ok(args)
}

/// Parses the arguments as `stipple render` does; a bad value is a `ValueError` naming the
/// option.
pub fn parse(args: &[String]) -> PyResult<RenderArgs> {
    parse_render_args(args).map_err(|e| {
        let text = e.to_string();
        let text = text
            .trim()
            .trim_start_matches("error: ")
            .split("\n\nFor more information")
            .next()
            .unwrap_or_default()
            .split("\n\nUsage:")
            .next()
            .unwrap_or_default()
            .trim()
            .to_string();
        let arg = match e.get(clap::error::ContextKind::InvalidArg) {
            Some(clap::error::ContextValue::String(s)) => s
                .trim_start_matches("--")
                .split([' ', '=', '<'])
                .next()
                .map(|s| s.replace('-', "_")),
            _ => None,
        };
        match arg {
            Some(a) if !a.is_empty() => value_error(format!("{a}: {}", python_names(&text))),
            _ => value_error(python_names(&text)),
        }
    })
}

/// The options `stipple.render` takes: a dict from each name to its help text.
#[pyfunction]
pub fn render_options(py: Python<'_>) -> PyResult<Bound<'_, PyDict>> {
    let d = PyDict::new(py);
    for o in cli_options() {
        let name = o.long.replace('-', "_");
        if reserved(&name).is_some() || name == "help" {
            continue;
        }
        let kind = if o.takes_value { "" } else { "(switch) " };
        d.set_item(name, format!("{kind}{}", python_names(&o.help)))?;
    }
    Ok(d)
}
