// Shared by the three kernels of the stable LSD radix sort (`src/gpu/sort.rs`): the
// block shape and the per-pass uniform block. The host prepends it (after
// the contract constants) to each sort shader, since WGSL has no includes.
//
// A block is 1024 items, handled by one workgroup of 256 invocations in 4 rounds of 256,
// so that the scatter's stable ranking stays within one round (see sort_scatter.wgsl).
// Digits are 8 bits: 256 bins, one per invocation.

const SORT_WG: u32 = 256u;
// SORT_BLOCK comes with the contract constants, from `sort::BLOCK`.
const SORT_ROUNDS: u32 = SORT_BLOCK / SORT_WG;

struct SortParams {
    // The digit of this pass is (key >> shift) & 255.
    shift: u32,
    // ceil(capacity / SORT_BLOCK): the rows of the digit-major histogram.
    blocks: u32,
    // Items the buffers hold; the live ones are the first min(count[0], capacity).
    capacity: u32,
    _pad: u32,
}

