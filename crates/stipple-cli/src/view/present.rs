//! Showing a rendered frame in the window, pixel for pixel (no filtering, no colour
//! conversion: the window shows exactly the PNG `stipple render` writes for the same camera).
//!
//! Two ways, picked when the window opens:
//! - **In place** (the GPU backend, when its adapter can present to the window): the window's
//!   surface is made on the renderer's own device, and a full-window triangle reads the
//!   frame's colour buffer where the last compute pass left it. Nothing crosses to the host.
//! - **Uploaded** (the CPU backend, or a GPU adapter that cannot present here): the frame's
//!   sRGB bytes go into a texture of the window's own device, drawn the same way.
//!
//! `STIPPLE_VIEW_PRESENT=copy` forces the uploaded path (to measure what in place saves).
//!
//! A lost device (a driver reset, a removed GPU) is reported by [`Presenter::lost`]; the
//! viewer then opens a new presenter (and renders on the CPU if the renderer's device went).

use anyhow::{anyhow, Result};
use std::sync::{Arc, Mutex};
use winit::window::Window;

const BLIT: &str = r#"
@group(0) @binding(0) var frame: texture_2d<f32>;
@group(1) @binding(0) var<storage, read> packed: array<u32>;
// Width, height, and 1 where the surface is sRGB (the bytes are decoded so that the
// surface's encoding gives them back).
@group(1) @binding(1) var<uniform> dims: vec4<u32>;

struct Out {
    @builtin(position) position: vec4<f32>,
    // 0..1 across the viewport the frame is drawn into, top left at (0, 0).
    @location(0) uv: vec2<f32>,
}

@vertex
fn vs(@builtin(vertex_index) i: u32) -> Out {
    let x = f32(i32(i & 1u) * 4 - 1);
    let y = f32(i32(i >> 1u) * 4 - 1);
    return Out(vec4<f32>(x, y, 0.0, 1.0), vec2<f32>(0.5 * (x + 1.0), 0.5 * (1.0 - y)));
}

@fragment
fn fs(o: Out) -> @location(0) vec4<f32> {
    let size = vec2<i32>(textureDimensions(frame));
    let q = clamp(vec2<i32>(floor(o.uv * vec2<f32>(size))), vec2<i32>(0, 0), size - vec2<i32>(1, 1));
    return textureLoad(frame, q, 0);
}

@fragment
fn fs_packed(o: Out) -> @location(0) vec4<f32> {
    let size = vec2<i32>(dims.xy);
    let q = clamp(vec2<i32>(floor(o.uv * vec2<f32>(size))), vec2<i32>(0, 0), size - vec2<i32>(1, 1));
    let c = unpack4x8unorm(packed[u32(q.y) * dims.x + u32(q.x)]);
    if dims.z == 0u {
        return c;
    }
    let lin = select(pow((c.rgb + 0.055) / 1.055, vec3<f32>(2.4)), c.rgb / 12.92, c.rgb <= vec3<f32>(0.04045));
    return vec4<f32>(lin, c.a);
}
"#;

/// The side panel's triangles and texture changes for one frame (see `view::panel`).
pub struct Overlay {
    pub primitives: Vec<egui::ClippedPrimitive>,
    pub textures: egui::TexturesDelta,
    pub pixels_per_point: f32,
}

impl Drop for Overlay {
    /// An overlay dropped unshown (the frame failed, the app ends): its texture changes go
    /// with it (egui asks that they be cleared, not dropped).
    fn drop(&mut self) {
        self.textures.clear();
    }
}

