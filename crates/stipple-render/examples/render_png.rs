//! Renders a point cloud file to a PNG through the library API (the `stipple render` CLI does
//! the same with every option):
//! `cargo run --release -p stipple-render --example render_png -- cloud.ply out.png`
use stipple_core::Camera;
use stipple_render::{gpu::GpuOptions, Backend, Pipeline, PreparedCloud, Renderer};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [input, output] = &args[..] else {
        return Err("usage: render_png CLOUD OUT.png".into());
    };
    let mut cloud = PreparedCloud::new(stipple_io::read_cloud(input.as_ref())?);
    // Normals and splat radii where the file has none (PCA over 16 neighbours).
    cloud.prepare_surface(16, true)?;
    let b = cloud.bounds();
    let origin = cloud.cloud.origin;
    let (lo, hi) = (origin + b.min.as_dvec3(), origin + b.max.as_dvec3());
    let camera = Camera::framing(lo, hi, 800, 600, 40.0);
    // Zhang & Pajarola's surface splats; Pipeline::default() is Dobrev's image-space pipeline.
    let pipe = Pipeline::splats(Default::default());
    let mut renderer = Renderer::new(Backend::Auto, GpuOptions::default())?;
    let frame = renderer.render(&cloud, &camera, &pipe)?;
    stipple_io::image::write_png(output.as_ref(), frame.width, frame.height, &frame.rgba)?;
    println!("wrote {output} ({} points)", cloud.cloud.len());
    Ok(())
}
