// Stage 2's mixture, backward, one invocation per Gaussian, from the gradient of its
// mixed colour: the gradient of its K mixing logits (softmax backward; the host spreads
// it over the map through the tap), and per operator the gradients of η and of the two
// hidden layers' pre-activations, from which `enhance_params.wgsl` sums the parameters'
// gradients. `MixScratch::backward` in `enhance::fit`, term by term; every output is
// written, zeros included, since the buffers outlive the iteration.

@group(0) @binding(1) var<storage, read> params: array<f32>;
@group(0) @binding(2) var<storage, read> gauss: array<u32>;
@group(0) @binding(3) var<storage, read> trace: array<f32>;
@group(0) @binding(4) var<storage, read> g_col: array<f32>;
@group(0) @binding(5) var<storage, read_write> g_logits: array<f32>;
@group(0) @binding(6) var<storage, read_write> back: array<f32>;

@compute @workgroup_size(GROUP, 1, 1)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let g = linear_id(wg, groups, lid);
    if (g >= mix.count) {
        return;
    }
    let k_all = mix.experts;
    let h = mix.hidden;
    let gc = vec3<f32>(g_col[3u * g], g_col[3u * g + 1u], g_col[3u * g + 2u]);
    let c = color0(g);
    let tw = trace_w(g);
    var g_w: array<f32, WIDTH_MAX>;
    g_w[0] = dot(gc, c);
    var g2: array<f32, WIDTH_MAX>;
    for (var op = 1u; op < k_all; op = op + 1u) {
        let tr = trace_raw(g, op);
        let raw = vec3<f32>(trace[tr], trace[tr + 1u], trace[tr + 2u]);
        let y = min(max(raw, vec3<f32>(mix.lo)), vec3<f32>(mix.hi));
        g_w[op] = dot(gc, y);
        // d out / d η = w·c·exp(η) = w·raw where no clamp is active.
        let live = raw > vec3<f32>(mix.lo) & raw < vec3<f32>(mix.hi) & abs(raw) < abs(c) * mix.gain_max;
        let gy = select(vec3<f32>(0.0), trace[tw + op] * gc * raw, live);
        let g_eta = gy.x + gy.y + gy.z;
        back[back_eta(g, op)] = g_eta;
        let p = (op - 1u) * mix.per;
        let w2 = p + 4u * h;
        let w3 = w2 + h * h + h;
        let t1 = trace_h1(g, op);
        let t2 = trace_h2(g, op);
        let o1 = back_g1(g, op);
        let o2 = back_g2(g, op);
        for (var j = 0u; j < h; j = j + 1u) {
            var v = 0.0;
            if (trace[t2 + j] > 0.0) {
                v = g_eta * params[w3 + j];
            }
            g2[j] = v;
            back[o2 + j] = v;
        }
        for (var l = 0u; l < h; l = l + 1u) {
            var v = 0.0;
            for (var j = 0u; j < h; j = j + 1u) {
                v = v + g2[j] * params[w2 + j * h + l];
            }
            if (!(trace[t1 + l] > 0.0)) {
                v = 0.0;
            }
            back[o1 + l] = v;
        }
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
