// Where each Gaussian's tile-list entries start: an exclusive prefix sum of `touched`
// in stored order, and the total, which sizes the sort. Two entry points, so that the
// work spreads over one workgroup per block of GROUP * SCAN_PER Gaussians rather than
// one workgroup for all (one SM of a hundred-plus):
// - `blocks`: each workgroup sums its block into `block_sums`;
// - `apply`: each workgroup adds up the block sums before its own, then writes its
//   Gaussians' offsets; the last block writes the total.
// (A dispatch between them that turned the block sums into offsets once would cost more
// than it saves: each dependent dispatch costs microseconds on a GPU.)
// Sums saturate, so an absurd total reads as an overflow, never as a small wrapped count.
// Saturating addition of unsigned values is associative, so any grouping gives the same
// numbers, bit for bit.

@group(0) @binding(1) var<storage, read> touched: array<u32>;
@group(0) @binding(2) var<storage, read_write> first_entry: array<u32>;
// [0]: entries in all (the sort's count).
@group(0) @binding(3) var<storage, read_write> entries: array<u32>;
// One per block: its sum.
@group(0) @binding(4) var<storage, read_write> block_sums: array<u32>;

var<workgroup> sums: array<u32, GROUP>;

fn add_sat(a: u32, b: u32) -> u32 {
    let s = a + b;
    return select(s, 0xffffffffu, s < a);
}

fn block_count() -> u32 {
    return (fit.count + GROUP * SCAN_PER - 1u) / (GROUP * SCAN_PER);
}

// Inclusive scan (Hillis-Steele) of `sums` across the workgroup, `sums[lid]` set by each
// invocation before the call.
fn scan_sums(lid: u32) {
    workgroupBarrier();
    for (var d = 1u; d < GROUP; d = d << 1u) {
        var v = sums[lid];
        if (lid >= d) {
            v = add_sat(v, sums[lid - d]);
        }
        workgroupBarrier();
        sums[lid] = v;
        workgroupBarrier();
    }
}

// The Gaussians of invocation `lid` of block `b`.
fn share_of(b: u32, lid: u32) -> vec2<u32> {
    let start = min(b * GROUP * SCAN_PER + lid * SCAN_PER, fit.count);
    return vec2<u32>(start, min(start + SCAN_PER, fit.count));
}

fn share_sum(share: vec2<u32>) -> u32 {
    var s = 0u;
    for (var g = share.x; g < share.y; g = g + 1u) {
        s = add_sat(s, touched[g]);
    }
    return s;
}

@compute @workgroup_size(GROUP, 1, 1)
fn blocks(@builtin(workgroup_id) wg: vec3<u32>,
          @builtin(num_workgroups) groups: vec3<u32>,
          @builtin(local_invocation_index) lid: u32) {
    let b = workgroup_index(wg, groups);
    if (b >= block_count()) {
        return;
    }
    sums[lid] = share_sum(share_of(b, lid));
    scan_sums(lid);
    if (lid == GROUP - 1u) {
        block_sums[b] = sums[GROUP - 1u];
    }
}

@compute @workgroup_size(GROUP, 1, 1)
fn apply(@builtin(workgroup_id) wg: vec3<u32>,
         @builtin(num_workgroups) groups: vec3<u32>,
         @builtin(local_invocation_index) lid: u32) {
    let b = workgroup_index(wg, groups);
    if (b >= block_count()) {
        // No Gaussians: no last block to write the total.
        if (b == 0u && lid == 0u) {
            entries[0] = 0u;
        }
        return;
    }
    // The blocks before this one.
    var before = 0u;
    for (var k = lid; k < b; k = k + GROUP) {
        before = add_sat(before, block_sums[k]);
    }
    sums[lid] = before;
    scan_sums(lid);
    var run = sums[GROUP - 1u];
    workgroupBarrier();
    let share = share_of(b, lid);
    sums[lid] = share_sum(share);
    scan_sums(lid);
    if (lid > 0u) {
        run = add_sat(run, sums[lid - 1u]);
    }
    for (var g = share.x; g < share.y; g = g + 1u) {
        first_entry[g] = run;
        run = add_sat(run, touched[g]);
    }
    if (b + 1u == block_count() && lid == GROUP - 1u) {
        entries[0] = run;
    }
}
