// peel_reference: the reference depth of the next peeled layer, per pixel the largest finite
// depth of the layer's 3×3 neighbourhood at most `bound` (4 d̃) behind the pixel's own
// (+inf stays +inf). CPU twin: cpu.rs peel_reference.

struct PeelReference {
    bound: f32,
    pad0: u32,
    pad1: u32,
    pad2: u32,
}

@group(0) @binding(0) var<uniform> view: View;
@group(0) @binding(1) var<uniform> pr: PeelReference;
@group(0) @binding(2) var<storage, read> surface: array<f32>;
@group(0) @binding(3) var<storage, read_write> peel_ref: array<f32>;

@compute @workgroup_size(8, 8)
fn peel_reference(@builtin(global_invocation_id) gid: vec3<u32>) {
    if (gid.x >= view.width || gid.y >= view.height) {
        return;
    }
    let w = view.width;
    let k = gid.y * w + gid.x;
    let d0 = surface[k];
    var m = d0;
    if (is_finite(d0)) {
        let limit = d0 + pr.bound;
        let y0 = max(i32(gid.y) - 1, 0);
        let y1 = min(i32(gid.y) + 1, i32(view.height) - 1);
        let x0 = max(i32(gid.x) - 1, 0);
        let x1 = min(i32(gid.x) + 1, i32(w) - 1);
        for (var y = y0; y <= y1; y = y + 1) {
            for (var x = x0; x <= x1; x = x + 1) {
                let d = surface[u32(y) * w + u32(x)];
                if (is_finite(d) && d > m && d <= limit) {
                    m = d;
                }
            }
        }
    }
    peel_ref[k] = m;
}
