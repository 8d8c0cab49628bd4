// fill_background (Dobrev §3.2): background pixels inside the silhouette take a neighbour's
// point. Used with fill.wgsl; CPU twin: cpu/fill_background.rs.

fn candidate(d: f32, id: u32) -> bool {
    return !is_point(id);
}

fn solid(d: f32, nd: f32, nid: u32) -> bool {
    return is_point(nid);
}
