// fill_occluded (Dobrev §3.3): a covered pixel surrounded on every side by points at least d̃
// nearer shows a hidden surface, and takes the nearest neighbour's point. Used with
// fill.wgsl; CPU twin: cpu/fill_occluded.rs.

fn candidate(d: f32, id: u32) -> bool {
    return is_point(id);
}

fn solid(d: f32, nd: f32, nid: u32) -> bool {
    return nd <= d - fp.gap;
}
