//! splat on the CPU (twin of `gpu.rs` / `splat.wgsl`): splats are binned into 32×32-pixel
//! tiles (a counting sort; each tile's list is sorted by point index, so results do not
//! depend on thread timing), and each tile runs the visibility and selection loops of the
//! module docs over its own list on one thread.

use super::{footprint, weight, Disc, Raster, SplatMode};
use crate::gbuffer::{is_point, GBuffer, BACKGROUND};
use crate::params::ViewParams;
use crate::passes::shade::cpu::{intensity_grey, linear_to_srgb8, srgb_to_linear_table, Albedo};
use glam::Vec3;
use rayon::prelude::*;
use std::sync::atomic::{AtomicU32, Ordering};

const TILE: u32 = 32;

/// The splats of a cloud.
pub struct SplatInput<'a> {
    pub positions: &'a [Vec3],
    pub normals: Option<&'a [Vec3]>,
    /// Radius per point, unscaled.
    pub radii: &'a [f32],
    /// Multiplies every radius.
    pub scale: f32,
    /// Shape per point (quadric splats; used only with normals).
    pub shapes: Option<&'a [super::SplatShape]>,
    /// Deferred blending: the group of every point and the number of groups.
    pub groups: Option<(&'a [u8], usize)>,
    /// Deferred blending: the low-precision depth of Eq. 6.
    pub quant: Option<super::DepthQuant>,
    /// ε of the ε-z test.
    pub epsilon: f32,
}

/// Per-pixel surface the splat pass leaves: unit normal facing the eye and linear albedo
/// (blending: the blended ones; Voronoi: the winning splat's, its normal where the pixel's
/// ray meets it).
#[derive(Clone, Debug, Default)]
pub struct Blended {
    pub normal: Vec<Vec3>,
    pub albedo: Vec<[f32; 3]>,
}

/// The blend of one pixel (Eq. 1): weighted sums, and the fragment of largest weight (ties:
/// the smaller point index).
#[derive(Clone, Default)]
struct Acc {
    w: f32,
    d: f32,
    n: Vec3,
    c: [f32; 3],
    top: f32,
    top_id: u32,
}

impl Acc {
    #[inline(always)]
    fn add(&mut self, fr: super::Frag, dsc: &Disc, sid: usize, dir: Vec3, albedo: [f32; 3]) {
        let wt = weight(fr.q);
        let nrm = dsc.normal_facing(&fr, dir);
        self.w += wt;
        self.d += wt * fr.depth;
        self.n += wt * nrm;
        for (a, c) in self.c.iter_mut().zip(albedo) {
            *a += wt * c;
        }
        if wt > self.top || (wt == self.top && (sid as u32) < self.top_id) {
            self.top = wt;
            self.top_id = sid as u32;
        }
    }
}

struct TileOut {
    depth: Vec<f32>,
    id: Vec<u32>,
    normal: Vec<Vec3>,
    albedo: Vec<[f32; 3]>,
}

/// The splats of a frame as discs (`splat`'s footprint pass reads them).
struct Splats<'a> {
    v: &'a ViewParams,
    s: &'a SplatInput<'a>,
}

/// What every tile of a frame reads: the splats, their footprints and the tiles' lists
/// (`splat`'s counting sort).
struct Tiles<'a> {
    splats: &'a Splats<'a>,
    mode: SplatMode,
    albedo: Option<(Albedo<'a>, &'a [f32; 256])>,
    srgb_lut: &'a [f32; 256],
    feet: &'a [Option<[u32; 4]>],
    list: &'a [AtomicU32],
    start: &'a [usize],
    tw: u32,
}

impl Splats<'_> {
    /// Splat `i` as a disc.
    #[inline(always)]
    fn disc(&self, i: usize) -> Disc {
        let s = self.s;
        Disc::new(
            self.v,
            s.positions[i],
            s.normals.map(|n| n[i]),
            s.radii[i] * s.scale,
            s.shapes.map(|k| k[i]),
        )
    }

    /// The footprints of splats `first..first + out.len()` into `out`.
    #[inline(always)]
    fn footprints(&self, first: usize, out: &mut [Option<[u32; 4]>]) {
        for (k, f) in out.iter_mut().enumerate() {
            *f = footprint(self.v, &self.disc(first + k));
        }
    }

    /// [`Splats::footprints`] compiled for AVX2 (as [`Tiles::tile_avx2`] is).
    ///
    /// # Safety
    /// The processor must have AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn footprints_avx2(&self, first: usize, out: &mut [Option<[u32; 4]>]) {
        self.footprints(first, out)
    }
}

