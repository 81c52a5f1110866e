// Radix sort, step 2 of 3 per pass: the digit-major histogram, in place, becomes
// exclusive prefix sums, i.e. the first output slot of each (digit, block).
//
// One workgroup of 256. The histogram is 256 rows (digits) of `blocks` counts, so
// invocation d serially sums row d, the 256 row totals are scanned in workgroup memory
// (Hillis–Steele, 8 steps), and invocation d rewrites its row as running offsets. Plain
// integer sums in a fixed order: deterministic. The serial rows cost O(blocks) per
// invocation, small beside the histogram and scatter for the sizes binning sorts (a
// million items is under 1000 blocks).

@group(0) @binding(0) var<uniform> params: SortParams;
@group(0) @binding(1) var<storage, read_write> hist: array<u32>;

var<workgroup> totals: array<u32, 256>;

@compute @workgroup_size(256, 1, 1)
fn main(@builtin(local_invocation_index) d: u32) {
    let row = d * params.blocks;
    var sum = 0u;
    for (var b = 0u; b < params.blocks; b = b + 1u) {
        sum = sum + hist[row + b];
    }
    totals[d] = sum;
    workgroupBarrier();
    for (var step = 1u; step < 256u; step = step << 1u) {
        var add = 0u;
        if (d >= step) {
            add = totals[d - step];
        }
        workgroupBarrier();
        totals[d] = totals[d] + add;
        workgroupBarrier();
    }
    // Inclusive total of digits ≤ d, less this row: where digit d starts.
    var offset = totals[d] - sum;
    for (var b = 0u; b < params.blocks; b = b + 1u) {
        let c = hist[row + b];
        hist[row + b] = offset;
        offset = offset + c;
    }
}
