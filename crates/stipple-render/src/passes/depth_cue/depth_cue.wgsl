// depth_cue: covered pixels fade towards a colour with their depth between the near and far
// planes. CPU twin: mod.rs (DepthCue::cpu).

struct DepthCue {
    colour: vec3<f32>,
    strength: f32,
}

@group(0) @binding(1) var<uniform> cue: DepthCue;

@compute @workgroup_size(8, 8)
fn depth_cue(@builtin(global_invocation_id) gid: vec3<u32>) {
    if (gid.x >= view.width || gid.y >= view.height) {
        return;
    }
    let k = gid.y * view.width + gid.x;
    let d = depth[k];
    if (!is_finite(d)) {
        dst[k] = src[k];
        return;
    }
    let t = clamp((d - view.near) / (view.far - view.near), 0.0, 1.0) * cue.strength;
    let c = src[k].xyz;
    dst[k] = vec4<f32>(c + (cue.colour - c) * t, 1.0);
}
