//! The shadow texture of a scene or a cloud (Dobrev §6): loaded from a cache file when the
//! cache was made for the same clouds, placement and lights with enough samples, refined
//! from it when it has fewer, else computed; saved back to the cache when one is named.

use crate::{cache, file, LoadedScene, SceneError};
use glam::DAffine3;
use std::hash::{Hash, Hasher};
use std::path::{Path, PathBuf};
use std::time::Instant;
use stipple_render::shadow::{self, ShadowSettings};
use stipple_render::{Light, LitTexture, PreparedCloud, Renderer};

/// What to make a shadow texture with.
pub struct ShadowJob<'a> {
    pub settings: ShadowSettings,
    /// Samples per light at most (1 to [`shadow::MAX_SAMPLES`]).
    pub max_samples: u32,
    /// A `.stshadow` cache file to read and write.
    pub cache: Option<PathBuf>,
    /// The scene the cloud comes from (its placement keys the cache), if any.
    pub scene: Option<&'a LoadedScene>,
}

/// The key a cache file must carry to be used for `cloud` under `lights`: the scene's
/// relative placement key, or for a single cloud its content at identity placement.
pub fn key(
    scene: Option<&LoadedScene>,
    cloud: &PreparedCloud,
    lights: &[Light],
    settings: &ShadowSettings,
) -> u64 {
    // Translucent shadows depend on every point's opacity, and coloured ones on the colours
    // of the translucent points.
    let alpha = cloud.alpha.as_deref().map(crc32fast::hash);
    let tint = stipple_render::translucent::coloured(cloud).then(|| {
        let mut crc = crc32fast::Hasher::new();
        if let (Some(a), Some(c)) = (&cloud.alpha, &cloud.cloud.colors) {
            for (a, c) in a.iter().zip(c) {
                if *a < 255 {
                    crc.update(c);
                }
            }
        }
        crc.finalize()
    });
    let placed = match scene {
        Some(s) => s.relative_key(lights, settings),
        None => {
            let (lo, hi) = cloud.cloud.world_bounds();
            let unit = (hi - lo).length().max(1e-9);
            file::relative_key(
                &[(file::content_hash(&cloud.cloud), DAffine3::IDENTITY)],
                unit,
                lights,
                settings,
            )
        }
    };
    let mut h = std::collections::hash_map::DefaultHasher::new();
    (placed, alpha, tint).hash(&mut h);
    h.finish()
}

/// Makes the shadow texture of `cloud` under `lights` (see the module documentation) and
/// sets it on the cloud. `progress(done, total)` follows the light samples computed.
/// Returns a line saying what was done.
pub fn make(
    renderer: &mut Renderer,
    cloud: &mut PreparedCloud,
    lights: &[Light],
    job: &ShadowJob<'_>,
    progress: &mut dyn FnMut(u32, u32),
) -> Result<String, SceneError> {
    let cache_error = |path: &Path, message: String| SceneError::Cache {
        path: path.to_path_buf(),
        message,
    };
    if let Some(c) = &job.cache {
        if stipple_io::extension(c) != "stshadow" {
            return Err(cache_error(
                c,
                "a shadow cache must be a .stshadow file".into(),
            ));
        }
    }
    let key = key(job.scene, cloud, lights, &job.settings);
    let wanted: Vec<u32> = lights
        .iter()
        .map(|l| shadow::light_samples(l).min(job.max_samples))
        .collect();
    let mut start: Option<LitTexture> = None;
    let mut note = String::new();
    if let Some(c) = job.cache.as_ref().filter(|c| c.exists()) {
        match cache::read(c, cloud.cloud.len()) {
            Ok(hit) if hit.key == key => {
                let done = wanted
                    .iter()
                    .enumerate()
                    .all(|(l, &w)| hit.lit.samples[l] >= w);
                if done {
                    cloud.set_lit(Some(hit.lit))?;
                    return Ok(format!("shadows loaded from {}", c.display()));
                }
                note = format!(", refining the {} cached", c.display());
                start = Some(hit.lit);
            }
            Ok(_) => {
                note = format!(
                    " ({} was made for other clouds, placement or lights)",
                    c.display()
                )
            }
            Err(e) => note = format!(" (cache not used: {e})"),
        }
    }
    let total: u32 = wanted
        .iter()
        .enumerate()
        .map(|(l, &w)| w.saturating_sub(start.as_ref().map_or(0, |s| s.samples[l])))
        .sum();
    let t0 = Instant::now();
    let lit = renderer.shadow_texture(
        cloud,
        lights,
        &job.settings,
        start,
        job.max_samples,
        progress,
    )?;
    let mut line = format!(
        "shadows: {total} light samples in {:.0} ms{note}",
        t0.elapsed().as_secs_f64() * 1e3
    );
    if let Some(c) = &job.cache {
        cache::write(c, key, &lit)?;
        line.push_str(&format!(", saved to {}", c.display()));
    }
    cloud.set_lit(Some(lit))?;
    Ok(line)
}

#[cfg(test)]
mod tests {
    use super::*;
    use stipple_render::{gpu::GpuOptions, AreaLight, AreaShape, Backend};

    /// Computed once, then loaded from the cache; more samples refine the cached texture;
    /// another light misses the cache.
    #[test]
    fn a_cached_texture_is_loaded_refined_or_recomputed() {
        let dir = std::env::temp_dir().join(format!("stipple-shadows-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("a.toml");
        std::fs::write(
            &path,
            "[[cloud]]\ndemo = \"plane-objects\"\npoints = 20000\n\
             [render]\nshadow_cache = \"a.stshadow\"\n",
        )
        .unwrap();
        let (mut cloud, scene) = crate::load(&path).unwrap();
        let light = |x: f64, samples: u32| {
            Light::Area(AreaLight {
                centre: [x, 3.0, 1.0],
                facing: [-x, -3.0, -1.0],
                shape: AreaShape::Disc { radius: 0.3 },
                samples,
            })
        };
        let mut r = Renderer::new(Backend::Cpu, GpuOptions::default()).unwrap();
        let job = |max_samples| ShadowJob {
            settings: ShadowSettings::default(),
            max_samples,
            cache: Some(scene.dir.join(scene.render.shadow_cache.as_ref().unwrap())),
            scene: Some(&scene),
        };
        let mut run = |cloud: &mut PreparedCloud, l: Light, max| {
            make(&mut r, cloud, &[l], &job(max), &mut |_, _| {}).unwrap()
        };
        let first = run(&mut cloud, light(1.0, 4), 2);
        assert!(first.starts_with("shadows: 2 light samples"), "{first}");
        assert!(first.contains("saved to"), "{first}");
        let lit = cloud.lit().unwrap().clone();
        let again = run(&mut cloud, light(1.0, 4), 2);
        assert!(again.starts_with("shadows loaded from"), "{again}");
        assert_eq!(cloud.lit().unwrap(), &lit);
        let more = run(&mut cloud, light(1.0, 4), 4);
        assert!(
            more.starts_with("shadows: 2 light samples") && more.contains("refining"),
            "{more}"
        );
        assert_eq!(cloud.lit().unwrap().samples[0], 4);
        let other = run(&mut cloud, light(-1.0, 4), 4);
        assert!(
            other.contains("made for other clouds, placement or lights"),
            "{other}"
        );
        std::fs::remove_dir_all(dir).unwrap();
    }
}
