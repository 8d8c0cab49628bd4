// The projection of a point (cpu::project::project_point, operation for operation), shared by
// project and shadow_texture. Needs `view` and `positions` declared by the including shader.

struct Hit {
    ok: bool,
    pixel: u32,
    depth: f32,
    // The point's index in the whole cloud.
    index: u32,
}

fn point_at(i: u32) -> vec3<f32> {
    return vec3<f32>(positions[3u * i], positions[3u * i + 1u], positions[3u * i + 2u]);
}

// cpu::project::project_point, operation for operation.
fn project_point(p: vec3<f32>) -> Hit {
    var h: Hit;
    h.ok = false;
    let d = p - view.eye;
    let z = dot3(d, view.forward);
    if (!(z >= view.near && z <= view.far)) {
        return h;
    }
    let x = dot3(d, view.right);
    let y = dot3(d, view.up);
    var nx: f32;
    var ny: f32;
    if (view.perspective == 1u) {
        let iz = 1.0 / z;
        nx = x * view.sx * iz;
        ny = y * view.sy * iz;
    } else {
        nx = x * view.sx;
        ny = y * view.sy;
    }
    let w = f32(view.width);
    let hh = f32(view.height);
    let fx = (nx + 1.0) * 0.5 * w;
    let fy = (1.0 - ny) * 0.5 * hh;
    if (!(fx >= 0.0 && fx < w && fy >= 0.0 && fy < hh)) {
        return h;
    }
    h.ok = true;
    h.pixel = u32(fy) * view.width + u32(fx);
    h.depth = z;
    return h;
}
