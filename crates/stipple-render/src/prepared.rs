//! The cloud as frames use it: what every frame needs computed once (point spacing,
//! intensity scale, opacities, objects, shadow textures, normals and splat radii).

use crate::*;
use stipple_core::{Camera, PointCloud};

/// A scene's objects: the object of each point and each object's material.
#[derive(Clone, Debug, PartialEq)]
pub struct ObjectTable {
    /// Object per point (at most [`MAX_OBJECTS`] objects).
    pub index: Vec<u8>,
    pub materials: Vec<Material>,
}

/// Objects a scene may hold (the object index is 8 bits per point).
pub const MAX_OBJECTS: usize = 256;

/// A point's opacity as blending uses it: 8 bits, as in an sRGBA file (α = a / 255).
#[inline]
pub fn alpha8(opacity: f32) -> u8 {
    (opacity.clamp(0.0, 1.0) * 255.0 + 0.5) as u8
}

pub use stipple_core::colour_map::intensity_scale;

/// A cloud with what every frame needs computed once: the point spacing (for d̃), the
/// intensity scale, opacities, and (for scenes) objects and shadow textures.
pub struct PreparedCloud {
    pub cloud: PointCloud,
    /// Median nearest-neighbour distance, world units.
    pub spacing: f32,
    /// Maps intensity to [0, 1] (1 / the 99th percentile), when the cloud has intensity that
    /// shows something ([`intensity_scale`]).
    pub intensity_scale: Option<f32>,
    /// Per-point opacity in 8 bits (None: every point is opaque).
    pub alpha: Option<Vec<u8>>,
    /// The mean opacity: what a pixel filled by the anisotropic fill (no point of its own)
    /// blends with.
    pub mean_alpha: f32,
    /// Objects and their materials (None: one object with the pipeline's material).
    pub objects: Option<ObjectTable>,
    /// A factor on each point's splat radius (a lookup table's `size`; see
    /// [`PreparedCloud::with_lookup`]). None: 1 for every point.
    pub size: Option<Vec<f32>>,
    /// Surface shape per point relative to the cloud's normals (quadric splats; see
    /// `stipple_core::normals::shapes`), from [`PreparedCloud::prepare_surface`]. None: flat
    /// splats. Valid only for the normals it was fitted to.
    pub shapes: Option<Vec<passes::splat::SplatShape>>,
    /// Deferred blending's splat groups, computed on first use (see
    /// [`PreparedCloud::groups`]), with the key and c they were made for.
    groups: std::sync::Mutex<Option<(u64, u32, std::sync::Arc<stipple_core::grouping::Grouping>)>>,
    /// The transparent splats' group memberships (see [`PreparedCloud::coverage`]).
    #[allow(clippy::type_complexity)]
    coverage:
        std::sync::Mutex<Option<(u64, (u32, crate::CoverageMethod), std::sync::Arc<Coverage>)>>,
    /// The cloud's bounds, computed on first use for the key they were made for (a frame
    /// needs them; recomputing them read every point, 30 ms a frame at 100 M points).
    bounds: std::sync::Mutex<Option<(u64, stipple_core::Bounds)>>,
    /// The shadow texture in use (see [`PreparedCloud::set_lit`]).
    lit: Option<LitTexture>,
    /// What [`PreparedCloud::prepare_surface`] did, whether the cloud had normals after it,
    /// and the k and viewpoint it used: a later call with nothing new to do repeats the report instead of the work. Whoever
    /// replaces the positions or normals afterwards clears it (`forget_surface`).
    surface: Option<(SurfaceReport, bool, usize, Option<glam::DVec3>)>,
    /// Unique per preparation: the GPU backend re-uploads when it changes.
    pub key: u64,
    /// Changes whenever the shadow texture does (the GPU backend re-uploads it alone).
    pub lit_key: u64,
}

static NEXT_CLOUD_KEY: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);

fn next_key() -> u64 {
    NEXT_CLOUD_KEY.fetch_add(1, std::sync::atomic::Ordering::Relaxed)
}

impl PreparedCloud {
    pub fn new(cloud: PointCloud) -> PreparedCloud {
        let spacing = cloud.estimate_spacing();
        PreparedCloud::with_spacing(cloud, spacing)
    }

