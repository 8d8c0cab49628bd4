// The hole-filling step shared by fill_background and fill_occluded (Dobrev §3.2–3.3);
// each of those files supplies `candidate`, `own_plane`, `solid` and `carry`. CPU twin: cpu/fill_background.rs
// (fill_changes, MaskTest).
//
// For a candidate pixel, every "solid" cell of the window blocks the half-plane masks it
// belongs to (masks.rs); when all eight are blocked the pixel takes the solid neighbour on the
// nearest ring with the smallest depth (ties: smaller id). Otherwise it is copied unchanged.

struct Fill {
    // First cell of this radius's window in `cells`, and how many cells it has.
    first: u32,
    count: u32,
    // d̃ for fill_occluded (unused by fill_background).
    gap: f32,
    // Counter slot that receives the number of changed pixels.
    slot: u32,
    // fill_occluded: 1 when `plane` holds each pixel's tangent plane (its slope-aware test).
    planes: u32,
    // Which half of `plane` this step reads (it writes the other): the step's index mod 2.
    parity: u32,
    pad0: u32,
    pad1: u32,
}

@group(0) @binding(0) var<uniform> view: View;
@group(0) @binding(1) var<uniform> fp: Fill;
// (dx, dy, mask bits, ring), sorted by ring: masks::window for radius 1, 2, 3.
@group(0) @binding(2) var<storage, read> cells: array<vec4<i32>>;
@group(0) @binding(3) var<storage, read> src_depth: array<f32>;
@group(0) @binding(4) var<storage, read> src_id: array<u32>;
@group(0) @binding(5) var<storage, read_write> dst_depth: array<f32>;
@group(0) @binding(6) var<storage, read_write> dst_id: array<u32>;
@group(0) @binding(7) var<storage, read_write> counters: array<atomic<u32>>;
// fill_occluded's planes, two per pixel (2k + parity: read, 2k + 1 − parity: written; see
// fill_planes.wgsl). fill_background binds it and never reads it.
@group(0) @binding(8) var<storage, read_write> plane: array<vec4<f32>>;

@compute @workgroup_size(8, 8)
fn fill(@builtin(global_invocation_id) gid: vec3<u32>) {
    let w = i32(view.width);
    let h = i32(view.height);
    let x = i32(gid.x);
    let y = i32(gid.y);
    if (x >= w || y >= h) {
        return;
    }
    let k = y * w + x;
    let d = src_depth[k];
    let id = src_id[k];
    dst_depth[k] = d;
    dst_id[k] = id;
    if (!candidate(d, id)) {
        return;
    }
    let own = own_plane(u32(k));
    carry(u32(k), u32(k));
    var blocked = 0u;
    var best_depth = infinity();
    var best_id = BACKGROUND;
    var best_ring = 0x7fffffff;
    var best_n = 0;
    for (var c = 0u; c < fp.count; c++) {
        if (c == 8u && blocked == 0xffu && best_ring == 1) {
            break;
        }
        let cell = cells[fp.first + c];
        let nx = x + cell.x;
        let ny = y + cell.y;
        if (nx < 0 || ny < 0 || nx >= w || ny >= h) {
            continue;
        }
        let n = ny * w + nx;
        let nd = src_depth[n];
        let nid = src_id[n];
        if (!solid(d, own, nd, nid, nx, ny)) {
            continue;
        }
        blocked |= u32(cell.z);
        let ring = cell.w;
        if (ring < best_ring
            || (ring == best_ring && (nd < best_depth || (nd == best_depth && nid < best_id)))) {
            best_depth = nd;
            best_id = nid;
            best_ring = ring;
            best_n = n;
        }
    }
    if (blocked == 0xffu) {
        dst_depth[k] = best_depth;
        dst_id[k] = best_id;
        carry(u32(k), u32(best_n));
        atomicAdd(&counters[fp.slot], 1u);
    }
}
