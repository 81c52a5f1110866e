// Backward pass of `sum` blending: for every entry of every tile list, the gradient of
// the loss with respect to that Gaussian's pixel-space mean, conic, opacity and colour,
// summed over the tile's pixels. One workgroup per tile; its invocations share out the
// tile's list entries, and each writes its own slot, so no atomics are needed and the
// host sums a Gaussian's slots in a fixed order (as `fit::raster::backward` does on the
// CPU, whose arithmetic this follows term by term).
//
// Bindings, `Params` and `SLOT` are in `backward_bindings.wgsl`, the contract constants in
// the prelude the host writes from the Rust constants (`gpu::contract`): it prepends both.

@compute @workgroup_size(64, 1, 1)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let tile = wg.y * params.tiles_x + wg.x;
    let first = offsets[tile];
    let last = offsets[tile + 1u];
    let x0 = wg.x * TILE;
    let y0 = wg.y * TILE;
    let x1 = min(x0 + TILE, params.width);
    let y1 = min(y0 + TILE, params.height);
    for (var e = first + lid; e < last; e = e + 64u) {
        let g = indices[e];
        let b = boxes[g];
        let p0 = gaussians[3u * g];
        let p1 = gaussians[3u * g + 1u];
        let p2 = gaussians[3u * g + 2u];
        let col = vec3<f32>(p1.z, p1.w, p2.x);
        var dc = vec3<f32>(0.0, 0.0, 0.0);
        var gx = 0.0;
        var gy = 0.0;
        var ga = 0.0;
        var gb = 0.0;
        var gc = 0.0;
        var go = 0.0;
        let ys = max(y0, b.y);
        let ye = min(y1, b.w + 1u);
        let xs = max(x0, b.x);
        let xe = min(x1, b.z + 1u);
        for (var j = ys; j < ye; j = j + 1u) {
            let dy = (f32(j) + 0.5) - p0.y;
            for (var i = xs; i < xe; i = i + 1u) {
                let dx = (f32(i) + 0.5) - p0.x;
                let power = -0.5 * (p0.z * dx * dx + p1.x * dy * dy) - p0.w * dx * dy;
                if (power > 0.0) {
                    continue;
                }
                let alpha = p1.y * exp(power);
                if (alpha < ALPHA_MIN) {
                    continue;
                }
                let o = 3u * (j * params.width + i);
                let d = vec3<f32>(dl_dimage[o], dl_dimage[o + 1u], dl_dimage[o + 2u]);
                dc = dc + alpha * d;
                let dl_dpower = dot(col, d) * alpha;
                gx = gx + dl_dpower * (p0.z * dx + p0.w * dy);
                gy = gy + dl_dpower * (p1.x * dy + p0.w * dx);
                ga = ga + dl_dpower * dx * dx;
                gb = gb + dl_dpower * dx * dy;
                gc = gc + dl_dpower * dy * dy;
                go = go + dl_dpower;
            }
        }
        let s = SLOT * e;
        slots[s] = gx;
        slots[s + 1u] = gy;
        slots[s + 2u] = -0.5 * ga;
        slots[s + 3u] = -gb;
        slots[s + 4u] = -0.5 * gc;
        slots[s + 5u] = go / p1.y;
        slots[s + 6u] = dc.x;
        slots[s + 7u] = dc.y;
        slots[s + 8u] = dc.z;
    }
}