    /// Prepares a cloud whose point spacing is already known (a LOD cut knows it from its
    /// nodes; estimating it would cost a neighbour search per frame).
    pub fn with_spacing(cloud: PointCloud, spacing: f32) -> PreparedCloud {
        let intensity_scale = cloud.intensity.as_deref().and_then(intensity_scale);
        let alpha: Option<Vec<u8>> = cloud
            .opacity
            .as_ref()
            .map(|o| o.iter().map(|&a| alpha8(a)).collect());
        let mean_alpha = match &alpha {
            Some(a) if !a.is_empty() => {
                a.iter().map(|&x| x as f64).sum::<f64>() / (255.0 * a.len() as f64)
            }
            _ => 1.0,
        } as f32;
        PreparedCloud {
            cloud,
            spacing,
            intensity_scale,
            alpha,
            mean_alpha,
            objects: None,
            size: None,
            shapes: None,
            groups: Default::default(),
            coverage: Default::default(),
            bounds: Default::default(),
            lit: None,
            surface: None,
            key: next_key(),
            lit_key: next_key(),
        }
    }

    /// After the positions or normals were replaced: the next `prepare_surface` works again.
    pub fn forget_surface(&mut self) {
        self.surface = None;
        self.shapes = None;
    }

    /// A copy to change for one frame (colours, opacity, shadows) while this one stays as it
    /// is: it has keys of its own, so the GPU backend uploads it rather than reusing this
    /// cloud's buffers.
    pub fn duplicate(&self) -> PreparedCloud {
        PreparedCloud {
            cloud: self.cloud.clone(),
            spacing: self.spacing,
            intensity_scale: self.intensity_scale,
            alpha: self.alpha.clone(),
            mean_alpha: self.mean_alpha,
            objects: self.objects.clone(),
            size: self.size.clone(),
            shapes: self.shapes.clone(),
            // Both are kept per key: made again for the new one on first use.
            groups: Default::default(),
            coverage: Default::default(),
            bounds: Default::default(),
            lit: self.lit.clone(),
            surface: self.surface.clone(),
            key: next_key(),
            lit_key: next_key(),
        }
    }

    /// Gives every point the same opacity.
    pub fn set_opacity(&mut self, opacity: f32) {
        let a = alpha8(opacity);
        self.alpha = Some(vec![a; self.cloud.len()]);
        self.mean_alpha = a as f32 / 255.0;
        self.key = next_key();
    }

    /// Gives the points objects with their own materials. Errors when the table does not
    /// match the cloud.
    pub fn with_objects(mut self, objects: ObjectTable) -> Result<PreparedCloud, RenderError> {
        if objects.index.len() != self.cloud.len() {
            return Err(ObjectError::Points {
                table: objects.index.len(),
                cloud: self.cloud.len(),
            }
            .into());
        }
        if objects.materials.is_empty() || objects.materials.len() > MAX_OBJECTS {
            return Err(ObjectError::Count(objects.materials.len()).into());
        }
        if let Some(&o) = objects
            .index
            .iter()
            .find(|&&o| o as usize >= objects.materials.len())
        {
            return Err(ObjectError::Material {
                object: o as u32,
                materials: objects.materials.len(),
            }
            .into());
        }
        self.objects = Some(objects);
        self.key = next_key();
        Ok(self)
    }

    /// Sets (or clears) the shadow texture shading uses. Errors when it does not match.
    pub fn set_lit(&mut self, lit: Option<LitTexture>) -> Result<(), RenderError> {
        if let Some(l) = &lit {
            if l.counts.len() != self.cloud.len() {
                return Err(shadow::ShadowError::Points {
                    texture: l.counts.len(),
                    cloud: self.cloud.len(),
                }
                .into());
            }
        }
        self.lit = lit;
        self.lit_key = next_key();
        Ok(())
    }

    pub fn lit(&self) -> Option<&LitTexture> {
        self.lit.as_ref()
    }

    /// The Phong terms by object.
    pub fn terms(&self, pipe: &Pipeline) -> Vec<passes::shade::cpu::Terms> {
        let t = |m: &Material| passes::shade::cpu::Terms {
            ambient: m.ambient,
            diffuse: m.diffuse,
            specular: m.specular,
            shininess: m.shininess,
        };
        match &self.objects {
            Some(o) => o.materials.iter().map(t).collect(),
            None => vec![t(&pipe.material)],
        }
    }

    /// The pipeline with its automatic settings resolved for this cloud and view.
    pub fn resolve(&self, pipe: &Pipeline, v: &ViewParams) -> Pipeline {
        let centre = self.centre_depth(v);
        let front = 0.5 * (self.depth_range(v).0 + centre);
        let mut p = pipe.resolved(v, self.spacing, centre, front);
        if let Some(s) = &mut p.splat {
            s.epsilon = Some(self.splat_epsilon(s));
            if matches!(s.mode, SplatMode::Deferred | SplatMode::Transparent) {
                // Transparent: the bucket sort's slices over the bounds' depths, ε thick
                // (layers farther apart never share a slice).
                s.depth_range = Some(self.depth_range(v));
            }
            if s.mode == SplatMode::Sorted {
                // The bucket sort's slices: over the bounds' depths, as thick as the smallest
                // splat (Gunjee §4.2's ε).
                s.depth_range = Some(self.depth_range(v));
                s.epsilon = Some(self.least_splat_radius() * s.scale);
            }
        }
        p
    }

