//! `stipple bench`: whole-frame timings, ms per pass (median over frames) and projection
//! throughput. Timing thresholds live here and in BENCHMARKS.md, never in tests.

use crate::args::{BackendArgs, CameraArgs, LookArgs, PipelineArgs, SourceArgs};
use crate::figures::{median, percentile};
use crate::Result;
use anyhow::anyhow;
use std::time::Instant;
use stipple_render::gpu::ProjectionPath;
use stipple_render::PassId;
use stipple_render::{PreparedCloud, Renderer};

#[derive(clap::Args)]
pub struct BenchArgs {
    #[command(flatten)]
    pub source: SourceArgs,
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
    look: LookArgs,
    #[command(flatten)]
    lod: crate::lod::LodArgs,
    /// Reproduce the rows of Dobrev et al. Table 3 for this cloud: frames per second with
    /// local illumination, transparency with 3 and 6 peeled layers, and shadows computed every
    /// frame with 1, 5 and 10 samples of an area light, at 512² and 1024² (the sizes can be
    /// changed with --table-sizes).
    #[arg(long)]
    table3: bool,
    /// Zhang & Pajarola Table 2 for this cloud: frames per second of the splat pipeline with
    /// the two-pass ε-z blend (their 2+1-pass reference), single-pass deferred blending with
    /// c = 0.8 and c = 0.4 and Voronoi rasterization, at 512² and 1024² (--table-sizes),
    /// beside the paper's Dragon figures (GeForce 7800 GTX, 1.1 M points). Normals and radii
    /// are prepared (and the groups coloured) before the clock starts; the grouping time is
    /// printed separately.
    #[arg(long, conflicts_with = "table3")]
    zhang: bool,
    /// Square image sizes for --table3 and --zhang.
    #[arg(long, value_delimiter = ',', default_values_t = [512u32, 1024])]
    table_sizes: Vec<u32>,
}

/// Zhang & Pajarola Table 2, Dragon row (fps on a GeForce 7800 GTX; image size not given).
const ZHANG_DRAGON: [(&str, f64); 3] =
    [("2+1-pass", 15.04), ("c = 0.8", 19.70), ("c = 0.4", 22.62)];

