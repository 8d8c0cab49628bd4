//! `stipple.render`, `stipple.Renderer` (a cloud kept uploaded for many cameras), the render
//! result, and `stipple.build_lod`.

use crate::camera::Camera;
use crate::cloud::{lock, Cloud, Held, Shared};
use crate::errors::{to_py, value_error};
use numpy::ndarray::{Array2, Array3};
use numpy::{PyArray2, PyArray3, PyArrayMethods};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::sync::{Arc, Mutex, OnceLock};
use stipple_cli::api;
use stipple_core::Camera as CoreCamera;
use stipple_render::{Frame, PreparedCloud};
use stipple_scene::LoadedScene;

/// What a renderer draws.
enum Source {
    /// A cloud (from NumPy, a file, a demo) or a scene file's merged clouds, kept in memory.
    Cloud {
        held: Shared,
        scene: Option<Arc<LoadedScene>>,
        /// The camera when none is given: the scene's, else the framing.
        default_camera: CoreCamera,
    },
    /// A `.stlod` tree, or a COPC file beyond the point budget: each render loads the cut its
    /// camera needs; the camera when none is given frames the tree's (the file's) bounds.
    Tree(PathBuf, CoreCamera),
}

/// Renderer(source, pipeline="auto", backend="auto", **options)
///
/// A source (a Cloud, or the path of a cloud file, scene file or .stlod tree) with a backend
/// and `stipple render` options, for many cameras: the cloud stays uploaded (GPU) and its
/// normals estimated across renders.
#[pyclass(module = "stipple._stipple", frozen)]
pub struct Renderer {
    source: Source,
    /// `stipple render`'s arguments (without input or camera), parsed again per render.
    args: Vec<String>,
    renderer: Arc<Mutex<stipple_render::Renderer>>,
    describe: String,
}

