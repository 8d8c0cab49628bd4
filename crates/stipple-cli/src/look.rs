//! Depth peeling, transparency and shadow textures on the command line: what `--layers`,
//! `--opacity`, `--shadows` and a scene's lights and render settings turn into.

use crate::args::{CameraArgs, LookArgs};
use crate::Result;
use anyhow::anyhow;
use glam::DVec3;
use stipple_core::Camera;
use stipple_render::shadow::{self, ShadowSettings};
use stipple_render::{Light, Pipeline, PreparedCloud, Renderer};
use stipple_scene::LoadedScene;

/// The camera arguments with a scene's camera filling what the command line left out.
pub fn scene_camera(args: &CameraArgs, s: &LoadedScene) -> CameraArgs {
    let mut a = args.clone();
    let v = |x: Option<[f64; 3]>| x.map(DVec3::from);
    a.eye = a.eye.or(v(s.camera.eye));
    a.target = a.target.or(v(s.camera.target));
    a.up = a.up.or(v(s.camera.up));
    a.fov = a.fov.or(s.camera.fov);
    a.size = a.size.or(s.camera.size.map(|[w, h]| (w, h)));
    // A scene's eye and view exclude each other as the flags do: the command line's wins.
    if args.eye.is_none() {
        a.view = a.view.or(s.camera.view);
    } else {
        a.view = None;
    }
    a
}

/// Whether the frame asks for transparency that only splats draw: translucent points
/// (`--opacity` below 1, or the file's or scene's alphas), an environment or an index of
/// refraction; not where a scene asks for peeling (`[render] transparency = "peel"`).
pub fn see_through(look: &LookArgs, scene: Option<&LoadedScene>, cloud: &PreparedCloud) -> bool {
    let peel = scene
        .is_some_and(|s| s.render.transparency == Some(stipple_scene::file::Transparency::Peel));
    !peel
        && (look.opacity.is_some_and(|o| o < 1.0)
            || look.env.is_some()
            || look.ior.is_some()
            || cloud.mean_alpha < 1.0)
}

/// Area lights given without a facing direction face the cloud's centre.
pub fn aim_area_lights(lights: &mut [Light], cloud: &PreparedCloud) {
    let (lo, hi) = cloud.cloud.world_bounds();
    let centre = (lo + hi) * 0.5;
    for l in lights {
        if let Light::Area(a) = l {
            if a.facing == [0.0; 3] {
                let f = centre - DVec3::from(a.centre);
                a.facing = if f.length() > 0.0 { f } else { -DVec3::Y }.to_array();
            }
        }
    }
}

/// The peeled layers asked for: `--layers`, else the scene's `layers`, else 1.
pub fn layers(look: &LookArgs, scene: Option<&LoadedScene>) -> u32 {
    look.layers
        .or(scene.and_then(|s| s.render.layers))
        .unwrap_or(1)
}

/// Applies the look: the scene's lights and background, layers, opacity, and the shadow
/// texture (computed, refined or loaded from the cache). Returns a line describing the
/// shadows, if any were made.
pub fn apply(
    cloud: &mut PreparedCloud,
    pipe: &mut Pipeline,
    scene: Option<&LoadedScene>,
    look: &LookArgs,
    background_given: bool,
    renderer: &mut Renderer,
) -> Result<Option<String>> {
    apply_progressively(cloud, pipe, scene, look, background_given, renderer, None)
        .map(|(line, _)| line)
}

/// What is left to refine of a shadow texture made with fewer samples than asked (Dobrev
/// §7: one sample while the view moves, more once it rests): the settings and lights it was
/// made with and the samples per light to reach.
#[derive(Clone, Debug)]
pub struct ShadowRefinement {
    pub settings: ShadowSettings,
    pub lights: Vec<Light>,
    pub max_samples: u32,
}

impl ShadowRefinement {
    /// Samples per light still to take.
    pub fn remaining(&self, cloud: &PreparedCloud) -> u32 {
        let taken = cloud.lit().map_or([0; 4], |l| l.samples);
        self.lights
            .iter()
            .zip(taken)
            .map(|(l, t)| {
                shadow::light_samples(l)
                    .min(self.max_samples)
                    .saturating_sub(t)
            })
            .sum()
    }

