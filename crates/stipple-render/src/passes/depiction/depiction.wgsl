// depiction (Pintus §6): one level of Eq. 2 on a depth image (the next level's depth and the
// weighted term added to the accumulator), then the colour times the merged term. CPU twin:
// cpu/depiction.rs.

struct Depiction {
    // This level's normalised Eq. 3 weight.
    weight: f32,
    // ε in pixel footprints.
    epsilon: f32,
    // 1 at the first level: set the accumulator instead of adding.
    first: u32,
    pad: u32,
}

@group(0) @binding(0) var<uniform> view: View;
@group(0) @binding(1) var<uniform> dp: Depiction;
@group(0) @binding(2) var<storage, read> src_depth: array<f32>;
@group(0) @binding(3) var<storage, read_write> dst_depth: array<f32>;
@group(0) @binding(4) var<storage, read_write> acc: array<f32>;

@compute @workgroup_size(8, 8)
fn depiction_level(@builtin(global_invocation_id) gid: vec3<u32>) {
    if (gid.x >= view.width || gid.y >= view.height) {
        return;
    }
    let w = i32(view.width);
    let h = i32(view.height);
    let k = gid.y * view.width + gid.x;
    let d = src_depth[k];
    if (!is_finite(d)) {
        dst_depth[k] = d;
        if (dp.first == 1u) {
            acc[k] = 0.0;
        }
        return;
    }
    var vals: array<f32, 9>;
    var n = 0u;
    for (var dy = -1; dy <= 1; dy++) {
        let ny = i32(gid.y) + dy;
        if (ny < 0 || ny >= h) {
            continue;
        }
        for (var dx = -1; dx <= 1; dx++) {
            let nx = i32(gid.x) + dx;
            if (nx < 0 || nx >= w) {
                continue;
            }
            let z = src_depth[u32(ny * w + nx)];
            if (is_finite(z)) {
                vals[n] = z;
                n++;
            }
        }
    }
    var sum = 0.0;
    for (var i = 0u; i < n; i++) {
        sum += vals[i];
    }
    let mu = sum / f32(n);
    var var_sum = 0.0;
    for (var i = 0u; i < n; i++) {
        var_sum += (vals[i] - mu) * (vals[i] - mu);
    }
    let sigma = sqrt(var_sum / f32(n));
    let lo = mu - sigma;
    let hi = mu + sigma;
    let eps = dp.epsilon * footprint(d);
    let om = clamp(1.0 - abs(d - lo) / (hi - lo + eps), 0.0, 1.0);
    dst_depth[k] = 0.5 * (mu + lo);
    if (dp.first == 1u) {
        acc[k] = dp.weight * om;
    } else {
        acc[k] = acc[k] + dp.weight * om;
    }
}
