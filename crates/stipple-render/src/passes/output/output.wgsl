// output: linear colour → sRGB 8-bit RGBA, through the same 16384-entry table as the CPU's
// shade::SrgbEncoder, so both backends encode a colour identically.

@group(0) @binding(0) var<uniform> view: View;
@group(0) @binding(1) var<storage, read> colour: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> encode_table: array<u32>;
@group(0) @binding(3) var<storage, read_write> rgba: array<u32>;

fn encode(c: f32) -> u32 {
    return encode_table[u32(clamp(c, 0.0, 1.0) * 16383.0 + 0.5)];
}

@compute @workgroup_size(8, 8)
fn output(@builtin(global_invocation_id) gid: vec3<u32>) {
    if (gid.x >= view.width || gid.y >= view.height) {
        return;
    }
    let k = gid.y * view.width + gid.x;
    let c = colour[k];
    rgba[k] = encode(c.x) | (encode(c.y) << 8u) | (encode(c.z) << 16u) | (255u << 24u);
}
