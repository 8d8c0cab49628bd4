//! `stipple.Cloud` from NumPy arrays (or `stipple.read`, `stipple.demo`), and its columns back.
//!
//! Copies: the arrays given are copied once into the cloud's own columns (positions become
//! `f32` offsets from an `f64` origin, the layout every pass reads), so any memory layout is
//! taken (C or Fortran order, strided views such as laspy's columns); the columns read back
//! (`positions`, `normals`, …) are copies too, so a cloud never changes under the caller.

use crate::errors::{to_py, value_error};
use glam::{DVec3, Vec3};
use numpy::{
    Element, PyArray1, PyArray2, PyArrayMethods, PyReadonlyArrayDyn, PyUntypedArray,
    PyUntypedArrayMethods,
};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::PathBuf;
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};
use stipple_core::PointCloud;
use stipple_render::PreparedCloud;

/// A cloud and its name for messages; renders estimate normals into it (once).
pub struct Held {
    pub prepared: PreparedCloud,
    pub label: String,
}

pub type Shared = Arc<Mutex<Held>>;

pub fn lock(h: &Shared) -> MutexGuard<'_, Held> {
    h.lock().unwrap_or_else(PoisonError::into_inner)
}

/// Cloud(positions, normals=None, colors=None, intensity=None, opacity=None, origin=None,
/// classification=None)
///
/// A point cloud from NumPy arrays: positions (N, 3) float32 or float64 (kept as float32
/// offsets from a float64 origin), normals (N, 3), colors (N, 3) uint8/uint16/float 0..1,
/// intensity (N,), opacity (N,) 0..1, classification (N,) uint8. Copied once; bad arrays raise
/// ValueError naming the argument.
#[pyclass(module = "stipple._stipple", frozen)]
pub struct Cloud {
    pub held: Shared,
}

impl Cloud {
    pub fn from_cloud(cloud: PointCloud, label: String) -> Cloud {
        Cloud {
            held: Arc::new(Mutex::new(Held {
                prepared: PreparedCloud::new(cloud),
                label,
            })),
        }
    }
}

/// An array's shape checked: `rows` rows of `cols` columns (None: one column, a 1-D array).
/// Any memory layout is taken (a strided view such as laspy's columns or `a[:, :3]`): the
/// elements are copied into the cloud's columns in any case.
fn checked<'py>(
    name: &str,
    v: &Bound<'py, PyAny>,
    rows: Option<usize>,
    cols: Option<usize>,
) -> PyResult<Bound<'py, PyUntypedArray>> {
    let a = v.cast::<PyUntypedArray>().map_err(|_| {
        value_error(format!(
            "{name}: expected a NumPy array, got {}",
            v.get_type()
                .name()
                .map(|n| n.to_string())
                .unwrap_or_default()
        ))
    })?;
    let shape = a.shape().to_vec();
    let want = match cols {
        Some(c) => format!("(N, {c})"),
        None => "(N,)".into(),
    };
    let ok = match cols {
        Some(c) => shape.len() == 2 && shape[1] == c,
        None => shape.len() == 1,
    };
    if !ok {
        return Err(value_error(format!(
            "{name}: expected shape {want}, got {shape:?}"
        )));
    }
    if let Some(n) = rows {
        if shape[0] != n {
            return Err(value_error(format!(
                "{name}: {} rows, but positions has {n}",
                shape[0]
            )));
        }
    }
    Ok(a.clone())
}

fn dtype_name(a: &Bound<'_, PyUntypedArray>) -> String {
    a.dtype().to_string()
}

/// The array's elements as `T` in row-major order, if its dtype is `T`.
fn elements<T: Element + Copy>(a: &Bound<'_, PyUntypedArray>) -> Option<Vec<T>> {
    let typed: PyReadonlyArrayDyn<'_, T> = a.extract().ok()?;
    // `as_slice` also takes Fortran order (memory order ≠ row order): only C order is a
    // plain copy; anything else is read in logical (row-major) order.
    Some(match typed.as_slice() {
        Ok(s) if a.is_c_contiguous() => s.to_vec(),
        _ => typed.as_array().iter().copied().collect(),
    })
}