/// One rendered frame: image (H, W, 4) uint8, depth (H, W) float32, normals (H, W, 3), the
/// camera used, stats (ms per pass) and the renderer's notes.
#[pyclass(module = "stipple._stipple", frozen)]
pub struct RenderResult {
    image: Py<PyAny>,
    depth: Py<PyAny>,
    camera: Camera,
    stats: Vec<(&'static str, f64)>,
    notes: Vec<String>,
    pipeline: String,
    backend: String,
    ms: f64,
    /// For the normals, made when first asked for: the frame (its ids), the cloud drawn and
    /// its camera.
    normal_source: Mutex<Option<(Frame, Shared, CoreCamera)>>,
    normals: OnceLock<Option<Py<PyAny>>>,
}

fn source_of(
    py: Python<'_>,
    source: &Bound<'_, PyAny>,
    args: &[String],
) -> PyResult<(Source, String)> {
    if let Ok(c) = source.cast::<Cloud>() {
        let held = c.get().held.clone();
        let default_camera = {
            let a = crate::options::parse(args)?;
            let h = held.clone();
            crate::run_detached(
                py,
                move || a.camera.build(&lock(&h).prepared.cloud),
                || false,
            )?
            .map_err(to_py)?
        };
        return Ok((
            Source::Cloud {
                held,
                scene: None,
                default_camera,
            },
            String::new(),
        ));
    }
    let path: PathBuf = source.extract().map_err(|_| {
        value_error(format!(
            "source: expected a stipple.Cloud or a file path (cloud, scene or .stlod tree), got \
             {}",
            source
                .get_type()
                .name()
                .map(|n| n.to_string())
                .unwrap_or_default()
        ))
    })?;
    if stipple_lod::is_tree(&path) {
        let a = crate::options::parse(args)?;
        let (_, camera) = stipple_cli::lod::open_with_camera(&path, &a.camera).map_err(to_py)?;
        return Ok((Source::Tree(path, camera), String::new()));
    }
    if stipple_io::copc::is_copc(&path) {
        let a = crate::options::parse(args)?;
        if let Some((_, camera)) =
            stipple_cli::lod::open_copc_cut(&path, &a.camera, &a.lod).map_err(to_py)?
        {
            return Ok((Source::Tree(path, camera), String::new()));
        }
    }
    let mut full = vec![path.to_string_lossy().into_owned()];
    full.extend_from_slice(args);
    let a = crate::options::parse(&full)?;
    let loaded = crate::run_detached(py, move || api::load(&a), || false)?.map_err(to_py)?;
    Ok((
        Source::Cloud {
            held: Arc::new(Mutex::new(Held {
                prepared: loaded.cloud,
                label: loaded.label,
            })),
            scene: loaded.scene.map(Arc::new),
            default_camera: loaded.camera,
        },
        path.to_string_lossy().into_owned(),
    ))
}

/// What a render sends back from its worker thread.
struct Done {
    frame: Frame,
    camera: CoreCamera,
    notes: Vec<String>,
    pipeline: String,
    ms: f64,
    /// The cloud drawn (the renderer's, or a copy changed for this render only).
    drawn: Shared,
}

/// Renders on the calling thread (a worker, with the GIL released).
fn render_now(
    source: &SourceRef,
    args: &[String],
    camera: Option<&Camera>,
    renderer: &Mutex<stipple_render::Renderer>,
) -> anyhow::Result<Done> {
    let mut notes = Vec::new();
    let mut renderer = renderer
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    match source {
        SourceRef::Tree(path) => {
            let mut full = vec![path.to_string_lossy().into_owned()];
            full.extend_from_slice(args);
            if let Some(c) = camera {
                full.extend(c.to_args());
            }
            let a = stipple_cli::api::parse_render_args(&full)?;
            let loaded = api::load(&a)?;
            stipple_cli::memory::check_frame(
                loaded.camera.width,
                loaded.camera.height,
                a.look.layers.unwrap_or(1),
            )?;
            let mut cloud = loaded.cloud;
            let r = api::render_prepared(
                &a,
                &mut cloud,
                &api::View {
                    camera: &loaded.camera,
                    scene: None,
                    tree: true,
                    label: &loaded.label,
                },
                &mut renderer,
                &mut |n| notes.push(n.to_string()),
            )?;
            Ok(Done {
                frame: r.frame,
                camera: loaded.camera,
                notes,
                pipeline: pipeline_name(&r.pipeline),
                ms: r.ms,
                drawn: Arc::new(Mutex::new(Held {
                    prepared: cloud,
                    label: loaded.label,
                })),
            })
        }
        SourceRef::Cloud {
            held,
            scene,
            default_camera,
        } => {
            let a = stipple_cli::api::parse_render_args(args)?;
            let mut h = lock(held);
            let cam = match camera {
                Some(c) if c.near.is_some() => c.to_core(None)?,
                Some(c) => {
                    // Near and far from the cloud's bounds (cached by the cloud).
                    let b = h.prepared.bounds();
                    let o = h.prepared.cloud.origin;
                    c.to_core(Some((o + b.min.as_dvec3(), o + b.max.as_dvec3())))?
                }
                None => default_camera.clone(),
            };
            stipple_cli::memory::check_frame(
                cam.width,
                cam.height,
                stipple_cli::look::layers(&a.look, scene.as_deref()),
            )?;
            // Options that change the cloud (colours, opacity, shadows) change a copy, so the
            // cloud stays as the caller gave it; the normals a render estimates are kept.
            let changes_cloud = a.colour.colour_by.is_some()
                || a.colour.lookup.is_some()
                || a.colour.clip_box.is_some()
                || a.look.opacity.is_some()
                || a.look.shadows
                || scene.is_some();
            let label = h.label.clone();
            let mut copy = changes_cloud.then(|| h.prepared.duplicate());
            let cloud: &mut PreparedCloud = match &mut copy {
                Some(c) => c,
                None => &mut h.prepared,
            };
            let r = api::render_prepared(
                &a,
                cloud,
                &api::View {
                    camera: &cam,
                    scene: scene.as_deref(),
                    tree: false,
                    label: &label,
                },
                &mut renderer,
                &mut |n| notes.push(n.to_string()),
            )?;
            drop(h);
            let drawn = match copy {
                Some(c) => Arc::new(Mutex::new(Held { prepared: c, label })),
                None => held.clone(),
            };
            Ok(Done {
                frame: r.frame,
                camera: cam,
                notes,
                pipeline: pipeline_name(&r.pipeline),
                ms: r.ms,
                drawn,
            })
        }
    }
}

/// A `Source` that can go to a worker thread.
enum SourceRef {
    Cloud {
        held: Shared,
        scene: Option<Arc<LoadedScene>>,
        default_camera: CoreCamera,
    },
    Tree(PathBuf),
}

fn pipeline_name(p: &stipple_render::Pipeline) -> String {
    use stipple_render::pipeline::GeometryPass;
    if p.splat.is_some() {
        "splat"
    } else if p
        .geometry
        .iter()
        .any(|g| matches!(g, GeometryPass::Visibility { .. }))
    {
        "raw"
    } else {
        "dobrev"
    }
    .into()
}

impl Renderer {
    fn new_from(
        py: Python<'_>,
        source: &Bound<'_, PyAny>,
        pipeline: &str,
        backend: &str,
        options: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<Renderer> {
        let args = crate::options::to_args(pipeline, backend, options)?;
        let parsed = crate::options::parse(&args)?;
        let (source, _) = source_of(py, source, &args)?;
        let r = crate::run_detached(py, move || parsed.backend.open(), || false)?.map_err(to_py)?;
        let describe = r.describe();
        Ok(Renderer {
            source,
            args,
            renderer: Arc::new(Mutex::new(r)),
            describe,
        })
    }

    fn render_with(&self, py: Python<'_>, camera: Option<Camera>) -> PyResult<RenderResult> {
        let source = match &self.source {
            Source::Cloud {
                held,
                scene,
                default_camera,
            } => SourceRef::Cloud {
                held: held.clone(),
                scene: scene.clone(),
                default_camera: default_camera.clone(),
            },
            Source::Tree(p, _) => SourceRef::Tree(p.clone()),
        };
        let args = self.args.clone();
        let renderer = self.renderer.clone();
        // Normal estimation, the long part of a first render, stops when asked; the frame
        // itself is short, so an interrupt waits for the worker to end.
        let stop = Arc::new(AtomicBool::new(false));
        let token = stop.clone();
        let done = crate::run_detached(
            py,
            move || {
                stipple_core::cancel::with_token(token, || {
                    render_now(&source, &args, camera.as_ref(), &renderer)
                })
            },
            || {
                stop.store(true, std::sync::atomic::Ordering::Relaxed);
                true
            },
        )?
        .map_err(to_py)?;
        Ok(RenderResult::from_done(py, done, self.describe.clone()))
    }
}

impl RenderResult {
    /// The normal image, made on first use (see the `normals` getter).
    fn normals_now(&self, py: Python<'_>) -> Option<Py<PyAny>> {
        self.normals
            .get_or_init(|| {
                let (frame, drawn, camera) = self
                    .normal_source
                    .lock()
                    .unwrap_or_else(std::sync::PoisonError::into_inner)
                    .take()?;
                let h = lock(&drawn);
                let n = frame.normal_image(&h.prepared, &camera);
                drop(h);
                let flat: Vec<f32> = n.into_iter().flatten().collect();
                let a =
                    Array3::from_shape_vec((frame.height as usize, frame.width as usize, 3), flat)
                        .expect("normals are H×W×3");
                Some(PyArray3::from_owned_array(py, a).into_any().unbind())
            })
            .as_ref()
            .map(|a| a.clone_ref(py))
    }

