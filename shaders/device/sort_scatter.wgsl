// Radix sort, step 3 of 3 per pass: each item goes to its (digit, block) offset plus its
// rank among the earlier items of the block with the same digit, which keeps equal
// digits in input order (a stable pass, so LSD passes compose into a stable sort).
//
// The rank must not depend on scheduling, so it is never taken from an atomic counter.
// The block is walked in SORT_ROUNDS rounds of 256 items, one per invocation. In a round
// each item sets its bit (its local index) in a 256-bit mask of its digit; a bitwise OR
// gives the same mask whatever order the ORs land in. An item's rank is then the
// population count of its digit's mask below its own bit, plus `next[digit]`, the slot
// after the previous rounds' items of that digit. Cost: at most 8 popcounts per item and
// 8 KiB of workgroup memory for the masks.

@group(0) @binding(0) var<uniform> params: SortParams;
@group(0) @binding(1) var<storage, read> count: array<u32>;
@group(0) @binding(2) var<storage, read> keys_in: array<u32>;
@group(0) @binding(3) var<storage, read> values_in: array<u32>;
// Output slot of the first item of each (digit, block), digit-major (sort_scan.wgsl).
@group(0) @binding(4) var<storage, read> offsets: array<u32>;
@group(0) @binding(5) var<storage, read_write> keys_out: array<u32>;
@group(0) @binding(6) var<storage, read_write> values_out: array<u32>;

// Output slot of this block's next item of each digit.
var<workgroup> next: array<u32, 256>;
// Bit (j % 32) of masks[d * 8 + j / 32] is set when item j of the round has digit d.
var<workgroup> masks: array<atomic<u32>, 2048>;

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
    // Invocation lid looks after digit lid's slot and mask words between rounds.
    next[lid] = offsets[lid * params.blocks + block];
    for (var w = 0u; w < 8u; w = w + 1u) {
        atomicStore(&masks[lid * 8u + w], 0u);
    }
    let n = min(count[0], params.capacity);
    let word = lid / 32u;
    let bit = 1u << (lid % 32u);
    workgroupBarrier();
    for (var r = 0u; r < SORT_ROUNDS; r = r + 1u) {
        let i = block * SORT_BLOCK + r * SORT_WG + lid;
        let live = i < n;
        var key = 0u;
        var digit = 0u;
        if (live) {
            key = keys_in[i];
            digit = (key >> params.shift) & 255u;
            atomicOr(&masks[digit * 8u + word], bit);
        }
        workgroupBarrier();
        if (live) {
            let m = digit * 8u;
            var rank = countOneBits(atomicLoad(&masks[m + word]) & (bit - 1u));
            for (var w = 0u; w < word; w = w + 1u) {
                rank = rank + countOneBits(atomicLoad(&masks[m + w]));
            }
            let dst = next[digit] + rank;
            keys_out[dst] = key;
            values_out[dst] = values_in[i];
        }
        workgroupBarrier();
        // Advance digit lid past this round's items and clear its mask.
        var seen = 0u;
        for (var w = 0u; w < 8u; w = w + 1u) {
            seen = seen + countOneBits(atomicLoad(&masks[lid * 8u + w]));
            atomicStore(&masks[lid * 8u + w], 0u);
        }
        next[lid] = next[lid] + seen;
        workgroupBarrier();
    }
}
