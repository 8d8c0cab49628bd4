//! One recording function per step of the frame: each records its pass (or passes) into
//! the frame's command encoder and ends a statistics section.

use super::record::*;
use super::resources::*;
use crate::device::cloud::GpuCloud;
use crate::device::context::GpuError;
use crate::device::iterate::IterateBlock;
use crate::params::ViewParams;
use crate::passes::antialias::gpu::AntialiasBlock;
use crate::passes::blend_layers::gpu::BlendBlock;
use crate::passes::depiction::gpu::DepictionBlock;
use crate::passes::edl::gpu::EdlBlock;
use crate::passes::fill::gpu::FillBlock;
use crate::passes::fill_anisotropic::gpu::FillAnisotropicBlock;
use crate::passes::project::gpu::{ChunkBlock, ResolveBlock, POINTS_PER_GROUP};
use crate::passes::project::gpu_hw::Targets;
use crate::passes::shade::gpu::{GatherBlock, ShadeBlock};
use crate::passes::shadow_texture::gpu::MarkBlock;
use crate::passes::smooth::gpu::SmoothBlock;
use crate::passes::visibility::gpu::VisibilityBlock;
use crate::pipeline::{ColourPass, GeometryPass, Iterations};
use crate::stats::PassId;
use wgpu::{Buffer, CommandEncoder};

pub(crate) fn record_project(
    rec: &mut Rec<'_>,
    kit: &Kit,
    f: &FrameBuffers,
    cloud: &GpuCloud,
    cull: bool,
    peel: Option<f32>,
) -> Result<(), GpuError> {
    let ctx = rec.ctx;
    rec.start();
    rec.enc.clear_buffer(&f.vis, 0, None);
    rec.enc.clear_buffer(&f.vis_id, 0, None);
    let slot = rec.slot()?;
    let q = rec.queries();
    let cull = cull && cloud.has_normals;
    let mut chunks = Vec::new();
    for (c, bg) in cloud.chunks.iter().zip(&f.cloud_groups().project) {
        let off = rec.arena.push(&ChunkBlock {
            base: c.base,
            count: c.count,
            cull: cull as u32,
            slot,
            peel: peel.is_some() as u32,
            gap: peel.unwrap_or(0.0),
            pad: [0; 2],
        })?;
        chunks.push((bg, off, ctx.grid(c.count.div_ceil(POINTS_PER_GROUP))));
    }
    let roff = rec.arena.push(&ResolveBlock {
        wide: kit.project.wide.is_some() as u32,
        pad: [0; 3],
    })?;
    let mut pass = rec.cpass(q.map(|q| q.0), q.map(|q| q.1));
    let stages: Vec<&wgpu::ComputePipeline> = match &kit.project.wide {
        Some((_, p)) => vec![p],
        None => vec![&kit.project.narrow_depth, &kit.project.narrow_index],
    };
    for p in stages {
        pass.set_pipeline(p);
        for (bg, off, (gx, gy)) in &chunks {
            pass.set_bind_group(0, *bg, &[*off]);
            pass.dispatch_workgroups(*gx, *gy, 1);
        }
    }
    pass.set_pipeline(&kit.project.resolve);
    pass.set_bind_group(0, &Binder::new(ctx, kit, f).resolve(), &[roff]);
    let (gx, gy) = flat_groups(ctx, f.width as u64 * f.height as u64);
    pass.dispatch_workgroups(gx, gy, 1);
    drop(pass);
    rec.end(PassId::Project, 1, vec![slot], q)
}

