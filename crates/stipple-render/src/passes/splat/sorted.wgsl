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
    pad0: u32,
    pad1: u32,
    pad2: u32,
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
// (radius, bend…) and the clip planes: three vec4 per point (the splat pass's shapes).
@group(0) @binding(17) var<storage, read> s_shapes: array<vec4<f32>>;
// Per point of the cloud: (centre x, centre y, radius, depth), (linear colour, τ).
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
    let raw = s_shapes[3u * local].x * sc.scale * per;
    let rho = clamp(raw, SORTED_MIN_RADIUS, MAX_FOOTPRINT / 2.0);
    var alpha = 1.0;
    var object = 0u;
    if (sc.has_style == 1u) {
        let st = s_style[local];
        alpha = f32((st >> 8u) & 0xffu) / 255.0;
        object = st & 0xffu;
    }
    var widened = 1.0;
    if (raw > 0.0) {
        widened = rho / raw;
    }
    let w_sum = sc.overlap * widened * widened;
    let tau = -log(1.0 - min(alpha, SORTED_MAX_ALPHA)) / max(w_sum, 1e-6);
    // shade::cpu::shade_points
    var albedo = sp.base_colour;
    if (sc.has_albedo == 1u) {
        let bits = s_albedo[local];
        albedo = vec3<f32>(to_linear[bits & 0xffu], to_linear[(bits >> 8u) & 0xffu], to_linear[(bits >> 16u) & 0xffu]);
    }
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
    let g = sc.base + local;
    s_splats[2u * g] = vec4<f32>(fx, fy, rho, z);
    s_splats[2u * g + 1u] = vec4<f32>(c, tau);
}

var<workgroup> tile_a: array<vec4<f32>, 256>;
var<workgroup> tile_b: array<vec4<f32>, 256>;
var<workgroup> tile_id: array<u32, 256>;
var<workgroup> tile_kept: u32;

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
        tile_kept = min(s_counts[2u * scomp.n], scomp.end);
    }
    let kept = workgroupUniformLoad(&tile_kept);
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
    var base = scomp.begin;
    loop {
        if (base >= kept) {
            break;
        }
        let k = base + li;
        var a = vec4<f32>(0.0, 0.0, -1.0, 0.0);
        var b = vec4<f32>(0.0);
        var id = 0u;
        if (k < kept) {
            id = s_order[k];
            a = s_splats[2u * id];
            b = s_splats[2u * id + 1u];
            // A splat that misses the tile is skipped by every thread.
            if (a.x + a.z < tx0 || a.x - a.z > tx0 + 16.0 || a.y + a.z < ty0 || a.y - a.z > ty0 + 16.0) {
                a.z = -1.0;
            }
        }
        tile_a[li] = a;
        tile_b[li] = b;
        tile_id[li] = id;
        workgroupBarrier();
        let m = min(256u, kept - base);
        if (inside) {
            for (var j = 0u; j < m; j++) {
                let s = tile_a[j];
                if (s.z < 0.0) {
                    continue;
                }
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
        workgroupBarrier();
        base = base + 256u;
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
