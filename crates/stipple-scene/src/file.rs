//! Scene files (TOML or JSON): several clouds, each with a transform, an optional colour, an
//! opacity and a material; lights; the camera; render settings. The format is documented in
//! `docs/scenes.md`, with examples in `examples/`.

use crate::{Host, SceneError};
use glam::{DAffine3, DMat3, DVec3};
use serde::Deserialize;
use std::hash::{Hash, Hasher};
use std::path::{Path, PathBuf};
use stipple_core::demo::{self, DemoScene};
use stipple_core::PointCloud;
use stipple_render::{
    AreaLight, AreaShape, Light, Material, ObjectTable, PreparedCloud, MAX_OBJECTS,
};

#[derive(Deserialize, Debug, Default)]
#[serde(deny_unknown_fields)]
pub struct SceneFile {
    #[serde(default)]
    pub camera: CameraSpec,
    #[serde(default)]
    pub render: RenderSpec,
    #[serde(default, rename = "cloud")]
    pub clouds: Vec<CloudSpec>,
    #[serde(default, rename = "light")]
    pub lights: Vec<LightSpec>,
}

/// The image size when neither the caller nor the scene gives one.
pub const DEFAULT_SIZE: (u32, u32) = (1024, 1024);
/// The vertical field of view (degrees) when neither the caller nor the scene gives one.
pub const DEFAULT_FOV: f64 = 45.0;
/// The most points a mesh of a scene is sampled to.
const MAX_SAMPLED: usize = 1 << 30;

#[derive(Deserialize, Debug, Default, Clone)]
#[serde(deny_unknown_fields)]
pub struct CameraSpec {
    pub eye: Option<[f64; 3]>,
    pub target: Option<[f64; 3]>,
    pub up: Option<[f64; 3]>,
    pub fov: Option<f64>,
    pub size: Option<[u32; 2]>,
    /// The direction the default framing looks from (`three-quarter`, `front`, `top`, …).
    pub view: Option<stipple_core::camera::View>,
}

/// How a scene's translucent clouds are drawn (`[render] transparency`).
#[derive(Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
pub enum Transparency {
    /// Depth peeling (Dobrev §4–5), `layers` deep.
    #[serde(rename = "peel")]
    Peel,
    /// Transparent splats (Zhang & Pajarola Algorithm 2): one pass.
    #[serde(rename = "splat-1pass")]
    Splat1Pass,
    /// Transparent splats with the nearest layer smoothly interpolated (Zhang & Pajarola
    /// Algorithm 3).
    #[serde(rename = "splat-2pass")]
    Splat2Pass,
}

#[derive(Deserialize, Debug, Default, Clone)]
#[serde(deny_unknown_fields)]
pub struct RenderSpec {
    pub layers: Option<u32>,
    pub background: Option<[u8; 3]>,
    /// Compute shadow textures for the lights that cast them (default true).
    pub shadows: Option<bool>,
    pub shadow_size: Option<u32>,
    /// Light layers of translucent shadows (see `ShadowSettings::layers`).
    pub shadow_layers: Option<u32>,
    /// Point and area lights fall off with the inverse square of the distance, at full
    /// strength this far from the light (see `Pipeline::falloff`).
    pub falloff: Option<f64>,
    /// A shadow cache file, relative to the scene file.
    pub shadow_cache: Option<PathBuf>,
    /// How translucent clouds are drawn: "peel" (Dobrev's depth peeling, `layers` deep; the
    /// default) or "splat-1pass" (Zhang & Pajarola's transparent splats, every layer in one
    /// pass; `layers` is then not used).
    pub transparency: Option<Transparency>,
    /// An environment behind transparent splats: "sky" or an equirectangular PNG or Radiance .hdr (relative
    /// to the scene file), as `--env`.
    pub env: Option<String>,
    /// Refractive index of transparent surfaces (they reflect and refract the environment),
    /// as `--ior`.
    pub ior: Option<f32>,
    /// Chromatic dispersion of the refraction, as `--dispersion`.
    pub dispersion: Option<f32>,
    /// How transparent splats make each group cover the surface: "duplicate" or
    /// "enlarge", as `--coverage`.
    pub coverage: Option<CoverageSpec>,
}

/// `[render] coverage` (see `stipple_render::CoverageMethod`).
#[derive(Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
#[serde(rename_all = "kebab-case")]
pub enum CoverageSpec {
    Duplicate,
    Enlarge,
}

impl From<CoverageSpec> for stipple_render::CoverageMethod {
    fn from(c: CoverageSpec) -> Self {
        match c {
            CoverageSpec::Duplicate => stipple_render::CoverageMethod::Duplicate,
            CoverageSpec::Enlarge => stipple_render::CoverageMethod::Enlarge,
        }
    }
}

#[derive(Deserialize, Debug, Clone)]
#[serde(deny_unknown_fields)]
pub struct CloudSpec {
    /// A cloud file, relative to the scene file.
    pub file: Option<PathBuf>,
    /// Or a generated shape: sphere, torus, plane, nested-tori, plane-objects.
    pub demo: Option<String>,
    pub points: Option<usize>,
    pub seed: Option<u64>,
    /// The tube radius of a `torus` demo (major radius 1).
    pub tube: Option<f32>,
    #[serde(default)]
    pub translate: [f64; 3],
    /// Rotations about X, then Y, then Z, in degrees.
    #[serde(default)]
    pub rotate: [f64; 3],
    /// Uniform scale.
    pub scale: Option<f64>,
    pub colour: Option<[u8; 3]>,
    pub opacity: Option<f32>,
    #[serde(default)]
    pub material: MaterialSpec,
    /// A volume file (.nrrd, .nii, .nii.gz, .raw): the value whose iso-surface becomes
    /// points (default: Otsu's threshold).
    pub iso: Option<f64>,
    /// A volume file: a transfer function instead of an iso-surface (a file relative to the
    /// scene file, or the points inline: `value r g b opacity` separated by `;`).
    pub transfer: Option<String>,
    /// A mesh file (a PLY with faces, .obj, .stl): sample its faces at this spacing (in the
    /// file's units) instead of taking its vertices.
    pub sample: Option<f64>,
    /// A lookup table file (relative to the scene file; see `stipple_core::lookup`): colour,
    /// opacity (times the cloud's `opacity`), splat size, material or visibility per value
    /// of an integer attribute of this cloud.
    pub lookup: Option<PathBuf>,
}

