// fill_background (Dobrev §3.2): background pixels inside the silhouette take a neighbour's
// point. Used with fill.wgsl; CPU twin: cpu/fill_background.rs.

fn candidate(d: f32, id: u32) -> bool {
    return !is_point(id);
}

fn own_plane(k: u32) -> vec4<f32> {
    return vec4<f32>(0.0);
}

fn carry(k: u32, src: u32) {
}

fn solid(d: f32, own: vec4<f32>, nd: f32, nid: u32, nx: i32, ny: i32) -> bool {
    return is_point(nid);
}
