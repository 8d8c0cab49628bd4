// The bindings every pixel pass shares (passes/pixel.rs); binding 1 is the pass's own
// uniform block, declared in its file.
@group(0) @binding(0) var<uniform> view: View;
@group(0) @binding(2) var<storage, read> ids: array<u32>;
@group(0) @binding(3) var<storage, read> depth: array<f32>;
@group(0) @binding(4) var<storage, read> src: array<vec4<f32>>;
@group(0) @binding(5) var<storage, read_write> dst: array<vec4<f32>>;
