// sorted splats (Gunjee §4.2), GPU twin of sorted.rs (CPU) and shade::cpu::shade_points.
// Appended to shade.wgsl (its uniforms, the sRGB table and phong_lights). Two kernels:
//   sorted_points     per chunk: each point's splat (centre in pixels, footprint radius,
//                     depth) and its shaded colour with its optical depth per unit weight
//   sorted_composite  one 16×16 tile a workgroup, one pixel a thread: the splats in the
//                     bucket sort's order, 256 at a time through workgroup memory, blended
//                     with "over" exactly as the CPU's bands do

struct SortedChunk {
    base: u32,
    count: u32,
    scale: f32,
    // The surface's expected sum of weights at a pixel, times scale² (sorted::expected_overlap).
    overlap: f32,
    has_normals: u32,
    has_albedo: u32,
    has_style: u32,
    has_lit: u32,
    // 0: sorted splats (Gunjee), 1: transparent splats (Zhang & Pajarola Algorithm 2).
    mode: u32,
    // 1: the chunk's normals orient the discs (lit or not).
    disc_normals: u32,
    // 1: transparent splats shaded per layer (deferred): the points give their albedo.
    deferred: u32,
    pad2: u32,
}

struct SortedComposite {
    // First-level buckets of the sort: the points kept are at sort_counts[2 n].
    n: u32,
    // This dispatch draws the splats begin..end of the order (and no further than those
    // kept); the first starts the accumulators, the last writes the pixels.
    begin: u32,
    end: u32,
    first: u32,
    last: u32,
    // Transparent splats: the number of groups K and the culling ε.
    groups: u32,
    epsilon: f32,
    // 1: each layer shaded from its blended normal (transparent::Deferred).
    deferred: u32,
    // Transparent splats' environment (env.rs): 0 none, 1 the sky, 2 the image t_env of
    // env_w × env_h texels; ior > 0: the nearest layer reflects it; the scene's up axis.
    env_kind: u32,
    env_w: u32,
    env_h: u32,
    ior: f32,
    env_up: vec3<f32>,
    // Chromatic dispersion δ (env::EnvSettings::dispersion).
    dispersion: f32,
    // Bit 0: Algorithm 3 (the nearest layer smoothly interpolated) where the nearest layer's
    // object does not choose; bit 1: some pixel may take it (sum the layers' colours).
    smooth_nearest: u32,
    // transparent::Phase: 0 every fragment; with refraction 1 the opaque ones (the surface
    // behind, written to t_acc's behind region), then 2 the translucent ones in front of it.
    phase: u32,
    // transparent_composite: this dispatch's band, its first tile row and how many tile
    // rows the band's group images hold.
    band_ty: u32,
    band_tiles: u32,
}

@group(0) @binding(11) var<uniform> sc: SortedChunk;
@group(0) @binding(12) var<storage, read> s_positions: array<f32>;
@group(0) @binding(13) var<storage, read> s_normals: array<f32>;
@group(0) @binding(14) var<storage, read> s_albedo: array<u32>;
@group(0) @binding(15) var<storage, read> s_style: array<u32>;
@group(0) @binding(16) var<storage, read> s_lit: array<vec2<u32>>;
// Coloured shadows (has_lit 2): red | blue << 16 per light.
@group(0) @binding(25) var<storage, read> s_lit_rb: array<vec4<u32>>;

// A coloured channel's sum over `s` samples as m, rounded to 8 bits (shade::cpu::lit_rgb).
fn lit8(sum: u32, s: u32) -> f32 {
    return f32(min((2u * sum + s) / (2u * s), 255u)) / 255.0;
}
// (radius, bend…), the clip planes and their bends: four vec4 per point (the splat pass's
// shapes).
@group(0) @binding(17) var<storage, read> s_shapes: array<vec4<f32>>;
// Per point of the cloud, four vec4. Sorted: (centre x, centre y, radius, depth), (linear
// colour, τ). Transparent: (point, r²), (unit normal, α), (linear colour, group mask's
// bits), (pixel rectangle x0, y0, x1, y1; x0 > x1: none).
@group(0) @binding(18) var<storage, read_write> s_splats: array<vec4<f32>>;
@group(0) @binding(19) var<storage, read> s_order: array<u32>;
@group(0) @binding(20) var<storage, read> s_counts: array<u32>;
@group(0) @binding(21) var<uniform> scomp: SortedComposite;
@group(0) @binding(22) var<storage, read_write> s_depth: array<f32>;
@group(0) @binding(23) var<storage, read_write> s_id: array<u32>;
// Per pixel between dispatches: colour and coverage so far.
@group(0) @binding(24) var<storage, read_write> s_acc: array<vec4<f32>>;

const SORTED_MAX_ALPHA: f32 = 0.999;
const SORTED_ID_WEIGHT: f32 = 0.1;
const SORTED_MIN_RADIUS: f32 = 0.70710677;
const MAX_FOOTPRINT: f32 = 256.0;

// Chunk point `local`'s style word: object in the low byte, 8-bit opacity in the next
// (opaque, object 0 without styles).
fn point_style(local: u32) -> u32 {
    if (sc.has_style == 1u) {
        return s_style[local];
    }
    return 0xff00u;
}

// Chunk point `local` at q shaded as shade::cpu::shade_points shades it.
// shade::cpu::point_albedo
fn point_albedo(local: u32) -> vec3<f32> {
    var albedo = sp.base_colour;
    if (sc.has_albedo == 1u) {
        let bits = s_albedo[local];
        albedo = vec3<f32>(to_linear[bits & 0xffu], to_linear[(bits >> 8u) & 0xffu], to_linear[(bits >> 16u) & 0xffu]);
    }
    return albedo;
}

fn shaded_point(local: u32, q: vec3<f32>, object: u32) -> vec3<f32> {
    let albedo = point_albedo(local);
    let mat = materials[object];
    var m = array<vec3<f32>, 4>(vec3<f32>(1.0), vec3<f32>(1.0), vec3<f32>(1.0), vec3<f32>(1.0));
    if (sc.has_lit != 0u) {
        let lw = s_lit[local];
        for (var l = 0u; l < 4u; l++) {
            if (sp.samples[l] > 0u) {
                let w = select(lw.y, lw.x, l < 2u);
                let g = (w >> (16u * (l % 2u))) & 0xffffu;
                if (sc.has_lit == 1u) {
                    m[l] = vec3<f32>(f32(g) / f32(sp.samples[l] * 255u));
                } else {
                    // shade::cpu::lit_rgb: each channel rounded to 8 bits.
                    let rb = s_lit_rb[local][l];
                    m[l] = vec3<f32>(lit8(rb & 0xffffu, sp.samples[l]), lit8(g, sp.samples[l]), lit8(rb >> 16u, sp.samples[l]));
                }
            }
        }
    }
    var c = albedo;
    if (sc.has_normals == 0u) {
        if (sc.has_lit != 0u) {
            c = unlit(albedo, m, mat);
        }
    } else {
        let n = vec3<f32>(s_normals[3u * local], s_normals[3u * local + 1u], s_normals[3u * local + 2u]);
        var to_eye = -view.forward;
        if (view.perspective == 1u) {
            let e = view.eye - q;
            let len = sqrt(dot3(e, e));
            if (len > 0.0) {
                to_eye = e * (1.0 / len);
            } else {
                to_eye = vec3<f32>(0.0);
            }
        }
        c = phong_lights(albedo, n, to_eye, q, m, mat);
    }
    return c;
}