pub(crate) fn record_splat(
    rec: &mut Rec<'_>,
    splat: &mut crate::passes::splat::gpu::SplatGpu,
    kit: &Kit,
    view: &Buffer,
    f: &FrameBuffers,
    cloud: &GpuCloud,
    s: crate::SplatSettings,
) -> Result<(), GpuError> {
    rec.start();
    let q = rec.queries();
    let timer = rec.timer;
    let mut begin = |enc: &mut CommandEncoder| {
        let timestamp_writes = match (timer, q) {
            (Some(t), Some((b, e))) => Some(wgpu::ComputePassTimestampWrites {
                query_set: &t.set,
                beginning_of_pass_write_index: Some(b),
                end_of_pass_write_index: Some(e),
            }),
            _ => None,
        };
        enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("splat"),
            timestamp_writes,
        })
        .forget_lifetime()
    };
    splat.record(
        rec.ctx,
        &mut rec.enc,
        rec.arena,
        view,
        cloud,
        (f.width, f.height),
        (s.epsilon.unwrap_or(0.0), s.scale),
        (&f.depth[0], &f.id[0]),
        (s.mode, s.quant()),
        (s.mode != crate::SplatMode::Voronoi).then_some(crate::passes::splat::gpu::BlendTargets {
            attr_pos: &f.attr_pos,
            attr_normal: &f.attr_normal,
            to_linear: &kit.to_linear,
        }),
        &mut begin,
    )?;
    rec.end(PassId::Splat, 1, vec![], q)
}

pub(crate) fn record_project_hw(
    rec: &mut Rec<'_>,
    kit: &Kit,
    f: &FrameBuffers,
    t: &Targets,
    copy: &wgpu::BindGroup,
    cloud: &GpuCloud,
    cull: bool,
) -> Result<(), GpuError> {
    let ctx = rec.ctx;
    rec.start();
    let q = rec.queries();
    let cull = cull && cloud.has_normals;
    let (hw, hw_group) = kit
        .project_hw
        .as_ref()
        .ok_or_else(|| GpuError::Wgpu("the hardware projection was not set up".into()))?;
    let mut draws = Vec::new();
    for c in &cloud.chunks {
        let off = rec.arena.push(&ChunkBlock {
            base: c.base,
            count: c.count,
            cull: cull as u32,
            slot: 0,
            peel: 0,
            gap: 0.0,
            pad: [0; 2],
        })?;
        draws.push((off, c));
    }
    {
        let clear = |c: wgpu::Color| wgpu::Operations {
            load: wgpu::LoadOp::Clear(c),
            store: wgpu::StoreOp::Store,
        };
        let timestamp_writes = match (rec.timer, q) {
            (Some(tm), Some((b, _))) => Some(wgpu::RenderPassTimestampWrites {
                query_set: &tm.set,
                beginning_of_pass_write_index: Some(b),
                end_of_pass_write_index: None,
            }),
            _ => None,
        };
        let mut pass = rec.enc.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("project_hw"),
            color_attachments: &[
                Some(wgpu::RenderPassColorAttachment {
                    view: &t.id,
                    depth_slice: None,
                    resolve_target: None,
                    ops: clear(wgpu::Color {
                        r: u32::MAX as f64,
                        g: 0.0,
                        b: 0.0,
                        a: 0.0,
                    }),
                }),
                Some(wgpu::RenderPassColorAttachment {
                    view: &t.depth,
                    depth_slice: None,
                    resolve_target: None,
                    ops: clear(wgpu::Color::TRANSPARENT),
                }),
            ],
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: &t.z,
                depth_ops: Some(wgpu::Operations {
                    load: wgpu::LoadOp::Clear(1.0),
                    store: wgpu::StoreOp::Discard,
                }),
                stencil_ops: None,
            }),
            timestamp_writes,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        pass.set_pipeline(&hw.pipeline);
        for (off, c) in &draws {
            pass.set_bind_group(0, hw_group, &[*off]);
            pass.set_vertex_buffer(0, c.positions.slice(..));
            let n = c.normals.as_ref().unwrap_or(&c.positions);
            pass.set_vertex_buffer(1, n.slice(..));
            pass.draw(0..c.count, 0..1);
        }
    }
    let mut pass = rec.cpass(None, q.map(|q| q.1));
    pass.set_pipeline(&hw.copy);
    pass.set_bind_group(0, copy, &[]);
    let (gx, gy) = grid_2d(ctx, f.width, f.height)?;
    pass.dispatch_workgroups(gx, gy, 1);
    drop(pass);
    rec.end(PassId::Project, 1, vec![], q)
}