    fn from_done(py: Python<'_>, d: Done, backend: String) -> RenderResult {
        let Done {
            mut frame,
            camera,
            notes,
            pipeline,
            ms,
            drawn,
        } = d;
        let (w, h) = (frame.width as usize, frame.height as usize);
        // The frame's buffers become the arrays' memory: no copy of the image; the depth is
        // copied once (the normals, made only when asked for, need it as rendered, and the
        // array handed out is the caller's to change).
        let rgba = std::mem::take(&mut frame.rgba);
        let depth = frame.depth.clone();
        let image = PyArray3::from_owned_array(
            py,
            Array3::from_shape_vec((h, w, 4), rgba).expect("RGBA is H×W×4"),
        )
        .into_any()
        .unbind();
        let depth = PyArray2::from_owned_array(
            py,
            Array2::from_shape_vec((h, w), depth).expect("depth is H×W"),
        )
        .into_any()
        .unbind();
        let mut stats: Vec<(&'static str, f64)> = Vec::new();
        for s in &frame.stats {
            match stats.iter_mut().find(|(n, _)| *n == s.name()) {
                Some((_, ms)) => *ms += s.ms,
                None => stats.push((s.name(), s.ms)),
            }
        }
        RenderResult {
            image,
            depth,
            camera: Camera::from_core(&camera),
            stats,
            notes,
            pipeline,
            backend,
            ms,
            normal_source: Mutex::new(Some((frame, drawn, camera))),
            normals: OnceLock::new(),
        }
    }
}

#[pymethods]
impl Renderer {
    #[new]
    #[pyo3(signature = (source, pipeline="auto", backend="auto", **options))]
    fn py_new(
        py: Python<'_>,
        source: &Bound<'_, PyAny>,
        pipeline: &str,
        backend: &str,
        options: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<Renderer> {
        Renderer::new_from(py, source, pipeline, backend, options)
    }

    /// Renders the source seen by `camera` (default: as `stipple render` frames it).
    #[pyo3(signature = (camera=None))]
    fn render(&self, py: Python<'_>, camera: Option<Camera>) -> PyResult<RenderResult> {
        self.render_with(py, camera)
    }

    /// The camera used when none is given.
    #[getter]
    fn default_camera(&self) -> Camera {
        match &self.source {
            Source::Cloud { default_camera, .. } | Source::Tree(_, default_camera) => {
                Camera::from_core(default_camera)
            }
        }
    }

    /// Where the passes run (the adapter, or the CPU and its threads).
    #[getter]
    fn backend(&self) -> String {
        self.describe.clone()
    }

    fn __repr__(&self) -> String {
        format!("<stipple.Renderer on {}>", self.describe)
    }
}

#[pymethods]
impl RenderResult {
    /// The image, uint8 (H, W, 4) RGBA (sRGB; the PNG `stipple render` writes).
    #[getter]
    fn image(&self, py: Python<'_>) -> Py<PyAny> {
        self.image.clone_ref(py)
    }