#[derive(Deserialize, Debug, Default, Clone)]
#[serde(deny_unknown_fields)]
pub struct MaterialSpec {
    pub ambient: Option<f32>,
    pub diffuse: Option<f32>,
    pub specular: Option<f32>,
    pub shininess: Option<f32>,
    /// Transparent splats: this cloud's refractive index (default: `[render] ior`).
    pub ior: Option<f32>,
    /// Transparent splats: this cloud's chromatic dispersion (default: `[render]
    /// dispersion`).
    pub dispersion: Option<f32>,
    /// Transparent splats: multiplies the Fresnel reflectance (default 1).
    pub reflectivity: Option<f32>,
    /// Transparent splats: the share of light behind absorbed per layer, besides the
    /// opacity: one number, or one per channel `[r, g, b]` (tinted glass; default 0).
    pub absorption: Option<Absorption>,
    /// Transparent splats: how this cloud's nearest layer is drawn where it is the nearest,
    /// "splat-1pass" (Algorithm 2) or "splat-2pass" (Algorithm 3, smoothly interpolated);
    /// default: `[render] transparency`. A scene without `[render] transparency` whose
    /// clouds choose draws transparent splats.
    pub transparency: Option<Transparency>,
}

/// A material's `absorption`: one share for every channel, or one per channel.
#[derive(Deserialize, Debug, Clone, Copy)]
#[serde(untagged)]
pub enum Absorption {
    Grey(f32),
    Rgb([f32; 3]),
}

#[derive(Deserialize, Debug, Clone)]
#[serde(deny_unknown_fields)]
pub struct LightSpec {
    /// point, area, directional or headlight.
    #[serde(rename = "type")]
    pub kind: String,
    pub position: Option<[f64; 3]>,
    pub direction: Option<[f64; 3]>,
    /// Area lights: the direction the light faces (default: towards the scene's centre).
    pub facing: Option<[f64; 3]>,
    /// Area lights: rectangle or disc.
    pub shape: Option<String>,
    /// Rectangle: [width, height].
    pub size: Option<[f64; 2]>,
    /// Disc: radius.
    pub radius: Option<f64>,
    /// Area lights: Monte Carlo samples (default 16, at most 255).
    pub samples: Option<u32>,
}

/// A scene's settings once its clouds are loaded and merged (the cloud is returned apart).
#[derive(Clone, Debug)]
pub struct LoadedScene {
    pub lights: Vec<Light>,
    pub camera: CameraSpec,
    pub render: RenderSpec,
    /// Where the scene file is (relative paths in it are resolved against it).
    pub dir: PathBuf,
    /// Identifies the clouds and their placement relative to each other and to the lights:
    /// unchanged when the whole scene moves rigidly (see [`LoadedScene::relative_key`]).
    objects: Vec<(u64, DAffine3)>,
    /// Size of the first object (the unit the placement key is quantised in).
    unit: f64,
    pub label: String,
    /// The cloud files the scene reads (resolved against its directory).
    pub files: Vec<PathBuf>,
}

/// Whether a path names a scene file.
pub fn is_scene(p: &Path) -> bool {
    matches!(stipple_io::extension(p).as_str(), "toml" | "json")
}

fn parse(path: &Path) -> std::result::Result<SceneFile, SceneError> {
    let text = std::fs::read_to_string(path).map_err(|e| SceneError::Read {
        path: path.to_path_buf(),
        source: e,
    })?;
    let parsed = if stipple_io::extension(path) == "json" {
        serde_json::from_str(&text).map_err(|e| e.to_string())
    } else {
        toml::from_str(&text).map_err(|e| e.to_string())
    };
    parsed.map_err(|e| SceneError::Parse {
        path: path.to_path_buf(),
        message: e.trim_end().to_string(),
    })
}

/// The transform of a cloud spec: world = translate + R (scale · p), R = Rz · Ry · Rx.
fn transform(c: &CloudSpec) -> DAffine3 {
    let [rx, ry, rz] = c.rotate.map(f64::to_radians);
    let r = DMat3::from_rotation_z(rz) * DMat3::from_rotation_y(ry) * DMat3::from_rotation_x(rx);
    DAffine3::from_mat3_translation(r * c.scale.unwrap_or(1.0), DVec3::from(c.translate))
}

/// Loads a scene file: reads or generates every cloud, applies transforms, colours and
/// opacities, and merges them into one cloud with an object table. `host` reads the cloud
/// files and checks what generated clouds may allocate (see [`Host`]).
pub fn load_with(
    path: &Path,
    host: &mut dyn Host,
) -> std::result::Result<(PreparedCloud, LoadedScene), SceneError> {
    build(parse(path)?, path, host)
}

