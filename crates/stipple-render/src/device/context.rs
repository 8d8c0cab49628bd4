//! Finding an adapter and opening a device, with the features checked explicitly.
//!
//! wgpu picks its backends from `WGPU_BACKEND` (vulkan, gl, ...) through
//! `InstanceDescriptor::with_env`, and quietly offers a GL adapter when Vulkan is missing.
//! GL lacks 64-bit atomics, so we never assume them: an adapter is *suitable* when it has
//! compute shaders and the storage limits the passes need; projection then uses 64-bit
//! atomics where the adapter has them and the two-pass 32-bit fallback elsewhere.

use std::sync::{Arc, Mutex};
use wgpu::{Adapter, Backend, DeviceType, DownlevelFlags, Features};

/// The hardware projection's render targets: point ids and depths.
pub(crate) const ID_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::R32Uint;
pub(crate) const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::R32Float;

/// Why there is no GPU frame.
#[derive(Debug, thiserror::Error)]
pub enum GpuError {
    #[error("no suitable GPU adapter: {0}")]
    NoAdapter(String),
    #[error("could not open the GPU device on {adapter}: {reason}")]
    Device { adapter: String, reason: String },
    #[error("the GPU cannot render this: {0}")]
    TooLarge(String),
    #[error("GPU error: {0}")]
    Wgpu(String),
    #[error("not implemented on the GPU backend: {0}")]
    Unsupported(String),
    #[error("this adapter cannot run {0}")]
    AdapterLacks(String),
}

/// Features that change how stipple runs on an adapter.
const WANTED: Features = Features::SHADER_INT64
    .union(Features::SHADER_INT64_ATOMIC_MIN_MAX)
    .union(Features::TIMESTAMP_QUERY);

/// What `stipple devices` prints about one adapter.
#[derive(Clone, Debug)]
pub struct AdapterReport {
    pub name: String,
    pub backend: Backend,
    pub device_type: DeviceType,
    pub driver: String,
    /// 64-bit atomicMin/Max (the one-pass projection).
    pub int64_atomics: bool,
    pub timestamps: bool,
    pub max_storage_binding: u64,
    pub max_buffer: u64,
    /// `Err(reason)` when the pipeline cannot run on it.
    pub suitable: Result<(), Unsupported>,
    /// `Err(reason)` when the hardware projection path (`--projection hardware`, a
    /// baseline) cannot run on it: its colour targets must be renderable.
    pub hardware_projection: Result<(), Unsupported>,
}

/// Why an adapter cannot run something (a missing feature, limit or format).
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct Unsupported(pub String);

/// Whether the hardware projection's render targets work on `a`.
fn hardware_projection(a: &Adapter) -> Result<(), String> {
    for f in [ID_FORMAT, DEPTH_FORMAT] {
        let usage = a.get_texture_format_features(f).allowed_usages;
        if !usage.contains(wgpu::TextureUsages::RENDER_ATTACHMENT) {
            return Err(format!("{f:?} is not renderable on this adapter"));
        }
    }
    Ok(())
}

impl AdapterReport {
    fn of(a: &Adapter) -> AdapterReport {
        let info = a.get_info();
        let f = a.features();
        let l = a.limits();
        AdapterReport {
            name: info.name,
            backend: info.backend,
            device_type: info.device_type,
            driver: format!("{} {}", info.driver, info.driver_info)
                .trim()
                .to_string(),
            int64_atomics: f
                .contains(Features::SHADER_INT64 | Features::SHADER_INT64_ATOMIC_MIN_MAX),
            timestamps: f.contains(Features::TIMESTAMP_QUERY),
            max_storage_binding: l.max_storage_buffer_binding_size,
            max_buffer: l.max_buffer_size,
            suitable: suitability(a).map_err(Unsupported),
            hardware_projection: hardware_projection(a).map_err(Unsupported),
        }
    }

    /// A software rasterizer (lavapipe, llvmpipe, WARP) rather than a GPU.
    pub fn is_software(&self) -> bool {
        self.device_type == DeviceType::Cpu
    }

