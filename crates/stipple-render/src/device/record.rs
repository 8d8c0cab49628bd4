//! Recording a frame: the command encoder with its counter slots and timestamp queries,
//! submission, statistics and readback.

use super::frame::*;
use crate::device::context::{GpuContext, GpuError};
use crate::device::util::Arena;
use crate::gbuffer::GBuffer;
use crate::stats::{PassId, PassStat};
use std::sync::Arc;
use std::time::Instant;
use wgpu::{Buffer, BufferUsages, CommandEncoder};

/// A section of the frame: one named pass as the statistics report it.
pub(crate) struct Section {
    pub(crate) pass: PassId,
    pub(crate) iterations: u32,
    pub(crate) until_stable: bool,
    pub(crate) slots: Vec<u32>,
    pub(crate) queries: Option<(u32, u32)>,
    pub(crate) wall_ms: f64,
}

/// Records the frame's passes; in synchronised timing mode submits and waits after each.
pub(crate) struct Rec<'a> {
    pub(crate) ctx: &'a GpuContext,
    pub(crate) enc: CommandEncoder,
    pub(crate) timer: Option<&'a Timer>,
    pub(crate) sync: bool,
    pub(crate) arena: &'a mut Arena,
    pub(crate) sections: Vec<Section>,
    pub(crate) next_query: u32,
    pub(crate) next_slot: u32,
    pub(crate) started: Instant,
}

impl<'a> Rec<'a> {
    pub(crate) fn slot(&mut self) -> Result<u32, GpuError> {
        let s = self.next_slot;
        if s as u64 >= SLOTS {
            return Err(GpuError::TooLarge(
                "too many pass iterations in one frame".into(),
            ));
        }
        self.next_slot += 1;
        Ok(s)
    }

    /// Timestamp query indices for the next section, when timestamps are available.
    pub(crate) fn queries(&mut self) -> Option<(u32, u32)> {
        let _ = self.timer?;
        if self.next_query + 2 > QUERIES {
            return None;
        }
        let q = (self.next_query, self.next_query + 1);
        self.next_query += 2;
        Some(q)
    }

    pub(crate) fn cpass(
        &mut self,
        begin: Option<u32>,
        end: Option<u32>,
    ) -> wgpu::ComputePass<'static> {
        let timestamp_writes = match (self.timer, begin.or(end)) {
            (Some(t), Some(_)) => Some(wgpu::ComputePassTimestampWrites {
                query_set: &t.set,
                beginning_of_pass_write_index: begin,
                end_of_pass_write_index: end,
            }),
            _ => None,
        };
        self.enc
            .begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: None,
                timestamp_writes,
            })
            .forget_lifetime()
    }

    /// One compute pass of a single dispatch of `grid` workgroups (the shape of most image
    /// passes), timed with the section's queries `q`.
    /// Opens the section of a step: its clock starts, and its timestamp queries (when the
    /// device has them) are taken.
    pub(crate) fn section(&mut self) -> Option<(u32, u32)> {
        self.start();
        self.queries()
    }

    /// A compute pass timed with the section's queries `q` (begin and end).
    pub(crate) fn timed_pass(&mut self, q: Option<(u32, u32)>) -> wgpu::ComputePass<'static> {
        self.cpass(q.map(|q| q.0), q.map(|q| q.1))
    }

    pub(crate) fn image_pass(
        &mut self,
        q: Option<(u32, u32)>,
        pipeline: &wgpu::ComputePipeline,
        group: &wgpu::BindGroup,
        offsets: &[u32],
        grid: (u32, u32),
    ) {
        let mut p = self.cpass(q.map(|q| q.0), q.map(|q| q.1));
        p.set_pipeline(pipeline);
        p.set_bind_group(0, group, offsets);
        p.dispatch_workgroups(grid.0, grid.1, 1);
    }

    pub(crate) fn start(&mut self) {
        self.started = Instant::now();
    }

    pub(crate) fn end(
        &mut self,
        pass: PassId,
        iterations: u32,
        slots: Vec<u32>,
        queries: Option<(u32, u32)>,
    ) -> Result<(), GpuError> {
        self.end_iterated(pass, iterations, false, slots, queries)
    }

    pub(crate) fn end_iterated(
        &mut self,
        pass: PassId,
        iterations: u32,
        until_stable: bool,
        slots: Vec<u32>,
        queries: Option<(u32, u32)>,
    ) -> Result<(), GpuError> {
        let mut wall_ms = f64::NAN;
        if self.sync {
            self.submit_and_wait()?;
            wall_ms = self.started.elapsed().as_secs_f64() * 1e3;
        }
        self.sections.push(Section {
            pass,
            iterations,
            until_stable,
            slots,
            queries,
            wall_ms,
        });
        Ok(())
    }

    pub(crate) fn submit_and_wait(&mut self) -> Result<(), GpuError> {
        let enc = std::mem::replace(
            &mut self.enc,
            self.ctx.device.create_command_encoder(&Default::default()),
        );
        self.arena.upload(&self.ctx.queue);
        self.ctx.queue.submit([enc.finish()]);
        wait(self.ctx)
    }
}

