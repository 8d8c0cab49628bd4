// antialias (Dobrev §3.5): the Laplace filter on depth / z_far marks silhouette pixels, which
// are blended with their Gaussian-weighted 3×3 neighbourhood. Used with weighted.wgsl; CPU
// twin: cpu/antialias.rs.

struct Antialias {
    inv_far: f32,
    threshold: f32,
    strength: f32,
    // Counter slot that receives the number of blended pixels.
    slot: u32,
}

@group(0) @binding(0) var<uniform> view: View;
@group(0) @binding(1) var<uniform> ap: Antialias;
@group(0) @binding(2) var<storage, read> depth: array<f32>;
@group(0) @binding(3) var<storage, read> src: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read_write> dst: array<vec4<f32>>;
@group(0) @binding(5) var<storage, read_write> counters: array<atomic<u32>>;

fn include(n: i32) -> bool {
    return true;
}

fn nd(x: u32, y: u32) -> f32 {
    let d = depth[y * view.width + x];
    if (d < infinity()) {
        return min(d * ap.inv_far, 1.0);
    }
    return 1.0;
}

@compute @workgroup_size(8, 8)
fn antialias(@builtin(global_invocation_id) gid: vec3<u32>) {
    let x = gid.x;
    let y = gid.y;
    if (x >= view.width || y >= view.height) {
        return;
    }
    let k = y * view.width + x;
    let c = nd(x, y);
    let l = nd(max(x, 1u) - 1u, y);
    let r = nd(min(x + 1u, view.width - 1u), y);
    let t = nd(x, max(y, 1u) - 1u);
    let b = nd(x, min(y + 1u, view.height - 1u));
    let lap = 4.0 * c - l - r - t - b;
    if (abs(lap) <= ap.threshold) {
        dst[k] = src[k];
        return;
    }
    let g = array<f32, 9>(1.0, 2.0, 1.0, 2.0, 4.0, 2.0, 1.0, 2.0, 1.0);
    let blur = weighted_3x3(i32(x), i32(y), g);
    let s = src[k].xyz;
    let a = 1.0 - ap.strength;
    dst[k] = vec4<f32>(a * s.x + ap.strength * blur.x, a * s.y + ap.strength * blur.y, a * s.z + ap.strength * blur.z, 1.0);
    atomicAdd(&counters[ap.slot], 1u);
}