/// Float elements (float32 or float64) as f64.
fn floats(name: &str, a: &Bound<'_, PyUntypedArray>) -> PyResult<Vec<f64>> {
    if let Some(v) = elements::<f32>(a) {
        return Ok(v.into_iter().map(f64::from).collect());
    }
    if let Some(v) = elements::<f64>(a) {
        return Ok(v);
    }
    Err(value_error(format!(
        "{name}: dtype {} is not supported: use float32 or float64",
        dtype_name(a)
    )))
}

fn first_non_finite(v: &[f64], cols: usize) -> Option<usize> {
    v.iter().position(|x| !x.is_finite()).map(|i| i / cols)
}

fn positions_of(
    v: &Bound<'_, PyAny>,
    origin: Option<DVec3>,
) -> PyResult<(DVec3, Vec<Vec3>, usize)> {
    let a = checked("positions", v, None, Some(3))?;
    let n = a.shape()[0];
    if n == 0 {
        return Err(value_error("positions: the cloud has no points"));
    }
    if let (Some(p), None) = (elements::<f32>(&a), origin) {
        // float32 without an origin: used as they are.
        if let Some(r) = p.iter().position(|x| !x.is_finite()) {
            return Err(value_error(format!(
                "positions: row {} is not finite (NaN or inf)",
                r / 3
            )));
        }
        let pos = p
            .chunks_exact(3)
            .map(|c| Vec3::new(c[0], c[1], c[2]))
            .collect();
        return Ok((DVec3::ZERO, pos, n));
    }
    let p = floats("positions", &a)?;
    if let Some(r) = first_non_finite(&p, 3) {
        return Err(value_error(format!(
            "positions: row {r} is not finite (NaN or inf)"
        )));
    }
    let world: Vec<DVec3> = p
        .chunks_exact(3)
        .map(|c| DVec3::new(c[0], c[1], c[2]))
        .collect();
    let origin = origin.unwrap_or_else(|| {
        // The centre of the bounds: f32 offsets keep the most precision (LiDAR coordinates
        // in metres of a national grid lose centimetres as f32 otherwise).
        let (lo, hi) = world.iter().fold(
            (DVec3::splat(f64::MAX), DVec3::splat(f64::MIN)),
            |(lo, hi), &w| (lo.min(w), hi.max(w)),
        );
        (lo + hi) * 0.5
    });
    let pos: Vec<Vec3> = world.iter().map(|&w| (w - origin).as_vec3()).collect();
    if let Some(r) = pos.iter().position(|p| !p.is_finite()) {
        return Err(value_error(format!(
            "positions: row {r} is too far from the origin for float32 offsets"
        )));
    }
    Ok((origin, pos, n))
}

fn colours_of(v: &Bound<'_, PyAny>, n: usize) -> PyResult<Vec<[u8; 3]>> {
    let a = checked("colors", v, Some(n), Some(3))?;
    let rows = |b: Vec<u8>| b.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
    if let Some(b) = elements::<u8>(&a) {
        return Ok(rows(b));
    }
    if let Some(w) = elements::<u16>(&a) {
        return Ok(rows(w.into_iter().map(|x| (x >> 8) as u8).collect()));
    }
    let f = floats("colors", &a).map_err(|_| {
        value_error(format!(
            "colors: dtype {} is not supported: use uint8 (0-255), uint16 (0-65535) or float \
             (0-1)",
            dtype_name(&a)
        ))
    })?;
    if let Some(i) = f.iter().position(|x| !(0.0..=1.0).contains(x)) {
        return Err(value_error(format!(
            "colors: float colours must lie in 0..1 (row {} has {})",
            i / 3,
            f[i]
        )));
    }
    Ok(rows(
        f.into_iter().map(|x| (x * 255.0).round() as u8).collect(),
    ))
}

fn intensity_of(v: &Bound<'_, PyAny>, n: usize) -> PyResult<Vec<u16>> {
    let a = checked("intensity", v, Some(n), None)?;
    if let Some(w) = elements::<u16>(&a) {
        return Ok(w);
    }
    if let Some(b) = elements::<u8>(&a) {
        return Ok(b.into_iter().map(u16::from).collect());
    }
    let wide: Option<Vec<f64>> = elements::<i64>(&a)
        .map(|v| v.into_iter().map(|x| x as f64).collect())
        .or_else(|| elements::<i32>(&a).map(|v| v.into_iter().map(f64::from).collect()))
        .or_else(|| elements::<u32>(&a).map(|v| v.into_iter().map(f64::from).collect()));
    let f = match wide {
        Some(f) => f,
        None => floats("intensity", &a)?,
    };
    if let Some(i) = f.iter().position(|x| !(0.0..=65535.0).contains(x)) {
        return Err(value_error(format!(
            "intensity: values must lie in 0..65535 (LAS intensity; element {i} is {})",
            f[i]
        )));
    }
    Ok(f.into_iter().map(|x| x.round() as u16).collect())
}