    /// Preference order: real GPUs first, then non-GL backends, then 64-bit atomics.
    fn rank(&self) -> (u8, u8, u8) {
        let t = match self.device_type {
            DeviceType::DiscreteGpu => 0,
            DeviceType::IntegratedGpu => 1,
            DeviceType::VirtualGpu => 2,
            DeviceType::Cpu => 3,
            DeviceType::Other => 4,
        };
        (
            t,
            (self.backend == Backend::Gl) as u8,
            !self.int64_atomics as u8,
        )
    }
}

fn suitability(a: &Adapter) -> Result<(), String> {
    let d = a.get_downlevel_capabilities();
    if !d.flags.contains(DownlevelFlags::COMPUTE_SHADERS) {
        return Err("no compute shaders".into());
    }
    let l = a.limits();
    if l.max_storage_buffers_per_shader_stage < 8 {
        return Err(format!(
            "{} storage buffers per stage (8 needed)",
            l.max_storage_buffers_per_shader_stage
        ));
    }
    if l.max_compute_invocations_per_workgroup < 256 || l.max_compute_workgroup_size_x < 256 {
        return Err("workgroups of 256 threads not supported".into());
    }
    Ok(())
}

/// The adapters of the backends `WGPU_BACKEND` names; without it, of the primary backends
/// (Vulkan, Metal, DX12), and of GL only when those offer none (GL lacks 64-bit atomics, and
/// probing it on a headless machine prints EGL noise).
fn adapters() -> Vec<(wgpu::Instance, Adapter)> {
    let from_env = std::env::var_os("WGPU_BACKEND").is_some();
    let desc = |backends| {
        let mut d = wgpu::InstanceDescriptor::new_without_display_handle_from_env();
        if !from_env {
            d.backends = backends;
        }
        d
    };
    let on = |backends| {
        let instance = wgpu::Instance::new(desc(backends));
        pollster::block_on(instance.enumerate_adapters(wgpu::Backends::all()))
            .into_iter()
            .map(|a| (instance.clone(), a))
            .collect::<Vec<_>>()
    };
    let found = on(wgpu::Backends::PRIMARY);
    if !found.is_empty() || from_env {
        return found;
    }
    on(wgpu::Backends::GL)
}

/// Every adapter stipple would consider (see `WGPU_BACKEND`).
pub fn list_adapters() -> Vec<AdapterReport> {
    adapters()
        .iter()
        .map(|(_, a)| AdapterReport::of(a))
        .collect()
}

/// How the backend runs (tests and benchmarks use the overrides).
#[derive(Clone, Debug, Default)]
pub struct GpuOptions {
    /// Use the 32-bit two-pass projection even where 64-bit atomics exist.
    pub force_32bit: bool,
    /// Points per chunk (default: as many as one storage binding holds).
    pub max_chunk_points: Option<usize>,
    /// Workgroups per dispatch dimension before a dispatch is split (default: the device's).
    pub max_groups_per_dim: Option<u32>,
}

/// An open device with what stipple learned about it.
pub struct GpuContext {
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    pub adapter: AdapterReport,
    pub limits: wgpu::Limits,
    pub int64_atomics: bool,
    pub timestamps: bool,
    pub options: GpuOptions,
    /// The instance and adapter the device was opened on (a window's surface made from the
    /// instance lets the renderer present its frames without a copy; see `stipple view`).
    pub instance: wgpu::Instance,
    pub wgpu_adapter: Adapter,
    errors: Arc<Mutex<Vec<String>>>,
    /// Why the device was lost, once it was (a driver reset, a removed GPU, `destroy`).
    lost: Arc<Mutex<Option<String>>>,
}

impl GpuContext {
    /// Opens the preferred suitable adapter.
    pub fn new(options: GpuOptions) -> Result<Arc<GpuContext>, GpuError> {
        let mut found: Vec<(AdapterReport, (wgpu::Instance, Adapter))> = adapters()
            .into_iter()
            .map(|a| (AdapterReport::of(&a.1), a))
            .collect();
        if found.is_empty() {
            return Err(GpuError::NoAdapter(
                "wgpu found no adapter (on Linux without a GPU, install mesa-vulkan-drivers for \
                 the lavapipe software adapter; WGPU_BACKEND restricts the backends searched)"
                    .into(),
            ));
        }
        let rejected: Vec<String> = found
            .iter()
            .filter_map(|(r, _)| {
                r.suitable
                    .as_ref()
                    .err()
                    .map(|why| format!("{} ({:?}): {why}", r.name, r.backend))
            })
            .collect();
        found.retain(|(r, _)| r.suitable.is_ok());
        found.sort_by_key(|(r, _)| r.rank());
        let Some((report, (instance, adapter))) = found.into_iter().next() else {
            return Err(GpuError::NoAdapter(format!(
                "every adapter lacks something: {}",
                rejected.join("; ")
            )));
        };
        Self::open(instance, adapter, report, options)
    }

