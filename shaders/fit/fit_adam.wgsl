// The end of a step, one invocation per Gaussian: gather its gradient from the backward
// pass's slots, chain it to the stored parameters, and take an Adam step.
//
// - Gather: a Gaussian's slots are its entries in the tile lists, visited in tile order
//   (row-major over its pixel box), each found by a binary search (a tile lists its
//   Gaussians in stored order). The order is fixed, so the sum is deterministic.
// - Chain rule: `fit::params::chain` term by term, at the parameters this step rendered
//   (ln σ and θ as `fit_project.wgsl` left them); a clamp of spec §6 that is active passes
//   no gradient. Opacity needs no such test: every step clamps it to [0, 1], and so does
//   the upload.
// - Adam: `fit::params::Adam::step`, non-finite gradients counted as 0, then the same
//   clamps of opacity and log-scales.
// A step whose tile lists overflowed their buffers rendered an incomplete image, so it
// changes nothing.
//
// Eight storage buffers at most: the least every adapter offers.

@group(0) @binding(1) var<storage, read> gaussians: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> boxes: array<vec4<u32>>;
@group(0) @binding(3) var<storage, read> offsets: array<u32>;
@group(0) @binding(4) var<storage, read> indices: array<u32>;
@group(0) @binding(5) var<storage, read> slots: array<f32>;
@group(0) @binding(6) var<storage, read> entries: array<u32>;
@group(0) @binding(7) var<storage, read_write> params: array<f32>;
// Adam's first moments for all Gaussians, then the second moments.
@group(0) @binding(8) var<storage, read_write> moments: array<f32>;


fn finite(x: f32) -> bool {
    return (bitcast<u32>(x) & 0x7f800000u) != 0x7f800000u;
}

fn rate(k: u32) -> f32 {
    if (k < 2u) {
        return fit.lr_position;
    }
    if (k < 4u) {
        return fit.lr_log_scale;
    }
    if (k == 4u) {
        return fit.lr_rotation;
    }
    if (k < 8u) {
        return fit.lr_color;
    }
    return fit.lr_opacity;
}

// Position of Gaussian g in tile t's list.
fn entry_of(g: u32, t: u32) -> u32 {
    var lo = offsets[t];
    var hi = offsets[t + 1u];
    while (lo < hi) {
        let mid = lo + (hi - lo) / 2u;
        if (indices[mid] < g) {
            lo = mid + 1u;
        } else {
            hi = mid;
        }
    }
    return lo;
}

@compute @workgroup_size(GROUP, 1, 1)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let g = linear_id(wg, groups, lid);
    if (g >= fit.count || entries[0] > fit.capacity) {
        return;
    }
    var grad: array<f32, 9>;
    for (var k = 0u; k < STRIDE; k = k + 1u) {
        grad[k] = 0.0;
    }
    let b = boxes[g];
    if (b.x <= b.z) {
        var d: array<f32, 9>;
        for (var k = 0u; k < SLOT; k = k + 1u) {
            d[k] = 0.0;
        }
        for (var ty = b.y / TILE; ty <= b.w / TILE; ty = ty + 1u) {
            for (var tx = b.x / TILE; tx <= b.z / TILE; tx = tx + 1u) {
                let e = entry_of(g, ty * fit.tiles_x + tx);
                for (var k = 0u; k < SLOT; k = k + 1u) {
                    d[k] = d[k] + slots[SLOT * e + k];
                }
            }
        }
        let fw = f32(fit.width);
        let fh = f32(fit.height);
        grad[0] = d[0] * fw;
        grad[1] = d[1] * fh;
        grad[5] = d[6];
        grad[6] = d[7];
        grad[7] = d[8];
        if (fit.has_opacity != 0u) {
            grad[8] = d[5];
        }
        // dL/dΣ = -Q G Q, G the symmetric gradient of the conic Q = [[A, B], [B, C]].
        let q0 = gaussians[3u * g];
        let qa = q0.z;
        let qb = q0.w;
        let qc = gaussians[3u * g + 1u].x;
        let rendered = gaussians[3u * g + 2u];
        let ga = d[2];
        let gb = d[3] * 0.5;
        let gc = d[4];
        let m00 = qa * ga + qb * gb;
        let m01 = qa * gb + qb * gc;
        let m10 = qb * ga + qc * gb;
        let m11 = qb * gb + qc * gc;
        let d_a = -(m00 * qa + m01 * qb);
        let d_c = -(m10 * qb + m11 * qc);
        let d_b = -2.0 * (m00 * qb + m01 * qc);
        // The pixel covariance before its clamps, to know which clamps are active.
        let l1 = rendered.y;
        let l2 = rendered.z;
        let th = rendered.w;
        let sigma = lsr_covariance(l1, l2, th);
        let a = sigma.x * fw * fw;
        let c = sigma.z * fh * fh;
        let bb = sigma.y * fw * fh;
        let sn = sin(wrap_angle(th));
        let cs = cos(wrap_angle(th));
        let cc = cs * cs;
        let ss = sn * sn;
        let sc = sn * cs;
        var d_suu = 0.0;
        if (a >= VAR_MIN && a <= VAR_MAX) {
            d_suu = d_a * fw * fw;
        }
        var d_svv = 0.0;
        if (c >= VAR_MIN && c <= VAR_MAX) {
            d_svv = d_c * fh * fh;
        }
        var d_suv = 0.0;
        if (abs(bb) < CORRELATION_MAX * sqrt(clamp(a, VAR_MIN, VAR_MAX) * clamp(c, VAR_MIN, VAR_MAX))) {
            d_suv = d_b * fw * fh;
        }
        // Σ = R diag(v1, v2) Rᵀ with v = exp(2 ln σ), R the rotation by θ.
        let v1 = exp(2.0 * l1);
        let v2 = exp(2.0 * l2);
        if (l1 >= LN_SIGMA_MIN && l1 <= LN_SIGMA_MAX) {
            grad[2] = 2.0 * v1 * (d_suu * cc + d_suv * sc + d_svv * ss);
        }
        if (l2 >= LN_SIGMA_MIN && l2 <= LN_SIGMA_MAX) {
            grad[3] = 2.0 * v2 * (d_suu * ss - d_suv * sc + d_svv * cc);
        }
        let s2 = 2.0 * sc;
        let c2 = cc - ss;
        grad[4] = (v2 - v1) * s2 * d_suu + (v1 - v2) * c2 * d_suv + (v1 - v2) * s2 * d_svv;
    }
    let last = select(8u, 9u, fit.has_opacity != 0u);
    for (var k = 0u; k < last; k = k + 1u) {
        let i = g * STRIDE + k;
        var gk = grad[k];
        if (!finite(gk)) {
            gk = 0.0;
        }
        let j = fit.count * STRIDE + i;
        let m = fit.beta1 * moments[i] + (1.0 - fit.beta1) * gk;
        let v = fit.beta2 * moments[j] + (1.0 - fit.beta2) * gk * gk;
        moments[i] = m;
        moments[j] = v;
        var x = params[i] - rate(k) * (m / fit.c1) / (sqrt(v / fit.c2) + fit.eps);
        if (k == 2u || k == 3u) {
            x = clamp(x, LN_SIGMA_MIN, LN_SIGMA_MAX);
        }
        if (k == 8u) {
            x = clamp(x, 0.0, 1.0);
        }
        params[i] = x;
    }
}