    /// View-axis depth, float32 (H, W), +inf on background (`--depth-out`).
    #[getter]
    fn depth(&self, py: Python<'_>) -> Py<PyAny> {
        self.depth.clone_ref(py)
    }

    /// World-space unit normals of the visible surface facing the eye, float32 (H, W, 3),
    /// NaN on background (`--normal-out`): the splats' blended normals, else the normal of the
    /// point each pixel shows, else the depth image's own. Made on first access.
    #[getter]
    fn normals(&self, py: Python<'_>) -> PyResult<Option<Py<PyAny>>> {
        crate::guard(|| self.normals_now(py))
    }

    /// The camera used, with the near and far planes fitted to the cloud.
    #[getter]
    fn camera(&self) -> Camera {
        self.camera.clone()
    }

    /// Milliseconds per pass (summed over iterations and layers).
    #[getter]
    fn stats<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        for (n, ms) in &self.stats {
            d.set_item(*n, *ms)?;
        }
        Ok(d)
    }

    /// Milliseconds the frame took (after any normal estimation and shadows).
    #[getter]
    fn ms(&self) -> f64 {
        self.ms
    }

    /// What the renderer told: the pipeline chosen, normals estimated, hints.
    #[getter]
    fn notes<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        PyList::new(py, &self.notes)
    }

    /// The pipeline that drew the frame: dobrev, splat or raw.
    #[getter]
    fn pipeline(&self) -> String {
        self.pipeline.clone()
    }

    /// Where it ran.
    #[getter]
    fn backend(&self) -> String {
        self.backend.clone()
    }

    /// Writes the image as PNG (the bytes `stipple render` writes). An existing file is not
    /// replaced unless `overwrite=True`.
    #[pyo3(signature = (path, overwrite=false))]
    fn save(&self, py: Python<'_>, path: PathBuf, overwrite: bool) -> PyResult<()> {
        if stipple_io::extension(&path) != "png" {
            return Err(value_error(format!(
                "{}: the image is written as PNG: name a .png file",
                path.display()
            )));
        }
        if path.exists() && !overwrite {
            return Err(pyo3::exceptions::PyFileExistsError::new_err(format!(
                "{}: already exists (pass overwrite=True to replace it)",
                path.display()
            )));
        }
        let img = self.image.bind(py).cast::<PyArray3<u8>>()?.readonly();
        let shape = img.as_array().shape().to_vec();
        let bytes = img
            .as_slice()
            .map_err(|e| value_error(e.to_string()))?
            .to_vec();
        stipple_io::image::write_png(&path, shape[1] as u32, shape[0] as u32, &bytes)
            .map_err(|e| to_py(e.into()))
    }

