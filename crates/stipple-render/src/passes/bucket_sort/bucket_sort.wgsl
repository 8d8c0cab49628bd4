// bucket_sort (Gunjee §4.2): points back to front in slices of thickness ε, by two levels of
// buckets. CPU twin: cpu.rs (see mod.rs for the algorithm). Kernels, in order:
//   depth_range  per chunk: each kept point's view depth (bits in `key`) and the range
//   classify     per chunk: depth → slice in `key`, first-level histogram
//   scan         one workgroup: first-level bucket starts (and running offsets)
//   scatter      per chunk: points into their first-level bucket (`first`)
//   refine       one workgroup per first-level bucket: its points into the K accurate
//                buckets, counted and scanned in workgroup memory (`order`)

struct Sort {
    base: u32,
    count: u32,
    near: f32,
    eps: f32,
    n: u32,
    k: u32,
    pad0: u32,
    pad1: u32,
}

@group(0) @binding(0) var<uniform> view: View;
@group(0) @binding(1) var<uniform> sp: Sort;
@group(0) @binding(2) var<storage, read> positions: array<f32>;
// Per point of the cloud: the depth's bits, then the slice; 0xffffffff where not kept.
@group(0) @binding(3) var<storage, read_write> key: array<u32>;
// [0, n): first-level running offsets; [n, 2n + 1): bucket starts (the last: points kept);
// [2n + 1], [2n + 2]: the least and greatest depth, order-preserving bits.
@group(0) @binding(4) var<storage, read_write> counts: array<atomic<u32>>;
@group(0) @binding(5) var<storage, read_write> first: array<u32>;
@group(0) @binding(6) var<storage, read_write> order: array<u32>;

const NONE: u32 = 0xffffffffu;
const MAX_K: u32 = 2048u;

// f32 bits that compare as unsigned integers in the order of the floats.
fn ordered(z: f32) -> u32 {
    let b = bitcast<u32>(z);
    if ((b & 0x80000000u) != 0u) {
        return ~b;
    }
    return b | 0x80000000u;
}

// Slicing::slice, operation for operation.
fn slice_of(z: f32) -> u32 {
    let s = max((z - sp.near) / sp.eps, 0.0);
    return min(u32(s), sp.n * sp.k - 1u);
}

@compute @workgroup_size(256)
fn depth_range(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(local_invocation_index) li: u32,
) {
    let local = group_index(wg, groups) * 256u + li;
    if (local >= sp.count) {
        return;
    }
    let h = project_point(point_at(local));
    if (h.ok) {
        key[sp.base + local] = bitcast<u32>(h.depth);
        atomicMin(&counts[2u * sp.n + 1u], ordered(h.depth));
        atomicMax(&counts[2u * sp.n + 2u], ordered(h.depth));
    } else {
        key[sp.base + local] = NONE;
    }
}

@compute @workgroup_size(256)
fn classify(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(local_invocation_index) li: u32,
) {
    let local = group_index(wg, groups) * 256u + li;
    if (local >= sp.count) {
        return;
    }
    let g = sp.base + local;
    let bits = key[g];
    if (bits != NONE) {
        let s = slice_of(bitcast<f32>(bits));
        key[g] = s;
        atomicAdd(&counts[sp.n - 1u - s / sp.k], 1u);
    }
}

var<workgroup> partial: array<u32, 256>;

// An exclusive scan of partial[0..256) in place (Hillis–Steele on inclusive sums).
fn scan_partials(li: u32) -> u32 {
    let own = partial[li];
    for (var step = 1u; step < 256u; step = step * 2u) {
        workgroupBarrier();
        var v = 0u;
        if (li >= step) {
            v = partial[li - step];
        }
        workgroupBarrier();
        partial[li] = partial[li] + v;
    }
    workgroupBarrier();
    return partial[li] - own;
}

@compute @workgroup_size(256)
fn scan(@builtin(local_invocation_index) li: u32) {
    let n = sp.n;
    let per = (n + 255u) / 256u;
    let lo = min(li * per, n);
    let hi = min(lo + per, n);
    var sum = 0u;
    for (var b = lo; b < hi; b++) {
        sum = sum + atomicLoad(&counts[b]);
    }
    partial[li] = sum;
    var at = scan_partials(li);
    for (var b = lo; b < hi; b++) {
        let c = atomicLoad(&counts[b]);
        atomicStore(&counts[b], at);
        atomicStore(&counts[n + b], at);
        at = at + c;
    }
    if (li == 255u) {
        atomicStore(&counts[2u * n], at);
    }
}

@compute @workgroup_size(256)
fn scatter(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(local_invocation_index) li: u32,
) {
    let local = group_index(wg, groups) * 256u + li;
    if (local >= sp.count) {
        return;
    }
    let g = sp.base + local;
    let s = key[g];
    if (s != NONE) {
        let at = atomicAdd(&counts[sp.n - 1u - s / sp.k], 1u);
        first[at] = g;
    }
}

var<workgroup> fine: array<atomic<u32>, MAX_K>;

@compute @workgroup_size(256)
fn refine(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(local_invocation_index) li: u32,
) {
    let b = group_index(wg, groups);
    if (b >= sp.n) {
        return;
    }
    let k = sp.k;
    let start = atomicLoad(&counts[sp.n + b]);
    let end = atomicLoad(&counts[sp.n + b + 1u]);
    for (var j = li; j < k; j += 256u) {
        atomicStore(&fine[j], 0u);
    }
    workgroupBarrier();
    for (var i = start + li; i < end; i += 256u) {
        atomicAdd(&fine[k - 1u - key[first[i]] % k], 1u);
    }
    workgroupBarrier();
    // Exclusive scan of the K counters: 256 runs, then their partial sums.
    let per = (k + 255u) / 256u;
    let lo = min(li * per, k);
    let hi = min(lo + per, k);
    var sum = 0u;
    for (var j = lo; j < hi; j++) {
        sum = sum + atomicLoad(&fine[j]);
    }
    partial[li] = sum;
    var at = start + scan_partials(li);
    for (var j = lo; j < hi; j++) {
        let c = atomicLoad(&fine[j]);
        atomicStore(&fine[j], at);
        at = at + c;
    }
    workgroupBarrier();
    for (var i = start + li; i < end; i += 256u) {
        let p = first[i];
        let at2 = atomicAdd(&fine[k - 1u - key[p] % k], 1u);
        order[at2] = p;
    }
}