    /// View depth of the centre of the cloud's bounds (of its bulk where a few points stray
    /// far from it: [`PointCloud::framing_bounds`]).
    fn centre_depth(&self, v: &ViewParams) -> f32 {
        let c = match self.cloud.framing_bounds() {
            (_, _, 0) => self.bounds().center(),
            (lo, hi, _) => ((lo + hi) * 0.5 - self.cloud.origin).as_vec3(),
        };
        (c - glam::Vec3::from(v.eye)).dot(glam::Vec3::from(v.forward))
    }

    /// The median point spacing in pixels at the centre of the cloud (NaN when the camera is
    /// inside the cloud's bounds centre plane).
    pub fn screen_spacing(&self, camera: &Camera) -> f32 {
        let v = ViewParams::new(camera, self.cloud.origin);
        let d = self.centre_depth(&v);
        if d > v.near {
            self.spacing / v.footprint(d)
        } else {
            f32::NAN
        }
    }

    /// The layer gap d̃ a pipeline uses for this cloud: its own, else derived from spacing.
    pub fn layer_gap(&self, pipe: &Pipeline) -> f32 {
        pipeline::layer_gap(pipe, self.spacing)
    }

    /// Splat radii, unscaled: the cloud's own (PLY `radius`, or from
    /// [`PreparedCloud::prepare_surface`]), else [`FALLBACK_RADIUS`] × the point spacing for
    /// every point; times each point's [`PreparedCloud::size`] factor.
    pub fn splat_radii(&self) -> std::borrow::Cow<'_, [f32]> {
        let fallback = FALLBACK_RADIUS * self.spacing.max(f32::MIN_POSITIVE);
        match (&self.cloud.radius, &self.size) {
            (Some(r), None) => std::borrow::Cow::Borrowed(r),
            (None, None) => std::borrow::Cow::Owned(vec![fallback; self.cloud.len()]),
            (r, Some(s)) => std::borrow::Cow::Owned(
                s.iter()
                    .enumerate()
                    .map(|(i, &f)| f * r.as_ref().map_or(fallback, |r| r[i]))
                    .collect(),
            ),
        }
    }

    /// Keeps the points whose flag is set (with their objects and size factors), prepared
    /// again; the shadow texture is dropped.
    pub fn retained(mut self, keep: &[bool]) -> Result<PreparedCloud, RenderError> {
        let mut cloud = std::mem::take(&mut self.cloud);
        cloud.retain(keep);
        if cloud.is_empty() {
            return Err(RenderError::EmptyCloud);
        }
        let mut p = PreparedCloud::new(cloud);
        p.size = self.size.take().map(|mut s| {
            stipple_core::lookup::retain(&mut s, keep);
            s
        });
        match self.objects.take() {
            Some(mut o) => {
                stipple_core::lookup::retain(&mut o.index, keep);
                p.with_objects(o)
            }
            None => Ok(p),
        }
    }

    /// Applies a lookup table (Gunjee §3; see [`stipple_core::lookup`]): colours (points
    /// without one from the table or the file take `base`'s colour), opacities, splat size
    /// factors and materials per key value, and leaves out hidden points. Materials
    /// override `base` (or each object's own in a scene): every object and material of the
    /// table that meet become an object of their own, at most [`MAX_OBJECTS`]. The shadow
    /// texture is dropped (make it after); the rest is prepared again.
    pub fn with_lookup(
        mut self,
        table: &stipple_core::lookup::LookupTable,
        base: &Material,
    ) -> Result<(PreparedCloud, stipple_core::lookup::Applied), RenderError> {
        let fallback = base.base_colour.map(srgb::linear_to_srgb8);
        let mut cloud = std::mem::take(&mut self.cloud);
        let mut size = self.size.take();
        let a = stipple_core::lookup::apply(&mut cloud, table, fallback, &mut size)?;
        let mut objects = self.objects.take();
        if let Some(o) = objects.as_mut() {
            if !a.kept.is_empty() {
                stipple_core::lookup::retain(&mut o.index, &a.kept);
            }
        }
        if !a.overrides.is_empty() {
            let (index, materials) = match objects {
                Some(o) => (o.index, o.materials),
                None => (vec![0; cloud.len()], vec![*base]),
            };
            // (object, slot) → new object.
            let mut pair = vec![u16::MAX; 256 * 256];
            let mut new_index = Vec::with_capacity(index.len());
            let mut new_materials: Vec<Material> = Vec::new();
            for (&o, &s) in index.iter().zip(&a.material_slot) {
                let at = o as usize * 256 + s as usize;
                let k = match pair[at] {
                    k if k != u16::MAX => k as usize,
                    _ => {
                        if new_materials.len() >= MAX_OBJECTS {
                            return Err(ObjectError::Count(new_materials.len() + 1).into());
                        }
                        let mut m = materials[o as usize];
                        if s > 0 {
                            let ov = a.overrides[s as usize - 1];
                            m.ambient = ov.ambient.unwrap_or(m.ambient);
                            m.diffuse = ov.diffuse.unwrap_or(m.diffuse);
                            m.specular = ov.specular.unwrap_or(m.specular);
                            m.shininess = ov.shininess.unwrap_or(m.shininess);
                        }
                        new_materials.push(m);
                        pair[at] = (new_materials.len() - 1) as u16;
                        new_materials.len() - 1
                    }
                };
                new_index.push(k as u8);
            }
            objects = Some(ObjectTable {
                index: new_index,
                materials: new_materials,
            });
        }
        let mut p = if a.kept.is_empty() {
            PreparedCloud::with_spacing(cloud, self.spacing)
        } else {
            PreparedCloud::new(cloud)
        };
        if a.kept.is_empty() {
            p.shapes = self.shapes.take();
        }
        p.size = size;
        let p = match objects {
            Some(o) => p.with_objects(o)?,
            None => p,
        };
        Ok((p, a))
    }

    /// The smallest positive splat radius, unscaled (the bucket sort's slice thickness,
    /// Gunjee §4.2's ε); +inf when no radius is positive.
    pub fn least_splat_radius(&self) -> f32 {
        self.splat_radii()
            .iter()
            .copied()
            .filter(|&r| r > 0.0)
            .fold(f32::INFINITY, f32::min)
    }

    /// The ε of the splat pass's ε-z test: the pipeline's own, else the median scaled radius.
    pub fn splat_epsilon(&self, s: &SplatSettings) -> f32 {
        s.epsilon.unwrap_or_else(|| {
            let r = self.splat_radii();
            let mut v: Vec<f32> = r.iter().step_by((r.len() / 4096).max(1)).copied().collect();
            let m = v.len() / 2;
            let median = if v.is_empty() {
                0.0
            } else {
                *v.select_nth_unstable_by(m, f32::total_cmp).1
            };
            passes::splat::epsilon(median * s.scale)
        })
    }

    /// Makes the cloud ready for lit and splat rendering: estimates normals where it has
    /// none (`estimate`), re-orients given normals whose signs are inconsistent, and
    /// computes splat radii where it has none (see `stipple_core::normals`). Does nothing
    /// that is already there; the GPU copy is refreshed on the next frame.
    pub fn prepare_surface(
        &mut self,
        k: usize,
        estimate: bool,
    ) -> Result<SurfaceReport, stipple_core::normals::NormalError> {
        self.prepare_surface_from(k, estimate, None)
    }

    /// [`PreparedCloud::prepare_surface`] with the sensor's position (world coordinates)
    /// when it is known: normals then face it (`stipple_core::normals::estimate_from`).
    pub fn prepare_surface_from(
        &mut self,
        k: usize,
        estimate: bool,
        viewpoint: Option<glam::DVec3>,
    ) -> Result<SurfaceReport, stipple_core::normals::NormalError> {
        self.prepare(k, estimate, viewpoint, true)
    }

    /// [`PreparedCloud::prepare_surface_from`] for normals and radii alone (`stipple
    /// normals` writes them out): no splat shapes are kept, so a render prepares them
    /// afresh (`stipple_core::normals::estimate_normals_from`).
    pub fn prepare_normals_from(
        &mut self,
        k: usize,
        viewpoint: Option<glam::DVec3>,
    ) -> Result<SurfaceReport, stipple_core::normals::NormalError> {
        self.prepare(k, true, viewpoint, false)
    }

    fn prepare(
        &mut self,
        k: usize,
        estimate: bool,
        viewpoint: Option<glam::DVec3>,
        shapes: bool,
    ) -> Result<SurfaceReport, stipple_core::normals::NormalError> {
        if let (Some((r, had_normals, k0, vp0)), true) = (&self.surface, shapes) {
            let c = &self.cloud;
            if c.normals.is_some() == *had_normals
                && (*k0, *vp0) == (k, viewpoint)
                && (*had_normals || !estimate)
                && c.radius.is_some()
            {
                // Done before (the Python package renders a cloud many times): the same
                // outcome, without the neighbour search.
                return Ok(SurfaceReport {
                    repeated: true,
                    seconds: 0.0,
                    ..r.clone()
                });
            }
        }
        let vp = viewpoint.map(|v| (v - self.cloud.origin).as_vec3());
        let c = &mut self.cloud;
        let need_normals = c.normals.is_none() && estimate;
        let mut report = SurfaceReport::default();
        if c.normals.is_none() && !need_normals && c.radius.is_some() {
            return Ok(report);
        }
        let t0 = std::time::Instant::now();
        let need_radii = c.radius.is_none();
        let e = match (&c.normals, c.normals_trusted) {
            (Some(given), true) => {
                stipple_core::normals::estimate_trusted(&c.positions, given, k, 1.0)?
            }
            _ => {
                // The sensor: the viewpoint given, else the directions the file gives per
                // point (airborne LiDAR), else not known.
                use stipple_core::normals::Towards;
                let towards = match (vp, c.sensor_dirs.as_deref()) {
                    (Some(v), _) => Towards::Point(v),
                    (None, Some(d)) => Towards::Each(d),
                    // A Z-up source (LiDAR) was seen from above.
                    (None, None) if c.z_up => Towards::Above,
                    (None, None) => Towards::Unknown,
                };
                report.oriented = match towards {
                    Towards::Point(_) => Oriented::Viewpoint,
                    Towards::Each(_) => Oriented::Aircraft,
                    Towards::Above => Oriented::FromAbove,
                    Towards::Unknown => Oriented::SpanningTree,
                };
                let estimate = if shapes {
                    stipple_core::normals::estimate_from
                } else {
                    stipple_core::normals::estimate_normals_from
                };
                // A depth camera's steps, smoothed across the steps (the points drawn
                // where the smoothing put them, at most a few steps along their rays).
                if let (Some(sensor), true) = (c.sensor, need_normals) {
                    let eye = (sensor.position - c.origin).as_vec3();
                    if let Some(d) = stipple_core::normals::quantised::dequantise(
                        &c.positions,
                        eye,
                        sensor.forward.as_vec3(),
                    )? {
                        c.positions = d.positions;
                        report.dequantised = Some((d.levels, d.steps));
                    }
                }
                estimate(&c.positions, c.normals.as_deref(), k, 1.0, towards)?
            }
        };
        if need_normals {
            c.normals = Some(e.normals);
            report.estimated = true;
        } else if c.normals.is_some() && e.flipped > 0 {
            c.normals = Some(e.normals);
            report.reoriented = e.flipped;
        }
        report.inconsistency = e.inconsistency;
        if need_radii {
            c.radius = Some(e.radii);
            report.radii = true;
        } else if let Some(r) = c.radius.as_mut() {
            // Radii from the file: a splat whose clip planes leave a third face out (a box's
            // corner) is held within it all the same.
            stipple_core::normals::scale_radii(r, &e.radius_factors);
        }
        report.seconds = t0.elapsed().as_secs_f64();
        self.key = next_key();
        if !shapes {
            self.shapes = None;
            self.surface = None;
            return Ok(report);
        }
        if c.normals.is_some() {
            self.shapes = Some(e.shapes);
        }
        self.surface = Some((report.clone(), self.cloud.normals.is_some(), k, viewpoint));
        Ok(report)
    }
}

