// Shared by every stipple shader (prepended at load time; keep in sync with params.rs).

// ViewParams (params.rs): the camera in the cloud's local frame.
struct View {
    eye: vec3<f32>,
    near: f32,
    right: vec3<f32>,
    far: f32,
    up: vec3<f32>,
    sx: f32,
    forward: vec3<f32>,
    sy: f32,
    width: u32,
    height: u32,
    perspective: u32,
    pad: u32,
}

// The id of a pixel that shows no point (gbuffer.rs BACKGROUND).
const BACKGROUND: u32 = 0xffffffffu;
// The id of a pixel the visibility operator emptied (gbuffer.rs HOLE): mutable by the fill.
const HOLE: u32 = 0xfffffffeu;

// cpu::project::EDGE_COS2: a normal whose squared cosine with the view ray is below this is
// seen edge-on (project.wgsl's facing, fill_planes.wgsl).
const EDGE_COS2: f32 = 0.01;

fn is_point(id: u32) -> bool {
    return id < HOLE;
}

fn infinity() -> f32 {
    return bitcast<f32>(0x7f800000u);
}

// Written out term by term, in the order the CPU reference (glam's Vec3::dot) adds them.
fn dot3(a: vec3<f32>, b: vec3<f32>) -> f32 {
    return a.x * b.x + a.y * b.y + a.z * b.z;
}

// The linear index of a workgroup in a 2-D dispatch (x up to the per-dimension limit, then y).
fn group_index(wg: vec3<u32>, groups: vec3<u32>) -> u32 {
    return wg.x + wg.y * groups.x;
}

fn is_finite(d: f32) -> bool {
    return d < infinity();
}

// The extremes of c / z over a splat's depths [zn, zf] (its screen bounds: splat.wgsl's
// footprint, sorted.wgsl's transparent splats).
fn ext_lo(c: f32, zn: f32, zf: f32) -> f32 {
    if (c >= 0.0) {
        return c / zf;
    }
    return c / zn;
}

fn ext_hi(c: f32, zn: f32, zf: f32) -> f32 {
    if (c >= 0.0) {
        return c / zn;
    }
    return c / zf;
}
