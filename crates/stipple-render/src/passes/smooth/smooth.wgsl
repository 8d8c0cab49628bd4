// smooth (Dobrev §3.4): a 3×3 low-pass filter over covered pixels only. Used with
// weighted.wgsl; CPU twin: cpu/smooth.rs.

struct Smooth {
    // Kernel weights in row order (Kernel::weights), padded to 12.
    w0: vec4<f32>,
    w1: vec4<f32>,
    w2: vec4<f32>,
}

@group(0) @binding(0) var<uniform> view: View;
@group(0) @binding(1) var<uniform> sm: Smooth;
@group(0) @binding(2) var<storage, read> id: array<u32>;
@group(0) @binding(3) var<storage, read> src: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read_write> dst: array<vec4<f32>>;

fn include(n: i32) -> bool {
    return is_point(id[n]);
}

@compute @workgroup_size(8, 8)
fn smooth_pass(@builtin(global_invocation_id) gid: vec3<u32>) {
    if (gid.x >= view.width || gid.y >= view.height) {
        return;
    }
    let k = gid.y * view.width + gid.x;
    if (!is_point(id[k])) {
        dst[k] = src[k];
        return;
    }
    let weights = array<f32, 9>(sm.w0.x, sm.w0.y, sm.w0.z, sm.w0.w, sm.w1.x, sm.w1.y, sm.w1.z, sm.w1.w, sm.w2.x);
    dst[k] = vec4<f32>(weighted_3x3(i32(gid.x), i32(gid.y), weights), 1.0);
}