    fn __repr__(&self, py: Python<'_>) -> String {
        let (w, h) = self.camera.size;
        let _ = py;
        format!(
            "<stipple.RenderResult {w}x{h}, {} pipeline, {:.1} ms on {}>",
            self.pipeline, self.ms, self.backend
        )
    }
}

/// Renders a cloud, a file (cloud, scene or `.stlod` tree) with `camera` (default: framed as
/// `stipple render` frames it). Options are `stipple render`'s flags in snake_case.
#[pyfunction]
#[pyo3(signature = (source, camera=None, pipeline="auto", backend="auto", **options))]
pub fn render(
    py: Python<'_>,
    source: &Bound<'_, PyAny>,
    camera: Option<Camera>,
    pipeline: &str,
    backend: &str,
    options: Option<&Bound<'_, PyDict>>,
) -> PyResult<RenderResult> {
    Renderer::new_from(py, source, pipeline, backend, options)?.render_with(py, camera)
}

/// Builds a multi-resolution tree (`.stlod`) from cloud files of any size (`stipple
/// build-lod`); options are its flags in snake_case (`max_node_points`, `temp_dir`,
/// `threads`, `force`). An interrupt stops the build and leaves no tree.
#[pyfunction]
#[pyo3(signature = (inputs, output, memory=None, **options))]
pub fn build_lod(
    py: Python<'_>,
    inputs: &Bound<'_, PyAny>,
    output: PathBuf,
    memory: Option<&Bound<'_, PyAny>>,
    options: Option<&Bound<'_, PyDict>>,
) -> PyResult<()> {
    let inputs: Vec<PathBuf> = match inputs.extract::<PathBuf>() {
        Ok(p) => vec![p],
        Err(_) => inputs
            .extract()
            .map_err(|_| value_error("inputs: expected a file path or a list of file paths"))?,
    };
    let mut argv: Vec<String> = vec!["stipple".into(), "build-lod".into()];
    argv.extend(inputs.iter().map(|p| p.to_string_lossy().into_owned()));
    argv.push(format!("--output={}", output.to_string_lossy()));
    if let Some(m) = memory {
        let m: String = match m.extract::<u64>() {
            Ok(bytes) => bytes.to_string(),
            Err(_) => m.extract().map_err(|_| {
                value_error("memory: bytes (an int) or a size such as \"4G\" or \"512M\"")
            })?,
        };
        argv.push(format!("--memory={m}"));
    }
    if let Some(d) = options {
        for (k, v) in d.iter() {
            let key: String = k.extract()?;
            let flag = format!("--{}", key.replace('_', "-"));
            if v.is_none() {
                continue;
            }
            match v.extract::<bool>() {
                Ok(true) => argv.push(flag),
                Ok(false) => {}
                Err(_) => argv.push(format!("{flag}={}", v.str()?)),
            }
        }
    }
    use clap::Parser;
    let cli = stipple_cli::Cli::try_parse_from(&argv).map_err(|e| {
        let text = e.to_string();
        value_error(crate::errors::python_names(
            text.trim()
                .trim_start_matches("error: ")
                .split("\n\n")
                .next()
                .unwrap_or_default(),
        ))
    })?;
    let Some(stipple_cli::Cmd::BuildLod(a)) = cli.cmd else {
        return Err(value_error("build_lod: could not read its arguments"));
    };
    let cancel = Arc::new(AtomicBool::new(false));
    let c = cancel.clone();
    crate::run_detached(
        py,
        move || stipple_cli::cmd::build_lod::build_lod_with(a, Some(c)),
        // The build stops at its next batch or node, removing what it wrote.
        || {
            cancel.store(true, std::sync::atomic::Ordering::Relaxed);
            true
        },
    )?
    .map_err(to_py)
}
