//! `stipple.Camera`: the command line's camera (eye, target, up, fov or orthographic height,
//! size; near and far from the cloud's bounds unless given).

use crate::cloud::Cloud;
use crate::errors::value_error;
use glam::DVec3;
use pyo3::prelude::*;
use stipple_core::camera::{Camera as CoreCamera, Projection};

/// Camera(eye, target, up=(0, 1, 0), fov=45, size=1024, near=None, far=None, ortho=None)
///
/// The command line's camera: from eye towards target, fov vertical in degrees (or ortho, an
/// orthographic view height), size (width, height) or one number; near and far are fitted to
/// the cloud rendered unless given.
#[pyclass(module = "stipple._stipple", frozen, from_py_object)]
#[derive(Clone, Debug)]
pub struct Camera {
    pub eye: DVec3,
    pub target: DVec3,
    pub up: DVec3,
    /// Vertical field of view in degrees (None: orthographic).
    pub fov: Option<f64>,
    /// Orthographic view height in world units.
    pub ortho: Option<f64>,
    pub size: (u32, u32),
    pub near: Option<f64>,
    pub far: Option<f64>,
}

fn vec3(name: &str, v: &Bound<'_, PyAny>) -> PyResult<DVec3> {
    let items: Vec<f64> = v
        .extract()
        .map_err(|_| value_error(format!("{name}: expected three numbers (x, y, z)")))?;
    match items[..] {
        [x, y, z] if x.is_finite() && y.is_finite() && z.is_finite() => Ok(DVec3::new(x, y, z)),
        [_, _, _] => Err(value_error(format!(
            "{name}: must be finite (no NaN or inf)"
        ))),
        _ => Err(value_error(format!(
            "{name}: expected three numbers (x, y, z), got {}",
            items.len()
        ))),
    }
}

fn size_of(v: &Bound<'_, PyAny>) -> PyResult<(u32, u32)> {
    if let Ok(n) = v.extract::<i64>() {
        return size_of_pair(n, n);
    }
    let p: Vec<i64> = v
        .extract()
        .map_err(|_| value_error("size: expected (width, height) in pixels or one number"))?;
    match p[..] {
        [w, h] => size_of_pair(w, h),
        _ => Err(value_error("size: expected (width, height) in pixels")),
    }
}

fn size_of_pair(w: i64, h: i64) -> PyResult<(u32, u32)> {
    let max = stipple_core::camera::MAX_SIDE as i64;
    if !(1..=max).contains(&w) || !(1..=max).contains(&h) {
        return Err(value_error(format!(
            "size: {w}x{h}: both sides must be between 1 and {max}"
        )));
    }
    Ok((w as u32, h as u32))
}

impl Camera {
    pub fn from_core(c: &CoreCamera) -> Camera {
        let (fov, ortho) = match c.projection {
            Projection::Perspective { fov_deg } => (Some(fov_deg), None),
            Projection::Orthographic { height } => (None, Some(height)),
        };
        Camera {
            eye: c.eye,
            target: c.target,
            up: c.up,
            fov,
            ortho,
            size: (c.width, c.height),
            near: Some(c.near),
            far: Some(c.far),
        }
    }

    /// The camera for a cloud with these world bounds: near and far fitted to them unless
    /// given (as the command line does).
    pub fn to_core(&self, bounds: Option<(DVec3, DVec3)>) -> anyhow::Result<CoreCamera> {
        let mut c = CoreCamera {
            eye: self.eye,
            target: self.target,
            up: self.up,
            projection: match (self.fov, self.ortho) {
                (_, Some(h)) => Projection::Orthographic { height: h },
                (Some(f), None) => Projection::Perspective { fov_deg: f },
                (None, None) => Projection::Perspective { fov_deg: 45.0 },
            },
            width: self.size.0,
            height: self.size.1,
            near: 0.0,
            far: 0.0,
        };
        c.validate().map_err(|e| anyhow::anyhow!("camera: {e}"))?;
        match (self.near, self.far, bounds) {
            (Some(n), Some(f), _) => {
                c.near = n;
                c.far = f;
            }
            (_, _, Some((lo, hi))) => c.fit_clip(lo, hi),
            _ => anyhow::bail!("camera: near and far are not set"),
        }
        Ok(c)
    }

    /// The command line's checks (eye ≠ target, up not along the view, fov range), whatever
    /// near and far will be.
    fn checked(self) -> PyResult<Camera> {
        let probe = Camera {
            near: Some(1.0),
            far: Some(2.0),
            ..self.clone()
        };
        probe
            .to_core(None)
            .map_err(|e| value_error(e.to_string()))?;
        Ok(self)
    }

    /// The camera as the command line's flags (for inputs the CLI's code loads: trees).
    pub fn to_args(&self) -> Vec<String> {
        let v = |d: DVec3| format!("{:?},{:?},{:?}", d.x, d.y, d.z);
        let mut a = vec![
            format!("--eye={}", v(self.eye)),
            format!("--target={}", v(self.target)),
            format!("--up={}", v(self.up)),
            format!("--size={}x{}", self.size.0, self.size.1),
        ];
        if let Some(f) = self.fov {
            a.push(format!("--fov={f:?}"));
        }
        if let Some(h) = self.ortho {
            a.push(format!("--ortho={h:?}"));
        }
        a
    }
}

