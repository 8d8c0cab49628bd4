// splat (Voronoi mode): GPU twin of passes/splat/cpu.rs; the maths of passes/splat/mod.rs,
// operation for operation. One thread per splat, four dispatches over the points:
//   splat_depth  : the nearest depth per pixel over all fragments and over those facing the
//                  eye (atomicMax of the complemented depth bits; buffers start 0); mod.rs
//                  reference turns the two into the ε-z test's reference depth
//   splat_select : among the fragments that count (mod.rs reference), the smallest (d/r)^2
//   splat_index  : among those at exactly that (d/r)^2, the smallest point index
//   splat_write  : the winning splat writes its depth and index into the G-buffer
// The result equals the CPU's lexicographic minimum of ((d/r)^2, index).
// Blend mode adds two:
//   splat_accum  : per splat, the fragments that count add their Gaussian weight, weighted
//                  depth offset, eye-facing normal and linear albedo into per-pixel
//                  fixed-point sums (integer atomics: exact and order-independent); in
//                  Voronoi mode the winner alone adds its normal and albedo with weight 1
//   splat_resolve: per pixel, after shade's gather, the normalised sums replace the pixel's
//                  depth (blend only), normal and albedo (the albedo as 8-bit sRGB, as the
//                  CPU stores it)
//   splat_pinholes: per pixel, after the resolve, a background pixel in a crack one pixel
//                  wide of a surface takes its neighbours' nearer surface (cpu::fill_pinholes)
// Deferred mode (Zhang & Pajarola §3.2) replaces all but the resolve:
//   splat_group_key      : ONE pass over the splats: per group and pixel the smallest Eq. 10
//                          key (atomicMax of its complement)
//   splat_group_id       : the smallest index among the splats with that key (ties only)
//   splat_group_composite: per pixel, Fig. 5 over the groups: z = min depth, the blend of
//                          the groups within eps, depth and id written, the sums for resolve

// Keep in sync with SplatBlock in passes/splat/gpu.rs.
struct SplatBlock {
    base: u32,
    count: u32,
    has_normals: u32,
    epsilon: f32,
    scale: f32,
    has_shapes: u32,
    has_albedo: u32,
    // Deferred blending: groups K, Eq. 6's d_min and n / (d_max - d_min); mode 2 = deferred.
    groups: u32,
    qmin: f32,
    qscale: f32,
    mode: u32,
    pad3: u32,
}

const MAX_FOOTPRINT: f32 = 256.0;

@group(0) @binding(0) var<uniform> view: View;
@group(0) @binding(1) var<uniform> blk: SplatBlock;
@group(0) @binding(2) var<storage, read> positions: array<f32>;
@group(0) @binding(3) var<storage, read> normals: array<f32>;
// Per point four vec4: (radius, A, B, C), the two clip planes and their bends into their rims
// (κ₀, s₀, κ₁, s₁); see Disc in passes/splat/mod.rs.
@group(0) @binding(4) var<storage, read> shapes: array<vec4<f32>>;
@group(0) @binding(5) var<storage, read_write> zbuf: array<atomic<u32>>;
@group(0) @binding(6) var<storage, read_write> qbuf: array<atomic<u32>>;
@group(0) @binding(7) var<storage, read_write> ibuf: array<atomic<u32>>;
@group(0) @binding(8) var<storage, read_write> depth_out: array<f32>;
@group(0) @binding(9) var<storage, read_write> id_out: array<u32>;
// Blend mode.
@group(0) @binding(10) var<storage, read> albedo: array<u32>;
@group(0) @binding(11) var<storage, read> to_linear: array<f32, 256>;
// Per pixel 8 fixed-point sums: weight, weight × (depth − reference) / eps, weight × normal (xyz,
// two's complement), weight × linear albedo (rgb).
@group(0) @binding(12) var<storage, read_write> acc: array<atomic<u32>>;
@group(0) @binding(13) var<storage, read_write> attr_pos: array<vec4<f32>>;
@group(0) @binding(14) var<storage, read_write> attr_normal: array<vec4<f32>>;

// Deferred blending: the group of every point (4 per word), the per-group keys and ids (K
// images of the frame's size), and the sRGB → linear table as a uniform.
@group(0) @binding(15) var<storage, read> group_of: array<u32>;
@group(0) @binding(16) var<storage, read_write> gkey: array<atomic<u32>>;
@group(0) @binding(17) var<storage, read_write> gid: array<atomic<u32>>;
@group(0) @binding(18) var<uniform> lin: array<vec4<f32>, 64>;
// Pinholes: shade's gathered per-pixel style (material, shadow sums), copied from a neighbour.
@group(0) @binding(19) var<storage, read_write> attr_style: array<vec4<u32>>;

// Fixed-point scale of the blend sums (passes/splat/gpu.rs FIXED).
const FIXED: f32 = 65536.0;

