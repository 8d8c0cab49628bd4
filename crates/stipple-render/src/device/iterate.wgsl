// iterate: for "until stable" iterations, writes the indirect dispatch arguments of the next
// iteration of a fill pass: its full grid while the previous iteration changed a pixel, an
// empty grid once it changed none (the stop is sticky: a skipped iteration counts zero).
// A stable iteration leaves its destination equal to its source, so the ping-pong buffers
// then hold the same image and skipping the rest is exact.

struct Iterate {
    prev_slot: u32,
    args_slot: u32,
    groups_x: u32,
    groups_y: u32,
}

@group(0) @binding(0) var<uniform> it: Iterate;
@group(0) @binding(1) var<storage, read> counters: array<u32>;
@group(0) @binding(2) var<storage, read_write> args: array<u32>;

@compute @workgroup_size(1)
fn iterate() {
    let go = counters[it.prev_slot] != 0u;
    args[3u * it.args_slot] = select(0u, it.groups_x, go);
    args[3u * it.args_slot + 1u] = select(0u, it.groups_y, go);
    args[3u * it.args_slot + 2u] = select(0u, 1u, go);
}