@compute @workgroup_size(256)
fn sorted_points(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(local_invocation_index) li: u32,
) {
    let local = group_index(wg, groups) * 256u + li;
    if (local >= sc.count) {
        return;
    }
    let q = vec3<f32>(s_positions[3u * local], s_positions[3u * local + 1u], s_positions[3u * local + 2u]);
    // sorted::composite's splat
    let d = q - view.eye;
    let z = dot3(d, view.forward);
    let x = dot3(d, view.right);
    let y = dot3(d, view.up);
    let focal = 0.5 * f32(view.height) * view.sy;
    var nx = x * view.sx;
    var ny = y * view.sy;
    var per = focal;
    if (view.perspective == 1u) {
        nx = x * view.sx / z;
        ny = y * view.sy / z;
        per = focal / z;
    }
    let fx = (nx + 1.0) * 0.5 * f32(view.width);
    let fy = (1.0 - ny) * 0.5 * f32(view.height);
    let raw = s_shapes[4u * local].x * sc.scale * per;
    let rho = clamp(raw, SORTED_MIN_RADIUS, MAX_FOOTPRINT / 2.0);
    let st = point_style(local);
    let alpha = f32((st >> 8u) & 0xffu) / 255.0;
    let object = st & 0xffu;
    var widened = 1.0;
    if (raw > 0.0) {
        widened = rho / raw;
    }
    let w_sum = sc.overlap * widened * widened;
    let tau = -log(1.0 - min(alpha, SORTED_MAX_ALPHA)) / max(w_sum, 1e-6);
    let c = shaded_point(local, q, object);
    let g = sc.base + local;
    s_splats[4u * g] = vec4<f32>(fx, fy, rho, z);
    s_splats[4u * g + 1u] = vec4<f32>(c, tau);
}

var<workgroup> tile_a: array<vec4<f32>, 256>;
var<workgroup> tile_b: array<vec4<f32>, 256>;
var<workgroup> tile_id: array<u32, 256>;
// The entries this tile walks: [tile_lo, tile_hi) of its binned list (tile_binned 1) or
// of the sorted order (bin_range).
var<workgroup> tile_lo: u32;
var<workgroup> tile_hi: u32;
var<workgroup> tile_binned: u32;
// Per round, bit j set: staged splat j meets the tile (two sets, alternating by round, so
// that one is cleared while the other is read): the pixels walk only those, in order.
var<workgroup> tile_hits: array<array<atomic<u32>, 8>, 2>;

// The order is drawn in dispatches of at most sorted_gpu::BATCH splats, the accumulators
// kept per pixel between them: on lavapipe one dispatch drew only the first 65 536 splats
// of a larger cloud (measured, cause not found), and short dispatches also keep a frame
// of many points clear of drivers' watchdogs.
@compute @workgroup_size(16, 16)
fn sorted_composite(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(local_invocation_id) lid: vec3<u32>,
    @builtin(local_invocation_index) li: u32,
) {
    let px = wg.x * 16u + lid.x;
    let py = wg.y * 16u + lid.y;
    let inside = px < view.width && py < view.height;
    let pix = py * view.width + px;
    let tx0 = f32(wg.x * 16u);
    let ty0 = f32(wg.y * 16u);
    if (li == 0u) {
        let r = bin_range(wg.y * binp.tiles_x + wg.x, scomp.begin, min(s_counts[2u * scomp.n], scomp.end));
        tile_lo = r.x;
        tile_hi = r.y;
        tile_binned = r.z;
    }
    let lo = workgroupUniformLoad(&tile_lo);
    let hi = workgroupUniformLoad(&tile_hi);
    let binned = workgroupUniformLoad(&tile_binned);
    var acc = vec4<f32>(0.0);
    var dep = infinity();
    var pid = BACKGROUND;
    if (inside && scomp.first == 0u) {
        acc = s_acc[pix];
        dep = s_depth[pix];
        pid = s_id[pix];
    }
    let cx = f32(px) + 0.5;
    let cy = f32(py) + 0.5;
    var base = lo;
    var round = 0u;
    loop {
        if (base >= hi) {
            break;
        }
        let buf = round & 1u;
        let e = base + li;
        if (e < hi) {
            var k = e;
            if (binned == 1u) {
                k = bin_pairs[e];
            }
            let id = s_order[k];
            let a = s_splats[4u * id];
            // Only splats that meet the tile are staged and marked (a splat that misses it
            // costs its one test here, not one per pixel).
            if (!(a.z < 0.0 || a.x + a.z < tx0 || a.x - a.z > tx0 + 16.0 || a.y + a.z < ty0 || a.y - a.z > ty0 + 16.0)) {
                tile_a[li] = a;
                tile_b[li] = s_splats[4u * id + 1u];
                tile_id[li] = id;
                atomicOr(&tile_hits[buf][li >> 5u], 1u << (li & 31u));
            }
        }
        workgroupBarrier();
        if (li < 8u) {
            atomicStore(&tile_hits[buf ^ 1u][li], 0u);
        }
        if (inside) {
            for (var w = 0u; w < 8u; w++) {
                var bits = atomicLoad(&tile_hits[buf][w]);
                loop {
                    if (bits == 0u) {
                        break;
                    }
                    let j = 32u * w + pop_bit(&bits);
                    let s = tile_a[j];
                    let dx = cx - s.x;
                    let dy = cy - s.y;
                    let inv = 1.0 / (s.z * s.z);
                    let d2 = (dx * dx + dy * dy) * inv;
                    if (d2 > 1.0) {
                        continue;
                    }
                    let t = tile_b[j];
                    let wgt = exp(-3.0 * d2);
                    let al = 1.0 - exp(-t.w * wgt);
                    acc = vec4<f32>(al * t.xyz + (1.0 - al) * acc.xyz, al + (1.0 - al) * acc.w);
                    if (wgt >= SORTED_ID_WEIGHT) {
                        dep = s.w;
                        pid = tile_id[j];
                    }
                }
            }
        }
        workgroupBarrier();
        base = base + 256u;
        round = round + 1u;
    }
    if (inside) {
        s_acc[pix] = acc;
        s_depth[pix] = dep;
        s_id[pix] = pid;
        if (scomp.last == 1u) {
            colour[pix] = vec4<f32>(acc.xyz + (1.0 - acc.w) * sp.background, 1.0);
            surface_depth[pix] = dep;
        }
    }
}

// ---- transparent splats (Zhang & Pajarola Algorithm 2), twin of transparent.rs ----
//   transparent_points     per chunk: each point's disc, shaded colour (deferred: albedo),
//                          opacity, group mask and pixel rectangle (transparent::bound)
//   transparent_composite  one 16×16 tile a workgroup, one pixel a thread: the splats in the
//                          bucket sort's order, 128 at a time through workgroup memory, each
//                          fragment blended into its groups' images unless within ε of the
//                          last one blended there; the K images kept per pixel between
//                          dispatches and averaged by the last

// Per pixel and group between dispatches, five vec4 (transparent::Layered): (colour behind
// the current layer, its fragment's α), (the fragment's colour, depth), ((d/r)², point,
// what the layers behind let through, how many they are), (the layer's weighted normals,
// weight sum), (its weighted colour and opacity). With refraction, after the K groups' 5 K
// vec4 per pixel: per pixel the surface behind (colour, depth; transparent::Behind), then
// per pixel the farthest translucent layer (weighted normals, depth).
@group(0) @binding(26) var<storage, read_write> t_acc: array<vec4<f32>>;
// The groups each point of the cloud is drawn in (bit k: group k).
@group(0) @binding(27) var<storage, read> t_masks: array<u32>;