/// Builds a scene described in code (or parsed): what [`load_with`] does after reading the
/// file. `path` names the scene in messages, and its directory is where relative cloud files
/// are looked for.
pub fn build(
    mut spec: SceneFile,
    path: &Path,
    host: &mut dyn Host,
) -> std::result::Result<(PreparedCloud, LoadedScene), SceneError> {
    let dir = path
        .parent()
        .map(Path::to_path_buf)
        .unwrap_or_else(|| PathBuf::from("."));
    let err = |what: String| SceneError::Invalid {
        path: path.to_path_buf(),
        message: what,
    };
    if spec.clouds.is_empty() {
        return Err(err("the scene lists no [[cloud]]".into()));
    }
    if spec.clouds.len() > MAX_OBJECTS {
        return Err(err(format!(
            "{} clouds; a scene holds at most {MAX_OBJECTS}",
            spec.clouds.len()
        )));
    }
    let mut parts = Vec::new();
    let mut materials = Vec::new();
    let mut objects = Vec::new();
    // Per part: the object of each point (lookup tables' materials add objects), and the
    // splat size factors a lookup table set.
    let mut part_index: Vec<Vec<u8>> = Vec::new();
    let mut sizes: Vec<Option<Vec<f32>>> = Vec::new();
    for (k, c) in spec.clouds.iter().enumerate() {
        let what = |m: String| err(format!("cloud {}: {m}", k + 1));
        let (cloud, name) = source(c, &dir, host).map_err(what)?;
        if cloud.is_empty() {
            return Err(what(format!("{name} has no points")));
        }
        let scale = c.scale.unwrap_or(1.0);
        if scale <= 0.0
            || !scale.is_finite()
            || !c.translate.iter().chain(&c.rotate).all(|v| v.is_finite())
        {
            return Err(what(
                "translate, rotate and scale must be finite, and scale positive".into(),
            ));
        }
        let opacity = c.opacity.unwrap_or(1.0);
        if !(0.0..=1.0).contains(&opacity) {
            return Err(what(format!("opacity {opacity}: must lie in 0..1")));
        }
        let m = material(&c.material, spec.render.ior).map_err(what)?;
        let t = transform(c);
        objects.push((content_hash(&cloud), t));
        let mut placed = place(cloud, &t, c.colour, opacity, &m);
        let base = materials.len();
        materials.push(m);
        let mut size = None;
        let mut index = vec![base as u8; placed.len()];
        if let Some(lk) = &c.lookup {
            let f = dir.join(lk);
            let mut table =
                stipple_io::lookup_table(&f).map_err(|e| what(format!("lookup {e}")))?;
            for e in table.value.values_mut().chain([&mut table.default]) {
                e.opacity = e.opacity.map(|o| o * opacity);
            }
            let fallback = m.base_colour.map(stipple_render::srgb::linear_to_srgb8);
            let a = stipple_core::lookup::apply(&mut placed, &table, fallback, &mut size)
                .map_err(|e| what(format!("lookup {}: {e}", f.display())))?;
            if materials.len() + a.overrides.len() > MAX_OBJECTS {
                return Err(what(format!(
                    "its lookup table's materials make more than {MAX_OBJECTS} objects"
                )));
            }
            for o in &a.overrides {
                materials.push(Material {
                    ambient: o.ambient.unwrap_or(m.ambient),
                    diffuse: o.diffuse.unwrap_or(m.diffuse),
                    specular: o.specular.unwrap_or(m.specular),
                    shininess: o.shininess.unwrap_or(m.shininess),
                    ..m
                });
            }
            index = if a.material_slot.is_empty() {
                vec![base as u8; placed.len()]
            } else {
                a.material_slot
                    .iter()
                    .map(|&s| (base + s as usize) as u8)
                    .collect()
            };
            host.note(&stipple_core::lookup::summary(&f, &table, &a));
            if !a.kept.is_empty() {
                // Hidden points make another object for the shadow cache.
                let mut h = std::collections::hash_map::DefaultHasher::new();
                (objects[k].0, &a.kept).hash(&mut h);
                objects[k].0 = h.finish();
            }
        }
        if materials.len() > MAX_OBJECTS {
            return Err(what(format!("more than {MAX_OBJECTS} objects")));
        }
        part_index.push(index);
        sizes.push(size);
        parts.push(placed);
    }
    let unit = {
        let (lo, hi) = parts[0].world_bounds();
        (hi - lo).length().max(1e-9)
    };
    let with_normals = parts.iter().filter(|p| p.normals.is_some()).count();
    if with_normals != 0 && with_normals != parts.len() {
        host.note(&format!(
            "{}: only {with_normals} of {} clouds have normals; the scene is rendered without \
             normals (unlit, raw pipeline)",
            path.display(),
            parts.len()
        ));
        for p in &mut parts {
            p.normals = None;
        }
    }
    let mut index = Vec::new();
    let mut merged = PointCloud::default();
    let any_size = sizes.iter().any(Option::is_some);
    let mut size = Vec::new();
    for (k, p) in parts.iter().enumerate() {
        index.extend_from_slice(&part_index[k]);
        if any_size {
            match &sizes[k] {
                Some(s) => size.extend_from_slice(s),
                None => size.extend(std::iter::repeat_n(1.0, p.len())),
            }
        }
        if k == 0 {
            merged = p.clone();
        } else {
            merged.append(p);
        }
    }
    merged.faces.clear();
    let mut cloud = PreparedCloud::new(merged)
        .with_objects(ObjectTable { index, materials })
        .map_err(|e| err(e.to_string()))?;
    if any_size {
        cloud.size = Some(size);
    }
    let centre = {
        let (lo, hi) = cloud.cloud.world_bounds();
        (lo + hi) * 0.5
    };
    let lights = spec
        .lights
        .iter()
        .enumerate()
        .map(|(i, l)| light(l, centre).map_err(|m| err(format!("light {}: {m}", i + 1))))
        .collect::<std::result::Result<Vec<_>, SceneError>>()?;
    if lights.len() > stipple_render::shadow::MAX_LIGHTS {
        return Err(err(format!(
            "{} lights; a scene holds at most {}",
            lights.len(),
            stipple_render::shadow::MAX_LIGHTS
        )));
    }
    if let Some(f) = spec.render.falloff {
        if !(f.is_finite() && f > 0.0 && f <= f32::MAX as f64) {
            return Err(err(format!(
                "falloff = {f}: a distance above zero (where lights shine at full strength)"
            )));
        }
    }
    // A cloud that picks its transparent-splat algorithm makes a scene of transparent
    // splats; one that peels cannot have it.
    if let Some(k) = spec
        .clouds
        .iter()
        .position(|c| c.material.transparency.is_some())
    {
        match spec.render.transparency {
            None => spec.render.transparency = Some(Transparency::Splat1Pass),
            Some(Transparency::Peel) => {
                return Err(err(format!(
                    "cloud {}: material transparency is for transparent splats, and \
                     [render] transparency = \"peel\" peels the frame (drop one of them)",
                    k + 1
                )))
            }
            Some(_) => {}
        }
    }
    if let Some(l) = spec.render.layers {
        if !(1..=stipple_render::pipeline::MAX_LAYERS).contains(&l) {
            return Err(err(format!(
                "layers = {l}: 1 to {}",
                stipple_render::pipeline::MAX_LAYERS
            )));
        }
    }
    Ok((
        cloud,
        LoadedScene {
            label: format!("scene {} ({} clouds)", path.display(), spec.clouds.len()),
            lights,
            camera: spec.camera,
            render: spec.render,
            files: spec
                .clouds
                .iter()
                .filter_map(|c| c.file.as_ref())
                .map(|f| {
                    if f.is_absolute() {
                        f.clone()
                    } else {
                        dir.join(f)
                    }
                })
                .collect(),
            dir,
            objects,
            unit,
        },
    ))
}