struct Splat {
    ok: bool,
    p: vec3<f32>,
    n: vec3<f32>,
    t1: vec3<f32>,
    t2: vec3<f32>,
    shape: vec3<f32>,
    // Disc::close (stipple_core::normals::closing_curvature of shape).
    close: f32,
    clip0: vec4<f32>,
    clip1: vec4<f32>,
    curve: vec4<f32>,
    // mod.rs Raster: au, av, ah, du, dv, dh, off as (c0, cx, cy); per clip plane in use m.o,
    // m.dir and c; flat or bent.
    l_au: vec3<f32>,
    l_av: vec3<f32>,
    l_ah: vec3<f32>,
    l_du: vec3<f32>,
    l_dv: vec3<f32>,
    l_dh: vec3<f32>,
    l_off: vec3<f32>,
    clip_o0: vec3<f32>,
    clip_d0: vec3<f32>,
    clip_o1: vec3<f32>,
    clip_d1: vec3<f32>,
    clip_c: vec2<f32>,
    // Per clip plane in use its bend into the rim (mod.rs Raster::rim): (½κ, w·t1, w·t2, s).
    rim0: vec4<f32>,
    rim1: vec4<f32>,
    clips: u32,
    bent: bool,
    r2: f32,
    x0: u32,
    y0: u32,
    x1: u32,
    y1: u32,
}

struct Frag {
    ok: bool,
    depth: f32,
    q: f32,
    u: f32,
    v: f32,
    front: bool,
}

// stipple_core::normals::tangent_frame.
fn tangent_frame(n: vec3<f32>) -> array<vec3<f32>, 2> {
    var sign = -1.0;
    if (n.z >= 0.0) {
        sign = 1.0;
    }
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    return array<vec3<f32>, 2>(
        vec3<f32>(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x),
        vec3<f32>(b, sign + n.y * n.y * a, -n.y),
    );
}

fn length_sq(a: vec3<f32>) -> f32 {
    return dot3(a, a);
}

// stipple_core::normals::closing_curvature (CLOSE_FROM = 0.5, SADDLE_FADE = 0.25).
fn closing_curvature(k: vec3<f32>, radius: f32) -> f32 {
    let m = 0.5 * (k.x + k.z);
    let d = sqrt(0.25 * (k.x - k.z) * (k.x - k.z) + k.y * k.y);
    var big = m - d;
    var small = m + d;
    if (m >= 0.0) {
        big = m + d;
        small = m - d;
    }
    if (!(abs(big) * radius >= 0.5)) {
        return 0.0;
    }
    return big * clamp(1.0 + small / (big * 0.25), 0.0, 1.0);
}