// The environment image (env::Environment::Image), linear RGB, row 0 at the zenith.
@group(0) @binding(28) var<storage, read> t_env: array<vec4<f32>>;

// Per object (material::Optics): (index of refraction, 0: the frame's; dispersion, −1: the
// frame's; reflectivity; 0), (absorption per channel, 0).
@group(0) @binding(29) var<uniform> t_optics: array<vec4<f32>, 512>;

// The optics of the pixel's nearest layer (env::Surface), set by t_set_surface.
var<private> t_eta: f32;
var<private> t_disp: f32;
var<private> t_refl: f32;
var<private> t_absorb: vec3<f32>;

// transparent::TransparentInput::surface: point pid's object's optics, else the frame's.
fn t_set_surface(pid: u32) {
    t_eta = scomp.ior;
    t_disp = scomp.dispersion;
    t_refl = 1.0;
    t_absorb = vec3<f32>(0.0);
    if (pid != BACKGROUND) {
        let obj = bitcast<u32>(s_splats[4u * pid + 2u].w) >> 8u;
        let a = t_optics[2u * obj];
        if (a.x > 0.0) {
            t_eta = a.x;
        }
        if (a.y >= 0.0) {
            t_disp = a.y;
        }
        t_refl = a.z;
        t_absorb = t_optics[2u * obj + 1u].xyz;
    }
}

// transparent::TransparentInput::smooth_at: whether a pixel whose nearest layer is point
// pid's takes Algorithm 3 (its object's choice, else the frame's).
fn t_smooth_at(pid: u32) -> bool {
    var own = 0.0;
    if (pid != BACKGROUND) {
        own = t_optics[2u * (bitcast<u32>(s_splats[4u * pid + 2u].w) >> 8u) + 1u].w;
    }
    if (own > 1.5) {
        return true;
    }
    if (own > 0.5) {
        return false;
    }
    return (scomp.smooth_nearest & 1u) != 0u;
}

// env::Surface::passed: what layers that let `through` pass let through with the absorption.
fn t_passed(through: f32, layers: f32) -> vec3<f32> {
    var p = vec3<f32>(through);
    for (var ch = 0u; ch < 3u; ch++) {
        if (t_absorb[ch] > 0.0) {
            p[ch] = through * pow(max(1.0 - t_absorb[ch], 1e-6), layers);
        }
    }
    return p;
}

// env::frame: (east, north, up).
fn env_frame(up: vec3<f32>) -> mat3x3<f32> {
    var u = vec3<f32>(0.0, 1.0, 0.0);
    let ul = length(up);
    if (ul > 0.0) {
        u = up / ul;
    }
    var east = vec3<f32>(1.0, 0.0, 0.0) - u * dot(u, vec3<f32>(1.0, 0.0, 0.0));
    let el = length(east);
    if (el > 0.0) {
        east = east / el;
    } else {
        east = vec3<f32>(0.0, 0.0, 1.0);
    }
    return mat3x3<f32>(east, cross(u, east), u);
}

fn env_texel(i: f32, j: f32) -> vec3<f32> {
    let w = i32(scomp.env_w);
    let h = i32(scomp.env_h);
    let ii = ((i32(i) % w) + w) % w;
    let jj = clamp(i32(j), 0, h - 1);
    return t_env[u32(jj * w + ii)].xyz;
}

// env::pixel_cone: the angle a pixel spans at the centre of a perspective view.
fn pixel_cone() -> f32 {
    if (view.perspective == 1u) {
        return 2.0 / (f32(max(view.height, 1u)) * view.sy);
    }
    return 0.0;
}

// x mod 2 in [0, 2) (f32::rem_euclid).
fn mod2(t: f32) -> f32 {
    return t - 2.0 * floor(t / 2.0);
}

// env::checker: the ground's squares of ½, +1 / −1, box-filtered over w ground units.
fn checker_wave(u: f32, w: f32) -> f32 {
    if (w < 1e-3) {
        return 1.0 - 2.0 * mod2(floor(u));
    }
    let hi = 1.0 - abs(mod2(u + 0.5 * w) - 1.0);
    let lo = 1.0 - abs(mod2(u - 0.5 * w) - 1.0);
    return (hi - lo) / w;
}

fn checker(gx: f32, gy: f32, w: f32) -> f32 {
    let ws = 2.0 * max(w, 0.0);
    return checker_wave(2.0 * gx, ws) * checker_wave(2.0 * gy, ws);
}

// env::Environment::sample.
fn env_sample(dir: vec3<f32>) -> vec3<f32> {
    let f = env_frame(scomp.env_up);
    var d = f[2];
    let dl = length(dir);
    if (dl > 0.0) {
        d = dir / dl;
    }
    let x = dot(d, f[0]);
    let y = dot(d, f[1]);
    let z = dot(d, f[2]);
    let horizon = vec3<f32>(0.80, 0.85, 0.92);
    if (scomp.env_kind == 1u) {
        if (z >= 0.0) {
            return mix(horizon, vec3<f32>(0.18, 0.36, 0.75), sqrt(z));
        }
        let gx = x / -z;
        let gy = y / -z;
        let c = checker(gx, gy, pixel_cone() / (z * z));
        let g0 = vec3<f32>(0.30, 0.30, 0.30);
        let g1 = vec3<f32>(0.12, 0.12, 0.12);
        let g = 0.5 * (g0 + g1) + 0.5 * (g0 - g1) * c;
        return mix(horizon, g, min(-8.0 * z, 1.0));
    }
    let w = f32(scomp.env_w);
    let h = f32(scomp.env_h);
    let lon = atan2(y, x);
    let lat = acos(clamp(z, -1.0, 1.0));
    let s = (0.5 - lon / 6.2831855) * w - 0.5;
    let t = lat / 3.1415927 * h - 0.5;
    let s0 = floor(s);
    let t0 = floor(t);
    let top = mix(env_texel(s0, t0), env_texel(s0 + 1.0, t0), s - s0);
    let bottom = mix(env_texel(s0, t0 + 1.0), env_texel(s0 + 1.0, t0 + 1.0), s - s0);
    return mix(top, bottom, t - t0);
}

// env::fresnel.
fn fresnel(cos_i: f32, eta: f32) -> f32 {
    let ci = clamp(cos_i, 0.0, 1.0);
    let si2 = max(1.0 - ci * ci, 0.0);
    let st2 = si2 / (eta * eta);
    if (st2 >= 1.0) {
        return 1.0;
    }
    let ct = sqrt(1.0 - st2);
    let rs = (ci - eta * ct) / (ci + eta * ct);
    let rp = (eta * ci - ct) / (eta * ci + ct);
    return 0.5 * (rs * rs + rp * rp);
}

// env::reflect_into.
fn reflect_into(c: vec3<f32>, dir: vec3<f32>, normal: vec3<f32>) -> vec3<f32> {
    let dl = length(dir);
    let nl = length(normal);
    if (dl == 0.0 || nl == 0.0) {
        return c;
    }
    let d = dir / dl;
    var n = normal / nl;
    if (dot(n, d) > 0.0) {
        n = -n;
    }
    let cos_i = -dot(n, d);
    let f = fresnel(cos_i, t_eta) * t_refl;
    let r = d + 2.0 * cos_i * n;
    return f * env_sample(r) + (1.0 - f) * c;
}

