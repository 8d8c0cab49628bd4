//! The Rust side of the Python package's overhead benchmark (BENCHMARKS.md, "Python"):
//! renders one input many times through `stipple_cli::api`, as `stipple.Renderer.render`
//! does from Python, and prints the mean wall time per frame.
//!
//!   cargo run --release -p stipple-cli --example render_loop -- INPUT|demo SIZE FRAMES [FLAGS…]
//!
//! e.g. `render_loop demo 1024 20 --backend cpu`; the flags are `stipple render`'s.

use std::time::Instant;

fn main() -> anyhow::Result<()> {
    let a: Vec<String> = std::env::args().skip(1).collect();
    if a.len() < 3 {
        anyhow::bail!("usage: render_loop INPUT|demo SIZE FRAMES [stipple render flags…]");
    }
    let (input, size, frames): (&str, u32, usize) = (&a[0], a[1].parse()?, a[2].parse()?);
    let mut argv: Vec<String> = vec![format!("--size={size}x{size}")];
    if input != "demo" {
        argv.insert(0, input.to_string());
    }
    argv.extend(a[3..].iter().cloned());
    let args = stipple_cli::api::parse_render_args(&argv)?;
    let loaded = stipple_cli::api::load(&args)?;
    let mut cloud = loaded.cloud;
    let mut renderer = args.backend.open()?;
    let view = stipple_cli::api::View {
        camera: &loaded.camera,
        scene: loaded.scene.as_ref(),
        tree: loaded.tree,
        label: &loaded.label,
    };
    let mut times = Vec::with_capacity(frames);
    let mut inner = Vec::with_capacity(frames);
    for k in 0..frames + 1 {
        let t0 = Instant::now();
        let r = stipple_cli::api::render_prepared(
            &args,
            &mut cloud,
            &view,
            &mut renderer,
            &mut |_| {},
        )?;
        std::hint::black_box(&r.frame.rgba);
        // The first frame estimates normals where the cloud has none: a warm-up.
        if k > 0 {
            times.push(t0.elapsed().as_secs_f64() * 1e3);
            inner.push(r.ms);
        }
    }
    times.sort_by(f64::total_cmp);
    inner.sort_by(f64::total_cmp);
    let mean = times.iter().sum::<f64>() / times.len().max(1) as f64;
    println!(
        "{} points, {size}², {} frames on {}: mean {mean:.2} ms, median {:.2} ms (the frame \
         alone: median {:.2} ms)",
        cloud.cloud.len(),
        times.len(),
        renderer.describe(),
        times[times.len() / 2],
        inner[inner.len() / 2]
    );
    Ok(())
}