    /// Opens a device on a given adapter of `instance` (checked for suitability): for a
    /// window, the adapter that can present to its surface.
    pub fn on_adapter(
        instance: wgpu::Instance,
        adapter: Adapter,
        options: GpuOptions,
    ) -> Result<Arc<GpuContext>, GpuError> {
        let report = AdapterReport::of(&adapter);
        if let Err(why) = &report.suitable {
            return Err(GpuError::NoAdapter(format!(
                "{} ({:?}): {why}",
                report.name, report.backend
            )));
        }
        Self::open(instance, adapter, report, options)
    }

    fn open(
        instance: wgpu::Instance,
        adapter: Adapter,
        report: AdapterReport,
        options: GpuOptions,
    ) -> Result<Arc<GpuContext>, GpuError> {
        let features = adapter.features() & WANTED;
        let limits = adapter.limits();
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("stipple"),
            required_features: features,
            required_limits: limits.clone(),
            ..Default::default()
        }))
        .map_err(|e| GpuError::Device {
            adapter: report.name.clone(),
            reason: e.to_string(),
        })?;
        let errors = Arc::new(Mutex::new(Vec::new()));
        let sink = errors.clone();
        device.on_uncaptured_error(Arc::new(move |e: wgpu::Error| {
            sink.lock().unwrap().push(e.to_string());
        }));
        let lost = Arc::new(Mutex::new(None));
        let sink = lost.clone();
        device.set_device_lost_callback(move |reason, message| {
            *sink.lock().unwrap() = Some(if message.is_empty() {
                format!("{reason:?}")
            } else {
                format!("{reason:?}: {message}")
            });
        });
        let int64_atomics = report.int64_atomics && !options.force_32bit;
        Ok(Arc::new(GpuContext {
            device,
            queue,
            timestamps: report.timestamps,
            adapter: report,
            limits,
            int64_atomics,
            options,
            instance,
            wgpu_adapter: adapter,
            errors,
            lost,
        }))
    }

    /// Why the device was lost, if it was: every later frame on it fails.
    pub fn lost(&self) -> Option<String> {
        self.lost.lock().unwrap().clone()
    }

    /// Errors wgpu reported since the last call, as one error.
    pub fn take_errors(&self) -> Result<(), GpuError> {
        let mut e = self.errors.lock().unwrap();
        if e.is_empty() {
            Ok(())
        } else {
            let msg = e.join("; ");
            e.clear();
            Err(GpuError::Wgpu(msg))
        }
    }

    /// The largest storage buffer a binding may hold (the binding limit and the buffer
    /// limit, whichever is smaller).
    pub fn binding_limit(&self) -> u64 {
        self.limits
            .max_storage_buffer_binding_size
            .min(self.limits.max_buffer_size)
    }

    pub fn max_groups_per_dim(&self) -> u32 {
        self.options
            .max_groups_per_dim
            .unwrap_or(self.limits.max_compute_workgroups_per_dimension)
            .max(1)
    }

    /// Splits `groups` workgroups into a 2-D grid within the per-dimension limit.
    pub fn grid(&self, groups: u32) -> (u32, u32) {
        let m = self.max_groups_per_dim();
        if groups <= m {
            (groups.max(1), 1)
        } else {
            (m, groups.div_ceil(m))
        }
    }

    /// A one-line description: adapter, backend and projection path.
    pub fn describe(&self) -> String {
        format!(
            "{} ({:?}, {:?}; projection: {})",
            self.adapter.name,
            self.adapter.backend,
            self.adapter.device_type,
            if self.int64_atomics {
                "64-bit atomics"
            } else {
                "32-bit two-pass"
            }
        )
    }
}
