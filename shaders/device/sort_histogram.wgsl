// Radix sort, step 1 of 3 per pass: how many items of each block have each digit.
//
// One workgroup per block of SORT_BLOCK items. Counts are gathered with workgroup u32
// atomics: a count does not depend on the order the additions land in, so the result is
// deterministic. They are written digit-major, hist[digit * blocks + block], so that one
// exclusive scan of the whole array (sort_scan.wgsl) gives every (digit, block) its first
// output slot, digits in order and, within a digit, blocks in order: what stability needs.
// Blocks past the live count still write their (zero) counts, because the scan reads
// every row and the host does not know the count.

@group(0) @binding(0) var<uniform> params: SortParams;
@group(0) @binding(1) var<storage, read> count: array<u32>;
@group(0) @binding(2) var<storage, read> keys: array<u32>;
@group(0) @binding(3) var<storage, read_write> hist: array<u32>;

var<workgroup> bins: array<atomic<u32>, SORT_MAX_BINS>;

@compute @workgroup_size(256, 1, 1)
fn main(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let block = workgroup_index(wg, groups);
    if (block >= params.blocks) {
        return;
    }
    let nbins = sort_bins();
    for (var d = lid; d < nbins; d = d + SORT_WG) {
        atomicStore(&bins[d], 0u);
    }
    workgroupBarrier();
    let n = min(count[0], params.capacity);
    for (var r = 0u; r < SORT_ROUNDS; r = r + 1u) {
        let i = block * SORT_BLOCK + r * SORT_WG + lid;
        if (i < n) {
            atomicAdd(&bins[digit_of(keys[i])], 1u);
        }
    }
    workgroupBarrier();
    for (var d = lid; d < nbins; d = d + SORT_WG) {
        hist[d * params.blocks + block] = atomicLoad(&bins[d]);
    }
}
