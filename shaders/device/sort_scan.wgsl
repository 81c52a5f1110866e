// Radix sort, step 2 of 3 per pass: the digit-major histogram, in place, becomes
// exclusive prefix sums, i.e. the first output slot of each (digit, block).
//
// The histogram read as one flat array (one row of `blocks` counts per digit) is
// scanned in two entry points, so that the work spreads over one workgroup per chunk
// of SORT_WG * SCAN_PER counts rather than one workgroup for all:
// - `chunks`: each workgroup sums its chunk into `chunk_sums`;
// - `apply`: each workgroup adds up the chunk sums before its own (at most a few hundred
//   even at 12 MP), then rewrites its chunk's counts as running offsets.
// A third dispatch that turned the chunk sums into offsets once would cost more than it
// saves: on a GPU each dependent dispatch costs microseconds however little it does.
// Plain integer sums: their grouping does not change them, so the offsets are those of
// a serial scan, deterministic.

@group(0) @binding(0) var<uniform> params: SortParams;
@group(0) @binding(1) var<storage, read_write> hist: array<u32>;
// One per chunk: its sum.
@group(0) @binding(2) var<storage, read_write> chunk_sums: array<u32>;
// With `params.ranges`, the first slot of each key 0..=ranges (see sort_common.wgsl).
@group(0) @binding(3) var<storage, read_write> ranges_out: array<u32>;

var<workgroup> sums: array<u32, 256>;

fn hist_len() -> u32 {
    return sort_bins() * params.blocks;
}

fn chunk_count() -> u32 {
    return (hist_len() + SORT_WG * SCAN_PER - 1u) / (SORT_WG * SCAN_PER);
}

// Inclusive scan (Hillis–Steele) of `sums` across the workgroup.
fn scan_sums(lid: u32) {
    workgroupBarrier();
    for (var step = 1u; step < 256u; step = step << 1u) {
        var add = 0u;
        if (lid >= step) {
            add = sums[lid - step];
        }
        workgroupBarrier();
        sums[lid] = sums[lid] + add;
        workgroupBarrier();
    }
}

// The counts of invocation `lid` of chunk `c`.
fn share_of(c: u32, lid: u32) -> vec2<u32> {
    let start = min(c * SORT_WG * SCAN_PER + lid * SCAN_PER, hist_len());
    return vec2<u32>(start, min(start + SCAN_PER, hist_len()));
}

fn share_sum(share: vec2<u32>) -> u32 {
    var s = 0u;
    for (var i = share.x; i < share.y; i = i + 1u) {
        s = s + hist[i];
    }
    return s;
}

@compute @workgroup_size(256, 1, 1)
fn chunks(@builtin(workgroup_id) wg: vec3<u32>,
          @builtin(num_workgroups) groups: vec3<u32>,
          @builtin(local_invocation_index) lid: u32) {
    let c = workgroup_index(wg, groups);
    if (c >= chunk_count()) {
        return;
    }
    sums[lid] = share_sum(share_of(c, lid));
    scan_sums(lid);
    if (lid == 255u) {
        chunk_sums[c] = sums[255u];
    }
}

@compute @workgroup_size(256, 1, 1)
fn apply(@builtin(workgroup_id) wg: vec3<u32>,
         @builtin(num_workgroups) groups: vec3<u32>,
         @builtin(local_invocation_index) lid: u32) {
    let c = workgroup_index(wg, groups);
    if (c >= chunk_count()) {
        return;
    }
    // The chunks before this one.
    var before = 0u;
    for (var k = lid; k < c; k = k + 256u) {
        before = before + chunk_sums[k];
    }
    sums[lid] = before;
    scan_sums(lid);
    let offset = sums[255u];
    workgroupBarrier();
    let share = share_of(c, lid);
    let s = share_sum(share);
    sums[lid] = s;
    scan_sums(lid);
    var run = offset + sums[lid] - s;
    let ranges = params.ranges;
    for (var i = share.x; i < share.y; i = i + 1u) {
        let count = hist[i];
        hist[i] = run;
        // Block 0 of digit d: the first slot of key d. For d = ranges below the last
        // digit, every live key is below it, so that slot is the live count.
        if (ranges != 0u && i % params.blocks == 0u && i / params.blocks <= ranges) {
            ranges_out[i / params.blocks] = run;
        }
        run = run + count;
    }
    // Where the keys use every digit, the end of the last range is the histogram's total,
    // which the one invocation holding its last count has.
    if (ranges != 0u && ranges == sort_bins() && share.x < share.y && share.y == hist_len()) {
        ranges_out[ranges] = run;
    }
}
