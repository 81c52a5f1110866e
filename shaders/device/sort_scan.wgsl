// Radix sort, step 2 of 3 per pass: the digit-major histogram, in place, becomes
// exclusive prefix sums, i.e. the first output slot of each (digit, block).
//
// The histogram read as one flat array (256 rows of `blocks` counts, digit-major) is
// scanned in three entry points, so that the work spreads over one workgroup per chunk
// of SORT_WG * SCAN_PER counts rather than one workgroup for all:
// - `chunks`: each workgroup sums its chunk into `chunk_sums`;
// - `top`: one workgroup turns the chunk sums into each chunk's starting offset;
// - `apply`: each workgroup rewrites its chunk's counts as running offsets.
// Plain integer sums: their grouping does not change them, so the offsets are those of
// a serial scan, deterministic.

@group(0) @binding(0) var<uniform> params: SortParams;
@group(0) @binding(1) var<storage, read_write> hist: array<u32>;
// One per chunk: its sum after `chunks`, its starting offset after `top`.
@group(0) @binding(2) var<storage, read_write> chunk_sums: array<u32>;

var<workgroup> sums: array<u32, 256>;

fn hist_len() -> u32 {
    return 256u * params.blocks;
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
fn top(@builtin(local_invocation_index) lid: u32) {
    let n = chunk_count();
    let share = (n + 255u) / 256u;
    let start = min(lid * share, n);
    let end = min(start + share, n);
    var s = 0u;
    for (var c = start; c < end; c = c + 1u) {
        s = s + chunk_sums[c];
    }
    sums[lid] = s;
    scan_sums(lid);
    var run = sums[lid] - s;
    for (var c = start; c < end; c = c + 1u) {
        let t = chunk_sums[c];
        chunk_sums[c] = run;
        run = run + t;
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
    let share = share_of(c, lid);
    let s = share_sum(share);
    sums[lid] = s;
    scan_sums(lid);
    var run = chunk_sums[c] + sums[lid] - s;
    for (var i = share.x; i < share.y; i = i + 1u) {
        let count = hist[i];
        hist[i] = run;
        run = run + count;
    }
}