// env::refracted.
fn refracted(d: vec3<f32>, n: vec3<f32>, eta: f32, layers: f32) -> vec3<f32> {
    let cos_i = clamp(-dot(n, d), -1.0, 1.0);
    let sin_i = sqrt(max(1.0 - cos_i * cos_i, 0.0));
    if (layers <= 0.0 || sin_i < 1e-6 || eta <= 0.0) {
        return d;
    }
    let sin_t = pow(1.0 / eta, layers) * sin_i;
    if (sin_t >= 1.0) {
        return d;
    }
    let tangent = (d + n * cos_i) / sin_i;
    return tangent * sin_t - n * sqrt(1.0 - sin_t * sin_t);
}

// env::finish: the environment let through (refracted) and reflected.
fn env_finish(c: vec3<f32>, dir: vec3<f32>, normal: vec3<f32>, has_n: bool, through: f32, layers: f32) -> vec3<f32> {
    let dl = length(dir);
    var d = vec3<f32>(0.0);
    if (dl > 0.0) {
        d = dir / dl;
    }
    var n = vec3<f32>(0.0);
    var ok = false;
    let nl = length(normal);
    if (has_n && nl > 0.0 && dl > 0.0) {
        n = normal / nl;
        if (dot(n, d) > 0.0) {
            n = -n;
        }
        ok = true;
    }
    var out = c;
    let passed = t_passed(through, layers);
    if (through > 0.0) {
        if (ok && t_eta > 0.0) {
            for (var ch = 0u; ch < 3u; ch++) {
                let eta_c = t_eta * (1.0 + t_disp * (f32(ch) - 1.0));
                let t = refracted(d, n, eta_c, layers);
                out[ch] = out[ch] + passed[ch] * env_sample(t)[ch];
            }
        } else {
            out = out + passed * env_sample(d);
        }
    }
    if (ok && t_eta > 0.0) {
        return reflect_into(out, d, n);
    }
    return out;
}

// Where the surface behind starts in t_acc (set by transparent_composite).
var<private> t_bbase: u32;

// transparent::to_pixel: (x, y, 1), or (0, 0, 0) behind the eye.
fn t_to_pixel(p: vec3<f32>) -> vec3<f32> {
    let d = p - view.eye;
    let x = dot3(d, view.right);
    let y = dot3(d, view.up);
    let z = dot3(d, view.forward);
    let w = f32(view.width);
    let h = f32(view.height);
    if (view.perspective == 1u) {
        if (!(z > 0.0)) {
            return vec3<f32>(0.0);
        }
        return vec3<f32>((x * view.sx / z + 1.0) * 0.5 * w - 0.5, (1.0 - y * view.sy / z) * 0.5 * h - 0.5, 1.0);
    }
    return vec3<f32>((x * view.sx + 1.0) * 0.5 * w - 0.5, (1.0 - y * view.sy) * 0.5 * h - 0.5, 1.0);
}

// transparent::Behind::depth_at
fn t_behind_depth(x: f32, y: f32) -> f32 {
    let i = u32(clamp(floor(x + 0.5), 0.0, f32(view.width) - 1.0));
    let j = u32(clamp(floor(y + 0.5), 0.0, f32(view.height) - 1.0));
    return t_acc[t_bbase + j * view.width + i].w;
}

fn t_behind_texel(i: f32, j: f32) -> vec3<f32> {
    let ii = min(u32(i), view.width - 1u);
    let jj = min(u32(j), view.height - 1u);
    return t_acc[t_bbase + jj * view.width + ii].xyz;
}

// transparent::Behind::colour_at
fn t_behind_colour(x_in: f32, y_in: f32) -> vec3<f32> {
    let x = clamp(x_in, 0.0, f32(view.width - 1u));
    let y = clamp(y_in, 0.0, f32(view.height - 1u));
    let x0 = floor(x);
    let y0 = floor(y);
    let top = mix(t_behind_texel(x0, y0), t_behind_texel(x0 + 1.0, y0), x - x0);
    let bottom = mix(t_behind_texel(x0, y0 + 1.0), t_behind_texel(x0 + 1.0, y0 + 1.0), x - x0);
    return mix(top, bottom, y - y0);
}

// transparent::refract_behind: where the ray meets the surface behind (hit), else the
// direction it leaves in.
struct TBehind {
    at: vec2<f32>,
    hit: bool,
    dir: vec3<f32>,
}

fn t_refract_behind(o: vec3<f32>, d: vec3<f32>, z_near: f32, n_near: vec3<f32>, has_far: bool, z_far: f32, n_far: vec3<f32>, eta: f32, z_start: f32) -> TBehind {
    let ul = length(d);
    var u = vec3<f32>(0.0);
    if (ul > 0.0) {
        u = d / ul;
    }
    let entry = o + d * z_near;
    var exit = entry;
    var out = u;
    if (has_far) {
        let inner = refracted(u, n_near, eta, 1.0);
        var nf = n_far;
        if (dot3(n_far, inner) < 0.0) {
            nf = -n_far;
        }
        let den = dot3(inner, nf);
        var s = 0.0;
        if (den > 1e-4) {
            s = max(dot3(o + d * z_far - entry, nf) / den, 0.0);
        }
        exit = entry + inner * s;
        out = refracted(inner, -nf, 1.0 / eta, 1.0);
    }
    let missed = TBehind(vec2<f32>(0.0), false, out);
    let z_exit = dot3(exit - view.eye, view.forward);
    let along = dot3(out, view.forward);
    if (along <= 1e-6) {
        return missed;
    }
    var at = t_to_pixel(exit);
    if (at.z == 0.0) {
        return missed;
    }
    var z_hit = t_behind_depth(at.x, at.y);
    if (!(z_hit < infinity())) {
        z_hit = z_start;
    }
    if (!(z_hit < infinity())) {
        return missed;
    }
    for (var k = 0u; k < 4u; k++) {
        let s = max((z_hit - z_exit) / along, 0.0);
        at = t_to_pixel(exit + out * s);
        if (at.z == 0.0) {
            return missed;
        }
        z_hit = t_behind_depth(at.x, at.y);
        if (!(z_hit < infinity())) {
            return missed;
        }
    }
    return TBehind(at.xy, true, out);
}

// What the nearest layer at the pixel lets be seen: the surface behind, or the environment
// (transparent::Drawing::run).
fn t_seen_behind(o: vec3<f32>, d: vec3<f32>, z_near: f32, n_near: vec3<f32>, has_far: bool, z_far: f32, n_far: vec3<f32>, eta: f32, z_start: f32) -> vec3<f32> {
    let b = t_refract_behind(o, d, z_near, n_near, has_far, z_far, n_far, eta, z_start);
    if (b.hit) {
        return t_behind_colour(b.at.x, b.at.y);
    }
    return env_sample(b.dir);
}

// A group image at a pixel, all its layers composited: colour, what they let through of
// what lies behind, how many they are.
struct TLayers {
    c: vec3<f32>,
    through: f32,
    layers: f32,
}

// The index of the lowest bit set in *bits, cleared there (staged splats that meet a tile,
// groups of a fragment).
fn pop_bit(bits: ptr<function, u32>) -> u32 {
    let j = firstTrailingBit(*bits);
    *bits = *bits & (*bits - 1u);
    return j;
}

