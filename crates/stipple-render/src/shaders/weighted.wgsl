// The 3×3 weighted mean shared by smooth and antialias (cpu/smooth.rs weighted_3x3): rows top
// to bottom, columns left to right, cells outside the image skipped, weights renormalised.
// `include` is defined by the pass.

fn weighted_3x3(x: i32, y: i32, weights: array<f32, 9>) -> vec3<f32> {
    let w = i32(view.width);
    let h = i32(view.height);
    var acc = vec3<f32>(0.0);
    var sum = 0.0;
    for (var dy = -1; dy <= 1; dy++) {
        let ny = y + dy;
        if (ny < 0 || ny >= h) {
            continue;
        }
        for (var dx = -1; dx <= 1; dx++) {
            let nx = x + dx;
            if (nx < 0 || nx >= w) {
                continue;
            }
            let n = ny * w + nx;
            if (!include(n)) {
                continue;
            }
            let f = weights[(dy + 1) * 3 + dx + 1];
            let c = src[n].xyz;
            acc = vec3<f32>(acc.x + f * c.x, acc.y + f * c.y, acc.z + f * c.z);
            sum += f;
        }
    }
    return acc / sum;
}
