// The L2 loss of the render against the target and its gradient, `2 (x - y) / n` as
// `fit::loss` computes it, with per-workgroup partial sums the host reads only when it
// reports progress: the squared error in f32, and the squared error of the 8-bit values
// (spec §6.5 rounding) as an exact integer, from which the PSNR follows exactly as
// `metrics::psnr` computes it.

@group(0) @binding(1) var<storage, read> image: array<f32>;
@group(0) @binding(2) var<storage, read> target_rgb: array<f32>;
@group(0) @binding(3) var<storage, read_write> dl_dimage: array<f32>;
@group(0) @binding(4) var<storage, read_write> loss_part: array<f32>;
@group(0) @binding(5) var<storage, read_write> sse8_part: array<u32>;

var<workgroup> sq: array<f32, GROUP>;
var<workgroup> sq8: array<u32, GROUP>;

fn byte(x: f32) -> i32 {
    return i32(floor(clamp(x, 0.0, 1.0) * 255.0 + 0.5));
}

@compute @workgroup_size(GROUP, 1, 1)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let p = linear_id(wg, groups, lid);
    let pixels = fit.width * fit.height;
    let n = f32(3u * pixels);
    var s = 0.0;
    var s8 = 0u;
    if (p < pixels) {
        for (var c = 0u; c < 3u; c = c + 1u) {
            let o = 3u * p + c;
            let d = image[o] - target_rgb[o];
            dl_dimage[o] = 2.0 * d / n;
            s = s + d * d;
            let e = byte(image[o]) - byte(target_rgb[o]);
            s8 = s8 + u32(e * e);
        }
    }
    sq[lid] = s;
    sq8[lid] = s8;
    workgroupBarrier();
    for (var k = GROUP / 2u; k > 0u; k = k >> 1u) {
        if (lid < k) {
            sq[lid] = sq[lid] + sq[lid + k];
            sq8[lid] = sq8[lid] + sq8[lid + k];
        }
        workgroupBarrier();
    }
    if (lid == 0u) {
        let w = workgroup_index(wg, groups);
        loss_part[w] = sq[0];
        sse8_part[w] = sq8[0];
    }
}
