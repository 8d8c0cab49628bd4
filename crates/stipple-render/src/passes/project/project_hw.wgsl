// project_hw: the hardware baseline for project — a PointList render pipeline with a depth
// test (1-pixel points; ties go to the earlier point, as primitives rasterize in order), then
// a compute pass that copies the id and view-depth targets into the G-buffer.

// The compute projection's ChunkBlock (the hardware path reads base, count and cull).
struct Chunk {
    base: u32,
    count: u32,
    cull: u32,
    slot: u32,
    peel: u32,
    gap: f32,
    pad0: u32,
    pad1: u32,
}

@group(0) @binding(0) var<uniform> view: View;
@group(0) @binding(1) var<uniform> chunk: Chunk;

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) @interpolate(flat) id: u32,
    @location(1) @interpolate(flat) depth: f32,
}

@vertex
fn vs(@builtin(vertex_index) vi: u32, @location(0) p: vec3<f32>, @location(1) n: vec3<f32>) -> VertexOut {
    var out: VertexOut;
    let d = p - view.eye;
    let z = dot3(d, view.forward);
    let x = dot3(d, view.right);
    let y = dot3(d, view.up);
    out.id = chunk.base + vi;
    out.depth = z;
    var to_point = view.forward;
    if (view.perspective == 1u) {
        to_point = d;
    }
    if (chunk.cull == 1u && dot3(n, to_point) > 0.0) {
        // Outside the clip volume: discarded before rasterization.
        out.clip = vec4<f32>(0.0, 0.0, 2.0, 1.0);
        return out;
    }
    let zr = (z - view.near) / (view.far - view.near);
    if (view.perspective == 1u) {
        out.clip = vec4<f32>(x * view.sx, y * view.sy, zr * view.far, z);
    } else {
        out.clip = vec4<f32>(x * view.sx, y * view.sy, zr, 1.0);
    }
    return out;
}

struct FragmentOut {
    @location(0) id: u32,
    @location(1) depth: f32,
}

@fragment
fn fs(v: VertexOut) -> FragmentOut {
    var out: FragmentOut;
    out.id = v.id;
    out.depth = v.depth;
    return out;
}

@group(0) @binding(2) var id_target: texture_2d<u32>;
@group(0) @binding(3) var depth_target: texture_2d<f32>;
@group(0) @binding(4) var<storage, read_write> g_depth: array<f32>;
@group(0) @binding(5) var<storage, read_write> g_id: array<u32>;

@compute @workgroup_size(8, 8)
fn copy_targets(@builtin(global_invocation_id) gid: vec3<u32>) {
    if (gid.x >= view.width || gid.y >= view.height) {
        return;
    }
    let k = gid.y * view.width + gid.x;
    let id = textureLoad(id_target, vec2<i32>(gid.xy), 0).x;
    g_id[k] = id;
    if (id == BACKGROUND) {
        g_depth[k] = infinity();
    } else {
        g_depth[k] = textureLoad(depth_target, vec2<i32>(gid.xy), 0).x;
    }
}
