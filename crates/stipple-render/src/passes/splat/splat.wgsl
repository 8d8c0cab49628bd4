// splat (Voronoi mode): GPU twin of passes/splat/cpu.rs; the maths of passes/splat/mod.rs,
// operation for operation. One thread per splat, four dispatches over the points:
//   splat_depth  : z_min per pixel (atomicMax of the complemented depth bits; buffers start 0)
//   splat_select : among fragments with depth <= z_min + eps, the smallest (d/r)^2 (bits)
//   splat_index  : among those at exactly that (d/r)^2, the smallest point index
//   splat_write  : the winning splat writes its depth and index into the G-buffer
// The result equals the CPU's lexicographic minimum of ((d/r)^2, index).

// Keep in sync with SplatBlock in passes/splat/gpu.rs.
struct SplatBlock {
    base: u32,
    count: u32,
    has_normals: u32,
    epsilon: f32,
    scale: f32,
    pad0: u32,
    pad1: u32,
    pad2: u32,
}

const MAX_FOOTPRINT: f32 = 256.0;

@group(0) @binding(0) var<uniform> view: View;
@group(0) @binding(1) var<uniform> blk: SplatBlock;
@group(0) @binding(2) var<storage, read> positions: array<f32>;
@group(0) @binding(3) var<storage, read> normals: array<f32>;
@group(0) @binding(4) var<storage, read> radii: array<f32>;
@group(0) @binding(5) var<storage, read_write> zbuf: array<atomic<u32>>;
@group(0) @binding(6) var<storage, read_write> qbuf: array<atomic<u32>>;
@group(0) @binding(7) var<storage, read_write> ibuf: array<atomic<u32>>;
@group(0) @binding(8) var<storage, read_write> depth_out: array<f32>;
@group(0) @binding(9) var<storage, read_write> id_out: array<u32>;

struct Splat {
    ok: bool,
    p: vec3<f32>,
    n: vec3<f32>,
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
}

fn length_sq(a: vec3<f32>) -> f32 {
    return dot3(a, a);
}

// mod.rs footprint + splat_normal.
fn load_splat(local: u32) -> Splat {
    var s: Splat;
    s.ok = false;
    if (local >= blk.count) {
        return s;
    }
    let p = vec3<f32>(positions[3u * local], positions[3u * local + 1u], positions[3u * local + 2u]);
    let r = radii[local] * blk.scale;
    let d = p - view.eye;
    let z = dot3(d, view.forward);
    let w = f32(view.width);
    let h = f32(view.height);
    let x = dot3(d, view.right);
    let y = dot3(d, view.up);
    var cx: f32;
    var cy: f32;
    var rx: f32;
    var ry: f32;
    if (view.perspective == 1u) {
        if (z - r <= view.near) {
            return s;
        }
        cx = (x * view.sx / z + 1.0) * 0.5 * w - 0.5;
        cy = (1.0 - y * view.sy / z) * 0.5 * h - 0.5;
        rx = r * view.sx * 0.5 * w / (z - r);
        ry = r * view.sy * 0.5 * h / (z - r);
    } else {
        if (z <= view.near) {
            return s;
        }
        cx = (x * view.sx + 1.0) * 0.5 * w - 0.5;
        cy = (1.0 - y * view.sy) * 0.5 * h - 0.5;
        rx = r * view.sx * 0.5 * w;
        ry = r * view.sy * 0.5 * h;
    }
    let half = MAX_FOOTPRINT * 0.5;
    rx = min(rx, half);
    ry = min(ry, half);
    let x0 = max(ceil(cx - rx), 0.0);
    let x1 = min(floor(cx + rx), w - 1.0);
    let y0 = max(ceil(cy - ry), 0.0);
    let y1 = min(floor(cy + ry), h - 1.0);
    if (!(x0 <= x1 && y0 <= y1)) {
        return s;
    }
    s.ok = true;
    s.p = p;
    s.r2 = r * r;
    s.x0 = u32(x0);
    s.y0 = u32(y0);
    s.x1 = u32(x1);
    s.y1 = u32(y1);
    if (blk.has_normals == 1u) {
        s.n = vec3<f32>(normals[3u * local], normals[3u * local + 1u], normals[3u * local + 2u]);
    } else if (view.perspective == 1u) {
        let e = view.eye - p;
        let l = sqrt(dot3(e, e));
        if (l > 0.0) {
            s.n = e / l;
        } else {
            s.n = vec3<f32>(0.0);
        }
    } else {
        s.n = -view.forward;
    }
    return s;
}

// ViewParams::pixel_ray + mod.rs fragment.
fn fragment(s: Splat, i: u32, j: u32) -> Frag {
    var f: Frag;
    f.ok = false;
    let nx = 2.0 * (f32(i) + 0.5) / f32(view.width) - 1.0;
    let ny = 1.0 - 2.0 * (f32(j) + 0.5) / f32(view.height);
    let off = view.right * (nx / view.sx) + view.up * (ny / view.sy);
    var o = view.eye;
    var dir = view.forward;
    if (view.perspective == 1u) {
        dir = view.forward + off;
    } else {
        o = view.eye + off;
    }
    let nd = dot3(s.n, dir);
    if (abs(nd) < 1e-6 * sqrt(dot3(dir, dir))) {
        return f;
    }
    let t = dot3(s.n, s.p - o) / nd;
    let hit = o + dir * t;
    let d2 = length_sq(hit - s.p);
    if (!(d2 < s.r2)) {
        return f;
    }
    var depth = t;
    if (view.perspective != 1u) {
        depth = t + dot3(o - view.eye, view.forward);
    }
    if (!(depth > view.near)) {
        return f;
    }
    f.ok = true;
    f.depth = depth;
    f.q = d2 / s.r2;
    return f;
}

fn splat_index_of(wg: vec3<u32>, groups: vec3<u32>, li: u32) -> u32 {
    return group_index(wg, groups) * 64u + li;
}

fn z_min(pixel: u32) -> f32 {
    return bitcast<f32>(~atomicLoad(&zbuf[pixel]));
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
                if (key > atomicLoad(&zbuf[k])) {
                    atomicMax(&zbuf[k], key);
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
            if (f.ok && f.depth <= z_min(k) + blk.epsilon) {
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
            if (f.ok && f.depth <= z_min(k) + blk.epsilon
                && ~bitcast<u32>(f.q) == atomicLoad(&qbuf[k])) {
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