impl PreparedCloud {
    /// The splat groups of deferred blending for overlap relaxation `c` (Zhang & Pajarola
    /// §4.1; `stipple_core::grouping`), computed on first use and kept until the cloud or
    /// c changes. A cloud too small to group gets one group.
    pub fn groups(&self, c: f32) -> std::sync::Arc<stipple_core::grouping::Grouping> {
        let mut g = self.groups.lock().unwrap_or_else(|e| e.into_inner());
        if let Some((k, cb, gr)) = g.as_ref() {
            if *k == self.key && *cb == c.to_bits() {
                return gr.clone();
            }
        }
        let radii = self.splat_radii();
        let normals = self.cloud.normals.as_deref();
        let gr = std::sync::Arc::new(
            stipple_core::grouping::grouping(&self.cloud.positions, normals, &radii, c)
                .unwrap_or_else(|_| stipple_core::grouping::Grouping {
                    group: vec![0; self.cloud.len()],
                    groups: 1,
                    max_degree: 0,
                    mean_degree: 0.0,
                    conflicts: 0,
                    c,
                }),
        );
        *g = Some((self.key, c.to_bits(), gr.clone()));
        gr
    }

    /// The groups transparent splats are drawn in (Zhang & Pajarola §4.2.2): with
    /// [`CoverageMethod::Duplicate`] the groups for relaxation `c`, each completed with
    /// duplicates until it covers the surface (`stipple_core::grouping::coverage_masks`);
    /// with [`CoverageMethod::Enlarge`] four balanced groups of enlarged splats
    /// (`stipple_core::grouping::coverage_by_radii`, c not used); computed on first use and
    /// kept until the cloud, c or the method changes.
    pub fn coverage(&self, c: f32, method: crate::CoverageMethod) -> std::sync::Arc<Coverage> {
        let mut g = self.coverage.lock().unwrap_or_else(|e| e.into_inner());
        let tag = (c.to_bits(), method);
        if let Some((k, t, cov)) = g.as_ref() {
            if *k == self.key && *t == tag {
                return cov.clone();
            }
        }
        let radii = self.splat_radii();
        let n = self.cloud.len();
        let cov = match method {
            crate::CoverageMethod::Duplicate => {
                let groups = self.groups(c);
                let (masks, duplicates) =
                    stipple_core::grouping::coverage_masks(&self.cloud.positions, &radii, &groups)
                        .unwrap_or_else(|_| (vec![1; n], 0));
                Coverage {
                    masks,
                    groups: groups
                        .groups
                        .clamp(1, stipple_core::grouping::TRANSPARENT_GROUPS),
                    duplicates,
                    enlarged: None,
                }
            }
            crate::CoverageMethod::Enlarge => {
                let (mut masks, duplicates, factor) =
                    stipple_core::grouping::coverage_by_radii(&self.cloud.positions, &radii)
                        .unwrap_or_else(|_| (vec![1; n], 0, vec![1.0; n]));
                let (mut most, mut sum) = (1.0f32, 0.0f64);
                for (m, f) in masks.iter_mut().zip(&factor) {
                    let q = Coverage::quantise(*f);
                    *m |= q << 16;
                    let f = Coverage::factor(*m);
                    most = most.max(f);
                    sum += f as f64;
                }
                Coverage {
                    masks,
                    groups: if n < 3 {
                        1
                    } else {
                        stipple_core::grouping::TRANSPARENT_GROUPS
                    },
                    duplicates,
                    enlarged: Some((most, (sum / n.max(1) as f64) as f32)),
                }
            }
        };
        let cov = std::sync::Arc::new(cov);
        *g = Some((self.key, tag, cov.clone()));
        cov
    }

