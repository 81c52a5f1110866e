// Stage 2's mixture, forward, one invocation per Gaussian: `Enhancer::weights_at` (the
// bilinear tap of the logit map, then a softmax) and `Enhancer::operator` for every
// operator, mixed as `enhance::fit` mixes them, in the same order of operations. The
// activations go to `trace` for the backward pass.

@group(0) @binding(1) var<storage, read> params: array<f32>;
@group(0) @binding(2) var<storage, read> logits: array<f32>;
@group(0) @binding(3) var<storage, read> gauss: array<u32>;
@group(0) @binding(4) var<storage, read_write> colors: array<f32>;
@group(0) @binding(5) var<storage, read_write> trace: array<f32>;

@compute @workgroup_size(GROUP, 1, 1)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let g = linear_id(wg, groups, lid);
    if (g >= mix.count) {
        return;
    }
    let k_all = mix.experts;
    let h = mix.hidden;
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
        w[k] = w[k] / sum;
        trace[trace_w(g) + k] = w[k];
    }

    let c = color0(g);
    var out = c * w[0];
    var h1: array<f32, WIDTH_MAX>;
    for (var op = 1u; op < k_all; op = op + 1u) {
        let p = (op - 1u) * mix.per;
        let b1 = p + 3u * h;
        let w2 = b1 + h;
        let b2 = w2 + h * h;
        let w3 = b2 + h;
        let b3 = w3 + h;
        let t1 = trace_h1(g, op);
        let t2 = trace_h2(g, op);
        for (var j = 0u; j < h; j = j + 1u) {
            let v = params[b1 + j] + params[p + 3u * j] * c.x + params[p + 3u * j + 1u] * c.y
                + params[p + 3u * j + 2u] * c.z;
            h1[j] = v;
            trace[t1 + j] = v;
        }
        var eta = 0.0;
        for (var j = 0u; j < h; j = j + 1u) {
            var s = 0.0;
            for (var l = 0u; l < h; l = l + 1u) {
                s = s + params[w2 + h * j + l] * max(h1[l], 0.0);
            }
            let v = params[b2 + j] + s;
            trace[t2 + j] = v;
            eta = eta + params[w3 + j] * max(v, 0.0);
        }
        eta = params[b3] + eta;
        let raw = c * exp(min(eta, mix.gain_log_max));
        let tr = trace_raw(g, op);
        trace[tr] = raw.x;
        trace[tr + 1u] = raw.y;
        trace[tr + 2u] = raw.z;
        let y = min(max(raw, vec3<f32>(mix.lo)), vec3<f32>(mix.hi));
        out = out + w[op] * y;
    }
    colors[3u * g] = out.x;
    colors[3u * g + 1u] = out.y;
    colors[3u * g + 2u] = out.z;
}