// mod.rs footprint + splat_normal.
fn load_splat(local: u32) -> Splat {
    var s: Splat;
    s.ok = false;
    if (local >= blk.count) {
        return s;
    }
    let p = vec3<f32>(positions[3u * local], positions[3u * local + 1u], positions[3u * local + 2u]);
    let sh = shapes[4u * local];
    let r = sh.x * blk.scale;
    s.p = p;
    s.r2 = r * r;
    // Disc::new.
    s.shape = vec3<f32>(0.0);
    s.clip0 = vec4<f32>(0.0);
    s.clip1 = vec4<f32>(0.0);
    s.curve = vec4<f32>(0.0);
    if (blk.has_normals == 1u) {
        let n = vec3<f32>(normals[3u * local], normals[3u * local + 1u], normals[3u * local + 2u]);
        let l2 = dot3(n, n);
        if (l2 > 0.0) {
            s.n = n * (1.0 / sqrt(l2));
        } else {
            s.n = vec3<f32>(0.0);
        }
        if (blk.has_shapes == 1u) {
            s.shape = sh.yzw;
            s.clip0 = shapes[4u * local + 1u];
            s.clip1 = shapes[4u * local + 2u];
            s.curve = shapes[4u * local + 3u];
        }
    } else if (view.perspective == 1u) {
        let e = view.eye - p;
        let l = sqrt(dot3(e, e));
        if (l > 0.0) {
            s.n = e * (1.0 / l);
        } else {
            s.n = vec3<f32>(0.0);
        }
    } else {
        s.n = -view.forward;
    }
    s.close = closing_curvature(s.shape, r);
    // mod.rs footprint.
    let d = p - view.eye;
    let x = dot3(d, view.right);
    let y = dot3(d, view.up);
    let z = dot3(d, view.forward);
    let rr = sqrt(s.r2);
    let kmax = abs(0.5 * (s.shape.x + s.shape.z))
        + sqrt(0.25 * (s.shape.x - s.shape.z) * (s.shape.x - s.shape.z) + s.shape.y * s.shape.y);
    // stipple_core::normals::patch_height.
    let qb = 0.5 * kmax * s.r2;
    let hb = 2.0 * qb / (1.0 + sqrt(max(1.0 - 2.0 * abs(s.close) * qb, 0.0)));
    let ex = footprint_ext(s.n, view.right, rr, hb);
    let ey = footprint_ext(s.n, view.up, rr, hb);
    let ez = footprint_ext(s.n, view.forward, rr, hb);
    let w = f32(view.width);
    let h = f32(view.height);
    var x0: f32;
    var x1: f32;
    var y0: f32;
    var y1: f32;
    var cx: f32;
    var cy: f32;
    if (view.perspective == 1u) {
        let zn = max(z - ez, view.near);
        let zf = z + ez;
        if (zf <= view.near) {
            return s;
        }
        let zc = max(z, zn);
        x0 = (ext_lo(x - ex, zn, zf) * view.sx + 1.0) * 0.5 * w - 0.5;
        x1 = (ext_hi(x + ex, zn, zf) * view.sx + 1.0) * 0.5 * w - 0.5;
        y0 = (1.0 - ext_hi(y + ey, zn, zf) * view.sy) * 0.5 * h - 0.5;
        y1 = (1.0 - ext_lo(y - ey, zn, zf) * view.sy) * 0.5 * h - 0.5;
        cx = (x * view.sx / zc + 1.0) * 0.5 * w - 0.5;
        cy = (1.0 - y * view.sy / zc) * 0.5 * h - 0.5;
    } else {
        if (z + ez <= view.near) {
            return s;
        }
        x0 = ((x - ex) * view.sx + 1.0) * 0.5 * w - 0.5;
        x1 = ((x + ex) * view.sx + 1.0) * 0.5 * w - 0.5;
        y0 = (1.0 - (y + ey) * view.sy) * 0.5 * h - 0.5;
        y1 = (1.0 - (y - ey) * view.sy) * 0.5 * h - 0.5;
        cx = (x * view.sx + 1.0) * 0.5 * w - 0.5;
        cy = (1.0 - y * view.sy) * 0.5 * h - 0.5;
    }
    let half = MAX_FOOTPRINT * 0.5;
    let fx0 = max(ceil(max(x0, cx - half)), 0.0);
    let fx1 = min(floor(min(x1, cx + half)), w - 1.0);
    let fy0 = max(ceil(max(y0, cy - half)), 0.0);
    let fy1 = min(floor(min(y1, cy + half)), h - 1.0);
    if (!(fx0 <= fx1 && fy0 <= fy1)) {
        return s;
    }
    s.ok = true;
    s.x0 = u32(fx0);
    s.y0 = u32(fy0);
    s.x1 = u32(fx1);
    s.y1 = u32(fy1);
    let tf = tangent_frame(s.n);
    s.t1 = tf[0];
    s.t2 = tf[1];
    raster_setup(&s);
    return s;
}

// footprint's half-extent of a splat along camera axis a.
fn footprint_ext(n: vec3<f32>, a: vec3<f32>, r: f32, hb: f32) -> f32 {
    let c = min(abs(dot3(n, a)), 1.0);
    return r * sqrt(max(1.0 - c * c, 0.0)) + hb * c;
}

fn proj(v0: vec3<f32>, vx: vec3<f32>, vy: vec3<f32>, axis: vec3<f32>) -> vec3<f32> {
    return vec3<f32>(dot3(v0, axis), dot3(vx, axis), dot3(vy, axis));
}

// mod.rs Raster::new's bend of clip plane m into its rim, (κ, s) → (½κ, w·t1, w·t2, s) with
// w = n × m normalised (all zero for a flat plane).
fn rim_of(s: Splat, m: vec3<f32>, k: vec2<f32>) -> vec4<f32> {
    if (k.x == 0.0) {
        return vec4<f32>(0.0);
    }
    let n = s.n;
    let c = vec3<f32>(n.y * m.z - n.z * m.y, n.z * m.x - n.x * m.z, n.x * m.y - n.y * m.x);
    let l = dot3(c, c);
    var w = vec3<f32>(0.0);
    if (l > 0.0) {
        w = c * (1.0 / sqrt(l));
    }
    return vec4<f32>(0.5 * k.x, dot3(w, s.t1), dot3(w, s.t2), k.y);
}