    /// The cloud's bounds (local coordinates), cached per [`PreparedCloud::key`]: code that
    /// moves points must give the cloud a new key, as the GPU copy needs anyway.
    pub fn bounds(&self) -> stipple_core::Bounds {
        let mut b = self.bounds.lock().unwrap_or_else(|e| e.into_inner());
        match *b {
            Some((key, bounds)) if key == self.key => bounds,
            _ => {
                let bounds = self.cloud.bounds();
                *b = Some((self.key, bounds));
                bounds
            }
        }
    }

    /// The view-depth range [min, max] of the cloud's bounds (min at least the near plane).
    pub fn depth_range(&self, v: &ViewParams) -> (f32, f32) {
        let b = self.bounds();
        let (eye, fwd) = (glam::Vec3::from(v.eye), glam::Vec3::from(v.forward));
        let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
        for i in 0..8 {
            let c = glam::Vec3::new(
                if i & 1 == 0 { b.min.x } else { b.max.x },
                if i & 2 == 0 { b.min.y } else { b.max.y },
                if i & 4 == 0 { b.min.z } else { b.max.z },
            );
            let d = (c - eye).dot(fwd);
            lo = lo.min(d);
            hi = hi.max(d);
        }
        (lo.max(v.near), hi.max(lo.max(v.near)))
    }
}