// transparent::TransparentInput::layer_colour: a layer's albedo shaded from its blended
// normal `nsum` at `depth` on the pixel's ray with point pid's object (deferred), else
// `albedo` itself (the point's own shading).
fn t_layer_colour(albedo: vec3<f32>, nsum: vec3<f32>, depth: f32, pid: u32, ro: vec3<f32>, rd: vec3<f32>) -> vec3<f32> {
    if (scomp.deferred == 0u) {
        return albedo;
    }
    var obj = 0u;
    if (pid != BACKGROUND) {
        obj = bitcast<u32>(s_splats[4u * pid + 2u].w) >> 8u;
    }
    let hit = ro + rd * depth;
    var to_eye = -view.forward;
    if (view.perspective == 1u) {
        let e = view.eye - hit;
        let len = sqrt(dot3(e, e));
        if (len > 0.0) {
            to_eye = e * (1.0 / len);
        } else {
            to_eye = vec3<f32>(0.0);
        }
    }
    var n = vec3<f32>(0.0);
    let nl = sqrt(dot3(nsum, nsum));
    if (nl > 0.0) {
        n = nsum * (1.0 / nl);
    }
    let ones = array<vec3<f32>, 4>(vec3<f32>(1.0), vec3<f32>(1.0), vec3<f32>(1.0), vec3<f32>(1.0));
    return phong_lights(albedo, n, to_eye, hit, ones, materials[obj]);
}

// transparent::Layered::composite and ::transmission, the current layer's colour `c`.
fn t_layers(s0: vec4<f32>, s1: vec4<f32>, s2: vec4<f32>, c: vec3<f32>) -> TLayers {
    var r = TLayers(s0.xyz, s2.z, s2.w);
    if (s1.w < infinity()) {
        r.c = s0.w * c + (1.0 - s0.w) * s0.xyz;
        r.through = s2.z * (1.0 - s0.w);
        r.layers = s2.w + 1.0;
    }
    return r;
}

// stipple_core::grouping::TRANSPARENT_GROUPS
const T_MAX_GROUPS: u32 = 4u;
// transparent::DRAW_SCALE
const T_DRAW_SCALE: f32 = 1.2;

// transparent::bound, operation for operation; (1, 1, 0, 0) when none.
fn t_bound(p: vec3<f32>, r: f32) -> vec4<f32> {
    let none = vec4<f32>(1.0, 1.0, 0.0, 0.0);
    let d = p - view.eye;
    let x = dot3(d, view.right);
    let y = dot3(d, view.up);
    let z = dot3(d, view.forward);
    let w = f32(view.width);
    let h = f32(view.height);
    if (z + r <= view.near) {
        return none;
    }
    var x0 = 0.0;
    var x1 = 0.0;
    var y0 = 0.0;
    var y1 = 0.0;
    var cx = 0.0;
    var cy = 0.0;
    if (view.perspective == 1u) {
        let zn = max(z - r, view.near);
        let zf = z + r;
        let zc = max(z, zn);
        x0 = (ext_lo(x - r, zn, zf) * view.sx + 1.0) * 0.5 * w - 0.5;
        x1 = (ext_hi(x + r, zn, zf) * view.sx + 1.0) * 0.5 * w - 0.5;
        y0 = (1.0 - ext_hi(y + r, zn, zf) * view.sy) * 0.5 * h - 0.5;
        y1 = (1.0 - ext_lo(y - r, zn, zf) * view.sy) * 0.5 * h - 0.5;
        cx = (x * view.sx / zc + 1.0) * 0.5 * w - 0.5;
        cy = (1.0 - y * view.sy / zc) * 0.5 * h - 0.5;
    } else {
        x0 = ((x - r) * view.sx + 1.0) * 0.5 * w - 0.5;
        x1 = ((x + r) * view.sx + 1.0) * 0.5 * w - 0.5;
        y0 = (1.0 - (y + r) * view.sy) * 0.5 * h - 0.5;
        y1 = (1.0 - (y - r) * view.sy) * 0.5 * h - 0.5;
        cx = (x * view.sx + 1.0) * 0.5 * w - 0.5;
        cy = (1.0 - y * view.sy) * 0.5 * h - 0.5;
    }
    let half = MAX_FOOTPRINT * 0.5;
    let bx0 = max(floor(max(x0, cx - half)) - 1.0, 0.0);
    let bx1 = min(ceil(min(x1, cx + half)) + 1.0, w - 1.0);
    let by0 = max(floor(max(y0, cy - half)) - 1.0, 0.0);
    let by1 = min(ceil(min(y1, cy + half)) + 1.0, h - 1.0);
    if (!(bx0 <= bx1 && by0 <= by1)) {
        return none;
    }
    return vec4<f32>(bx0, by0, bx1, by1);
}

@compute @workgroup_size(256)
fn transparent_points(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(local_invocation_index) li: u32,
) {
    let local = group_index(wg, groups) * 256u + li;
    if (local >= sc.count) {
        return;
    }
    let g = sc.base + local;
    let q = vec3<f32>(s_positions[3u * local], s_positions[3u * local + 1u], s_positions[3u * local + 2u]);
    // The groups (bits 0–7) and the radius factor in 1/256 (bits 16–31, 0: none;
    // Coverage::factor).
    let mask = t_masks[g];
    var factor = 1.0;
    if ((mask >> 16u) != 0u) {
        factor = f32(mask >> 16u) / 256.0;
    }
    let r = s_shapes[4u * local].x * sc.scale * T_DRAW_SCALE * factor;
    var n = -view.forward;
    if (sc.disc_normals == 1u) {
        n = vec3<f32>(s_normals[3u * local], s_normals[3u * local + 1u], s_normals[3u * local + 2u]);
    } else if (view.perspective == 1u) {
        n = view.eye - q;
    }
    // glam's normalize_or_zero
    let rcp = 1.0 / sqrt(dot3(n, n));
    var ok = rcp > 0.0 && rcp < infinity();
    if (ok) {
        n = n * rcp;
    }
    let st = point_style(local);
    let alpha = f32((st >> 8u) & 0xffu) / 255.0;
    let object = st & 0xffu;
    var rect = vec4<f32>(1.0, 1.0, 0.0, 0.0);
    if (ok && r > 0.0 && (mask & 0xffu) != 0u) {
        rect = t_bound(q, r);
    }
    var c = vec3<f32>(0.0);
    if (sc.deferred == 1u) {
        c = point_albedo(local);
    } else {
        c = shaded_point(local, q, object);
    }
    s_splats[4u * g] = vec4<f32>(q, r * r);
    s_splats[4u * g + 1u] = vec4<f32>(n, alpha);
    // The groups' bits, and above them the point's object (t_set_surface).
    s_splats[4u * g + 2u] = vec4<f32>(c, bitcast<f32>((mask & 0xffu) | (object << 8u)));
    s_splats[4u * g + 3u] = rect;
}

var<workgroup> t_tile_p: array<vec4<f32>, 128>;
var<workgroup> t_tile_n: array<vec4<f32>, 128>;
var<workgroup> t_tile_c: array<vec4<f32>, 128>;
var<workgroup> t_tile_r: array<vec4<f32>, 128>;
var<workgroup> t_tile_id: array<u32, 128>;
var<workgroup> t_lo: u32;
var<workgroup> t_hi: u32;
var<workgroup> t_binned: u32;
// As tile_hits: bit j set when staged splat j meets the tile.
var<workgroup> t_hits: array<array<atomic<u32>, 4>, 2>;