/// How long a wait for the GPU may take before it is an error, in seconds: ten minutes
/// (lavapipe's slowest frames take a minute or two), or `STIPPLE_GPU_TIMEOUT`.
pub fn gpu_timeout() -> std::time::Duration {
    timeout_from(std::env::var("STIPPLE_GPU_TIMEOUT").ok().as_deref())
}

/// The limit a value of `STIPPLE_GPU_TIMEOUT` sets: a positive number of seconds, else ten
/// minutes.
fn timeout_from(value: Option<&str>) -> std::time::Duration {
    let s = value
        .and_then(|v| v.trim().parse::<f64>().ok())
        .filter(|s| s.is_finite() && *s > 0.0)
        .unwrap_or(600.0);
    std::time::Duration::from_secs_f64(s.min(1e7))
}

/// Waits for the work submitted so far: a GPU that never finishes (a hung driver) gives an
/// error after [`gpu_timeout`] instead of holding the program forever.
pub(crate) fn wait(ctx: &GpuContext) -> Result<(), GpuError> {
    let limit = gpu_timeout();
    ctx.device
        .poll(wgpu::PollType::Wait {
            submission_index: None,
            timeout: Some(limit),
        })
        .map_err(|e| match e {
            wgpu::PollError::Timeout => GpuError::Wgpu(format!(
                "the GPU did not finish within {} s (a hung driver, or work far too large for \
                 this adapter; STIPPLE_GPU_TIMEOUT=SECONDS sets the limit, --backend cpu \
                 renders without the GPU)",
                limit.as_secs_f64()
            )),
            e => GpuError::Wgpu(e.to_string()),
        })?;
    ctx.take_errors()
}

/// Reads a mappable buffer's first `bytes` bytes.
pub(crate) fn read_back(ctx: &GpuContext, buf: &Buffer, bytes: u64) -> Result<Vec<u8>, GpuError> {
    read_back_with(ctx, buf, bytes, |b| b.to_vec())
}

/// Maps a mappable buffer's first `bytes` bytes and hands them to `take` (which copies out
/// what it needs: one copy instead of two for a frame's images).
pub(crate) fn read_back_with<T>(
    ctx: &GpuContext,
    buf: &Buffer,
    bytes: u64,
    take: impl FnOnce(&[u8]) -> T,
) -> Result<T, GpuError> {
    let slice = buf.slice(..bytes);
    let status = Arc::new(std::sync::Mutex::new(None));
    let s = status.clone();
    slice.map_async(wgpu::MapMode::Read, move |r| *s.lock().unwrap() = Some(r));
    wait(ctx)?;
    match status.lock().unwrap().take() {
        Some(Ok(())) => {}
        other => {
            return Err(GpuError::Wgpu(format!(
                "mapping the readback buffer failed: {other:?}"
            )))
        }
    }
    let out = take(
        &slice
            .get_mapped_range()
            .map_err(|e| GpuError::Wgpu(e.to_string()))?,
    );
    buf.unmap();
    Ok(out)
}

pub(crate) fn grid_2d(ctx: &GpuContext, w: u32, h: u32) -> Result<(u32, u32), GpuError> {
    let (gx, gy) = (w.div_ceil(8), h.div_ceil(8));
    let m = ctx.limits.max_compute_workgroups_per_dimension;
    if gx > m || gy > m {
        return Err(GpuError::TooLarge(format!(
            "{w}×{h} pixels needs {gx}×{gy} workgroups (the device allows {m} per dimension)"
        )));
    }
    Ok((gx, gy))
}

pub(crate) fn recorder<'a>(
    ctx: &'a GpuContext,
    shared: &'a Shared,
    arena: &'a mut Arena,
    sync: bool,
) -> Rec<'a> {
    let mut enc = ctx.device.create_command_encoder(&Default::default());
    enc.clear_buffer(&shared.counters, 0, None);
    Rec {
        ctx,
        enc,
        timer: shared.timer.as_ref(),
        sync: sync && shared.timer.is_none(),
        arena,
        sections: Vec::new(),
        next_query: 0,
        next_slot: 0,
        started: Instant::now(),
    }
}

pub(crate) fn read_f32(ctx: &GpuContext, buf: &Buffer, n: usize) -> Result<Vec<f32>, GpuError> {
    Ok(bytemuck::cast_slice(&copy_out(ctx, buf, 4 * n as u64)?).to_vec())
}