impl Tiles<'_> {
    /// Point `id`'s linear albedo.
    #[inline]
    fn albedo_of(&self, id: usize) -> [f32; 3] {
        match self.albedo {
            Some((Albedo::Colours(c), lut)) => c[id].map(|x| lut[x as usize]),
            Some((Albedo::Intensity(t, sc), lut)) => [lut[intensity_grey(t[id], sc) as usize]; 3],
            Some((Albedo::Constant(c), _)) => c,
            None => [1.0; 3],
        }
    }

    /// [`Tiles::tile`] compiled for AVX2: the rasterizer's lanes ([`Raster::eval_rect`]) and
    /// the blending loops become 8-wide vector instructions. Without FMA, so that every
    /// operation rounds as in [`Tiles::tile`]: the same image to the bit.
    ///
    /// # Safety
    /// The processor must have AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn tile_avx2(&self, frags: &mut Vec<(u32, u32, super::Frag)>, t: usize) -> TileOut {
        self.tile(frags, t)
    }

    /// Tile `t`: its splats' fragments into `frags` (reused from the thread's previous
    /// tile: no growth by doubling per tile), then visibility and blending or selection.
    #[inline(always)]
    fn tile(&self, frags: &mut Vec<(u32, u32, super::Frag)>, t: usize) -> TileOut {
        let Tiles {
            splats,
            mode,
            srgb_lut,
            feet,
            list,
            start,
            tw,
            ..
        } = *self;
        let Splats { v, s } = *splats;
        let (w, h) = (v.width, v.height);
        let disc = |i: usize| splats.disc(i);
        let lut_albedo = |id: usize| self.albedo_of(id);
        let mut ids: Vec<u32> = list[start[t]..start[t + 1]]
            .iter()
            .map(|a| a.load(Ordering::Relaxed))
            .collect();
        ids.sort_unstable();
        let (tx, ty) = (t as u32 % tw, t as u32 / tw);
        let (px0, py0) = (tx * TILE, ty * TILE);
        let (px1, py1) = ((px0 + TILE).min(w) - 1, (py0 + TILE).min(h) - 1);
        let tile_w = (px1 - px0 + 1) as usize;
        let m = tile_w * (py1 - py0 + 1) as usize;
        // Every fragment in the tile, computed once: (local pixel, splat in `discs`,
        // fragment), in splat index order.
        // (A loop, not `collect`: `collect` is a function of its own, which would not be
        // compiled for AVX2 with `tile_avx2`.)
        let mut discs: Vec<Disc> = Vec::with_capacity(ids.len());
        for &sid in &ids {
            discs.push(disc(sid as usize));
        }
        frags.clear();
        for (li, &sid) in ids.iter().enumerate() {
            let fp = feet[sid as usize].expect("listed splats have footprints");
            let r = Raster::new(v, &discs[li]);
            let rect = [
                fp[0].max(px0),
                fp[1].max(py0),
                fp[2].min(px1),
                fp[3].min(py1),
            ];
            r.eval_rect(rect, |x, y, fr| {
                let k = (y - py0) as usize * tile_w + (x - px0) as usize;
                frags.push((k as u32, li as u32, fr));
            });
        }
        // The pixels' ray directions, computed once per pixel rather than per fragment.
        let mut dirs = Vec::with_capacity(m);
        for k in 0..m {
            let (x, y) = ((k % tile_w) as u32 + px0, (k / tile_w) as u32 + py0);
            dirs.push(v.pixel_ray(x, y).1);
        }
        let mut out = TileOut {
            depth: vec![f32::INFINITY; m],
            id: vec![BACKGROUND; m],
            normal: Vec::new(),
            albedo: Vec::new(),
        };
        let mut acc = vec![Acc::default(); if mode == SplatMode::Voronoi { 0 } else { m }];
        if let SplatMode::Deferred = mode {
            // §3.2 geometry pass: one pass over the splats, each into its group's image
            // with a plain depth test on the key of Eq. 10 (low-precision depth, then
            // the Voronoi distance): per group and pixel the nearest layer's splat
            // nearest its centre.
            let (groups, k_groups) = s.groups.expect("deferred blending needs groups");
            let q = s
                .quant
                .expect("deferred blending needs the depth quantisation");
            let mut gkey = vec![u32::MAX; m * k_groups];
            // The winning fragment (its place in `frags`) per group and pixel.
            let mut win = vec![u32::MAX; m * k_groups];
            for (fi, &(k, li, fr)) in frags.iter().enumerate() {
                let at = groups[ids[li as usize] as usize] as usize * m + k as usize;
                let key = q.key(fr.depth, fr.q, fr.front);
                if key < gkey[at] {
                    gkey[at] = key;
                    win[at] = fi as u32;
                }
            }
            // Compositing (Fig. 5): the nearest depth over the groups, then the blend of
            // the groups within ε of it.
            for k in 0..m {
                let dir = dirs[k];
                let winners = (0..k_groups)
                    .map(|g| win[g * m + k])
                    .filter(|&fi| fi != u32::MAX)
                    .map(|fi| frags[fi as usize]);
                let (za, zf) = winners
                    .clone()
                    .fold((f32::INFINITY, f32::INFINITY), |(a, f), w| {
                        let zf = if w.2.front { f.min(w.2.depth) } else { f };
                        (a.min(w.2.depth), zf)
                    });
                let (z, front_only) = super::reference(za, zf, s.epsilon);
                for (_, li, fr) in winners {
                    if fr.depth <= z + s.epsilon && (fr.front || !front_only) {
                        let sid = ids[li as usize] as usize;
                        acc[k].add(fr, &discs[li as usize], sid, dir, lut_albedo(sid));
                    }
                }
            }
        } else {
            let mut zall = vec![f32::INFINITY; m];
            let mut zfront = vec![f32::INFINITY; m];
            for &(k, _, fr) in frags.iter() {
                let k = k as usize;
                zall[k] = zall[k].min(fr.depth);
                if fr.front {
                    zfront[k] = zfront[k].min(fr.depth);
                }
            }
            let refs: Vec<(f32, bool)> = (0..m)
                .map(|k| super::reference(zall[k], zfront[k], s.epsilon))
                .collect();
            let counts = |k: usize, fr: &super::Frag| {
                let (z, front_only) = refs[k];
                fr.depth <= z + s.epsilon && (fr.front || !front_only)
            };
            if mode == SplatMode::Voronoi {
                // Per pixel the counting fragment of smallest (d/r)² (ties: the first,
                // of the smaller point index), in `frags`.
                let mut best = vec![f32::INFINITY; m];
                let mut win = vec![u32::MAX; m];
                for (fi, &(k, _, fr)) in frags.iter().enumerate() {
                    let k = k as usize;
                    if counts(k, &fr) && fr.q < best[k] {
                        best[k] = fr.q;
                        win[k] = fi as u32;
                    }
                }
                // The winner's depth and point, and its bent splat's normal at the hit
                // (turned to the eye) and albedo: the pixel is shaded as the surface
                // there, not as the point's flat disc.
                out.normal = vec![Vec3::ZERO; m];
                out.albedo = vec![[0.0; 3]; m];
                for (k, &fi) in win.iter().enumerate() {
                    if fi == u32::MAX {
                        continue;
                    }
                    let (_, li, fr) = frags[fi as usize];
                    let sid = ids[li as usize] as usize;
                    out.depth[k] = fr.depth;
                    out.id[k] = sid as u32;
                    out.normal[k] = discs[li as usize].normal_facing(&fr, dirs[k]);
                    out.albedo[k] = lut_albedo(sid).map(|c| srgb_lut[linear_to_srgb8(c) as usize]);
                }
                return out;
            }
            for &(k, li, fr) in frags.iter() {
                let k = k as usize;
                if counts(k, &fr) {
                    let sid = ids[li as usize] as usize;
                    acc[k].add(fr, &discs[li as usize], sid, dirs[k], lut_albedo(sid));
                }
            }
        }
        out.normal = vec![Vec3::ZERO; m];
        out.albedo = vec![[0.0; 3]; m];
        for (k, a) in acc.iter().enumerate() {
            if a.w > 0.0 {
                out.depth[k] = a.d / a.w;
                out.id[k] = a.top_id;
                out.normal[k] = a.n.normalize_or_zero();
                // Stored as 8-bit sRGB, as every albedo is (the GPU twin does the same).
                out.albedo[k] = a.c.map(|c| srgb_lut[linear_to_srgb8(c / a.w) as usize]);
            }
        }
        out
    }
}