fn source(
    c: &CloudSpec,
    dir: &Path,
    host: &mut dyn Host,
) -> std::result::Result<(PointCloud, String), String> {
    match (&c.file, &c.demo) {
        (Some(f), None) => {
            let p = if f.is_absolute() {
                f.clone()
            } else {
                dir.join(f)
            };
            let transfer = c
                .transfer
                .as_deref()
                .map(|t| stipple_io::transfer_function(t, Some(dir)))
                .transpose()
                .map_err(|e| format!("transfer: {e}"))?;
            let opt = stipple_io::ReadOptions {
                iso: c.iso,
                transfer,
            };
            let mut cloud = host.read(&p, &opt)?;
            if let Some(spacing) = c.sample {
                let name = p.display();
                host.check_points(
                    &format!("sample = {spacing}"),
                    (stipple_core::mesh::area(&cloud) / (spacing * spacing)).min(1e18) as u64,
                )?;
                cloud =
                    stipple_core::mesh::sample(&cloud, spacing, MAX_SAMPLED, c.seed.unwrap_or(1))
                        .map_err(|e| format!("{name}: sample = {spacing}: {e}"))?
                        .cloud;
            }
            Ok((cloud, p.display().to_string()))
        }
        (None, Some(d)) => {
            let n = c.points.unwrap_or(200_000);
            if n == 0 {
                return Err("points must be at least 1".to_string());
            }
            host.check_points(&format!("points = {n}"), n as u64)?;
            let seed = c.seed.unwrap_or(1);
            let grey = [200, 200, 200];
            let cloud = match d.as_str() {
                "torus" => {
                    let tube = c.tube.unwrap_or(0.35);
                    if !(tube > 0.0 && tube < 1.0) {
                        return Err(format!("tube {tube}: must lie strictly between 0 and 1"));
                    }
                    demo::torus(n, tube, [214, 170, 60], seed)
                }
                "plane" => demo::plane(n, grey, seed),
                other => match DemoScene::from_name(other) {
                    Some(s) => demo::generate(s, n, seed),
                    None => {
                        return Err(format!(
                            "unknown demo `{other}` (sphere, torus, plane, nested-tori, \
                             plane-objects)"
                        ))
                    }
                },
            };
            Ok((cloud, format!("demo `{d}`")))
        }
        _ => Err("give exactly one of `file` and `demo`".to_string()),
    }
}

/// A cloud's material, checked (`frame_ior`: the scene's `[render] ior`).
fn material(m: &MaterialSpec, frame_ior: Option<f32>) -> std::result::Result<Material, String> {
    let d = Material::default();
    let optics = stipple_render::material::Optics {
        ior: m.ior,
        dispersion: m.dispersion,
        reflectivity: m.reflectivity.unwrap_or(1.0),
        absorption: match m.absorption {
            None => [0.0; 3],
            Some(Absorption::Grey(a)) => [a; 3],
            Some(Absorption::Rgb(a)) => a,
        },
        smooth_nearest: match m.transparency {
            None => None,
            Some(Transparency::Splat1Pass) => Some(false),
            Some(Transparency::Splat2Pass) => Some(true),
            Some(Transparency::Peel) => {
                return Err(
                    "material transparency \"peel\": depth peeling draws the whole \
                            frame ([render] transparency = \"peel\"); a cloud picks \
                            \"splat-1pass\" or \"splat-2pass\""
                        .into(),
                )
            }
        },
    };
    if let Some(eta) = optics.ior {
        if !(eta > 0.0 && eta <= 10.0) {
            return Err(format!(
                "material ior {eta}: a refractive index lies in (0, 10] (glass 1.5, water 1.33)"
            ));
        }
    }
    if let Some(dv) = optics.dispersion {
        if !(0.0..=0.2).contains(&dv) {
            return Err(format!(
                "material dispersion {dv}: 0 to 0.2 (glass: about 0.01)"
            ));
        }
        if optics.ior.or(frame_ior).is_none() {
            return Err(format!(
                "material dispersion {dv} spreads the refraction of an ior: give the \
                 material's ior or [render] ior"
            ));
        }
    }
    if !(0.0..=1.0).contains(&optics.reflectivity) {
        return Err(format!(
            "material reflectivity {}: must lie in 0..1",
            optics.reflectivity
        ));
    }
    if let Some(a) = optics.absorption.iter().find(|a| !(0.0..=1.0).contains(*a)) {
        return Err(format!("material absorption {a}: must lie in 0..1"));
    }
    let out = Material {
        ambient: m.ambient.unwrap_or(d.ambient),
        diffuse: m.diffuse.unwrap_or(d.diffuse),
        specular: m.specular.unwrap_or(d.specular),
        shininess: m.shininess.unwrap_or(d.shininess),
        base_colour: d.base_colour,
        optics,
    };
    for (name, v) in [
        ("ambient", out.ambient),
        ("diffuse", out.diffuse),
        ("specular", out.specular),
    ] {
        if !(0.0..=4.0).contains(&v) {
            return Err(format!("material {name} {v}: must lie in 0..4"));
        }
    }
    if !(0.0..=1024.0).contains(&out.shininess) {
        return Err(format!(
            "material shininess {}: must lie in 0..1024",
            out.shininess
        ));
    }
    Ok(out)
}

/// A hash of a cloud's positions and normals as read (before placement).
pub fn content_hash(c: &PointCloud) -> u64 {
    let mut h = std::collections::hash_map::DefaultHasher::new();
    c.len().hash(&mut h);
    c.origin.to_array().map(f64::to_bits).hash(&mut h);
    let mut crc = crc32fast::Hasher::new();
    crc.update(bytemuck::cast_slice(&c.positions));
    if let Some(n) = &c.normals {
        crc.update(bytemuck::cast_slice(n));
    }
    crc.finalize().hash(&mut h);
    h.finish()
}