@compute @workgroup_size(16, 16)
fn transparent_composite(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(local_invocation_id) lid: vec3<u32>,
    @builtin(local_invocation_index) li: u32,
) {
    let px = wg.x * 16u + lid.x;
    let ty = wg.y + scomp.band_ty;
    let py = ty * 16u + lid.y;
    let inside = px < view.width && py < view.height;
    let npix = view.width * view.height;
    // The group images hold this band of tile rows only (the frame is drawn band by band
    // where all of it would not fit a binding); the surface behind, the whole frame.
    let bnpix = scomp.band_tiles * 16u * view.width;
    let bpix = (py - scomp.band_ty * 16u) * view.width + px;
    let pix = py * view.width + px;
    let tx0 = f32(wg.x * 16u);
    let ty0 = f32(ty * 16u);
    if (li == 0u) {
        let r = bin_range(ty * binp.tiles_x + wg.x, scomp.begin, min(s_counts[2u * scomp.n], scomp.end));
        t_lo = r.x;
        t_hi = r.y;
        t_binned = r.z;
    }
    let lo = workgroupUniformLoad(&t_lo);
    let hi = workgroupUniformLoad(&t_hi);
    let binned = workgroupUniformLoad(&t_binned);
    let k_groups = min(max(scomp.groups, 1u), T_MAX_GROUPS);
    // transparent::Layered per group
    var st0: array<vec4<f32>, 4>;
    var st1: array<vec4<f32>, 4>;
    var st2: array<vec4<f32>, 4>;
    // The current layer's kernel-weighted normal sum (with an environment) and, for
    // Algorithm 3, weight sum; its kernel-weighted colour and opacity sums.
    var st3: array<vec4<f32>, 4>;
    var st4: array<vec4<f32>, 4>;
    // transparent::pixel_ray
    let sxn = (2.0 * f32(px) + 1.0) / f32(view.width) - 1.0;
    let syn = 1.0 - (2.0 * f32(py) + 1.0) / f32(view.height);
    let offset = view.right * (sxn / view.sx) + view.up * (syn / view.sy);
    var ro = view.eye;
    var rd = view.forward + offset;
    if (view.perspective != 1u) {
        ro = view.eye + offset;
        rd = view.forward;
    }
    // With an environment the layers composite over black; what they let through of it is
    // added at the end (env_finish), along the refracted ray.
    var behind = sp.background;
    if (scomp.env_kind != 0u) {
        behind = vec3<f32>(0.0);
    }
    for (var g = 0u; g < k_groups; g++) {
        st0[g] = vec4<f32>(behind, 0.0);
        st1[g] = vec4<f32>(0.0, 0.0, 0.0, infinity());
        // (d/r)², point, what the layers behind let through, how many they are.
        st2[g] = vec4<f32>(0.0, bitcast<f32>(BACKGROUND), 1.0, 0.0);
        st3[g] = vec4<f32>(0.0);
        st4[g] = vec4<f32>(0.0);
    }
    if (inside && scomp.first == 0u) {
        for (var g = 0u; g < k_groups; g++) {
            let b = 5u * (g * bnpix + bpix);
            st0[g] = t_acc[b];
            st1[g] = t_acc[b + 1u];
            st2[g] = t_acc[b + 2u];
            st3[g] = t_acc[b + 3u];
            st4[g] = t_acc[b + 4u];
        }
    }
    // Refraction: the surface behind (culls the translucent fragments behind it) and the
    // farthest translucent layer (weighted normals, depth).
    t_bbase = 5u * k_groups * bnpix;
    var behind_z = infinity();
    var far = vec4<f32>(0.0, 0.0, 0.0, infinity());
    if (inside && scomp.phase == 2u) {
        behind_z = t_acc[t_bbase + pix].w;
        if (scomp.first == 0u) {
            far = t_acc[t_bbase + npix + pix];
        }
    }
    let fx = f32(px);
    let fy = f32(py);
    var base = lo;
    var round = 0u;
    loop {
        if (base >= hi) {
            break;
        }
        let buf = round & 1u;
        if (li < 128u) {
            let e = base + li;
            if (e < hi) {
                var k = e;
                if (binned == 1u) {
                    k = bin_pairs[e];
                }
                let id = s_order[k];
                let rect = s_splats[4u * id + 3u];
                // Only splats that meet the tile are staged and marked (a splat that misses
                // it costs its one test here, not one per pixel).
                if (rect.x <= rect.z && !(rect.z < tx0 || rect.x > tx0 + 15.0 || rect.w < ty0 || rect.y > ty0 + 15.0)) {
                    t_tile_p[li] = s_splats[4u * id];
                    t_tile_n[li] = s_splats[4u * id + 1u];
                    t_tile_c[li] = s_splats[4u * id + 2u];
                    t_tile_r[li] = rect;
                    t_tile_id[li] = id;
                    atomicOr(&t_hits[buf][li >> 5u], 1u << (li & 31u));
                }
            }
        }
        workgroupBarrier();
        if (li < 4u) {
            atomicStore(&t_hits[buf ^ 1u][li], 0u);
        }
        if (inside) {
            for (var w = 0u; w < 4u; w++) {
                var hit_bits = atomicLoad(&t_hits[buf][w]);
                loop {
                    if (hit_bits == 0u) {
                        break;
                    }
                    let j = 32u * w + pop_bit(&hit_bits);
                    let rect = t_tile_r[j];
                    if (fx < rect.x || fx > rect.z || fy < rect.y || fy > rect.w) {
                        continue;
                    }
                    let sp4 = t_tile_p[j];
                    let nn = t_tile_n[j];
                    // transparent::flat_hit
                    let dn = dot3(rd, nn.xyz);
                    if (dn == 0.0) {
                        continue;
                    }
                    let a = ro - sp4.xyz;
                    let t = -dot3(a, nn.xyz) / dn;
                    let hit = a + rd * t;
                    let d2 = dot3(hit, hit);
                    if (!(t > view.near && d2 < sp4.w)) {
                        continue;
                    }
                    let q = d2 / sp4.w;
                    let id = t_tile_id[j];
                    let cm = t_tile_c[j];
                    let al = nn.w;
                    // transparent::Phase: opaque fragments (α = 255/255) alone, then the
                    // translucent ones in front of them.
                    let opaque = al * 255.0 >= 254.5;
                    if ((scomp.phase == 1u && !opaque) || (scomp.phase == 2u && (opaque || t > behind_z))) {
                        continue;
                    }
                    // splat::weight: of the normal turned to the eye (an environment), and for
                    // Algorithm 3 of the colour and opacity.
                    let wq = exp(-3.0 * q);
                    var wn = vec4<f32>(0.0);
                    var wc = vec4<f32>(0.0);
                    if (scomp.env_kind != 0u || scomp.deferred == 1u) {
                        wn = vec4<f32>(wq * select(nn.xyz, -nn.xyz, dn > 0.0), 0.0);
                    }
                    if ((scomp.smooth_nearest & 2u) != 0u) {
                        wn.w = wq;
                        wc = wq * vec4<f32>(cm.xyz, al);
                    }
                    if (scomp.phase == 2u) {
                        if (!(far.w < infinity())) {
                            far = vec4<f32>(wn.xyz, t);
                        } else if (t >= far.w - scomp.epsilon) {
                            far = vec4<f32>(far.xyz + wn.xyz, far.w);
                        }
                    }
                    var bits = bitcast<u32>(cm.w) & 0xffu;
                    loop {
                        if (bits == 0u) {
                            break;
                        }
                        let g = pop_bit(&bits);
                        if (g >= k_groups) {
                            break;
                        }
                        // transparent::Layered::add
                        let depth = st1[g].w;
                        if (t < depth - scomp.epsilon) {
                            if (depth < infinity()) {
                                let s0 = st0[g];
                                let lc = t_layer_colour(st1[g].xyz, st3[g].xyz, depth, bitcast<u32>(st2[g].y), ro, rd);
                                st0[g] = vec4<f32>(s0.w * lc + (1.0 - s0.w) * s0.xyz, s0.w);
                                st2[g].z = st2[g].z * (1.0 - s0.w);
                                st2[g].w = st2[g].w + 1.0;
                            }
                            st3[g] = wn;
                            st4[g] = wc;
                        } else {
                            st3[g] = st3[g] + wn;
                            st4[g] = st4[g] + wc;
                            let cq = st2[g].x;
                            let cid = bitcast<u32>(st2[g].y);
                            if (q > cq || (q == cq && id >= cid)) {
                                continue;
                            }
                        }
                        st0[g].w = al;
                        st1[g] = vec4<f32>(cm.xyz, t);
                        st2[g] = vec4<f32>(q, bitcast<f32>(id), st2[g].z, st2[g].w);
                    }
                }
            }
        }
        workgroupBarrier();
        base = base + 128u;
        round = round + 1u;
    }
    if (inside) {
        if (scomp.last == 1u) {
            var sum = vec3<f32>(0.0);
            var dep = infinity();
            var pid = BACKGROUND;
            var through = 0.0;
            var layers = 0.0;
            for (var g = 0u; g < k_groups; g++) {
                let lc = t_layer_colour(st1[g].xyz, st3[g].xyz, st1[g].w, bitcast<u32>(st2[g].y), ro, rd);
                let all = t_layers(st0[g], st1[g], st2[g], lc);
                sum = sum + all.c;
                through = through + all.through;
                layers = layers + all.layers;
                if (st1[g].w < dep) {
                    dep = st1[g].w;
                    pid = bitcast<u32>(st2[g].y);
                }
            }
            let inv = 1.0 / f32(k_groups);
            var out = sum * inv;
            if (dep < infinity() && t_smooth_at(pid)) {
                // transparent::composite, Algorithm 3.
                let near = dep + scomp.epsilon;
                var f = vec4<f32>(0.0);
                var wsum = 0.0;
                var nsum = vec3<f32>(0.0);
                var co = vec3<f32>(0.0);
                var to = 0.0;
                var lo = 0.0;
                for (var g = 0u; g < k_groups; g++) {
                    if (st1[g].w <= near) {
                        f = f + st4[g];
                        wsum = wsum + st3[g].w;
                        nsum = nsum + st3[g].xyz;
                        co = co + st0[g].xyz;
                        to = to + st2[g].z;
                        lo = lo + st2[g].w;
                    } else {
                        let lc = t_layer_colour(st1[g].xyz, st3[g].xyz, st1[g].w, bitcast<u32>(st2[g].y), ro, rd);
                        let all = t_layers(st0[g], st1[g], st2[g], lc);
                        co = co + all.c;
                        to = to + all.through;
                        lo = lo + all.layers;
                    }
                }
                if (wsum > 0.0) {
                    let af = f.w / wsum;
                    // C_F: the blended colours (deferred: the blended albedo, shaded from
                    // the blended normal).
                    let cf = t_layer_colour(f.xyz / wsum, nsum, dep, pid, ro, rd);
                    out = af * cf + (1.0 - af) * (co * inv);
                    through = (1.0 - af) * to;
                    layers = lo + f32(k_groups);
                }
            }
            if (scomp.env_kind != 0u) {
                t_set_surface(pid);
                // The mean normal of the groups' fragments at the nearest layer, each turned
                // to the eye (transparent::composite).
                var n = vec3<f32>(0.0);
                for (var g = 0u; g < k_groups; g++) {
                    let gid = bitcast<u32>(st2[g].y);
                    if (gid != BACKGROUND && st1[g].w <= dep + scomp.epsilon) {
                        n = n + st3[g].xyz;
                    }
                }
                if (scomp.phase == 1u) {
                    // The surface behind, over the environment along the pixel's ray,
                    // reflecting it.
                    out = env_finish(out, rd, n, pid != BACKGROUND, through * inv, 0.0);
                    t_acc[t_bbase + pix] = vec4<f32>(out, dep);
                    s_depth[pix] = dep;
                    s_id[pix] = pid;
                    return;
                }
                let bd = behind_z;
                if (scomp.phase == 2u && pid == BACKGROUND) {
                    // No translucent layer: the surface behind as it is.
                    out = t_acc[t_bbase + pix].xyz;
                    dep = bd;
                    pid = s_id[pix];
                } else if (scomp.phase == 2u) {
                    let ul = length(rd);
                    let nl = length(n);
                    var nn = vec3<f32>(0.0);
                    if (nl > 0.0) {
                        nn = n / nl;
                    }
                    if (ul > 0.0 && dot3(nn, rd / ul) > 0.0) {
                        nn = -nn;
                    }
                    let fl = length(far.xyz);
                    let has_far = far.w > dep + scomp.epsilon && fl > 0.0;
                    var nf = vec3<f32>(0.0);
                    if (fl > 0.0) {
                        nf = far.xyz / fl;
                    }
                    var seen = vec3<f32>(0.0);
                    var eta = 1.0;
                    if (t_eta > 0.0) {
                        eta = t_eta;
                    }
                    if (t_disp == 0.0) {
                        seen = t_seen_behind(ro, rd, dep, nn, has_far, far.w, nf, eta, bd);
                    } else {
                        for (var ch = 0u; ch < 3u; ch++) {
                            let eta_c = eta * (1.0 + t_disp * (f32(ch) - 1.0));
                            seen[ch] = t_seen_behind(ro, rd, dep, nn, has_far, far.w, nf, eta_c, bd)[ch];
                        }
                    }
                    out = out + t_passed(through * inv, layers * inv) * seen;
                    if (t_eta > 0.0) {
                        out = reflect_into(out, rd, nn);
                    }
                } else {
                    out = env_finish(out, rd, n, pid != BACKGROUND, through * inv, layers * inv);
                }
            }
            colour[pix] = vec4<f32>(out, 1.0);
            surface_depth[pix] = dep;
            s_depth[pix] = dep;
            s_id[pix] = pid;
        } else {
            for (var g = 0u; g < k_groups; g++) {
                let b = 5u * (g * bnpix + bpix);
                t_acc[b] = st0[g];
                t_acc[b + 1u] = st1[g];
                t_acc[b + 2u] = st2[g];
                t_acc[b + 3u] = st3[g];
                t_acc[b + 4u] = st4[g];
            }
            if (scomp.phase == 2u) {
                t_acc[t_bbase + npix + pix] = far;
            }
        }
    }
}