/// Rasterizes the splats into `g` (depth and point id per pixel). `blended` receives the
/// per-pixel normal and albedo ([`Blended`]; `albedo` gives a point's linear albedo).
/// Returns the splats with a footprint on screen.
pub fn splat(
    v: &ViewParams,
    s: &SplatInput,
    mode: SplatMode,
    albedo: Option<(Albedo, &[f32; 256])>,
    g: &mut GBuffer,
    blended: Option<&mut Blended>,
) -> u64 {
    splat_with(v, s, mode, albedo, g, blended, true)
}

/// [`splat`], with vector instructions (AVX2) where `vector` and the processor has them, else
/// with the instructions every processor of the target has: the same image either way.
fn splat_with(
    v: &ViewParams,
    s: &SplatInput,
    mode: SplatMode,
    albedo: Option<(Albedo, &[f32; 256])>,
    g: &mut GBuffer,
    blended: Option<&mut Blended>,
    vector: bool,
) -> u64 {
    let (w, h) = (v.width, v.height);
    let (tw, th) = (w.div_ceil(TILE), h.div_ceil(TILE));
    let n = s.positions.len();
    #[cfg(target_arch = "x86_64")]
    let avx2 = vector && std::arch::is_x86_feature_detected!("avx2");
    #[cfg(not(target_arch = "x86_64"))]
    let _ = vector;
    let splats = Splats { v, s };
    const CHUNK: usize = 4096;
    let mut feet = vec![None; n];
    feet.par_chunks_mut(CHUNK).enumerate().for_each(|(c, out)| {
        #[cfg(target_arch = "x86_64")]
        if avx2 {
            // SAFETY: the processor has AVX2 (detected above).
            return unsafe { splats.footprints_avx2(c * CHUNK, out) };
        }
        splats.footprints(c * CHUNK, out)
    });
    let drawn = feet.par_iter().filter(|f| f.is_some()).count() as u64;
    // Counting sort of (tile, splat).
    let counts: Vec<AtomicU32> = (0..tw * th).map(|_| AtomicU32::new(0)).collect();
    let tiles_of = |f: &[u32; 4]| {
        let (x0, x1) = (f[0] / TILE, f[2] / TILE);
        let (y0, y1) = (f[1] / TILE, f[3] / TILE);
        (y0..=y1).flat_map(move |y| (x0..=x1).map(move |x| (y * tw + x) as usize))
    };
    feet.par_iter().flatten().for_each(|f| {
        for t in tiles_of(f) {
            counts[t].fetch_add(1, Ordering::Relaxed);
        }
    });
    let mut start = vec![0usize; (tw * th) as usize + 1];
    for t in 0..(tw * th) as usize {
        start[t + 1] = start[t] + counts[t].load(Ordering::Relaxed) as usize;
    }
    let cursor: Vec<AtomicU32> = start[..start.len() - 1]
        .iter()
        .map(|&s| AtomicU32::new(s as u32))
        .collect();
    let list: Vec<AtomicU32> = (0..start[start.len() - 1])
        .map(|_| AtomicU32::new(0))
        .collect();
    feet.par_iter().enumerate().for_each(|(i, f)| {
        if let Some(f) = f {
            for t in tiles_of(f) {
                let at = cursor[t].fetch_add(1, Ordering::Relaxed);
                list[at as usize].store(i as u32, Ordering::Relaxed);
            }
        }
    });
    let srgb_lut = srgb_to_linear_table();
    let tiles = Tiles {
        splats: &splats,
        mode,
        albedo,
        srgb_lut: &srgb_lut,
        feet: &feet,
        list: &list,
        start: &start,
        tw,
    };
    let outs: Vec<TileOut> = (0..(tw * th) as usize)
        .into_par_iter()
        .map_init(Vec::new, |frags, t| {
            #[cfg(target_arch = "x86_64")]
            if avx2 {
                // SAFETY: the processor has AVX2 (detected above).
                return unsafe { tiles.tile_avx2(frags, t) };
            }
            tiles.tile(frags, t)
        })
        .collect();
    let npx = (w * h) as usize;
    let mut blended = blended;
    if let Some(b) = blended.as_deref_mut() {
        b.normal.clear();
        b.normal.resize(npx, Vec3::ZERO);
        b.albedo.clear();
        b.albedo.resize(npx, [0.0; 3]);
    }
    // The tiles' outputs into the frame, a band of tile rows per task.
    let band = (TILE * w) as usize;
    let tiles = |ty: usize| &outs[ty * tw as usize..][..tw as usize];
    let (depth, id) = (g.depth.par_chunks_mut(band), g.id.par_chunks_mut(band));
    match blended.as_deref_mut() {
        Some(b) => depth
            .zip(id)
            .zip(b.normal.par_chunks_mut(band))
            .zip(b.albedo.par_chunks_mut(band))
            .enumerate()
            .for_each(|(ty, (((d, i), nr), al))| {
                band_rows(tiles(ty), w as usize, |o, dst, src, n| {
                    d[dst..dst + n].copy_from_slice(&o.depth[src..src + n]);
                    i[dst..dst + n].copy_from_slice(&o.id[src..src + n]);
                    nr[dst..dst + n].copy_from_slice(&o.normal[src..src + n]);
                    al[dst..dst + n].copy_from_slice(&o.albedo[src..src + n]);
                })
            }),
        None => depth.zip(id).enumerate().for_each(|(ty, (d, i))| {
            band_rows(tiles(ty), w as usize, |o, dst, src, n| {
                d[dst..dst + n].copy_from_slice(&o.depth[src..src + n]);
                i[dst..dst + n].copy_from_slice(&o.id[src..src + n]);
            })
        }),
    }
    fill_pinholes(w as usize, h as usize, g, blended, s.epsilon);
    drawn
}

