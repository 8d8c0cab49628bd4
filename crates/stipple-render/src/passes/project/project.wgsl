// project: the compute rasterizer's shared part (Dobrev §3.1; Schütz et al.'s pattern).
// Included by project_atomic64.wgsl and project_atomic32.wgsl; CPU twin: cpu/project.rs.

// One chunk of the cloud (a storage binding holds at most max_storage_buffer_binding_size).
struct Chunk {
    // Index of the chunk's first point in the whole cloud.
    base: u32,
    count: u32,
    // 1: discard points whose normal faces away from the eye.
    cull: u32,
    // Counter slot that receives the number of points kept.
    slot: u32,
    // 1: depth peeling, keep only points the previous layer does not hold (see peeled).
    peel: u32,
    gap: f32,
    // 1: the cloud has normals (the peel's same-surface test uses them).
    has_normals: u32,
    pad1: u32,
}

// cpu::project::PEEL_SLOPE_CAP, PEEL_NEIGHBOUR_GAPS and GRAZING_COS2 (EDGE_COS2: common.wgsl).
const PEEL_SLOPE_CAP: f32 = 16.0;
const PEEL_NEIGHBOUR_GAPS: f32 = 4.0;
const GRAZING_COS2: f32 = 0.25;

// cpu::project::Facing.
const FRONT: u32 = 0u;
const BACK: u32 = 1u;
const EDGE: u32 = 2u;

// Threads per workgroup, and points per thread: a workgroup projects WG × BATCH consecutive
// points, one coalesced block of WG at a time.
const WG: u32 = 256u;
const BATCH: u32 = 8u;

@group(0) @binding(0) var<uniform> view: View;
@group(0) @binding(1) var<uniform> chunk: Chunk;
@group(0) @binding(2) var<storage, read> positions: array<f32>;
@group(0) @binding(3) var<storage, read> normals: array<f32>;
@group(0) @binding(4) var<storage, read_write> counters: array<atomic<u32>>;
// What the previous layer left (depth peeling; bound but unread otherwise): see
// peel_reference.wgsl.
@group(0) @binding(5) var<storage, read> peel_ref: array<vec4<f32>>;
// One bit per point, set once a layer's test has peeled it (cpu::project::PeelTest::done).
@group(0) @binding(6) var<storage, read_write> done: array<atomic<u32>>;

var<workgroup> kept: atomic<u32>;

// Adds the workgroup's kept points (`mine`: this thread's) to the frame's counter (call in
// uniform control flow). One shared atomic per thread, not per point.
fn count_kept(li: u32, mine: u32) {
    if (mine > 0u) {
        atomicAdd(&kept, mine);
    }
    workgroupBarrier();
    if (li == 0u) {
        atomicAdd(&counters[chunk.slot], atomicLoad(&kept));
    }
}

fn normal_at(local: u32) -> vec3<f32> {
    return vec3<f32>(normals[3u * local], normals[3u * local + 1u], normals[3u * local + 2u]);
}

// cpu::project::to_point: the direction of the ray from the eye to p.
fn to_point(p: vec3<f32>) -> vec3<f32> {
    if (view.perspective == 1u) {
        return p - view.eye;
    }
    return view.forward;
}

// cpu::project::back_facing.
fn turned_away(p: vec3<f32>, n: vec3<f32>) -> bool {
    return dot3(n, to_point(p)) > 0.0;
}

// cpu::project::Facing::of.
fn facing(p: vec3<f32>, n: vec3<f32>) -> u32 {
    let ray = to_point(p);
    let c = dot3(n, ray);
    if (c * c < EDGE_COS2 * dot3(n, n) * dot3(ray, ray)) {
        return EDGE;
    }
    if (c > 0.0) {
        return BACK;
    }
    return FRONT;
}

// cpu::project::Facing::opposes.
fn opposes(a: u32, b: u32) -> bool {
    return (a == FRONT && b == BACK) || (a == BACK && b == FRONT);
}

