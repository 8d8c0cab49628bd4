//! Showing a rendered frame in the window: the frame's sRGB bytes go into a texture of the
//! window's own wgpu device and a full-window triangle copies them to the surface, pixel for
//! pixel (no filtering, no colour conversion: the window shows exactly the PNG `stipple
//! render` writes for the same camera).
//!
//! The renderer (CPU or GPU backend) and the window have a device each: the frame is read
//! back by the renderer and uploaded here. A frame of 1024² is 4 MiB each way; sharing one
//! device would save that copy and is left for later.

use anyhow::{anyhow, Result};
use std::sync::Arc;
use winit::window::Window;

const BLIT: &str = r#"
@group(0) @binding(0) var frame: texture_2d<f32>;

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
    /// The frame's texture (re-made when the size changes) and its bind group.
    texture: Option<(wgpu::Texture, wgpu::BindGroup, u32, u32)>,
    /// Texture format: unorm where the surface is unorm, sRGB where it is sRGB (decoded on
    /// read, encoded on write: the same bytes either way).
    texture_format: wgpu::TextureFormat,
    pub adapter_name: String,
}

impl Presenter {
    pub fn new(
        window: Arc<Window>,
        display: winit::event_loop::OwnedDisplayHandle,
    ) -> Result<Presenter> {
        let size = window.inner_size();
        let mut desc =
            wgpu::InstanceDescriptor::new_with_display_handle_from_env(Box::new(display));
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
        let adapter_name = adapter.get_info().name;
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("stipple view"),
            ..Default::default()
        }))
        .map_err(|e| anyhow!("{adapter_name}: {e}"))?;
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
        let pl = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("view blit"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
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
                entry_point: Some("fs"),
                compilation_options: Default::default(),
                targets: &[Some(config.format.into())],
            }),
            multiview_mask: None,
            cache: None,
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
            texture: None,
            texture_format,
            adapter_name,
        })
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

    /// Shows a frame (`rgba`: w × h sRGB bytes, row 0 at the top). Returns false when the
    /// surface was not ready (occluded, outdated): the caller draws again later.
    /// `left`: the frame's left edge in the window (right of the open panel).
    pub fn show(
        &mut self,
        w: u32,
        h: u32,
        rgba: &[u8],
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
        let r = self.show_frame(w, h, rgba, left, overlay.as_deref());
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
        rgba: &[u8],
        left: u32,
        overlay: Option<&Overlay>,
    ) -> Result<bool> {
        if rgba.len() != (w as usize) * (h as usize) * 4 || w == 0 || h == 0 {
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
        let frame = match self.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(t)
            | wgpu::CurrentSurfaceTexture::Suboptimal(t) => t,
            wgpu::CurrentSurfaceTexture::Outdated | wgpu::CurrentSurfaceTexture::Lost => {
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
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, group, &[]);
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
        Ok(true)
    }
}