// mod.rs Raster::new, operation for operation.
fn raster_setup(s: ptr<function, Splat>) {
    let w = f32(view.width);
    let h = f32(view.height);
    let ox = view.right * (2.0 / w / view.sx);
    let oy = view.up * (-2.0 / h / view.sy);
    let o0 = view.right * ((1.0 / w - 1.0) / view.sx) + view.up * ((1.0 - 1.0 / h) / view.sy);
    let zero = vec3<f32>(0.0);
    var orig0 = view.eye;
    var orig1 = zero;
    var orig2 = zero;
    var dir0 = view.forward + o0;
    var dir1 = ox;
    var dir2 = oy;
    if (view.perspective != 1u) {
        orig0 = view.eye + o0;
        orig1 = ox;
        orig2 = oy;
        dir0 = view.forward;
        dir1 = zero;
        dir2 = zero;
    }
    let a0 = orig0 - (*s).p;
    var off = zero;
    if (view.perspective != 1u) {
        off = proj(orig0 - view.eye, orig1, orig2, view.forward);
    }
    (*s).l_au = proj(a0, orig1, orig2, (*s).t1);
    (*s).l_av = proj(a0, orig1, orig2, (*s).t2);
    (*s).l_ah = proj(a0, orig1, orig2, (*s).n);
    (*s).l_du = proj(dir0, dir1, dir2, (*s).t1);
    (*s).l_dv = proj(dir0, dir1, dir2, (*s).t2);
    (*s).l_dh = proj(dir0, dir1, dir2, (*s).n);
    (*s).l_off = off;
    // The planes in use first (Raster keeps them in order).
    var clips = 0u;
    let p0 = (*s).clip0;
    let p1 = (*s).clip1;
    (*s).rim0 = vec4<f32>(0.0);
    (*s).rim1 = vec4<f32>(0.0);
    if (any(p0 != vec4<f32>(0.0))) {
        (*s).clip_o0 = proj(orig0, orig1, orig2, p0.xyz);
        (*s).clip_d0 = proj(dir0, dir1, dir2, p0.xyz);
        (*s).clip_c.x = p0.w;
        (*s).rim0 = rim_of(*s, p0.xyz, (*s).curve.xy);
        clips = 1u;
    }
    if (any(p1 != vec4<f32>(0.0))) {
        if (clips == 0u) {
            (*s).clip_o0 = proj(orig0, orig1, orig2, p1.xyz);
            (*s).clip_d0 = proj(dir0, dir1, dir2, p1.xyz);
            (*s).clip_c.x = p1.w;
            (*s).rim0 = rim_of(*s, p1.xyz, (*s).curve.zw);
        } else {
            (*s).clip_o1 = proj(orig0, orig1, orig2, p1.xyz);
            (*s).clip_d1 = proj(dir0, dir1, dir2, p1.xyz);
            (*s).clip_c.y = p1.w;
            (*s).rim1 = rim_of(*s, p1.xyz, (*s).curve.zw);
        }
        clips = clips + 1u;
    }
    (*s).clips = clips;
    (*s).bent = any((*s).shape != vec3<f32>(0.0));
}

fn affine(c: vec3<f32>, x: f32, y: f32) -> f32 {
    return c.x + c.y * x + c.z * y;
}

// mod.rs Raster::hit.
fn raster_hit(s: Splat, t: f32, au: f32, av: f32, du: f32, dv: f32, dh: f32, off: f32, x: f32, y: f32) -> Frag {
    var f: Frag;
    f.ok = false;
    let depth = t + off;
    let u = au + t * du;
    let w = av + t * dv;
    let d2 = u * u + w * w;
    if (!(depth > view.near && d2 < s.r2)) {
        return f;
    }
    let along0 = s.rim0.y * u + s.rim0.z * w - s.rim0.w;
    if (s.clips > 0u && affine(s.clip_o0, x, y) + t * affine(s.clip_d0, x, y) + s.rim0.x * along0 * along0 > s.clip_c.x) {
        return f;
    }
    let along1 = s.rim1.y * u + s.rim1.z * w - s.rim1.w;
    if (s.clips > 1u && affine(s.clip_o1, x, y) + t * affine(s.clip_d1, x, y) + s.rim1.x * along1 * along1 > s.clip_c.y) {
        return f;
    }
    f.ok = true;
    f.depth = depth;
    f.q = d2 / s.r2;
    f.u = u;
    f.v = w;
    f.front = dh < 0.0;
    return f;
}