fn back_facing(p: vec3<f32>, local: u32) -> bool {
    if (chunk.cull == 0u) {
        return false;
    }
    return turned_away(p, normal_at(local));
}

// The tangent-plane test of cpu::project::PeelTest::peeled against the layer's point at
// pixel q, for a point at p, view depth `depth`, facing `own`.
fn on_plane(p: vec3<f32>, depth: f32, own: u32, q: u32) -> bool {
    let r = peel_ref[2u * q + 1u];
    if (r.z < 0.5) {
        return false;
    }
    let pl = peel_ref[2u * q];
    let f = facing(p, pl.xyz);
    if (opposes(own, f)) {
        return false;
    }
    let off = dot3(pl.xyz, p) - pl.w;
    var behind = off;
    if (f == FRONT) {
        behind = -off;
    } else if (f == EDGE) {
        behind = abs(off);
    }
    return behind <= chunk.gap && depth <= r.y + PEEL_SLOPE_CAP * chunk.gap;
}

// cpu::project::PeelTest::peeled: does the point belong to a layer already peeled?
fn peeled(p: vec3<f32>, local: u32, pixel: u32, depth: f32) -> bool {
    let r = peel_ref[2u * pixel + 1u];
    if (chunk.has_normals == 1u) {
        if (depth <= r.y) {
            return true;
        }
        if (r.z < 0.5) {
            return false;
        }
        let n = normal_at(local);
        let own = facing(p, n);
        // An edge-on point behind a covered pixel starts no layer (cpu::project::Facing).
        if (own == EDGE) {
            return true;
        }
        if (opposes(own, facing(p, peel_ref[2u * pixel].xyz))) {
            return false;
        }
        if (on_plane(p, depth, own, pixel)) {
            return true;
        }
        // Only grazing points (cpu::project::GRAZING_COS2).
        let ray = to_point(p);
        let c = dot3(n, ray);
        if (c * c > GRAZING_COS2 * dot3(n, n) * dot3(ray, ray)) {
            return false;
        }
        // The layer's surface here: the point on the ray through p at the layer's depth.
        var here = p - view.forward * (depth - r.y);
        if (view.perspective == 1u) {
            here = view.eye + (p - view.eye) * (r.y / depth);
        }
        let w = view.width;
        let x = pixel % w;
        let y = pixel / w;
        for (var yy = max(y, 1u) - 1u; yy < min(y + 2u, view.height); yy++) {
            for (var xx = max(x, 1u) - 1u; xx < min(x + 2u, w); xx++) {
                let q = yy * w + xx;
                if (q == pixel) {
                    continue;
                }
                let pl = peel_ref[2u * q];
                if (abs(dot3(pl.xyz, here) - pl.w) <= PEEL_NEIGHBOUR_GAPS * chunk.gap
                    && on_plane(p, depth, own, q)) {
                    return true;
                }
            }
        }
        return false;
    }
    return depth <= r.x + chunk.gap;
}

// The point a thread handles in round k of its workgroup's batch, projected: not ok when
// past the end of the chunk, outside the view or back-facing.
fn visible_point(wg: vec3<u32>, groups: vec3<u32>, li: u32, k: u32) -> Hit {
    let local = (group_index(wg, groups) * BATCH + k) * WG + li;
    var h: Hit;
    h.ok = false;
    if (local >= chunk.count) {
        return h;
    }
    let p = point_at(local);
    h = project_point(p);
    if (h.ok && back_facing(p, local)) {
        h.ok = false;
    }
    if (h.ok && chunk.peel == 1u) {
        // A point peeled by an earlier layer stays peeled; one peeled now is marked. (The
        // two passes of the 32-bit path agree: a point marked by the first was peeled.)
        let i = chunk.base + local;
        let bit = 1u << (i % 32u);
        if ((atomicLoad(&done[i / 32u]) & bit) != 0u) {
            h.ok = false;
        } else if (peeled(p, local, h.pixel, h.depth)) {
            atomicOr(&done[i / 32u], bit);
            h.ok = false;
        }
    }
    h.index = chunk.base + local;
    return h;
}
