// The gradient of every operator parameter over one chunk of `shape.chunk` Gaussians,
// one invocation per (chunk, parameter), summed in Gaussian order: the partial sums
// `enhance::fit` adds per chunk. The host adds the chunks in order, so the result does
// not depend on scheduling, and no atomics are needed.

@group(0) @binding(1) var<storage, read> gauss: array<u32>;
@group(0) @binding(2) var<storage, read> trace: array<f32>;
@group(0) @binding(3) var<storage, read> back: array<f32>;
// Chunk-major: chunk c's sum for parameter i at c·params + i.
@group(0) @binding(4) var<storage, read_write> partials: array<f32>;

// Gaussian g's share of the gradient of parameter q of operator op.
fn share(g: u32, op: u32, q: u32) -> f32 {
    let h = shape.hidden;
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
    let params = (shape.experts - 1u) * shape.per;
    let chunks = (shape.count + shape.chunk - 1u) / shape.chunk;
    let id = linear_id(wg, groups, lid);
    if (params == 0u || id >= chunks * params) {
        return;
    }
    let chunk = id / params;
    let i = id % params;
    let op = i / shape.per + 1u;
    let q = i % shape.per;
    let start = chunk * shape.chunk;
    let end = min(start + shape.chunk, shape.count);
    var part = 0.0;
    for (var g = start; g < end; g = g + 1u) {
        part = part + share(g, op, q);
    }
    partials[id] = part;
}
