// resolve: the visibility buffer of project (complemented keys) → G-buffer depth + point id.
// 64-bit keys are read as two 32-bit words (x = low = ~index, y = high = ~depth bits); the
// 32-bit fallback's two buffers are bound the same way, as separate words. Empty pixels hold
// zero: background (depth +inf).

struct Resolve {
    // 1: keys are 64-bit (words interleaved), 0: two separate buffers.
    wide: u32,
    pad0: u32,
    pad1: u32,
    pad2: u32,
}

@group(0) @binding(0) var<uniform> view: View;
@group(0) @binding(1) var<uniform> rp: Resolve;
@group(0) @binding(2) var<storage, read> vis: array<u32>;
@group(0) @binding(3) var<storage, read> vis_id: array<u32>;
@group(0) @binding(4) var<storage, read_write> depth: array<f32>;
@group(0) @binding(5) var<storage, read_write> id: array<u32>;

@compute @workgroup_size(256)
fn resolve(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(local_invocation_index) li: u32,
) {
    let i = group_index(wg, groups) * 256u + li;
    if (i >= view.width * view.height) {
        return;
    }
    var hi: u32;
    var lo: u32;
    if (rp.wide == 1u) {
        lo = vis[2u * i];
        hi = vis[2u * i + 1u];
    } else {
        hi = vis[i];
        lo = vis_id[i];
    }
    if (hi == 0u) {
        depth[i] = infinity();
        id[i] = BACKGROUND;
    } else {
        depth[i] = bitcast<f32>(~hi);
        id[i] = ~lo;
    }
}