/// The window's surface and what copies a frame onto it.
pub struct Presenter {
    egui: egui_wgpu::Renderer,
    surface: wgpu::Surface<'static>,
    device: wgpu::Device,
    queue: wgpu::Queue,
    config: wgpu::SurfaceConfiguration,
    pipeline: wgpu::RenderPipeline,
    layout: wgpu::BindGroupLayout,
    /// The in-place path: the pipeline reading a renderer's colour buffer, its layout and
    /// uniform buffer (None when uploading).
    packed: Option<(wgpu::RenderPipeline, wgpu::BindGroupLayout, wgpu::Buffer)>,
    /// The frame's texture (re-made when the size changes) and its bind group.
    texture: Option<(wgpu::Texture, wgpu::BindGroup, u32, u32)>,
    /// Texture format: unorm where the surface is unorm, sRGB where it is sRGB (decoded on
    /// read, encoded on write: the same bytes either way).
    texture_format: wgpu::TextureFormat,
    pub adapter_name: String,
    /// Why the window's device was lost (set by wgpu's callback).
    lost: Arc<Mutex<Option<String>>>,
    /// wgpu errors on the window's own device (reported, not panicking).
    errors: Arc<Mutex<Vec<String>>>,
}

/// Where the frame to show is.
pub enum Source<'a> {
    /// sRGB bytes on the host, `w` × `h` × 4.
    Bytes(&'a [u8]),
    /// A renderer's colour buffer on the presenter's own device (see
    /// `Renderer::image`): one packed `u32` per pixel.
    Device(&'a wgpu::Buffer),
}

impl Presenter {
    /// A presenter for `window`. With `gpu` (the renderer's device), frames are presented in
    /// place when that adapter can present to the window; otherwise (and without `gpu`) the
    /// window gets a device of its own and frames are uploaded. [`Presenter::in_place`] says
    /// which.
    pub fn new(
        window: Arc<Window>,
        display: winit::event_loop::OwnedDisplayHandle,
        gpu: Option<&Arc<stipple_render::gpu::GpuContext>>,
    ) -> Result<Presenter> {
        let size = window.inner_size();
        let gpu = gpu.filter(|_| std::env::var("STIPPLE_VIEW_PRESENT").as_deref() != Ok("copy"));
        let shared = match gpu {
            Some(ctx) => match ctx.instance.create_surface(window.clone()) {
                Ok(s) if ctx.wgpu_adapter.is_surface_supported(&s) => Some((
                    s,
                    ctx.wgpu_adapter.clone(),
                    ctx.device.clone(),
                    ctx.queue.clone(),
                )),
                Ok(_) => {
                    eprintln!(
                        "stipple: note: {} cannot present to this window; frames are copied to \
                         a second device",
                        ctx.adapter.name
                    );
                    None
                }
                Err(e) => {
                    eprintln!(
                        "stipple: note: no surface on {} ({e}); frames are copied to a second \
                         device",
                        ctx.adapter.name
                    );
                    None
                }
            },
            None => None,
        };
        let in_place = shared.is_some();
        let (surface, adapter, device, queue) = match shared {
            Some(s) => s,
            None => own_device(window, display)?,
        };
        let adapter_name = adapter.get_info().name;
        let lost = Arc::new(Mutex::new(None));
        let errors = Arc::new(Mutex::new(Vec::new()));
        if !in_place {
            // The renderer's device has its own callbacks; the window's own one reports here.
            let sink = lost.clone();
            device.set_device_lost_callback(move |reason, message| {
                *sink.lock().unwrap() = Some(if message.is_empty() {
                    format!("{reason:?}")
                } else {
                    format!("{reason:?}: {message}")
                });
            });
            let sink = errors.clone();
            device.on_uncaptured_error(Arc::new(move |e: wgpu::Error| {
                sink.lock().unwrap().push(e.to_string());
            }));
        }
        let mut config = surface
            .get_default_config(&adapter, size.width.max(1), size.height.max(1))
            .ok_or_else(|| anyhow!("{adapter_name} cannot present to this window"))?;
        let caps = surface.get_capabilities(&adapter);
        // An 8-bit format, unorm preferred (the frame's bytes are sRGB already).
        let pick = |srgb: bool| {
            caps.formats.iter().copied().find(|f| {
                matches!(
                    f.remove_srgb_suffix(),
                    wgpu::TextureFormat::Bgra8Unorm | wgpu::TextureFormat::Rgba8Unorm
                ) && f.is_srgb() == srgb
            })
        };
        config.format = pick(false)
            .or_else(|| pick(true))
            .ok_or_else(|| anyhow!("{adapter_name}: no 8-bit surface format"))?;
        config.present_mode = wgpu::PresentMode::Fifo;
        surface.configure(&device, &config);
        let texture_format = if config.format.is_srgb() {
            wgpu::TextureFormat::Rgba8UnormSrgb
        } else {
            wgpu::TextureFormat::Rgba8Unorm
        };
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("view blit"),
            source: wgpu::ShaderSource::Wgsl(BLIT.into()),
        });
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("view blit"),
            entries: &[wgpu::BindGroupLayoutEntry {
                binding: 0,
                visibility: wgpu::ShaderStages::FRAGMENT,
                ty: wgpu::BindingType::Texture {
                    sample_type: wgpu::TextureSampleType::Float { filterable: false },
                    view_dimension: wgpu::TextureViewDimension::D2,
                    multisampled: false,
                },
                count: None,
            }],
        });
        let blit = |layouts: &[Option<&wgpu::BindGroupLayout>], entry: &str| {
            let pl = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("view blit"),
                bind_group_layouts: layouts,
                immediate_size: 0,
            });
            device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some("view blit"),
                layout: Some(&pl),
                vertex: wgpu::VertexState {
                    module: &module,
                    entry_point: Some("vs"),
                    compilation_options: Default::default(),
                    buffers: &[],
                },
                primitive: Default::default(),
                depth_stencil: None,
                multisample: Default::default(),
                fragment: Some(wgpu::FragmentState {
                    module: &module,
                    entry_point: Some(entry),
                    compilation_options: Default::default(),
                    targets: &[Some(config.format.into())],
                }),
                multiview_mask: None,
                cache: None,
            })
        };
        let pipeline = blit(&[Some(&layout)], "fs");
        let packed = in_place.then(|| {
            let entry = |binding, ty| wgpu::BindGroupLayoutEntry {
                binding,
                visibility: wgpu::ShaderStages::FRAGMENT,
                ty: wgpu::BindingType::Buffer {
                    ty,
                    has_dynamic_offset: false,
                    min_binding_size: None,
                },
                count: None,
            };
            let l = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("view blit packed"),
                entries: &[
                    entry(0, wgpu::BufferBindingType::Storage { read_only: true }),
                    entry(1, wgpu::BufferBindingType::Uniform),
                ],
            });
            let p = blit(&[None, Some(&l)], "fs_packed");
            let dims = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("view blit dims"),
                size: 16,
                usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            (p, l, dims)
        });
        let egui = egui_wgpu::Renderer::new(&device, config.format, Default::default());
        Ok(Presenter {
            egui,
            surface,
            device,
            queue,
            config,
            pipeline,
            layout,
            packed,
            texture: None,
            texture_format,
            adapter_name,
            lost,
            errors,
        })
    }

    /// Destroys the window's own device, as a driver reset would (tests of recovery).
    pub fn destroy_device(&self) {
        self.device.destroy();
    }

    /// Frames are presented from the renderer's own device (no copy to the host).
    pub fn in_place(&self) -> bool {
        self.packed.is_some()
    }

    /// Why the window's own device was lost (the uploaded path; in place, the renderer's
    /// context reports it).
    pub fn lost(&self) -> Option<String> {
        self.lost.lock().unwrap().clone()
    }

    /// The window changed size.
    pub fn resize(&mut self, w: u32, h: u32) {
        if w == 0 || h == 0 {
            return;
        }
        self.config.width = w;
        self.config.height = h;
        self.surface.configure(&self.device, &self.config);
    }

    /// Shows a frame (w × h, row 0 at the top). Returns false when the
    /// surface was not ready (occluded, outdated): the caller draws again later.
    /// `left`: the frame's left edge in the window (right of the open panel).
    pub fn show(
        &mut self,
        w: u32,
        h: u32,
        frame: Source<'_>,
        left: u32,
        mut overlay: Option<&mut Overlay>,
    ) -> Result<bool> {
        // The panel's texture changes first, whatever happens to this frame (egui sends each
        // change once).
        if let Some(o) = overlay.as_deref_mut() {
            for (id, deltas) in &o.textures.set {
                for delta in deltas {
                    self.egui
                        .update_texture(&self.device, &self.queue, *id, delta);
                }
            }
        }
        let r = self.show_frame(w, h, frame, left, overlay.as_deref());
        if let Some(o) = overlay {
            for id in &o.textures.free {
                self.egui.free_texture(id);
            }
            o.textures.clear();
        }
        r
    }

    fn show_frame(
        &mut self,
        w: u32,
        h: u32,
        source: Source<'_>,
        left: u32,
        overlay: Option<&Overlay>,
    ) -> Result<bool> {
        if w == 0 || h == 0 {
            return Err(anyhow!("an empty frame ({w}x{h})"));
        }
        // The uploaded frame's texture is bound at group 0, a device frame's buffer at 1.
        let (pipeline, group, slot) = match source {
            Source::Bytes(rgba) => {
                let group = self.upload(w, h, rgba)?;
                (&self.pipeline, group, 0)
            }
            Source::Device(buffer) => {
                let Some((pipeline, layout, dims)) = &self.packed else {
                    return Err(anyhow!("a device frame given to an uploading presenter"));
                };
                if buffer.size() < 4 * w as u64 * h as u64 {
                    return Err(anyhow!(
                        "a frame of {w}x{h} in a buffer of {} bytes",
                        buffer.size()
                    ));
                }
                let srgb = self.config.format.is_srgb() as u32;
                self.queue
                    .write_buffer(dims, 0, bytemuck::cast_slice(&[w, h, srgb, 0]));
                let group = self.device.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: Some("view blit packed"),
                    layout,
                    entries: &[
                        wgpu::BindGroupEntry {
                            binding: 0,
                            resource: buffer.as_entire_binding(),
                        },
                        wgpu::BindGroupEntry {
                            binding: 1,
                            resource: dims.as_entire_binding(),
                        },
                    ],
                });
                (pipeline, group, 1)
            }
        };
        let frame = match self.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(t)
            | wgpu::CurrentSurfaceTexture::Suboptimal(t) => t,
            wgpu::CurrentSurfaceTexture::Outdated | wgpu::CurrentSurfaceTexture::Lost => {
                // The surface went (a resize raced the frame, a display change): made again
                // here, drawn on the next try.
                self.surface.configure(&self.device, &self.config);
                return Ok(false);
            }
            _ => return Ok(false),
        };
        let view = frame.texture.create_view(&Default::default());
        let mut enc = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("view"),
            });
        let screen = egui_wgpu::ScreenDescriptor {
            size_in_pixels: [self.config.width, self.config.height],
            pixels_per_point: overlay.map_or(1.0, |o| o.pixels_per_point),
        };
        let mut extra = Vec::new();
        if let Some(o) = overlay {
            extra = self.egui.update_buffers(
                &self.device,
                &self.queue,
                &mut enc,
                &o.primitives,
                &screen,
            );
        }
        {
            let mut pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("view blit"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: &view,
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Clear(wgpu::Color::BLACK),
                        store: wgpu::StoreOp::Store,
                    },
                })],
                depth_stencil_attachment: None,
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            pass.set_pipeline(pipeline);
            pass.set_bind_group(slot, &group, &[]);
            let (cw, ch) = (self.config.width as f32, self.config.height as f32);
            let x0 = (left as f32).min(cw - 1.0);
            pass.set_viewport(
                x0,
                0.0,
                (w as f32).min(cw - x0),
                (h as f32).min(ch),
                0.0,
                1.0,
            );
            pass.draw(0..3, 0..1);
            pass.set_viewport(0.0, 0.0, cw, ch, 0.0, 1.0);
            if let Some(o) = overlay {
                let mut pass = pass.forget_lifetime();
                self.egui.render(&mut pass, &o.primitives, &screen);
            }
        }
        self.queue.submit(extra.into_iter().chain([enc.finish()]));
        self.queue.present(frame);
        let errors = std::mem::take(&mut *self.errors.lock().unwrap());
        if !errors.is_empty() {
            return Err(anyhow!("presenting the frame: {}", errors.join("; ")));
        }
        Ok(true)
    }

    /// The host frame into the window device's texture (made again when the size changes);
    /// returns its bind group.
    fn upload(&mut self, w: u32, h: u32, rgba: &[u8]) -> Result<wgpu::BindGroup> {
        if rgba.len() != (w as usize) * (h as usize) * 4 {
            return Err(anyhow!("a frame of {w}x{h} with {} bytes", rgba.len()));
        }
        if !matches!(&self.texture, Some((_, _, tw, th)) if (*tw, *th) == (w, h)) {
            let texture = self.device.create_texture(&wgpu::TextureDescriptor {
                label: Some("view frame"),
                size: wgpu::Extent3d {
                    width: w,
                    height: h,
                    depth_or_array_layers: 1,
                },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format: self.texture_format,
                usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
                view_formats: &[],
            });
            let view = texture.create_view(&Default::default());
            let group = self.device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("view frame"),
                layout: &self.layout,
                entries: &[wgpu::BindGroupEntry {
                    binding: 0,
                    resource: wgpu::BindingResource::TextureView(&view),
                }],
            });
            self.texture = Some((texture, group, w, h));
        }
        let (texture, group, _, _) = self.texture.as_ref().expect("made above");
        self.queue.write_texture(
            wgpu::TexelCopyTextureInfo {
                texture,
                mip_level: 0,
                origin: wgpu::Origin3d::ZERO,
                aspect: wgpu::TextureAspect::All,
            },
            rgba,
            wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(4 * w),
                rows_per_image: Some(h),
            },
            wgpu::Extent3d {
                width: w,
                height: h,
                depth_or_array_layers: 1,
            },
        );
        Ok(group.clone())
    }
}

