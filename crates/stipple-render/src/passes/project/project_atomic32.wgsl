// project without 64-bit atomics: two passes over the points. Pass 1 keeps the nearest depth
// per pixel (atomicMax of the complemented depth bits; depths are positive, so their bits
// order like the values); pass 2 keeps, among the points at exactly that depth, the smallest
// index. The result equals the 64-bit key minimum.

@group(0) @binding(7) var<storage, read_write> vis_depth: array<atomic<u32>>;
@group(0) @binding(8) var<storage, read_write> vis_id: array<atomic<u32>>;

@compute @workgroup_size(256)
fn project_depth(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(local_invocation_index) li: u32,
) {
    var mine = 0u;
    for (var k = 0u; k < BATCH; k++) {
        let h = visible_point(wg, groups, li, k);
        if (!h.ok) {
            continue;
        }
        mine += 1u;
        let key = ~bitcast<u32>(h.depth);
        if (key > atomicLoad(&vis_depth[h.pixel])) {
            atomicMax(&vis_depth[h.pixel], key);
        }
    }
    count_kept(li, mine);
}

@compute @workgroup_size(256)
fn project_index(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(local_invocation_index) li: u32,
) {
    for (var k = 0u; k < BATCH; k++) {
        let h = visible_point(wg, groups, li, k);
        if (!h.ok) {
            continue;
        }
        if (~bitcast<u32>(h.depth) == atomicLoad(&vis_depth[h.pixel])) {
            atomicMax(&vis_id[h.pixel], ~h.index);
        }
    }
}
