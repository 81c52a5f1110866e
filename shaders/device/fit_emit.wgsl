// One (tile, Gaussian) entry per tile a Gaussian covers, written in stored order of the
// Gaussians and row-major over each one's tiles. A stable sort by tile then gives every
// tile its Gaussians in stored order, which `alpha` blending needs and which keeps the
// backward pass's sums in a fixed order. Entries past the capacity are dropped; the step
// that overflowed is then skipped (`fit_adam.wgsl`) and the host grows the buffers.

@group(0) @binding(1) var<storage, read> boxes: array<vec4<u32>>;
@group(0) @binding(2) var<storage, read> first_entry: array<u32>;
@group(0) @binding(3) var<storage, read_write> keys: array<u32>;
@group(0) @binding(4) var<storage, read_write> values: array<u32>;

@compute @workgroup_size(GROUP, 1, 1)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let g = linear_id(wg, groups, lid);
    if (g >= fit.count) {
        return;
    }
    let b = boxes[g];
    if (b.x > b.z) {
        return;
    }
    var e = first_entry[g];
    for (var ty = b.y / TILE; ty <= b.w / TILE; ty = ty + 1u) {
        for (var tx = b.x / TILE; tx <= b.z / TILE; tx = tx + 1u) {
            if (e >= fit.capacity) {
                return;
            }
            keys[e] = ty * fit.tiles_x + tx;
            values[e] = g;
            e = e + 1u;
        }
    }
}