/// An instance, surface, adapter and device of the window's own.
fn own_device(
    window: Arc<Window>,
    display: winit::event_loop::OwnedDisplayHandle,
) -> Result<(
    wgpu::Surface<'static>,
    wgpu::Adapter,
    wgpu::Device,
    wgpu::Queue,
)> {
    let mut desc = wgpu::InstanceDescriptor::new_with_display_handle_from_env(Box::new(display));
    if std::env::var_os("WGPU_BACKEND").is_none() {
        desc.backends = wgpu::Backends::VULKAN | wgpu::Backends::GL;
    }
    let instance = wgpu::Instance::new(desc);
    let surface = instance
        .create_surface(window)
        .map_err(|e| anyhow!("the window cannot be drawn into with wgpu: {e}"))?;
    let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
        power_preference: wgpu::PowerPreference::HighPerformance,
        force_fallback_adapter: false,
        compatible_surface: Some(&surface),
        apply_limit_buckets: false,
    }))
    .map_err(|e| {
        anyhow!(
            "no GPU adapter can present to this window ({e}); install a Vulkan driver \
             (Mesa's lavapipe: apt-get install mesa-vulkan-drivers) or use stipple render"
        )
    })?;
    let name = adapter.get_info().name;
    let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
        label: Some("stipple view"),
        ..Default::default()
    }))
    .map_err(|e| anyhow!("{name}: {e}"))?;
    Ok((surface, adapter, device, queue))
}
