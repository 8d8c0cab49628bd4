// fill_planes: each pixel's tangent plane for the slope-aware occluded fill (CPU twin:
// cpu/fill.rs `FillPlane::of`), from the positions and normals gather wrote: with the normal
// turned to face the eye, the four numbers of cpu/fill.rs `plane_coefficients`, into
// plane[2k]; zero where the pixel shows no point or its point
// is seen edge-on (normal within 6° of perpendicular to the ray: common.wgsl's EDGE_COS2).

struct FillPlanes {
    pad0: u32,
    pad1: u32,
    pad2: u32,
    pad3: u32,
}

@group(0) @binding(0) var<uniform> view: View;
@group(0) @binding(1) var<uniform> fpl: FillPlanes;
@group(0) @binding(2) var<storage, read> id: array<u32>;
@group(0) @binding(3) var<storage, read> attr_pos: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read> attr_normal: array<vec4<f32>>;
@group(0) @binding(5) var<storage, read_write> plane: array<vec4<f32>>;

@compute @workgroup_size(8, 8)
fn fill_planes(@builtin(global_invocation_id) gid: vec3<u32>) {
    if (gid.x >= view.width || gid.y >= view.height) {
        return;
    }
    let k = gid.y * view.width + gid.x;
    var out = vec4<f32>(0.0);
    if (is_point(id[k])) {
        let x = attr_pos[k].xyz;
        var n = attr_normal[k].xyz;
        var ray = view.forward;
        if (view.perspective == 1u) {
            ray = x - view.eye;
        }
        let c = dot3(n, ray);
        if (!(c * c < EDGE_COS2 * dot3(n, n) * dot3(ray, ray))) {
            if (c > 0.0) {
                n = -n;
            }
            out = vec4<f32>(
                dot3(n, view.right) / view.sx,
                dot3(n, view.up) / view.sy,
                dot3(n, view.forward),
                dot3(n, view.eye) - dot3(n, x),
            );
        }
    }
    plane[2u * k] = out;
}
