// The range of each parameter component over all Gaussians: what `Quantizer::fit` takes
// as the ends of its code range, so that quantization-aware steps render the parameters
// as the file will hold them. One workgroup; each invocation scans a strided share, then
// a tree reduction (min and max do not depend on order, so the result is exact).

@group(0) @binding(1) var<storage, read> params: array<f32>;
// (min, max) per component.
@group(0) @binding(2) var<storage, read_write> ranges: array<f32>;

var<workgroup> lo: array<f32, GROUP>;
var<workgroup> hi: array<f32, GROUP>;

@compute @workgroup_size(GROUP, 1, 1)
fn main(@builtin(local_invocation_index) lid: u32) {
    for (var k = 0u; k < STRIDE; k = k + 1u) {
        var a = 3.4e38;
        var b = -3.4e38;
        for (var g = lid; g < fit.count; g = g + GROUP) {
            let x = params[g * STRIDE + k];
            a = min(a, x);
            b = max(b, x);
        }
        lo[lid] = a;
        hi[lid] = b;
        workgroupBarrier();
        for (var s = GROUP / 2u; s > 0u; s = s >> 1u) {
            if (lid < s) {
                lo[lid] = min(lo[lid], lo[lid + s]);
                hi[lid] = max(hi[lid], hi[lid + s]);
            }
            workgroupBarrier();
        }
        if (lid == 0u) {
            ranges[2u * k] = lo[0];
            ranges[2u * k + 1u] = hi[0];
        }
        workgroupBarrier();
    }
}
