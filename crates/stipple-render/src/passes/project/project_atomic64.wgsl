// project with 64-bit atomics (SHADER_INT64_ATOMIC_MIN_MAX): one atomicMax of the complemented
// key ~(depth bits << 32 | point index) per point, after an early-out read. The complement
// turns "nearest, then smallest index" into a maximum, so the buffer clears to zero.
// With only MIN_MAX the value an atomic returns must be discarded: it is.

@group(0) @binding(7) var<storage, read_write> vis: array<atomic<u64>>;

@compute @workgroup_size(256)
fn project(
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
        let key = ~((u64(bitcast<u32>(h.depth)) << 32u) | u64(h.index));
        if (key > atomicLoad(&vis[h.pixel])) {
            atomicMax(&vis[h.pixel], key);
        }
    }
    count_kept(li, mine);
}