/// Applies a transform (and colour, opacity) to a cloud; clouds without colours get their
/// grey (intensity) or the material's colour baked in, so every object keeps its own look.
fn place(
    mut c: PointCloud,
    t: &DAffine3,
    colour: Option<[u8; 3]>,
    opacity: f32,
    m: &Material,
) -> PointCloud {
    let (lo, hi) = c.world_bounds();
    let centre = (lo + hi) * 0.5;
    let new_origin = t.transform_point3(centre).round();
    let origin = c.origin;
    for p in &mut c.positions {
        let w = origin + p.as_dvec3();
        *p = (t.transform_point3(w) - new_origin).as_vec3();
    }
    c.origin = new_origin;
    let r = t.matrix3;
    if let Some(n) = &mut c.normals {
        for v in n {
            *v = (r * v.as_dvec3()).normalize_or_zero().as_vec3();
        }
    }
    // Where the sensor was turns with the cloud.
    if let Some(d) = &mut c.sensor_dirs {
        for v in d.iter_mut().filter(|v| **v != [0; 3]) {
            let u = r * DVec3::new(v[0] as f64, v[1] as f64, v[2] as f64);
            *v = stipple_core::cloud::quantise_dir(u);
        }
    }
    if let Some(s) = &mut c.sensor {
        s.position = t.transform_point3(s.position);
        s.forward = (r * s.forward).normalize_or(s.forward);
        s.up = (r * s.up).normalize_or(s.up);
    }
    if let Some(col) = colour {
        c.colors = Some(vec![col; c.len()]);
    } else if c.colors.is_none() {
        let grey = c.intensity.as_ref().and_then(|i| {
            let scale = stipple_render::intensity_scale(i)?;
            Some(
                i.iter()
                    .map(|&t| stipple_render::srgb::intensity_grey(t, scale))
                    .collect::<Vec<u8>>(),
            )
        });
        c.colors = Some(match grey {
            Some(g) => g.into_iter().map(|v| [v; 3]).collect(),
            None => vec![m.base_colour.map(stipple_render::srgb::linear_to_srgb8); c.len()],
        });
    }
    if opacity < 1.0 || c.opacity.is_some() {
        let o = c.opacity.take().unwrap_or_else(|| vec![1.0; c.len()]);
        c.opacity = Some(o.into_iter().map(|a| a * opacity).collect());
    }
    c
}

fn vec3(v: Option<[f64; 3]>, what: &str) -> std::result::Result<[f64; 3], String> {
    let v = v.ok_or_else(|| format!("needs `{what}`"))?;
    if v.iter().all(|x| x.is_finite()) {
        Ok(v)
    } else {
        Err(format!("`{what}` must be finite"))
    }
}

fn light(l: &LightSpec, centre: DVec3) -> std::result::Result<Light, String> {
    match l.kind.as_str() {
        "headlight" => Ok(Light::Headlight),
        "directional" => Ok(Light::Directional(vec3(l.direction, "direction")?)),
        "point" => Ok(Light::Point(vec3(l.position, "position")?)),
        "area" => {
            let c = vec3(l.position, "position")?;
            let facing = match l.facing {
                Some(f) => f,
                None => (centre - DVec3::from(c)).to_array(),
            };
            let shape = match l.shape.as_deref().unwrap_or("disc") {
                "rectangle" => {
                    let [width, height] = l.size.ok_or("a rectangle needs `size = [w, h]`")?;
                    AreaShape::Rectangle { width, height }
                }
                "disc" => AreaShape::Disc {
                    radius: l.radius.ok_or("a disc needs `radius`")?,
                },
                s => return Err(format!("unknown shape `{s}` (rectangle, disc)")),
            };
            let a = Light::Area(AreaLight {
                centre: c,
                facing,
                shape,
                samples: l.samples.unwrap_or(16),
            });
            stipple_render::lights::validate(&[a]).map_err(|e| e.to_string())?;
            Ok(a)
        }
        k => Err(format!(
            "unknown light type `{k}` (point, area, directional, headlight)"
        )),
    }
}

/// Quantises a length in units of `unit` (a millionth of it).
fn q(x: f64, unit: f64) -> i64 {
    (x / unit * 1e6).round() as i64
}

impl CameraSpec {
    /// The camera for a scene whose world bounds are `lo`..`hi`: the default framing (from
    /// the side, Z up when `z_up`), then what the spec gives: a target moves the framed view
    /// with it, an eye replaces it; an orthographic view of height `ortho` if given. Near and
    /// far always fit the bounds.
    pub fn camera(
        &self,
        lo: glam::DVec3,
        hi: glam::DVec3,
        z_up: bool,
        ortho: Option<f64>,
    ) -> std::result::Result<stipple_core::Camera, stipple_core::camera::CameraError> {
        let (w, h) = self.size.map(|[w, h]| (w, h)).unwrap_or(DEFAULT_SIZE);
        let fov = self.fov.unwrap_or(DEFAULT_FOV);
        let view = self.view.unwrap_or_default();
        let mut cam = stipple_core::Camera::framing_view(lo, hi, w, h, fov, z_up, view);
        let framed_dir = cam.eye - cam.target;
        if let Some(t) = self.target.map(DVec3::from) {
            cam.target = t;
            if self.eye.is_none() {
                cam.eye = t + framed_dir;
            }
        }
        if let Some(e) = self.eye {
            cam.eye = DVec3::from(e);
        }
        if let Some(u) = self.up {
            cam.up = DVec3::from(u);
        }
        if let Some(hh) = ortho {
            cam.projection = stipple_core::Projection::Orthographic { height: hh };
        }
        cam.validate()?;
        cam.fit_clip(lo, hi);
        Ok(cam)
    }
}

impl LoadedScene {
    /// The scene's camera for its merged cloud (see [`CameraSpec::camera`]).
    pub fn camera(
        &self,
        cloud: &PreparedCloud,
    ) -> std::result::Result<stipple_core::Camera, stipple_core::camera::CameraError> {
        let (lo, hi) = cloud.cloud.world_bounds();
        self.camera.camera(lo, hi, cloud.cloud.z_up, None)
    }

