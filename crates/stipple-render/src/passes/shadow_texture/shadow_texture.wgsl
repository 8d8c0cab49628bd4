// shadow_texture (Dobrev §6, Gunjee §4.1): add, per point, the light a sample brings (255
// when it reaches the point, T · 255 behind translucent light layers). CPU twin:
// cpu/shadow_texture.rs. `reference` is the light image's depth after the hole fills; a
// point is lit when its light-space depth is at most reference + Δd at its pixel, with
// Δd = d̃' · min(1 / |⟨v, n⟩|, cap) (d̃' without normals), d̃' = max(d̃, three light pixels). A cube face marks only the points
// whose dominant direction from the light is its own.

struct Mark {
    base: u32,
    count: u32,
    gap: f32,
    slope_cap: f32,
    // 0-5: a cube face; 6: every point.
    face: u32,
    // Which light's 16 bits: word light / 2, shift 16 · (light % 2).
    light: u32,
    has_normals: u32,
    slot: u32,
    // 0 opaque, 1 a translucent light layer, 2 the points no layer marked.
    mode: u32,
    // Coloured shadows: the accumulator holds optical depths per channel; red and blue go to
    // lit_rb.
    coloured: u32,
    pad1: u32,
    pad2: u32,
}

@group(0) @binding(0) var<uniform> view: View;
@group(0) @binding(1) var<uniform> mp: Mark;
@group(0) @binding(2) var<storage, read> positions: array<f32>;
@group(0) @binding(3) var<storage, read> normals: array<f32>;
@group(0) @binding(4) var<storage, read> reference: array<f32>;
@group(0) @binding(5) var<storage, read_write> lit: array<u32>;
@group(0) @binding(6) var<storage, read_write> counters: array<atomic<u32>>;
// Per light pixel the blend accumulator (.w: the light the layers so far let through).
@group(0) @binding(7) var<storage, read> acc: array<vec4<f32>>;
// One bit per point of the cloud: marked by an earlier light layer of this sample.
@group(0) @binding(8) var<storage, read_write> marked: array<atomic<u32>>;
// Coloured shadows: per point and light, red | blue << 16.
@group(0) @binding(9) var<storage, read_write> lit_rb: array<u32>;

// cpu::amount
fn amount(t: f32) -> u32 {
    return u32(clamp(t, 0.0, 1.0) * 255.0 + 0.5);
}

var<workgroup> marked_here: atomic<u32>;

// shadow::dominant_face
fn dominant_face(d: vec3<f32>) -> u32 {
    let a = abs(d);
    if (a.x >= a.y && a.x >= a.z) {
        return select(1u, 0u, d.x >= 0.0);
    }
    if (a.y >= a.z) {
        return select(3u, 2u, d.y >= 0.0);
    }
    return select(5u, 4u, d.z >= 0.0);
}

// cpu::shadow_texture::light_gap and offset
fn offset(d: vec3<f32>, local: u32, z: f32) -> f32 {
    let gap = max(mp.gap, 3.0 * (2.0 / (f32(view.height) * view.sy) * z));
    if (mp.has_normals == 0u) {
        return gap;
    }
    let n = vec3<f32>(normals[3u * local], normals[3u * local + 1u], normals[3u * local + 2u]);
    let c = abs(dot3(d * (1.0 / sqrt(dot3(d, d))), n));
    if (c * mp.slope_cap > 1.0) {
        return gap * (1.0 / c);
    }
    return gap * mp.slope_cap;
}

@compute @workgroup_size(256)
fn mark(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(local_invocation_index) li: u32,
) {
    let local = group_index(wg, groups) * 256u + li;
    if (local < mp.count) {
        let i = mp.base + local;
        let bit = 1u << (i % 32u);
        let skip = mp.mode != 0u && (atomicLoad(&marked[i / 32u]) & bit) != 0u;
        let q = point_at(local);
        let d = q - view.eye;
        if (!skip && (mp.face == 6u || dominant_face(d) == mp.face)) {
            let h = project_point(q);
            if (h.ok && (mp.mode == 2u || h.depth <= reference[h.pixel] + offset(d, local, h.depth))) {
                var add = 255u;
                var red_blue = 255u | (255u << 16u);
                if (mp.mode != 0u) {
                    atomicOr(&marked[i / 32u], bit);
                    let a = acc[h.pixel];
                    if (mp.coloured == 1u) {
                        add = amount(exp(-a.y));
                        red_blue = amount(exp(-a.x)) | (amount(exp(-a.z)) << 16u);
                    } else {
                        add = amount(a.w);
                    }
                }
                if (mp.coloured == 1u) {
                    let r = 4u * local + mp.light;
                    lit_rb[r] = lit_rb[r] + red_blue;
                }
                let w = 2u * local + mp.light / 2u;
                lit[w] = lit[w] + (add << (16u * (mp.light % 2u)));
                atomicAdd(&marked_here, 1u);
            }
        }
    }
    workgroupBarrier();
    if (li == 0u) {
        atomicAdd(&counters[mp.slot], atomicLoad(&marked_here));
    }
}