/// The surface a pinhole at pixel `k` (image `w` wide; `covered` says which pixels the
/// splats cover) takes: of its four neighbours (above, left, right, below) the covered ones
/// within `epsilon` of the nearest covered depth, in that order, the nearest first (ties:
/// the first); None unless two opposite neighbours are covered and within `epsilon` of each
/// other (the pixel lies on one surface, in a crack one pixel wide). As splat.wgsl
/// `pinhole_group`.
pub fn pinhole_group(
    depth: &[f32],
    covered: impl Fn(usize) -> bool,
    k: usize,
    w: usize,
    epsilon: f32,
) -> Option<([usize; 4], usize)> {
    let nb = [k - w, k - 1, k + 1, k + w];
    let on = nb.map(&covered);
    let across =
        |a: usize, b: usize| on[a] && on[b] && (depth[nb[a]] - depth[nb[b]]).abs() <= epsilon;
    if !(across(0, 3) || across(1, 2)) {
        return None;
    }
    let mut near = usize::MAX;
    for a in 0..4 {
        if on[a] && (near == usize::MAX || depth[nb[a]] < depth[nb[near]]) {
            near = a;
        }
    }
    let mut group = [nb[near]; 4];
    let mut count = 1;
    for a in 0..4 {
        if a != near && on[a] && depth[nb[a]] <= depth[nb[near]] + epsilon {
            group[count] = nb[a];
            count += 1;
        }
    }
    Some((group, count))
}