type PassTimes = Vec<(PassId, Vec<f64>, u32, u64)>;
/// Host-side steps of a frame outside the passes (see `Frame::host_ms`), per frame.
type HostTimes = Vec<(&'static str, Vec<f64>)>;

/// A GPU frame's host steps as one line: "record 0.10, submit + wait 1.69, …".
fn host_steps(steps: &[(&str, f64)]) -> String {
    let parts: Vec<String> = steps
        .iter()
        .map(|(step, ms)| format!("{step} {ms:.2}"))
        .collect();
    parts.join(", ")
}

/// One cell of a table benchmark on stderr, with the frame's host steps where it has them.
fn report_cell(size: u32, name: &str, ms: f64, host: &[(&str, f64)]) {
    if host.is_empty() {
        eprintln!("  {size}² {name}: {ms:.1} ms");
    } else {
        eprintln!(
            "  {size}² {name}: {ms:.1} ms (host steps: {} ms)",
            host_steps(host)
        );
    }
}

/// Times `frames` frames after `warmup`: per-pass times and whole-frame wall times.
fn time_frames(
    r: &mut Renderer,
    cloud: &PreparedCloud,
    camera: &stipple_core::Camera,
    pipe: &stipple_render::Pipeline,
    warmup: usize,
    frames: usize,
) -> Result<(PassTimes, Vec<f64>, HostTimes)> {
    for _ in 0..warmup {
        r.render(cloud, camera, pipe)?;
    }
    let mut per_pass: PassTimes = Vec::new();
    let mut totals = Vec::new();
    let mut host: HostTimes = Vec::new();
    for _ in 0..frames {
        let t = Instant::now();
        let f = r.render(cloud, camera, pipe)?;
        totals.push(t.elapsed().as_secs_f64() * 1e3);
        for (k, s) in f.stats.iter().enumerate() {
            if per_pass.len() <= k {
                per_pass.push((s.pass, Vec::new(), s.iterations, s.count));
            }
            per_pass[k].1.push(s.ms);
        }
        for (k, &(name, ms)) in f.host_ms.iter().enumerate() {
            if host.len() <= k {
                host.push((name, Vec::new()));
            }
            host[k].1.push(ms);
        }
    }
    Ok((per_pass, totals, host))
}

pub fn run(a: BenchArgs) -> Result<()> {
    if a.frames == 0 {
        return Err(anyhow!("--frames must be at least 1"));
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
    let scene_file = a
        .source
        .input
        .as_deref()
        .filter(|p| stipple_scene::is_scene(p));
    let (mut cloud, label, camera, scene) = match scene_file {
        Some(p) => {
            let (cloud, s, camera) = crate::look::load_scene(p, &a.camera)?;
            (cloud, s.label.clone(), camera, Some(s))
        }
        None => {
            let (cloud, label) = a.source.load()?;
            let camera = a.camera.build(&cloud.cloud)?;
            (cloud, label, camera, None)
        }
    };
    crate::memory::check_frame(
        camera.width,
        camera.height,
        crate::look::layers(&a.look, scene.as_ref()),
    )?;
    let load_s = t0.elapsed().as_secs_f64();
    if a.table3 {
        return table3(&a, cloud, &label, &mut r);
    }
    if a.zhang {
        return zhang(&a, cloud, &label, &mut r);
    }
    let peeled = crate::look::layers(&a.look, scene.as_ref()) > 1;
    let see_through = !peeled && crate::look::see_through(&a.look, scene.as_ref(), &cloud);
    let (mut pipe, notes) = a
        .pipeline
        .choose(&mut cloud, &camera, false, peeled, see_through)?;
    for n in &notes {
        println!("  {n}");
    }
    if let Some(line) = crate::look::apply(
        &mut cloud,
        &mut pipe,
        scene.as_ref(),
        &a.look,
        a.pipeline.background.is_some(),
        &mut r,
    )? {
        println!("  {line}");
    }
    let (mut per_pass, mut totals, mut host) =
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
    // Per frame, the passes' sum (GPU time where timestamp queries are used), before the
    // medians below sort each pass's figures.
    let mut frame_sums: Vec<f64> = (0..a.frames)
        .map(|i| per_pass.iter().filter_map(|(_, ms, _, _)| ms.get(i)).sum())
        .collect();
    frame_sums.sort_by(f64::total_cmp);
    let mut project_ms = f64::NAN;
    let mut sum = 0.0;
    for (name, ms, it, count) in &mut per_pass {
        let m = median(ms);
        sum += m;
        let extra = if *name == PassId::Project {
            project_ms = m;
            format!("   {:.1} M points/s", n as f64 / m / 1e3)
        } else {
            String::new()
        };
        println!("  {:<16} {m:>9.3} {it:>6} {count:>12}{extra}", name.name());
    }
    println!("  {:<16} {:>9.3} ms", "passes (sum)", sum);
    let t = median(&mut totals);
    println!(
        "  {:<16} {:>9.2} ms   ({:.1} fps, wall time with upload of uniforms and readback)",
        "frame",
        t,
        1e3 / t
    );
    if a.frames >= 20 {
        // The tail a viewer's frame rate is judged by.
        println!(
            "  {:<16} {:>9.2} ms p95, {:.2} ms p99, {:.2} ms max (wall); passes (sum) p99 {:.3} ms",
            "frame tail",
            percentile(&totals, 0.95),
            percentile(&totals, 0.99),
            percentile(&totals, 1.0),
            percentile(&frame_sums, 0.99)
        );
    }
    if !host.is_empty() {
        let medians: Vec<(&str, f64)> = host.iter_mut().map(|(n, v)| (*n, median(v))).collect();
        println!("  of which host    {} ms (medians)", host_steps(&medians));
    }
    if let (Some(g), true) = (r.gpu_mut(), project_ms.is_finite()) {
        // The other projection path, for comparison.
        let other = match g.projection {
            ProjectionPath::Compute => ProjectionPath::Hardware,
            ProjectionPath::Hardware => ProjectionPath::Compute,
        };
        let this = g.projection;
        g.projection = other;
        let (mut pp, _, _) = time_frames(&mut r, &cloud, &camera, &pipe, 1, a.frames)?;
        let Some(p) = pp.iter_mut().find(|p| p.0 == PassId::Project) else {
            return Ok(());
        };
        let m = median(&mut p.1);
        println!(
            "  project ({other:?}) {m:>9.3} ms   {:.1} M points/s   ({this:?} is {:.1}× faster)",
            n as f64 / m / 1e3,
            m / project_ms
        );
    }
    Ok(())
}

/// The rows of Dobrev Table 3.
const ROWS: [(&str, u32, u32); 6] = [
    ("Local illumination", 1, 0),
    ("Transparency (3 layers)", 3, 0),
    ("Transparency (6 layers)", 6, 0),
    ("Shadows (1 sample)", 1, 1),
    ("Shadows (5 samples)", 1, 5),
    ("Shadows (10 samples)", 1, 10),
];

/// Dobrev Table 3 for one cloud: fps per row and image size. Transparency uses the cloud's
/// opacities (0.5 where it has none); shadows come from a disc light above the viewer
/// (radius a tenth of the cloud's diagonal) and are recomputed every frame, as in the paper.
fn table3(a: &BenchArgs, mut cloud: PreparedCloud, label: &str, r: &mut Renderer) -> Result<()> {
    if let Some(g) = r.gpu_mut() {
        g.sync_timing = false;
    }
    if cloud.alpha.is_none() {
        cloud.set_opacity(0.5);
    }
    let base = a.pipeline.build_for(cloud.cloud.normals.is_some())?;
    let (lo, hi) = cloud.cloud.world_bounds();
    let diag = (hi - lo).length();
    let centre = (lo + hi) * 0.5;
    let mut cols: Vec<Vec<f64>> = Vec::new();
    for &size in &a.table_sizes {
        let mut cam_args = a.camera.clone();
        cam_args.size = Some((size, size));
        let camera = cam_args.build(&cloud.cloud)?;
        let b = camera.basis();
        let eye = camera.eye;
        let light = stipple_render::Light::Area(stipple_render::AreaLight {
            centre: (eye + b.up * (0.6 * diag) - b.right * (0.3 * diag)).to_array(),
            facing: (centre - eye).to_array(),
            shape: stipple_render::AreaShape::Disc { radius: 0.1 * diag },
            samples: 10,
        });
        let mut col = Vec::new();
        for (name, layers, samples) in ROWS {
            let mut pipe = base.clone();
            pipe.layers = layers;
            if samples > 0 {
                pipe.lights = vec![light];
            }
            let settings = stipple_render::shadow::ShadowSettings::default();
            let mut last_host = Vec::new();
            let mut frame = |cloud: &mut PreparedCloud| -> Result<f64> {
                let t = Instant::now();
                if samples > 0 {
                    let lit = r.shadow_texture(
                        cloud,
                        &pipe.lights,
                        &settings,
                        None,
                        samples,
                        &mut |_, _| {},
                    )?;
                    cloud.set_lit(Some(lit))?;
                }
                let f = r.render(cloud, &camera, &pipe)?;
                last_host = f.host_ms;
                Ok(t.elapsed().as_secs_f64() * 1e3)
            };
            for _ in 0..a.warmup.min(1) {
                frame(&mut cloud)?;
            }
            let mut ms = Vec::new();
            for _ in 0..a.frames {
                ms.push(frame(&mut cloud)?);
            }
            cloud.set_lit(None)?;
            let m = median(&mut ms);
            report_cell(size, name, m, &last_host);
            col.push(1e3 / m);
        }
        cols.push(col);
    }
    println!(
        "Dobrev Table 3 rows: {label}, {} points, {}, median of {} frames, fps",
        cloud.cloud.len(),
        r.describe(),
        a.frames
    );
    print!("  {:<26}", "Resolution");
    for s in &a.table_sizes {
        print!(" {:>9}", format!("{s}²"));
    }
    println!();
    for (k, (name, _, _)) in ROWS.iter().enumerate() {
        print!("  {name:<26}");
        for c in &cols {
            print!(" {:>9.2}", c[k]);
        }
        println!();
    }
    Ok(())
}

/// `stipple bench --zhang`: see [`BenchArgs::zhang`].
fn zhang(a: &BenchArgs, mut cloud: PreparedCloud, label: &str, r: &mut Renderer) -> Result<()> {
    use stipple_render::{Pipeline, SplatMode, SplatSettings};
    if let Some(g) = r.gpu_mut() {
        g.sync_timing = false;
    }
    let t0 = Instant::now();
    let report = cloud
        .prepare_surface(stipple_core::normals::DEFAULT_K, true)
        .map_err(|e| anyhow!("normal estimation: {e}"))?;
    let prep_s = t0.elapsed().as_secs_f64();
    let rows: [(&str, SplatMode, f32); 4] = [
        ("blend, 2 passes (ε-z)", SplatMode::Blend, 0.4),
        ("deferred, c = 0.8", SplatMode::Deferred, 0.8),
        ("deferred, c = 0.4", SplatMode::Deferred, 0.4),
        ("voronoi", SplatMode::Voronoi, 0.4),
    ];
    let mut groups_line = Vec::new();
    for c in [0.8f32, 0.4] {
        let t = Instant::now();
        let g = cloud.groups(c);
        groups_line.push(format!(
            "c = {c}: K = {} / max degree {} / mean degree {:.1} ({} conflicts), coloured in {:.2} s",
            g.groups,
            g.max_degree,
            g.mean_degree,
            g.conflicts,
            t.elapsed().as_secs_f64()
        ));
    }
    let mut cols: Vec<Vec<f64>> = Vec::new();
    for &size in &a.table_sizes {
        let mut cam_args = a.camera.clone();
        cam_args.size = Some((size, size));
        let camera = cam_args.build(&cloud.cloud)?;
        let mut col = Vec::new();
        for (name, mode, c) in rows {
            let mut pipe = Pipeline::splats(SplatSettings {
                mode,
                c,
                ..Default::default()
            });
            if let Some(bg) = a.pipeline.background {
                pipe.background = bg;
            }
            let (_, mut totals, mut host_t) =
                time_frames(r, &cloud, &camera, &pipe, a.warmup, a.frames)?;
            let m = median(&mut totals);
            let last_host: Vec<(&str, f64)> =
                host_t.iter_mut().map(|(n, v)| (*n, median(v))).collect();
            report_cell(size, name, m, &last_host);
            col.push(1e3 / m);
        }
        cols.push(col);
    }
    println!(
        "Zhang & Pajarola Table 2 rows: {label}, {} points, {}, median of {} frames, fps",
        cloud.cloud.len(),
        r.describe(),
        a.frames
    );
    println!(
        "  surface: {}normals and radii in {prep_s:.2} s",
        if report.estimated { "estimated " } else { "" }
    );
    for l in &groups_line {
        println!("  groups {l}");
    }
    print!("  {:<24}", "Resolution");
    for s in &a.table_sizes {
        print!(" {:>9}", format!("{s}²"));
    }
    println!("   paper (7800 GTX, Dragon 1.1 M)");
    for (k, (name, mode, c)) in rows.iter().enumerate() {
        print!("  {name:<24}");
        for col in &cols {
            print!(" {:>9.2}", col[k]);
        }
        let paper = match (mode, c) {
            (SplatMode::Blend, _) => Some(ZHANG_DRAGON[0]),
            (SplatMode::Deferred, c) if *c > 0.5 => Some(ZHANG_DRAGON[1]),
            (SplatMode::Deferred, _) => Some(ZHANG_DRAGON[2]),
            _ => None,
        };
        match paper {
            Some((what, fps)) => println!("   {fps:.2} ({what})"),
            None => println!("   -"),
        }
    }
    Ok(())
}