fn unit_floats(name: &str, v: &Bound<'_, PyAny>, n: usize) -> PyResult<Vec<f32>> {
    let a = checked(name, v, Some(n), None)?;
    let f = floats(name, &a)?;
    if let Some(i) = f.iter().position(|x| !(0.0..=1.0).contains(x)) {
        return Err(value_error(format!(
            "{name}: values must lie in 0..1 (element {i} is {})",
            f[i]
        )));
    }
    Ok(f.into_iter().map(|x| x as f32).collect())
}

fn normals_of(v: &Bound<'_, PyAny>, n: usize) -> PyResult<Vec<Vec3>> {
    let a = checked("normals", v, Some(n), Some(3))?;
    let f = floats("normals", &a)?;
    if let Some(r) = first_non_finite(&f, 3) {
        return Err(value_error(format!(
            "normals: row {r} is not finite (NaN or inf)"
        )));
    }
    Ok(f.chunks_exact(3)
        .map(|c| {
            let v = DVec3::new(c[0], c[1], c[2]);
            // Unit length (a zero normal stays zero: the point is drawn unlit).
            v.normalize_or_zero().as_vec3()
        })
        .collect())
}

fn to_array2<'py, T: Element + Copy>(
    py: Python<'py>,
    rows: Vec<[T; 3]>,
) -> PyResult<Bound<'py, PyArray2<T>>> {
    let n = rows.len();
    let flat: Vec<T> = rows.into_iter().flatten().collect();
    PyArray1::from_vec(py, flat).reshape([n, 3])
}

#[pymethods]
impl Cloud {
    #[new]
    #[pyo3(signature = (positions, normals=None, colors=None, intensity=None, opacity=None, origin=None, classification=None))]
    #[allow(clippy::too_many_arguments)]
    fn py_new(
        positions: &Bound<'_, PyAny>,
        normals: Option<&Bound<'_, PyAny>>,
        colors: Option<&Bound<'_, PyAny>>,
        intensity: Option<&Bound<'_, PyAny>>,
        opacity: Option<&Bound<'_, PyAny>>,
        origin: Option<(f64, f64, f64)>,
        classification: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Cloud> {
        let origin = origin.map(DVec3::from);
        if origin.is_some_and(|o| !o.is_finite()) {
            return Err(value_error("origin: must be finite"));
        }
        let (origin, positions, n) = positions_of(positions, origin)?;
        let classification = classification
            .map(|c| {
                let a = checked("classification", c, Some(n), None)?;
                elements::<u8>(&a).ok_or_else(|| {
                    value_error(format!(
                        "classification: dtype {} is not supported: use uint8 (ASPRS codes)",
                        dtype_name(&a)
                    ))
                })
            })
            .transpose()?;
        let cloud = PointCloud {
            origin,
            positions,
            normals: normals.map(|v| normals_of(v, n)).transpose()?,
            colors: colors.map(|v| colours_of(v, n)).transpose()?,
            intensity: intensity.map(|v| intensity_of(v, n)).transpose()?,
            classification,
            opacity: opacity.map(|v| unit_floats("opacity", v, n)).transpose()?,
            radius: None,
            faces: Vec::new(),
            ..Default::default()
        };
        cloud
            .validate()
            .map_err(|e| value_error(format!("cloud: {e}")))?;
        Ok(Cloud::from_cloud(cloud, "NumPy cloud".into()))
    }

    fn __len__(&self) -> usize {
        lock(&self.held).prepared.cloud.len()
    }

    fn __repr__(&self) -> String {
        let h = lock(&self.held);
        let c = &h.prepared.cloud;
        let mut attrs = vec![];
        for (name, has) in [
            ("normals", c.normals.is_some()),
            ("colors", c.colors.is_some()),
            ("intensity", c.intensity.is_some()),
            ("classification", c.classification.is_some()),
            ("opacity", c.opacity.is_some()),
        ] {
            if has {
                attrs.push(name);
            }
        }
        format!(
            "<stipple.Cloud {} points [{}] from {}>",
            c.len(),
            attrs.join(", "),
            h.label
        )
    }

    /// Count, world bounds, origin, median point spacing and the attributes present.
    fn info<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let h = lock(&self.held);
        let c = &h.prepared.cloud;
        let d = PyDict::new(py);
        let (lo, hi) = c.world_bounds();
        d.set_item("count", c.len())?;
        d.set_item("bounds", (lo.to_array(), hi.to_array()))?;
        d.set_item("origin", c.origin.to_array())?;
        d.set_item("spacing", h.prepared.spacing)?;
        let mut attrs = vec![];
        for (name, has) in [
            ("normals", c.normals.is_some()),
            ("colors", c.colors.is_some()),
            ("intensity", c.intensity.is_some()),
            ("classification", c.classification.is_some()),
            ("opacity", c.opacity.is_some()),
            ("radius", c.radius.is_some()),
            ("return_number", c.return_number.is_some()),
        ] {
            if has {
                attrs.push(name);
            }
        }
        let mut attrs: Vec<String> = attrs.into_iter().map(String::from).collect();
        attrs.extend(c.fields.iter().map(|f| f.name.clone()));
        d.set_item("attributes", attrs)?;
        d.set_item("z_up", c.z_up)?;
        d.set_item("source", h.label.clone())?;
        Ok(d)
    }