/// Pinholes: a background pixel in a crack one pixel wide of a surface the splats cover
/// ([`pinhole_group`]) takes the nearer surface among its neighbours: their mean depth and,
/// with `blended`, their mean normal; the nearest one's point and albedo (a Voronoi cell's
/// colour stays its point's). Two splats cut at
/// clip planes that meet along a line leave the pixels on it to neither (the default render
/// of the Stanford Armadillo had 78 such pixels). Wider gaps, and cracks between surfaces
/// more than `epsilon` apart in depth, stay. Every pixel is judged by what the splats drew,
/// so the order does not matter. As splat.wgsl `splat_pinholes`. Returns the pixels filled.
pub fn fill_pinholes(
    w: usize,
    h: usize,
    g: &mut GBuffer,
    mut blended: Option<&mut Blended>,
    epsilon: f32,
) -> usize {
    if w < 3 || h < 3 {
        return 0;
    }
    let fills: Vec<(usize, [usize; 4], usize)> = (1..h - 1)
        .into_par_iter()
        .flat_map_iter(|y| {
            let (id, depth) = (&g.id, &g.depth);
            let covered = move |j: usize| is_point(id[j]);
            (1..w - 1).filter_map(move |x| {
                let k = y * w + x;
                if id[k] != BACKGROUND {
                    return None;
                }
                pinhole_group(depth, covered, k, w, epsilon).map(|(gr, n)| (k, gr, n))
            })
        })
        .collect();
    for &(k, group, count) in &fills {
        let group = &group[..count];
        let depth = group.iter().map(|&j| g.depth[j]).sum::<f32>() / count as f32;
        g.depth[k] = depth;
        g.id[k] = g.id[group[0]];
        if let Some(b) = blended.as_deref_mut() {
            let n: Vec3 = group.iter().map(|&j| b.normal[j]).sum();
            b.normal[k] = n.try_normalize().unwrap_or(b.normal[group[0]]);
            b.albedo[k] = b.albedo[group[0]];
        }
    }
    fills.len()
}