// mod.rs Raster::eval.
fn fragment(s: Splat, i: u32, j: u32) -> Frag {
    let x = f32(i);
    let y = f32(j);
    let au = affine(s.l_au, x, y);
    let av = affine(s.l_av, x, y);
    let ah = affine(s.l_ah, x, y);
    let du = affine(s.l_du, x, y);
    let dv = affine(s.l_dv, x, y);
    let dh = affine(s.l_dh, x, y);
    let off = affine(s.l_off, x, y);
    if (!s.bent) {
        return raster_hit(s, -ah / dh, au, av, du, dv, dh, off, x, y);
    }
    var f: Frag;
    f.ok = false;
    let ka = s.shape.x;
    let kb = s.shape.y;
    let kc = s.shape.z;
    let kd = s.close;
    var qd = 0.5 * (ka * du * du + kc * dv * dv) + kb * du * dv;
    var l = ka * au * du + kb * (au * dv + av * du) + kc * av * dv;
    var qa = 0.5 * (ka * au * au + kc * av * av) + kb * au * av;
    if (kd != 0.0) {
        qd = qd + 0.5 * kd * dh * dh;
        l = l + kd * ah * dh;
        qa = qa + 0.5 * kd * ah * ah;
    }
    let b = l - dh;
    let c = qa - ah;
    let disc = b * b - 4.0 * qd * c;
    if (!(disc >= 0.0)) {
        return f;
    }
    var sq = sqrt(disc);
    if (!(b >= 0.0)) {
        sq = -sq;
    }
    let root = -0.5 * (b + sq);
    if (root == 0.0) {
        return f;
    }
    var ta = c / root;
    var tb = root / qd;
    if (tb < ta) {
        let tmp = ta;
        ta = tb;
        tb = tmp;
    }
    // The closed surface's near half, D h < 1.
    if (kd == 0.0 || kd * (ah + ta * dh) < 1.0) {
        let first = raster_hit(s, ta, au, av, du, dv, dh, off, x, y);
        if (first.ok) {
            return first;
        }
    }
    if (!(kd == 0.0 || kd * (ah + tb * dh) < 1.0)) {
        return f;
    }
    return raster_hit(s, tb, au, av, du, dv, dh, off, x, y);
}

fn splat_index_of(wg: vec3<u32>, groups: vec3<u32>, li: u32) -> u32 {
    return group_index(wg, groups) * 64u + li;
}

// mod.rs reference: (reference depth, 1 when only eye-facing fragments count) of a pixel,
// from the nearest depth over all fragments (zbuf[2k]) and over eye-facing ones (zbuf[2k+1]).
fn reference(pixel: u32) -> vec2<f32> {
    let za = bitcast<f32>(~atomicLoad(&zbuf[2u * pixel]));
    let zf = bitcast<f32>(~atomicLoad(&zbuf[2u * pixel + 1u]));
    if (is_finite(zf) && za >= zf - blk.epsilon) {
        return vec2<f32>(zf, 1.0);
    }
    return vec2<f32>(za, 0.0);
}

fn counts(f: Frag, pixel: u32) -> bool {
    let r = reference(pixel);
    return f.ok && f.depth <= r.x + blk.epsilon && (f.front || r.y == 0.0);
}

@compute @workgroup_size(64)
fn splat_depth(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(local_invocation_index) li: u32,
) {
    let local = splat_index_of(wg, groups, li);
    let s = load_splat(local);
    if (!s.ok) {
        return;
    }
    for (var y = s.y0; y <= s.y1; y++) {
        for (var x = s.x0; x <= s.x1; x++) {
            let f = fragment(s, x, y);
            if (f.ok) {
                let key = ~bitcast<u32>(f.depth);
                let k = y * view.width + x;
                if (key > atomicLoad(&zbuf[2u * k])) {
                    atomicMax(&zbuf[2u * k], key);
                }
                if (f.front && key > atomicLoad(&zbuf[2u * k + 1u])) {
                    atomicMax(&zbuf[2u * k + 1u], key);
                }
            }
        }
    }
}

@compute @workgroup_size(64)
fn splat_select(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(local_invocation_index) li: u32,
) {
    let local = splat_index_of(wg, groups, li);
    let s = load_splat(local);
    if (!s.ok) {
        return;
    }
    for (var y = s.y0; y <= s.y1; y++) {
        for (var x = s.x0; x <= s.x1; x++) {
            let f = fragment(s, x, y);
            let k = y * view.width + x;
            if (counts(f, k)) {
                atomicMax(&qbuf[k], ~bitcast<u32>(f.q));
            }
        }
    }
}

@compute @workgroup_size(64)
fn splat_index(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(local_invocation_index) li: u32,
) {
    let local = splat_index_of(wg, groups, li);
    let s = load_splat(local);
    if (!s.ok) {
        return;
    }
    for (var y = s.y0; y <= s.y1; y++) {
        for (var x = s.x0; x <= s.x1; x++) {
            let f = fragment(s, x, y);
            let k = y * view.width + x;
            if (counts(f, k) && ~bitcast<u32>(f.q) == atomicLoad(&qbuf[k])) {
                atomicMax(&ibuf[k], ~(blk.base + local));
            }
        }
    }
}

@compute @workgroup_size(64)
fn splat_write(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(local_invocation_index) li: u32,
) {
    let local = splat_index_of(wg, groups, li);
    let s = load_splat(local);
    if (!s.ok) {
        return;
    }
    let id = blk.base + local;
    for (var y = s.y0; y <= s.y1; y++) {
        for (var x = s.x0; x <= s.x1; x++) {
            let k = y * view.width + x;
            if (~atomicLoad(&ibuf[k]) == id) {
                let f = fragment(s, x, y);
                depth_out[k] = f.depth;
                id_out[k] = id;
            }
        }
    }
}

