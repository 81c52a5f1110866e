// Backward pass of `alpha` blending. One workgroup per 16×16 tile, one invocation per
// pixel. Each pixel first replays the forward pass over the tile's list to find its
// final transmittance and how far down the list it took light (as `fit::raster::forward`
// records), then walks the list back to front, recovering the transmittance before each
// Gaussian and the colour composited behind it, exactly as `fit::raster::backward` does
// on the CPU. A Gaussian's gradient is the sum of its pixels' contributions: the
// workgroup adds them with a fixed tree reduction and writes one slot per list entry, so
// no atomics are needed and the result does not depend on scheduling.
//
// Bindings, `Params` and `SLOT` are in `backward_bindings.wgsl`, the contract constants in
// the prelude the host writes from the Rust constants (`gpu::contract`): it prepends both.

const PIXELS: u32 = 256u;

var<workgroup> partial: array<f32, 2304>; // PIXELS * SLOT

/// alpha of Gaussian `g` at pixel (i, j), capped, or 0 where spec §6.3 skips it.
fn alpha_at(g: u32, i: u32, j: u32) -> f32 {
    let b = boxes[g];
    if (i < b.x || i > b.z || j < b.y || j > b.w) {
        return 0.0;
    }
    let p0 = gaussians[3u * g];
    let p1 = gaussians[3u * g + 1u];
    let dx = (f32(i) + 0.5) - p0.x;
    let dy = (f32(j) + 0.5) - p0.y;
    let power = -0.5 * (p0.z * dx * dx + p1.x * dy * dy) - p0.w * dx * dy;
    if (power > 0.0) {
        return 0.0;
    }
    let alpha = min(p1.y * exp(power), ALPHA_MAX);
    if (alpha < ALPHA_MIN) {
        return 0.0;
    }
    return alpha;
}

@compute @workgroup_size(16, 16, 1)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_id) lid3: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let tile = wg.y * params.tiles_x + wg.x;
    let first = offsets[tile];
    let count = offsets[tile + 1u] - first;
    let i = wg.x * TILE + lid3.x;
    let j = wg.y * TILE + lid3.y;
    let inside = i < params.width && j < params.height;

    // Forward replay: final transmittance and the list length that took light.
    var trans = 1.0;
    var last = 0u;
    var d = vec3<f32>(0.0, 0.0, 0.0);
    if (inside) {
        for (var pos = 0u; pos < count; pos = pos + 1u) {
            let alpha = alpha_at(indices[first + pos], i, j);
            if (alpha == 0.0 || trans < TRANSMITTANCE_MIN) {
                continue;
            }
            trans = trans * (1.0 - alpha);
            last = pos + 1u;
        }
        let o = 3u * (j * params.width + i);
        d = vec3<f32>(dl_dimage[o], dl_dimage[o + 1u], dl_dimage[o + 2u]);
    }

    // Back to front.
    var behind = vec3<f32>(0.0, 0.0, 0.0);
    var prev_alpha = 0.0;
    var prev_color = vec3<f32>(0.0, 0.0, 0.0);
    for (var k = 0u; k < count; k = k + 1u) {
        let pos = count - 1u - k;
        let g = indices[first + pos];
        var s: array<f32, 9>;
        for (var q = 0u; q < SLOT; q = q + 1u) {
            s[q] = 0.0;
        }
        var alpha = 0.0;
        if (inside && pos < last) {
            alpha = alpha_at(g, i, j);
        }
        if (alpha > 0.0) {
            let p0 = gaussians[3u * g];
            let p1 = gaussians[3u * g + 1u];
            let p2 = gaussians[3u * g + 2u];
            let col = vec3<f32>(p1.z, p1.w, p2.x);
            let t = trans / (1.0 - alpha);
            trans = t;
            let b = prev_alpha * prev_color + (1.0 - prev_alpha) * behind;
            behind = b;
            s[6] = alpha * t * d.x;
            s[7] = alpha * t * d.y;
            s[8] = alpha * t * d.z;
            let dl_dalpha = (col.x - b.x) * t * d.x + (col.y - b.y) * t * d.y + (col.z - b.z) * t * d.z;
            prev_color = col;
            prev_alpha = alpha;
            // A capped alpha does not move with the geometry.
            if (alpha < ALPHA_MAX) {
                let dx = (f32(i) + 0.5) - p0.x;
                let dy = (f32(j) + 0.5) - p0.y;
                let dl_dpower = dl_dalpha * alpha;
                s[0] = dl_dpower * (p0.z * dx + p0.w * dy);
                s[1] = dl_dpower * (p1.x * dy + p0.w * dx);
                s[2] = dl_dpower * -0.5 * dx * dx;
                s[3] = dl_dpower * -dx * dy;
                s[4] = dl_dpower * -0.5 * dy * dy;
                s[5] = dl_dalpha * alpha / p1.y;
            }
        }
        for (var q = 0u; q < SLOT; q = q + 1u) {
            partial[lid * SLOT + q] = s[q];
        }
        workgroupBarrier();
        for (var stride = PIXELS / 2u; stride > 0u; stride = stride / 2u) {
            if (lid < stride) {
                for (var q = 0u; q < SLOT; q = q + 1u) {
                    partial[lid * SLOT + q] = partial[lid * SLOT + q] + partial[(lid + stride) * SLOT + q];
                }
            }
            workgroupBarrier();
        }
        if (lid == 0u) {
            for (var q = 0u; q < SLOT; q = q + 1u) {
                slots[SLOT * (first + pos) + q] = partial[q];
            }
        }
        workgroupBarrier();
    }
}
