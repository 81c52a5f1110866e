// Where each Gaussian's tile-list entries start: an exclusive prefix sum of `touched`
// in stored order, and the total, which sizes the sort. One workgroup: each invocation
// sums a contiguous share, a scan of the GROUP shares, then each writes its share's
// offsets. Sums saturate, so an absurd total reads as an overflow, never as a small
// wrapped count.

@group(0) @binding(1) var<storage, read> touched: array<u32>;
@group(0) @binding(2) var<storage, read_write> first_entry: array<u32>;
// [0]: entries in all (the sort's count).
@group(0) @binding(3) var<storage, read_write> entries: array<u32>;

var<workgroup> sums: array<u32, GROUP>;

fn add_sat(a: u32, b: u32) -> u32 {
    let s = a + b;
    return select(s, 0xffffffffu, s < a);
}

@compute @workgroup_size(GROUP, 1, 1)
fn main(@builtin(local_invocation_index) lid: u32) {
    let n = fit.count;
    let share = (n + GROUP - 1u) / GROUP;
    let start = min(lid * share, n);
    let end = min(start + share, n);
    var s = 0u;
    for (var g = start; g < end; g = g + 1u) {
        s = add_sat(s, touched[g]);
    }
    sums[lid] = s;
    workgroupBarrier();
    // Inclusive scan of the shares (Hillis-Steele).
    for (var d = 1u; d < GROUP; d = d << 1u) {
        var v = sums[lid];
        if (lid >= d) {
            v = add_sat(v, sums[lid - d]);
        }
        workgroupBarrier();
        sums[lid] = v;
        workgroupBarrier();
    }
    var run = 0u;
    if (lid > 0u) {
        run = sums[lid - 1u];
    }
    for (var g = start; g < end; g = g + 1u) {
        first_entry[g] = run;
        run = add_sat(run, touched[g]);
    }
    if (lid == GROUP - 1u) {
        entries[0] = sums[GROUP - 1u];
    }
}