// Background where no splat won: runs per pixel before splat_write.
@compute @workgroup_size(256)
fn splat_clear(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(local_invocation_index) li: u32,
) {
    let k = group_index(wg, groups) * 256u + li;
    if (k >= view.width * view.height) {
        return;
    }
    depth_out[k] = infinity();
    id_out[k] = BACKGROUND;
}

// Disc::normal_at, turned towards the eye along the pixel's ray (mod.rs / cpu.rs blend).
fn blend_normal(s: Splat, f: Frag, i: u32, j: u32) -> vec3<f32> {
    var up = s.n;
    if (s.close != 0.0) {
        let q = 0.5 * (s.shape.x * f.u * f.u + s.shape.z * f.v * f.v) + s.shape.y * f.u * f.v;
        up = up * sqrt(max(1.0 - 2.0 * s.close * q, 0.0));
    }
    let m = up - (s.shape.x * f.u + s.shape.y * f.v) * s.t1 - (s.shape.y * f.u + s.shape.z * f.v) * s.t2;
    let l2 = dot3(m, m);
    var n = vec3<f32>(0.0);
    if (l2 > 0.0) {
        n = m * (1.0 / sqrt(l2));
    }
    let nx = 2.0 * (f32(i) + 0.5) / f32(view.width) - 1.0;
    let ny = 1.0 - 2.0 * (f32(j) + 0.5) / f32(view.height);
    var dir = view.forward;
    if (view.perspective == 1u) {
        dir = view.forward + view.right * (nx / view.sx) + view.up * (ny / view.sy);
    }
    if (dot3(n, dir) > 0.0) {
        n = -n;
    }
    return n;
}

fn fixed_u(x: f32) -> u32 {
    return u32(max(x, 0.0) * FIXED + 0.5);
}

fn fixed_i(x: f32) -> u32 {
    return bitcast<u32>(i32(round(x * FIXED)));
}

@compute @workgroup_size(64)
fn splat_accum(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(local_invocation_index) li: u32,
) {
    let local = splat_index_of(wg, groups, li);
    let s = load_splat(local);
    if (!s.ok) {
        return;
    }
    var c = vec3<f32>(0.0);
    if (blk.has_albedo == 1u) {
        let a = albedo[local];
        c = vec3<f32>(to_linear[a & 0xffu], to_linear[(a >> 8u) & 0xffu], to_linear[(a >> 16u) & 0xffu]);
    }
    let id = blk.base + local;
    for (var y = s.y0; y <= s.y1; y++) {
        for (var x = s.x0; x <= s.x1; x++) {
            let k = y * view.width + x;
            // Voronoi: the pixel's winner alone, weight 1 (its normal at the hit and its
            // albedo; the depth is splat_write's).
            if (blk.mode == 0u && ~atomicLoad(&ibuf[k]) != id) {
                continue;
            }
            let f = fragment(s, x, y);
            if (!counts(f, k)) {
                continue;
            }
            let z0 = reference(k).x;
            // mod.rs weight
            var wt = exp(-3.0 * f.q);
            if (blk.mode == 0u) {
                wt = 1.0;
            }
            let n = blend_normal(s, f, x, y);
            var dz = 0.0;
            if (blk.epsilon > 0.0) {
                dz = clamp((f.depth - z0) / blk.epsilon, 0.0, 1.0);
            }
            let b = 8u * k;
            atomicAdd(&acc[b], fixed_u(wt));
            atomicAdd(&acc[b + 1u], fixed_u(wt * dz));
            atomicAdd(&acc[b + 2u], fixed_i(wt * n.x));
            atomicAdd(&acc[b + 3u], fixed_i(wt * n.y));
            atomicAdd(&acc[b + 4u], fixed_i(wt * n.z));
            if (blk.has_albedo == 1u) {
                atomicAdd(&acc[b + 5u], fixed_u(wt * c.x));
                atomicAdd(&acc[b + 6u], fixed_u(wt * c.y));
                atomicAdd(&acc[b + 7u], fixed_u(wt * c.z));
            }
        }
    }
}

// shade::linear_to_srgb8.
fn srgb8(c: f32) -> u32 {
    let x = clamp(c, 0.0, 1.0);
    var s: f32;
    if (x <= 0.0031308) {
        s = x * 12.92;
    } else {
        s = 1.055 * pow(x, 1.0 / 2.4) - 0.055;
    }
    return u32(s * 255.0 + 0.5);
}

