// The gradient of every operator parameter, one invocation per parameter, summed over
// the Gaussians as `enhance::fit` sums it: in chunks of `mix.chunk` Gaussians, each
// chunk's sum added to the total in order. The order is fixed, so the result does not
// depend on scheduling, and no atomics are needed.

@group(0) @binding(1) var<storage, read> gauss: array<u32>;
@group(0) @binding(2) var<storage, read> trace: array<f32>;
@group(0) @binding(3) var<storage, read> back: array<f32>;
@group(0) @binding(4) var<storage, read_write> g_params: array<f32>;

// Gaussian g's share of the gradient of parameter q of operator op.
fn share(g: u32, op: u32, q: u32) -> f32 {
    let h = mix.hidden;
    if (q < 3u * h) {
        // W1[l][ci]
        let c = color0(g);
        return back[back_g1(g, op) + q / 3u] * c[q % 3u];
    }
    if (q < 4u * h) {
        return back[back_g1(g, op) + q - 3u * h];
    }
    if (q < 4u * h + h * h) {
        // W2[j][l]
        let r = q - 4u * h;
        return back[back_g2(g, op) + r / h] * max(trace[trace_h1(g, op) + r % h], 0.0);
    }
    if (q < 5u * h + h * h) {
        return back[back_g2(g, op) + q - 4u * h - h * h];
    }
    if (q < 6u * h + h * h) {
        // W3[j]
        let j = q - 5u * h - h * h;
        return back[back_eta(g, op)] * max(trace[trace_h2(g, op) + j], 0.0);
    }
    return back[back_eta(g, op)];
}

@compute @workgroup_size(GROUP, 1, 1)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let i = linear_id(wg, groups, lid);
    if (i >= (mix.experts - 1u) * mix.per) {
        return;
    }
    let op = i / mix.per + 1u;
    let q = i % mix.per;
    var total = 0.0;
    for (var start = 0u; start < mix.count; start = start + mix.chunk) {
        var part = 0.0;
        let end = min(start + mix.chunk, mix.count);
        for (var g = start; g < end; g = g + 1u) {
            part = part + share(g, op, q);
        }
        total = total + part;
    }
    g_params[i] = total;
}