#[pymethods]
impl Camera {
    #[new]
    #[pyo3(signature = (eye, target, up=None, fov=None, size=None, near=None, far=None, ortho=None))]
    #[allow(clippy::too_many_arguments)]
    fn py_new(
        eye: &Bound<'_, PyAny>,
        target: &Bound<'_, PyAny>,
        up: Option<&Bound<'_, PyAny>>,
        fov: Option<f64>,
        size: Option<&Bound<'_, PyAny>>,
        near: Option<f64>,
        far: Option<f64>,
        ortho: Option<f64>,
    ) -> PyResult<Camera> {
        let c = Camera {
            eye: vec3("eye", eye)?,
            target: vec3("target", target)?,
            up: up.map(|u| vec3("up", u)).transpose()?.unwrap_or(DVec3::Y),
            fov: if ortho.is_some() {
                if fov.is_some() {
                    return Err(value_error("give fov (perspective) or ortho, not both"));
                }
                None
            } else {
                Some(fov.unwrap_or(45.0))
            },
            ortho,
            size: size
                .map(size_of)
                .transpose()?
                .unwrap_or(stipple_scene::file::DEFAULT_SIZE),
            near,
            far,
        };
        if near.is_some() != far.is_some() {
            return Err(value_error("give both near and far, or neither"));
        }
        if let (Some(n), Some(f)) = (near, far) {
            if !(n.is_finite() && f.is_finite() && f > n) {
                return Err(value_error(format!(
                    "near {n} and far {f}: must be finite with far > near"
                )));
            }
        }
        c.checked()
    }

    /// The camera `stipple render` uses for this cloud when no camera is given: the whole
    /// cloud framed (Z-up for LiDAR), or the sensor's view for a file that records it;
    /// `view` names the side to frame from, as `--view` does ("three-quarter", "top", …).
    #[staticmethod]
    #[pyo3(signature = (cloud, size=None, fov=None, view=None))]
    fn framing(
        py: Python<'_>,
        cloud: &Cloud,
        size: Option<&Bound<'_, PyAny>>,
        fov: Option<f64>,
        view: Option<&str>,
    ) -> PyResult<Camera> {
        let size = size.map(size_of).transpose()?;
        let mut args = Vec::new();
        if let Some((w, h)) = size {
            args.push(format!("--size={w}x{h}"));
        }
        if let Some(f) = fov {
            args.push(format!("--fov={f:?}"));
        }
        if let Some(v) = view {
            args.push(format!("--view={v}"));
        }
        let a = crate::options::parse(&args)?;
        let held = cloud.held.clone();
        let cam = crate::run_detached(
            py,
            move || {
                let h = crate::cloud::lock(&held);
                a.camera.build(&h.prepared.cloud)
            },
            || false,
        )?
        .map_err(crate::errors::to_py)?;
        Ok(Camera::from_core(&cam))
    }

    /// Reads the JSON of `stipple render --camera-out` (or `Camera.to_json`).
    #[staticmethod]
    fn from_json(text: &str) -> PyResult<Camera> {
        CoreCamera::from_json(text)
            .map(|c| Camera::from_core(&c))
            .map_err(|e| value_error(format!("camera JSON: {e}")))
    }

    /// The camera as the command line's JSON (near and far must be known: a camera from a
    /// result, `framing` or `from_json` has them).
    fn to_json(&self) -> PyResult<String> {
        let c = self.to_core(None).map_err(|_| {
            value_error(
                "to_json: near and far are not set; they come from the cloud a camera renders \
                 (use result.camera.to_json(), or give near= and far=)",
            )
        })?;
        Ok(c.to_json())
    }

    #[getter]
    fn eye(&self) -> (f64, f64, f64) {
        self.eye.into()
    }
    #[getter]
    fn target(&self) -> (f64, f64, f64) {
        self.target.into()
    }
    #[getter]
    fn up(&self) -> (f64, f64, f64) {
        self.up.into()
    }
    #[getter]
    fn fov(&self) -> Option<f64> {
        self.fov
    }
    #[getter]
    fn ortho(&self) -> Option<f64> {
        self.ortho
    }
    #[getter]
    fn size(&self) -> (u32, u32) {
        self.size
    }
    #[getter]
    fn near(&self) -> Option<f64> {
        self.near
    }
    #[getter]
    fn far(&self) -> Option<f64> {
        self.far
    }

    /// A copy with some fields changed: `cam.replace(eye=(0, 1, 5))`.
    #[pyo3(signature = (eye=None, target=None, up=None, fov=None, size=None))]
    fn replace(
        &self,
        eye: Option<&Bound<'_, PyAny>>,
        target: Option<&Bound<'_, PyAny>>,
        up: Option<&Bound<'_, PyAny>>,
        fov: Option<f64>,
        size: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Camera> {
        // Near and far are fitted again to the cloud the new camera renders.
        let mut c = Camera {
            near: None,
            far: None,
            ..self.clone()
        };
        if let Some(e) = eye {
            c.eye = vec3("eye", e)?;
        }
        if let Some(t) = target {
            c.target = vec3("target", t)?;
        }
        if let Some(u) = up {
            c.up = vec3("up", u)?;
        }
        if let Some(f) = fov {
            c.fov = Some(f);
            c.ortho = None;
        }
        if let Some(s) = size {
            c.size = size_of(s)?;
        }
        c.checked()
    }

    fn __repr__(&self) -> String {
        let v = |d: DVec3| format!("({}, {}, {})", d.x, d.y, d.z);
        let proj = match (self.fov, self.ortho) {
            (_, Some(h)) => format!("ortho={h}"),
            (f, None) => format!("fov={}", f.unwrap_or(45.0)),
        };
        format!(
            "Camera(eye={}, target={}, up={}, {proj}, size=({}, {}){})",
            v(self.eye),
            v(self.target),
            v(self.up),
            self.size.0,
            self.size.1,
            match (self.near, self.far) {
                (Some(n), Some(f)) => format!(", near={n}, far={f}"),
                _ => String::new(),
            }
        )
    }
}