pub(crate) fn record_geometry(
    rec: &mut Rec<'_>,
    kit: &Kit,
    f: &FrameBuffers,
    cur: &mut Cursor,
    pass: &GeometryPass,
    default_gap: f32,
) -> Result<(), GpuError> {
    let ctx = rec.ctx;
    rec.start();
    let (fill, its, radius, gap) = match *pass {
        GeometryPass::FillBackground { iterations, radius } => {
            (&kit.fill_background, iterations, radius, 0.0)
        }
        GeometryPass::FillOccluded {
            iterations,
            layer_gap,
            radius,
        } => (
            &kit.fill_occluded,
            iterations,
            radius,
            layer_gap.unwrap_or(default_gap),
        ),
        GeometryPass::Visibility { kernel, threshold } => {
            let (first, count) = *kit
                .vis_ranges
                .get(kernel as usize)
                .filter(|r| r.1 > 0)
                .ok_or_else(|| {
                    GpuError::TooLarge(format!("visibility kernel {kernel} (3 to 15)"))
                })?;
            let slot = rec.slot()?;
            let off = rec.arena.push(&VisibilityBlock {
                first,
                count,
                threshold,
                slot,
            })?;
            let q = rec.queries();
            let (gx, gy) = grid_2d(ctx, f.width, f.height)?;
            rec.image_pass(
                q,
                &kit.visibility.pipeline,
                &Binder::new(ctx, kit, f).visibility(cur.g),
                &[off],
                (gx, gy),
            );
            cur.g = 1 - cur.g;
            return rec.end(pass.id(), 1, vec![slot], q);
        }
    };
    let (first, count) = *kit
        .cell_ranges
        .get(radius as usize)
        .filter(|_| radius >= 1)
        .ok_or_else(|| GpuError::TooLarge(format!("fill radius {radius} (1 to 3)")))?;
    let q = rec.queries();
    let (gx, gy) = grid_2d(ctx, f.width, f.height)?;
    let stable = matches!(its, Iterations::UntilStable { .. });
    let mut steps = Vec::new();
    let mut slots = Vec::new();
    for k in 0..its.max() {
        let slot = rec.slot()?;
        let off = rec.arena.push(&FillBlock {
            first,
            count,
            gap,
            slot,
        })?;
        let it = if stable && k > 0 {
            Some(rec.arena.push(&IterateBlock {
                prev_slot: slot - 1,
                args_slot: slot,
                groups_x: gx,
                groups_y: gy,
            })?)
        } else {
            None
        };
        steps.push((cur.g, off, it, slot));
        slots.push(slot);
        cur.g = 1 - cur.g;
    }
    let b = Binder::new(ctx, kit, f);
    let groups = [b.fill(fill, 0), b.fill(fill, 1)];
    let mut p = rec.cpass(q.map(|q| q.0), q.map(|q| q.1));
    for (src, off, it, slot) in steps {
        if let Some(ioff) = it {
            p.set_pipeline(&kit.iterate.pipeline);
            p.set_bind_group(0, &kit.iterate_group, &[ioff]);
            p.dispatch_workgroups(1, 1, 1);
            p.set_pipeline(&fill.pipeline);
            p.set_bind_group(0, &groups[src], &[off]);
            p.dispatch_workgroups_indirect(&kit.indirect, slot as u64 * 12);
        } else {
            p.set_pipeline(&fill.pipeline);
            p.set_bind_group(0, &groups[src], &[off]);
            p.dispatch_workgroups(gx, gy, 1);
        }
    }
    drop(p);
    rec.end_iterated(pass.id(), its.max(), stable, slots, q)
}

