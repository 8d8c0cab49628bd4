// shade (Dobrev §3.1): point id → lit linear colour and surface depth. CPU twin: cpu/shade.rs
// (see there for the maths: Phong with one light, two-sided normals, and the tangent-plane
// surface depth capped by d̃).

struct Shade {
    light_count: u32,
    has_normals: u32,
    // 0: constant albedo, 1: per-point sRGB albedo from gather.
    has_albedo: u32,
    // 1: a shadow texture is bound (sums in attr_style.yz).
    has_lit: u32,
    base_colour: vec3<f32>,
    max_correction: f32,
    background: vec3<f32>,
    // Point lights' falloff distance d0 (strength (d0 / d)^2); 0: none.
    falloff: f32,
    // Shadow samples per light (0: m = 1 for that light).
    samples: vec4<u32>,
    // xyz: direction towards the light (w = 1) or position (w = 2); w = 0: headlight.
    lights: array<vec4<f32>, 4>,
}

@group(0) @binding(0) var<uniform> view: View;
@group(0) @binding(1) var<uniform> sp: Shade;
@group(0) @binding(2) var<storage, read> g_depth: array<f32>;
@group(0) @binding(3) var<storage, read> g_id: array<u32>;
@group(0) @binding(4) var<storage, read> attr_pos: array<vec4<f32>>;
@group(0) @binding(5) var<storage, read> attr_normal: array<vec4<f32>>;
// sRGB 8-bit → linear (shade::srgb_to_linear_table).
@group(0) @binding(6) var<storage, read> to_linear: array<f32, 256>;
@group(0) @binding(7) var<storage, read_write> colour: array<vec4<f32>>;
@group(0) @binding(8) var<storage, read_write> surface_depth: array<f32>;
@group(0) @binding(9) var<storage, read> attr_style: array<vec4<u32>>;
// Material terms by object: ambient, diffuse, specular, shininess.
@group(0) @binding(10) var<uniform> materials: array<vec4<f32>, 256>;

fn normalize3(v: vec3<f32>) -> vec3<f32> {
    return v * (1.0 / sqrt(dot3(v, v)));
}

fn powi(x: f32, n: i32) -> f32 {
    var r = 1.0;
    var b = x;
    var e = abs(n);
    loop {
        if (e == 0) {
            break;
        }
        if ((e & 1) == 1) {
            r = r * b;
        }
        b = b * b;
        e = e >> 1u;
    }
    if (n < 0) {
        return 1.0 / r;
    }
    return r;
}

@compute @workgroup_size(8, 8)
fn shade(@builtin(global_invocation_id) gid: vec3<u32>) {
    if (gid.x >= view.width || gid.y >= view.height) {
        return;
    }
    let k = gid.y * view.width + gid.x;
    let pid = g_id[k];
    if (!is_point(pid)) {
        colour[k] = vec4<f32>(sp.background, 1.0);
        surface_depth[k] = infinity();
        return;
    }
    let a = attr_pos[k];
    var albedo = sp.base_colour;
    if (sp.has_albedo == 1u) {
        let bits = bitcast<u32>(a.w);
        albedo = vec3<f32>(to_linear[bits & 0xffu], to_linear[(bits >> 8u) & 0xffu], to_linear[(bits >> 16u) & 0xffu]);
    }
    var depth = g_depth[k];
    let st = attr_style[k];
    let mat = materials[st.x & 0xffu];
    // shade::lit_rgb
    var m = array<vec3<f32>, 4>(vec3<f32>(1.0), vec3<f32>(1.0), vec3<f32>(1.0), vec3<f32>(1.0));
    if (sp.has_lit == 1u) {
        for (var l = 0u; l < 4u; l++) {
            if (sp.samples[l] > 0u) {
                let w = select(st.z, st.y, l < 2u);
                m[l] = vec3<f32>(f32((w >> (16u * (l % 2u))) & 0xffffu) / f32(sp.samples[l] * 255u));
            }
        }
    } else if (sp.has_lit == 2u) {
        // Coloured: gather packed 8 bits per channel and light (byte 3 · light + channel).
        for (var l = 0u; l < 4u; l++) {
            m[l] = vec3<f32>(packed_lit(st, 3u * l), packed_lit(st, 3u * l + 1u), packed_lit(st, 3u * l + 2u));
        }
    }
    if (sp.has_normals == 0u) {
        var c = albedo;
        if (sp.has_lit != 0u) {
            c = unlit(albedo, m, mat);
        }
        colour[k] = vec4<f32>(c, 1.0);
        surface_depth[k] = depth;
        return;
    }
    var n = attr_normal[k].xyz;
    // view.pixel_ray
    let ndx = 2.0 * (f32(gid.x) + 0.5) / f32(view.width) - 1.0;
    let ndy = 1.0 - 2.0 * (f32(gid.y) + 0.5) / f32(view.height);
    let off = view.right * (ndx / view.sx) + view.up * (ndy / view.sy);
    var o = view.eye;
    var dir = view.forward;
    if (view.perspective == 1u) {
        dir = view.forward + off;
    } else {
        o = view.eye + off;
    }
    let unit = normalize3(dir);
    let q = a.xyz;
    let nd = dot3(n, dir);
    let shift = dot3(o - view.eye, view.forward);
    if (abs(dot3(n, unit)) >= 0.2) {
        var t = dot3(n, q - o) / nd;
        if (view.perspective != 1u) {
            t = t + shift;
        }
        if (abs(t - depth) <= sp.max_correction) {
            depth = t;
        }
    }
    var hit: vec3<f32>;
    if (view.perspective == 1u) {
        hit = o + dir * depth;
    } else {
        hit = o + dir * (depth - shift);
    }
    let to_eye = -unit;
    colour[k] = vec4<f32>(phong_lights(albedo, n, to_eye, hit, m, mat), 1.0);
    surface_depth[k] = depth;
}

