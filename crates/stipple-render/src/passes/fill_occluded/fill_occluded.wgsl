// fill_occluded (Dobrev §3.3): a covered pixel surrounded on every side by points at least d̃
// nearer shows a hidden surface, and takes the nearest neighbour's point. Used with
// fill.wgsl; CPU twin: cpu/fill_occluded.rs and cpu/fill.rs (`FillPlane`).

fn candidate(d: f32, id: u32) -> bool {
    return is_point(id);
}

// The tangent plane of the pixel's point (cpu::fill::plane_coefficients; zero where it says
// nothing), or zero without planes.
fn own_plane(k: u32) -> vec4<f32> {
    if (fp.planes == 0u) {
        return vec4<f32>(0.0);
    }
    return plane[2u * k + fp.parity];
}

// The pixel k keeps the plane of pixel `src` for the next step.
fn carry(k: u32, src: u32) {
    if (fp.planes == 1u) {
        plane[2u * k + 1u - fp.parity] = plane[2u * src + fp.parity];
    }
}

// cpu::fill::FillPlane::in_front (own: cpu::fill::plane_coefficients).
fn in_front(own: vec4<f32>, nx: i32, ny: i32, nd: f32) -> bool {
    let u = (f32(nx) + 0.5) * (2.0 / f32(view.width)) - 1.0;
    let v = 1.0 - (f32(ny) + 0.5) * (2.0 / f32(view.height));
    var off = 0.0;
    if (view.perspective == 1u) {
        off = own.w + nd * (own.z + u * own.x + v * own.y);
    } else {
        off = own.w + u * own.x + v * own.y + nd * own.z;
    }
    return off > fp.gap;
}

fn solid(d: f32, own: vec4<f32>, nd: f32, nid: u32, nx: i32, ny: i32) -> bool {
    if (!(nd <= d - fp.gap)) {
        return false;
    }
    if (all(own == vec4<f32>(0.0))) {
        return true;
    }
    return in_front(own, nx, ny, nd);
}