/// Splat radius in point spacings for clouds without radii (about what
/// `stipple_core::normals` gives a regular sampling).
pub const FALLBACK_RADIUS: f32 = 2.0;

/// What [`PreparedCloud::prepare_surface`] did.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SurfaceReport {
    /// Normals were estimated (the cloud had none).
    pub estimated: bool,
    /// Given normals turned round (their signs were inconsistent).
    pub reoriented: usize,
    /// The given normals' share of inconsistent neighbour pairs.
    pub inconsistency: f32,
    /// Splat radii were computed.
    pub radii: bool,
    pub seconds: f64,
    /// Nothing was done: this repeats the report of an earlier call on the same cloud.
    pub repeated: bool,
    /// How the normals' signs were chosen.
    pub oriented: Oriented,
    /// The depths were quantised in steps wider than the points' spacing (a depth
    /// camera's) and were smoothed across the steps before estimating: how many distinct
    /// depths there were, and the smallest and largest step
    /// (`stipple_core::normals::quantised`).
    pub dequantised: Option<(usize, (f32, f32))>,
}

impl SurfaceReport {
    /// A line for the user where the depths were a depth camera's steps and were smoothed.
    pub fn dequantised_note(&self) -> Option<String> {
        let (levels, (lo, hi)) = self.dequantised?;
        Some(format!(
            "the depths take {levels} values, in steps of {lo:.3} to {hi:.3} along the \
             sensor's axis (a depth camera's): points moved onto a surface fitted across the \
             steps (at most {} steps along their rays) before estimating normals",
            stipple_core::normals::quantised::MAX_MOVE
        ))
    }
}

