// blend_layers (Dobrev §5): front-to-back "under" compositing of peeled layers. CPU twin:
// cpu/blend_layers.rs. acc = (colour gathered so far, transmittance T); each layer adds
// T · α · c and leaves T · (1 − α); compose adds the background through what is left.

struct Blend {
    // α of a pixel with a surface but no point (filled by the anisotropic fill).
    hole_alpha: f32,
    slot: u32,
    pad0: u32,
    pad1: u32,
    // Linear background colour (compose).
    background: vec3<f32>,
    pad2: u32,
}

@group(0) @binding(0) var<uniform> view: View;
@group(0) @binding(1) var<uniform> bp: Blend;
@group(0) @binding(2) var<storage, read> id: array<u32>;
@group(0) @binding(3) var<storage, read> surface: array<f32>;
@group(0) @binding(4) var<storage, read> attr_style: array<vec4<u32>>;
@group(0) @binding(5) var<storage, read_write> colour: array<vec4<f32>>;
@group(0) @binding(6) var<storage, read_write> acc: array<vec4<f32>>;
@group(0) @binding(7) var<storage, read_write> counters: array<atomic<u32>>;
// Per pixel (from gather): position and, in .w, the point's sRGB albedo word.
@group(0) @binding(8) var<storage, read> attr_pos: array<vec4<f32>>;

var<workgroup> covered: atomic<u32>;

@compute @workgroup_size(8, 8)
fn begin(@builtin(global_invocation_id) gid: vec3<u32>) {
    if (gid.x >= view.width || gid.y >= view.height) {
        return;
    }
    acc[gid.y * view.width + gid.x] = vec4<f32>(0.0, 0.0, 0.0, 1.0);
}

@compute @workgroup_size(8, 8)
fn blend(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(local_invocation_index) li: u32,
) {
    if (gid.x < view.width && gid.y < view.height) {
        let k = gid.y * view.width + gid.x;
        let pid = id[k];
        var a = 0.0;
        if (is_point(pid)) {
            a = f32((attr_style[k].x >> 8u) & 0xffu) / 255.0;
        } else if (is_finite(surface[k])) {
            a = bp.hole_alpha;
        }
        if (a > 0.0) {
            let s = acc[k];
            let t = s.w;
            let w = t * a;
            let c = colour[k];
            acc[k] = vec4<f32>(s.x + w * c.x, s.y + w * c.y, s.z + w * c.z, t * (1.0 - a));
            atomicAdd(&covered, 1u);
        }
    }
    workgroupBarrier();
    if (li == 0u) {
        atomicAdd(&counters[bp.slot], atomicLoad(&covered));
    }
}

// translucent::srgb8_to_linear
fn srgb8_to_linear(v: u32) -> f32 {
    let c = f32(v) / 255.0;
    if (c <= 0.04045) {
        return c / 12.92;
    }
    return pow((c + 0.055) / 1.055, 2.4);
}

// translucent::weights
fn tint_weights(bits: u32) -> vec3<f32> {
    let lin = vec3<f32>(srgb8_to_linear(bits & 0xffu), srgb8_to_linear((bits >> 8u) & 0xffu), srgb8_to_linear((bits >> 16u) & 0xffu));
    let s = vec3<f32>(1.0) - lin + vec3<f32>(0.1);
    let mean = (s.x + s.y + s.z) * (1.0 / 3.0);
    return s / mean;
}

// translucent::optical_depth
fn optical_depth(a: f32) -> f32 {
    if (a >= 1.0) {
        return 1000.0;
    }
    return -log(1.0 - a);
}

// cpu::blend_layers::transmit: a light layer of coloured translucent shadows adds τ · w per
// channel to the accumulator's colour and leaves T · (1 − α).
@compute @workgroup_size(8, 8)
fn transmit(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(local_invocation_index) li: u32,
) {
    if (gid.x < view.width && gid.y < view.height) {
        let k = gid.y * view.width + gid.x;
        let pid = id[k];
        var a = 0.0;
        var w = vec3<f32>(1.0);
        if (is_point(pid)) {
            a = f32((attr_style[k].x >> 8u) & 0xffu) / 255.0;
            w = tint_weights(bitcast<u32>(attr_pos[k].w));
        } else if (is_finite(surface[k])) {
            a = bp.hole_alpha;
        }
        if (a > 0.0) {
            let s = acc[k];
            let tau = optical_depth(a);
            acc[k] = vec4<f32>(s.xyz + tau * w, s.w * (1.0 - a));
            atomicAdd(&covered, 1u);
        }
    }
    workgroupBarrier();
    if (li == 0u) {
        atomicAdd(&counters[bp.slot], atomicLoad(&covered));
    }
}

@compute @workgroup_size(8, 8)
fn compose(@builtin(global_invocation_id) gid: vec3<u32>) {
    if (gid.x >= view.width || gid.y >= view.height) {
        return;
    }
    let k = gid.y * view.width + gid.x;
    let s = acc[k];
    colour[k] = vec4<f32>(s.x + s.w * bp.background.x, s.y + s.w * bp.background.y, s.z + s.w * bp.background.z, 1.0);
}