    /// Takes one more sample of every light that wants more. Returns the samples taken so
    /// far and wanted in all (summed over the lights).
    pub fn step(&self, cloud: &mut PreparedCloud, renderer: &mut Renderer) -> Result<(u32, u32)> {
        let start = cloud.lit().cloned();
        let taken = start
            .as_ref()
            .map_or(0, |l| l.samples.iter().max().copied().unwrap_or(0));
        let lit = renderer.shadow_texture(
            cloud,
            &self.lights,
            &self.settings,
            start,
            (taken + 1).min(self.max_samples),
            &mut |_, _| {},
        )?;
        let done: u32 = lit.samples.iter().sum();
        cloud.set_lit(Some(lit))?;
        Ok((done, done + self.remaining(cloud)))
    }
}

/// The environment of `--env` and `--ior`, else of the scene's `env` and `ior` (None when
/// none is given and no object has an ior of its own), about the cloud's up axis.
fn environment(
    look: &LookArgs,
    scene: Option<&LoadedScene>,
    cloud: &PreparedCloud,
) -> Result<Option<stipple_render::env::EnvSettings>> {
    let z_up = cloud.cloud.z_up;
    // A scene's cloud whose material has an ior refracts and reflects on its own.
    let object_ior = cloud
        .objects
        .as_ref()
        .is_some_and(|t| t.materials.iter().any(|m| m.optics.ior.is_some()));
    use stipple_render::env::{EnvSettings, Environment};
    let ior = look.ior.or(scene.and_then(|s| s.render.ior));
    if let Some(eta) = ior {
        if !(eta > 0.0 && eta <= 10.0) {
            return Err(anyhow!("--ior {eta}: a refractive index lies in (0, 10]"));
        }
    }
    let dispersion = look
        .dispersion
        .or(scene.and_then(|s| s.render.dispersion))
        .unwrap_or(0.0);
    if !(0.0..=0.2).contains(&dispersion) {
        return Err(anyhow!(
            "--dispersion {dispersion}: 0 to 0.2 (glass: about 0.01)"
        ));
    }
    if dispersion > 0.0 && ior.is_none() && !object_ior {
        return Err(anyhow!(
            "--dispersion spreads the refraction of --ior: give --ior too"
        ));
    }
    let from_scene = scene.and_then(|s| {
        s.render.env.as_ref().map(|e| match e.as_str() {
            "sky" => std::path::PathBuf::from("sky"),
            f => s.dir.join(f),
        })
    });
    let env = match look.env.clone().or(from_scene) {
        None if ior.is_none() && !object_ior => return Ok(None),
        None => Environment::Sky,
        Some(p) if p.as_os_str() == "sky" => Environment::Sky,
        Some(p) => {
            // A Radiance HDR file (linear, high dynamic range) or a PNG (sRGB).
            let hdr = p.extension().is_some_and(|e| e.eq_ignore_ascii_case("hdr"));
            let (w, h, env) = if hdr {
                let (w, h, texels) = stipple_io::hdr::read_hdr(&p)
                    .map_err(|e| anyhow!("--env {}: {e}", p.display()))?;
                (w, h, Environment::from_linear(w, h, texels))
            } else {
                let (w, h, rgba) = stipple_io::image::read_png(&p)
                    .map_err(|e| anyhow!("--env {}: {e}", p.display()))?;
                (w, h, Environment::from_rgba8(w, h, &rgba))
            };
            let env = env.map_err(|e| anyhow!("--env {}: {e}", p.display()))?;
            if let Environment::Image { width, height, .. } = &env {
                if (*width, *height) != (w, h) {
                    eprintln!(
                        "stipple: note: {}: the environment image ({w}×{h}) is used at \
                         {width}×{height}, the most a GPU binds",
                        p.display()
                    );
                }
            }
            env
        }
    };
    Ok(Some(EnvSettings {
        env: std::sync::Arc::new(env),
        up: if z_up { glam::Vec3::Z } else { glam::Vec3::Y },
        ior,
        dispersion,
    }))
}