/// How [`PreparedCloud::prepare_surface_from`] chose the normals' signs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Oriented {
    /// Propagated over a spanning tree of the neighbour graph.
    #[default]
    SpanningTree,
    /// The spanning tree's, each component turned by its horizontal surfaces (Z-up).
    FromAbove,
    /// Facing the sensor's position (a viewpoint given, or the file's).
    Viewpoint,
    /// Facing the aircraft, in the direction the file gives for each point
    /// (`PointCloud::sensor_dirs`: airborne LiDAR).
    Aircraft,
}

impl Oriented {
    /// For messages: "estimated normals … (oriented {this})".
    pub fn describe(self) -> &'static str {
        match self {
            Oriented::SpanningTree => "by a spanning tree",
            Oriented::FromAbove => "by a spanning tree, each part turned to face up",
            Oriented::Viewpoint => "towards the sensor's position",
            Oriented::Aircraft => "towards the aircraft, from GPS times and scan angles",
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The cached bounds are the cloud's, and a new key (what moving points requires, for
    /// the GPU copy too) recomputes them.
    #[test]
    fn cached_bounds_follow_the_key() {
        let positions: Vec<glam::Vec3> = (0..1000)
            .map(|i| glam::Vec3::new(i as f32 * 0.01, (i % 7) as f32, -((i % 13) as f32)))
            .collect();
        let mut p = PreparedCloud::with_spacing(PointCloud::from_positions(positions), 0.01);
        let b = p.bounds();
        assert_eq!(b, p.cloud.bounds());
        p.cloud.positions[3] = glam::Vec3::splat(100.0);
        assert_eq!(p.bounds(), b, "same key: the cached bounds");
        p.key = next_key();
        let moved = p.bounds();
        assert_eq!(moved, p.cloud.bounds());
        assert_eq!(moved.max, glam::Vec3::splat(100.0));
    }

    /// A second preparation with nothing new to do repeats the first's report (a cloud
    /// rendered twice draws the same frame); a new k, or forgetting, does the work again.
    #[test]
    fn a_repeated_preparation_repeats_its_report() {
        let positions: Vec<glam::Vec3> = (0..2000)
            .map(|i| {
                let (a, b) = (i as f32 * 0.1, i as f32 * 0.37);
                glam::Vec3::new(a.cos() * b.sin(), a.sin() * b.sin(), b.cos())
            })
            .collect();
        let mut p = PreparedCloud::new(PointCloud::from_positions(positions));
        let first = p.prepare_surface(16, true).unwrap();
        assert!(first.estimated && !first.repeated);
        let normals = p.cloud.normals.clone();
        let second = p.prepare_surface(16, true).unwrap();
        assert!(second.repeated && second.estimated, "{second:?}");
        assert_eq!(p.cloud.normals, normals);
        let copy = p.duplicate();
        assert_ne!(copy.key, p.key);
        assert!(p.prepare_surface(12, true).is_ok_and(|r| !r.repeated));
        p.forget_surface();
        assert!(p.prepare_surface(12, true).is_ok_and(|r| !r.repeated));
    }

    /// Trusted normals (a volume's gradient) are kept as they are, even where a consistency
    /// check would turn them round.
    #[test]
    fn trusted_normals_are_not_turned_round() {
        let positions: Vec<glam::Vec3> = (0..3000)
            .map(|i| {
                let (a, b) = (i as f32 * 0.1, i as f32 * 0.37);
                glam::Vec3::new(a.cos() * b.sin(), a.sin() * b.sin(), b.cos())
            })
            .collect();
        // Every normal inward: consistent, but against the outward seed of the check.
        let inward: Vec<glam::Vec3> = positions.iter().map(|p| -p.normalize()).collect();
        let cloud = PointCloud {
            normals: Some(inward.clone()),
            ..PointCloud::from_positions(positions)
        };
        let mut checked = PreparedCloud::new(cloud.clone());
        let r = checked.prepare_surface(16, true).unwrap();
        assert!(r.reoriented > 1000, "{r:?}");
        let mut trusted = PreparedCloud::new(PointCloud {
            normals_trusted: true,
            ..cloud
        });
        let r = trusted.prepare_surface(16, true).unwrap();
        assert_eq!(r.reoriented, 0);
        let kept = trusted.cloud.normals.as_ref().unwrap();
        assert!(kept
            .iter()
            .zip(&inward)
            .all(|(a, b)| (*a - *b).length() < 1e-5));
        assert!(trusted.cloud.radius.is_some() && trusted.shapes.is_some());
    }

    /// Radii a file gives (`stipple normals` writes the k-th neighbour's) are held within
    /// the same caps as estimated ones: a box's corner point whose normal is the three
    /// faces' mean keeps a small splat either way (and they grow over the sample's holes
    /// as estimated ones do).
    #[test]
    fn radii_from_a_file_keep_the_corner_caps() {
        let mut r = stipple_core::rng::Rng::new(3);
        let (mut pts, mut nrm) = (Vec::new(), Vec::new());
        for _ in 0..3000 {
            let axis = (r.f32() * 3.0) as usize % 3;
            let s = if r.f32() < 0.5 { 1.0 } else { -1.0 };
            let mut p = glam::Vec3::new(r.f32(), r.f32(), r.f32()) * 1.6 - 0.8;
            p[axis] = 0.8 * s;
            let mut n = glam::Vec3::ZERO;
            n[axis] = s;
            pts.push(p);
            nrm.push(n);
        }
        let corner = pts.len();
        pts.push(glam::Vec3::splat(0.8 - 0.004));
        nrm.push(glam::Vec3::ONE.normalize());
        let cloud = PointCloud {
            normals: Some(nrm),
            ..PointCloud::from_positions(pts)
        };
        let mut estimated = PreparedCloud::new(cloud.clone());
        estimated.prepare_surface(16, true).unwrap();
        let capped = estimated.cloud.radius.as_ref().unwrap()[corner];
        let full = stipple_core::normals::splat_radii(
            &stipple_core::normals::neighbours(&cloud.positions, 16).unwrap(),
            1.0,
        );
        assert!(capped < 0.5 * full[corner], "{capped} {}", full[corner]);
        let mut given = PreparedCloud::new(PointCloud {
            radius: Some(full.clone()),
            ..cloud
        });
        given.prepare_surface(16, true).unwrap();
        let kept = given.cloud.radius.as_ref().unwrap();
        assert_eq!(kept[corner], capped);
        // Shrunk only at the caps; grown (at most HOLE_GROW) next to the sample's holes.
        let shrunk = kept.iter().zip(&full).filter(|(a, b)| a < b).count();
        assert!(shrunk < 100, "{shrunk} radii shrunk");
        let grow = stipple_core::normals::HOLE_GROW * 1.0001;
        assert!(kept.iter().zip(&full).all(|(a, b)| *a <= grow * b));
    }
}

/// The groups transparent splats are drawn in ([`PreparedCloud::coverage`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Coverage {
    /// Per point, the groups it is drawn in (bit k: group k; bits 0–7) and the factor its
    /// splat is enlarged by in 1/256 (bits 16–31; 0: not enlarged), see
    /// [`Coverage::factor`].
    pub masks: Vec<u32>,
    /// The number of groups K.
    pub groups: usize,
    /// Memberships beyond each point's own group.
    pub duplicates: usize,
    /// With enlarged radii: the largest factor and the mean.
    pub enlarged: Option<(f32, f32)>,
}

impl Coverage {
    /// The groups of a mask (bit k: group k).
    #[inline]
    pub fn groups_of(mask: u32) -> u32 {
        mask & 0xff
    }

    /// The factor a mask's splat is enlarged by (as the WGSL twin decodes it).
    #[inline]
    pub fn factor(mask: u32) -> f32 {
        match mask >> 16 {
            0 => 1.0,
            q => q as f32 / 256.0,
        }
    }

    /// A factor in 1/256, as a mask's upper 16 bits hold it.
    pub fn quantise(f: f32) -> u32 {
        ((f * 256.0).round() as u32).clamp(256, 0xffff)
    }
}