pub(crate) fn read_colour(
    ctx: &GpuContext,
    buf: &Buffer,
    n: usize,
) -> Result<Vec<[f32; 3]>, GpuError> {
    let raw = copy_out(ctx, buf, 16 * n as u64)?;
    let c4: &[[f32; 4]] = bytemuck::cast_slice(&raw);
    Ok(c4.iter().map(|c| [c[0], c[1], c[2]]).collect())
}

pub(crate) fn read_g(
    ctx: &GpuContext,
    f: &FrameBuffers,
    which: usize,
) -> Result<GBuffer, GpuError> {
    let n = f.width as usize * f.height as usize;
    let mut g = GBuffer::new(f.width, f.height);
    g.depth = read_f32(ctx, &f.depth[which], n)?;
    g.id = bytemuck::cast_slice(&copy_out(ctx, &f.id[which], 4 * n as u64)?).to_vec();
    Ok(g)
}

/// Copies a storage buffer out through a temporary mappable buffer (tests and tools).
pub(crate) fn copy_out(ctx: &GpuContext, buf: &Buffer, bytes: u64) -> Result<Vec<u8>, GpuError> {
    let tmp = ctx.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("copy out"),
        size: bytes.max(4),
        usage: BufferUsages::MAP_READ | BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let mut enc = ctx.device.create_command_encoder(&Default::default());
    enc.copy_buffer_to_buffer(buf, 0, &tmp, 0, bytes);
    ctx.queue.submit([enc.finish()]);
    read_back(ctx, &tmp, bytes)
}

/// Submits the recorded frame (with the counter and timestamp readbacks).
pub(crate) fn finish(mut rec: Rec<'_>, shared: &Shared) -> Result<Vec<Section>, GpuError> {
    rec.enc
        .copy_buffer_to_buffer(&shared.counters, 0, &shared.counters_read, 0, SLOTS * 4);
    if let (Some(t), true) = (rec.timer, rec.next_query > 0) {
        rec.enc
            .resolve_query_set(&t.set, 0..rec.next_query, &t.resolve, 0);
        rec.enc
            .copy_buffer_to_buffer(&t.resolve, 0, &t.read, 0, rec.next_query as u64 * 8);
    }
    rec.submit_and_wait()?;
    Ok(rec.sections)
}

pub(crate) fn stats(
    ctx: &GpuContext,
    shared: &Shared,
    sections: &[Section],
) -> Result<Vec<PassStat>, GpuError> {
    let counters: Vec<u32> =
        bytemuck::cast_slice(&read_back(ctx, &shared.counters_read, SLOTS * 4)?).to_vec();
    let stamps: Option<(Vec<u64>, f64)> = match &shared.timer {
        Some(t) if sections.iter().any(|s| s.queries.is_some()) => Some((
            bytemuck::cast_slice(&read_back(ctx, &t.read, QUERIES as u64 * 8)?).to_vec(),
            t.period_ns,
        )),
        _ => None,
    };
    Ok(sections
        .iter()
        .map(|s| {
            let ms = match (&stamps, s.queries) {
                (Some((ts, period)), Some((b, e))) => {
                    ts[e as usize].saturating_sub(ts[b as usize]) as f64 * period / 1e6
                }
                _ => s.wall_ms,
            };
            // Iterations "until stable" stop after the first that changed nothing.
            let mut iterations = s.iterations;
            if s.until_stable {
                if let Some(k) = s.slots.iter().position(|&k| counters[k as usize] == 0) {
                    iterations = iterations.min(k as u32 + 1);
                }
            }
            PassStat {
                pass: s.pass,
                ms,
                iterations,
                count: s.slots.iter().map(|&k| counters[k as usize] as u64).sum(),
            }
        })
        .collect())
}

pub(crate) fn flat_groups(ctx: &GpuContext, n: u64) -> (u32, u32) {
    ctx.grid(n.div_ceil(256) as u32)
}

#[cfg(test)]
mod tests {
    /// The wait's limit: ten minutes, or what `STIPPLE_GPU_TIMEOUT` says where it is a
    /// positive number of seconds.
    #[test]
    fn the_gpu_wait_has_a_limit() {
        use super::timeout_from;
        assert_eq!(timeout_from(Some("2.5")).as_secs_f64(), 2.5);
        assert_eq!(timeout_from(Some(" 30 ")).as_secs(), 30);
        for bad in [
            None,
            Some("0"),
            Some("-3"),
            Some("soon"),
            Some("NaN"),
            Some(""),
        ] {
            assert_eq!(timeout_from(bad).as_secs(), 600, "{bad:?}");
        }
    }
}
