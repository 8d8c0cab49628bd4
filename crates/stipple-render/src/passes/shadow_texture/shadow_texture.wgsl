// shadow_texture (Dobrev §6): count, per point, the light samples that reach it. CPU twin:
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
    // 8 × the light's index: which byte of the counts.
    shift: u32,
    has_normals: u32,
    slot: u32,
}

@group(0) @binding(0) var<uniform> view: View;
@group(0) @binding(1) var<uniform> mp: Mark;
@group(0) @binding(2) var<storage, read> positions: array<f32>;
@group(0) @binding(3) var<storage, read> normals: array<f32>;
@group(0) @binding(4) var<storage, read> reference: array<f32>;
@group(0) @binding(5) var<storage, read_write> lit: array<u32>;
@group(0) @binding(6) var<storage, read_write> counters: array<atomic<u32>>;

var<workgroup> marked: atomic<u32>;

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
        let q = point_at(local);
        let d = q - view.eye;
        if (mp.face == 6u || dominant_face(d) == mp.face) {
            let h = project_point(q);
            if (h.ok && h.depth <= reference[h.pixel] + offset(d, local, h.depth)) {
                lit[local] = lit[local] + (1u << mp.shift);
                atomicAdd(&marked, 1u);
            }
        }
    }
    workgroupBarrier();
    if (li == 0u) {
        atomicAdd(&counters[mp.slot], atomicLoad(&marked));
    }
}
