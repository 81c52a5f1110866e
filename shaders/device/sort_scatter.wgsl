// Radix sort, step 3 of 3 per pass: each item goes to its (digit, block) offset plus its
// rank among the earlier items of the block with the same digit, which keeps equal
// digits in input order (a stable pass, so LSD passes compose into a stable sort).
//
// The rank must not depend on scheduling, so it is never taken from an atomic counter.
// The workgroup sorts its block's words `digit << SORT_INDEX_BITS | position` with a
// bitonic network (the positions are distinct, so the words are, and the order of the
// sorted block is fixed: by digit, then by position). An item's rank is then its place
// in the sorted block minus the place of the first item with its digit. Cost: 55
// compare-exchange steps of the workgroup, 12 KiB of workgroup memory, and no memory per
// digit beyond one slot, so digits can be 11 bits wide.

@group(0) @binding(0) var<uniform> params: SortParams;
@group(0) @binding(1) var<storage, read> count: array<u32>;
@group(0) @binding(2) var<storage, read> keys_in: array<u32>;
@group(0) @binding(3) var<storage, read> values_in: array<u32>;
// Output slot of the first item of each (digit, block), digit-major (sort_scan.wgsl).
@group(0) @binding(4) var<storage, read> offsets: array<u32>;
@group(0) @binding(5) var<storage, read_write> keys_out: array<u32>;
@group(0) @binding(6) var<storage, read_write> values_out: array<u32>;

// The word of a position past the live count: above every live word, so it sorts last.
const DEAD: u32 = 0xffffffffu;

var<workgroup> order: array<u32, SORT_BLOCK>;
// Place in `order` of the first item of each digit.
var<workgroup> first: array<u32, SORT_MAX_BINS>;

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
    let n = min(count[0], params.capacity);
    let base = block * SORT_BLOCK;
    for (var s = lid; s < SORT_BLOCK; s = s + SORT_WG) {
        var word = DEAD;
        if (base + s < n) {
            word = (digit_of(keys_in[base + s]) << SORT_INDEX_BITS) | s;
        }
        order[s] = word;
    }
    // Bitonic sort, ascending: stage (k, j) compares each place a whose bit j is clear
    // with a + j, in the direction that bit k of a gives.
    for (var k = 2u; k <= SORT_BLOCK; k = k << 1u) {
        for (var j = k >> 1u; j > 0u; j = j >> 1u) {
            workgroupBarrier();
            for (var q = lid; q < SORT_BLOCK / 2u; q = q + SORT_WG) {
                let a = ((q & ~(j - 1u)) << 1u) | (q & (j - 1u));
                let x = order[a];
                let y = order[a + j];
                if ((x > y) == ((a & k) == 0u)) {
                    order[a] = y;
                    order[a + j] = x;
                }
            }
        }
    }
    workgroupBarrier();
    for (var s = lid; s < SORT_BLOCK; s = s + SORT_WG) {
        let word = order[s];
        if (word != DEAD) {
            let d = word >> SORT_INDEX_BITS;
            if (s == 0u || (order[s - 1u] >> SORT_INDEX_BITS) != d) {
                first[d] = s;
            }
        }
    }
    workgroupBarrier();
    for (var s = lid; s < SORT_BLOCK; s = s + SORT_WG) {
        let word = order[s];
        if (word != DEAD) {
            let d = word >> SORT_INDEX_BITS;
            let src = base + (word & (SORT_BLOCK - 1u));
            let dst = offsets[d * params.blocks + block] + s - first[d];
            keys_out[dst] = keys_in[src];
            values_out[dst] = values_in[src];
        }
    }
}