/// [`apply`], taking at most `first_samples` samples per light now (None: all) and saying
/// what is left to refine.
pub fn apply_progressively(
    cloud: &mut PreparedCloud,
    pipe: &mut Pipeline,
    scene: Option<&LoadedScene>,
    look: &LookArgs,
    background_given: bool,
    renderer: &mut Renderer,
    first_samples: Option<u32>,
) -> Result<(Option<String>, Option<ShadowRefinement>)> {
    if let Some(s) = scene {
        s.apply_to(pipe, background_given);
    }
    // Transparent splats' coverage: the command line's, else the scene's.
    let coverage = look
        .coverage
        .or(scene.and_then(|s| s.render.coverage.map(Into::into)));
    if let (Some(c), Some(s)) = (coverage, pipe.splat.as_mut()) {
        s.coverage = c;
    }
    aim_area_lights(&mut pipe.lights, cloud);
    stipple_render::lights::validate(&pipe.lights).map_err(|e| anyhow!("--light: {e}"))?;
    pipe.layers = layers(look, scene);
    if !(1..=stipple_render::pipeline::MAX_LAYERS).contains(&pipe.layers) {
        return Err(anyhow!(
            "--layers {}: 1 to {}",
            pipe.layers,
            stipple_render::pipeline::MAX_LAYERS
        ));
    }
    let transparent = pipe
        .splat
        .is_some_and(|s| s.mode == stipple_render::SplatMode::Transparent);
    if transparent && pipe.layers > 1 {
        if look.layers.is_some() {
            eprintln!(
                "stipple: note: transparent splats composite every layer in one pass: --layers \
                 is not used"
            );
        }
        pipe.layers = 1;
    }
    if let Some(o) = look.opacity {
        if !(0.0..=1.0).contains(&o) {
            return Err(anyhow!("--opacity {o}: must lie in 0..1"));
        }
        cloud.set_opacity(o);
    }
    // A translucent cloud drawn with blending splats and no peeling: transparent splats show
    // it through (one pass, every layer); asked-for peeling (--layers) keeps peeling.
    if let (true, 1, Some(s)) = (cloud.mean_alpha < 1.0, pipe.layers, &mut pipe.splat) {
        if s.mode == stipple_render::SplatMode::Blend {
            // Algorithm 3: the surface in front smoothly interpolated (Algorithm 2 shows
            // each point's shading noise there as specks).
            s.mode = stipple_render::SplatMode::Transparent;
            s.smooth_nearest = true;
            eprintln!(
                "stipple: note: translucent points: drawn as transparent splats (Zhang & \
                 Pajarola's Algorithm 3, every layer in one pass; --layers N peels instead)"
            );
        }
    }
    pipe.environment = environment(look, scene, cloud)?;
    if let (Some(_), 1, Some(s)) = (&pipe.environment, pipe.layers, &mut pipe.splat) {
        // An environment (or an index of refraction) around opaque points drawn with
        // blending splats: transparent splats show it behind and reflected.
        if s.mode == stipple_render::SplatMode::Blend {
            s.mode = stipple_render::SplatMode::Transparent;
        }
    }
    if pipe.environment.is_some()
        && !pipe
            .splat
            .is_some_and(|s| s.mode == stipple_render::SplatMode::Transparent)
    {
        return Err(anyhow!(
            "--env, --ior and a scene material's ior apply to transparent splats: add \
             --pipeline splat --splat transparent (or --opacity below 1 with splats; in a \
             scene, [render] transparency = \"splat-1pass\" or \"splat-2pass\")"
        ));
    }
    if look.coverage.is_some()
        && !pipe
            .splat
            .is_some_and(|s| s.mode == stipple_render::SplatMode::Transparent)
    {
        eprintln!(
            "stipple: note: --coverage applies to transparent splats (--pipeline splat --splat \
             transparent, or a translucent cloud drawn with splats): not used here"
        );
    }
    if look.opacity.is_some_and(|o| o < 1.0)
        && pipe.layers == 1
        && !pipe.splat.is_some_and(|s| s.mode.is_ordered())
    {
        eprintln!(
            "stipple: note: --opacity shows only with depth peeling or transparent splats: \
             add --layers N (the number of surfaces a ray crosses, e.g. 2 for a closed \
             surface), or --pipeline splat --splat transparent"
        );
    }
    let wanted = match scene {
        Some(s) => !look.no_shadows && (look.shadows || s.render.shadows.unwrap_or(true)),
        None => look.shadows,
    };
    if !wanted {
        return Ok((None, None));
    }
    if pipe.lights.iter().all(|l| shadow::light_samples(l) == 0) {
        if scene.is_some() && !look.shadows {
            return Ok((None, None));
        }
        let raw = pipe
            .geometry
            .iter()
            .any(|g| matches!(g, stipple_render::pipeline::GeometryPass::Visibility { .. }));
        if raw {
            return Err(anyhow!(
                "--shadows: the raw pipeline (--raw, or --pipeline raw) draws without lights, \
                 so nothing casts shadows; leave it out (normals are estimated for clouds \
                 without them) or add --pipeline dobrev"
            ));
        }
        return Err(anyhow!(
            "--shadows: no light casts shadows; give --light point:x,y,z or disc:x,y,z,r (a \
             headlight or a directional light has no position)"
        ));
    }
    if cloud.cloud.normals.is_none() || !pipe.lighting {
        eprintln!(
            "stipple: note: the cloud has no normals (or lighting is off): shadowed points are \
             drawn at the ambient level, lit ones unchanged"
        );
    }
    let settings = ShadowSettings {
        size: look
            .shadow_size
            .or(scene.and_then(|s| s.render.shadow_size))
            .unwrap_or(0),
        layers: look
            .shadow_layers
            .or(scene.and_then(|s| s.render.shadow_layers))
            .unwrap_or(ShadowSettings::default().layers),
        ..ShadowSettings::default()
    };
    settings.validate().map_err(|e| {
        let flag = match e {
            shadow::ShadowError::Layers(_) => "--shadow-layers (or a scene's shadow_layers)",
            _ => "--shadow-size",
        };
        anyhow!("{flag}: {e}")
    })?;
    let max_samples = look.shadow_samples.unwrap_or(shadow::MAX_SAMPLES);
    if !(1..=shadow::MAX_SAMPLES).contains(&max_samples) {
        return Err(anyhow!(
            "--shadow-samples {max_samples}: 1 to {}",
            shadow::MAX_SAMPLES
        ));
    }
    if let Some(n) = look.shadow_samples {
        // Honoured as given for every area light (a light's own count is only the default).
        for l in &mut pipe.lights {
            if let Light::Area(a) = l {
                a.samples = n;
            }
        }
    }
    let job = stipple_scene::shadows::ShadowJob {
        settings,
        max_samples: first_samples.map_or(max_samples, |f| f.clamp(1, max_samples)),
        cache: look
            .shadow_cache
            .clone()
            .or_else(|| scene.and_then(|s| s.render.shadow_cache.as_ref().map(|p| s.dir.join(p)))),
        scene,
    };
    let bar = indicatif::ProgressBar::new(0);
    bar.set_style(
        indicatif::ProgressStyle::with_template(
            "shadows {bar:30} {pos}/{len} light samples, {elapsed} (ETA {eta})",
        )
        .expect("template"),
    );
    let line = stipple_scene::shadows::make(renderer, cloud, &pipe.lights, &job, &mut |d, t| {
        bar.set_length(t as u64);
        bar.set_position(d as u64);
    })?;
    bar.finish_and_clear();
    let refine = ShadowRefinement {
        settings,
        lights: pipe.lights.clone(),
        max_samples,
    };
    let refine = (refine.remaining(cloud) > 0).then_some(refine);
    Ok((Some(line), refine))
}