    /// World positions, float64 (N, 3) (a copy).
    #[getter]
    fn positions<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let h = lock(&self.held);
        let c = &h.prepared.cloud;
        let rows: Vec<[f64; 3]> = (0..c.len()).map(|i| c.world(i).to_array()).collect();
        drop(h);
        to_array2(py, rows)
    }

    /// Unit normals, float32 (N, 3), or None (a copy; a render that estimated normals
    /// keeps them here).
    #[getter]
    fn normals<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyArray2<f32>>>> {
        let rows: Option<Vec<[f32; 3]>> = lock(&self.held)
            .prepared
            .cloud
            .normals
            .as_ref()
            .map(|n| n.iter().map(|v| v.to_array()).collect());
        rows.map(|r| to_array2(py, r)).transpose()
    }

    /// Colours, uint8 (N, 3) sRGB, or None.
    #[getter]
    fn colors<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyArray2<u8>>>> {
        let rows = lock(&self.held).prepared.cloud.colors.clone();
        rows.map(|r| to_array2(py, r)).transpose()
    }

    /// LiDAR intensity, uint16 (N,), or None.
    #[getter]
    fn intensity<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyArray1<u16>>> {
        let v = lock(&self.held).prepared.cloud.intensity.clone();
        v.map(|v| PyArray1::from_vec(py, v))
    }

    /// Per-point opacity, float32 (N,) in 0..1, or None.
    #[getter]
    fn opacity<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyArray1<f32>>> {
        let v = lock(&self.held).prepared.cloud.opacity.clone();
        v.map(|v| PyArray1::from_vec(py, v))
    }

    /// ASPRS classification codes, uint8 (N,), or None.
    #[getter]
    fn classification<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyArray1<u8>>> {
        let v = lock(&self.held).prepared.cloud.classification.clone();
        v.map(|v| PyArray1::from_vec(py, v))
    }

    /// Splat radii, float32 (N,) world units, or None (estimated with the normals).
    #[getter]
    fn radius<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyArray1<f32>>> {
        let r = lock(&self.held).prepared.cloud.radius.clone();
        r.map(|r| PyArray1::from_vec(py, r))
    }

    /// The file's scalar fields (PLY/PCD properties and LAS extra bytes stipple has no
    /// column for: curvature, confidence, a material id, …): a dict of name → float64 (N,)
    /// (copies; NaN where a merged cloud's point has no value). `render(colour_by=NAME)` and
    /// lookup tables take these names.
    #[getter]
    fn fields<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let cols: Vec<(String, Vec<f64>)> = {
            let h = lock(&self.held);
            let c = &h.prepared.cloud;
            c.fields
                .iter()
                .map(|f| (f.name.clone(), (0..c.len()).map(|i| f.value(i)).collect()))
                .collect()
        };
        let d = PyDict::new(py);
        for (name, v) in cols {
            d.set_item(name, PyArray1::from_vec(py, v))?;
        }
        Ok(d)
    }

    /// The f64 world origin the positions are stored relative to.
    #[getter]
    fn origin(&self) -> (f64, f64, f64) {
        lock(&self.held).prepared.cloud.origin.into()
    }

    /// Writes the cloud (`.ply`, `.las`, `.laz`, `.xyz`), with the normals and radii a render
    /// estimated. An existing file is not replaced unless `overwrite=True`.
    #[pyo3(signature = (path, overwrite=false))]
    fn save(&self, py: Python<'_>, path: PathBuf, overwrite: bool) -> PyResult<()> {
        if path.exists() && !overwrite {
            return Err(pyo3::exceptions::PyFileExistsError::new_err(format!(
                "{}: already exists (pass overwrite=True to replace it)",
                path.display()
            )));
        }
        let held = self.held.clone();
        crate::run_detached(
            py,
            move || {
                let h = lock(&held);
                stipple_io::write_cloud(&path, &h.prepared.cloud)
            },
            || false,
        )?
        .map_err(|e| to_py(e.into()))
    }
}

