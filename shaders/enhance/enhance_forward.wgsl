// Stage 2's mixture, forward, in three entry points sharing these bindings:
// - `weights`, one invocation per Gaussian: `Enhancer::weights_at` (the bilinear tap of
//   the logit map, then a softmax);
// - `operators`, one invocation per (Gaussian, operator): `Enhancer::operator`;
// - `mixed`, one invocation per Gaussian: the operators' clamped outputs mixed by the
//   weights, in `enhance::fit`'s order.
// Splitting per operator keeps every invocation's loops short (software rasterizers such
// as lavapipe cut an invocation off after 65535 loop iterations) and gives a GPU K − 1
// times more invocations. The activations stay in `trace` for the backward pass.

@group(0) @binding(1) var<storage, read> params: array<f32>;
@group(0) @binding(2) var<storage, read> logits: array<f32>;
@group(0) @binding(3) var<storage, read> gauss: array<u32>;
@group(0) @binding(4) var<storage, read_write> colors: array<f32>;
@group(0) @binding(5) var<storage, read_write> trace: array<f32>;

@compute @workgroup_size(GROUP, 1, 1)
fn weights(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>,
           @builtin(local_invocation_index) lid: u32) {
    let g = linear_id(wg, groups, lid);
    if (g >= shape.count) {
        return;
    }
    let k_all = shape.experts;
    var w: array<f32, WIDTH_MAX>;
    for (var k = 0u; k < k_all; k = k + 1u) {
        w[k] = 0.0;
    }
    for (var i = 0u; i < 4u; i = i + 1u) {
        let cell = gauss[GAUSS * g + i];
        let b = bitcast<f32>(gauss[GAUSS * g + 4u + i]);
        for (var k = 0u; k < k_all; k = k + 1u) {
            w[k] = w[k] + b * logits[cell * k_all + k];
        }
    }
    // Softmax, shifted by the largest logit.
    var top = w[0];
    for (var k = 1u; k < k_all; k = k + 1u) {
        top = max(top, w[k]);
    }
    var sum = 0.0;
    for (var k = 0u; k < k_all; k = k + 1u) {
        w[k] = exp(w[k] - top);
        sum = sum + w[k];
    }
    for (var k = 0u; k < k_all; k = k + 1u) {
        trace[trace_w(g) + k] = w[k] / sum;
    }
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
    let c = color0(g);
    let t = tensors(op);
    let t1 = trace_h1(g, op);
    let t2 = trace_h2(g, op);
    var h1: array<f32, WIDTH_MAX>;
    for (var j = 0u; j < h; j = j + 1u) {
        let v = params[t.b1 + j] + params[t.w1 + 3u * j] * c.x
            + params[t.w1 + 3u * j + 1u] * c.y + params[t.w1 + 3u * j + 2u] * c.z;
        h1[j] = v;
        trace[t1 + j] = v;
    }
    var eta = 0.0;
    for (var j = 0u; j < h; j = j + 1u) {
        var s = 0.0;
        for (var l = 0u; l < h; l = l + 1u) {
            s = s + params[t.w2 + h * j + l] * max(h1[l], 0.0);
        }
        let v = params[t.b2 + j] + s;
        trace[t2 + j] = v;
        eta = eta + params[t.w3 + j] * max(v, 0.0);
    }
    eta = params[t.b3] + eta;
    let raw = c * exp(min(eta, shape.gain_log_max));
    let tr = trace_raw(g, op);
    trace[tr] = raw.x;
    trace[tr + 1u] = raw.y;
    trace[tr + 2u] = raw.z;
}

@compute @workgroup_size(GROUP, 1, 1)
fn mixed(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>,
         @builtin(local_invocation_index) lid: u32) {
    let g = linear_id(wg, groups, lid);
    if (g >= shape.count) {
        return;
    }
    let tw = trace_w(g);
    var out = color0(g) * trace[tw];
    for (var op = 1u; op < shape.experts; op = op + 1u) {
        out = out + trace[tw + op] * clamped(output(g, op));
    }
    colors[3u * g] = out.x;
    colors[3u * g + 1u] = out.y;
    colors[3u * g + 2u] = out.z;
}