    /// Gives a pipeline the scene's lights (where it lists any), its background (unless
    /// `keep_background`: the user chose one) and its `layers` (where set).
    pub fn apply_to(&self, pipe: &mut stipple_render::Pipeline, keep_background: bool) {
        if !self.lights.is_empty() {
            pipe.lights = self.lights.clone();
        }
        if let (Some(b), false) = (self.render.background, keep_background) {
            pipe.background = b;
        }
        if let Some(l) = self.render.layers {
            pipe.layers = l;
        }
        if let Some(t @ (Transparency::Splat1Pass | Transparency::Splat2Pass)) =
            self.render.transparency
        {
            // Splats drawn back to front with their opacities, every layer in one pass
            // (Algorithm 2), the nearest layer smoothly interpolated (Algorithm 3).
            let s = pipe.splat.unwrap_or_default();
            pipe.splat = Some(stipple_render::SplatSettings {
                mode: stipple_render::SplatMode::Transparent,
                smooth_nearest: t == Transparency::Splat2Pass || s.smooth_nearest,
                ..s
            });
            pipe.geometry.clear();
            pipe.backface_culling = false;
            pipe.layers = 1;
        }
        // The command line's --light-falloff wins.
        if let (Some(f), None) = (self.render.falloff, pipe.falloff) {
            pipe.falloff = Some(f as f32);
        }
    }

    /// A key for the shadow texture of this scene under `lights` and `settings`: the clouds'
    /// contents, each cloud's placement relative to the first and the lights relative to the
    /// first cloud, quantised to a millionth of its size. Moving or turning the whole scene
    /// (clouds and lights together) keeps the key; moving a light or one cloud changes it.
    pub fn relative_key(
        &self,
        lights: &[Light],
        settings: &stipple_render::shadow::ShadowSettings,
    ) -> u64 {
        relative_key(&self.objects, self.unit, lights, settings)
    }
}

