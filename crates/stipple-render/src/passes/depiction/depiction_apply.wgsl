// depiction_apply (Pintus §6): the filled colour times the merged shading term (background
// unchanged). With depiction.wgsl; CPU twin: cpu/depiction.rs apply.

@group(0) @binding(0) var<uniform> view: View;
@group(0) @binding(1) var<storage, read> depth: array<f32>;
@group(0) @binding(2) var<storage, read> shading: array<f32>;
@group(0) @binding(3) var<storage, read> src: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read_write> dst: array<vec4<f32>>;

@compute @workgroup_size(8, 8)
fn depiction_apply(@builtin(global_invocation_id) gid: vec3<u32>) {
    if (gid.x >= view.width || gid.y >= view.height) {
        return;
    }
    let k = gid.y * view.width + gid.x;
    var s = 1.0;
    if (is_finite(depth[k])) {
        s = shading[k];
    }
    let c = src[k];
    dst[k] = vec4<f32>(c.x * s, c.y * s, c.z * s, 1.0);
}
