// Per-Gaussian projection for the fitting loop: the parameters this step renders (the
// float ones, or during quantization-aware steps the values the file would hold), then
// format-spec.md §6 steps 1–7 as `render::project` does them: covariance, clamps, conic,
// centre, pixel box, opacity and colour. A Gaussian that can touch no pixel gets no tile.
// The output layout is the one `render.wgsl` and the backward passes read, with the
// rendered ln σ1, ln σ2 and θ in the free lanes, where the chain rule finds them.

@group(0) @binding(1) var<storage, read> params: array<f32>;
@group(0) @binding(2) var<storage, read> ranges: array<f32>;
// Three vec4 per Gaussian: (mx, my, A, B), (C, opacity, r, g), (b, ln σ1, ln σ2, θ).
@group(0) @binding(3) var<storage, read_write> gaussians: array<vec4<f32>>;
// Pixel box (x0, y0, x1, y1), inclusive; x0 > x1 for a Gaussian that is not drawn.
@group(0) @binding(4) var<storage, read_write> boxes: array<vec4<u32>>;
// Tiles the pixel box covers; 0 for a Gaussian that is not drawn.
@group(0) @binding(5) var<storage, read_write> touched: array<u32>;

fn bits_of(k: u32) -> u32 {
    if (k < 2u) {
        return fit.bits_position;
    }
    if (k < 4u) {
        return fit.bits_covariance;
    }
    if (k == 4u) {
        return fit.bits_angle;
    }
    if (k < 8u) {
        return fit.bits_color;
    }
    return fit.bits_opacity;
}

// `Quantizer::quantize` then `dequantize` (format/quant.rs), in f32: the nearest of
// 2^bits levels between the component's ends, both ends exact.
fn quantized(x: f32, k: u32) -> f32 {
    let lo = ranges[2u * k];
    let hi = ranges[2u * k + 1u];
    let bits = bits_of(k);
    if (bits == 0u || !(hi > lo)) {
        return lo;
    }
    let top = f32((1u << bits) - 1u);
    let code = floor(clamp((x - lo) / (hi - lo), 0.0, 1.0) * top + 0.5);
    let t = code / top;
    return clamp(lo * (1.0 - t) + hi * t, lo, hi);
}

// `render::project::pixel_span`: pixels whose centre lies in [m - r, m + r], clipped;
// x > y when there are none.
fn pixel_span(m: f32, r: f32, n: u32) -> vec2<u32> {
    let lo = ceil(m - r - 0.5);
    let hi = floor(m + r - 0.5);
    if (!(lo <= hi && hi >= 0.0)) {
        return vec2<u32>(1u, 0u);
    }
    let limit = f32(n);
    let a = u32(clamp(lo, 0.0, limit));
    let b = min(u32(clamp(hi, 0.0, limit)), n - 1u);
    if (a > b) {
        return vec2<u32>(1u, 0u);
    }
    return vec2<u32>(a, b);
}

@compute @workgroup_size(GROUP, 1, 1)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let g = linear_id(wg, groups, lid);
    if (g >= fit.count) {
        return;
    }
    var p: array<f32, 9>;
    for (var k = 0u; k < STRIDE; k = k + 1u) {
        var x = params[g * STRIDE + k];
        if (fit.qat != 0u && (k < 8u || fit.has_opacity != 0u)) {
            x = quantized(x, k);
        }
        p[k] = x;
    }
    touched[g] = 0u;
    boxes[g] = vec4<u32>(1u, 1u, 0u, 0u);
    let fw = f32(fit.width);
    let fh = f32(fit.height);

    // Steps 1-4 (`CovParam::covariance`, then the pixel clamps and the conic). The
    // clamps keep det ≥ (1 - CORRELATION_MAX²)·VAR_MIN² > 0, so the conic is finite.
    var s = vec3<f32>(0.0);
    if (fit.cholesky != 0u) {
        let l11 = clamp(p[2], -CHOLESKY_MAX, CHOLESKY_MAX);
        let l21 = clamp(p[3], -CHOLESKY_MAX, CHOLESKY_MAX);
        let l22 = clamp(p[4], -CHOLESKY_MAX, CHOLESKY_MAX);
        s = vec3<f32>(l11 * l11, l11 * l21, l21 * l21 + l22 * l22);
    } else {
        s = lsr_covariance(p[2], p[3], p[4]);
    }
    let a = clamp(s.x * fw * fw, VAR_MIN, VAR_MAX);
    let c = clamp(s.z * fh * fh, VAR_MIN, VAR_MAX);
    let lim = CORRELATION_MAX * sqrt(a * c);
    let b = clamp(s.y * fw * fh, -lim, lim);
    let det = a * c - b * b;

    // Steps 5-6: centre and pixel box.
    let mx = p[0] * fw;
    let my = p[1] * fh;
    let xs = pixel_span(mx, EXTENT_SIGMAS * sqrt(a), fit.width);
    let ys = pixel_span(my, EXTENT_SIGMAS * sqrt(c), fit.height);
    if (xs.x > xs.y || ys.x > ys.y) {
        return;
    }

    // Step 7: opacity and colour.
    var o = 1.0;
    if (fit.has_opacity != 0u) {
        o = clamp(p[8], 0.0, 1.0);
    }
    if (o < ALPHA_MIN) {
        return;
    }
    let col = clamp(vec3<f32>(p[5], p[6], p[7]), vec3<f32>(-COLOR_MAX), vec3<f32>(COLOR_MAX));
    gaussians[3u * g] = vec4<f32>(mx, my, c / det, -b / det);
    gaussians[3u * g + 1u] = vec4<f32>(a / det, o, col.x, col.y);
    gaussians[3u * g + 2u] = vec4<f32>(col.z, p[2], p[3], p[4]);
    boxes[g] = vec4<u32>(xs.x, ys.x, xs.y, ys.y);
    touched[g] = (xs.y / TILE - xs.x / TILE + 1u) * (ys.y / TILE - ys.x / TILE + 1u);
}
