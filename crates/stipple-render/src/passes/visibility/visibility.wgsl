// visibility (Pintus §4): the free solid angle above each pixel's sample, over 8 sectors of
// the kernel's disc; pixels below the threshold become HOLE. CPU twin: cpu/visibility.rs.

struct Visibility {
    // This kernel's offsets in the table: first entry and count.
    first: u32,
    count: u32,
    threshold: f32,
    // Counter slot that receives the number of points judged invisible.
    slot: u32,
}

@group(0) @binding(0) var<uniform> view: View;
@group(0) @binding(1) var<uniform> vp: Visibility;
// (dx, dy, sector, 0) per neighbour (cpu::visibility::kernel_offsets).
@group(0) @binding(2) var<storage, read> offsets: array<vec4<i32>>;
@group(0) @binding(3) var<storage, read> src_depth: array<f32>;
@group(0) @binding(4) var<storage, read> src_id: array<u32>;
@group(0) @binding(5) var<storage, read_write> dst_depth: array<f32>;
@group(0) @binding(6) var<storage, read_write> dst_id: array<u32>;
@group(0) @binding(7) var<storage, read_write> counters: array<atomic<u32>>;

@compute @workgroup_size(8, 8)
fn visibility(@builtin(global_invocation_id) gid: vec3<u32>) {
    if (gid.x >= view.width || gid.y >= view.height) {
        return;
    }
    let w = i32(view.width);
    let h = i32(view.height);
    let k = gid.y * view.width + gid.x;
    let id = src_id[k];
    var z = view.far;
    if (is_point(id)) {
        z = src_depth[k];
    }
    let p0 = view_position(gid.x, gid.y, z);
    var to_eye = vec3<f32>(0.0, 0.0, -1.0);
    if (view.perspective == 1u) {
        to_eye = -p0 * (1.0 / sqrt(dot3(p0, p0)));
    }
    var horizon = array<f32, 8>(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
    for (var c = 0u; c < vp.count; c++) {
        let o = offsets[vp.first + c];
        let nx = i32(gid.x) + o.x;
        let ny = i32(gid.y) + o.y;
        if (nx < 0 || ny < 0 || nx >= w || ny >= h) {
            continue;
        }
        let n = u32(ny * w + nx);
        if (!is_point(src_id[n])) {
            continue;
        }
        let d = view_position(u32(nx), u32(ny), src_depth[n]) - p0;
        let len2 = dot3(d, d);
        if (len2 <= 0.0) {
            continue;
        }
        let cosine = dot3(to_eye, d) / sqrt(len2);
        if (cosine > horizon[o.z]) {
            horizon[o.z] = cosine;
        }
    }
    var open = 0.0;
    for (var s = 0; s < 8; s++) {
        open += 1.0 - horizon[s];
    }
    if (open / 8.0 >= vp.threshold) {
        dst_depth[k] = src_depth[k];
        dst_id[k] = id;
    } else {
        if (is_point(id)) {
            atomicAdd(&counters[vp.slot], 1u);
        }
        dst_depth[k] = infinity();
        dst_id[k] = HOLE;
    }
}