/// See [`LoadedScene::relative_key`]; `objects` are (content hash, placement) pairs.
pub fn relative_key(
    objects: &[(u64, DAffine3)],
    unit: f64,
    lights: &[Light],
    settings: &stipple_render::shadow::ShadowSettings,
) -> u64 {
    let mut h = std::collections::hash_map::DefaultHasher::new();
    let inv = objects[0].1.inverse();
    for (content, t) in objects {
        content.hash(&mut h);
        let rel = inv * *t;
        for v in rel.matrix3.to_cols_array() {
            ((v * 1e6).round() as i64).hash(&mut h);
        }
        for v in rel.translation.to_array() {
            q(v, unit).hash(&mut h);
        }
    }
    let point = |p: [f64; 3], h: &mut std::collections::hash_map::DefaultHasher| {
        for v in inv.transform_point3(DVec3::from(p)).to_array() {
            q(v, unit).hash(h);
        }
    };
    let dir = |d: [f64; 3], h: &mut std::collections::hash_map::DefaultHasher| {
        for v in inv
            .transform_vector3(DVec3::from(d))
            .normalize_or_zero()
            .to_array()
        {
            ((v * 1e6).round() as i64).hash(h);
        }
    };
    for l in lights {
        match l {
            Light::Headlight => 0u8.hash(&mut h),
            Light::Directional(d) => {
                1u8.hash(&mut h);
                dir(*d, &mut h);
            }
            Light::Point(p) => {
                2u8.hash(&mut h);
                point(*p, &mut h);
            }
            Light::Area(a) => {
                3u8.hash(&mut h);
                point(a.centre, &mut h);
                dir(a.facing, &mut h);
                match a.shape {
                    AreaShape::Rectangle { width, height } => {
                        (q(width, unit), q(height, unit)).hash(&mut h)
                    }
                    AreaShape::Disc { radius } => q(radius, unit).hash(&mut h),
                }
                // Not the sample count: samples come in a fixed sequence, so a texture
                // with fewer samples is refined rather than recomputed.
            }
        }
    }
    (
        settings.size,
        settings.slope_cap.to_bits(),
        settings.layer_gap.map(f32::to_bits),
        settings.background_fill_iterations,
        settings.occluded_fill_iterations,
        settings.layers,
    )
        .hash(&mut h);
    h.finish()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::load;
    use glam::Vec3;

    fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
        let p = dir.join(name);
        std::fs::write(&p, text).unwrap();
        p
    }

    fn tmp(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("stipple-scene-{name}-{}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    /// A cloud's lookup table (by a PLY property) sets colours, opacities (times the
    /// cloud's), splat sizes and materials (objects of their own beside the other cloud's)
    /// and hides points; a bad table names the cloud and the file.
    #[test]
    fn lookup_tables_give_points_their_look_per_value() {
        let d = tmp("lookup");
        let mut ply = String::from(
            "ply\nformat ascii 1.0\nelement vertex 6\nproperty float x\nproperty float y\n\
             property float z\nproperty int material\nend_header\n",
        );
        for i in 0..6 {
            ply.push_str(&format!("{i} 0 0 {}\n", i % 3));
        }
        write(&d, "c.ply", &ply);
        write(
            &d,
            "t.toml",
            "key = \"material\"\n[value.0]\ncolour = [1, 2, 3]\nopacity = 0.5\n\
             material = { specular = 0.9 }\n[value.1]\nshow = false\n[value.2]\nsize = 3\n",
        );
        let p = write(
            &d,
            "s.toml",
            r#"
[[cloud]]
demo = "sphere"
points = 100

[[cloud]]
file = "c.ply"
lookup = "t.toml"
opacity = 0.5
material = { ambient = 0.05 }
"#,
        );
        let (c, _) = load(&p).unwrap();
        assert_eq!(c.cloud.len(), 104, "two points hidden");
        let o = c.objects.as_ref().unwrap();
        assert_eq!(o.materials.len(), 3);
        let (plain, shiny) = (&o.materials[1], &o.materials[2]);
        assert_eq!(
            (plain.ambient, plain.specular),
            (0.05, Material::default().specular)
        );
        assert_eq!((shiny.ambient, shiny.specular), (0.05, 0.9));
        // The file's points in order: material 0, 2, 0, 2.
        assert_eq!(&o.index[100..], &[2, 1, 2, 1]);
        let colours = c.cloud.colors.as_ref().unwrap();
        assert_eq!(colours[100], [1, 2, 3]);
        let alpha = c.alpha.as_ref().unwrap();
        assert_eq!((alpha[0], alpha[100], alpha[101]), (255, 64, 128));
        let size = c.size.as_ref().unwrap();
        assert_eq!((size[0], size[100], size[101]), (1.0, 1.0, 3.0));
        let radii = c.splat_radii();
        assert!((radii[101] / radii[100] - 3.0).abs() < 1e-5);
        write(&d, "t.toml", "key = \"segment\"\n");
        let e = load(&p).err().unwrap().to_string();
        assert!(
            e.contains("cloud 2: lookup") && e.contains("`segment`"),
            "{e}"
        );
        std::fs::remove_dir_all(d).ok();
    }

    #[test]
    fn a_scene_merges_placed_clouds_with_their_objects() {
        let d = tmp("merge");
        let p = write(
            &d,
            "s.toml",
            r#"
[[cloud]]
demo = "sphere"
points = 1000
translate = [10, 0, 0]
scale = 2
colour = [255, 0, 0]
opacity = 0.5
material = { ambient = 0.1, diffuse = 0.9, ior = 1.33, dispersion = 0.01, absorption = [0.2, 0.1, 0.0] }

[[cloud]]
demo = "plane"
points = 500
rotate = [90, 0, 0]
material = { reflectivity = 0.25, absorption = 0.3, transparency = "splat-2pass" }

[[light]]
type = "area"
position = [0, 5, 0]
shape = "rectangle"
size = [1, 2]
samples = 8
"#,
        );
        let (c, s) = load(&p).unwrap();
        let c = &c;
        assert_eq!(c.cloud.len(), 1500);
        let o = c.objects.as_ref().unwrap();
        assert_eq!(o.index.iter().filter(|&&i| i == 0).count(), 1000);
        assert_eq!(o.materials[0].ambient, 0.1);
        assert_eq!(o.materials[1].ambient, Material::default().ambient);
        // Optics per cloud; the frame's index and dispersion where not given.
        let o0 = o.materials[0].optics;
        assert_eq!((o0.ior, o0.dispersion), (Some(1.33), Some(0.01)));
        assert_eq!((o0.reflectivity, o0.absorption), (1.0, [0.2, 0.1, 0.0]));
        let o1 = o.materials[1].optics;
        assert_eq!((o1.ior, o1.dispersion), (None, None));
        assert_eq!((o1.reflectivity, o1.absorption), (0.25, [0.3; 3]));
        // The transparency algorithm per cloud: the plane's Algorithm 3, the sphere the
        // frame's; a cloud that chooses makes a frame of transparent splats (Algorithm 2
        // where no cloud chooses).
        assert_eq!((o0.smooth_nearest, o1.smooth_nearest), (None, Some(true)));
        assert_eq!(s.render.transparency, Some(Transparency::Splat1Pass));
        let mut pipe = stipple_render::Pipeline::default();
        s.apply_to(&mut pipe, false);
        let sp = pipe.splat.unwrap();
        assert_eq!(sp.mode, stipple_render::SplatMode::Transparent);
        assert!(!sp.smooth_nearest);
        // The sphere: radius 2 around (10, 0, 0), red, α 0.5.
        for i in 0..1000 {
            let w = c.cloud.world(i);
            assert!(((w - DVec3::new(10.0, 0.0, 0.0)).length() - 2.0).abs() < 1e-4);
            assert_eq!(c.cloud.colors.as_ref().unwrap()[i], [255, 0, 0]);
            assert_eq!(c.alpha.as_ref().unwrap()[i], 128);
        }
        // The plane turned about X by 90°: y = 0 → z = 0, its normal +Y → +Z.
        for i in 1000..1500 {
            assert!(c.cloud.world(i).z.abs() < 1e-6);
            assert!((c.cloud.normals.as_ref().unwrap()[i] - Vec3::Z).length() < 1e-5);
            assert_eq!(c.alpha.as_ref().unwrap()[i], 255);
        }
        assert!(matches!(s.lights[0], Light::Area(a) if a.samples == 8));
        std::fs::remove_dir_all(d).unwrap();
    }

    #[test]
    fn bad_scenes_are_clear_errors() {
        let d = tmp("bad");
        for (text, want) in [
            ("", "lists no [[cloud]]"),
            ("[[cloud]]\ndemo = \"cube\"\n", "unknown demo `cube`"),
            ("[[cloud]]\nfile = \"a.ply\"\ndemo = \"sphere\"\n", "exactly one of"),
            ("[[cloud]]\ndemo = \"sphere\"\nopacity = 2\n", "opacity 2"),
            (
                "[[cloud]]\ndemo = \"sphere\"\n[render]\ncoverage = \"stretch\"\n",
                "unknown variant `stretch`",
            ),
            (
                "[[cloud]]\ndemo = \"sphere\"\nmaterial = { ior = 0 }\n",
                "cloud 1: material ior 0",
            ),
            (
                "[[cloud]]\ndemo = \"sphere\"\nmaterial = { ior = -1.5 }\n",
                "material ior -1.5",
            ),
            (
                "[[cloud]]\ndemo = \"sphere\"\nmaterial = { ior = 1.5, dispersion = 0.5 }\n",
                "material dispersion 0.5",
            ),
            (
                "[[cloud]]\ndemo = \"sphere\"\nmaterial = { dispersion = 0.01 }\n",
                "give the material's ior or [render] ior",
            ),
            (
                "[[cloud]]\ndemo = \"sphere\"\nmaterial = { reflectivity = 2 }\n",
                "material reflectivity 2",
            ),
            (
                "[[cloud]]\ndemo = \"sphere\"\nmaterial = { absorption = [0, 1.5, 0] }\n",
                "material absorption 1.5",
            ),
            ("[[cloud]]\ndemo = \"sphere\"\ncolor = [1, 2, 3]\n", "unknown field `color`"),
            ("[[cloud]]\nfile = \"missing.ply\"\n", "missing.ply"),
            (
                "[[cloud]]\ndemo = \"sphere\"\n[[light]]\ntype = \"spot\"\n",
                "unknown light type `spot`",
            ),
            (
                "[[cloud]]\ndemo = \"sphere\"\n[[light]]\ntype = \"area\"\nposition = [0, 1, 0]\nradius = 0.1\nsamples = 999\n",
                "999 samples",
            ),
            ("[[cloud]]\ndemo = \"sphere\"\n[render]\nlayers = 0\n", "layers = 0"),
            (
                "[[cloud]]\ndemo = \"sphere\"\n[render]\ntransparency = \"glass\"\n",
                "unknown variant `glass`",
            ),
            (
                "[[cloud]]\ndemo = \"sphere\"\nmaterial = { transparency = \"peel\" }\n",
                "material transparency \"peel\"",
            ),
            (
                "[[cloud]]\ndemo = \"sphere\"\n[[cloud]]\ndemo = \"plane\"\nmaterial = { transparency = \"splat-2pass\" }\n[render]\ntransparency = \"peel\"\n",
                "cloud 2: material transparency is for transparent splats",
            ),
        ] {
            let p = write(&d, "bad.toml", text);
            let e = load(&p)
                .err()
                .unwrap_or_else(|| panic!("{text:?} loaded"))
                .to_string();
            assert!(e.contains("bad.toml") && e.contains(want), "{text:?}: {e}");
        }
        std::fs::remove_dir_all(d).unwrap();
    }

    #[test]
    fn the_key_follows_relative_placement_only() {
        let s = stipple_render::shadow::ShadowSettings::default();
        let a = DAffine3::from_translation(DVec3::new(1.0, 2.0, 3.0));
        let b = DAffine3::from_rotation_y(0.3) * DAffine3::from_translation(DVec3::X);
        let light = |p: DVec3| Light::Point(p.to_array());
        let base = relative_key(&[(7, a), (9, b)], 2.0, &[light(DVec3::Y * 5.0)], &s);
        // The whole scene moved and turned together: same key.
        let m = DAffine3::from_rotation_z(1.1)
            * DAffine3::from_translation(DVec3::new(40.0, -3.0, 8.0));
        let moved = relative_key(
            &[(7, m * a), (9, m * b)],
            2.0,
            &[light(m.transform_point3(DVec3::Y * 5.0))],
            &s,
        );
        assert_eq!(base, moved);
        // The light moved: another key; one cloud moved or changed: another key.
        assert_ne!(
            base,
            relative_key(&[(7, a), (9, b)], 2.0, &[light(DVec3::Y * 5.1)], &s)
        );
        assert_ne!(
            base,
            relative_key(&[(7, a), (9, m * b)], 2.0, &[light(DVec3::Y * 5.0)], &s)
        );
        assert_ne!(
            base,
            relative_key(&[(8, a), (9, b)], 2.0, &[light(DVec3::Y * 5.0)], &s)
        );
    }

    /// A scene built in code: two placed demo clouds, a light and a background, given to a
    /// pipeline.
    #[test]
    fn a_scene_built_in_code_configures_a_pipeline() {
        let cloud = |demo: &str, x: f64| CloudSpec {
            file: None,
            demo: Some(demo.into()),
            points: Some(2_000),
            seed: None,
            tube: None,
            translate: [x, 0.0, 0.0],
            rotate: [0.0; 3],
            scale: None,
            colour: None,
            opacity: Some(0.5),
            material: MaterialSpec::default(),
            iso: None,
            transfer: None,
            sample: None,
            lookup: None,
        };
        let spec = SceneFile {
            clouds: vec![cloud("sphere", -2.0), cloud("torus", 2.0)],
            lights: vec![LightSpec {
                kind: "point".into(),
                position: Some([0.0, 5.0, 0.0]),
                direction: None,
                facing: None,
                shape: None,
                size: None,
                radius: None,
                samples: None,
            }],
            render: RenderSpec {
                layers: Some(3),
                background: Some([1, 2, 3]),
                ..RenderSpec::default()
            },
            ..SceneFile::default()
        };
        let (c, s) = build(spec, Path::new("in-code"), &mut crate::Plain).unwrap();
        assert_eq!(c.cloud.len(), 4_000);
        assert_eq!(c.objects.as_ref().unwrap().materials.len(), 2);
        let mut pipe = stipple_render::Pipeline::default();
        s.apply_to(&mut pipe, false);
        assert_eq!(pipe.lights, vec![Light::Point([0.0, 5.0, 0.0])]);
        assert_eq!((pipe.background, pipe.layers), ([1, 2, 3], 3));
        let mut kept = stipple_render::Pipeline::default();
        s.apply_to(&mut kept, true);
        assert_eq!(
            kept.background,
            stipple_render::Pipeline::default().background
        );
        // Transparency by splats: one pass of transparent splats, no peeling, no fills.
        let mut t = s.clone();
        t.render.transparency = Some(Transparency::Splat1Pass);
        let mut pipe = stipple_render::Pipeline::default();
        t.apply_to(&mut pipe, false);
        assert_eq!(
            pipe.splat.map(|s| s.mode),
            Some(stipple_render::SplatMode::Transparent)
        );
        assert_eq!(pipe.layers, 1);
        assert!(pipe.geometry.is_empty());
        assert!(!pipe.splat.unwrap().smooth_nearest);
        // Algorithm 3: the same, the nearest layer smoothly interpolated.
        t.render.transparency = Some(Transparency::Splat2Pass);
        let mut pipe = stipple_render::Pipeline::default();
        t.apply_to(&mut pipe, false);
        let s = pipe.splat.unwrap();
        assert_eq!(s.mode, stipple_render::SplatMode::Transparent);
        assert!(s.smooth_nearest);
    }

    /// The scene's camera: its size, fov and target, the framing's direction kept, near and
    /// far around the cloud.
    #[test]
    fn the_scene_camera_applies_the_spec_over_the_framing() {
        let d = tmp("camera");
        let p = write(
            &d,
            "c.toml",
            "[camera]\nsize = [320, 200]\nfov = 30\ntarget = [0.5, 0, 0]\n\
             [[cloud]]\ndemo = \"sphere\"\npoints = 500\n",
        );
        let (c, s) = load(&p).unwrap();
        let cam = s.camera(&c).unwrap();
        assert_eq!((cam.width, cam.height), (320, 200));
        assert_eq!(
            cam.projection,
            stipple_core::Projection::Perspective { fov_deg: 30.0 }
        );
        assert_eq!(cam.target, DVec3::new(0.5, 0.0, 0.0));
        let framed = CameraSpec::default()
            .camera(DVec3::splat(-1.0), DVec3::splat(1.0), false, None)
            .unwrap();
        let dir = |e: DVec3, t: DVec3| (e - t).normalize();
        assert!(dir(cam.eye, cam.target).dot(dir(framed.eye, framed.target)) > 0.999);
        let dist = (cam.eye - DVec3::new(0.5, 0.0, 0.0)).length();
        assert!(cam.near < dist - 0.9 && cam.far > dist + 0.9, "{cam:?}");
        std::fs::remove_dir_all(d).unwrap();
    }
}