pub(crate) fn record_shade(
    rec: &mut Rec<'_>,
    kit: &Kit,
    f: &FrameBuffers,
    cur: &Cursor,
    cloud: &GpuCloud,
    block: ShadeBlock,
    splat: Option<&mut crate::passes::splat::gpu::SplatGpu>,
) -> Result<(), GpuError> {
    let ctx = rec.ctx;
    rec.start();
    let q = rec.queries();
    let mut gathers = Vec::new();
    for (c, groups) in cloud.chunks.iter().zip(&f.cloud_groups().gather) {
        let off = rec.arena.push(&GatherBlock {
            base: c.base,
            count: c.count,
            has_normals: c.normals.is_some() as u32,
            has_albedo: c.albedo.is_some() as u32,
            has_style: c.style.is_some() as u32,
            has_lit: c.lit.is_some() as u32,
            pad: [0; 2],
        })?;
        gathers.push((&groups[cur.g], off));
    }
    let soff = rec.arena.push(&block)?;
    let (fx, fy) = flat_groups(ctx, f.width as u64 * f.height as u64);
    let (gx, gy) = grid_2d(ctx, f.width, f.height)?;
    let mut p = rec.cpass(q.map(|q| q.0), q.map(|q| q.1));
    p.set_pipeline(&kit.shade.gather.pipeline);
    for (bg, off) in &gathers {
        p.set_bind_group(0, *bg, &[*off]);
        p.dispatch_workgroups(fx, fy, 1);
    }
    if let Some(sg) = splat {
        sg.record_resolve(&mut p);
    }
    p.set_pipeline(&kit.shade.shade.pipeline);
    p.set_bind_group(0, &Binder::new(ctx, kit, f).shade(cur.g), &[soff]);
    p.dispatch_workgroups(gx, gy, 1);
    drop(p);
    rec.end(PassId::Shade, 1, vec![], q)
}