// ---- Per-tile binning of the sorted splats (sorted and transparent composites) ----
//   bin_count  per sorted position: count the 16×16 tiles its splat reaches
//   bin_scan   one workgroup: the tiles' offsets (exclusive prefix sum) and the total
//   bin_fill   per sorted position: its index into each tile's list (unordered)
//   bin_sort   one workgroup per tile: its list sorted by position (back to front again)
// The composites then walk only their tile's list, unless the lists overflowed bin_pairs
// (the total exceeds the capacity), when they walk every splat as before.

struct BinParams {
    // First-level buckets of the sort: the points kept are at s_counts[2 n].
    n: u32,
    tiles_x: u32,
    tiles_y: u32,
    // Entries bin_pairs holds.
    capacity: u32,
    // 1: transparent splats (pixel rectangle at s_splats[4 id + 3]); 0: sorted splats
    // (centre and footprint radius in pixels at s_splats[4 id]).
    transparent: u32,
    pad0: u32,
    pad1: u32,
    pad2: u32,
}

// [0, T): per tile its count, then its fill cursor; [T, 2T]: the offsets (exclusive), the
// total at 2T. T = tiles_x · tiles_y.
@group(0) @binding(30) var<storage, read_write> bin_cnt: array<atomic<u32>>;
// Per tile its list of sorted positions, at its offset.
@group(0) @binding(31) var<storage, read_write> bin_pairs: array<u32>;
@group(0) @binding(32) var<uniform> binp: BinParams;

