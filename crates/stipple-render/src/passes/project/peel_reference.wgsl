// peel_reference: what the next peeled layer is compared with (CPU twin: cpu.rs
// peel_reference, peel_planes and PeelTest). Per pixel two vec4s: [2k] the tangent plane of
// the layer's point there (normal, n · x), [2k + 1] (without normals: the largest finite
// depth of the 3×3 neighbourhood at most `bound` = 4 d̃ behind the pixel's own; the pixel's
// own depth; 1 when the plane is valid (the pixel shows a point and the cloud has normals)
// else 0; 0).

struct PeelReference {
    bound: f32,
    has_normals: u32,
    pad1: u32,
    pad2: u32,
}

@group(0) @binding(0) var<uniform> view: View;
@group(0) @binding(1) var<uniform> pr: PeelReference;
@group(0) @binding(2) var<storage, read> surface: array<f32>;
@group(0) @binding(3) var<storage, read_write> peel_ref: array<vec4<f32>>;
// The layer's per-pixel point positions and normals (written by shade's gather).
@group(0) @binding(4) var<storage, read> attr_pos: array<vec4<f32>>;
@group(0) @binding(5) var<storage, read> attr_normal: array<vec4<f32>>;

@compute @workgroup_size(8, 8)
fn peel_reference(@builtin(global_invocation_id) gid: vec3<u32>) {
    if (gid.x >= view.width || gid.y >= view.height) {
        return;
    }
    let w = view.width;
    let k = gid.y * w + gid.x;
    let d0 = surface[k];
    var m = d0;
    var valid = 0.0;
    var plane = vec4<f32>(0.0);
    if (is_finite(d0) && pr.has_normals == 1u) {
        let n = attr_normal[k].xyz;
        plane = vec4<f32>(n, dot3(n, attr_pos[k].xyz));
        valid = 1.0;
    } else if (is_finite(d0)) {
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
    peel_ref[2u * k] = plane;
    peel_ref[2u * k + 1u] = vec4<f32>(m, d0, valid, 0.0);
}