// Byte j of a pixel's packed coloured lit values (words y, z, w of its style), as m.
fn packed_lit(st: vec4<u32>, j: u32) -> f32 {
    let w = select(select(st.w, st.z, j < 8u), st.y, j < 4u);
    return f32((w >> (8u * (j % 4u))) & 0xffu) / 255.0;
}

// shade::cpu::unlit: a point without a normal under shadow textures.
fn unlit(albedo: vec3<f32>, m: array<vec3<f32>, 4>, mat: vec4<f32>) -> vec3<f32> {
    let nl = clamp(sp.light_count, 1u, 4u);
    var sum = vec3<f32>(0.0);
    for (var l = 0u; l < nl; l++) {
        sum = sum + m[l];
    }
    return albedo * (mat.x + (1.0 - mat.x) * (sum / f32(nl)));
}

// shade::phong over the frame's lights, for a point at `hit` with normal `n_in` (turned to
// the eye), lit values `m` and material (ambient, diffuse, specular, shininess) `mat`.
fn phong_lights(
    albedo: vec3<f32>,
    n_in: vec3<f32>,
    to_eye: vec3<f32>,
    hit: vec3<f32>,
    m: array<vec3<f32>, 4>,
    mat: vec4<f32>,
) -> vec3<f32> {
    var n = n_in;
    // shade::phong, over the lights
    if (dot3(n, to_eye) < 0.0) {
        n = -n;
    }
    var kk = vec3<f32>(mat.x);
    var sp_sum = vec3<f32>(0.0);
    for (var li = 0u; li < sp.light_count; li++) {
        let light = sp.lights[li];
        var l = to_eye;
        var strength = m[li];
        if (light.w == 1.0) {
            l = light.xyz;
        } else if (light.w == 2.0) {
            let lv = light.xyz - hit;
            let len2 = dot3(lv, lv);
            if (len2 > 0.0) {
                l = normalize3(lv);
            } else {
                l = vec3<f32>(0.0);
            }
            // shade::cpu::falloff
            if (sp.falloff > 0.0) {
                if (len2 > 0.0) {
                    strength = strength * (sp.falloff * sp.falloff / len2);
                } else {
                    strength = vec3<f32>(0.0);
                }
            }
        }
        let nl = dot3(n, l);
        if (nl > 0.0) {
            let r = 2.0 * nl * n - l;
            kk = kk + strength * mat.y * nl;
            sp_sum = sp_sum + strength * mat.z * powi(max(dot3(r, to_eye), 0.0), i32(mat.w));
        }
    }
    return albedo * kk + sp_sum;
}
