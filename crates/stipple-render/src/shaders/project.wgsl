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
}

// Threads per workgroup, and points per thread: a workgroup projects WG × BATCH consecutive
// points, one coalesced block of WG at a time.
const WG: u32 = 256u;
const BATCH: u32 = 8u;

@group(0) @binding(0) var<uniform> view: View;
@group(0) @binding(1) var<uniform> chunk: Chunk;
@group(0) @binding(2) var<storage, read> positions: array<f32>;
@group(0) @binding(3) var<storage, read> normals: array<f32>;
@group(0) @binding(4) var<storage, read_write> counters: array<atomic<u32>>;

var<workgroup> kept: atomic<u32>;

// Adds the workgroup's kept points to the frame's counter (call in uniform control flow).
fn count_kept(li: u32) {
    workgroupBarrier();
    if (li == 0u) {
        atomicAdd(&counters[chunk.slot], atomicLoad(&kept));
    }
}

struct Hit {
    ok: bool,
    pixel: u32,
    depth: f32,
    // The point's index in the whole cloud.
    index: u32,
}

fn point_at(i: u32) -> vec3<f32> {
    return vec3<f32>(positions[3u * i], positions[3u * i + 1u], positions[3u * i + 2u]);
}

// cpu::project::project_point, operation for operation.
fn project_point(p: vec3<f32>) -> Hit {
    var h: Hit;
    h.ok = false;
    let d = p - view.eye;
    let z = dot3(d, view.forward);
    if (!(z >= view.near && z <= view.far)) {
        return h;
    }
    let x = dot3(d, view.right);
    let y = dot3(d, view.up);
    var nx: f32;
    var ny: f32;
    if (view.perspective == 1u) {
        let iz = 1.0 / z;
        nx = x * view.sx * iz;
        ny = y * view.sy * iz;
    } else {
        nx = x * view.sx;
        ny = y * view.sy;
    }
    let w = f32(view.width);
    let hh = f32(view.height);
    let fx = (nx + 1.0) * 0.5 * w;
    let fy = (1.0 - ny) * 0.5 * hh;
    if (!(fx >= 0.0 && fx < w && fy >= 0.0 && fy < hh)) {
        return h;
    }
    h.ok = true;
    h.pixel = u32(fy) * view.width + u32(fx);
    h.depth = z;
    return h;
}

// cpu::project::back_facing.
fn back_facing(p: vec3<f32>, local: u32) -> bool {
    if (chunk.cull == 0u) {
        return false;
    }
    let n = vec3<f32>(normals[3u * local], normals[3u * local + 1u], normals[3u * local + 2u]);
    var to_point = view.forward;
    if (view.perspective == 1u) {
        to_point = p - view.eye;
    }
    return dot3(n, to_point) > 0.0;
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
    h.index = chunk.base + local;
    return h;
}