pub(crate) fn record_colour(
    rec: &mut Rec<'_>,
    kit: &Kit,
    f: &FrameBuffers,
    cur: &mut Cursor,
    pass: &ColourPass,
    v: &ViewParams,
) -> Result<(), GpuError> {
    let ctx = rec.ctx;
    rec.start();
    let q = rec.queries();
    let (gx, gy) = grid_2d(ctx, f.width, f.height)?;
    if let Some(pp) = pass.pixel() {
        let off = rec.arena.push_bytes(&pp.block(v))?;
        let missing = || GpuError::Wgpu(format!("pixel pass {} was not set up", pp.name()));
        let pass = kit.pixel.get(pp.name()).ok_or_else(missing)?;
        let group = Binder::new(ctx, kit, f).pixel(pp.name(), pass, cur.g, cur.colour);
        rec.image_pass(q, &pass.pipeline, &group, &[off], (gx, gy));
        cur.colour = 1 - cur.colour;
        return rec.end(pp.id(), 1, vec![], q);
    }
    match *pass {
        ColourPass::Smooth { kernel, iterations } => {
            let off = rec.arena.push(&SmoothBlock::new(kernel))?;
            let b = Binder::new(ctx, kit, f);
            let mut p = rec.cpass(q.map(|q| q.0), q.map(|q| q.1));
            p.set_pipeline(&kit.smooth.pipeline);
            for _ in 0..iterations {
                p.set_bind_group(0, &b.smooth(cur.g, cur.colour), &[off]);
                p.dispatch_workgroups(gx, gy, 1);
                cur.colour = 1 - cur.colour;
            }
            drop(p);
            rec.end(PassId::Smooth, iterations, vec![], q)
        }
        ColourPass::Antialias {
            threshold,
            strength,
        } => {
            let slot = rec.slot()?;
            let off = rec.arena.push(&AntialiasBlock {
                inv_far: 1.0 / v.far,
                threshold,
                strength,
                slot,
            })?;
            rec.image_pass(
                q,
                &kit.antialias.pipeline,
                &Binder::new(ctx, kit, f).antialias(cur.colour),
                &[off],
                (gx, gy),
            );
            cur.colour = 1 - cur.colour;
            rec.end(PassId::Antialias, 1, vec![slot], q)
        }
        ColourPass::FillAnisotropic {
            iterations,
            delta,
            all_empty,
        } => {
            let mut steps = Vec::new();
            let mut slots = Vec::new();
            for _ in 0..iterations {
                let slot = rec.slot()?;
                steps.push(rec.arena.push(&FillAnisotropicBlock {
                    delta,
                    all_empty: all_empty as u32,
                    slot,
                    pad: 0,
                })?);
                slots.push(slot);
            }
            let b = Binder::new(ctx, kit, f);
            let mut s = 0;
            let mut p = rec.cpass(q.map(|q| q.0), q.map(|q| q.1));
            p.set_pipeline(&kit.fill_anisotropic.pipeline);
            for off in steps {
                p.set_bind_group(0, &b.fill_anisotropic(cur.g, cur.colour, s), &[off]);
                p.dispatch_workgroups(gx, gy, 1);
                cur.colour = 1 - cur.colour;
                s = 1 - s;
            }
            drop(p);
            if s == 1 {
                // The filled depth ended in surface_b: every later pass reads `surface`.
                let n = f.width as u64 * f.height as u64;
                rec.enc
                    .copy_buffer_to_buffer(&f.surface_b, 0, &f.surface, 0, 4 * n);
            }
            rec.end(PassId::FillAnisotropic, iterations, slots, q)
        }
        ColourPass::Depiction {
            levels,
            xi,
            epsilon,
        } => {
            let mut offs = Vec::new();
            for (k, weight) in crate::passes::depiction::cpu::level_weights(levels, xi)
                .into_iter()
                .enumerate()
            {
                offs.push(rec.arena.push(&DepictionBlock {
                    weight,
                    epsilon,
                    first: (k == 0) as u32,
                    pad: 0,
                })?);
            }
            let n = f.width as u64 * f.height as u64;
            rec.enc
                .copy_buffer_to_buffer(&f.surface, 0, &f.levels[0], 0, 4 * n);
            let mut p = rec.cpass(q.map(|q| q.0), q.map(|q| q.1));
            p.set_pipeline(&kit.depiction.level.pipeline);
            for (k, off) in offs.iter().enumerate() {
                p.set_bind_group(0, &Binder::new(ctx, kit, f).level(k % 2), &[*off]);
                p.dispatch_workgroups(gx, gy, 1);
            }
            p.set_pipeline(&kit.depiction.apply.pipeline);
            p.set_bind_group(0, &Binder::new(ctx, kit, f).apply(cur.colour), &[]);
            p.dispatch_workgroups(gx, gy, 1);
            drop(p);
            cur.colour = 1 - cur.colour;
            rec.end(PassId::Depiction, levels, vec![], q)
        }
        ColourPass::Edl { strength, radius } => {
            let off = rec.arena.push(&EdlBlock::new(strength, radius))?;
            rec.image_pass(
                q,
                &kit.edl.pipeline,
                &Binder::new(ctx, kit, f).edl(cur.colour),
                &[off],
                (gx, gy),
            );
            cur.colour = 1 - cur.colour;
            rec.end(PassId::Edl, 1, vec![], q)
        }
        ColourPass::DepthCue { .. } => unreachable!("a pixel pass, recorded above"),
    }
}

/// `begin` (no `hole_alpha`: clears the accumulator) or `blend` of the current layer.
pub(crate) fn record_blend(
    rec: &mut Rec<'_>,
    kit: &Kit,
    f: &FrameBuffers,
    cur: &Cursor,
    hole_alpha: Option<f32>,
    background: [f32; 3],
) -> Result<(), GpuError> {
    let ctx = rec.ctx;
    rec.start();
    let slot = rec.slot()?;
    let off = rec.arena.push(&BlendBlock {
        hole_alpha: hole_alpha.unwrap_or(0.0),
        slot,
        pad: [0; 2],
        background,
        pad2: 0,
    })?;
    let q = rec.queries();
    let (gx, gy) = grid_2d(ctx, f.width, f.height)?;
    let mut p = rec.cpass(q.map(|q| q.0), q.map(|q| q.1));
    p.set_pipeline(match hole_alpha {
        Some(_) => &kit.blend.blend,
        None => &kit.blend.begin,
    });
    p.set_bind_group(
        0,
        &Binder::new(ctx, kit, f).blend(cur.g, cur.colour),
        &[off],
    );
    p.dispatch_workgroups(gx, gy, 1);
    drop(p);
    match hole_alpha {
        Some(_) => rec.end(PassId::BlendLayers, 1, vec![slot], q),
        None => rec.end(PassId::BlendBegin, 1, vec![], q),
    }
}