/// Reads a cloud file: every format `stipple render` reads (PLY, LAS/LAZ/COPC, XYZ, PCD, E57,
/// OBJ/STL vertices, volumes as their iso-surface with `iso`, or through a transfer function
/// with `transfer`, as `--transfer` takes it: a file or the points inline).
#[pyfunction]
#[pyo3(signature = (path, iso=None, transfer=None))]
pub fn read(
    py: Python<'_>,
    path: PathBuf,
    iso: Option<f64>,
    transfer: Option<String>,
) -> PyResult<Cloud> {
    if stipple_lod::is_tree(&path) || stipple_scene::is_scene(&path) {
        return Err(value_error(format!(
            "{}: a tree or a scene file, not a cloud: pass its path to stipple.render or \
             stipple.Renderer",
            path.display()
        )));
    }
    if iso.is_some_and(|v| !v.is_finite()) {
        return Err(value_error("iso: must be finite"));
    }
    if iso.is_some() && transfer.is_some() {
        return Err(value_error(
            "iso and transfer: a volume is drawn as an iso-surface or through a transfer \
             function, not both",
        ));
    }
    let transfer = transfer
        .as_deref()
        .map(|t| stipple_io::transfer_function(t, None))
        .transpose()
        .map_err(|e| value_error(format!("transfer: {e}")))?;
    let label = path.display().to_string();
    let cloud = crate::run_detached(
        py,
        move || {
            let c = stipple_io::read_cloud_with(&path, &stipple_io::ReadOptions { iso, transfer })?;
            Ok::<_, stipple_io::IoError>(PreparedCloud::new(c))
        },
        || false,
    )?
    .map_err(|e| to_py(e.into()))?;
    Ok(Cloud {
        held: Arc::new(Mutex::new(Held {
            prepared: cloud,
            label,
        })),
    })
}

/// A built-in demo scene: plane-objects (the default), sphere, torus, nested-tori.
#[pyfunction]
#[pyo3(signature = (name="plane-objects", points=None, seed=1))]
pub fn demo(name: &str, points: Option<usize>, seed: u64) -> PyResult<Cloud> {
    use stipple_core::demo::DemoScene;
    let scene = DemoScene::from_name(name).ok_or_else(|| {
        let names: Vec<&str> = DemoScene::ALL.iter().map(|d| d.name()).collect();
        value_error(format!(
            "demo: unknown scene `{name}` (one of: {})",
            names.join(", ")
        ))
    })?;
    let n = points.unwrap_or(scene.default_points());
    if n == 0 {
        return Err(value_error("points: must be at least 1"));
    }
    stipple_cli::memory::check_points(
        &format!("points={n}"),
        n as u64,
        stipple_cli::memory::BYTES_PER_POINT,
    )
    .map_err(|e| value_error(crate::errors::python_names(&e.to_string())))?;
    Ok(Cloud::from_cloud(
        stipple_core::demo::generate(scene, n, seed),
        format!("demo scene `{}`", scene.name()),
    ))
}