/// The rows of a band's tiles (`tiles`, left to right; frame width `w`): `put(tile, dst,
/// src, n)` for each, `n` pixels from `src` in the tile to `dst` in the band.
fn band_rows(tiles: &[TileOut], w: usize, mut put: impl FnMut(&TileOut, usize, usize, usize)) {
    for (tx, o) in tiles.iter().enumerate() {
        let px0 = tx * TILE as usize;
        let tile_w = (px0 + TILE as usize).min(w) - px0;
        for r in 0..o.depth.len() / tile_w {
            put(o, r * w + px0, r * tile_w, tile_w);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A crack one pixel wide through one surface closes with its neighbours' surface; a
    /// crack two pixels wide, one between surfaces farther apart than ε and the image's
    /// border stay.
    #[test]
    fn cracks_one_pixel_wide_close_and_nothing_else() {
        let fill = |rows: &[&str], eps: f32| {
            let mut g = GBuffer::from_ascii(rows);
            let (w, h) = (g.width as usize, g.height as usize);
            let mut b = Blended {
                normal: (0..w * h)
                    .map(|k| Vec3::new(k as f32, 1.0, 0.0).normalize())
                    .collect(),
                albedo: (0..w * h).map(|k| [k as f32; 3]).collect(),
            };
            let before = (g.clone(), b.normal.clone(), b.albedo.clone());
            let n = fill_pinholes(w, h, &mut g, Some(&mut b), eps);
            (n, before, g, b)
        };
        // Closed: left and right within ε; above and below too, and the nearest (left,
        // the first of the two nearest) gives the point.
        let (n, (g0, n0, a0), g, b) = fill(&["333", "2.2", "333"], 1.5);
        assert_eq!(n, 1);
        let (k, group) = (4, [3, 1, 5, 7]);
        assert_eq!(g.depth[k], 2.5);
        assert_eq!(g.id[k], g0.id[3]);
        let sum: Vec3 = group.iter().map(|&j| n0[j]).sum();
        assert!((b.normal[k] - sum.normalize()).length() < 1e-6);
        assert_eq!(b.albedo[k], a0[3]);
        for j in (0..9).filter(|&j| j != k) {
            assert_eq!(
                (g.depth[j].to_bits(), g.id[j]),
                (g0.depth[j].to_bits(), g0.id[j])
            );
            assert_eq!((b.normal[j], b.albedo[j]), (n0[j], a0[j]));
        }
        // Only the nearer surface within ε of the nearest: above and below (depth 9) not.
        let (n, _, g, _) = fill(&["999", "2.2", "999"], 1.5);
        assert_eq!((n, g.depth[4]), (1, 2.0));
        // Open: two wide, between depths 2 and 7 (ε 1.5), on the border.
        for rows in [
            &["2..2", "2..2", "2..2"][..],
            &["2.7", "2.7", "2.7"],
            &["2.2", "222", "222"],
        ] {
            let (n, (g0, ..), g, _) = fill(rows, 1.5);
            assert_eq!(n, 0, "{rows:?}");
            assert_eq!(g, g0);
        }
    }

    /// A plane of sparse points facing the camera: Voronoi covers every pixel inside, and
    /// each pixel shows the point nearest it (the Voronoi cell).
    #[test]
    fn voronoi_covers_a_sparse_plane_with_nearest_points() {
        let v = ViewParams::axis_aligned(64, 64, false, 1.0 / 32.0);
        // Points 4 px apart on the plane z = 5, radius 3 px.
        let mut pos = Vec::new();
        for j in 0..16 {
            for i in 0..16 {
                pos.push(Vec3::new(
                    (i as f32 - 7.5) * 4.0 + 0.3,
                    (j as f32 - 7.5) * 4.0 - 0.2,
                    5.0,
                ));
            }
        }
        let normals = vec![-Vec3::Z; pos.len()];
        let radii = vec![3.0; pos.len()];
        let input = SplatInput {
            positions: &pos,
            normals: Some(&normals),
            radii: &radii,
            scale: 1.0,
            shapes: None,
            groups: None,
            quant: None,
            epsilon: 1.0,
        };
        let mut g = GBuffer::new(64, 64);
        let drawn = splat(&v, &input, SplatMode::Voronoi, None, &mut g, None);
        assert_eq!(drawn, 256);
        for j in 2..62u32 {
            for i in 2..62u32 {
                let k = (j * 64 + i) as usize;
                let id = g.id[k];
                assert_ne!(id, BACKGROUND, "hole at {i},{j}");
                assert_eq!(g.depth[k], 5.0);
                // The pixel's position in the plane (x right, y up).
                let q = Vec3::new(i as f32 + 0.5 - 32.0, 32.0 - (j as f32 + 0.5), 5.0);
                let nearest = (0..pos.len())
                    .min_by(|&a, &b| {
                        (pos[a] - q)
                            .length_squared()
                            .total_cmp(&(pos[b] - q).length_squared())
                    })
                    .unwrap();
                let d_win = (pos[id as usize] - q).length();
                let d_near = (pos[nearest] - q).length();
                assert!(d_win <= d_near + 1e-4, "pixel {i},{j}");
            }
        }
    }

    /// Two planes: the far one never shows where the near one covers; ε-z keeps one layer.
    #[test]
    fn the_nearer_surface_hides_the_farther() {
        let v = ViewParams::axis_aligned(32, 32, false, 1.0 / 16.0);
        let mut pos = Vec::new();
        for z in [5.0, 9.0] {
            for j in 0..8 {
                for i in 0..8 {
                    pos.push(Vec3::new(i as f32 * 4.0 - 14.0, j as f32 * 4.0 - 14.0, z));
                }
            }
        }
        let radii = vec![3.0; pos.len()];
        let input = SplatInput {
            positions: &pos,
            normals: None,
            radii: &radii,
            scale: 1.0,
            shapes: None,
            groups: None,
            quant: None,
            epsilon: 1.0,
        };
        for mode in [SplatMode::Voronoi, SplatMode::Blend] {
            let mut g = GBuffer::new(32, 32);
            let mut b = Blended::default();
            splat(&v, &input, mode, None, &mut g, Some(&mut b));
            for k in 0..32 * 32 {
                assert!(g.id[k] < 64, "{mode:?}: pixel {k} shows {}", g.id[k]);
                assert!((g.depth[k] - 5.0).abs() < 1e-5);
                if mode == SplatMode::Blend {
                    // Eye-facing discs: the blended normal faces the eye.
                    assert!((b.normal[k] - Vec3::new(0.0, 0.0, -1.0)).length() < 1e-4);
                }
            }
        }
    }

    /// Normals of random sign blend to the eye-facing normal, not to zero.
    #[test]
    fn blending_turns_normals_towards_the_eye() {
        let v = ViewParams::axis_aligned(16, 16, false, 1.0 / 8.0);
        let mut pos = Vec::new();
        let mut nrm = Vec::new();
        for j in 0..8 {
            for i in 0..8 {
                pos.push(Vec3::new(i as f32 * 2.0 - 7.0, j as f32 * 2.0 - 7.0, 3.0));
                nrm.push(if (i + j) % 2 == 0 { Vec3::Z } else { -Vec3::Z });
            }
        }
        let radii = vec![2.5; pos.len()];
        let input = SplatInput {
            positions: &pos,
            normals: Some(&nrm),
            radii: &radii,
            scale: 1.0,
            shapes: None,
            groups: None,
            quant: None,
            epsilon: 0.5,
        };
        let mut g = GBuffer::new(16, 16);
        let mut b = Blended::default();
        splat(&v, &input, SplatMode::Blend, None, &mut g, Some(&mut b));
        assert!(b.normal.iter().all(|n| (n.z + 1.0).abs() < 1e-5));
    }

    /// Deferred blending equals the two-pass blend when no two splats of a group overlap
    /// (§3.2, Eq. 2–4), and with every splat in one group it keeps one splat per pixel.
    #[test]
    fn deferred_blending_equals_blending_for_independent_groups() {
        let v = ViewParams::axis_aligned(64, 64, true, 1.0);
        let mut pos = Vec::new();
        let mut groups = Vec::new();
        for j in 0..16 {
            for i in 0..16 {
                // A plane tilted a little, 6 units in front of the eye, points 0.4 apart.
                let (x, y) = ((i as f32 - 7.5) * 0.4, (j as f32 - 7.5) * 0.4);
                pos.push(Vec3::new(x, y, 6.0 + 0.1 * x));
                groups.push((i % 2 + 2 * (j % 2)) as u8);
            }
        }
        let n = Vec3::new(-0.1, 0.0, 1.0).normalize();
        let normals = vec![n; pos.len()];
        let radii = vec![0.3; pos.len()];
        let colours: Vec<[u8; 3]> = (0..pos.len())
            .map(|i| [(i * 7 % 256) as u8, 90, 200])
            .collect();
        let lut = srgb_to_linear_table();
        let mut input = SplatInput {
            positions: &pos,
            normals: Some(&normals),
            radii: &radii,
            scale: 1.0,
            shapes: None,
            groups: Some((&groups, 4)),
            quant: Some(super::super::DepthQuant::new(5.0, 8.0, 0.3)),
            epsilon: 0.3,
        };
        let run = |mode, input: &SplatInput| {
            let mut g = GBuffer::new(64, 64);
            let mut b = Blended::default();
            let albedo = Some((Albedo::Colours(&colours), &lut));
            splat(&v, input, mode, albedo, &mut g, Some(&mut b));
            (g, b)
        };
        let (ga, ba) = run(SplatMode::Blend, &input);
        let (gb, bb) = run(SplatMode::Deferred, &input);
        let mut covered = 0;
        for k in 0..64 * 64 {
            assert_eq!(ga.id[k], gb.id[k], "pixel {k}");
            if ga.id[k] == BACKGROUND {
                continue;
            }
            covered += 1;
            assert!((ga.depth[k] - gb.depth[k]).abs() < 1e-5, "pixel {k}");
            assert!((ba.normal[k] - bb.normal[k]).length() < 1e-5, "pixel {k}");
            for c in 0..3 {
                assert!(
                    (ba.albedo[k][c] - bb.albedo[k][c]).abs() < 1e-3,
                    "pixel {k}"
                );
            }
        }
        assert!(covered > 1000, "{covered}");
        // One group: overlapping splats of the group compete in the depth test, so each
        // pixel blends exactly one splat: its own albedo, no mixture.
        let one = vec![0u8; pos.len()];
        input.groups = Some((&one, 1));
        let (gc, bc) = run(SplatMode::Deferred, &input);
        for k in 0..64 * 64 {
            if gc.id[k] != BACKGROUND {
                let own = colours[gc.id[k] as usize].map(|x| lut[x as usize]);
                assert_eq!(bc.albedo[k], own, "pixel {k}");
            }
        }
    }

    /// The AVX2 build of the tile loops (`Tiles::tile_avx2`) gives the same image, to the
    /// bit, as the plain one: bent, flat, clipped and rim-curved splats of random sizes and
    /// colours, in every mode and both projections.
    #[test]
    fn vector_instructions_change_no_bit() {
        #[cfg(target_arch = "x86_64")]
        if !std::arch::is_x86_feature_detected!("avx2") {
            eprintln!("skipped: this processor has no AVX2, so both paths are the same code");
            return;
        }
        let mut seed = 0x2545_f491_4f6c_dd1du64;
        let mut rnd = move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 40) as f32 / (1u64 << 24) as f32
        };
        let n = 3000;
        let (mut pos, mut nrm, mut radii, mut shapes, mut colours, mut groups) =
            (vec![], vec![], vec![], vec![], vec![], vec![]);
        for i in 0..n {
            pos.push(Vec3::new(
                rnd() * 4.0 - 2.0,
                rnd() * 4.0 - 2.0,
                5.0 + rnd() * 2.0,
            ));
            nrm.push(Vec3::new(rnd() - 0.5, rnd() - 0.5, -1.0).normalize());
            radii.push(0.05 + 0.2 * rnd());
            let mut shape = super::super::SplatShape::default();
            if i % 4 != 0 {
                shape.bend = [rnd() * 8.0 - 4.0, rnd() * 2.0 - 1.0, rnd() * 8.0 - 4.0];
            }
            if i % 3 == 0 {
                let m = Vec3::new(rnd() - 0.5, rnd() - 0.5, rnd() - 0.5).normalize();
                shape.clip[0] = [m.x, m.y, m.z, m.dot(pos[i]) + 0.05];
                if i % 6 == 0 {
                    shape.curve[0] = [rnd() * 4.0, rnd() * 0.1];
                }
            }
            shapes.push(shape);
            colours.push([(i * 37 % 256) as u8, (i * 11 % 256) as u8, 128]);
            groups.push((i % 5) as u8);
        }
        let lut = srgb_to_linear_table();
        let input = SplatInput {
            positions: &pos,
            normals: Some(&nrm),
            radii: &radii,
            scale: 1.0,
            shapes: Some(&shapes),
            groups: Some((&groups, 5)),
            quant: Some(super::super::DepthQuant::new(4.0, 8.0, 0.2)),
            epsilon: 0.2,
        };
        let mut fragments = 0;
        for perspective in [true, false] {
            let v =
                ViewParams::axis_aligned(96, 80, perspective, if perspective { 2.0 } else { 0.4 });
            for mode in [SplatMode::Voronoi, SplatMode::Blend, SplatMode::Deferred] {
                let run = |vector| {
                    let mut g = GBuffer::new(96, 80);
                    let mut b = Blended::default();
                    let albedo = Some((Albedo::Colours(&colours), &lut));
                    splat_with(&v, &input, mode, albedo, &mut g, Some(&mut b), vector);
                    (g, b)
                };
                let ((ga, ba), (gb, bb)) = (run(false), run(true));
                let bits = |x: &[f32]| x.iter().map(|f| f.to_bits()).collect::<Vec<_>>();
                assert_eq!(ga.id, gb.id, "{mode:?}, perspective {perspective}");
                assert_eq!(bits(&ga.depth), bits(&gb.depth), "{mode:?}");
                assert_eq!(ba.normal, bb.normal, "{mode:?}");
                assert_eq!(ba.albedo, bb.albedo, "{mode:?}");
                fragments += ga.id.iter().filter(|&&i| i != BACKGROUND).count();
            }
        }
        // The scene covers most pixels in every run (6 runs of 96×80).
        assert!(fragments > 6 * 96 * 80 / 2, "{fragments}");
    }
}
