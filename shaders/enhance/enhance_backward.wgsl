// Stage 2's mixture, backward, from the gradient of each Gaussian's mixed colour, in two
// entry points sharing these bindings (split as the forward pass is, and for the same
// reasons):
// - `operators`, one invocation per (Gaussian, operator): the gradients of η and of the
//   two hidden layers' pre-activations, from which `enhance_params.wgsl` sums the
//   parameters' gradients;
// - `logits`, one invocation per Gaussian: the gradient of its K mixing logits (softmax
//   backward; the host spreads it over the map through the tap).
// `MixScratch::backward` in `enhance::fit`, term by term. Every output is written, zeros
// included, since the buffers outlive the iteration.

@group(0) @binding(1) var<storage, read> params: array<f32>;
@group(0) @binding(2) var<storage, read> gauss: array<u32>;
@group(0) @binding(3) var<storage, read> trace: array<f32>;
@group(0) @binding(4) var<storage, read> g_col: array<f32>;
@group(0) @binding(5) var<storage, read_write> g_logits: array<f32>;
@group(0) @binding(6) var<storage, read_write> back: array<f32>;

fn color_gradient(g: u32) -> vec3<f32> {
    return vec3<f32>(g_col[3u * g], g_col[3u * g + 1u], g_col[3u * g + 2u]);
}

@compute @workgroup_size(GROUP, 1, 1)
fn operators(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>,
             @builtin(local_invocation_index) lid: u32) {
    let item = gaussian_and_operator(linear_id(wg, groups, lid));
    if (item.x >= shape.count) {
        return;
    }
    let g = item.x;
    let op = item.y;
    let h = shape.hidden;
    let gc = color_gradient(g);
    let c = color0(g);
    let raw = output(g, op);
    // d out / d η = w·c·exp(η) = w·raw where no clamp is active.
    let live = (raw > vec3<f32>(shape.lo)) & (raw < vec3<f32>(shape.hi))
        & (abs(raw) < abs(c) * exp(shape.gain_log_max));
    let gy = select(vec3<f32>(0.0), trace[trace_w(g) + op] * gc * raw, live);
    let g_eta = gy.x + gy.y + gy.z;
    back[back_eta(g, op)] = g_eta;
    let t = tensors(op);
    let t1 = trace_h1(g, op);
    let t2 = trace_h2(g, op);
    let o1 = back_g1(g, op);
    let o2 = back_g2(g, op);
    var g2: array<f32, WIDTH_MAX>;
    for (var j = 0u; j < h; j = j + 1u) {
        var v = 0.0;
        if (trace[t2 + j] > 0.0) {
            v = g_eta * params[t.w3 + j];
        }
        g2[j] = v;
        back[o2 + j] = v;
    }
    for (var l = 0u; l < h; l = l + 1u) {
        var v = 0.0;
        for (var j = 0u; j < h; j = j + 1u) {
            v = v + g2[j] * params[t.w2 + j * h + l];
        }
        if (!(trace[t1 + l] > 0.0)) {
            v = 0.0;
        }
        back[o1 + l] = v;
    }
}

@compute @workgroup_size(GROUP, 1, 1)
fn logits(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>,
          @builtin(local_invocation_index) lid: u32) {
    let g = linear_id(wg, groups, lid);
    if (g >= shape.count) {
        return;
    }
    let k_all = shape.experts;
    let gc = color_gradient(g);
    let tw = trace_w(g);
    var g_w: array<f32, WIDTH_MAX>;
    g_w[0] = dot(gc, color0(g));
    for (var op = 1u; op < k_all; op = op + 1u) {
        g_w[op] = dot(gc, clamped(output(g, op)));
    }
    // Softmax: d/d logit_k = w_k (g_w_k − Σ_j w_j g_w_j).
    var s = 0.0;
    for (var k = 0u; k < k_all; k = k + 1u) {
        s = s + trace[tw + k] * g_w[k];
    }
    for (var k = 0u; k < k_all; k = k + 1u) {
        g_logits[g * k_all + k] = trace[tw + k] * (g_w[k] - s);
    }
}
