// fill_anisotropic (Pintus §5): one Jacobi iteration of the 3×3 fill of emptied pixels: the
// median of valid neighbours first, then Eq. 1's weighted mean. CPU twin:
// cpu/fill_anisotropic.rs.

struct FillAnisotropic {
    delta: f32,
    // 1: every empty pixel is mutable (no visibility pass ran).
    all_empty: u32,
    // Counter slot that receives the number of newly filled pixels.
    slot: u32,
    pad: u32,
}

@group(0) @binding(0) var<uniform> view: View;
@group(0) @binding(1) var<uniform> fp: FillAnisotropic;
@group(0) @binding(2) var<storage, read> id: array<u32>;
@group(0) @binding(3) var<storage, read> src_depth: array<f32>;
@group(0) @binding(4) var<storage, read> src: array<vec4<f32>>;
@group(0) @binding(5) var<storage, read_write> dst_depth: array<f32>;
@group(0) @binding(6) var<storage, read_write> dst: array<vec4<f32>>;
@group(0) @binding(7) var<storage, read_write> counters: array<atomic<u32>>;

// 1 − r/2 for edge and corner neighbours (cpu::fill_anisotropic::EDGE_WEIGHT, CORNER_WEIGHT).
const EDGE_WEIGHT: f32 = 0.5;
const CORNER_WEIGHT: f32 = 0.29289323;

@compute @workgroup_size(8, 8)
fn fill_anisotropic(@builtin(global_invocation_id) gid: vec3<u32>) {
    if (gid.x >= view.width || gid.y >= view.height) {
        return;
    }
    let w = i32(view.width);
    let h = i32(view.height);
    let k = gid.y * view.width + gid.x;
    let z0 = src_depth[k];
    let c0 = src[k];
    dst_depth[k] = z0;
    dst[k] = c0;
    let pid = id[k];
    if (!(pid == HOLE || (fp.all_empty == 1u && !is_point(pid)))) {
        return;
    }
    var nz: array<f32, 8>;
    var ni: array<u32, 8>;
    var corner: array<bool, 8>;
    var count = 0u;
    for (var dy = -1; dy <= 1; dy++) {
        let ny = i32(gid.y) + dy;
        if (ny < 0 || ny >= h) {
            continue;
        }
        for (var dx = -1; dx <= 1; dx++) {
            let nx = i32(gid.x) + dx;
            if ((dx == 0 && dy == 0) || nx < 0 || nx >= w) {
                continue;
            }
            let n = u32(ny * w + nx);
            let z = src_depth[n];
            if (is_finite(z)) {
                nz[count] = z;
                ni[count] = n;
                corner[count] = dx != 0 && dy != 0;
                count++;
            }
        }
    }
    if (count == 0u) {
        return;
    }
    if (!is_finite(z0)) {
        // Insertion sort by depth, stable (ties keep reading order).
        for (var i = 1u; i < count; i++) {
            var j = i;
            while (j > 0u && nz[j] < nz[j - 1u]) {
                let tz = nz[j];
                nz[j] = nz[j - 1u];
                nz[j - 1u] = tz;
                let ti = ni[j];
                ni[j] = ni[j - 1u];
                ni[j - 1u] = ti;
                j--;
            }
        }
        let m = (count - 1u) / 2u;
        dst_depth[k] = nz[m];
        dst[k] = src[ni[m]];
        atomicAdd(&counters[fp.slot], 1u);
        return;
    }
    let inv_delta = 1.0 / (fp.delta * footprint(z0));
    var sz = z0;
    var sc = c0.xyz;
    var sw = 1.0;
    for (var i = 0u; i < count; i++) {
        var radial = EDGE_WEIGHT;
        if (corner[i]) {
            radial = CORNER_WEIGHT;
        }
        let z = nz[i];
        let wt = radial * (1.0 - min(abs(z - z0) * inv_delta, 1.0));
        if (wt > 0.0) {
            let c = src[ni[i]].xyz;
            sz += wt * z;
            sc = vec3<f32>(sc.x + wt * c.x, sc.y + wt * c.y, sc.z + wt * c.z);
            sw += wt;
        }
    }
    dst_depth[k] = sz / sw;
    dst[k] = vec4<f32>(sc.x / sw, sc.y / sw, sc.z / sw, 1.0);
}
