//! # shade (GPU twin of `cpu.rs`)
//!
//! Two steps: `gather` (gather.wgsl), once per chunk of the cloud, copies each pixel's
//! point (position, normal, albedo, object and opacity, shadow counts) into per-pixel buffers; `shade` (shade.wgsl) then
//! lights every pixel and computes its surface depth, as the CPU does.

use crate::device::cloud::GpuCloud;
use crate::device::context::{GpuContext, GpuError};
use crate::device::frame::{Binder, Cursor, GpuPass, Shared};
use crate::device::record::{flat_groups, grid_2d, Rec};
use crate::device::util::{Pass, Res, DYNAMIC, READ, UNIFORM, WRITE};
use crate::passes::shade::cpu::{LocalLight, ShadeParams};
use crate::stats::PassId;

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub(crate) struct GatherBlock {
    pub base: u32,
    pub count: u32,
    pub has_normals: u32,
    pub has_albedo: u32,
    pub has_style: u32,
    /// 0 none, 1 grey, 2 coloured (see gather.wgsl).
    pub has_lit: u32,
    pub pad: [u32; 2],
    pub samples: [u32; 4],
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub(crate) struct ShadeBlock {
    pub light_count: u32,
    pub has_normals: u32,
    pub has_albedo: u32,
    pub has_lit: u32,
    pub base_colour: [f32; 3],
    pub max_correction: f32,
    pub background: [f32; 3],
    /// Point lights' falloff distance (0: none).
    pub falloff: f32,
    pub samples: [u32; 4],
    /// xyz and kind (0 headlight, 1 directional, 2 point).
    pub lights: [[f32; 4]; 4],
}

const _: () = assert!(std::mem::size_of::<ShadeBlock>() == 128);

/// Material terms by object as the shader's uniform array holds them.
pub(crate) type MaterialTable = [[f32; 4]; crate::MAX_OBJECTS];

impl ShadeBlock {
    /// The block and material table for a cloud under a pipeline: the CPU's shade
    /// parameters (cpu::shade_params) with the cloud's attributes.
    pub fn for_cloud(
        cloud: &crate::device::cloud::GpuCloud,
        pipe: &crate::Pipeline,
    ) -> (ShadeBlock, Box<MaterialTable>) {
        let gap = crate::pipeline::layer_gap(pipe, cloud.spacing);
        let materials = cloud.materials.clone().unwrap_or_else(|| {
            vec![crate::passes::shade::cpu::Terms {
                ambient: pipe.material.ambient,
                diffuse: pipe.material.diffuse,
                specular: pipe.material.specular,
                shininess: pipe.material.shininess,
            }]
        });
        let params =
            crate::passes::shade::shade_params(cloud.origin, pipe, gap, materials, cloud.samples);
        let constant = (!cloud.has_albedo).then_some(pipe.material.base_colour);
        let has_lit = cloud.chunks.iter().any(|c| c.lit.is_some()) && cloud.samples != [0; 4];
        let coloured = has_lit && cloud.chunks.iter().all(|c| c.lit_rb.is_some());
        let mut block = ShadeBlock::new(
            &params,
            cloud.has_normals && pipe.lighting,
            constant,
            has_lit,
        );
        if coloured {
            block.has_lit = 2;
        }
        (block, material_table(&params))
    }

    pub fn new(
        p: &ShadeParams,
        has_normals: bool,
        albedo: Option<[f32; 3]>,
        has_lit: bool,
    ) -> ShadeBlock {
        let mut lights = [[0.0; 4]; 4];
        for (slot, l) in lights.iter_mut().zip(&p.lights) {
            *slot = match *l {
                LocalLight::Headlight => [0.0; 4],
                LocalLight::Directional(d) => [d.x, d.y, d.z, 1.0],
                LocalLight::Point(q) => [q.x, q.y, q.z, 2.0],
            };
        }
        ShadeBlock {
            light_count: p.lights.len().min(4) as u32,
            has_normals: has_normals as u32,
            has_albedo: albedo.is_none() as u32,
            has_lit: has_lit as u32,
            base_colour: albedo.unwrap_or([0.0; 3]),
            max_correction: p.max_correction,
            background: p.background,
            falloff: p.falloff,
            samples: p.samples,
            lights,
        }
    }
}

/// The shader's material table for shade parameters.
pub(crate) fn material_table(p: &ShadeParams) -> Box<MaterialTable> {
    let mut t = Box::new([[0.0f32; 4]; crate::MAX_OBJECTS]);
    for (slot, m) in t.iter_mut().zip(&p.materials) {
        *slot = [m.ambient, m.diffuse, m.specular, m.shininess];
    }
    t
}

/// The pass's pipelines and its material table (a uniform array, written per frame).
pub(crate) struct Shade {
    gather: Pass,
    shade: Pass,
    materials: wgpu::Buffer,
}

impl GpuPass for Shade {
    fn new(ctx: &GpuContext, _: &Shared) -> Shade {
        let d = &ctx.device;
        Shade {
            gather: Pass::new(
                d,
                &crate::device::shaders::GATHER_MODULE,
                "gather",
                &[
                    UNIFORM, DYNAMIC, READ, READ, READ, READ, WRITE, WRITE, READ, READ, WRITE, READ,
                ],
            ),
            shade: Pass::new(
                d,
                &crate::device::shaders::SHADE_MODULE,
                "shade",
                &[
                    UNIFORM, DYNAMIC, READ, READ, READ, READ, READ, WRITE, WRITE, READ, UNIFORM,
                ],
            ),
            materials: d.create_buffer(&wgpu::BufferDescriptor {
                label: Some("materials"),
                size: std::mem::size_of::<MaterialTable>() as u64,
                usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }),
        }
    }
}

/// Records shade from geometry image `cur.g` (writing `materials` first when given): gather per chunk, then `before_shade` (after
/// blended splats, the splat pass's resolve of its per-pixel sums, in the same compute pass),
/// then shade into colour image 0 and the surface depth.
pub(crate) fn record(
    rec: &mut Rec<'_>,
    b: Binder<'_>,
    cur: &Cursor,
    cloud: &GpuCloud,
    (block, materials): (ShadeBlock, Option<&MaterialTable>),
    before_shade: Option<&mut dyn FnMut(&mut wgpu::ComputePass<'static>)>,
) -> Result<(), GpuError> {
    let (ctx, f, s) = (b.ctx, b.f, b.shared);
    let q = rec.section();
    let pass = b.pass::<Shade>();
    // The frame's material table (once per frame: peeled layers share it).
    if let Some(m) = materials {
        ctx.queue
            .write_buffer(&pass.materials, 0, bytemuck::cast_slice(&m[..]));
    }
    let gathers = gather_groups(rec, b, cur, cloud)?;
    let soff = rec.arena.push(&block)?;
    let [view, sblock] = b.view_and::<ShadeBlock>();
    let shade = b.bind(
        "shade",
        &pass.shade.bgl,
        &[
            view,
            sblock,
            Res::Buf(&f.depth[cur.g]),
            Res::Buf(&f.id[cur.g]),
            Res::Buf(&f.attr_pos),
            Res::Buf(&f.attr_normal),
            Res::Buf(&s.to_linear),
            Res::Buf(&f.colour[0]),
            Res::Buf(&f.surface),
            Res::Buf(&f.attr_style),
            Res::Buf(&pass.materials),
        ],
    );
    let (fx, fy) = flat_groups(ctx, f.pixels());
    let (gx, gy) = grid_2d(ctx, f.width, f.height)?;
    let mut p = rec.timed_pass(q);
    p.set_pipeline(&pass.gather.pipeline);
    for (bg, off) in &gathers {
        p.set_bind_group(0, bg, &[*off]);
        p.dispatch_workgroups(fx, fy, 1);
    }
    if let Some(f) = before_shade {
        f(&mut p);
    }
    p.set_pipeline(&pass.shade.pipeline);
    p.set_bind_group(0, &shade, &[soff]);
    p.dispatch_workgroups(gx, gy, 1);
    drop(p);
    rec.end(PassId::Shade, 1, vec![], q)
}

/// The gather step's bind groups and offsets, one per chunk (see gather.wgsl).
fn gather_groups(
    rec: &mut Rec<'_>,
    b: Binder<'_>,
    cur: &Cursor,
    cloud: &GpuCloud,
) -> Result<Vec<(wgpu::BindGroup, u32)>, GpuError> {
    let (f, pass) = (b.f, b.pass::<Shade>());
    let mut gathers = Vec::new();
    for c in &cloud.chunks {
        let off = rec.arena.push(&GatherBlock {
            base: c.base,
            count: c.count,
            has_normals: c.normals.is_some() as u32,
            has_albedo: c.albedo.is_some() as u32,
            has_style: c.style.is_some() as u32,
            has_lit: match (&c.lit, &c.lit_rb) {
                (Some(_), Some(_)) => 2,
                (Some(_), None) => 1,
                (None, _) => 0,
            },
            pad: [0; 2],
            samples: cloud.samples,
        })?;
        let [view, gblock] = b.view_and::<GatherBlock>();
        let or_dummy = |x: &Option<wgpu::Buffer>| x.as_ref().unwrap_or(&cloud.dummy).clone();
        let (normals, albedo) = (or_dummy(&c.normals), or_dummy(&c.albedo));
        let (style, lit) = (or_dummy(&c.style), or_dummy(&c.lit));
        let group = b.bind_chunk(
            "gather",
            &pass.gather.bgl,
            &[
                view,
                gblock,
                Res::Buf(&f.id[cur.g]),
                Res::Buf(&c.positions),
                Res::Buf(&normals),
                Res::Buf(&albedo),
                Res::Buf(&f.attr_pos),
                Res::Buf(&f.attr_normal),
                Res::Buf(&style),
                Res::Buf(&lit),
                Res::Buf(&f.attr_style),
                Res::Buf(c.lit_rb.as_ref().unwrap_or(&cloud.dummy)),
            ],
        );
        gathers.push((group, off));
    }
    Ok(gathers)
}

/// Records gather alone: every pixel's point attributes from geometry image `cur.g` (a
/// translucent light layer's opacities and planes, which have no shade).
pub(crate) fn record_gather(
    rec: &mut Rec<'_>,
    b: Binder<'_>,
    cur: &Cursor,
    cloud: &GpuCloud,
    id: PassId,
) -> Result<(), GpuError> {
    let q = rec.section();
    let gathers = gather_groups(rec, b, cur, cloud)?;
    let pass = b.pass::<Shade>();
    let (fx, fy) = flat_groups(b.ctx, b.f.pixels());
    let mut p = rec.timed_pass(q);
    p.set_pipeline(&pass.gather.pipeline);
    for (bg, off) in &gathers {
        p.set_bind_group(0, bg, &[*off]);
        p.dispatch_workgroups(fx, fy, 1);
    }
    drop(p);
    rec.end(id, 1, vec![], q)
}