// The tiles (x0, y0, x1, y1) splat `id` may reach (a superset of the composites' own
// test); x0 > x1 when none.
fn bin_tiles(id: u32) -> vec4<i32> {
    let none = vec4<i32>(1, 0, 0, 0);
    var lo = vec2<f32>(0.0);
    var hi = vec2<f32>(0.0);
    if (binp.transparent == 1u) {
        let r = s_splats[4u * id + 3u];
        if (!(r.x <= r.z && r.y <= r.w)) {
            return none;
        }
        lo = r.xy;
        hi = r.zw;
    } else {
        let a = s_splats[4u * id];
        if (a.z < 0.0) {
            return none;
        }
        lo = a.xy - vec2<f32>(a.z + 1.0);
        hi = a.xy + vec2<f32>(a.z + 1.0);
    }
    let tmax = vec2<f32>(f32(binp.tiles_x) - 1.0, f32(binp.tiles_y) - 1.0);
    if (hi.x < 0.0 || hi.y < 0.0 || lo.x > (tmax.x + 1.0) * 16.0 || lo.y > (tmax.y + 1.0) * 16.0) {
        return none;
    }
    let t0 = clamp(floor(lo / 16.0), vec2<f32>(0.0), tmax);
    let t1 = clamp(floor(hi / 16.0), vec2<f32>(0.0), tmax);
    return vec4<i32>(i32(t0.x), i32(t0.y), i32(t1.x), i32(t1.y));
}

@compute @workgroup_size(256)
fn bin_count(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(local_invocation_index) li: u32,
) {
    let k = group_index(wg, groups) * 256u + li;
    if (k >= s_counts[2u * binp.n]) {
        return;
    }
    let t = bin_tiles(s_order[k]);
    for (var ty = t.y; ty <= t.w; ty++) {
        for (var tx = t.x; tx <= t.z; tx++) {
            atomicAdd(&bin_cnt[u32(ty) * binp.tiles_x + u32(tx)], 1u);
        }
    }
}

var<workgroup> bin_sums: array<u32, 256>;

@compute @workgroup_size(256)
fn bin_scan(@builtin(local_invocation_index) li: u32) {
    let tiles = binp.tiles_x * binp.tiles_y;
    let per = (tiles + 255u) / 256u;
    let first = li * per;
    var sum = 0u;
    for (var t = first; t < min(first + per, tiles); t++) {
        sum = sum + atomicLoad(&bin_cnt[t]);
    }
    bin_sums[li] = sum;
    workgroupBarrier();
    if (li == 0u) {
        var run = 0u;
        for (var i = 0u; i < 256u; i++) {
            let s = bin_sums[i];
            bin_sums[i] = run;
            run = run + s;
        }
        atomicStore(&bin_cnt[2u * tiles], run);
    }
    workgroupBarrier();
    var off = bin_sums[li];
    for (var t = first; t < min(first + per, tiles); t++) {
        let c = atomicLoad(&bin_cnt[t]);
        atomicStore(&bin_cnt[tiles + t], off);
        atomicStore(&bin_cnt[t], 0u);
        off = off + c;
    }
}

@compute @workgroup_size(256)
fn bin_fill(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(local_invocation_index) li: u32,
) {
    let k = group_index(wg, groups) * 256u + li;
    let tiles = binp.tiles_x * binp.tiles_y;
    if (k >= s_counts[2u * binp.n] || atomicLoad(&bin_cnt[2u * tiles]) > binp.capacity) {
        return;
    }
    let t = bin_tiles(s_order[k]);
    for (var ty = t.y; ty <= t.w; ty++) {
        for (var tx = t.x; tx <= t.z; tx++) {
            let tile = u32(ty) * binp.tiles_x + u32(tx);
            let slot = atomicAdd(&bin_cnt[tile], 1u);
            bin_pairs[atomicLoad(&bin_cnt[tiles + tile]) + slot] = k;
        }
    }
}

var<workgroup> bin_len: u32;

@compute @workgroup_size(256)
fn bin_sort(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(local_invocation_index) li: u32,
) {
    let tiles = binp.tiles_x * binp.tiles_y;
    let tile = wg.y * binp.tiles_x + wg.x;
    if (li == 0u) {
        bin_len = 0u;
        if (tile < tiles && atomicLoad(&bin_cnt[2u * tiles]) <= binp.capacity) {
            bin_len = atomicLoad(&bin_cnt[tile]);
        }
    }
    let n = workgroupUniformLoad(&bin_len);
    if (n < 2u) {
        return;
    }
    let base = atomicLoad(&bin_cnt[tiles + tile]);
    var p2 = 2u;
    loop {
        if (p2 >= n) {
            break;
        }
        p2 = p2 * 2u;
    }
    // Bitonic sort with every comparison ascending (each merge starts by comparing mirrored
    // positions), so the virtual padding past n (+∞) never moves and its pairs are skipped.
    var size = 2u;
    loop {
        if (size > p2) {
            break;
        }
        var half = size / 2u;
        var mirrored = true;
        loop {
            if (half == 0u) {
                break;
            }
            for (var i = li; i < p2 / 2u; i += 256u) {
                let blk = i / half;
                let pos = i % half;
                var a = 0u;
                var b = 0u;
                if (mirrored) {
                    a = blk * size + pos;
                    b = blk * size + size - 1u - pos;
                } else {
                    a = blk * 2u * half + pos;
                    b = a + half;
                }
                if (b < n) {
                    let va = bin_pairs[base + a];
                    let vb = bin_pairs[base + b];
                    if (va > vb) {
                        bin_pairs[base + a] = vb;
                        bin_pairs[base + b] = va;
                    }
                }
            }
            storageBarrier();
            mirrored = false;
            half = half / 2u;
        }
        size = size * 2u;
    }
}

// The first index of tile `tile`'s sorted list [lo, hi) whose position is at least `k`.
fn bin_lower_bound(lo_in: u32, hi_in: u32, k: u32) -> u32 {
    var lo = lo_in;
    var hi = hi_in;
    loop {
        if (lo >= hi) {
            break;
        }
        let mid = lo + (hi - lo) / 2u;
        if (bin_pairs[mid] < k) {
            lo = mid + 1u;
        } else {
            hi = mid;
        }
    }
    return lo;
}

// The entries a composite's tile walks in this dispatch: its list's entries for positions
// [begin, kept) when binned (x, y: the entries; z: 1), else the positions themselves.
fn bin_range(tile: u32, begin: u32, kept: u32) -> vec3<u32> {
    let tiles = binp.tiles_x * binp.tiles_y;
    if (binp.capacity == 0u || atomicLoad(&bin_cnt[2u * tiles]) > binp.capacity) {
        return vec3<u32>(begin, max(begin, kept), 0u);
    }
    let lo = atomicLoad(&bin_cnt[tiles + tile]);
    let hi = lo + atomicLoad(&bin_cnt[tile]);
    let a = bin_lower_bound(lo, hi, begin);
    let b = bin_lower_bound(a, hi, kept);
    return vec3<u32>(a, b, 1u);
}
