// Where each tile's list starts in the sorted entries: the first entry whose tile is not
// below it (a binary search), for tiles 0..=tiles, so tile t lists
// values[offsets[t] .. offsets[t + 1]].

@group(0) @binding(1) var<storage, read> keys: array<u32>;
@group(0) @binding(2) var<storage, read> entries: array<u32>;
@group(0) @binding(3) var<storage, read_write> offsets: array<u32>;

@compute @workgroup_size(GROUP, 1, 1)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let t = linear_id(wg, groups, lid);
    if (t > fit.tiles_x * fit.tiles_y) {
        return;
    }
    var lo = 0u;
    var hi = min(entries[0], fit.capacity);
    while (lo < hi) {
        let mid = lo + (hi - lo) / 2u;
        if (keys[mid] < t) {
            lo = mid + 1u;
        } else {
            hi = mid;
        }
    }
    offsets[t] = lo;
}
