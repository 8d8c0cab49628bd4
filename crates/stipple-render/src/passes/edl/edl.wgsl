// edl: eye-dome lighting from the surface depth (log2 depth differences to 8 neighbours at a
// radius; background neighbours outline). CPU twin: cpu/edl.rs.

struct Edl {
    // The eight neighbour offsets (cpu::edl::offsets), two per vec4.
    o01: vec4<i32>,
    o23: vec4<i32>,
    o45: vec4<i32>,
    o67: vec4<i32>,
    strength: f32,
    pad0: u32,
    pad1: u32,
    pad2: u32,
}

@group(0) @binding(0) var<uniform> view: View;
@group(0) @binding(1) var<uniform> ep: Edl;
@group(0) @binding(2) var<storage, read> depth: array<f32>;
@group(0) @binding(3) var<storage, read> src: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read_write> dst: array<vec4<f32>>;

// cpu::edl::BACKGROUND_RESPONSE and SCALE.
const BACKGROUND_RESPONSE: f32 = 100.0;
const SCALE: f32 = 300.0;

@compute @workgroup_size(8, 8)
fn edl(@builtin(global_invocation_id) gid: vec3<u32>) {
    if (gid.x >= view.width || gid.y >= view.height) {
        return;
    }
    let w = i32(view.width);
    let h = i32(view.height);
    let k = gid.y * view.width + gid.x;
    let d = depth[k];
    if (!is_finite(d)) {
        dst[k] = src[k];
        return;
    }
    let off = array<vec2<i32>, 8>(ep.o01.xy, ep.o01.zw, ep.o23.xy, ep.o23.zw, ep.o45.xy, ep.o45.zw, ep.o67.xy, ep.o67.zw);
    let l0 = log2(d);
    var sum = 0.0;
    for (var i = 0; i < 8; i++) {
        let nx = i32(gid.x) + off[i].x;
        let ny = i32(gid.y) + off[i].y;
        if (nx < 0 || ny < 0 || nx >= w || ny >= h) {
            continue;
        }
        let z = depth[u32(ny * w + nx)];
        if (is_finite(z)) {
            sum += max(l0 - log2(z), 0.0);
        } else {
            sum += BACKGROUND_RESPONSE;
        }
    }
    let s = exp(-SCALE * ep.strength * (sum / 8.0));
    let c = src[k];
    dst[k] = vec4<f32>(c.x * s, c.y * s, c.z * s, 1.0);
}
