//! `stipple bench`: whole-frame timings, ms per pass (median over frames) and projection
//! throughput. Timing thresholds live here and in BENCHMARKS.md, never in tests.

use crate::args::{BackendArgs, CameraArgs, PipelineArgs, SourceArgs};
use crate::Result;
use std::time::Instant;
use stipple_render::gpu::ProjectionPath;
use stipple_render::{PreparedCloud, Renderer};

#[derive(clap::Args)]
pub struct BenchArgs {
    #[command(flatten)]
    source: SourceArgs,
    #[command(flatten)]
    camera: CameraArgs,
    #[command(flatten)]
    pipeline: PipelineArgs,
    /// Frames to time (the median is reported).
    #[arg(long, default_value_t = 10)]
    frames: usize,
    /// Untimed frames first.
    #[arg(long, default_value_t = 2)]
    warmup: usize,
    #[command(flatten)]
    backend: BackendArgs,
    #[command(flatten)]
    lod: crate::lod::LodArgs,
}

pub fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    if v.is_empty() {
        return f64::NAN;
    }
    let m = v.len() / 2;
    if v.len() % 2 == 1 {
        v[m]
    } else {
        0.5 * (v[m - 1] + v[m])
    }
}

type PassTimes = Vec<(&'static str, Vec<f64>, u32, u64)>;

/// Times `frames` frames after `warmup`: per-pass times and whole-frame wall times.
fn time_frames(
    r: &mut Renderer,
    cloud: &PreparedCloud,
    camera: &stipple_core::Camera,
    pipe: &stipple_render::Pipeline,
    warmup: usize,
    frames: usize,
) -> Result<(PassTimes, Vec<f64>)> {
    for _ in 0..warmup {
        r.render(cloud, camera, pipe).map_err(|e| e.to_string())?;
    }
    let mut per_pass: PassTimes = Vec::new();
    let mut totals = Vec::new();
    for _ in 0..frames {
        let t = Instant::now();
        let f = r.render(cloud, camera, pipe).map_err(|e| e.to_string())?;
        totals.push(t.elapsed().as_secs_f64() * 1e3);
        for (k, s) in f.stats.iter().enumerate() {
            if per_pass.len() <= k {
                per_pass.push((s.name, Vec::new(), s.iterations, s.count));
            }
            per_pass[k].1.push(s.ms);
        }
    }
    Ok((per_pass, totals))
}

pub fn run(a: BenchArgs) -> Result<()> {
    if a.frames == 0 {
        return Err("--frames must be at least 1".into());
    }
    let mut r = a.backend.open()?;
    if let Some(g) = r.gpu_mut() {
        // Without timestamp queries, time each pass by submitting and waiting.
        g.sync_timing = true;
    }
    if let Some(p) = a.source.input.as_deref().filter(|p| crate::lod::is_tree(p)) {
        return crate::lod::bench(p, &a.camera, &a.pipeline, &a.lod, &mut r, a.frames);
    }
    let t0 = Instant::now();
    let (cloud, label) = a.source.load()?;
    let load_s = t0.elapsed().as_secs_f64();
    let camera = a.camera.build(&cloud.cloud)?;
    let pipe = a.pipeline.build_for(cloud.cloud.normals.is_some())?;
    let (mut per_pass, mut totals) =
        time_frames(&mut r, &cloud, &camera, &pipe, a.warmup, a.frames)?;
    let n = cloud.cloud.len();
    println!(
        "stipple bench: {label}, {n} points, {}x{}, {}, {} frames (median)",
        camera.width,
        camera.height,
        r.describe(),
        a.frames
    );
    println!("  load + prepare     {:>9.1} ms", load_s * 1e3);
    println!("  {:<16} {:>9} {:>6} {:>12}", "pass", "ms", "iter", "count");
    let mut project_ms = f64::NAN;
    let mut sum = 0.0;
    for (name, ms, it, count) in &mut per_pass {
        let m = median(ms);
        sum += m;
        let extra = if *name == "project" {
            project_ms = m;
            format!("   {:.1} M points/s", n as f64 / m / 1e3)
        } else {
            String::new()
        };
        println!("  {name:<16} {m:>9.3} {it:>6} {count:>12}{extra}");
    }
    println!("  {:<16} {:>9.3} ms", "passes (sum)", sum);
    let t = median(&mut totals);
    println!(
        "  {:<16} {:>9.2} ms   ({:.1} fps, wall time with upload of uniforms and readback)",
        "frame",
        t,
        1e3 / t
    );
    if let Some(g) = r.gpu_mut() {
        // The other projection path, for comparison.
        let other = match g.projection {
            ProjectionPath::Compute => ProjectionPath::Hardware,
            ProjectionPath::Hardware => ProjectionPath::Compute,
        };
        let this = g.projection;
        g.projection = other;
        let (mut pp, _) = time_frames(&mut r, &cloud, &camera, &pipe, 1, a.frames)?;
        let m = median(&mut pp[0].1);
        println!(
            "  project ({other:?}) {m:>9.3} ms   {:.1} M points/s   ({this:?} is {:.1}× faster)",
            n as f64 / m / 1e3,
            m / project_ms
        );
    }
    Ok(())
}
