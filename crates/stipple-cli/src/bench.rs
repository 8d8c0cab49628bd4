//! `stipple bench`: whole-frame timings, ms per pass (median over frames) and projection
//! throughput. Timing thresholds live here and in BENCHMARKS.md, never in tests.

use crate::args::{CameraArgs, PipelineArgs, SourceArgs};
use crate::Result;
use std::time::Instant;
use stipple_render::cpu::CpuRenderer;
use stipple_render::{Backend, ViewParams};

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
    /// Backend to time: cpu, gpu or auto.
    #[arg(long, default_value = "cpu", value_parser = Backend::parse)]
    backend: Backend,
}

fn median(v: &mut [f64]) -> f64 {
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

pub fn run(a: BenchArgs) -> Result<()> {
    if a.frames == 0 {
        return Err("--frames must be at least 1".into());
    }
    let backend = crate::args::resolve_backend(a.backend)?;
    let t0 = Instant::now();
    let (cloud, label) = a.source.load()?;
    let load_s = t0.elapsed().as_secs_f64();
    let camera = a.camera.build(&cloud.cloud)?;
    let pipe = a.pipeline.build()?;
    let v = ViewParams::new(&camera, cloud.cloud.origin);
    let mut r = CpuRenderer::new();
    for _ in 0..a.warmup {
        r.render(&cloud, &v, &pipe);
    }
    let mut per_pass: Vec<(&'static str, Vec<f64>, u32, u64)> = Vec::new();
    let mut totals = Vec::new();
    for _ in 0..a.frames {
        let t = Instant::now();
        let f = r.render(&cloud, &v, &pipe);
        totals.push(t.elapsed().as_secs_f64() * 1e3);
        for (k, s) in f.stats.iter().enumerate() {
            if per_pass.len() <= k {
                per_pass.push((s.name, Vec::new(), s.iterations, s.count));
            }
            per_pass[k].1.push(s.ms);
        }
    }
    let n = cloud.cloud.len();
    println!(
        "stipple bench: {label}, {n} points, {}x{}, backend {}, {} threads, {} frames (median)",
        camera.width,
        camera.height,
        if backend == Backend::Gpu {
            "gpu"
        } else {
            "cpu"
        },
        rayon::current_num_threads(),
        a.frames
    );
    println!("  load + prepare     {:>9.1} ms", load_s * 1e3);
    println!("  {:<16} {:>9} {:>6} {:>12}", "pass", "ms", "iter", "count");
    for (name, ms, it, count) in &mut per_pass {
        let m = median(ms);
        let extra = if *name == "project" {
            format!("   {:.1} M points/s", n as f64 / m / 1e3)
        } else {
            String::new()
        };
        println!("  {name:<16} {m:>9.2} {it:>6} {count:>12}{extra}");
    }
    let t = median(&mut totals);
    println!("  {:<16} {:>9.2} ms   ({:.1} fps)", "frame", t, 1e3 / t);
    Ok(())
}
