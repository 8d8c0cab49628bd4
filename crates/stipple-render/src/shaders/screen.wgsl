// Screen geometry shared by the raw-cloud passes (needs the pass to bind `view`; keep in
// sync with params.rs).

// ViewParams::view_position: the view-space position (camera at the origin, +z forward) at
// view depth z on pixel (i, j)'s centre ray.
fn view_position(i: u32, j: u32, z: f32) -> vec3<f32> {
    let nx = 2.0 * (f32(i) + 0.5) / f32(view.width) - 1.0;
    let ny = 1.0 - 2.0 * (f32(j) + 0.5) / f32(view.height);
    var s = 1.0;
    if (view.perspective == 1u) {
        s = z;
    }
    return vec3<f32>(nx / view.sx * s, ny / view.sy * s, z);
}

// ViewParams::footprint: the world size of one pixel at view depth z.
fn footprint(z: f32) -> f32 {
    var s = 1.0;
    if (view.perspective == 1u) {
        s = z;
    }
    return 2.0 / (f32(view.height) * view.sy) * s;
}
