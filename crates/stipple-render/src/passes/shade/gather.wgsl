// gather: for every pixel whose point lies in this chunk of the cloud, fetch the point's
// position, normal and albedo into per-pixel attribute buffers, so shade reads one place
// whatever the chunk. Runs once per chunk, after the geometry passes.

struct Gather {
    base: u32,
    count: u32,
    has_normals: u32,
    has_albedo: u32,
    has_style: u32,
    // 0 none, 1 grey sums (copied), 2 coloured (packed to 8 bits per channel and light).
    has_lit: u32,
    pad0: u32,
    pad1: u32,
    // Samples per light (coloured: to normalise).
    samples: vec4<u32>,
}

@group(0) @binding(0) var<uniform> view: View;
@group(0) @binding(1) var<uniform> gp: Gather;
@group(0) @binding(2) var<storage, read> id: array<u32>;
@group(0) @binding(3) var<storage, read> positions: array<f32>;
@group(0) @binding(4) var<storage, read> normals: array<f32>;
// sRGB 8-bit albedo per point, packed r | g << 8 | b << 16.
@group(0) @binding(5) var<storage, read> albedo: array<u32>;
// xyz = position, w = the albedo word (bit pattern).
@group(0) @binding(6) var<storage, read_write> attr_pos: array<vec4<f32>>;
@group(0) @binding(7) var<storage, read_write> attr_normal: array<vec4<f32>>;
// Per point: object | 8-bit opacity << 8; shadow texture sums in two words (lights
// 0 | 1 << 16, 2 | 3 << 16).
@group(0) @binding(8) var<storage, read> style: array<u32>;
@group(0) @binding(9) var<storage, read> lit: array<vec2<u32>>;
// Per pixel: (style, lit words, 0) of the pixel's point; coloured: (style, the lit values
// m of (light, channel) as bytes 3 · light + channel of words y, z, w).
@group(0) @binding(10) var<storage, read_write> attr_style: array<vec4<u32>>;
// Coloured shadow textures: red | blue << 16 per light.
@group(0) @binding(11) var<storage, read> lit_rb: array<vec4<u32>>;

// shade::cpu::lit_rgb: a channel's sum over `s` samples rounded to 8 bits (255 unshadowed).
fn lit8(sum: u32, s: u32) -> u32 {
    if (s == 0u) {
        return 255u;
    }
    return min((2u * sum + s) / (2u * s), 255u);
}

@compute @workgroup_size(256)
fn gather(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(local_invocation_index) li: u32,
) {
    let i = group_index(wg, groups) * 256u + li;
    if (i >= view.width * view.height) {
        return;
    }
    let pid = id[i];
    if (!is_point(pid) || pid < gp.base || pid - gp.base >= gp.count) {
        return;
    }
    let l = pid - gp.base;
    var a = 0u;
    if (gp.has_albedo == 1u) {
        a = albedo[l];
    }
    attr_pos[i] = vec4<f32>(positions[3u * l], positions[3u * l + 1u], positions[3u * l + 2u], bitcast<f32>(a));
    if (gp.has_normals == 1u) {
        attr_normal[i] = vec4<f32>(normals[3u * l], normals[3u * l + 1u], normals[3u * l + 2u], 0.0);
    }
    var st = vec4<u32>(0xff00u, 0u, 0u, 0u);
    if (gp.has_style == 1u) {
        st.x = style[l];
    }
    if (gp.has_lit == 1u) {
        let w = lit[l];
        st.y = w.x;
        st.z = w.y;
    } else if (gp.has_lit == 2u) {
        let w = lit[l];
        let rb = lit_rb[l];
        var packed = array<u32, 3>(0u, 0u, 0u);
        for (var li = 0u; li < 4u; li++) {
            let s = gp.samples[li];
            let g = (select(w.y, w.x, li < 2u) >> (16u * (li % 2u))) & 0xffffu;
            let q = vec3<u32>(lit8(rb[li] & 0xffffu, s), lit8(g, s), lit8(rb[li] >> 16u, s));
            for (var c = 0u; c < 3u; c++) {
                let j = 3u * li + c;
                packed[j / 4u] = packed[j / 4u] | (q[c] << (8u * (j % 4u)));
            }
        }
        st.y = packed[0];
        st.z = packed[1];
        st.w = packed[2];
    }
    attr_style[i] = st;
}