/// A scene file's merged cloud, its settings and the camera.
pub fn load_scene(
    path: &std::path::Path,
    camera: &CameraArgs,
) -> Result<(PreparedCloud, LoadedScene, Camera)> {
    let (cloud, s) = stipple_scene::load_with(path, &mut CliHost)?;
    let cam = scene_camera(camera, &s).build(&cloud.cloud).map_err(|e| {
        anyhow!(
            "{}: {e} (from its [camera] table and the camera flags given)",
            path.display()
        )
    })?;
    Ok((cloud, s, cam))
}

/// Scene loading as the command line does it: a spinner while reading, the memory budget
/// for generated clouds, notes on stderr.
struct CliHost;

impl stipple_scene::Host for CliHost {
    fn read(
        &mut self,
        path: &std::path::Path,
        opt: &stipple_io::ReadOptions,
    ) -> std::result::Result<stipple_core::PointCloud, String> {
        crate::args::read_with_options(path, opt).map_err(|e| crate::message(&e))
    }

    fn check_points(&mut self, what: &str, n: u64) -> std::result::Result<(), String> {
        crate::memory::check_points(what, n, crate::memory::BYTES_PER_POINT)
            .map_err(|e| crate::message(&e))
    }

    fn note(&mut self, message: &str) {
        eprintln!("stipple: note: {message}");
    }
}