@compute @workgroup_size(256)
fn splat_resolve(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(local_invocation_index) li: u32,
) {
    let k = group_index(wg, groups) * 256u + li;
    if (k >= view.width * view.height) {
        return;
    }
    let b = 8u * k;
    let w = atomicLoad(&acc[b]);
    if (w == 0u) {
        return;
    }
    let wf = f32(w);
    if (blk.mode == 1u) {
        depth_out[k] = reference(k).x + blk.epsilon * (f32(atomicLoad(&acc[b + 1u])) / wf);
    }
    let n = vec3<f32>(
        f32(bitcast<i32>(atomicLoad(&acc[b + 2u]))),
        f32(bitcast<i32>(atomicLoad(&acc[b + 3u]))),
        f32(bitcast<i32>(atomicLoad(&acc[b + 4u]))),
    );
    let l2 = dot3(n, n);
    if (l2 > 0.0) {
        attr_normal[k] = vec4<f32>(n * (1.0 / sqrt(l2)), 0.0);
    }
    if (blk.has_albedo == 1u) {
        let r = srgb8(f32(atomicLoad(&acc[b + 5u])) / wf);
        let g = srgb8(f32(atomicLoad(&acc[b + 6u])) / wf);
        let bl = srgb8(f32(atomicLoad(&acc[b + 7u])) / wf);
        let a = attr_pos[k];
        attr_pos[k] = vec4<f32>(a.xyz, bitcast<f32>(r | (g << 8u) | (bl << 16u)));
    }
}

// Covered by the splats (their weight: a fill never writes it).
fn drawn(j: u32) -> bool {
    return atomicLoad(&acc[8u * j]) != 0u;
}

// cpu::pinhole_group: of the four neighbours of pixel k (above, left, right, below) the
// covered ones within epsilon of the nearest covered depth (the nearest first; ties: the
// first); count 0 unless two opposite neighbours are covered and within epsilon of each
// other, or where k lies on the image's border.
struct Pinhole {
    group: array<u32, 4>,
    count: u32,
}

fn pinhole_group(k: u32) -> Pinhole {
    var p: Pinhole;
    p.count = 0u;
    let w = view.width;
    let x = k % w;
    let y = k / w;
    if (x == 0u || y == 0u || x + 1u >= w || y + 1u >= view.height) {
        return p;
    }
    let nb = array<u32, 4>(k - w, k - 1u, k + 1u, k + w);
    let on = array<bool, 4>(drawn(nb[0]), drawn(nb[1]), drawn(nb[2]), drawn(nb[3]));
    let d = array<f32, 4>(depth_out[nb[0]], depth_out[nb[1]], depth_out[nb[2]], depth_out[nb[3]]);
    let vertical = on[0] && on[3] && abs(d[0] - d[3]) <= blk.epsilon;
    let horizontal = on[1] && on[2] && abs(d[1] - d[2]) <= blk.epsilon;
    if (!(vertical || horizontal)) {
        return p;
    }
    var near = 4u;
    for (var a = 0u; a < 4u; a++) {
        if (on[a] && (near == 4u || d[a] < d[near])) {
            near = a;
        }
    }
    p.group = array<u32, 4>(nb[near], nb[near], nb[near], nb[near]);
    p.count = 1u;
    for (var a = 0u; a < 4u; a++) {
        if (a != near && on[a] && d[a] <= d[near] + blk.epsilon) {
            p.group[p.count] = nb[a];
            p.count += 1u;
        }
    }
    return p;
}

// cpu::fill_pinholes: after the resolve (the frame's depths, normals and albedos final), a
// background pixel in a crack one pixel wide of one surface (pinhole_group) takes the nearer
// surface among its neighbours: their mean depth and normal, and the nearest one's point
// (its gathered position and style) and albedo. It reads only pixels the splats covered, which
// no fill writes: no order matters.
@compute @workgroup_size(256)
fn splat_pinholes(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(local_invocation_index) li: u32,
) {
    let k = group_index(wg, groups) * 256u + li;
    if (k >= view.width * view.height || id_out[k] != BACKGROUND) {
        return;
    }
    let p = pinhole_group(k);
    if (p.count == 0u) {
        return;
    }
    var sum = 0.0;
    var n = vec3<f32>(0.0);
    for (var a = 0u; a < p.count; a++) {
        let j = p.group[a];
        sum += depth_out[j];
        n += attr_normal[j].xyz;
    }
    let first = p.group[0];
    depth_out[k] = sum / f32(p.count);
    id_out[k] = id_out[first];
    attr_style[k] = attr_style[first];
    let l2 = dot3(n, n);
    if (l2 > 0.0) {
        attr_normal[k] = vec4<f32>(n * (1.0 / sqrt(l2)), 0.0);
    } else {
        attr_normal[k] = attr_normal[first];
    }
    // The nearest one's position (its point's) and albedo.
    attr_pos[k] = attr_pos[first];
}

// DepthQuant::key (mod.rs).
fn quant_key(depth: f32, q: f32, front: bool) -> u32 {
    let level = u32(clamp(floor((depth - blk.qmin) * blk.qscale), 0.0, 65535.0));
    let vor = u32(clamp(floor(q * 32768.0), 0.0, 32767.0));
    var back = 1u;
    if (front) {
        back = 0u;
    }
    return (level << 16u) | (back << 15u) | vor;
}