/// The composite over the background into colour image 0.
pub(crate) fn record_compose(
    rec: &mut Rec<'_>,
    kit: &Kit,
    f: &FrameBuffers,
    background: [f32; 3],
) -> Result<(), GpuError> {
    let ctx = rec.ctx;
    rec.start();
    let off = rec.arena.push(&BlendBlock {
        hole_alpha: 0.0,
        slot: 0,
        pad: [0; 2],
        background,
        pad2: 0,
    })?;
    let q = rec.queries();
    let (gx, gy) = grid_2d(ctx, f.width, f.height)?;
    rec.image_pass(
        q,
        &kit.blend.compose,
        &Binder::new(ctx, kit, f).blend(0, 0),
        &[off],
        (gx, gy),
    );
    rec.end(PassId::Compose, 1, vec![], q)
}

/// `shadow_texture` over every chunk against the light image in `cur.g`.
pub(crate) fn record_mark(
    rec: &mut Rec<'_>,
    kit: &Kit,
    f: &FrameBuffers,
    cur: &Cursor,
    cloud: &GpuCloud,
    mp: &crate::passes::shadow_texture::cpu::MarkParams,
) -> Result<(), GpuError> {
    let ctx = rec.ctx;
    rec.start();
    let slot = rec.slot()?;
    let q = rec.queries();
    let mut work = Vec::new();
    for (c, groups) in cloud.chunks.iter().zip(&f.cloud_groups().mark) {
        let groups = groups
            .as_ref()
            .ok_or_else(|| GpuError::Wgpu("shadow_texture: a chunk has no shadow counts".into()))?;
        let off = rec.arena.push(&MarkBlock {
            base: c.base,
            count: c.count,
            gap: mp.gap,
            slope_cap: mp.slope_cap,
            face: mp.face,
            shift: 8 * mp.light,
            has_normals: c.normals.is_some() as u32,
            slot,
        })?;
        work.push((&groups[cur.g], off, flat_groups(ctx, c.count as u64)));
    }
    let mut p = rec.cpass(q.map(|q| q.0), q.map(|q| q.1));
    p.set_pipeline(&kit.mark.pipeline);
    for (bg, off, (gx, gy)) in work {
        p.set_bind_group(0, bg, &[off]);
        p.dispatch_workgroups(gx, gy, 1);
    }
    drop(p);
    rec.end(PassId::ShadowTexture, 1, vec![slot], q)
}

pub(crate) fn record_output(
    rec: &mut Rec<'_>,
    kit: &Kit,
    f: &FrameBuffers,
    cur: &Cursor,
) -> Result<(), GpuError> {
    let ctx = rec.ctx;
    rec.start();
    let q = rec.queries();
    let (gx, gy) = grid_2d(ctx, f.width, f.height)?;
    rec.image_pass(
        q,
        &kit.output.pipeline,
        &Binder::new(ctx, kit, f).output(cur.colour),
        &[],
        (gx, gy),
    );
    rec.end(PassId::Output, 1, vec![], q)
}

/// The next peeled layer's reference depth from the current surface depth (see
/// `passes::project::cpu::peel_reference`); `bound` = 4 d̃.
pub(crate) fn record_peel_reference(
    rec: &mut Rec<'_>,
    kit: &Kit,
    f: &FrameBuffers,
    bound: f32,
) -> Result<(), GpuError> {
    let ctx = rec.ctx;
    rec.start();
    let off = rec
        .arena
        .push(&crate::passes::project::gpu::PeelReferenceBlock { bound, pad: [0; 3] })?;
    let q = rec.queries();
    let (gx, gy) = grid_2d(ctx, f.width, f.height)?;
    let group = Binder::new(ctx, kit, f).peel_reference();
    rec.image_pass(q, &kit.peel_reference.pipeline, &group, &[off], (gx, gy));
    rec.end(PassId::PeelReference, 1, vec![], q)
}