fn group_image(local: u32, pixel: u32) -> u32 {
    let g = (group_of[local >> 2u] >> (8u * (local & 3u))) & 0xffu;
    return g * view.width * view.height + pixel;
}

@compute @workgroup_size(64)
fn splat_group_key(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(local_invocation_index) li: u32,
) {
    let local = splat_index_of(wg, groups, li);
    let s = load_splat(local);
    if (!s.ok) {
        return;
    }
    for (var y = s.y0; y <= s.y1; y++) {
        for (var x = s.x0; x <= s.x1; x++) {
            let f = fragment(s, x, y);
            if (f.ok) {
                let at = group_image(local, y * view.width + x);
                let key = ~quant_key(f.depth, f.q, f.front);
                if (key > atomicLoad(&gkey[at])) {
                    atomicMax(&gkey[at], key);
                }
            }
        }
    }
}

@compute @workgroup_size(64)
fn splat_group_id(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(local_invocation_index) li: u32,
) {
    let local = splat_index_of(wg, groups, li);
    let s = load_splat(local);
    if (!s.ok) {
        return;
    }
    for (var y = s.y0; y <= s.y1; y++) {
        for (var x = s.x0; x <= s.x1; x++) {
            let f = fragment(s, x, y);
            if (f.ok) {
                let at = group_image(local, y * view.width + x);
                if (~quant_key(f.depth, f.q, f.front) == atomicLoad(&gkey[at])) {
                    atomicMax(&gid[at], ~(blk.base + local));
                }
            }
        }
    }
}

fn lin_of(c: u32) -> f32 {
    return lin[c >> 2u][c & 3u];
}

@compute @workgroup_size(8, 8)
fn splat_group_composite(@builtin(global_invocation_id) gid3: vec3<u32>) {
    if (gid3.x >= view.width || gid3.y >= view.height) {
        return;
    }
    let k = gid3.y * view.width + gid3.x;
    let pixels = view.width * view.height;
    // z: the nearest depth over the groups' winners.
    var za = infinity();
    var zf = infinity();
    for (var g = 0u; g < blk.groups; g++) {
        let w = atomicLoad(&gid[g * pixels + k]);
        if (w != 0u) {
            let f = fragment(load_splat(~w - blk.base), gid3.x, gid3.y);
            if (f.ok) {
                za = min(za, f.depth);
                if (f.front) {
                    zf = min(zf, f.depth);
                }
            }
        }
    }
    // mod.rs reference.
    var z = za;
    var front_only = false;
    if (is_finite(zf) && za >= zf - blk.epsilon) {
        z = zf;
        front_only = true;
    }
    var sw = 0.0;
    var sd = 0.0;
    var sn = vec3<f32>(0.0);
    var sc = vec3<f32>(0.0);
    var top = 0.0;
    var top_id = 0xffffffffu;
    for (var g = 0u; g < blk.groups; g++) {
        let w = atomicLoad(&gid[g * pixels + k]);
        if (w == 0u) {
            continue;
        }
        let id = ~w;
        let local = id - blk.base;
        let s = load_splat(local);
        let f = fragment(s, gid3.x, gid3.y);
        if (!f.ok || !(f.depth <= z + blk.epsilon) || (front_only && !f.front)) {
            continue;
        }
        let wt = exp(-3.0 * f.q);
        let n = blend_normal(s, f, gid3.x, gid3.y);
        sw = sw + wt;
        sd = sd + wt * f.depth;
        sn = sn + wt * n;
        if (blk.has_albedo == 1u) {
            let a = albedo[local];
            sc = sc + wt * vec3<f32>(lin_of(a & 0xffu), lin_of((a >> 8u) & 0xffu), lin_of((a >> 16u) & 0xffu));
        }
        if (wt > top || (wt == top && id < top_id)) {
            top = wt;
            top_id = id;
        }
    }
    let b = 8u * k;
    if (sw > 0.0) {
        depth_out[k] = sd / sw;
        id_out[k] = top_id;
        // The sums for splat_resolve, in its fixed point (normalised by the weight there).
        let inv = 1.0 / sw;
        atomicStore(&acc[b], fixed_u(1.0));
        atomicStore(&acc[b + 2u], fixed_i(sn.x * inv));
        atomicStore(&acc[b + 3u], fixed_i(sn.y * inv));
        atomicStore(&acc[b + 4u], fixed_i(sn.z * inv));
        atomicStore(&acc[b + 5u], fixed_u(sc.x * inv));
        atomicStore(&acc[b + 6u], fixed_u(sc.y * inv));
        atomicStore(&acc[b + 7u], fixed_u(sc.z * inv));
    } else {
        depth_out[k] = infinity();
        id_out[k] = BACKGROUND;
        atomicStore(&acc[b], 0u);
    }
}
